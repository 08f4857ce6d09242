"""Integration: the accumulated-correction paper's equivalence theorem, outages, the innovation gate, non-finite refusal,
and the generated filters on simulated data."""

import dataclasses
import shutil

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.simulation.doppler import DOPPLER
from modelgen.simulation.filter_loop import Measurement, run_filter
from modelgen.simulation.filters import ReferenceFilter, filter_factory
from modelgen.simulation.flight import fly_profile, profile_layout, simulate_sensors
from modelgen.simulation.ins_aiding import initial_covariance
from modelgen.simulation.profile_keys import Outage
from modelgen.simulation.scenario import load_profile
from modelgen.simulation.trajectory import generate_trajectory

pytestmark = pytest.mark.flight


class LinearErrorNavigator:
    """A linear error system e(k) = Phi e(k-1) + w(k), z = H (output) + v: the accumulated-correction paper's linear case.

    The "navigation output" is truth + e with truth = 0, so outputs are errors.
    """

    def __init__(self, phi, H, x0, noise, measurement_noise, parameters):
        self.phi, self.H, self.e = phi, H, x0.copy()
        self.noise, self.measurement_noise, self.params = noise, measurement_noise, parameters

    def advance(self, cycle):
        self.e = self.phi @ self.e + self.noise[cycle]

    def output(self):
        return self.e.copy()

    def correct_output(self, output, dx):
        return output - dx

    def feedback(self, dx):
        self.e = self.e - dx

    def parameters(self, corrected_output):
        return self.params

    def measurement(self, cycle, corrected_output, accumulated):
        return Measurement(self.H @ corrected_output + self.measurement_noise[cycle], np.arange(self.H.shape[0]))

    def estimation_error(self, cycle, corrected_output, estimate):
        return corrected_output


@pytest.fixture(scope="module")
def linear_case(paper_derived, level_flight):
    T, n_cycles = 60.0, 120
    reference = ReferenceFilter(paper_derived, np.zeros(18), np.eye(18))
    phi, qd = reference.transition(level_flight, T)
    m = paper_derived.numeric(level_flight)
    rng = np.random.default_rng(7)
    P0 = np.diag(np.r_[np.radians([120 / 3600, 120 / 3600, 20 / 60]) ** 2, [0.01, 0.01, 1e-12, 1e-12],
                      np.full(3, 4.8e-7**2), np.full(3, 4.8e-7**2), np.full(3, 1e-3**2), [0.42**2, 0.42**2]])
    vals, vecs = np.linalg.eigh(qd)
    root = vecs * np.sqrt(np.clip(vals, 0, None))
    noise = rng.standard_normal((n_cycles + 1, 18)) @ root.T
    measurement_noise = rng.standard_normal((n_cycles + 1, 2)) * np.sqrt(np.diag(m["R"]))
    x0 = np.sqrt(np.diag(P0)) * rng.standard_normal(18)
    fed_back = np.zeros(18, bool)
    fed_back[[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 16, 17]] = True  # navigation, gyro constants, Doppler bias

    def run(mode, **kw):
        nav = LinearErrorNavigator(phi, m["H"], x0, noise, measurement_noise, level_flight)
        kalman = ReferenceFilter(paper_derived, np.zeros(18), P0)
        return run_filter(nav, kalman, lambda p: (m["H"], m["R"]), mode, n_cycles, T, fed_back, **kw)

    return run


def test_accumulated_correction_equals_closed_loop_feedback_in_the_linear_case(linear_case):
    # The accumulated-correction paper's theorem: subtracting the accumulated estimates from the free
    # subsystem's output is closed-loop feedback.  Corrected outputs agree to
    # rounding (1e-9 of their size) over 120 updates; the core paper adds that open
    # loop is the same for a linear filter.
    closed, accumulated, open_loop = (linear_case(m) for m in ("closed_loop", "accumulated", "open_loop"))
    scale = np.abs(closed.outputs).max(axis=0) + 1e-300
    assert np.max(np.abs(accumulated.outputs - closed.outputs) / scale) < 1e-9
    assert np.max(np.abs(open_loop.outputs - closed.outputs) / scale) < 1e-9
    assert closed.updates == accumulated.updates == 120


def test_accumulation_without_extrapolation_is_not_closed_loop(linear_case):
    # The accumulated corrections must be carried by Phi between updates
    # (the accumulated-correction paper eq. (10): accumulated velocity corrections extrapolated into
    # position); holding them constant breaks the equivalence.
    closed = linear_case("closed_loop")
    naive = linear_case("accumulated", propagate_accumulator=False)
    scale = np.abs(closed.outputs).max(axis=0) + 1e-300
    assert np.max(np.abs(naive.outputs - closed.outputs) / scale) > 1e-3


# -- the simulated flight -------------------------------------------------------------


@pytest.fixture(scope="module")
def short_flight(paper_derived):
    """Half an hour of the paper's flight at a 20 Hz IMU, Doppler every 60 s."""
    scenario = load_profile("profile_000").with_changes(hours=0.5, imu_rate=20.0, coning="two")
    trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0 / scenario.filter.period)
    layout = profile_layout(scenario, paper_derived, trajectory)
    sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(11))
    return scenario, trajectory, layout, sensors


def run(flight, derived, sensors=None, mode="closed_loop", make_filter=None, **scenario_changes):
    scenario, trajectory, layout, base = flight
    scenario = scenario.with_changes(**scenario_changes) if scenario_changes else scenario
    make_filter = make_filter or (lambda x, P: ReferenceFilter(derived, x, P))
    return fly_profile(scenario, derived, trajectory, np.random.default_rng(0), make_filter, mode=mode,
                       sensors=sensors or base, layout=layout)


def with_doppler(sensors, **changes):
    return dataclasses.replace(sensors, aiding=dataclasses.replace(sensors.aiding, **changes))


def test_layout_identifies_the_paper_models_sign_conventions(short_flight):
    # ned_doppler18: +C eps in the attitude equations (eps = true - measured),
    # +C nabla in the velocity equations, Z = dV - dV_d.
    conventions = short_flight[2].conventions
    assert conventions["attitude"] == 1.0
    assert conventions["gyro_constant"] == conventions["gyro_markov"] == -1.0
    assert conventions["accelerometer_markov"] == 1.0
    assert conventions["doppler_bias"] == 1.0


def test_doppler_outage_skips_the_updates_it_covers(short_flight, paper_derived):
    scenario, trajectory, layout, sensors = short_flight
    outage = Outage(600.0, 1200.0)  # measurements at 600, 660, ..., 1140 s
    valid = ~((sensors.aiding.times >= 600.0) & (sensors.aiding.times < 1200.0))
    result = run(short_flight, paper_derived, with_doppler(sensors, valid=valid))
    assert result.skipped == 10
    assert result.updates == 30 - 10
    east_velocity_sigma = result.sigma[:, 4]
    assert east_velocity_sigma[1140] > 1.5 * east_velocity_sigma[540]  # no update: uncertainty grows
    assert east_velocity_sigma[1260] < east_velocity_sigma[1140]  # first update after the outage
    # the scenario file's outage list produces the same mask
    dop = dataclasses.replace(scenario.sensors["doppler"], outages=(outage,))
    again = simulate_sensors(scenario.with_sensor("doppler", dop), trajectory, np.random.default_rng(11))
    assert np.array_equal(again.aiding.valid, valid)


def test_innovation_gate_rejects_an_injected_outlier_and_counts_it(short_flight, paper_derived):
    sensors = short_flight[3]
    velocity = sensors.aiding.velocity.copy()
    velocity[15] += [0.0, 20.0, 0.0]  # 20 m/s east at t = 900 s
    outlier = with_doppler(sensors, velocity=velocity)
    gated = run(short_flight, paper_derived, outlier)
    assert gated.rejected == [900.0]
    assert gated.updates == 29
    ungated = run(short_flight, paper_derived, outlier, filter=dataclasses.replace(short_flight[0].filter, gate_probability=0.0))
    assert ungated.rejected == [] and ungated.updates == 30
    # the accepted outlier corrupts the east velocity; the rejected one does not
    assert abs(ungated.estimation_error[900, 4]) > 10 * abs(gated.estimation_error[900, 4])


def test_non_finite_measurement_is_refused_and_the_run_goes_on(short_flight, paper_derived):
    sensors = short_flight[3]
    velocity = sensors.aiding.velocity.copy()
    velocity[10, 0] = np.nan
    result = run(short_flight, paper_derived, with_doppler(sensors, velocity=velocity))
    assert result.refused == [600.0]
    assert result.updates == 29
    assert np.all(np.isfinite(result.estimation_error)) and np.all(np.isfinite(result.sigma))


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_reference_filter_refuses_non_finite_measurement_with_state_unchanged(paper_derived, level_flight, bad):
    m = paper_derived.numeric(level_flight)
    kalman = ReferenceFilter(paper_derived, np.arange(18) * 1e-6, np.eye(18))
    x, P = kalman.state, kalman.covariance
    with pytest.raises(ModelError, match="non-finite"):
        kalman.update(np.array([0.1, bad]), m["H"], m["R"])
    assert np.array_equal(kalman.state, x) and np.array_equal(kalman.covariance, P)


@pytest.fixture(scope="module")
def generated_filters(paper_derived, tmp_path_factory):
    """Makers of the generated Python and C filters, as `modelgen simulate --filter` builds them."""
    return {implementation: filter_factory(paper_derived, implementation, tmp_path_factory.mktemp(implementation))
            for implementation in ("python", "c")}


@pytest.mark.compile
def test_generated_python_filter_runs_the_flight_like_the_reference(short_flight, paper_derived, generated_filters):
    make = generated_filters["python"]
    generated = run(short_flight, paper_derived, make_filter=make)
    reference = run(short_flight, paper_derived)
    assert generated.updates == reference.updates == 30
    assert np.allclose(generated.sigma, reference.sigma, rtol=1e-8, atol=1e-300)
    assert np.allclose(generated.estimation_error, reference.estimation_error, rtol=1e-6, atol=1e-9 * np.abs(reference.estimation_error).max(axis=0))


@pytest.mark.compile
@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler")
def test_generated_c_filter_runs_the_flight_like_the_reference(short_flight, paper_derived, generated_filters):
    make = generated_filters["c"]
    generated = run(short_flight, paper_derived, make_filter=make)
    reference = run(short_flight, paper_derived)
    assert generated.updates == reference.updates == 30
    assert np.allclose(generated.sigma, reference.sigma, rtol=1e-8, atol=1e-300)
    assert np.allclose(generated.estimation_error, reference.estimation_error, rtol=1e-6, atol=1e-9 * np.abs(reference.estimation_error).max(axis=0))
    # the C itself refuses a non-finite measurement, leaving its state unchanged
    kalman = make(np.zeros(18), initial_covariance(short_flight[2], short_flight[0], short_flight[1].initial_state(), DOPPLER))
    state, covariance = kalman.state, kalman.covariance
    assert kalman.compiled.update(np.array([np.nan, 0.0])) != 0
    assert np.array_equal(kalman.state, state) and np.array_equal(kalman.covariance, covariance)


def test_unknown_filter_implementation_is_refused_by_name(paper_derived, tmp_path):
    with pytest.raises(ModelError, match="unknown filter implementation 'fortran'"):
        filter_factory(paper_derived, "fortran", tmp_path)


def test_seed_001_set_up_runs_ins_gps15_at_20_hz_with_a_300_hz_mechanization():
    # profile_001: 300 Hz strapdown (three-sample, 15 samples per cycle), 20 Hz GPS position and
    # velocity into the 15-state ENU model; its gyro bias enters as -C eps (measured - true).
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model

    scenario = load_profile("profile_001").with_changes(hours=1 / 60)
    derived = derive(load_model(scenario.filter.model))
    trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0 / scenario.filter.period)
    layout = profile_layout(scenario, derived, trajectory)
    assert layout.conventions == {"attitude": 1.0, "gyro_constant": 1.0, "accelerometer_constant": 1.0}
    result = fly_profile(scenario, derived, trajectory, np.random.default_rng(3),
                         lambda x, P: ReferenceFilter(derived, x, P), layout=layout)
    assert result.updates + len(result.rejected) == 60 * 20
    assert np.all(np.isfinite(result.nees[1:]))
    # position error of the corrected output is at the GPS noise level, not the free INS's
    assert np.all(np.abs(result.estimation_error[-1, 6:8]) < 3 * result.sigma[-1, 6:8] + 1e-12)
