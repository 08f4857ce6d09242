"""What every log reader returns: IMU samples and GNSS epochs in SI units on one time scale.

Whatever the format (CSV, RTKLIB .pos, PX4 ULog, ROS 2 bag), a reader hands
the navigator an :class:`ImuLog` and a :class:`GnssLog` with these
conventions, so that the navigator never knows where its data came from:

* time: seconds, float64, strictly increasing.  Normally GPS time written as
  seconds since 1970-01-01 on the GPS calendar (``calendar.timegm`` of the GPST
  date and time, no leap seconds inside), the scale of RTKLIB's GPST output;
  a format converts UTC (or JST) stamps onto it with the leap-second table
  (:mod:`modelgen.navigator.logs.gps_time`).  A ULog without GNSS time keeps
  its boot time (``time_scale`` says which).
* IMU: specific force [m/s^2] and angular rate [rad/s] in the IMU's own axes
  (the configuration's ``rotation_to_body_deg`` takes them to body axes).
* GNSS: geodetic WGS-84 latitude and longitude [rad], height [m] as the log
  gives it, velocity north/east/down [m/s], 1-sigma of north/east/up position
  [m] and of north/east/up velocity [m/s]; ``quality`` in RTKLIB's Q codes
  (1 fixed, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP), to which every format
  maps its own fix status (docs/log-formats.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

STANDARD_GRAVITY = 9.80665  # [m/s^2], the "g" of accelerometer data sheets

# Units the IMU CSV columns may be given in, as a factor to SI.
ACCEL_UNITS = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}
GYRO_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0}

#: RTKLIB solution quality codes (the Q column of a .pos file).
QUALITY_NAMES = {1: "fixed", 2: "float", 3: "SBAS", 4: "DGPS", 5: "single", 6: "PPP"}


class ImuGap(NamedTuple):
    """An IMU interval longer than the configured gap factor times the median interval.

    ``start`` is the time of the last sample before the gap and ``length`` the
    interval to the first sample after it, both on the IMU log's own time scale
    (before the configuration's ``time_offset_s``) [s].
    """

    start: float
    length: float

    @property
    def end(self) -> float:
        """Time of the first sample after the gap [s]."""
        return self.start + self.length


@dataclass
class ImuLog:
    """IMU samples in the IMU's own axes, SI units; ``time`` strictly increasing.

    ``gaps`` lists every interval longer than ``imu.gap_factor`` times the
    median interval.  With ``imu.gap_action: refuse`` (the default) a log with
    a gap never reaches the navigator; with ``propagate`` it does, and the gap
    list is the navigator's to honour: the covariance is propagated over the
    gap's whole length and no GNSS epoch inside a gap is applied
    (:func:`modelgen.navigator.logs.checks.epochs_inside_gaps`).

    ``records`` numbers each sample in its file (CSV line, or message number of
    the topic) so that a refusal can name where the sample is (:meth:`where`).
    """

    path: str
    time: np.ndarray  # [s]
    specific_force: np.ndarray  # (n, 3) [m/s^2]
    angular_rate: np.ndarray  # (n, 3) [rad/s]
    gaps: list[ImuGap] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    records: np.ndarray | None = None  # per sample: CSV line number, or message number (1-based)
    record_kind: str = ""  # "" for text (file:line), else what a record is, e.g. "sensor_combined message"
    time_scale: str = "GPST"  # "GPST" (see the module docstring) or "boot" (a ULog without GNSS time)

    def where(self, index: int) -> str:
        """'file:line' (text) or 'file: <record kind> N' (binary) of sample ``index``."""
        if self.records is None:
            return self.path
        number = int(self.records[index])
        return f"{self.path}:{number}" if not self.record_kind else f"{self.path}: {self.record_kind} {number}"


@dataclass
class GnssLog:
    """GNSS solution epochs; angles in radians, velocities NED [m/s]."""

    path: str
    time: np.ndarray  # [s], same scale as the IMU time
    latitude: np.ndarray  # [rad]
    longitude: np.ndarray  # [rad]
    height: np.ndarray  # [m]
    quality: np.ndarray  # RTKLIB Q: 1 fixed, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP
    satellites: np.ndarray
    sigma_position: np.ndarray  # (n, 3) sdn, sde, sdu [m]
    velocity: np.ndarray | None  # (n, 3) vn, ve, vd [m/s] (RTKLIB gives up; stored down)
    sigma_velocity: np.ndarray | None  # (n, 3) sdvn, sdve, sdvu [m/s]
    notes: list[str] = field(default_factory=list)
    time_scale: str = "GPST"


def gnss_log(path: str, rows: dict[str, np.ndarray], notes: list[str], time_scale: str = "GPST") -> GnssLog:
    """A GnssLog from named columns (the binary readers build theirs this way)."""
    velocity = rows.get("velocity")
    return GnssLog(path, rows["time"], rows["latitude"], rows["longitude"], rows["height"],
                   rows["quality"].astype(int), rows["satellites"].astype(int), rows["sigma_position"],
                   velocity, rows.get("sigma_velocity") if velocity is not None else None, notes, time_scale)
