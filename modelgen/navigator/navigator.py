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

from modelgen.errors import ModelError
from modelgen.navigator.alignment import Alignment, align  # noqa: F401  (the alignment lives in alignment.py)
from modelgen.navigator.config import NavigatorConfig
from modelgen.navigator import cconfig
from modelgen.navigator.cconfig_fields import WINDOW_SAMPLES_MIN
from modelgen.navigator import ecef
from modelgen.navigator.errorstate import ErrorStateFilter, rotate
from modelgen.navigator.logs import GnssLog, ImuLog, ScalarLog, check_logs, epochs_inside_gaps, read_scalar
from modelgen.navigator.mechanization import (dcm_to_euler, euler_to_dcm, gravity, mechanize, quaternion_to_dcm,
                                              radii)
from modelgen.navigator.outages import in_outage, outage_windows
from modelgen.navigator import sensors as aiding_sensors
from modelgen.navigator.sensors import SENSORS, AidingSensor, StreamCursor
from modelgen.navigator.spec import NavigatorSpec, quantities

HISTORY = 16  # INS velocities kept (one per covariance step) for the GNSS velocity latency
OUTPUT_FIELDS = ("time", "latitude", "longitude", "height", "v_north", "v_east", "v_down", "roll", "pitch", "yaw",
                 "sigma_north", "sigma_east", "sigma_up", "gyro_bias_x", "gyro_bias_y", "gyro_bias_z",
                 "accel_bias_x", "accel_bias_y", "accel_bias_z", "in_outage", "gnss_used", "nis", "gnss_quality",
                 "cov_north_east", "cov_east_up", "cov_up_north", "gyro_scale_factor_x", "gyro_scale_factor_y",
                 "gyro_scale_factor_z", "accel_scale_factor_x", "accel_scale_factor_y", "accel_scale_factor_z")


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
    #: the sensor-error blocks the model estimates (NavigatorSpec.estimated_sensors): the output columns of the
    #: others hold their fixed value, 0
    estimated: tuple[str, ...] = ()


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
    #: the enabled aiding sensors' own logs by sensor name (odometer, barometer), times on the GNSS time
    aiding: dict[str, ScalarLog] = field(default_factory=dict)


def prepare(config: NavigatorConfig, imu: ImuLog, gnss: GnssLog) -> Inputs:
    """Rotate the IMU into body axes, shift its time, drop GNSS epochs outside the IMU span or in its gaps (noted)."""
    aiding = read_aiding_logs(config)  # the aiding sensors' own logs (odometer, barometer): refused first if bad
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
    for log in aiding.values():
        notes.extend(log.notes)
    from modelgen.navigator.alignment import check_still_window, check_zupt_window

    check_still_window(config, time)  # a window longer than the log, refused before any navigator is built
    check_zupt_window(config, time)
    return Inputs(time, imu.specific_force @ to_imu, imu.angular_rate @ to_imu, kept, notes, float(gnss.time[0]), gnss,
                  aiding)


def read_aiding_logs(config: NavigatorConfig) -> dict[str, ScalarLog]:
    """The enabled aiding sensors' own logs (config.aiding), their time stamps shifted by their time_offset_s."""
    out = {}
    for section, settings in (getattr(config, "aiding", None) or {}).items():
        if settings.enabled and settings.file is not None:
            log = read_scalar(section, settings.file, settings.time_column, settings.value_column, settings.unit)
            log.time = log.time + settings.time_offset
            out[section] = log
    return out


def stationary_mask(time: np.ndarray, force: np.ndarray, rate: np.ndarray, gyro_bias: np.ndarray,
                    window: float, gyro_max: float, accel_std_max: float) -> np.ndarray:
    """Per sample: the window of ``window`` seconds ending there is still (causal, IMU only)."""
    n = max(WINDOW_SAMPLES_MIN, int(round(window / float(np.median(np.diff(time))))))
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
    """[sigma_vN, sigma_vE, sigma_vD, sigma_pN, sigma_pE, sigma_pD] of epoch j, or None if its Q is not used.

    The receiver's sigma x the quality factor, floored, x the square root of the variance factor."""
    factor = config.quality_factor.get(int(gnss.quality[j]))
    if factor is None:
        return None
    sv, sp = gnss.sigma_velocity[j], gnss.sigma_position[j]
    v = np.maximum(np.array([sv[0], sv[1], sv[2]]) * factor, config.minimum_sigma_velocity)
    p = np.maximum(np.array([sp[0], sp[1], sp[2]]) * factor, config.minimum_sigma_position)
    # R x variance factor (gnss.position/velocity_variance_factor): sigma x its square root
    return np.concatenate([v * math.sqrt(config.gnss_velocity_variance_factor),
                           p * math.sqrt(config.gnss_position_variance_factor)])


def antenna_ecef(nav: np.ndarray, lever: np.ndarray, rate_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Antenna e-frame position and velocity of an e-frame state (ecef model): r + C l, v + C (w x l)."""
    c = quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3])
    return nav[7:10] + c @ lever, nav[4:7] + c @ np.cross(rate_body, lever)


def antenna(nav: np.ndarray, lever: np.ndarray, rate_body: np.ndarray,
            frame_ecef: bool = False) -> tuple[float, float, float, np.ndarray]:
    """Antenna latitude, longitude, height and NED velocity from the IMU state and the lever arm.

    ``frame_ecef``: ``nav`` is an e-frame state (:mod:`modelgen.navigator.ecef`); the velocity is rotated into NED
    at the IMU's position.
    """
    if frame_ecef:
        r, v = antenna_ecef(nav, lever, rate_body)
        lat, lon, h = ecef.geodetic(nav[7:10])
        lat_a, lon_a, h_a = ecef.geodetic(r)
        return lat_a, lon_a, h_a, ecef.ned_to_ecef(lat, lon).T @ v
    c = quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3])
    offset = c @ lever
    rm, rn = radii(nav[7])
    lat = nav[7] + offset[0] / (rm + nav[9])
    lon = nav[8] + offset[1] / ((rn + nav[9]) * math.cos(nav[7]))
    velocity = nav[4:7] + c @ np.cross(rate_body, lever)
    return lat, lon, nav[9] - offset[2], velocity


def _gnss_measurement(nav: np.ndarray, lever: np.ndarray, rate: np.ndarray, g: GnssLog, j: int,
                      t: float, delayed_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """antenna(INS) - GNSS: velocity [m/s] and position [m], NED.

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
    return v - vg, np.array([(lat - lat_g) * (rm + nav[9]), (lon - lon_g) * (rn + nav[9]) * math.cos(nav[7]),
                             -(h - h_g)])


def _gnss_measurement_ecef(nav: np.ndarray, lever: np.ndarray, rate: np.ndarray, g: GnssLog, j: int,
                           t: float, delayed_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """antenna(INS) - GNSS of an e-frame state: velocity [m/s] and position [m] in e-frame axes.

    The GNSS fix is extrapolated to t as :func:`_gnss_measurement` does (along NED by its velocity), then
    converted to the e-frame; its NED velocity is rotated into the e-frame at the fix.
    """
    r, v = antenna_ecef(nav, lever, rate)
    v = v - nav[4:7] + delayed_velocity
    dt = t - g.time[j]
    vg = g.velocity[j]
    rm, rn = radii(g.latitude[j])
    lat_g = g.latitude[j] + vg[0] * dt / (rm + g.height[j])
    lon_g = g.longitude[j] + vg[1] * dt / ((rn + g.height[j]) * math.cos(g.latitude[j]))
    h_g = g.height[j] - vg[2] * dt
    r_g = ecef.geodetic_to_ecef(lat_g, lon_g, h_g)
    return v - ecef.ned_to_ecef(g.latitude[j], g.longitude[j]) @ vg, r - r_g


def corrected(sample: np.ndarray, bias: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """A sensor sample corrected with the estimates: (raw - b) / (1 + s)."""
    return (sample - bias) / (1.0 + scale)


def fly(config: NavigatorConfig, inputs: Inputs, spec: NavigatorSpec,
        progress: Callable[[float], None] | None = None, record=None,
        table: tuple[AidingSensor, ...] = SENSORS, monitor: Callable | None = None) -> Flight:
    """Fly the whole log forward in real time with the spec's model; return the per-epoch outputs.

    ``record``: a fresh :class:`modelgen.navigator.smoother.ForwardRecord` to
    fill with what the smoother needs (transitions, covariances, corrections,
    nominal states at the outputs); the flight carries it as ``forward_record``.
    ``table``: the aiding sensors (:data:`modelgen.navigator.sensors.SENSORS`); those the configuration enables are
    tried at every covariance step in table order, the GNSS epochs at theirs.
    ``monitor``: called at every update tried as ``monitor(source, time, nu, S, r, nis)`` (the sensor's name, the
    update's time, the innovation, its covariance H P H^T + R, R's diagonal, the NIS;
    :mod:`modelgen.navigator.tuning` records the innovations with it).
    """
    g = inputs.gnss
    time, force, rate = inputs.time, inputs.force, inputs.rate
    lever = np.asarray(config.lever_arm, float)
    windows = outage_windows(config.outage_schedule, config.outage_windows, inputs.first_epoch, float(g.time[-1]))
    outage = in_outage(g.time, windows)
    start = align(config, inputs, outage)
    j0, k, nav = start.epoch, start.sample, start.nav
    if spec.ecef:  # the alignment is geodetic/NED; an ecef model flies r^e, v^e, C_b^e
        nav = ecef.state_from_ned(nav)
    sensors = {"gyro_bias": np.array(start.gyro_bias, float), "accel_bias": np.array(start.accel_bias, float),
               "gyro_scale_factor": np.zeros(3), "accel_scale_factor": np.zeros(3),
               "carried": np.zeros(len(spec.carried))}  # an aiding sensor's own error (NavigatorSpec.carried)
    gyro_bias, accel_bias = sensors["gyro_bias"], sensors["accel_bias"]  # updated in place by the feedback
    gyro_scale, accel_scale = sensors["gyro_scale_factor"], sensors["accel_scale_factor"]
    module = spec.module
    median_dt = float(np.median(np.diff(time)))
    step = max(1, int(round(config.predict_period / median_dt)))
    from modelgen.navigator.alignment import still_window_samples

    values = cconfig.values(config, spec, max(WINDOW_SAMPLES_MIN, int(round(config.zupt_window / median_dt))), step,
                            still_window_samples(config, time), table)
    # the C navigator's own configuration check (cconfig.bounds), so that both refuse the same configurations,
    # with the buffers the C gets for this log (a window longer than the log is refused)
    capacities = {"WINDOW_MAX": cconfig.window_capacity(config.zupt_window, time),
                  "REST_MAX": cconfig.rest_capacity(config.rest_window, config.still_window, config.zupt_window, time)}
    refused = cconfig.check(values, capacities)
    if refused is not None:
        raise cconfig.refusal(config.path, refused, values[refused.name], capacities, "Python")
    cfg = cconfig.namespace(values)
    speed0 = float(np.hypot(g.velocity[j0, 0], g.velocity[j0, 1]))
    sv = float(np.hypot(g.sigma_velocity[j0, 0], g.sigma_velocity[j0, 1]))
    heading_sigma = math.hypot(math.atan2(sv, speed0), config.heading_extra_sigma)
    def parameters(force_ned: np.ndarray, sig: np.ndarray) -> np.ndarray:
        c_bn = quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3])
        return spec.parameter_vector(quantities(spec, nav, c_bn, force_ned, corrected(rate[k], gyro_bias, gyro_scale),
                                                sig, cfg, radii, gravity))

    initial = spec.initial_covariance(config, nav, heading_sigma, radii)
    if spec.carried:  # their steady state, from the model at the first epoch's sigmas (the force plays no part)
        first_sigmas = _gnss_sigmas(config, g, j0)
        initial = spec.carried_covariance(initial, parameters(np.zeros(3), np.ones(6) if first_sigmas is None
                                                              else first_sigmas))
    kf = ErrorStateFilter(module, initial)
    if record is not None:
        record.start(kf.P, partial(_apply_correction, spec))
    kf.recorder = record
    kf.monitor = monitor

    still = (stationary_mask(time, force, rate, gyro_bias, config.zupt_window, config.zupt_gyro_max,
                             config.zupt_accel_std_max) if config.zupt_enabled else np.zeros(len(time), bool))
    gates = {1: cfg.gate_1, 2: cfg.gate_2, 3: cfg.gate_3, "gnss": cfg.gate_gnss}
    step_sensors = enabled_step_sensors(table, cfg, inputs)
    history = np.zeros(6)
    outputs = []
    gnss_nis: list[float] = []
    counts = {"gnss_updates": 0, "gnss_rejected": 0, "gnss_released": 0, "gnss_deweighted": 0, "gnss_quality_skipped": 0,
              **{s.counter: 0 for s in aiding_sensors.step_sensors(table)}, "predicts": 0}
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
            mechanize(nav, history, time, force, rate, k + 1, stop + 1, gyro_bias, accel_bias, mean_force,
                      gyro_scale, accel_scale, spec.rates)
            period = time[stop] - time[k]
            k = stop
            kf.predict(parameters(mean_force[0:3] / mean_force[3], last_sigmas), period)
            spec.propagate_carried(sensors, kf.Phi)
            counts["predicts"] += 1
            _remember(velocity_history, time[k], nav)
            _aid_step(step_sensors, time[k], nav, kf, spec, sensors, cfg, gates, deweight, counts,
                      {"speed": float(np.linalg.norm(nav[4:7])), "still": bool(still[k]),
                       "rate_norm": float(np.linalg.norm(rate[k] - gyro_bias)), "cfg": cfg},
                      corrected(rate[k], gyro_bias, gyro_scale))
        used = 0
        nis = float("nan")
        sigmas = _gnss_sigmas(config, g, j)
        if not outage[j] and sigmas is None:
            counts["gnss_quality_skipped"] += 1
        elif not outage[j]:
            last_sigmas = sigmas
            delayed = np.array([np.interp(time[k] - config.velocity_latency, velocity_history[0], velocity_history[1 + i])
                                for i in range(3)])
            measurement = _gnss_measurement_ecef if spec.ecef else _gnss_measurement
            dv, dp = measurement(nav, lever, corrected(rate[k], gyro_bias, gyro_scale), g, j, time[k], delayed)
            z, r = spec.gnss_z(dv, dp, sigmas)
            H = module.measurement_matrix(parameters(mean_force[0:3] / max(mean_force[3], 1e-9), sigmas))
            z = z - spec.carried_correction(H, sensors)  # measured = true + e: the carried estimate's share
            if spec.ecef:  # the e-frame rows turned along NED, where the receiver's sigmas are
                T, sigma_index = spec.gnss_rotation(ecef.ned_to_ecef(*ecef.geodetic(nav[7:10])[:2]))
                z, H, r = T @ z, T @ H, np.square(sigmas[sigma_index])
            gate = gates["gnss"] if rejected_run < config.gate_release_epochs else math.inf
            result = kf.update(z, H, r, gate, deweight, "gnss", float(time[k]))
            nis = result.nis
            gnss_nis.append(nis)
            if result.accepted:
                counts["gnss_updates"] += 1
                if nis > gates["gnss"]:
                    counts["gnss_deweighted"] += 1
                if rejected_run >= config.gate_release_epochs:
                    counts["gnss_released"] += 1
                rejected_run = 0
                used = 1
                _reset(kf, spec, nav, sensors)
            else:
                counts["gnss_rejected"] += 1
                rejected_run += 1
        outputs.append(_record(spec, time[k], nav, lever, corrected(rate[k], gyro_bias, gyro_scale), kf.P, sensors,
                               bool(outage[j]), used, nis, int(g.quality[j])))
        if kf.recorder is not None:
            kf.recorder.output(nav, sensors, partial(_row, spec, time[k], lever, rate[k], bool(outage[j]), used, nis,
                                                     int(g.quality[j])))
        if progress is not None and (j - j0) % 200 == 0:
            progress((j - j0) / max(1, n_epochs - j0))
    if progress is not None:
        progress(1.0)
    return Flight(np.array(outputs), windows, inputs.first_epoch, float(g.time[j0]), gnss_nis, gates["gnss"], counts,
                  list(inputs.notes), start.record(), kf.recorder, spec.estimated_sensors)


def enabled_step_sensors(table: tuple[AidingSensor, ...], cfg, inputs: Inputs) -> list[tuple]:
    """(entry, compiled condition, stream cursor or None) of every enabled entry tried at a covariance step."""
    out = []
    for sensor in aiding_sensors.step_sensors(table):
        if not getattr(cfg, sensor.enabled):
            continue
        cursor = None
        if sensor.stream != "imu":
            log = inputs.aiding.get(sensor.stream)
            if log is None:
                raise ModelError(f"{sensor.section} is enabled but no {sensor.stream} log was read")
            cursor = StreamCursor(log.time, log.value)
        out.append((sensor, aiding_sensors.compiled_condition(sensor), cursor))
    return out


def _aid_step(step_sensors: list[tuple], t: float, nav: np.ndarray, kf: ErrorStateFilter, spec: NavigatorSpec,
              sensors: dict[str, np.ndarray], cfg, gates: dict, deweight: bool, counts: dict[str, int], env: dict,
              rate_body: np.ndarray) -> None:
    """The aiding updates at the end of a covariance step at time t: each enabled entry in table order.

    A log stream's latest sample at or before t not taken yet is taken (whether or not it is then used); an
    entry whose group already had an entry whose condition held is skipped; otherwise its condition
    (evaluated on ``env``: speed, still, rate_norm and cfg at the step's start, and ``fresh``) decides.
    """
    tried: set[str] = set()
    for sensor, condition, cursor in step_sensors:
        fresh, measured = cursor.take(t) if cursor is not None else (True, 0.0)
        if sensor.group and sensor.group in tried:
            continue
        if not eval(condition, {"__builtins__": {}}, {**env, "fresh": fresh}):  # noqa: S307 - the table's own
            continue
        if sensor.group:
            tried.add(sensor.group)
        c_bn = quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3])
        z, H = aiding_sensors.rows(sensor, spec, nav, c_bn, rate_body, measured, cfg)
        r = np.square(aiding_sensors.sigmas(sensor, cfg))
        if kf.update(z, H, r, gates[sensor.dof], deweight, sensor.name, t).accepted:
            counts[sensor.counter] += 1
            _reset(kf, spec, nav, sensors)


def _remember(history: np.ndarray, t: float, nav: np.ndarray) -> None:
    """Shift the INS velocity history by one column and store (t, v) last (oldest first)."""
    history[:, :-1] = history[:, 1:]
    history[0, -1] = t
    history[1:, -1] = nav[4:7]


def _reset(kf: ErrorStateFilter, spec: NavigatorSpec, nav: np.ndarray, sensors: dict[str, np.ndarray]) -> None:
    """Feed the estimate back and zero the error state (closed loop)."""
    if kf.recorder is not None:
        kf.recorder.corrected(kf.x, kf.P)
    spec.feedback(nav, kf.x, sensors, radii, rotate)
    kf.x = np.zeros_like(kf.x)


def _apply_correction(spec: NavigatorSpec, nav: np.ndarray, sensors: dict[str, np.ndarray], dx: np.ndarray) -> None:
    """The closed-loop feedback of a correction dx into a nominal state (the smoother applies its own with it)."""
    spec.feedback(nav, dx, sensors, radii, rotate)


def _row(spec: NavigatorSpec, t: float, lever: np.ndarray, raw_rate: np.ndarray, outage: bool, used: int, nis: float,
         quality: int, nav: np.ndarray, sensors: dict[str, np.ndarray], P: np.ndarray) -> list[float]:
    """An output row of a (smoothed) nominal state: :func:`_record` with its sensor estimates."""
    rate = corrected(raw_rate, sensors["gyro_bias"], sensors["gyro_scale_factor"])
    return _record(spec, t, nav, lever, rate, P, sensors, outage, used, nis, quality)


def _record(spec: NavigatorSpec, t: float, nav: np.ndarray, lever: np.ndarray, rate: np.ndarray, P: np.ndarray,
            sensors: dict[str, np.ndarray], outage: bool, used: int, nis: float, quality: int) -> list[float]:
    """One output row (OUTPUT_FIELDS): antenna position, velocity, attitude, 1-sigma position, sensor estimates."""
    lat, lon, h, v = antenna(nav, lever, rate, spec.ecef)
    c_bn = ecef.local_view(nav)[4] if spec.ecef else quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3])
    roll, pitch, yaw = dcm_to_euler(c_bn)
    # cross covariances [m^2] (north-east, east-up, up-north): the 2x2 horizontal covariance with sn, se
    sn, se, su, cne, ceu, cun = spec.position_output(P, nav, radii)
    return [t, lat, lon, h, v[0], v[1], v[2], roll, pitch, yaw, sn, se, su, *sensors["gyro_bias"], *sensors["accel_bias"],
            float(outage), float(used), nis, float(quality), cne, ceu, cun, *sensors["gyro_scale_factor"],
            *sensors["accel_scale_factor"]]


