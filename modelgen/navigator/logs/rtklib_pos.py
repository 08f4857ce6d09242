"""RTKLIB .pos solution files: the header's time system and solution type are read and honoured.

The file is untrusted data; refusals name ``file:line``.

Header (lines starting with ``%``)
  The column header RTKLIB writes (``%  GPST  latitude(deg) longitude(deg) ...``)
  must come before the first solution row: its first word is the time system,
  its second the solution type.  Without it neither can be known, and the
  file is refused.

  * time system ``GPST``: used as is; ``UTC``: put on GPS time with the leap
    seconds of each epoch's date (``modelgen/data/leap_seconds.yaml``);
    ``JST``: UTC + 9 h, then likewise.  Anything else is refused.
  * solution ``latitude(deg) longitude(deg) height(m)`` (RTKLIB's default
    ``llh``), ``latitude(d'")`` (degrees, minutes, seconds: three fields each) and
    ``x-ecef(m) y-ecef(m) z-ecef(m)`` (``xyz``: converted to WGS-84 latitude,
    longitude, ellipsoidal height; the ECEF covariance rotated to north, east,
    up) are read.  ``e-baseline(m)`` / ``n-baseline(m)`` (a baseline to a base
    station, ENU or NED) is refused: it is not a position on the Earth, and
    must never be read as degrees.

Rows
  * time as calendar ``YYYY/MM/DD hh:mm:ss.sss`` or, in GPST only, as GPS
    ``week`` and ``time of week``;
  * Q, ns, the three standard deviations and the three signed covariance
    roots, age, ratio; velocities and their standard deviations when the
    header names them (``vn(m/s)`` ... or ``vx(m/s)`` ...);
  * a short row or a field that is not a number is refused (file:line); an
    epoch not after the one before it is refused (file:line); a row with
    Q = 0 (no solution) is dropped and counted; an empty or header-only file
    is refused.
"""

from __future__ import annotations

import calendar
import math
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from modelgen.errors import ModelError
from modelgen.navigator.logs.files import read_text
from modelgen.navigator.logs.formats import LogFormat, LogSource
from modelgen.navigator.logs.gps_time import GPS_EPOCH_S, NS, TIME_SYSTEMS, seconds, to_gpst_ns
from modelgen.navigator.logs.records import GnssLog

SECONDS_PER_WEEK = 604800
#: The solution types of RTKLIB's column header, by the header's second word.
SOLUTIONS = {"latitude(deg)": "llh", "latitude(d'\")": "dms", "x-ecef(m)": "xyz",
             "e-baseline(m)": "enu", "n-baseline(m)": "ned"}
BASELINE_REASON = ("a baseline to the base station, not a position on the Earth (write the solution as "
                   "lat/lon/height or ECEF: RTKLIB option out-solformat=llh or xyz)")


@dataclass(frozen=True)
class Header:
    """What the column header says: time system, solution type, whether velocities follow."""

    time_system: str
    solution: str  # "llh", "dms" or "xyz"
    velocity: bool
    line: int


def parse_header(line: str, where: str, number: int) -> Header | None:
    """The column header's meaning, or None if this ``%`` line is not a column header."""
    words = line.lstrip("%").split()
    if len(words) < 2 or not any(w in SOLUTIONS or w.startswith("latitude(") or w.endswith("-baseline(m)")
                                 or w.endswith("-ecef(m)") for w in words[1:2]):
        return None
    system, solution = words[0], words[1]
    if system not in TIME_SYSTEMS:
        raise ModelError(f"{where}: time system {system!r} in the column header is not one of "
                         f"{', '.join(TIME_SYSTEMS)}")
    kind = SOLUTIONS.get(solution)
    if kind in ("enu", "ned"):
        raise ModelError(f"{where}: {kind.upper()}-baseline solution ({solution}): {BASELINE_REASON}; "
                         "refused")
    if kind is None:
        raise ModelError(f"{where}: solution type {solution!r} in the column header is not read "
                         f"(read: {', '.join(k for k, v in SOLUTIONS.items() if v in ('llh', 'dms', 'xyz'))})")
    velocity_words = {"vx(m/s)", "vx"} if kind == "xyz" else {"vn(m/s)", "vn"}
    return Header(system, kind, bool(velocity_words & set(words)) and any(w.startswith("sdv") for w in words), number)


def _number(text: str, where: str, column: int) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ModelError(f"{where}: column {column} {text.strip()[:40]!r} is not a number") from None
    if not math.isfinite(value):
        raise ModelError(f"{where}: non-finite value in column {column}")
    return value


def _epoch_ns(fields: list[str], header: Header, where: str) -> int:
    """Integer nanoseconds since 1970 (in the header's time system) of a row's two time fields."""
    date, clock = fields[0], fields[1]
    if "/" in date:
        try:
            year, month, day = (int(x) for x in date.split("/"))
            hour, minute, second_text = clock.split(":")
            second = Decimal(second_text)
            if not (1 <= month <= 12 and 1 <= day <= 31 and 0 <= int(hour) < 24 and 0 <= int(minute) < 60
                    and 0 <= second < 61):
                raise ValueError
            stamp = calendar.timegm((year, month, day, int(hour), int(minute), 0, 0, 0, 0))
        except (ValueError, OverflowError, InvalidOperation):
            raise ModelError(f"{where}: time {date} {clock!r} is not 'YYYY/MM/DD hh:mm:ss.sss'") from None
        return stamp * NS + int((second * NS).to_integral_value())
    try:
        week, tow = int(date), Decimal(clock)
        if week < 0 or not (0 <= tow < SECONDS_PER_WEEK):
            raise ValueError
    except (ValueError, InvalidOperation):
        raise ModelError(f"{where}: expected 'YYYY/MM/DD hh:mm:ss.sss' or GPS week and time of week, got "
                         f"{date!r} {clock!r}") from None
    if header.time_system != "GPST":
        raise ModelError(f"{where}: a week / time-of-week time is GPS time, but the header says "
                         f"{header.time_system}")
    return (GPS_EPOCH_S + week * SECONDS_PER_WEEK) * NS + int((tow * NS).to_integral_value())


def _dms(fields: list[str], where: str, first_column: int) -> float:
    """Degrees from RTKLIB's 'd m s' (three fields; the sign is the degrees field's)."""
    d, m, s = (_number(f, where, first_column + k) for k, f in enumerate(fields))
    if not (0 <= m < 60 and 0 <= s < 60):
        raise ModelError(f"{where}: {' '.join(fields)} is not degrees, minutes (< 60) and seconds (< 60)")
    sign = -1.0 if fields[0].strip().startswith("-") else 1.0
    return sign * (abs(d) + m / 60.0 + s / 3600.0)


def _row_values(fields: list[str], header: Header, where: str) -> list[float]:
    """[x1, x2, x3, Q, ns, sd1, sd2, sd3, sd12, sd23, sd31, (v1, v2, v3, sdv1..sdv31)] of a row.

    For llh/dms the position is latitude, longitude [deg], height; for xyz ECEF [m].
    """
    if header.solution == "dms":
        need = 2 + 6 + 1 + 10
        if len(fields) < need:
            raise ModelError(f"{where}: {len(fields)} columns; a d/m/s solution row has at least {need}")
        position = [_dms(fields[2:5], where, 3), _dms(fields[5:8], where, 6), _number(fields[8], where, 9)]
        rest, first = fields[9:], 10
    else:
        need = 15
        if len(fields) < need:
            names = ("date, time, lat, lon, height" if header.solution == "llh" else "date, time, x, y, z")
            raise ModelError(f"{where}: {len(fields)} columns; an RTKLIB {header.solution} solution row has at "
                             f"least 15 ({names}, Q, ns, 3 sd, 3 sd cross, age, ratio)")
        position = [_number(f, where, 3 + k) for k, f in enumerate(fields[2:5])]
        rest, first = fields[5:], 6
    count = 8 + (9 if header.velocity else 0)  # Q ns sd*6 [v*3 sdv*6]; age, ratio sit between
    if len(rest) < count + 2:
        raise ModelError(f"{where}: {len(fields)} columns; the header names "
                         f"{'velocities, ' if header.velocity else ''}so a row has at least "
                         f"{len(fields) - len(rest) + count + 2}")
    values = [_number(f, where, first + k) for k, f in enumerate(rest[:count + 2])]
    del values[8:10]  # age, ratio
    return position + values


def _covariance(sd: np.ndarray) -> np.ndarray:
    """(n, 3, 3) covariance from RTKLIB's sd1, sd2, sd3 and signed roots sd12, sd23, sd31."""
    n = len(sd)
    c = np.zeros((n, 3, 3))
    for i in range(3):
        c[:, i, i] = sd[:, i] ** 2
    for (i, j), k in (((0, 1), 3), ((1, 2), 4), ((2, 0), 5)):
        c[:, i, j] = c[:, j, i] = np.sign(sd[:, k]) * sd[:, k] ** 2
    return c


def _ecef_to_ned(latitude: np.ndarray, longitude: np.ndarray, vectors: np.ndarray,
                 covariance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ECEF vectors and covariances rotated into NED at each point: (vectors, 1-sigma of N, E, up)."""
    from modelgen.simulation.earth import ned_to_ecef_matrix  # imported here: simulation loads numba (1 s)

    out = np.empty_like(vectors)
    sigma = np.empty_like(vectors)
    for k in range(len(vectors)):
        c_ne = ned_to_ecef_matrix(float(latitude[k]), float(longitude[k])).T
        out[k] = c_ne @ vectors[k]
        sigma[k] = np.sqrt(np.maximum(np.diag(c_ne @ covariance[k] @ c_ne.T), 0.0))
    return out, sigma


def read_rtklib_pos(path: str | Path) -> GnssLog:
    """Read an RTKLIB .pos solution (see the module docstring for what is read, refused and handled)."""
    path = Path(path)
    header: Header | None = None
    rows: list[list[float]] = []
    stamps: list[int] = []
    no_solution: list[int] = []
    previous, previous_line = -1, 0
    for number, line in enumerate(read_text(path).splitlines(), start=1):
        stripped = line.strip()
        if not stripped:
            continue
        where = f"{path}:{number}"
        if stripped.startswith("%"):
            found = parse_header(stripped, where, number)
            if found is not None:
                header = found
            continue
        if header is None:
            raise ModelError(f"{where}: solution row before RTKLIB's column header ('%  GPST  latitude(deg) "
                             "longitude(deg) height(m) Q ns ...'): the time system and the solution type "
                             "cannot be known")
        fields = stripped.split()
        if len(fields) < 2:
            raise ModelError(f"{where}: {len(fields)} column(s); not an RTKLIB solution row")
        stamp = _epoch_ns(fields, header, where)
        values = _row_values(fields, header, where)
        if stamp <= previous:
            kind = "duplicated" if stamp == previous else "goes back in"
            raise ModelError(f"{where}: epoch {fields[0]} {fields[1]} {kind} time (line {previous_line} is later "
                             "or equal)")
        previous, previous_line = stamp, number
        if values[3] != int(values[3]):
            raise ModelError(f"{where}: quality Q {values[3]!r} is not an integer")
        if int(values[3]) == 0:
            no_solution.append(number)
            continue
        if header.solution != "xyz" and not (-90.0 <= values[0] <= 90.0 and -180.0 <= values[1] <= 360.0):
            raise ModelError(f"{where}: latitude/longitude {values[0]}, {values[1]} out of range")
        if min(values[5:8]) < 0 or (header.velocity and min(values[14:17]) < 0):
            raise ModelError(f"{where}: negative standard deviation")
        rows.append(values)
        stamps.append(stamp)
    notes = []
    if no_solution:
        notes.append(f"{path}: {len(no_solution)} epoch(s) with Q = 0 (no solution) dropped "
                     f"(lines {', '.join(map(str, no_solution[:5]))}{' ...' if len(no_solution) > 5 else ''})")
    if header is None or (not rows and not no_solution):
        raise ModelError(f"{path}: no solution epochs (empty or header-only .pos file)")
    if not rows:
        return GnssLog(str(path), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, int),
                       np.zeros(0, int), np.zeros((0, 3)), None, None, notes)
    gpst_ns, time_notes = to_gpst_ns(np.array(stamps, dtype=np.int64), header.time_system, str(path))
    if header.time_system != "GPST":
        notes.append(f"{path}: times in {header.time_system} (column header) put on GPS time with the leap "
                     "seconds of their date")
    return _log(str(path), header, np.array(rows), seconds(gpst_ns), notes + time_notes)


def _log(path: str, header: Header, data: np.ndarray, time: np.ndarray, notes: list[str]) -> GnssLog:
    """The GnssLog of parsed rows, llh/dms as read, xyz converted to geodetic and NED."""
    velocity = sigma_velocity = None
    if header.solution == "xyz":
        from modelgen.simulation.earth import ecef_to_geodetic  # only for ECEF files (simulation loads numba)

        latitude, longitude, height = ecef_to_geodetic(data[:, 0:3])
        sigma = _ecef_to_ned(latitude, longitude, np.zeros((len(data), 3)), _covariance(data[:, 5:11]))[1]
        if header.velocity:
            velocity, sigma_velocity = _ecef_to_ned(latitude, longitude, data[:, 11:14], _covariance(data[:, 14:20]))
        notes.append(f"{path}: ECEF solution converted to WGS-84 latitude, longitude and ellipsoidal height")
    else:
        latitude, longitude, height = np.radians(data[:, 0]), np.radians(data[:, 1]), data[:, 2]
        sigma = data[:, 5:8]
        if header.velocity:
            velocity = data[:, 11:14] * np.array([1.0, 1.0, -1.0])  # RTKLIB's up to down
            sigma_velocity = data[:, 14:17]
    return GnssLog(path, time, latitude, longitude, height, data[:, 3].astype(int), data[:, 4].astype(int),
                   sigma, velocity, sigma_velocity, notes)


def _read(source: LogSource) -> GnssLog:
    return read_rtklib_pos(source.path)


FORMAT = LogFormat(
    name="rtklib_pos",
    summary="RTKLIB solution (.pos): lat/lon/height or ECEF, GPST/UTC/JST, with or without velocities",
    read_gnss=_read,
)
