"""The compiled filter loop (strapdown, glue and generated C in one loop) flies as the Python loop does."""

import shutil

import numpy as np
import pytest

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.loading import load_model
from modelgen.simulation.filters import filter_factory
from modelgen.simulation.flight import profile_layout, simulate_sensors
from modelgen.simulation.native_loop import native_supported
from modelgen.simulation.scenario import load_profile
from modelgen.simulation.streaming import fly_modes
from modelgen.simulation.trajectory import generate_trajectory

pytestmark = [pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler"),
              pytest.mark.compile, pytest.mark.flight]

MODES = ("open_loop", "closed_loop", "accumulated")
EXACT = ("times", "outputs", "raw_outputs", "estimation_error", "sigma")


def fly_both(scenario, derived, tmp_path, **changes):
    """The three modes by the Python loop and by the compiled loop, same C filter and sensors."""
    make = filter_factory(derived, "c", tmp_path)
    results = {}
    for glue in ("python", "compiled"):
        trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0 / scenario.filter.period, streamed=True)
        sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(5))
        layout = profile_layout(scenario, derived, trajectory)
        results[glue] = fly_modes(scenario, derived, trajectory, sensors, layout, make, MODES, glue=glue, **changes)
    assert native_supported(scenario.aiding_sensor, make)
    return results["python"], results["compiled"]


def assert_same_flight(python, compiled):
    """Histories bit for bit; NEES to 1e-9 where P is well conditioned (LAPACK builds differ); the gate's
    normalized innovations to 1e-12 (C's H, R and NIS against numpy's); every count equal."""
    for mode in MODES:
        a, b = python[mode], compiled[mode]
        assert (a.updates, a.skipped, a.rejected, a.refused) == (b.updates, b.skipped, b.rejected, b.refused)
        for name in EXACT:
            assert np.array_equal(getattr(a, name), getattr(b, name)), (mode, name)
        assert np.array_equal(np.isnan(a.nees), np.isnan(b.nees))
        conditioned = np.isfinite(a.nees) & (a.nees < 1e4)
        assert np.allclose(a.nees[conditioned], b.nees[conditioned], rtol=1e-9, atol=0)
        d2a, d2b = (np.array([d for _, d in r.innovations]) for r in (a, b))
        assert len(d2a) == len(d2b) and np.allclose(d2a, d2b, rtol=1e-12, atol=0)


def test_compiled_loop_flies_the_paper_doppler_flight_as_the_python_loop(paper_derived, tmp_path):
    scenario = load_profile("profile_000").with_changes(hours=1 / 12, imu_rate=30.0)
    python, compiled = fly_both(scenario, paper_derived, tmp_path)
    assert compiled["closed_loop"].updates == 5
    assert_same_flight(python, compiled)


def test_compiled_loop_flies_gps_in_enu_with_decimated_records_as_the_python_loop(tmp_path):
    scenario = load_profile("profile_001").with_changes(hours=1 / 120)  # 30 s: 600 GPS updates at 20 Hz
    derived = derive(load_model(scenario.filter.model))
    python, compiled = fly_both(scenario, derived, tmp_path, record_every=7, piece_seconds=2.0)
    assert compiled["closed_loop"].updates == 600 and len(compiled["closed_loop"].times) == 600 // 7 + 2
    assert_same_flight(python, compiled)


def test_compiled_loop_counts_an_outage_and_a_gated_outlier_like_the_python_loop(paper_derived, tmp_path):
    import dataclasses

    from modelgen.simulation.profile_keys import Outage

    scenario = load_profile("profile_000").with_changes(hours=1 / 12, imu_rate=30.0)
    doppler = dataclasses.replace(scenario.sensors["doppler"], outages=(Outage(100.0, 130.0),), white_noise=0.1)
    scenario = scenario.with_sensor("doppler", doppler)
    make = filter_factory(paper_derived, "c", tmp_path)
    results = {}
    for glue in ("python", "compiled"):
        trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=True)
        sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(5))
        velocity = sensors.aiding.velocity.copy()
        velocity[4, 0] += 500.0  # an outlier at t = 240 s
        sensors.aiding = dataclasses.replace(sensors.aiding, velocity=velocity)
        layout = profile_layout(scenario, paper_derived, trajectory)
        results[glue] = fly_modes(scenario, paper_derived, trajectory, sensors, layout, make, MODES, glue=glue)
    for mode in MODES:
        a, b = results["python"][mode], results["compiled"][mode]
        assert b.skipped == a.skipped == 1 and b.rejected == a.rejected == [240.0]
    assert_same_flight(results["python"], results["compiled"])


def test_unknown_glue_is_refused_by_name(paper_derived, tmp_path):
    scenario = load_profile("profile_000").with_changes(hours=1 / 360, imu_rate=30.0)
    trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=True)
    sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(5))
    layout = profile_layout(scenario, paper_derived, trajectory)
    with pytest.raises(ModelError, match="unknown glue 'fortran'"):
        fly_modes(scenario, paper_derived, trajectory, sensors, layout, filter_factory(paper_derived, "c", tmp_path),
                  MODES, glue="fortran")


def test_uncorrected_modes_sharing_one_mechanization_fly_as_each_flown_alone(paper_derived, tmp_path, monkeypatch):
    import modelgen.simulation.streaming as streaming
    from modelgen.simulation import native_loop

    scenario = load_profile("profile_000").with_changes(hours=1 / 12, imu_rate=30.0)
    make = filter_factory(paper_derived, "c", tmp_path)
    roles = []

    def watched(loops):
        native_loop.share_mechanization(loops)
        roles.extend((loop.mode, loop.trace_role) for loop in loops)

    def fly(modes):
        trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0, streamed=True)
        sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(5))
        layout = profile_layout(scenario, paper_derived, trajectory)
        return fly_modes(scenario, paper_derived, trajectory, sensors, layout, make, modes, piece_seconds=7.0)

    monkeypatch.setattr(streaming, "share_mechanization", watched)
    together = fly(("accumulated", "closed_loop", "open_loop"))
    assert roles == [("accumulated", native_loop.TRACE_WRITE), ("closed_loop", native_loop.TRACE_NONE),
                     ("open_loop", native_loop.TRACE_READ)]
    for mode in ("accumulated", "open_loop"):
        alone = fly((mode,))[mode]
        assert alone.updates == together[mode].updates == 5
        for name in EXACT + ("nees",):
            assert np.array_equal(getattr(alone, name), getattr(together[mode], name), equal_nan=True), (mode, name)


def test_compiled_loop_flies_the_same_flight_when_its_pieces_integrate_the_truth_positions(paper_derived, tmp_path):
    scenario = load_profile("profile_000").with_changes(hours=1 / 12, imu_rate=30.0)
    make = filter_factory(paper_derived, "c", tmp_path)
    results = []
    for positions_in_pieces in (False, True):
        trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0 / scenario.filter.period, streamed=True,
                                         positions_in_pieces=positions_in_pieces)
        sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(5))
        layout = profile_layout(scenario, paper_derived, trajectory)
        results.append(fly_modes(scenario, paper_derived, trajectory, sensors, layout, make, MODES, piece_seconds=20.0))
    for mode in MODES:
        for name in EXACT + ("nees",):
            assert np.array_equal(getattr(results[0][mode], name), getattr(results[1][mode], name), equal_nan=True)
