"""The initial alignment: a rest window found by the IMU's own zero-velocity detector, heading from the GNSS course.

Rules (the Python reference; the generated C navigator does the same itself,
templates/navigator_source.c.j2 ``rest_keep``/``rest_epoch``/``align``, from
its per-sample and per-epoch calls):

* No GNSS epoch inside a (simulated) outage is used for anything: neither as
  a rest epoch nor as the heading epoch.
* The **still detector** (``alignment.still_window_s``, ``gyro_std_max_deg_s``,
  ``accel_std_max_m_s2``): an IMU sample is still when, over the window of that
  many seconds ending at it, the RMS deviation of the angular-rate vector from
  its window mean and that of the specific-force vector from its window mean
  are both below their limits.  Deviations from the window mean do not depend
  on the (unknown) sensor biases.
* A **rest candidate** is a used GNSS epoch slower than ``rest_speed_m_s``
  whose last IMU sample at or before it is still.  Its window is the IMU
  samples of the ``rest_window_s`` seconds up to the epoch, cut after the
  last sample in it the detector calls moving (the motion is then reported:
  the window was shortened).  A candidate with fewer than
  ``rest_min_s`` seconds or 10 samples of still data does not replace an
  earlier one.
* The **heading epoch** is the first used GNSS epoch at least
  ``heading_speed_m_s`` fast (horizontal) with a used quality; the alignment
  takes roll, pitch, gyro bias and the accelerometer bias along gravity from
  the latest candidate before it, the heading from its course.

Every way this can fail has its own message (:func:`no_heading_error`,
:func:`no_rest_error`): the IMU log ends before the first fast GNSS epoch,
the log ends with the vehicle still at rest (no used epoch even as fast as
``rest_speed_m_s``), the fast epochs are all in outages or of unused
quality, the vehicle moves but never as fast as ``heading_speed_m_s``, no
rest epoch, the IMU moving at every rest epoch.  A log without any GNSS fix
is refused before the alignment (:func:`modelgen.navigator.logs.checks.check_gnss_fixes`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from modelgen.errors import ModelError
from modelgen.navigator.config import NavigatorConfig, key_place
from modelgen.navigator.mechanization import (NAV_SIZE, dcm_to_quaternion, euler_to_dcm, gravity,
                                              level_from_accelerometers, radii)
from modelgen.navigator.outages import in_outage, outage_windows

#: The prepared log (modelgen.navigator.navigator.Inputs: time, IMU samples, GNSS epochs).  Named, not
#: imported: navigator.py calls align(), so an import back would be a cycle (tests/test_architecture.py).
Inputs = Any

MIN_REST_SAMPLES = 10


@dataclass
class Alignment:
    """The initial alignment (:func:`align`): where the flight starts and with what."""

    epoch: int  # GNSS epoch it completed at (index into Inputs.gnss)
    sample: int  # IMU sample the flight starts at (first at or after that epoch)
    nav: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    roll: float
    pitch: float
    heading: float
    time: float  # the epoch's time [s]
    rest_end: float  # end of the rest window: the rest candidate's GNSS epoch [s]
    rest_samples: int  # IMU samples in the rest window
    rest_start: float = math.nan  # time of the rest window's first IMU sample [s]
    motion_time: float = math.nan  # the last sample the detector called moving inside the configured window, or NaN

    def record(self) -> dict[str, float]:
        """The values Flight.alignment holds (the C navigator reports the same)."""
        return {"time": self.time, "roll": self.roll, "pitch": self.pitch, "heading": self.heading,
                "rest_end": self.rest_end, "rest_samples": float(self.rest_samples), "rest_start": self.rest_start,
                "motion_time": self.motion_time}


def detector_samples(window_s: float, time: np.ndarray) -> int:
    """A detector window of ``window_s`` seconds in samples at the log's median rate (at least 2)."""
    from modelgen.navigator.cconfig_fields import WINDOW_SAMPLES_MIN

    return max(WINDOW_SAMPLES_MIN, int(round(window_s / float(np.median(np.diff(time))))))


def still_window_samples(config: NavigatorConfig, time: np.ndarray) -> int:
    """The still detector's window in samples at the log's median rate (at least 2)."""
    return detector_samples(config.still_window, time)


def refuse_window_longer_than_log(config: NavigatorConfig, time: np.ndarray, key: str, window_s: float,
                                  detector: str, consequence: str) -> None:
    """Refuse a detector window longer than the whole IMU log, naming the line of its key ``key``.

    No sample of such a log can be called still: said as what the configuration asks, not left to a later
    diagnosis (which names no configuration line), to the C's bound on its buffer (which a window between the
    log's length and the buffer's power-of-two size passes), or to a flight that silently never uses it."""
    size = detector_samples(window_s, time)
    if size > len(time):
        raise ModelError(f"{key_place(config.path, key)}: {key}: the {detector}'s window of {window_s:g} s "
                         f"is {size} IMU samples, more than the whole IMU log has ({len(time)} samples, "
                         f"{float(time[-1] - time[0]):.3g} s): {consequence}; give a window shorter than the log")


def check_still_window(config: NavigatorConfig, time: np.ndarray) -> None:
    """Refuse a still detector window longer than the whole IMU log (the IMU could not be levelled at rest)."""
    refuse_window_longer_than_log(config, time, "alignment.still_window_s", config.still_window, "still detector",
                                  "no sample could be called still, so the IMU could not be levelled at rest")


def check_zupt_window(config: NavigatorConfig, time: np.ndarray) -> None:
    """Refuse an enabled ZUPT whose detector window is longer than the whole IMU log (no ZUPT would be made)."""
    if config.zupt_enabled:
        refuse_window_longer_than_log(config, time, "zupt.window_s", config.zupt_window, "zero-velocity detector",
                                      "it could never call the IMU still, so no ZUPT would be made (or give "
                                      "zupt.enabled: false)")


def still_samples(force: np.ndarray, rate: np.ndarray, size: int, gyro_std_max: float,
                  accel_std_max: float) -> np.ndarray:
    """Per sample: the window of ``size`` samples ending there is still (RMS deviations from the window means)."""
    still = np.zeros(len(force), dtype=bool)
    if len(force) < size:
        return still

    def rms_deviation(x: np.ndarray) -> np.ndarray:
        windows = np.lib.stride_tricks.sliding_window_view(x, size, axis=0)  # (m, 3, size)
        mean = windows.sum(axis=2, keepdims=True) / size
        return np.sqrt(((windows - mean) ** 2).sum(axis=(1, 2)) / size)

    still[size - 1:] = (rms_deviation(rate) < gyro_std_max) & (rms_deviation(force) < accel_std_max)
    return still


def used_epochs(config: NavigatorConfig, inputs: Inputs, outage: np.ndarray | None = None) -> np.ndarray:
    """Per GNSS epoch: outside every outage (an outage epoch is used for nothing, the alignment included)."""
    g = inputs.gnss
    if outage is None:
        windows = outage_windows(config.outage_schedule, config.outage_windows, inputs.first_epoch, float(g.time[-1]))
        outage = in_outage(g.time, windows)
    return ~outage


def align(config: NavigatorConfig, inputs: Inputs, outage: np.ndarray | None = None) -> Alignment:
    """The start: GNSS epoch and IMU sample, the initial navigation state, gyro and accelerometer bias."""
    g = inputs.gnss
    use = used_epochs(config, inputs, outage)
    speed = np.hypot(g.velocity[:, 0], g.velocity[:, 1])
    usable = np.array([config.quality_factor.get(int(q)) is not None for q in g.quality])
    moving = np.nonzero((speed >= config.heading_speed) & usable & use)[0]
    if len(moving) == 0:
        raise no_heading_error(config, inputs, use)
    j = int(moving[0])
    k = int(np.searchsorted(inputs.time, g.time[j]))
    time = inputs.time[: k + 1]
    size = still_window_samples(config, inputs.time)
    still = still_samples(inputs.force[: k + 1], inputs.rate[: k + 1], size, config.still_gyro_std_max,
                          config.still_accel_std_max)
    candidate = None
    for e in np.nonzero(use[:j] & (speed[:j] < config.rest_speed))[0]:
        b = int(np.searchsorted(time, g.time[e], side="right")) - 1  # last sample at or before the epoch
        if b < 0 or not still[b]:
            continue
        a = int(np.searchsorted(time, g.time[e] - config.rest_window, side="left"))
        motion = np.nonzero(~still[a:b + 1])[0]
        motion_time = math.nan
        if len(motion):
            motion_time = float(time[a + motion[-1]])
            a += int(motion[-1]) + 1
        if b - a + 1 < MIN_REST_SAMPLES or time[b] - time[a] < config.rest_span_min:
            continue
        candidate = (int(e), a, b, motion_time)
    if candidate is None:
        raise no_rest_error(config, inputs, use, j, still)
    e, a, b, motion_time = candidate
    samples = slice(a, b + 1)
    mean_force = inputs.force[samples].mean(axis=0)
    roll, pitch = level_from_accelerometers(mean_force)
    yaw = math.atan2(g.velocity[j, 1], g.velocity[j, 0])
    gyro_bias = inputs.rate[samples].mean(axis=0)
    # At rest the specific force's magnitude is normal gravity: the excess is an
    # accelerometer bias along the measured direction (the part across it is
    # indistinguishable from tilt and is left to the filter).
    norm = float(np.linalg.norm(mean_force))
    accel_bias = (norm - gravity(g.latitude[j], g.height[j])) * mean_force / norm
    c = euler_to_dcm(roll, pitch, yaw)
    nav = np.zeros(NAV_SIZE)
    nav[0:4] = dcm_to_quaternion(c)
    nav[4:7] = g.velocity[j]
    rm, rn = radii(g.latitude[j])
    offset = c @ np.asarray(config.lever_arm)
    nav[7] = g.latitude[j] - offset[0] / (rm + g.height[j])
    nav[8] = g.longitude[j] - offset[1] / ((rn + g.height[j]) * math.cos(g.latitude[j]))
    nav[9] = g.height[j] + offset[2]
    return Alignment(j, k, nav, gyro_bias, accel_bias, roll, pitch, yaw, float(g.time[j]), float(g.time[e]),
                     b - a + 1, float(inputs.time[a]), motion_time)


def alignment_note(config: NavigatorConfig, record: dict[str, float], first_epoch: float) -> str | None:
    """The warning when the IMU saw motion inside the configured rest window (the window was shortened)."""
    motion = record.get("motion_time", math.nan)
    if motion is None or not math.isfinite(motion):
        return None
    still = record["rest_end"] - record["rest_start"]
    return (f"alignment: the IMU's still detector saw motion at {motion - first_epoch:.2f} s, "
            f"{record['rest_end'] - motion:.2f} s before the end of the rest window "
            f"({record['rest_end'] - first_epoch:.2f} s): levelled from the {still:.2f} s "
            f"({int(record['rest_samples'])} samples) still after it instead of alignment.rest_window_s = "
            f"{config.rest_window:g} s")


def no_heading_error(config: NavigatorConfig, inputs: Inputs, use: np.ndarray) -> ModelError:
    """Why no epoch can give the heading: log ends first, fast epochs only in outages or of unused quality, no motion."""
    g = inputs.gnss
    speed = np.hypot(g.velocity[:, 0], g.velocity[:, 1])
    usable = np.array([config.quality_factor.get(int(q)) is not None for q in g.quality])
    fast = speed >= config.heading_speed
    where = f"{g.path}: no alignment"
    source = inputs.source_gnss
    if source is not None and source.velocity is not None:
        later = (source.time > inputs.time[-1]) & (np.hypot(source.velocity[:, 0], source.velocity[:, 1])
                                                    >= config.heading_speed)
        if later.any() and not (fast & usable & use).any():
            return ModelError(f"{where}: the IMU log ends at {inputs.time[-1] - inputs.first_epoch:.2f} s (after the "
                              "first GNSS epoch), before the first GNSS epoch faster than alignment.heading_speed_m_s "
                              f"= {config.heading_speed:g} m/s "
                              f"({source.time[np.argmax(later)] - inputs.first_epoch:.2f} s): the log ends before "
                              "the alignment")
    if (fast & usable).any():
        return ModelError(f"{where}: every GNSS epoch faster than alignment.heading_speed_m_s = "
                          f"{config.heading_speed:g} m/s lies inside a simulated outage ({int((fast & usable).sum())} "
                          "epochs); an epoch inside an outage is used for nothing, the alignment included")
    if fast.any():
        return ModelError(f"{where}: the GNSS epochs faster than alignment.heading_speed_m_s = {config.heading_speed:g} "
                          f"m/s ({int(fast.sum())}) all have a quality gnss.quality_factor does not use")
    fastest = int(np.argmax(np.where(use, speed, -1.0)))
    if speed[fastest] < config.rest_speed:
        end = min(float(g.time[-1]), float(inputs.time[-1]))
        return ModelError(f"{where}: the log ends at {end - inputs.first_epoch:.2f} s with the vehicle still at rest "
                          f"(every used GNSS epoch slower than alignment.rest_speed_m_s = {config.rest_speed:g} m/s; "
                          f"fastest {speed[fastest]:.2f} m/s): it ends before the alignment, whose heading needs a "
                          f"GNSS epoch faster than alignment.heading_speed_m_s = {config.heading_speed:g} m/s")
    return ModelError(f"{where}: the vehicle never moves faster than alignment.heading_speed_m_s = "
                      f"{config.heading_speed:g} m/s in the log (fastest used GNSS epoch {speed[fastest]:.2f} m/s at "
                      f"{g.time[fastest] - inputs.first_epoch:.2f} s): no heading for the alignment")


def no_rest_error(config: NavigatorConfig, inputs: Inputs, use: np.ndarray, j: int, still: np.ndarray) -> ModelError:
    """Why no rest window before the heading epoch j: no slow epoch, or the IMU moving at (or just before) each."""
    g = inputs.gnss
    speed = np.hypot(g.velocity[:, 0], g.velocity[:, 1])
    at = f"{g.path}: no alignment: before the heading epoch at {g.time[j] - inputs.first_epoch:.2f} s"
    slow = np.nonzero(use[:j] & (speed[:j] < config.rest_speed))[0]
    if len(slow) == 0:
        return ModelError(f"{at} no used GNSS epoch is at rest (slower than alignment.rest_speed_m_s = "
                          f"{config.rest_speed:g} m/s): the IMU cannot be levelled")
    return ModelError(f"{at} no GNSS epoch at rest ({len(slow)} slower than {config.rest_speed:g} m/s) has "
                      f"{config.rest_span_min:g} s (alignment.rest_min_s, at most rest_window_s) of IMU samples the still detector calls still "
                      f"before it ({100 * float(np.mean(still)):.0f} % of the samples are still; detector: "
                      f"alignment.still_window_s {config.still_window:g} s, gyro_std_max_deg_s "
                      f"{math.degrees(config.still_gyro_std_max):g}, accel_std_max_m_s2 {config.still_accel_std_max:g}): "
                      "the IMU cannot be levelled at rest")
