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
from typing import TYPE_CHECKING

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.aiding import FilterMaker, Progress, SensorData
from modelgen.simulation.error_layout import ErrorLayout
from modelgen.simulation.filter_loop import RunResult
from modelgen.simulation.imu import ImuErrorStream, corrupt_increments
from modelgen.simulation.rotation import quaternion_product, rotation_vectors_to_quaternions
from modelgen.simulation.scenario import FlightProfile
from modelgen.simulation.streaming import PIECE_SECONDS, fly_modes
from modelgen.simulation.trajectory import Trajectory

if TYPE_CHECKING:  # sympy-based, named in annotations only: a run of the compiled loop imports no sympy
    from modelgen.derivation.symbolic import DerivedModel
    from modelgen.simulation.model_outline import ModelOutline


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


def imu_error_stream(profile: FlightProfile, n_samples: int, record_every: int,
                     rng: np.random.Generator) -> ImuErrorStream:
    """The IMU errors of a flight of ``n_samples``, streamed: the first draws :func:`simulate_sensors` makes.

    It needs no truth, so it can be drawn while the truth is computed (``modelgen
    simulate`` does) and handed to :func:`simulate_sensors` as ``imu_stream``.
    """
    return ImuErrorStream(profile.imu_budget, 1.0 / profile.imu_rate, n_samples, record_every, rng)


def simulate_sensors(profile: FlightProfile, trajectory: Trajectory, rng: np.random.Generator,
                     stream_errors: bool | None = None, imu_stream: ImuErrorStream | None = None) -> SensorData:
    """One realization of every sensor error of the profile (the aiding sensor's last, from its plug-in).

    For a streamed trajectory (or ``stream_errors=True``) the IMU errors are
    an :class:`ImuErrorStream` (nothing of the length of the flight is held);
    ``rng`` is drawn from exactly as for a whole one, so the same seed gives
    the same flight.  Streamed errors on a held trajectory suit many runs of
    one flight (a Monte Carlo worker): the ideal increments are made once and
    shared, and each run adds only its pieces of measured increments.
    ``imu_stream``: that stream already drawn from ``rng`` (:func:`imu_error_stream`).
    """
    stream = imu_stream
    if stream is not None:
        if (stream.n, stream.record_every, stream.dt) != (trajectory.n_samples, trajectory.record_every, trajectory.dt):
            raise ModelError(f"simulate_sensors: the IMU error stream ({stream.n} samples, a record every "
                             f"{stream.record_every}) is not this trajectory's ({trajectory.n_samples}, "
                             f"{trajectory.record_every})")
        dtheta = dvel = None
        history = stream.history
    elif trajectory.streamed or stream_errors:
        stream = ImuErrorStream(profile.imu_budget, trajectory.dt, trajectory.n_samples, trajectory.record_every, rng)
        dtheta = dvel = None
        history = stream.history
    else:
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
    return SensorData(trajectory, dtheta, dvel, history, initial, altitude, record, stream)


def profile_layout(profile: FlightProfile, derived: DerivedModel, trajectory: Trajectory) -> ErrorLayout:
    """How ``derived``'s error states map onto the simulated errors, as the profile's aiding sensor says."""
    return profile.aiding_sensor.layout(profile, derived, trajectory)


def fly_profile(profile: FlightProfile, derived: DerivedModel | ModelOutline, trajectory: Trajectory,
                rng: np.random.Generator, make_filter: FilterMaker, mode: str | None = None,
                sensors: SensorData | None = None,
                layout: ErrorLayout | None = None, progress: Progress | None = None,
                truth_profile: FlightProfile | None = None, record_every: int = 1,
                piece_seconds: float | None = None) -> RunResult:
    """Simulate the sensors (unless given) and run the filter in ``mode`` over the whole trajectory.

    The filter is tuned from ``profile``; the sensors are drawn from
    ``truth_profile`` if given (a mis-modelled filter), else from ``profile``.
    A streamed ``trajectory`` (``generate_trajectory(..., streamed=True)``) is
    flown piece by piece (:mod:`modelgen.simulation.streaming`, pieces of
    ``piece_seconds``), with memory independent of the flight's duration and
    the same result as a held one for the same ``rng``.

    Returns a :class:`RunResult`: rows at t = 0 and then every
    ``record_every`` filter cycles (and the last), each with the corrected
    output, the INS's own output, the estimation error (true error state minus
    estimate, model states), sqrt(diag P) and the NEES; plus counts of updates,
    outage skips, gate rejections and refusals over every cycle.
    """
    mode = mode or profile.filter.mode
    layout = layout or profile_layout(profile, derived, trajectory)
    sensors = sensors or simulate_sensors(truth_profile or profile, trajectory, rng)
    if not hasattr(profile.aiding_sensor, "filter_loop"):
        if trajectory.streamed:
            raise ModelError(f"aiding sensor {profile.aiding_sensor.name!r} cannot fly a streamed trajectory "
                             "(it has no filter_loop())")
        return profile.aiding_sensor.fly(profile, derived, trajectory, sensors, layout, make_filter, mode, progress)
    results = fly_modes(profile, derived, trajectory, sensors, layout, make_filter, [mode],
                        (lambda _: progress) if progress else None, piece_seconds or PIECE_SECONDS, record_every)
    return results[mode]
