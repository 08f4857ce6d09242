"""A complete GNSS/INS navigator flown on recorded logs (issue 13).

One module per idea: :mod:`logs` reads the IMU CSV and the RTKLIB .pos file,
:mod:`config` the navigator configuration, :mod:`mechanization` is the
strapdown NED mechanization, :mod:`errorstate` drives the generated filter
(model ``models/ins_gps15_nav.yaml``), :mod:`outages` builds the simulated GNSS
outages, :mod:`navigator` is the forward real-time loop (the Python reference),
:mod:`cnav` generates, compiles and drives the C navigator
(templates/navigator_*.j2), :mod:`embedded` builds it for the Cortex-M4F and
replays under qemu-arm, :mod:`metrics` and :mod:`report` turn a flight into the
summary, figures and trajectory files, :mod:`replay` runs it all and
:mod:`cli` is ``modelgen replay``.
"""
