"""Readers for the recorded logs: an IMU CSV (plain or gzip) and an RTKLIB .pos solution.

Both readers treat the files as untrusted data.  What they refuse, they refuse
with ``file:line: reason`` (:class:`~modelgen.errors.ModelError`); what they
handle, they handle as documented here and count in the returned log's
``notes`` so that the report can say it:

IMU CSV
  * a row with the wrong number of columns, or a used column that is not a
    number, is refused (file:line);
  * a row with a NaN or infinite value in a used column is dropped and counted
    (the gap it leaves is then bridged like any dropped sample);
  * a time stamp that is not strictly after the previous kept one (duplicated
    or going backwards) is refused (file:line): which of the two is right
    cannot be known;
  * a gap longer than ``gap_factor`` times the median sample interval is
    reported (time and length) and bridged with the actual dt by the
    mechanization;
  * a file with no data rows is refused.

RTKLIB .pos
  * lines starting with ``%`` are header lines; the solution must be in the
    ``GPST date time, latitude, longitude, height`` form (RTKLIB's default
    "lat/lon/height" output with calendar time); anything else is refused;
  * a data row with fewer than 15 columns or a non-numeric field is refused
    (file:line); a row with 24 or more columns carries velocities (vn, ve, vu
    and their standard deviations), which are then used;
  * non-monotonic or duplicated epochs are refused (file:line);
  * an empty or header-only file is refused.
"""

from __future__ import annotations

import calendar
import gzip
import math
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from modelgen.errors import ModelError

GZIP_MAGIC = b"\x1f\x8b"
STANDARD_GRAVITY = 9.80665  # [m/s^2], the "g" of accelerometer data sheets

# Units the IMU columns may be given in, as a factor to SI.
ACCEL_UNITS = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}
GYRO_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0}


@dataclass(frozen=True)
class ImuColumns:
    """Where the IMU quantities are in a CSV row (1-based columns) and in which units."""

    count: int  # number of columns every row must have
    time: int  # time stamp [s]
    accel: tuple[int, int, int]  # specific force x, y, z
    gyro: tuple[int, int, int]  # angular rate x, y, z
    accel_unit: str = "g"
    gyro_unit: str = "rad/s"


@dataclass
class ImuLog:
    """IMU samples in the IMU's own axes, SI units; ``time`` strictly increasing."""

    path: str
    time: np.ndarray  # [s]
    specific_force: np.ndarray  # (n, 3) [m/s^2]
    angular_rate: np.ndarray  # (n, 3) [rad/s]
    gaps: list[tuple[float, float]] = field(default_factory=list)  # (time before the gap, gap length) [s]
    notes: list[str] = field(default_factory=list)


@dataclass
class GnssLog:
    """GNSS solution epochs; angles in radians, velocities NED [m/s]."""

    path: str
    time: np.ndarray  # [s], same scale as the IMU time
    latitude: np.ndarray  # [rad]
    longitude: np.ndarray  # [rad]
    height: np.ndarray  # [m]
    quality: np.ndarray  # RTKLIB Q: 1 fixed, 2 float, 4 DGPS, 5 single, ...
    satellites: np.ndarray
    sigma_position: np.ndarray  # (n, 3) sdn, sde, sdu [m]
    velocity: np.ndarray | None  # (n, 3) vn, ve, vd [m/s] (RTKLIB gives up; stored down)
    sigma_velocity: np.ndarray | None  # (n, 3) sdvn, sdve, sdvu [m/s]
    notes: list[str] = field(default_factory=list)


def _read_text(path: Path) -> str:
    """The file's text, gunzipped if it starts with the gzip magic bytes; refuse unreadable files."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ModelError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if raw[:2] == GZIP_MAGIC:
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as exc:
            raise ModelError(f"{path}: is not a valid gzip file ({exc})") from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ModelError(f"{path}: is not UTF-8 text (byte {exc.start})") from None


def _number(text: str, where: str, what: str) -> float:
    """A float from a field, or a ModelError naming the place and the field."""
    try:
        return float(text)
    except ValueError:
        raise ModelError(f"{where}: {what} {text.strip()[:40]!r} is not a number") from None


def read_imu_csv(path: str | Path, columns: ImuColumns, gap_factor: float = 3.0) -> ImuLog:
    """Read an IMU CSV log (see the module docstring for what is refused and what is handled)."""
    path = Path(path)
    if columns.accel_unit not in ACCEL_UNITS:
        raise ModelError(f"{path}: accelerometer unit {columns.accel_unit!r} unknown (use {', '.join(ACCEL_UNITS)})")
    if columns.gyro_unit not in GYRO_UNITS:
        raise ModelError(f"{path}: gyro unit {columns.gyro_unit!r} unknown (use {', '.join(GYRO_UNITS)})")
    used = (columns.time, *columns.accel, *columns.gyro)
    if min(used) < 1 or max(used) > columns.count:
        raise ModelError(f"{path}: column map {used} outside 1..{columns.count}")
    rows: list[list[float]] = []
    dropped: list[int] = []
    previous_time = -math.inf
    previous_line = 0
    for number, line in enumerate(_read_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        fields = line.split(",")
        where = f"{path}:{number}"
        if len(fields) != columns.count:
            raise ModelError(f"{where}: {len(fields)} columns, expected {columns.count}")
        values = [_number(fields[c - 1], where, f"column {c}") for c in used]
        if not all(math.isfinite(v) for v in values):
            dropped.append(number)
            continue
        if values[0] <= previous_time:
            kind = "duplicated" if values[0] == previous_time else "goes back in"
            raise ModelError(f"{where}: time stamp {values[0]!r} {kind} time "
                             f"(line {previous_line} has {previous_time!r})")
        previous_time, previous_line = values[0], number
        rows.append(values)
    if not rows:
        raise ModelError(f"{path}: no IMU samples")
    data = np.array(rows)
    log = ImuLog(str(path), data[:, 0], data[:, 1:4] * ACCEL_UNITS[columns.accel_unit],
                 data[:, 4:7] * GYRO_UNITS[columns.gyro_unit])
    if dropped:
        shown = ", ".join(map(str, dropped[:5])) + (" ..." if len(dropped) > 5 else "")
        log.notes.append(f"{path}: {len(dropped)} row(s) with NaN/infinite values dropped (lines {shown})")
    log.gaps = find_gaps(log.time, gap_factor)
    for start, length in log.gaps[:5]:
        log.notes.append(f"{path}: IMU gap of {length:.3f} s after t = {start:.3f} s, bridged with the actual dt")
    if len(log.gaps) > 5:
        log.notes.append(f"{path}: {len(log.gaps) - 5} more IMU gap(s)")
    return log


def find_gaps(time: np.ndarray, factor: float) -> list[tuple[float, float]]:
    """(start, length) of every interval longer than ``factor`` times the median interval."""
    if len(time) < 3:
        return []
    dt = np.diff(time)
    limit = factor * float(np.median(dt))
    return [(float(time[i]), float(dt[i])) for i in np.nonzero(dt > limit)[0]]


def _gpst_seconds(date: str, clock: str, where: str) -> float:
    """'YYYY/MM/DD' 'hh:mm:ss.sss' (GPST calendar) as seconds since 1970-01-01 on the same scale."""
    try:
        year, month, day = (int(x) for x in date.split("/"))
        hour, minute, second = clock.split(":")
        seconds = float(second)
        stamp = calendar.timegm((year, month, day, int(hour), int(minute), 0, 0, 0, 0))
    except (ValueError, OverflowError):
        raise ModelError(f"{where}: time {date} {clock!r} is not 'YYYY/MM/DD hh:mm:ss.sss'") from None
    if not (1 <= month <= 12 and 1 <= day <= 31 and 0 <= int(hour) < 24 and 0 <= int(minute) < 60
            and 0.0 <= seconds < 61.0):
        raise ModelError(f"{where}: time {date} {clock} out of range")
    return stamp + seconds


def read_rtklib_pos(path: str | Path) -> GnssLog:
    """Read an RTKLIB .pos solution in lat/lon/height form (see the module docstring)."""
    path = Path(path)
    rows: list[list[float]] = []
    has_velocity = True
    previous_time = -math.inf
    previous_line = 0
    for number, line in enumerate(_read_text(path).splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("%"):
            continue
        where = f"{path}:{number}"
        fields = stripped.split()
        if len(fields) < 15:
            raise ModelError(f"{where}: {len(fields)} columns; an RTKLIB lat/lon/height solution row has at "
                             "least 15 (date, time, lat, lon, height, Q, ns, sdn, sde, sdu, sdne, sdeu, sdun, age, ratio)")
        if "/" not in fields[0] or ":" not in fields[1]:
            raise ModelError(f"{where}: expected GPST 'YYYY/MM/DD hh:mm:ss.sss' time, got {fields[0]!r} {fields[1]!r} "
                             "(only RTKLIB's calendar-time lat/lon/height output is read)")
        t = _gpst_seconds(fields[0], fields[1], where)
        values = [t] + [_number(f, where, f"column {k + 3}") for k, f in enumerate(fields[2:24])]
        if not all(math.isfinite(v) for v in values):
            raise ModelError(f"{where}: non-finite value in a solution row")
        if len(fields) < 24:
            has_velocity = False
        if t <= previous_time:
            kind = "duplicated" if t == previous_time else "goes back in"
            raise ModelError(f"{where}: epoch {fields[0]} {fields[1]} {kind} time (line {previous_line} is later or equal)")
        previous_time, previous_line = t, number
        if not (-90.0 <= values[1] <= 90.0 and -180.0 <= values[2] <= 360.0):
            raise ModelError(f"{where}: latitude/longitude {values[1]}, {values[2]} out of range")
        rows.append(values)
    if not rows:
        raise ModelError(f"{path}: no solution epochs (empty or header-only .pos file)")
    width = min(len(r) for r in rows)
    data = np.array([r[:width] for r in rows])
    velocity = sigma_velocity = None
    if has_velocity and width >= 23:
        velocity = data[:, 14:17] * np.array([1.0, 1.0, -1.0])
        sigma_velocity = data[:, 17:20]
    sigma = data[:, 6:9]
    if np.any(sigma < 0):
        bad = int(np.nonzero(np.any(sigma < 0, axis=1))[0][0])
        raise ModelError(f"{path}: epoch {bad + 1}: negative standard deviation")
    return GnssLog(str(path), data[:, 0], np.radians(data[:, 1]), np.radians(data[:, 2]), data[:, 3],
                   data[:, 4].astype(int), data[:, 5].astype(int), sigma, velocity, sigma_velocity)
