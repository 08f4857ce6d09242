"""IMU CSV (plain or gzip): one sample a line, columns and units from the configuration.

The file is untrusted data.  What the reader refuses, it refuses with
``file:line: reason``; what it handles, it counts in the log's ``notes``:

* a row with the wrong number of columns, or a used column that is not a
  number, is refused (file:line);
* a row with a NaN or infinite value in a used column is dropped and counted
  (the interval it leaves then counts towards the gap check like any other);
* a time stamp that is not strictly after the previous kept one (duplicated or
  going backwards) is refused (file:line): which of the two is right cannot be
  known;
* a file with no data rows is refused; a file beyond the size limit, or a
  gzip stream that would expand beyond it, is refused
  (:mod:`modelgen.navigator.logs.files`).

Time is seconds in ``time_system`` (GPST by default: GPS time as seconds since
1970 on the GPS calendar, the scale of RTKLIB's GPST output); a UTC or JST
column is put on GPS time with the leap seconds of its date.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from modelgen.errors import ModelError
from modelgen.navigator.logs.checks import apply_gap_policy
from modelgen.navigator.logs.files import read_text
from modelgen.navigator.logs.formats import LogFormat, LogSource, Option
from modelgen.navigator.logs.gps_time import JST_MINUS_UTC_S, NS, TIME_SYSTEMS, gps_minus_utc
from modelgen.navigator.logs.records import ACCEL_UNITS, GYRO_UNITS, ImuLog


@dataclass(frozen=True)
class ImuColumns:
    """Where the IMU quantities are in a CSV row (1-based columns) and in which units."""

    count: int  # number of columns every row must have
    time: int  # time stamp [s]
    accel: tuple[int, int, int]  # specific force x, y, z
    gyro: tuple[int, int, int]  # angular rate x, y, z
    accel_unit: str = "g"
    gyro_unit: str = "rad/s"


def _number(text: str, where: str, what: str) -> float:
    """A float from a field, or a ModelError naming the place and the field."""
    try:
        return float(text)
    except ValueError:
        raise ModelError(f"{where}: {what} {text.strip()[:40]!r} is not a number") from None


def read_imu_csv(path: str | Path, columns: ImuColumns, gap_factor: float | None = None, gap_action: str = "refuse",
                 time_system: str = "GPST") -> ImuLog:
    """Read an IMU CSV log (see the module docstring for what is refused and what is handled).

    With ``gap_factor`` the gap policy (:func:`~modelgen.navigator.logs.checks.apply_gap_policy`)
    is applied here; :func:`modelgen.navigator.logs.read_imu` applies it to every format alike.
    """
    path = Path(path)
    if columns.accel_unit not in ACCEL_UNITS:
        raise ModelError(f"{path}: accelerometer unit {columns.accel_unit!r} unknown (use {', '.join(ACCEL_UNITS)})")
    if columns.gyro_unit not in GYRO_UNITS:
        raise ModelError(f"{path}: gyro unit {columns.gyro_unit!r} unknown (use {', '.join(GYRO_UNITS)})")
    used = (columns.time, *columns.accel, *columns.gyro)
    if min(used) < 1 or max(used) > columns.count:
        raise ModelError(f"{path}: column map {used} outside 1..{columns.count}")
    rows: list[list[float]] = []
    lines: list[int] = []
    dropped: list[int] = []
    previous_time = -math.inf
    previous_line = 0
    for number, line in enumerate(read_text(path).splitlines(), start=1):
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
        lines.append(number)
    if not rows:
        raise ModelError(f"{path}: no IMU samples")
    data = np.array(rows)
    time = _on_gps_time(data[:, 0], time_system, str(path))
    log = ImuLog(str(path), time, data[:, 1:4] * ACCEL_UNITS[columns.accel_unit],
                 data[:, 4:7] * GYRO_UNITS[columns.gyro_unit], records=np.array(lines))
    if dropped:
        shown = ", ".join(map(str, dropped[:5])) + (" ..." if len(dropped) > 5 else "")
        log.notes.append(f"{path}: {len(dropped)} row(s) with NaN/infinite values dropped (lines {shown})")
    return log if gap_factor is None else apply_gap_policy(log, gap_factor, gap_action)


def _on_gps_time(time: np.ndarray, system: str, where: str) -> np.ndarray:
    """CSV seconds in ``system`` onto GPS time (the leap seconds of each sample's date)."""
    if system == "GPST":
        return time
    if system not in TIME_SYSTEMS:
        raise ModelError(f"{where}: time system {system!r} is not one of {', '.join(TIME_SYSTEMS)}")
    utc = time - (JST_MINUS_UTC_S if system == "JST" else 0)
    return utc + gps_minus_utc((utc * NS).astype(np.int64))


def columns_of(source: LogSource) -> ImuColumns:
    """The column map and units of a csv source's validated options."""
    o = source.options
    columns = ImuColumns(o["columns.count"], o["columns.time"], o["columns.accel"], o["columns.gyro"],
                         o["units.accel"], o["units.gyro"])
    used = (columns.time, *columns.accel, *columns.gyro)
    if columns.count < 7 or min(used) < 1 or max(used) > columns.count:
        raise ModelError(f"{source.where('imu.columns')}: column numbers must be within 1..{columns.count} "
                         "(and count at least 7)")
    return columns


def _read(source: LogSource) -> ImuLog:
    return read_imu_csv(source.path, columns_of(source), time_system=source.options["time_system"])


FORMAT = LogFormat(
    name="csv",
    summary="IMU samples as comma-separated text, one sample a line (plain or gzip)",
    imu_options=(
        Option("units.accel", "choice", choices=tuple(ACCEL_UNITS), doc="unit of the specific force",
               what="accelerometer unit"),
        Option("units.gyro", "choice", choices=tuple(GYRO_UNITS), doc="unit of the angular rate", what="gyro unit"),
        Option("columns.count", "integer", doc="number of columns every row has"),
        Option("columns.time", "integer", doc="column of the time stamp [s] (1-based)"),
        Option("columns.accel", "columns3", doc="columns of the specific force x, y, z"),
        Option("columns.gyro", "columns3", doc="columns of the angular rate x, y, z"),
        Option("time_system", "choice", "GPST", TIME_SYSTEMS,
               doc="time scale of the time column: seconds since 1970 in GPST (default), UTC or JST"),
    ),
    read_imu=_read,
)
