"""Trajectory generation: the held-angle shortcut gives the numbers of computing every angle each sample."""

import math

import numpy as np

from modelgen.simulation.scenario import load_profile
from modelgen.simulation.trajectory import (HEADING_HELD, PITCH_HELD, ROLL_HELD, FlightPath, Segment, _increments,
                                            _truth_records, segment_table)


def _every_kind_of_segment() -> FlightPath:
    """Climb, level off, cruise, roll in, banked turn, roll out, accelerate: each angle held and moving."""
    d = math.radians
    return FlightPath("mixed", d(30.0), d(120.0), 500.0, 120.0, d(10.0), -5.0, 0.0, (
        Segment("climb", 20.0), Segment("level off", 25.0, vertical_acceleration=0.2), Segment("cruise", 15.0),
        Segment("roll in", 5.0, roll_rate=d(-6.0)), Segment("turn", 30.0, turn_rate=d(-1.5)),
        Segment("roll out", 5.0, roll_rate=d(6.0)), Segment("accelerate", 10.0, horizontal_acceleration=0.5)))


def _generate(table: np.ndarray, path: FlightPath, dt: float) -> tuple[np.ndarray, ...]:
    n = int(path.duration / dt)
    truth = np.empty((n // 10 + 1, 11))
    _truth_records(table, path.latitude, path.longitude, dt, n, 10, truth)
    theta, velocity = np.empty((n, 3)), np.empty((n, 3))
    _increments(table, path.latitude, path.longitude, dt, 0, n, theta, velocity, truth, 10, False)
    return truth, theta, velocity


def test_held_angles_give_the_increments_and_truth_of_computing_every_angle_bit_for_bit():
    for path in (_every_kind_of_segment(), load_profile("profile_001").path.truncated(900.0)):
        table = segment_table(path)
        flags = table[:, [HEADING_HELD, ROLL_HELD, PITCH_HELD]]
        assert flags.any() and not flags.all()  # some angles held, some moving
        computed = table.copy()
        computed[:, [HEADING_HELD, ROLL_HELD, PITCH_HELD]] = 0.0  # every angle's functions computed per sample
        for held, each in zip(_generate(table, path, 0.01), _generate(computed, path, 0.01)):
            assert np.array_equal(held, each)
