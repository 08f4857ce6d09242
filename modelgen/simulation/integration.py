"""Running a Kalman filter on simulated data, with the three correction modes.

Correction modes (seed 003 §1; seed 000 §2; seed 001 §3.2):

* ``open_loop`` -- output compensation: the INS runs free, the filter estimates
  its whole error x^ and the output is INS (-) x^.
* ``closed_loop`` -- feedback: after each update the estimated navigation
  errors and random-constant sensor errors are fed back into the mechanization
  (attitude, velocity, position, gyro/accelerometer compensation, Doppler
  compensation) and those filter states are reset to zero.  Markov states are
  not fed back (a fed-back Markov estimate would have to decay inside the
  mechanization); they stay in the filter.
* ``accumulated`` -- seed 003's accumulated-error correction: the INS and the
  sensors run free as in open loop, but the fed-back part of every estimate is
  added to an accumulator A and reset in the filter as in closed loop; A is
  carried between updates by the same transition matrix as the errors
  (A(k) = Phi A(k-1), which is seed 003's extrapolation of accumulated velocity
  corrections into position, eq. (10)), the sensor outputs are corrected by A
  before they enter the filter (eq. (3)) and the output is INS (-) A.  The
  theorem of seed 003: in the linear case this output equals the closed-loop
  output; ``tests/simulation`` checks it to numerical precision.

Faults: a measurement marked invalid (outage) skips the update; an innovation
whose normalized square nu^T S^-1 nu exceeds the chi-square quantile of the
gate probability is rejected and counted; a non-finite measurement is refused
(counted, the filter state untouched; the filters themselves raise ModelError).

The loop is written against two small protocols: a navigator (the system
whose errors are estimated: :class:`StrapdownNavigator` for the simulated
flight, a linear error system in the tests) and a filter
(:mod:`modelgen.simulation.filters`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np
from scipy.stats import chi2

from modelgen.derive.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.doppler import DopplerRecord, simulate_doppler
from modelgen.simulation.error_layout import ErrorLayout, build_layout, frame_matrix
from modelgen.simulation.filters import KalmanFilter, ModelMatrices, named_parameters
from modelgen.simulation.gps import GpsRecord, PseudorangeRecord, simulate_position_velocity, simulate_pseudoranges
from modelgen.simulation.imu import ImuErrorHistory, corrupt_increments
from modelgen.simulation.rotation import quaternion_product, quaternion_to_dcm, rotation_vectors_to_quaternions
from modelgen.simulation.scenario import Scenario
from modelgen.simulation.strapdown import ALGORITHMS, Strapdown
from modelgen.simulation.trajectory import Trajectory

MODES = ("open_loop", "closed_loop", "accumulated")


# -- protocols -------------------------------------------------------------------------


@dataclass(frozen=True)
class Measurement:
    """z (model measurement rows ``rows``) or, when ``valid`` is False, an outage."""

    z: np.ndarray
    rows: np.ndarray
    valid: bool = True


class Navigator(Protocol):
    """The system whose errors the filter estimates."""

    def advance(self, cycle: int) -> None: ...

    def output(self) -> np.ndarray: ...

    def correct_output(self, output: np.ndarray, dx: np.ndarray) -> np.ndarray: ...

    def feedback(self, dx: np.ndarray) -> None: ...

    def parameters(self, corrected_output: np.ndarray) -> dict[str, float]: ...

    def measurement(self, cycle: int, corrected_output: np.ndarray, accumulated: np.ndarray) -> Measurement | None: ...

    def estimation_error(self, cycle: int, corrected_output: np.ndarray, estimate: np.ndarray) -> np.ndarray: ...


@dataclass
class RunResult:
    """Per-cycle records of one filtered run (row 0 = t = 0, before any step)."""

    mode: str
    filter_name: str
    times: np.ndarray
    outputs: np.ndarray  # corrected navigation output
    raw_outputs: np.ndarray  # the navigator's own output (INS, before output correction)
    estimation_error: np.ndarray  # true error state minus estimate, model states
    sigma: np.ndarray  # sqrt(diag(P))
    nees: np.ndarray  # e^T P^-1 e (NaN where P is singular)
    updates: int = 0
    skipped: int = 0  # outage
    rejected: list[float] = field(default_factory=list)  # gate, times
    refused: list[float] = field(default_factory=list)  # non-finite, times
    innovations: list[tuple[float, float]] = field(default_factory=list)  # (time, normalized squared innovation)


@functools.lru_cache(maxsize=64)
def gate_threshold(probability: float, dimension: int) -> float:
    """chi-square quantile for the gate; infinity when gating is off (cached: asked every update)."""
    if probability <= 0:
        return math.inf
    return float(chi2.ppf(probability, dimension))


def nees(error: np.ndarray, covariance: np.ndarray) -> float:
    """e^T P^-1 e, or NaN if P is singular (e.g. zero initial variances at t = 0)."""
    try:
        L = np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        return math.nan
    y = np.linalg.solve(L, error)
    return float(y @ y)


def run_filter(navigator: Navigator, kalman: KalmanFilter, measurement_matrices: Callable[[dict], tuple[np.ndarray, np.ndarray]],
               mode: str, n_cycles: int, period: float, fed_back: np.ndarray, gate_probability: float = 0.0,
               filter_name: str = "", progress: Callable[[int, int], None] | None = None,
               propagate_accumulator: bool = True) -> RunResult:
    """The correction-mode loop (module docstring) over ``n_cycles`` filter cycles.

    ``propagate_accumulator=False`` holds the accumulator constant between
    updates instead of carrying it by Phi -- the naive accumulation that seed
    003 warns against (section 2, after the proof); only for demonstrating
    that the extrapolation is needed.
    """
    if mode not in MODES:
        raise ModelError(f"integration: unknown correction mode {mode!r} (choose from {', '.join(MODES)})")
    x0 = kalman.state
    n = len(x0)
    accumulated = np.zeros(n)

    def total_estimate() -> np.ndarray:
        return accumulated + kalman.state

    def record(k: int) -> None:
        raw = navigator.output()
        estimate = total_estimate()
        corrected = navigator.correct_output(raw, estimate)
        error = navigator.estimation_error(k, corrected, estimate)
        P = kalman.covariance
        result.times[k] = k * period
        result.outputs[k] = corrected
        result.raw_outputs[k] = raw
        result.estimation_error[k] = error
        result.sigma[k] = np.sqrt(np.maximum(np.diag(P), 0.0))
        result.nees[k] = nees(error, P)

    first = navigator.output()
    result = RunResult(mode, filter_name, np.zeros(n_cycles + 1), np.zeros((n_cycles + 1, len(first))),
                       np.zeros((n_cycles + 1, len(first))), np.zeros((n_cycles + 1, n)), np.zeros((n_cycles + 1, n)),
                       np.full(n_cycles + 1, math.nan))
    record(0)
    for k in range(1, n_cycles + 1):
        navigator.advance(k)
        raw = navigator.output()
        parameters = navigator.parameters(navigator.correct_output(raw, total_estimate()))
        phi, qd = kalman.transition(parameters, period)
        kalman.predict(phi, qd)
        if mode == "accumulated" and propagate_accumulator:
            accumulated = phi @ accumulated
        corrected_for_filter = navigator.correct_output(raw, accumulated) if mode == "accumulated" else raw
        measurement = navigator.measurement(k, corrected_for_filter, accumulated)
        if measurement is not None:
            t = k * period
            if not measurement.valid:
                result.skipped += 1
            elif not np.all(np.isfinite(measurement.z)):
                result.refused.append(t)
            else:
                H_all, R_all = measurement_matrices(parameters)
                rows = measurement.rows
                H, R = H_all[rows], R_all[np.ix_(rows, rows)]
                x, P = kalman.state, kalman.covariance
                innovation = measurement.z - H @ x
                S = H @ P @ H.T + R
                d2 = float(innovation @ np.linalg.solve(S, innovation))
                result.innovations.append((t, d2))
                if d2 > gate_threshold(gate_probability, len(rows)):
                    result.rejected.append(t)
                else:
                    try:
                        kalman.update(measurement.z, H, R)
                    except ModelError:
                        result.refused.append(t)
                    else:
                        result.updates += 1
                        if mode != "open_loop":
                            dx = np.where(fed_back, kalman.state, 0.0)
                            if mode == "closed_loop":
                                navigator.feedback(dx)
                            else:
                                accumulated = accumulated + dx
                            kalman.set_state(kalman.state - dx)
        record(k)
        if progress is not None:
            progress(k, n_cycles)
    return result


# -- the simulated flight ------------------------------------------------------------------


@dataclass
class SensorData:
    """Everything one simulated run measures, plus the truth of its errors."""

    trajectory: Trajectory
    delta_theta: np.ndarray
    delta_velocity: np.ndarray
    imu_errors: ImuErrorHistory
    initial_navigation: np.ndarray
    altitude_reference: np.ndarray  # at record times
    doppler: DopplerRecord | None
    gps: GpsRecord | None
    pseudoranges: PseudorangeRecord | None = None  # every record time (aiding: pseudorange)


def perturbed_initial_state(truth0: np.ndarray, attitude: np.ndarray, velocity: np.ndarray,
                            position_m: np.ndarray) -> np.ndarray:
    """INS initial state: truth with attitude error psi (NED), velocity and horizontal position errors."""
    nav = truth0.copy()
    nav[6:10] = quaternion_product(rotation_vectors_to_quaternions(-np.asarray(attitude)), truth0[6:10])
    nav[3:6] += velocity
    meridian, prime_vertical = earth.radii_of_curvature(truth0[0])
    nav[0] += position_m[0] / (meridian + truth0[2])
    nav[1] += position_m[1] / ((prime_vertical + truth0[2]) * math.cos(truth0[0]))
    return nav


def simulate_sensors(scenario: Scenario, trajectory: Trajectory, rng: np.random.Generator) -> SensorData:
    """One realization of every sensor error of the scenario."""
    dtheta, dvel, history = corrupt_increments(trajectory.delta_theta, trajectory.delta_velocity, trajectory.dt,
                                               scenario.imu_budget, rng, trajectory.record_every)
    ie = scenario.initial_errors
    initial = perturbed_initial_state(
        trajectory.initial_state(),
        np.asarray(ie.attitude) * rng.standard_normal(3),
        np.r_[ie.velocity * rng.standard_normal(2), 0.0],
        ie.position * rng.standard_normal(2),
    )
    truth = trajectory.truth
    altitude = truth[:, 3] + scenario.altitude_noise * rng.standard_normal(len(truth))
    record_period = trajectory.record_period
    doppler = gps = pseudoranges = None
    if scenario.filter.aiding == "pseudorange":
        # a pseudo-range INS is initialized from a 3-D fix: height and vertical velocity errors too
        initial[2] += ie.position * rng.standard_normal()
        initial[5] += ie.velocity * rng.standard_normal()
        pseudoranges = simulate_pseudoranges(truth[:, 0], truth[:, 1:4], scenario.pseudorange, rng, scenario.constellation)
    elif scenario.filter.aiding == "doppler":
        step = whole_ratio(scenario.doppler.period, record_period, "doppler period")
        rows = np.arange(0, len(truth), step)
        doppler = simulate_doppler(truth[rows, 0], truth[rows, 4:7], truth[rows, 7:11], scenario.doppler, rng)
    else:
        step = whole_ratio(scenario.gps.period, record_period, "gps period")
        rows = np.arange(0, len(truth), step)
        gps = simulate_position_velocity(truth[rows, 0], truth[rows, 1:4], truth[rows, 4:7], scenario.gps, rng)
    return SensorData(trajectory, dtheta, dvel, history, initial, altitude, doppler, gps, pseudoranges)


def whole_ratio(a: float, b: float, what: str) -> int:
    """a / b for a sensor period a that must be a whole multiple of the filter period b."""
    ratio = a / b
    if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6 * ratio:
        raise ModelError(f"scenario: {what} {a} s is not a whole multiple of the filter period {b} s")
    return int(round(ratio))


def samples_per_cycle(trajectory: Trajectory, coning: str) -> int:
    """IMU samples per filter cycle, refused unless a whole number of coning updates."""
    samples = trajectory.record_every
    if samples % ALGORITHMS[coning][1]:
        raise ModelError(f"scenario: {samples} IMU samples per filter cycle is not a multiple of "
                         f"the {coning}-sample update")
    return samples


def operating_point(nav: np.ndarray, specific_force: np.ndarray, frame: str, scenario: Scenario) -> dict[str, float]:
    """Every parameter a model of the library may ask for, by its spelled-out name.

    Operating point (from the corrected navigation output) plus error
    statistics (from the scenario).  c11..c33 is C_b^n in the model's frame.
    """
    lat, lon, h = float(nav[0]), float(nav[1]), float(nav[2])
    v = nav[3:6]
    C = quaternion_to_dcm(nav[6:10])
    if frame.upper() not in ("", "NED"):
        C = frame_matrix(frame) @ C
    meridian, prime_vertical = earth.radii_of_curvature(lat)
    b = scenario.imu_budget
    gyro_rate = 1.0 / b.gyro_markov_correlation_time
    accel_rate = 1.0 / b.accel_markov_correlation_time
    out = {
        "latitude": lat, "longitude": lon, "height": h,
        "velocity_north": v[0], "velocity_east": v[1], "velocity_down": v[2], "velocity_up": -v[2],
        "specific_force_north": specific_force[0], "specific_force_east": specific_force[1],
        "specific_force_down": specific_force[2], "specific_force_up": -specific_force[2],
        "earth_rate": earth.EARTH_RATE,
        "earth_radius": math.sqrt((meridian + h) * (prime_vertical + h)),
        "meridian_radius": meridian, "prime_vertical_radius": prime_vertical,
        "gravity": earth.normal_gravity(lat, h),
        "gyro_angle_random_walk": b.gyro_white_noise, "accel_velocity_random_walk": b.accel_white_noise,
        "doppler_noise_sigma_north": scenario.doppler.white_noise, "doppler_noise_sigma_east": scenario.doppler.white_noise,
        "gps_velocity_sigma_east": scenario.gps.velocity_noise, "gps_velocity_sigma_north": scenario.gps.velocity_noise,
        "gps_velocity_sigma_up": scenario.gps.velocity_noise,
        "gps_position_sigma_north": scenario.gps.position_noise, "gps_position_sigma_east": scenario.gps.position_noise,
        "gps_position_sigma_up": scenario.gps.height_noise,
    }
    for i in range(3):
        for j in range(3):
            out[f"c{i + 1}{j + 1}"] = float(C[i, j])
    for axis in "xyz":
        out[f"gyro_markov_rate_{axis}"] = gyro_rate
        out[f"gyro_markov_sigma_{axis}"] = b.gyro_markov_drift
        out[f"accel_markov_rate_{axis}"] = accel_rate
        out[f"accel_markov_sigma_{axis}"] = b.accel_markov_bias
    return out


#: sensor quantity -> (kind, NED axis or position index, sign)
_QUANTITY = {
    "velocity_north": ("velocity", 0, 1.0), "velocity_east": ("velocity", 1, 1.0),
    "velocity_down": ("velocity", 2, 1.0), "velocity_up": ("velocity", 2, -1.0),
    "latitude": ("angle", 0, 1.0), "longitude": ("angle", 1, 1.0), "height": ("height", 2, 1.0),
    "position_north": ("metres", 0, 1.0), "position_east": ("metres", 1, 1.0),
}


class StrapdownNavigator:
    """The simulated INS (strapdown on corrupted increments) with its aiding sensor."""

    def __init__(self, scenario: Scenario, layout: ErrorLayout, sensors: SensorData, mapping: dict[str, str]):
        self.scenario, self.layout, self.sensors = scenario, layout, sensors
        trajectory = sensors.trajectory
        self.samples_per_cycle = samples_per_cycle(trajectory, scenario.coning)
        self.strapdown = Strapdown(sensors.initial_navigation, trajectory.imu_rate, scenario.coning,
                                   scenario.vertical_damping)
        self.sensor_compensation = np.zeros(3)  # Doppler bias fed back (closed loop), NED
        self.frame = layout.derived.model.frame or "NED"
        model = layout.derived.model
        self.rows = np.array([model.measurement_names.index(name) for name in mapping])
        self.quantities = [_QUANTITY[q] for q in mapping.values()]
        record = sensors.doppler if sensors.doppler is not None else sensors.gps
        self.record = record
        self.every = int(round((record.times[1] - record.times[0]) / trajectory.record_period)) if len(record.times) > 1 else 1

    # navigator protocol
    def advance(self, cycle: int) -> None:
        start = (cycle - 1) * self.samples_per_cycle
        heights = self.sensors.altitude_reference
        self.strapdown.run(self.sensors.delta_theta, self.sensors.delta_velocity, start, start + self.samples_per_cycle,
                           (heights[cycle - 1], heights[cycle]))

    def output(self) -> np.ndarray:
        return self.strapdown.navigation_state()

    def correct_output(self, output: np.ndarray, dx: np.ndarray) -> np.ndarray:
        return self.layout.corrected(output, dx)

    def feedback(self, dx: np.ndarray) -> None:
        self.strapdown.correct(self.layout.corrected(self.output(), dx))
        self.strapdown.gyro_bias += self.layout.sensor_vector("gyro_constant", dx)
        self.strapdown.accel_bias += self.layout.sensor_vector("accelerometer_constant", dx)
        self.sensor_compensation += self.layout.sensor_vector("doppler_bias", dx)

    def parameters(self, corrected_output: np.ndarray) -> dict[str, float]:
        values = operating_point(corrected_output, self.strapdown.specific_force, self.frame, self.scenario)
        return named_parameters(self.layout.derived, values, validate=False)

    def measurement(self, cycle: int, corrected_output: np.ndarray, accumulated: np.ndarray) -> Measurement | None:
        if cycle % self.every:
            return None
        j = cycle // self.every
        if j >= len(self.record.times):
            return None
        if not self.record.valid[j]:
            return Measurement(np.zeros(len(self.rows)), self.rows, valid=False)
        nav = corrected_output
        if self.sensors.doppler is not None:
            velocity = self.record.velocity[j]
            if self.record.frame == "body":  # resolve with the INS attitude (attitude-induced error)
                velocity = quaternion_to_dcm(nav[6:10]) @ velocity
            velocity = velocity - self.sensor_compensation - self.layout.sensor_vector("doppler_bias", accumulated)
            position = None
        else:
            velocity, position = self.record.velocity[j], self.record.position[j]
        z = np.empty(len(self.rows))
        meridian, prime_vertical = earth.radii_of_curvature(nav[0])
        for i, (kind, axis, sign) in enumerate(self.quantities):
            if kind == "velocity":
                z[i] = sign * (nav[3 + axis] - velocity[axis])
            elif position is None:
                raise ModelError(f"scenario: the Doppler cannot measure {kind} (filter.measurements.doppler)")
            elif kind in ("angle", "height"):
                z[i] = nav[axis] - position[axis]
            else:
                scale = meridian + nav[2] if axis == 0 else (prime_vertical + nav[2]) * math.cos(nav[0])
                z[i] = (nav[axis] - position[axis]) * scale
        return Measurement(z, self.rows)

    def estimation_error(self, cycle: int, corrected_output: np.ndarray, estimate: np.ndarray) -> np.ndarray:
        layout, errors = self.layout, self.sensors.imu_errors
        truth = self.sensors.trajectory.truth[cycle, 1:]
        true_state = layout.navigation_error(corrected_output, truth)
        true_state += layout.sensor_states("gyro_constant", errors.gyro_constant - self.strapdown.gyro_bias)
        true_state += layout.sensor_states("gyro_markov", errors.gyro_markov[cycle])
        true_state += layout.sensor_states("accelerometer_constant", errors.accel_constant - self.strapdown.accel_bias)
        true_state += layout.sensor_states("accelerometer_markov", errors.accel_markov[cycle])
        if self.sensors.doppler is not None:
            true_state += layout.sensor_states("doppler_bias", self.sensors.doppler.bias[0] - self.sensor_compensation)
        sensor_part = np.ones(layout.n, bool)
        for group in ("attitude", "velocity", "position"):
            sensor_part[layout.indices(group)] = False
        # navigation states: the corrected output already has the estimate removed
        return np.where(sensor_part, true_state - estimate, true_state)


def initial_covariance(layout: ErrorLayout, scenario: Scenario, truth0: np.ndarray) -> np.ndarray:
    """P0 from the scenario's initial errors and error budget, in the model's states."""
    P = np.zeros((layout.n, layout.n))
    ie, b = scenario.initial_errors, scenario.imu_budget
    meridian, prime_vertical = earth.radii_of_curvature(truth0[0])
    for e in layout.groups.get("attitude", []):
        P[e.index, e.index] = ie.attitude[e.axis] ** 2
    for e in layout.groups.get("velocity", []):
        P[e.index, e.index] = ie.velocity**2 if e.axis < 2 else 0.0
    for e in layout.groups.get("position", []):
        scale = {0: meridian + truth0[2], 1: (prime_vertical + truth0[2]) * math.cos(truth0[0])}.get(e.axis, 1.0)
        P[e.index, e.index] = (ie.position / scale) ** 2 if e.axis != 2 and e.axis != 5 else 0.0
    sigmas = {"gyro_constant": b.gyro_constant_drift, "gyro_markov": b.gyro_markov_drift,
              "accelerometer_constant": b.accel_constant_bias, "accelerometer_markov": b.accel_markov_bias,
              "doppler_bias": scenario.doppler.bias}
    for group, sigma in sigmas.items():
        for e in layout.groups.get(group, []):
            P[e.index, e.index] = sigma**2
    return P


def scenario_layout(scenario: Scenario, derived: DerivedModel, trajectory: Trajectory) -> ErrorLayout:
    """The error layout, its sign conventions identified at the flight's start."""
    if scenario.filter.aiding == "pseudorange":  # mapped explicitly by modelgen.simulation.pseudorange
        return ErrorLayout(derived, {})
    truth0 = trajectory.initial_state()
    frame = derived.model.frame or "NED"
    values = operating_point(truth0, np.array([0.0, 0.0, -earth.normal_gravity(truth0[0], truth0[2])]), frame, scenario)
    m = derived.numeric(named_parameters(derived, values))
    aiding = scenario.filter.aiding
    mapping = scenario.filter.measurements.get(aiding, {})
    rows = {}
    for name, quantity in mapping.items():
        kind, axis, sign = _QUANTITY[quantity]
        if kind == "velocity":
            rows[derived.model.measurement_names.index(name)] = (axis, sign)
    radius = values["earth_radius"]
    return build_layout(derived, scenario.filter.states, m["F"], m["H"], quaternion_to_dcm(truth0[6:10]), rows, radius)


def measurement_function(derived: DerivedModel) -> Callable[[dict], tuple[np.ndarray, np.ndarray]]:
    """H and R of the model at an operating point."""

    evaluate = ModelMatrices(derived)

    def matrices(parameters: dict) -> tuple[np.ndarray, np.ndarray]:
        m = evaluate(parameters)
        return m["H"], m["R"]

    return matrices


def run_scenario(scenario: Scenario, derived: DerivedModel, trajectory: Trajectory, rng: np.random.Generator,
                 make_filter: Callable[[np.ndarray, np.ndarray], KalmanFilter], mode: str | None = None,
                 sensors: SensorData | None = None, layout: ErrorLayout | None = None,
                 progress: Callable[[int, int], None] | None = None,
                 truth_scenario: Scenario | None = None) -> RunResult:
    """Simulate the sensors (unless given) and run the filter in ``mode`` over the whole trajectory.

    The filter is tuned from ``scenario``; the sensors are drawn from
    ``truth_scenario`` if given (a mis-modelled filter), else from ``scenario``.
    """
    mode = mode or scenario.filter.mode
    layout = layout or scenario_layout(scenario, derived, trajectory)
    sensors = sensors or simulate_sensors(truth_scenario or scenario, trajectory, rng)
    if scenario.filter.aiding == "pseudorange":
        from modelgen.simulation.pseudorange import run_pseudorange_scenario  # it builds on this module

        return run_pseudorange_scenario(scenario, derived, trajectory, sensors, make_filter, mode, progress)
    mapping = scenario.filter.measurements.get(scenario.filter.aiding)
    if not mapping:
        raise ModelError(f"scenario {scenario.name!r}: filter.measurements.{scenario.filter.aiding} is missing")
    navigator = StrapdownNavigator(scenario, layout, sensors, mapping)
    P0 = initial_covariance(layout, scenario, trajectory.initial_state())
    kalman = make_filter(np.zeros(layout.n), P0)
    n_cycles = len(trajectory.truth) - 1
    return run_filter(navigator, kalman, measurement_function(derived), mode, n_cycles, trajectory.record_period,
                      layout.fed_back_mask(), scenario.filter.gate_probability,
                      getattr(kalman, "name", type(kalman).__name__), progress)
