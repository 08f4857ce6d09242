"""Trajectory generation: the held-angle shortcut gives the numbers of computing every angle each sample; the
software-pipelined, memoized increments give the numbers of taking the samples one after the other; a held trajectory's truth
positions, filled by its increments, are those the truth integration computes."""

import math

import numpy as np
import pytest

from modelgen.simulation.scenario import load_profile
from modelgen.simulation.trajectory import (HEADING_HELD, MEMO_COLUMNS, PITCH_HELD, ROLL_HELD, FlightPath, Segment,
                                            _increments, _position_rate, _rk4_from, _segment_index,
                                            _split_sample_increments, _truth_records, generate_trajectory,
                                            segment_table)

pytestmark = pytest.mark.flight


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


def _one_sample_after_the_other(table: np.ndarray, path: FlightPath, dt: float, n: int) -> tuple[np.ndarray, ...]:
    """The increments as the plain algorithm takes them: each sample's RK4, then its Gauss nodes on each part of the
    sample a segment boundary leaves (every sample by the general, splitting path, every node computed), then the
    next sample."""
    starts = table[:, 0]
    lat, lon, seg = path.latitude, path.longitude, 0
    theta, velocity = np.empty((n, 3)), np.empty((n, 3))
    for k in range(n):
        seg = _segment_index(k * dt, starts, seg)
        k1a, k1o, _ = _position_rate(k * dt, lat, table, seg)
        lat1, lon1, _, i1 = _rk4_from(table, starts, seg, k, dt, lat, lon, k1a, k1o)
        m1, _, _ = _position_rate((k + 1) * dt, lat1, table, i1)
        sums = _split_sample_increments(table, starts, seg, k * dt, (k + 1) * dt, dt, lat, k1a, lat1, m1,
                                        np.full((3, MEMO_COLUMNS), np.nan))  # no memo: every node computed
        theta[k], velocity[k] = sums[:3], sums[3:]
        lat, lon = lat1, lon1
    return theta, velocity


def _along_a_parallel(latitude_deg: float, heading_deg: float) -> FlightPath:
    """Climb, level off and cruise on one heading: due east (90 deg) the latitude stays the same to the last bit and
    the cruise repeats its integrands node after node (the memos give them back); the equator's latitude is a zero."""
    d = math.radians
    return FlightPath("parallel", d(latitude_deg), d(7.0), 300.0, 100.0, d(heading_deg), -3.0, 0.0, (
        Segment("climb", 3.0), Segment("level off", 3.0, vertical_acceleration=1.0), Segment("cruise", 40.0)))


@pytest.mark.parametrize("path, dt", [
    (_every_kind_of_segment(), 1.0 / 7.3),  # segment boundaries fall inside samples: those samples are split
    (_along_a_parallel(45.0, 90.0), 0.01),  # the memos hit
    (_along_a_parallel(0.0, 90.0), 0.01),  # a zero latitude: never taken from a memo
    (_along_a_parallel(-30.0, 0.0), 0.01),  # due north: heading and roll zeros in the memo keys
], ids=["every kind of segment", "east", "east on the equator", "north"])
def test_pipelined_memoized_increments_are_those_of_taking_the_samples_one_after_the_other_bit_for_bit(path, dt):
    n = int(path.duration / dt)
    table = segment_table(path)
    plain = _one_sample_after_the_other(table, path, dt, n)
    truth = np.empty((n // 10 + 1, 11))
    _truth_records(table, path.latitude, path.longitude, dt, n, 10, truth)
    last = (n - 1) // 10 * 10  # pieces start at a record sample (every 10th), from its truth row's position
    for start, stop in ((0, n), (10, n), (30, 31), (0, 1), (last, n), (last, last + 1)):  # whole, pieces, one sample
        theta, velocity = np.empty((stop - start, 3)), np.empty((stop - start, 3))
        _increments(table, truth[start // 10, 1], truth[start // 10, 2], dt, start, stop, theta, velocity, truth, 10,
                    False)
        assert np.array_equal(theta, plain[0][start:stop]) and np.array_equal(velocity, plain[1][start:stop])


def test_a_held_trajectorys_truth_positions_are_those_the_truth_integration_computes_bit_for_bit():
    path = _every_kind_of_segment()
    held = generate_trajectory(path, 50.0, 5.0)  # positions filled by the increments
    integrated = generate_trajectory(path, 50.0, 5.0, streamed=True)  # positions from _truth_records
    assert not np.isnan(held.truth).any()
    assert np.array_equal(held.truth, integrated.truth)
