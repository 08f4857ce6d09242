"""The aiding-sensor plug-in interface, and what every sensor's navigator shares.

An aiding sensor of the simulation (Doppler radar, GPS position/velocity,
GPS pseudo-ranges, or one a user adds) is one module holding one object that
follows :class:`AidingSensor`, plus one entry in the registry
:data:`modelgen.simulation.sensors.SENSORS`, keyed by the name a flight profile
gives in ``filter.aiding``.  The object carries everything about the sensor:

* its profile keys (:meth:`AidingSensor.read_settings` reads the profile
  section of its own name);
* its noise (:meth:`AidingSensor.noise_parameters`: the model parameters its
  measurement noise sets, by their spelled-out names);
* its measurement simulation (:meth:`AidingSensor.simulate`);
* its measurement function in the filter loop (:meth:`AidingSensor.fly`: the
  navigator that forms z from the INS output and the simulated record).

No other module tests the aiding name: the loader, the flight and the report
ask the profile's sensor object.  This module is below every sensor, the
flight and the profile loader, so none of them import each other in a circle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Mapping, Protocol

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.error_layout import ErrorLayout, frame_matrix
from modelgen.simulation.filter_loop import RunResult
from modelgen.simulation.filters import KalmanFilter, ModelMatrices
from modelgen.simulation.imu import ImuErrorBudget, ImuErrorHistory, ImuErrorStream
from modelgen.simulation.profile_keys import ProfileSection
from modelgen.simulation.rotation import quaternion_to_dcm
from modelgen.simulation.strapdown import ALGORITHMS
from modelgen.simulation.trajectory import Trajectory

if TYPE_CHECKING:  # sympy-based, named in annotations only: a run of the compiled loop imports no sympy
    from modelgen.derivation.symbolic import DerivedModel

#: the maker of a fresh filter from (x0, P0), see :func:`modelgen.simulation.filters.filter_factory`
FilterMaker = Callable[[np.ndarray, np.ndarray], KalmanFilter]
Progress = Callable[[int, int], None]


@dataclass
class SensorData:
    """Everything one simulated run measures, plus the truth of its errors.

    Streamed (``imu_stream`` set, from a streamed trajectory) the IMU
    increments are not held: the streaming driver puts each piece into
    ``delta_theta``/``delta_velocity`` with its first sample in ``sample_offset``.

    ``aiding`` is the record the profile's aiding sensor simulated (its own
    type: :class:`~modelgen.simulation.doppler.DopplerRecord`,
    :class:`~modelgen.simulation.gps.GpsRecord`...).
    """

    trajectory: Trajectory
    delta_theta: np.ndarray | None  # measured increments; streamed: the current piece only
    delta_velocity: np.ndarray | None
    imu_errors: ImuErrorHistory
    initial_navigation: np.ndarray
    altitude_reference: np.ndarray  # at record times
    aiding: Any
    imu_stream: ImuErrorStream | None = None  # streamed: replays the measured increments piece by piece
    sample_offset: int = 0  # streamed: the IMU sample of row 0 of delta_theta / delta_velocity

    @property
    def streamed(self) -> bool:
        """True when the measured increments come piece by piece (:mod:`modelgen.simulation.streaming`)."""
        return self.imu_stream is not None


class AidingSensor(Protocol):
    """One aiding sensor: profile keys, noise, measurement simulation, measurement function.

    ``profile`` arguments are :class:`modelgen.simulation.scenario.FlightProfile`
    (not imported here: the profile module builds on the registry of sensors).
    """

    #: the profile's ``filter.aiding`` value and the name of the profile section with its keys
    name: str
    #: navigation quantities ``filter.measurements.<name>`` may map model measurements to
    #: (``velocity_north``...; empty when the sensor maps its rows itself)
    quantities: tuple[str, ...]

    def read_settings(self, section: ProfileSection) -> Any:
        """Its settings (SI) from its profile section (all defaults when the section is absent)."""

    def period(self, settings: Any) -> float:
        """Seconds between two of its measurements."""

    def noise_parameters(self, settings: Any) -> dict[str, float]:
        """Values of the model parameters its measurement noise sets (R), by their spelled-out names."""

    def simulate(self, profile: Any, trajectory: Trajectory, initial_navigation: np.ndarray,
                 rng: np.random.Generator) -> Any:
        """One realization of its outputs over the flight (drawn from ``rng`` after the IMU's errors).

        May refine the INS initial state in place (a pseudo-range receiver's
        3-D fix also initializes height and vertical velocity).
        """

    def layout(self, profile: Any, derived: DerivedModel, trajectory: Trajectory) -> ErrorLayout:
        """How the model's error states map onto the simulated errors."""

    def fly(self, profile: Any, derived: DerivedModel, trajectory: Trajectory, sensors: SensorData,
            layout: ErrorLayout, make_filter: FilterMaker, mode: str, progress: Progress | None) -> RunResult:
        """Run the filter loop with this sensor's navigator (its measurement function) over the flight."""


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


def operating_point(nav: np.ndarray, specific_force: np.ndarray, frame: str, imu_budget: ImuErrorBudget,
                    sensor_noise: Mapping[str, float]) -> dict[str, float]:
    """Every parameter a model of the library may ask for, by its spelled-out name.

    Operating point (from the corrected navigation output) plus error
    statistics (the IMU budget, and ``sensor_noise``: every sensor's
    :meth:`AidingSensor.noise_parameters`).  c11..c33 is C_b^n in the model's frame.
    """
    lat, lon, h = float(nav[0]), float(nav[1]), float(nav[2])
    v = nav[3:6]
    C = quaternion_to_dcm(nav[6:10])
    if frame.upper() not in ("", "NED"):
        C = frame_matrix(frame) @ C
    meridian, prime_vertical = earth.radii_of_curvature(lat)
    b = imu_budget
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
        **sensor_noise,
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


def measurement_function(derived: DerivedModel) -> Callable[[dict], tuple[np.ndarray, np.ndarray]]:
    """H and R of the model at an operating point."""

    evaluate = ModelMatrices(derived)

    def matrices(parameters: dict) -> tuple[np.ndarray, np.ndarray]:
        m = evaluate(parameters)
        return m["H"], m["R"]

    return matrices
