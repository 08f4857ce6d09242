"""Navigation simulation (issue 5): the generated filters on simulated flights.

Data flows one way through the modules:

    scenario (profile_*.yaml) -> trajectory (truth, ideal IMU increments on WGS-84, ``earth``)
    -> imu, doppler, gps (sensor errors) -> strapdown (mechanization)
    -> integration (filter, correction modes, faults; ``filters``, ``error_layout``)
    -> montecarlo (ensembles, NEES) -> report (`modelgen simulate`: figures, summary).

Hot loops are compiled with numba when it is installed (``jit``).
"""
