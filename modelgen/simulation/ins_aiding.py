"""Aiding by a sensor that measures navigation quantities (velocity, position).

:class:`NavigationQuantitySensor` is the common part of such sensor plug-ins
(the Doppler radar and the GPS position/velocity receiver, or a sensor a user
registers): it implements :class:`~modelgen.simulation.aiding.AidingSensor`
from four things a subclass gives -- its profile keys, its noise, a record
simulated at its epochs and :meth:`NavigationQuantitySensor.fix`, the
sensor's output at one epoch in navigation quantities.  The profile's
``filter.measurements.<sensor>`` mapping says which model measurement is
which quantity; z = INS value - sensor value.

:class:`StrapdownNavigator` is the simulated INS (strapdown on corrupted
increments) with such a sensor: the navigator of the filter loop.  A sensor
with a random-constant bias of its own (the Doppler) names the error-layout
group of its bias states (``bias_group``); the navigator then feeds the bias
estimate back into the sensor's compensation like the IMU's.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.aiding import (
    FilterMaker,
    Progress,
    SensorData,
    measurement_function,
    operating_point,
    samples_per_cycle,
    whole_ratio,
)
from modelgen.simulation.error_layout import ErrorLayout, build_layout
from modelgen.simulation.filter_loop import FilterLoop, Measurement, RunResult
from modelgen.simulation.filters import named_parameters
from modelgen.simulation.native_loop import NativeFilterLoop
from modelgen.simulation.profile_keys import ProfileSection
from modelgen.simulation.rotation import quaternion_to_dcm
from modelgen.simulation.strapdown import Strapdown
from modelgen.simulation.trajectory import Trajectory

if TYPE_CHECKING:  # sympy-based, named in annotations only: a run of the compiled loop imports no sympy
    from modelgen.derivation.symbolic import DerivedModel
    from modelgen.simulation.model_outline import ModelOutline

#: sensor quantity -> (kind, NED axis or position index, sign)
QUANTITIES = {
    "velocity_north": ("velocity", 0, 1.0), "velocity_east": ("velocity", 1, 1.0),
    "velocity_down": ("velocity", 2, 1.0), "velocity_up": ("velocity", 2, -1.0),
    "latitude": ("angle", 0, 1.0), "longitude": ("angle", 1, 1.0), "height": ("height", 2, 1.0),
    "position_north": ("metres", 0, 1.0), "position_east": ("metres", 1, 1.0),
}


class NavigationQuantitySensor(ABC):
    """Base of the plug-ins whose output is NED velocity and/or geodetic position (module docstring).

    A subclass sets ``name`` and overrides :meth:`read_settings`,
    :meth:`period`, :meth:`noise_parameters`, :meth:`simulate_at` and
    :meth:`fix`; a sensor with bias states also sets ``bias_group`` and
    overrides :meth:`true_bias` and :meth:`bias_sigma`.
    """

    name = ""
    quantities: tuple[str, ...] = tuple(QUANTITIES)
    bias_group: str | None = None  # error-layout group of the sensor's own bias states, if any
    #: whether :meth:`simulate_at` reads the truth's latitude and longitude; a sensor that does not lets
    #: ``modelgen simulate`` integrate them while the flight goes (``generate_trajectory(positions_in_pieces=True)``)
    reads_truth_position = True

    # -- what a subclass gives ---------------------------------------------------------
    @abstractmethod
    def read_settings(self, section: ProfileSection) -> Any:
        """Its settings (SI) from its profile section."""

    @abstractmethod
    def period(self, settings: Any) -> float:
        """Seconds between two of its measurements."""

    def noise_parameters(self, settings: Any) -> dict[str, float]:
        """Model parameters its measurement noise sets."""
        return {}

    @abstractmethod
    def simulate_at(self, settings: Any, truth: np.ndarray, rng: np.random.Generator) -> Any:
        """Its record at the truth rows ``truth`` (columns of ``trajectory.TRUTH_COLUMNS``).

        The record has ``times`` and ``valid`` (outages) per epoch.
        """

    @abstractmethod
    def fix(self, record: Any, epoch: int, navigation: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Measurement function: its output at ``epoch`` as (NED velocity, (lat, lon, h)), None for what it lacks.

        ``navigation`` is the INS output the filter sees (lat, lon, h, v_NED,
        q_b^n): a sensor that measures in body axes resolves with its attitude.
        """

    # A subclass whose fix() is a table lookup may also give
    #     fix_table(record) -> (velocity (epochs, 3), position (epochs, 3), velocity in body axes: bool)
    # (NaN where it measures nothing); the compiled filter loop then flies it
    # (modelgen.simulation.native_loop), else the Python loop does.

    def true_bias(self, record: Any) -> np.ndarray:
        """The true bias (NED, 3) of the sensor's bias states."""
        return np.zeros(3)

    def bias_sigma(self, settings: Any) -> float:
        """rms of the bias states at the start."""
        return 0.0

    # -- the AidingSensor interface ----------------------------------------------------------
    def simulate(self, profile: Any, trajectory: Trajectory, initial_navigation: np.ndarray,
                 rng: np.random.Generator) -> Any:
        """Its record at every ``period`` (a whole number of filter cycles)."""
        settings = profile.sensors[self.name]
        step = whole_ratio(self.period(settings), trajectory.record_period, f"{self.name} period")
        rows = np.arange(0, len(trajectory.truth), step)
        return self.simulate_at(settings, trajectory.truth[rows], rng)

    def layout(self, profile: Any, derived: DerivedModel, trajectory: Trajectory) -> ErrorLayout:
        """The error layout, its sign conventions identified at the flight's start."""
        truth0 = trajectory.initial_state()
        frame = derived.model.frame or "NED"
        gravity = np.array([0.0, 0.0, -earth.normal_gravity(truth0[0], truth0[2])])
        values = operating_point(truth0, gravity, frame, profile.imu_budget, profile.constant_parameters())
        m = derived.numeric(named_parameters(derived, values))
        rows = {}
        for name, quantity in profile.filter.measurements.get(self.name, {}).items():
            kind, axis, sign = QUANTITIES[quantity]
            if kind == "velocity":
                rows[derived.model.measurement_names.index(name)] = (axis, sign)
        radius = values["earth_radius"]
        return build_layout(derived, profile.filter.states, m["F"], m["H"], quaternion_to_dcm(truth0[6:10]), rows, radius)

    def filter_loop(self, profile: Any, derived: DerivedModel, trajectory: Trajectory, sensors: SensorData,
                    layout: ErrorLayout, make_filter: FilterMaker, mode: str, progress: Progress | None,
                    record_every: int = 1, sink: Any = None) -> FilterLoop:
        """The filter loop with a :class:`StrapdownNavigator` aided by this sensor, ready to step."""
        mapping = profile.filter.measurements.get(self.name)
        if not mapping:
            raise ModelError(f"scenario {profile.name!r}: filter.measurements.{self.name} is missing")
        navigator = StrapdownNavigator(profile, layout, sensors, mapping, self)
        P0 = initial_covariance(layout, profile, trajectory.initial_state(), self)
        kalman = make_filter(np.zeros(layout.n), P0)
        return FilterLoop(navigator, kalman, measurement_function(derived), mode, len(trajectory.truth) - 1,
                          trajectory.record_period, layout.fed_back_mask(), profile.filter.gate_probability,
                          getattr(kalman, "name", type(kalman).__name__), progress, record_every=record_every, sink=sink)

    def native_loop(self, profile: Any, derived: DerivedModel | ModelOutline, trajectory: Trajectory,
                    sensors: SensorData,
                    layout: ErrorLayout, make_filter: Any, mode: str, progress: Progress | None,
                    record_every: int = 1) -> Any:
        """The same loop in compiled code with the generated C filter (:mod:`modelgen.simulation.native_loop`).

        Needs :meth:`fix_table` (a subclass that gives it) and a filter maker
        with ``native`` (``filter_factory(..., "c", ...)``).
        """
        mapping = profile.filter.measurements.get(self.name)
        if not mapping:
            raise ModelError(f"scenario {profile.name!r}: filter.measurements.{self.name} is missing")
        navigator = StrapdownNavigator(profile, layout, sensors, mapping, self)
        P0 = initial_covariance(layout, profile, trajectory.initial_state(), self)
        native = make_filter.native(np.zeros(layout.n), P0)
        values = operating_point(navigator.output(), navigator.strapdown.specific_force, navigator.frame,
                                 profile.imu_budget, navigator.noise)
        return NativeFilterLoop(navigator, native, mode, len(trajectory.truth) - 1, trajectory.record_period,
                                layout.fed_back_mask(), profile.filter.gate_probability, values, record_every, progress)

    def fly(self, profile: Any, derived: DerivedModel, trajectory: Trajectory, sensors: SensorData,
            layout: ErrorLayout, make_filter: FilterMaker, mode: str, progress: Progress | None) -> RunResult:
        """The filter loop with a :class:`StrapdownNavigator` aided by this sensor over the whole (held) flight."""
        loop = self.filter_loop(profile, derived, trajectory, sensors, layout, make_filter, mode, progress)
        for k in range(1, loop.n_cycles + 1):
            loop.step(k)
        return loop.result


class StrapdownNavigator:
    """The simulated INS (strapdown on corrupted increments) with a navigation-quantity sensor."""

    def __init__(self, profile: Any, layout: ErrorLayout, sensors: SensorData, mapping: dict[str, str],
                 sensor: NavigationQuantitySensor):
        self.profile, self.layout, self.sensors, self.sensor = profile, layout, sensors, sensor
        trajectory = sensors.trajectory
        self.samples_per_cycle = samples_per_cycle(trajectory, profile.coning)
        self.strapdown = Strapdown(sensors.initial_navigation, trajectory.imu_rate, profile.coning,
                                   profile.vertical_damping)
        self.sensor_compensation = np.zeros(3)  # sensor bias fed back (closed loop), NED
        self.frame = layout.derived.model.frame or "NED"
        model = layout.derived.model
        self.rows = np.array([model.measurement_names.index(name) for name in mapping])
        self.quantities = [QUANTITIES[q] for q in mapping.values()]
        self.record = sensors.aiding
        record = self.record
        self.every = int(round((record.times[1] - record.times[0]) / trajectory.record_period)) if len(record.times) > 1 else 1
        self.noise = profile.constant_parameters()

    # navigator protocol
    def advance(self, cycle: int) -> None:
        start = (cycle - 1) * self.samples_per_cycle - self.sensors.sample_offset
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
        if self.sensor.bias_group:
            self.sensor_compensation += self.layout.sensor_vector(self.sensor.bias_group, dx)

    def parameters(self, corrected_output: np.ndarray) -> dict[str, float]:
        values = operating_point(corrected_output, self.strapdown.specific_force, self.frame, self.profile.imu_budget,
                                 self.noise)
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
        velocity, position = self.sensor.fix(self.record, j, nav)
        if self.sensor.bias_group and velocity is not None:
            velocity = velocity - self.sensor_compensation - self.layout.sensor_vector(self.sensor.bias_group, accumulated)
        z = np.empty(len(self.rows))
        meridian, prime_vertical = earth.radii_of_curvature(nav[0])
        for i, (kind, axis, sign) in enumerate(self.quantities):
            if kind == "velocity":
                if velocity is None:
                    raise ModelError(f"scenario: the {self.sensor.name} sensor cannot measure velocity "
                                     f"(filter.measurements.{self.sensor.name})")
                z[i] = sign * (nav[3 + axis] - velocity[axis])
            elif position is None:
                raise ModelError(f"scenario: the {self.sensor.name} sensor cannot measure {kind} "
                                 f"(filter.measurements.{self.sensor.name})")
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
        if self.sensor.bias_group:
            true_state += layout.sensor_states(self.sensor.bias_group,
                                               self.sensor.true_bias(self.record) - self.sensor_compensation)
        sensor_part = np.ones(layout.n, bool)
        for group in ("attitude", "velocity", "position"):
            sensor_part[layout.indices(group)] = False
        # navigation states: the corrected output already has the estimate removed
        return np.where(sensor_part, true_state - estimate, true_state)


def initial_covariance(layout: ErrorLayout, profile: Any, truth0: np.ndarray,
                       sensor: NavigationQuantitySensor) -> np.ndarray:
    """P0 from the profile's initial errors, the IMU error budget and the sensor's bias, in the model's states."""
    P = np.zeros((layout.n, layout.n))
    ie, b = profile.initial_errors, profile.imu_budget
    meridian, prime_vertical = earth.radii_of_curvature(truth0[0])
    for e in layout.groups.get("attitude", []):
        P[e.index, e.index] = ie.attitude[e.axis] ** 2
    for e in layout.groups.get("velocity", []):
        P[e.index, e.index] = ie.velocity**2 if e.axis < 2 else 0.0
    for e in layout.groups.get("position", []):
        scale = {0: meridian + truth0[2], 1: (prime_vertical + truth0[2]) * math.cos(truth0[0])}.get(e.axis, 1.0)
        P[e.index, e.index] = (ie.position / scale) ** 2 if e.axis != 2 and e.axis != 5 else 0.0
    sigmas = {"gyro_constant": b.gyro_constant_drift, "gyro_markov": b.gyro_markov_drift,
              "accelerometer_constant": b.accel_constant_bias, "accelerometer_markov": b.accel_markov_bias}
    if sensor.bias_group:
        sigmas[sensor.bias_group] = sensor.bias_sigma(profile.sensors[sensor.name])
    for group, sigma in sigmas.items():
        for e in layout.groups.get(group, []):
            P[e.index, e.index] = sigma**2
    return P
