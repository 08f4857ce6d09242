"""A complete GNSS/INS navigator flown on recorded logs (issue 13).

One module per idea: :mod:`logs` reads the IMU CSV and the RTKLIB .pos file,
:mod:`config` the navigator configuration, :mod:`mechanization` is the
strapdown NED mechanization, :mod:`errorstate` drives the generated
``ins_gps15`` filter, :mod:`outages` builds the simulated GNSS outages,
:mod:`navigator` is the forward real-time loop, :mod:`metrics` and
:mod:`report` turn a flight into the summary, figures and trajectory files,
and :mod:`cli` is ``modelgen replay``.
"""
