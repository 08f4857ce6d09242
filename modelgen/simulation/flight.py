"""One simulated flight: the sensors' errors drawn, the filter flown in a correction mode.

:func:`simulate_sensors` draws one realization of every sensor error of a
flight profile (IMU, initial INS errors, reference altitude, then the aiding
sensor's own record through its plug-in); :func:`fly_profile` runs the filter
loop (:mod:`modelgen.simulation.filter_loop`) with the navigator of the
profile's aiding sensor (:mod:`modelgen.simulation.sensors`).  Neither knows
which sensor it is: the profile's sensor object does.
"""

from __future__ import annotations

import math

import numpy as np

from modelgen.derive.symbolic import DerivedModel
from modelgen.simulation import earth
from modelgen.simulation.aiding import FilterMaker, Progress, SensorData
from modelgen.simulation.error_layout import ErrorLayout
from modelgen.simulation.filter_loop import RunResult
from modelgen.simulation.imu import corrupt_increments
from modelgen.simulation.rotation import quaternion_product, rotation_vectors_to_quaternions
from modelgen.simulation.scenario import FlightProfile
from modelgen.simulation.trajectory import Trajectory


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


def simulate_sensors(profile: FlightProfile, trajectory: Trajectory, rng: np.random.Generator) -> SensorData:
    """One realization of every sensor error of the profile (the aiding sensor's last, from its plug-in)."""
    dtheta, dvel, history = corrupt_increments(trajectory.delta_theta, trajectory.delta_velocity, trajectory.dt,
                                               profile.imu_budget, rng, trajectory.record_every)
    ie = profile.initial_errors
    initial = perturbed_initial_state(
        trajectory.initial_state(),
        np.asarray(ie.attitude) * rng.standard_normal(3),
        np.r_[ie.velocity * rng.standard_normal(2), 0.0],
        ie.position * rng.standard_normal(2),
    )
    truth = trajectory.truth
    altitude = truth[:, 3] + profile.altitude_noise * rng.standard_normal(len(truth))
    record = profile.aiding_sensor.simulate(profile, trajectory, initial, rng)
    return SensorData(trajectory, dtheta, dvel, history, initial, altitude, record)


def profile_layout(profile: FlightProfile, derived: DerivedModel, trajectory: Trajectory) -> ErrorLayout:
    """How ``derived``'s error states map onto the simulated errors, as the profile's aiding sensor says."""
    return profile.aiding_sensor.layout(profile, derived, trajectory)


def fly_profile(profile: FlightProfile, derived: DerivedModel, trajectory: Trajectory, rng: np.random.Generator,
                make_filter: FilterMaker, mode: str | None = None, sensors: SensorData | None = None,
                layout: ErrorLayout | None = None, progress: Progress | None = None,
                truth_profile: FlightProfile | None = None) -> RunResult:
    """Simulate the sensors (unless given) and run the filter in ``mode`` over the whole trajectory.

    The filter is tuned from ``profile``; the sensors are drawn from
    ``truth_profile`` if given (a mis-modelled filter), else from ``profile``.
    """
    mode = mode or profile.filter.mode
    layout = layout or profile_layout(profile, derived, trajectory)
    sensors = sensors or simulate_sensors(truth_profile or profile, trajectory, rng)
    return profile.aiding_sensor.fly(profile, derived, trajectory, sensors, layout, make_filter, mode, progress)
