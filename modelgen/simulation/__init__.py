"""Navigation simulation: the generated filters on simulated flights.

Data flows one way through the modules:

    scenario (flight profile, profile_*.yaml; ``profile_keys``) -> trajectory (truth, ideal IMU increments
    on WGS-84, ``earth``) -> imu and the aiding sensor (``sensors``: a registry of plug-ins, ``aiding``;
    ``doppler``, ``gps``, ``pseudorange``) -> strapdown (mechanization) -> flight (sensors drawn, the
    sensor's navigator, ``ins_aiding``) -> filter_loop (correction modes, faults; ``filters``,
    ``error_layout``) -> montecarlo (ensembles, NEES) -> flight_report (`modelgen simulate`: ``flight_start``
    makes the truth and IMU errors early, ``flight_errors`` measures the outputs, ``flight_figures`` draws them,
    ``figure_process`` in other processes, ``flight_summary`` writes summary.md).

A flight is flown in pieces (``streaming``): a streamed trajectory holds only
the truth, the IMU errors replay from saved generator positions, every
correction mode steps through each piece in one pass, and histories go to
memory at a chosen rate and, if asked, to CSV files as they are made
(``history``).  With the generated C filter the cycle runs in one compiled
loop (``native_loop``); other filters and sensors fly the Python loop.

Hot loops are compiled with numba when it is installed (``jit``).
"""
