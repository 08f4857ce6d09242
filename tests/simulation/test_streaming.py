"""Streaming: a flight flown in pieces is bit for bit the flight flown whole, whatever the piece length."""

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.simulation.filter_loop import recorded_cycles
from modelgen.simulation.filters import ReferenceFilter
from modelgen.simulation.flight import fly_profile, profile_layout, simulate_sensors
from modelgen.simulation.imu import ImuErrorBudget, ImuErrorStream, corrupt_increments
from modelgen.simulation.scenario import load_profile
from modelgen.simulation.streaming import fly_modes
from modelgen.simulation.trajectory import generate_trajectory

pytestmark = pytest.mark.flight

FIELDS = ("times", "outputs", "raw_outputs", "estimation_error", "sigma", "nees")


@pytest.fixture(scope="module")
def scenario():
    """Five minutes of the paper's flight (the climb) at a 30 Hz IMU, Doppler every 60 s."""
    return load_profile("profile_000").with_changes(hours=1 / 12, imu_rate=30.0)


def test_streamed_trajectory_pieces_are_the_whole_trajectorys_increments(scenario):
    whole = generate_trajectory(scenario.path, scenario.imu_rate, 1.0)
    streamed = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=True)
    assert streamed.delta_theta is None and streamed.n_samples == whole.n_samples
    assert np.array_equal(streamed.truth, whole.truth)
    step = 7 * streamed.record_every
    pieces = [streamed.increments(a, a + step) for a in range(0, streamed.n_samples, step)]
    assert np.array_equal(np.concatenate([p[0] for p in pieces]), whole.delta_theta)
    assert np.array_equal(np.concatenate([p[1] for p in pieces]), whole.delta_velocity)
    with pytest.raises(ModelError, match="must start at a record sample"):
        streamed.increments(1, 10)


@pytest.mark.parametrize("n, record_every, piece", [(5000, 30, 60), (4999, 7, 91), (300, 300, 300)])
def test_imu_error_stream_replays_the_whole_realization_bit_for_bit(n, record_every, piece):
    budget = ImuErrorBudget(1e-6, 2e-6, 3600.0, 1e-7, 1e-5, 1e-3, 2e-3, 1800.0, 1e-4, 2e-5)  # every error present
    ideal = np.random.default_rng(3)
    theta, velocity = ideal.standard_normal((n, 3)), ideal.standard_normal((n, 3))
    rng_whole, rng_stream = np.random.default_rng(9), np.random.default_rng(9)
    measured_theta, measured_velocity, history = corrupt_increments(theta, velocity, 0.01, budget, rng_whole, record_every)
    stream = ImuErrorStream(budget, 0.01, n, record_every, rng_stream)
    # the generator goes on exactly as after the whole-flight draw (initial errors, aiding sensor...)
    assert np.array_equal(rng_whole.standard_normal(5), rng_stream.standard_normal(5))
    cursor = stream.cursor()
    parts = [cursor.corrupt(theta[i:i + piece], velocity[i:i + piece]) for i in range(0, n, piece)]
    assert np.array_equal(np.concatenate([p[0] for p in parts]), measured_theta)
    assert np.array_equal(np.concatenate([p[1] for p in parts]), measured_velocity)
    for name in ("gyro_constant", "gyro_markov", "accel_constant", "accel_markov", "gyro_scale_factor", "accel_scale_factor"):
        assert np.array_equal(getattr(stream.history, name), getattr(history, name)), name


def test_truth_positions_integrated_by_the_pieces_are_the_truths_and_the_pieces_must_come_in_order(scenario):
    plain = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=True)
    later = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=True, positions_in_pieces=True)
    motion = [0, *range(3, 11)]  # time, height, velocity, attitude: closed form, there from the start
    assert np.array_equal(later.truth[:, motion], plain.truth[:, motion]) and np.array_equal(later.truth[0], plain.truth[0])
    assert np.isnan(later.truth[1:, 1:3]).all()
    step = 7 * later.record_every
    with pytest.raises(ModelError, match="not known yet"):
        later.increments(step, 2 * step)
    for start in range(0, later.n_samples, step):
        made, wanted = later.increments(start, start + step), plain.increments(start, start + step)
        assert np.array_equal(made[0], wanted[0]) and np.array_equal(made[1], wanted[1])
    assert np.array_equal(later.truth, plain.truth)
    with pytest.raises(ModelError, match="needs a streamed trajectory"):
        generate_trajectory(scenario.path, scenario.imu_rate, 1.0, positions_in_pieces=True)


def test_a_flight_whose_pieces_integrate_the_truth_positions_is_the_streamed_flight_bit_for_bit(scenario, paper_derived):
    streamed = _fly(scenario, paper_derived, True, 7.0)
    for piece_seconds in (7.0, 60.0):
        later = _fly(scenario, paper_derived, True, piece_seconds, positions_in_pieces=True)
        for mode, result in streamed.items():
            assert result.updates == later[mode].updates
            for name in FIELDS:
                assert np.array_equal(getattr(result, name), getattr(later[mode], name), equal_nan=True), (mode, name)


def _fly(scenario, derived, streamed, piece_seconds, record_every=1, positions_in_pieces=False):
    trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=streamed,
                                     positions_in_pieces=positions_in_pieces)
    layout = profile_layout(scenario, derived, trajectory)
    sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(21))
    return fly_modes(scenario, derived, trajectory, sensors, layout, lambda x, P: ReferenceFilter(derived, x, P),
                     ("open_loop", "closed_loop", "accumulated"), piece_seconds=piece_seconds, record_every=record_every)


def test_a_streamed_flight_is_the_held_flight_bit_for_bit_for_any_piece_length(scenario, paper_derived):
    held = _fly(scenario, paper_derived, False, 10.0)
    for piece_seconds in (1.0, 7.0, 1e6):
        streamed = _fly(scenario, paper_derived, True, piece_seconds)
        for mode, result in held.items():
            assert result.updates == streamed[mode].updates == 5
            for name in FIELDS:
                assert np.array_equal(getattr(result, name), getattr(streamed[mode], name), equal_nan=True), (mode, name, piece_seconds)


def test_fly_profile_on_a_streamed_trajectory_matches_the_held_one(scenario, paper_derived):
    results = []
    for streamed in (False, True):
        trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=streamed)
        results.append(fly_profile(scenario, paper_derived, trajectory, np.random.default_rng(4),
                                   lambda x, P: ReferenceFilter(paper_derived, x, P), mode="closed_loop"))
    for name in FIELDS:
        assert np.array_equal(getattr(results[0], name), getattr(results[1], name), equal_nan=True), name


def test_decimated_histories_are_the_full_rate_rows_at_the_recorded_cycles(scenario, paper_derived):
    full = _fly(scenario, paper_derived, True, 10.0)
    decimated = _fly(scenario, paper_derived, True, 10.0, record_every=7)
    cycles = recorded_cycles(len(full["closed_loop"].times) - 1, 7)
    assert cycles[-1] == 300 and cycles[-2] == 294  # every 7th and the last
    for mode, result in full.items():
        assert decimated[mode].updates == result.updates
        for name in FIELDS:
            assert np.array_equal(getattr(result, name)[cycles], getattr(decimated[mode], name), equal_nan=True)


def test_a_piece_length_that_is_not_a_positive_number_is_refused(scenario, paper_derived):
    with pytest.raises(ModelError, match="piece length must be a positive number of seconds"):
        _fly(scenario, paper_derived, True, 0.0)


@pytest.mark.parametrize("probability, dimension", [(0.9999, 1), (0.9999, 2), (0.95, 3), (0.5, 8)])
def test_gate_threshold_is_scipys_chi_square_quantile(probability, dimension):
    from scipy.stats import chi2

    from modelgen.simulation.filter_loop import gate_threshold

    assert gate_threshold(probability, dimension) == chi2.ppf(probability, dimension)


def test_markov_recursion_is_lfilter_bit_for_bit():
    from scipy.signal import lfilter

    from modelgen.simulation.imu import markov_sequence

    a = np.exp(-1.0 / 300.0 / 3600.0)
    drive = 1e-3 * np.random.default_rng(2).standard_normal((20000, 3))
    rng = np.random.default_rng(8)
    sequence = markov_sequence(20000, 1e-3, 3600.0, 1.0 / 300.0, rng)
    rng = np.random.default_rng(8)
    drive = 1e-3 * np.sqrt(1.0 - a * a) * rng.standard_normal((20000, 3))
    drive[0] = 1e-3 * rng.standard_normal(3)
    assert np.array_equal(sequence, lfilter([1.0], [1.0, -a], drive, axis=0))


def test_histories_are_written_piece_by_piece_with_the_rows_held_in_memory(scenario, paper_derived, tmp_path):
    import csv

    from modelgen.simulation.history import CsvHistory, history_columns

    trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=True)
    layout = profile_layout(scenario, paper_derived, trajectory)
    sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(21))
    names = paper_derived.model.state_names
    histories = {mode: CsvHistory(tmp_path / f"{mode}.csv", names) for mode in ("open_loop", "closed_loop")}
    seen = []

    class Watching(CsvHistory):  # the file grows while the flight goes on, one piece at a time
        def write(self, result, start, stop):
            seen.append(stop)
            super().write(result, start, stop)

    histories["closed_loop"].close()
    histories["closed_loop"] = Watching(tmp_path / "closed_loop.csv", names)
    results = fly_modes(scenario, paper_derived, trajectory, sensors, layout,
                        lambda x, P: ReferenceFilter(paper_derived, x, P), ("open_loop", "closed_loop"),
                        piece_seconds=60.0, record_every=10, histories=histories)
    for history in histories.values():
        history.close()
    assert seen == [7, 13, 19, 25, 31]  # row 0 and rows every 10 s: 6 more per 60-s piece, the last included
    for mode, result in results.items():
        with open(tmp_path / f"{mode}.csv", newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
        assert rows[0] == history_columns(names) and len(rows) == len(result.times) + 1
        table = np.array(rows[1:], dtype=float)
        assert np.array_equal(table[:, 0], result.times)
        assert np.array_equal(table[:, 11:11 + len(names)], result.estimation_error)  # repr: exact round trip
        assert np.array_equal(table[:, -1], result.nees, equal_nan=True)


def test_streamed_errors_on_a_held_trajectory_fly_the_held_flight_bit_for_bit(scenario, paper_derived):
    trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0)
    layout = profile_layout(scenario, paper_derived, trajectory)
    results = []
    for stream_errors in (False, True):
        sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(21), stream_errors=stream_errors)
        assert sensors.streamed == stream_errors
        results.append(fly_modes(scenario, paper_derived, trajectory, sensors, layout,
                                 lambda x, P: ReferenceFilter(paper_derived, x, P), ("closed_loop",), piece_seconds=7.0))
    for name in FIELDS:
        assert np.array_equal(getattr(results[0]["closed_loop"], name), getattr(results[1]["closed_loop"], name),
                              equal_nan=True), name


def test_imu_errors_drawn_before_the_truth_give_the_same_sensors_and_a_foreign_stream_is_refused(scenario):
    from modelgen.simulation.flight import imu_error_stream
    from modelgen.simulation.trajectory import sample_counts

    trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=True)
    assert sample_counts(scenario.path, scenario.imu_rate, 1.0) == (trajectory.n_samples, trajectory.record_every)
    plain = simulate_sensors(scenario, trajectory, np.random.default_rng(21))
    rng = np.random.default_rng(21)
    early = simulate_sensors(scenario, trajectory, rng,
                             imu_stream=imu_error_stream(scenario, trajectory.n_samples, trajectory.record_every, rng))
    assert np.array_equal(plain.initial_navigation, early.initial_navigation)
    assert np.array_equal(plain.altitude_reference, early.altitude_reference)
    assert np.array_equal(plain.aiding.velocity, early.aiding.velocity)
    pieces = [s.imu_stream.cursor().corrupt(*trajectory.increments(0, 600)) for s in (plain, early)]
    assert all(np.array_equal(a, b) for a, b in zip(*pieces))
    foreign = imu_error_stream(scenario, trajectory.n_samples - 30, trajectory.record_every, np.random.default_rng(1))
    with pytest.raises(ModelError, match="IMU error stream .* is not this trajectory's"):
        simulate_sensors(scenario, trajectory, np.random.default_rng(21), imu_stream=foreign)
