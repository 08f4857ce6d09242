"""UTC (and JST) stamps onto GPS time, with the leap seconds of their date from a data table.

The navigator's time scale is GPS time written as seconds since 1970-01-01 on
the GPS calendar (``calendar.timegm`` of the GPST date and time).  A UTC stamp
on the same calendar is behind it by GPS - UTC, the number of leap seconds
inserted since 1980-01-06; that number comes from ``modelgen/data/leap_seconds.yaml``
(data, not code).  JST is UTC + 9 h.

Times are converted in integer nanoseconds, so that the one division to
seconds at the end rounds once: the same instant read from a .pos text, a
ULog's microseconds or a ROS stamp's nanoseconds becomes the same float.
"""

from __future__ import annotations

import calendar
import datetime
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path, read_yaml

NS = 1_000_000_000
JST_MINUS_UTC_S = 9 * 3600
#: The GPS week/time-of-week origin, 1980-01-06 00:00:00 GPST, in seconds since 1970 (GPS calendar).
GPS_EPOCH_S = calendar.timegm((1980, 1, 6, 0, 0, 0, 0, 0, 0))
TIME_SYSTEMS = ("GPST", "UTC", "JST")


@dataclass(frozen=True)
class LeapTable:
    """GPS - UTC [s] from each effective date (UTC seconds since 1970), and how far the table is known."""

    effective_s: np.ndarray  # int64, ascending
    gps_minus_utc_s: np.ndarray  # int64
    known_until_s: int  # end of the last day the table is known complete (UTC seconds since 1970)
    known_until: str


def _date_seconds(value: object, what: str) -> int:
    """Seconds since 1970 (UTC) of a YAML date or 'YYYY-MM-DD' text at 00:00."""
    if isinstance(value, str):
        value = datetime.date.fromisoformat(value)
    if not isinstance(value, datetime.date):
        raise ModelError(f"{data_path('leap_seconds.yaml')}: {what}: {value!r} is not a date")
    return calendar.timegm((value.year, value.month, value.day, 0, 0, 0, 0, 0, 0))


@lru_cache(maxsize=1)
def leap_table() -> LeapTable:
    """The shipped leap-second table (read once)."""
    data = read_yaml(data_path("leap_seconds.yaml"), "leap-second table")
    rows = sorted((_date_seconds(d, "gps_minus_utc"), int(n)) for d, n in data["gps_minus_utc"])
    known = _date_seconds(data["known_until"], "known_until") + 86400
    return LeapTable(np.array([r[0] for r in rows], dtype=np.int64), np.array([r[1] for r in rows], dtype=np.int64),
                     known, str(data["known_until"]))


def gps_minus_utc(utc_ns: np.ndarray) -> np.ndarray:
    """GPS - UTC [s] in force at each UTC instant (integer nanoseconds since 1970)."""
    table = leap_table()
    index = np.searchsorted(table.effective_s, np.asarray(utc_ns, dtype=np.int64) // NS, side="right") - 1
    return np.where(index >= 0, table.gps_minus_utc_s[np.maximum(index, 0)], 0)


def to_gpst_ns(stamps_ns: np.ndarray, system: str, where: str) -> tuple[np.ndarray, list[str]]:
    """Integer nanoseconds since 1970 in ``system`` (GPST, UTC, JST) -> GPST nanoseconds, and notes.

    Refused: a time system not in :data:`TIME_SYSTEMS`, and UTC before the GPS
    epoch (no GPS time existed).  Noted: stamps after the table's known_until
    (converted with its last value).
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    if system == "GPST":
        return stamps, []
    if system not in TIME_SYSTEMS:
        raise ModelError(f"{where}: time system {system!r} is not one of {', '.join(TIME_SYSTEMS)}")
    utc = stamps - JST_MINUS_UTC_S * NS if system == "JST" else stamps
    notes = []
    if len(utc) and int(utc.min()) // NS < GPS_EPOCH_S:
        raise ModelError(f"{where}: {system} time {_calendar(int(utc.min()))} is before the GPS epoch 1980-01-06: "
                         "it cannot be put on GPS time")
    table = leap_table()
    if len(utc) and int(utc.max()) // NS >= table.known_until_s:
        notes.append(f"{where}: {system} times after {table.known_until} (the end of modelgen's leap-second table) "
                     f"converted to GPS time with GPS - UTC = {int(table.gps_minus_utc_s[-1])} s; a leap second "
                     "announced later would be missing")
    return utc + gps_minus_utc(utc) * NS, notes


def seconds(ns: np.ndarray) -> np.ndarray:
    """Integer nanoseconds -> float seconds, correctly rounded (Python's integer division, one rounding)."""
    return np.array([n / NS for n in np.asarray(ns, dtype=np.int64).tolist()], dtype=float)


def _calendar(ns: int) -> str:
    return datetime.datetime.fromtimestamp(ns // NS, datetime.timezone.utc).strftime("%Y/%m/%d %H:%M:%S")
