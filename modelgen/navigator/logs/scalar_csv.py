"""Aiding-sensor logs of one value per time stamp (odometer speed, barometric height) as CSV, plain or gzip.

One sample a line: comma-separated fields, the time stamp [s, GPST seconds
since 1970 like the IMU CSV] and the value in the columns the configuration
names (1-based); the value's unit is converted to SI (:data:`STREAMS`).  The
file is untrusted data; the reader refuses with ``file:line: reason``:

* a row with fewer columns than the highest used one, or a used field that is
  not a number (a first line that is not a number is a header and skipped;
  lines starting with ``#`` are comments);
* a time stamp not strictly after the previous kept one;
* a file with no samples, or beyond the size limit
  (:mod:`modelgen.navigator.logs.files`).

A row with a NaN or infinite value is dropped and counted in the log's notes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from modelgen.errors import ModelError
from modelgen.navigator.logs.files import read_text


@dataclass(frozen=True)
class ScalarStream:
    """One kind of scalar log: its name (= the configuration section), the quantity and its accepted units."""

    name: str
    quantity: str
    units: dict[str, float]  # unit -> factor to SI
    si_unit: str


#: the scalar log streams, one entry each (the aiding sensors that read a log of their own)
STREAMS: dict[str, ScalarStream] = {s.name: s for s in (
    ScalarStream("odometer", "wheel speed", {"m/s": 1.0, "km/h": 1.0 / 3.6, "mph": 0.44704}, "m/s"),
    ScalarStream("barometer", "barometric height", {"m": 1.0, "ft": 0.3048}, "m"),
)}


@dataclass
class ScalarLog:
    """A read scalar log: time [s, GPST], value [SI], where it came from and what was handled."""

    path: str
    stream: str
    time: np.ndarray
    value: np.ndarray
    notes: list[str] = field(default_factory=list)


def read_scalar_csv(path: str | Path, stream: str, time_column: int, value_column: int, unit: str) -> ScalarLog:
    """Read a time-and-value CSV of a stream (see the module docstring for what is refused and handled)."""
    path = Path(path)
    kind = STREAMS[stream]
    if unit not in kind.units:
        raise ModelError(f"{path}: {stream} unit {unit!r} unknown (use {', '.join(kind.units)})")
    needed = max(time_column, value_column)
    times: list[float] = []
    values: list[float] = []
    dropped: list[int] = []
    previous, previous_line = -math.inf, 0
    first = True
    for number, line in enumerate(read_text(path).splitlines(), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.split(",")
        where = f"{path}:{number}"
        if len(fields) < needed:
            raise ModelError(f"{where}: {len(fields)} column(s), the {stream} columns need {needed} "
                             f"(time column {time_column}, value column {value_column})")
        try:
            t, v = float(fields[time_column - 1]), float(fields[value_column - 1])
        except ValueError:
            if first:  # a header line
                first = False
                continue
            raise ModelError(f"{where}: {stream} time or value {fields[time_column - 1].strip()[:20]!r}, "
                             f"{fields[value_column - 1].strip()[:20]!r} is not a number") from None
        first = False
        if not (math.isfinite(t) and math.isfinite(v)):
            dropped.append(number)
            continue
        if t <= previous:
            what = "duplicated" if t == previous else "goes back in"
            raise ModelError(f"{where}: time stamp {t!r} {what} time (line {previous_line} has {previous!r})")
        previous, previous_line = t, number
        times.append(t)
        values.append(v * kind.units[unit])
    if not times:
        raise ModelError(f"{path}: no {kind.quantity} samples")
    log = ScalarLog(str(path), stream, np.array(times), np.array(values))
    if dropped:
        shown = ", ".join(map(str, dropped[:5])) + (" ..." if len(dropped) > 5 else "")
        log.notes.append(f"{path}: {len(dropped)} {stream} row(s) with NaN/infinite values dropped (lines {shown})")
    return log
