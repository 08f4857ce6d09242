"""The forward, real-time navigator loop: alignment, mechanization, filter, GNSS/ZUPT/NHC updates.

Nothing from the future is used: every decision at time t uses IMU samples up
to t and GNSS epochs up to t (the zero-velocity detector's window ends at the
current sample; a GNSS epoch is applied at the first IMU sample at or after it,
extrapolated to that sample by its own velocity).  Outputs are written at every
GNSS epoch (inside outages too), at that IMU sample, at the antenna.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import numpy as np
from scipy.stats import chi2

from modelgen.errors import ModelError
from modelgen.model.frames import NED_TO_ENU
from modelgen.navigator.alignment import Alignment, align  # noqa: F401  (the alignment lives in alignment.py)
from modelgen.navigator.config import NavigatorConfig
from modelgen.navigator.errorstate import ErrorStateFilter, feedback
from modelgen.navigator.logs import GnssLog, ImuLog, check_logs, epochs_inside_gaps
from modelgen.navigator.mechanization import dcm_to_euler, euler_to_dcm, mechanize, quaternion_to_dcm, radii
from modelgen.navigator.outages import in_outage, outage_windows

HISTORY = 16  # INS velocities kept (one per covariance step) for the GNSS velocity latency
OUTPUT_FIELDS = ("time", "latitude", "longitude", "height", "v_north", "v_east", "v_down", "roll", "pitch", "yaw",
                 "sigma_north", "sigma_east", "sigma_up", "gyro_bias_x", "gyro_bias_y", "gyro_bias_z",
                 "accel_bias_x", "accel_bias_y", "accel_bias_z", "in_outage", "gnss_used", "nis", "gnss_quality",
                 "cov_north_east", "cov_east_up", "cov_up_north")


@dataclass
class Flight:
    """What a flight produced: per-epoch outputs and the counts the report states."""

    outputs: np.ndarray  # (epochs, len(OUTPUT_FIELDS))
    outages: list[tuple[float, float]]  # absolute (start, end)
    first_epoch: float  # the GNSS file's first epoch [s] (outage schedule and report times count from it)
    alignment_time: float
    gnss_nis: list[float] = field(default_factory=list)  # NIS of every GNSS update tried outside outages
    gate: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    #: the alignment: time (the GNSS epoch it completed at) [s], roll, pitch, heading [rad], rest_end [s], rest_samples
    alignment: dict[str, float] = field(default_factory=dict)
    #: what the smoother needs (fly(..., record=ForwardRecord())): modelgen.navigator.smoother.ForwardRecord, else None
    forward_record: object | None = None


@dataclass
class Inputs:
    """The logs prepared for the loop: body-axis IMU, aligned times, GNSS epochs after the first IMU sample."""

    time: np.ndarray
    force: np.ndarray  # body axes [m/s^2]
    rate: np.ndarray  # body axes [rad/s]
    gnss: GnssLog
    notes: list[str]
    first_epoch: float  # the GNSS file's first epoch [s]: the outage schedule and the report count from it
    source_gnss: GnssLog | None = None  # the GNSS log as read (for the alignment's diagnosis of a log that ends first)


def prepare(config: NavigatorConfig, imu: ImuLog, gnss: GnssLog) -> Inputs:
    """Rotate the IMU into body axes, shift its time, drop GNSS epochs outside the IMU span or in its gaps (noted)."""
    check_logs(imu, gnss, config.quality_factor, config.time_offset)  # no fix, nothing in the IMU span: refused
    if gnss.velocity is None:
        raise ModelError(f"{gnss.path}: the navigator needs GNSS velocities (vn, ve, vu columns)")
    # The data's convention (checked on the drive: the vehicle is level at rest only this way):
    # the angles rotate body axes into IMU axes, C = euler(angles) maps body -> IMU, so a
    # sample in IMU axes is C^T v in body axes.
    to_imu = euler_to_dcm(*config.rotation_to_body)
    time = imu.time + config.time_offset
    in_gap = epochs_inside_gaps(gnss.time, imu.gaps, config.time_offset)  # imu.gap_action: propagate
    keep = (gnss.time >= time[0]) & (gnss.time <= time[-1]) & ~in_gap
    notes = list(imu.notes) + list(gnss.notes)
    if in_gap.any():
        notes.append(f"{gnss.path}: {int(in_gap.sum())} GNSS epoch(s) inside IMU gaps not used (no IMU sample "
                     "to apply them at)")
    dropped_before = int(np.sum(gnss.time < time[0]))
    if dropped_before:
        notes.append(f"{gnss.path}: {dropped_before} GNSS epoch(s) before the first IMU sample not used")
    dropped_after = int(np.sum(gnss.time > time[-1]))
    if dropped_after:
        notes.append(f"{gnss.path}: {dropped_after} GNSS epoch(s) after the last IMU sample not used")
    if not keep.any():
        raise ModelError(f"{gnss.path}: no GNSS epoch inside the IMU log's time span "
                         f"({time[0]:.3f} .. {time[-1]:.3f} s)")
    kept = GnssLog(gnss.path, gnss.time[keep], gnss.latitude[keep], gnss.longitude[keep], gnss.height[keep],
                   gnss.quality[keep], gnss.satellites[keep], gnss.sigma_position[keep], gnss.velocity[keep],
                   gnss.sigma_velocity[keep], gnss.notes)
    return Inputs(time, imu.specific_force @ to_imu, imu.angular_rate @ to_imu, kept, notes, float(gnss.time[0]), gnss)


def stationary_mask(time: np.ndarray, force: np.ndarray, rate: np.ndarray, gyro_bias: np.ndarray,
                    window: float, gyro_max: float, accel_std_max: float) -> np.ndarray:
    """Per sample: the window of ``window`` seconds ending there is still (causal, IMU only)."""
    n = max(2, int(round(window / float(np.median(np.diff(time))))))
    rate_norm = np.linalg.norm(rate - gyro_bias, axis=1)
    force_norm = np.linalg.norm(force, axis=1)
    still = np.zeros(len(time), dtype=bool)
    if len(time) < n:
        return still
    windows_rate = np.lib.stride_tricks.sliding_window_view(rate_norm, n).max(axis=1)
    windows_force = np.lib.stride_tricks.sliding_window_view(force_norm, n).std(axis=1)
    still[n - 1:] = (windows_rate < gyro_max) & (windows_force < accel_std_max)
    return still


def _gnss_sigmas(config: NavigatorConfig, gnss: GnssLog, j: int) -> np.ndarray | None:
    """[sigma_vE, sigma_vN, sigma_vU, sigma_pN, sigma_pE, sigma_pU] of epoch j, or None if its Q is not used."""
    factor = config.quality_factor.get(int(gnss.quality[j]))
    if factor is None:
        return None
    sv, sp = gnss.sigma_velocity[j], gnss.sigma_position[j]
    v = np.maximum(np.array([sv[1], sv[0], sv[2]]) * factor, config.minimum_sigma_velocity)
    p = np.maximum(np.array([sp[0], sp[1], sp[2]]) * factor, config.minimum_sigma_position)
    return np.concatenate([v, p])


def antenna(nav: np.ndarray, lever: np.ndarray, rate_body: np.ndarray) -> tuple[float, float, float, np.ndarray]:
    """Antenna latitude, longitude, height and NED velocity from the IMU state and the lever arm."""
    c = quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3])
    offset = c @ lever
    rm, rn = radii(nav[7])
    lat = nav[7] + offset[0] / (rm + nav[9])
    lon = nav[8] + offset[1] / ((rn + nav[9]) * math.cos(nav[7]))
    velocity = nav[4:7] + c @ np.cross(rate_body, lever)
    return lat, lon, nav[9] - offset[2], velocity


def initial_covariance(config: NavigatorConfig, nav: np.ndarray, heading_sigma: float) -> np.ndarray:
    """P0: attitude, velocity, position (as dL, dlambda, dh), gyro and accelerometer biases."""
    rm, rn = radii(nav[7])
    sigmas = [config.roll_pitch_sigma, config.roll_pitch_sigma, heading_sigma,
              *[config.velocity_sigma] * 3,
              config.position_sigma / (rm + nav[9]), config.position_sigma / ((rn + nav[9]) * math.cos(nav[7])),
              config.height_sigma, *[config.gyro_bias_sigma] * 3, *[config.accel_bias_sigma] * 3]
    return np.diag(np.square(sigmas))


def _gnss_measurement(nav: np.ndarray, lever: np.ndarray, rate: np.ndarray, g: GnssLog, j: int,
                      t: float, delayed_velocity: np.ndarray) -> np.ndarray:
    """z = antenna(INS) - GNSS: [vE, vN, vU] [m/s], [N, E, U] [m].

    The GNSS position is extrapolated by its velocity from its epoch to the IMU
    sample time t; the GNSS velocity is compared with the INS velocity
    ``delayed_velocity`` of its latency earlier (the velocity error is taken as
    constant over that latency, so H is the model's).
    """
    lat, lon, h, v = antenna(nav, lever, rate)
    v = v - nav[4:7] + delayed_velocity
    dt = t - g.time[j]
    vg = g.velocity[j]
    rm, rn = radii(g.latitude[j])
    lat_g = g.latitude[j] + vg[0] * dt / (rm + g.height[j])
    lon_g = g.longitude[j] + vg[1] * dt / ((rn + g.height[j]) * math.cos(g.latitude[j]))
    h_g = g.height[j] - vg[2] * dt
    rm, rn = radii(nav[7])
    return np.array([v[1] - vg[1], v[0] - vg[0], -(v[2] - vg[2]),
                     (lat - lat_g) * (rm + nav[9]), (lon - lon_g) * (rn + nav[9]) * math.cos(nav[7]), h - h_g])


def _nhc_rows(nav: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """z = body lateral and vertical velocity, and H = [-C_n^b [v x], C_n^b, 0] rows y, z (ENU states)."""
    c_nb = (NED_TO_ENU @ quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3])).T  # ENU -> body
    v = NED_TO_ENU @ nav[4:7]
    skew = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    H = np.zeros((2, 15))
    H[:, 0:3] = -(c_nb @ skew)[1:3]
    H[:, 3:6] = c_nb[1:3]
    return (c_nb @ v)[1:3], H


def fly(config: NavigatorConfig, inputs: Inputs, module, progress: Callable[[float], None] | None = None,
        record=None) -> Flight:
    """Fly the whole log forward in real time; return the per-epoch outputs.

    ``record``: a fresh :class:`modelgen.navigator.smoother.ForwardRecord` to
    fill with what the smoother needs (transitions, covariances, corrections,
    nominal states at the outputs); the flight carries it as ``forward_record``.
    """
    g = inputs.gnss
    time, force, rate = inputs.time, inputs.force, inputs.rate
    lever = np.asarray(config.lever_arm, float)
    windows = outage_windows(config.outage_schedule, config.outage_windows, inputs.first_epoch, float(g.time[-1]))
    outage = in_outage(g.time, windows)
    start = align(config, inputs, outage)
    j0, k, nav, gyro_bias, accel_bias = start.epoch, start.sample, start.nav, start.gyro_bias, start.accel_bias
    speed0 = float(np.hypot(g.velocity[j0, 0], g.velocity[j0, 1]))
    sv = float(np.hypot(g.sigma_velocity[j0, 0], g.sigma_velocity[j0, 1]))
    heading_sigma = math.hypot(math.atan2(sv, speed0), config.heading_extra_sigma)
    noise = {"gyro_angle_random_walk": config.noise["gyro_white"].si,
             "accel_velocity_random_walk": config.noise["accel_white"].si,
             "gyro_bias_driving_noise": config.noise["gyro_bias_driving"].si,
             "accel_bias_driving_noise": config.noise["accel_bias_driving"].si}
    kf = ErrorStateFilter(module, initial_covariance(config, nav, heading_sigma), noise)
    sensors = {"gyro_bias": gyro_bias, "accel_bias": accel_bias}  # the arrays the feedback corrects in place
    if record is not None:
        record.start(kf.P, _apply_correction)
    kf.recorder = record
    still = (stationary_mask(time, force, rate, gyro_bias, config.zupt_window, config.zupt_gyro_max,
                             config.zupt_accel_std_max) if config.zupt_enabled else np.zeros(len(time), bool))
    step = max(1, int(round(config.predict_period / float(np.median(np.diff(time))))))
    gates = {m: float(chi2.ppf(config.nis_gate_probability, m)) for m in (2, 3, 6)}
    history = np.zeros(6)
    outputs = []
    gnss_nis: list[float] = []
    counts = {"gnss_updates": 0, "gnss_rejected": 0, "gnss_released": 0, "gnss_deweighted": 0, "gnss_quality_skipped": 0,
              "zupt_updates": 0, "nhc_updates": 0, "predicts": 0}
    rejected_run = 0
    deweight = config.gate_action == "deweight"
    last_sigmas = _gnss_sigmas(config, g, j0)
    if last_sigmas is None:
        last_sigmas = np.full(6, 1.0)
    mean_force = np.zeros(4)
    velocity_history = np.tile(np.r_[time[k], nav[4:7]][:, None], (1, HISTORY))  # time, vN, vE, vD per column
    velocity_history[0] -= np.arange(HISTORY)[::-1] * 1e-3
    n_epochs = len(g.time)
    for j in range(j0, n_epochs):
        target = int(np.searchsorted(time, g.time[j]))
        if target >= len(time):
            break
        while k < target:
            stop = min(target, k + step)
            mean_force[:] = 0.0
            mechanize(nav, history, time, force, rate, k + 1, stop + 1, gyro_bias, accel_bias, mean_force)
            period = time[stop] - time[k]
            k = stop
            kf.predict(kf.parameters(nav, mean_force[0:3] / mean_force[3], last_sigmas), period)
            counts["predicts"] += 1
            _remember(velocity_history, time[k], nav)
            speed = float(np.linalg.norm(nav[4:7]))
            if still[k] and speed < config.zupt_speed_max:
                v_enu = NED_TO_ENU @ nav[4:7]
                H = np.zeros((3, 15))
                H[:, 3:6] = np.eye(3)
                if kf.update(v_enu, H, np.full(3, config.zupt_sigma**2), gates[3], deweight).accepted:
                    counts["zupt_updates"] += 1
                    _reset(kf, nav, gyro_bias, accel_bias)
            elif (config.nhc_enabled and speed > config.nhc_speed_min
                  and float(np.linalg.norm(rate[k] - gyro_bias)) < config.nhc_rate_max):
                z, H = _nhc_rows(nav)
                r = np.array([config.nhc_sigma_lateral**2, config.nhc_sigma_vertical**2])
                if kf.update(z, H, r, gates[2], deweight).accepted:
                    counts["nhc_updates"] += 1
                    _reset(kf, nav, gyro_bias, accel_bias)
        used = 0
        nis = float("nan")
        sigmas = _gnss_sigmas(config, g, j)
        if not outage[j] and sigmas is None:
            counts["gnss_quality_skipped"] += 1
        elif not outage[j]:
            last_sigmas = sigmas
            delayed = np.array([np.interp(time[k] - config.velocity_latency, velocity_history[0], velocity_history[1 + i])
                                for i in range(3)])
            z = _gnss_measurement(nav, lever, rate[k] - gyro_bias, g, j, time[k], delayed)
            p = kf.parameters(nav, mean_force[0:3] / max(mean_force[3], 1e-9), sigmas)
            H = module.measurement_matrix(p)
            r = np.square(sigmas)
            gate = gates[6] if rejected_run < config.gate_release_epochs else math.inf
            result = kf.update(z, H, r, gate, deweight)
            nis = result.nis
            gnss_nis.append(nis)
            if result.accepted:
                counts["gnss_updates"] += 1
                if nis > gates[6]:
                    counts["gnss_deweighted"] += 1
                if rejected_run >= config.gate_release_epochs:
                    counts["gnss_released"] += 1
                rejected_run = 0
                used = 1
                _reset(kf, nav, gyro_bias, accel_bias)
            else:
                counts["gnss_rejected"] += 1
                rejected_run += 1
        outputs.append(_record(time[k], nav, lever, rate[k] - gyro_bias, kf.P, gyro_bias, accel_bias,
                               bool(outage[j]), used, nis, int(g.quality[j])))
        if kf.recorder is not None:
            kf.recorder.output(nav, sensors, partial(_row, time[k], lever, rate[k], bool(outage[j]), used, nis,
                                                     int(g.quality[j])))
        if progress is not None and (j - j0) % 200 == 0:
            progress((j - j0) / max(1, n_epochs - j0))
    if progress is not None:
        progress(1.0)
    return Flight(np.array(outputs), windows, inputs.first_epoch, float(g.time[j0]), gnss_nis, gates[6], counts,
                  list(inputs.notes), start.record(), kf.recorder)


def _remember(history: np.ndarray, t: float, nav: np.ndarray) -> None:
    """Shift the INS velocity history by one column and store (t, v) last (oldest first)."""
    history[:, :-1] = history[:, 1:]
    history[0, -1] = t
    history[1:, -1] = nav[4:7]


def _reset(kf: ErrorStateFilter, nav: np.ndarray, gyro_bias: np.ndarray, accel_bias: np.ndarray) -> None:
    """Feed the estimate back and zero the error state (closed loop)."""
    if kf.recorder is not None:
        kf.recorder.corrected(kf.x, kf.P)
    feedback(nav, kf.x, gyro_bias, accel_bias)
    kf.x = np.zeros_like(kf.x)


def _apply_correction(nav: np.ndarray, sensors: dict[str, np.ndarray], dx: np.ndarray) -> None:
    """The closed-loop feedback of a correction dx into a nominal state (the smoother applies its own with it)."""
    feedback(nav, dx, sensors["gyro_bias"], sensors["accel_bias"])


def _row(t: float, lever: np.ndarray, raw_rate: np.ndarray, outage: bool, used: int, nis: float, quality: int,
         nav: np.ndarray, sensors: dict[str, np.ndarray], P: np.ndarray) -> list[float]:
    """An output row of a (smoothed) nominal state: :func:`_record` with its sensor estimates."""
    return _record(t, nav, lever, raw_rate - sensors["gyro_bias"], P, sensors["gyro_bias"], sensors["accel_bias"],
                   outage, used, nis, quality)


def _record(t: float, nav: np.ndarray, lever: np.ndarray, rate: np.ndarray, P: np.ndarray, gyro_bias: np.ndarray,
            accel_bias: np.ndarray, outage: bool, used: int, nis: float, quality: int) -> list[float]:
    """One output row (OUTPUT_FIELDS): antenna position, velocity, attitude, 1-sigma position, biases."""
    lat, lon, h, v = antenna(nav, lever, rate)
    roll, pitch, yaw = dcm_to_euler(quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3]))
    rm, rn = radii(nav[7])
    sn = math.sqrt(max(P[6, 6], 0.0)) * (rm + nav[9])
    se = math.sqrt(max(P[7, 7], 0.0)) * (rn + nav[9]) * math.cos(nav[7])
    su = math.sqrt(max(P[8, 8], 0.0))
    # cross covariances [m^2] (north-east, east-up, up-north): the 2x2 horizontal covariance with sn, se
    cne = P[6, 7] * (rm + nav[9]) * (rn + nav[9]) * math.cos(nav[7])
    ceu = P[7, 8] * (rn + nav[9]) * math.cos(nav[7])
    cun = P[8, 6] * (rm + nav[9])
    return [t, lat, lon, h, v[0], v[1], v[2], roll, pitch, yaw, sn, se, su, *gyro_bias, *accel_bias,
            float(outage), float(used), nis, float(quality), cne, ceu, cun]


