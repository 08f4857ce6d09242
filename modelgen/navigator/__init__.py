"""A complete GNSS/INS navigator flown on recorded logs.

One module per idea: :mod:`logs` reads the IMU CSV and the RTKLIB .pos file,
:mod:`config` the navigator configuration, :mod:`mechanization` is the
strapdown NED mechanization, :mod:`spec` reads what the navigator needs from
the derived model file (any navigation model: error blocks, feedback, P0,
measurement rows, parameter code; derived once per replay), :mod:`cconfig` is
the C configuration's one field list, :mod:`errorstate` drives the generated
filter (models ``models/ins_gps15_nav.yaml``, ``models/ins_gnss21_rw_nav.yaml``
or the user's), :mod:`outages` builds the simulated GNSS
outages, :mod:`navigator` is the forward real-time loop (the Python reference),
:mod:`cnav` generates, compiles and drives the C navigator
(templates/navigator_*.j2), :mod:`embedded` builds it for the Cortex-M4F and
replays under qemu-arm, :mod:`metrics` and :mod:`report` turn a flight into the
summary, figures and trajectory files, :mod:`replay` runs it all and
:mod:`cli` is ``modelgen replay``.
"""
