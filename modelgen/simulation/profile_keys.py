"""Reading one section of a flight-profile file (modelgen/data/profile_*.yaml) with its units.

Every number carries its unit in its key name (``_deg``, ``_kmh``, ``_dph``...);
:class:`ProfileSection` converts to SI and refuses unknown keys, missing keys and
non-numbers with a message naming the file, the line and the key.  It is the one
reader of profile keys: the profile loader (``scenario``) and every aiding sensor
plug-in (``aiding``) read their own sections with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from modelgen.errors import ModelError
from modelgen.model.file_fields import is_number

DEG = math.pi / 180.0
ARCSEC = DEG / 3600.0
ARCMIN = DEG / 60.0
HOUR = 3600.0
KMH = 1000.0 / 3600.0
DPH = DEG / HOUR  # deg/h -> rad/s


#: Bounds of a flight (an hours or IMU rate without bound would run out of memory, or for days).  The longest
#: flight is 10 days; 10 kHz is five times the fastest tactical IMUs' 2 kHz; the samples of a flight are at most
#: those of 10 days at 300 Hz (the core paper's rate): the truth, the IMU and the strapdown are flown per sample.
MAX_FLIGHT_HOURS = 240.0
MAX_IMU_RATE_HZ = 10_000.0
MAX_IMU_SAMPLES = int(MAX_FLIGHT_HOURS * HOUR * 300)


def check_flight_size(hours: float | None, rate_hz: float | None, where_hours: str, where_rate: str) -> None:
    """Refuse a flight longer than :data:`MAX_FLIGHT_HOURS`, an IMU faster than :data:`MAX_IMU_RATE_HZ`, or both
    together over :data:`MAX_IMU_SAMPLES` samples, naming the limit (either may be None: not known yet)."""
    if hours is not None and hours > MAX_FLIGHT_HOURS:
        raise ModelError(f"{where_hours}: a flight of {hours:g} h is longer than modelgen flies: at most "
                         f"{MAX_FLIGHT_HOURS:g} h (10 days)")
    if rate_hz is not None and rate_hz > MAX_IMU_RATE_HZ:
        raise ModelError(f"{where_rate}: an IMU rate of {rate_hz:g} Hz is faster than modelgen flies: at most "
                         f"{MAX_IMU_RATE_HZ:g} Hz")
    if hours is not None and rate_hz is not None and hours * HOUR * rate_hz > MAX_IMU_SAMPLES:
        raise ModelError(f"{where_rate}: {rate_hz:g} Hz for {hours:g} h ({where_hours}) is {hours * HOUR * rate_hz:.3g} IMU samples, "
                         f"more than modelgen flies: at most {MAX_IMU_SAMPLES:.3g} ({MAX_FLIGHT_HOURS:g} h at 300 Hz)")


@dataclass(frozen=True)
class Outage:
    """A sensor's measurements in [start, end) seconds are marked invalid."""

    start: float
    end: float


def valid_mask(times: np.ndarray, outages: tuple[Outage, ...]) -> np.ndarray:
    """True at the measurement times outside every outage."""
    valid = np.ones(times.shape, bool)
    for o in outages:
        valid &= ~((times >= o.start) & (times < o.end))
    return valid


class ProfileSection:
    """Reads one mapping of the file, converting units and refusing what is unknown."""

    def __init__(self, data: Any, where: str, lines: dict[str, str] | None = None, path: str = ""):
        self.lines, self.path = lines or {}, path
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise ModelError(f"{self.lines.get(path, where)}: {path or where} must be a mapping, got {type(data).__name__}")
        self.data, self.where, self.used = data, where, set()

    def at(self, key: str) -> str:
        """Where ``key`` of this section is, for messages: ``file:line: doppler.period_s`` when the line is known."""
        full = f"{self.path}.{key}" if self.path else key
        line = self.lines.get(full)
        return f"{line}: {full}" if line else f"{self.where}.{key}"

    def number(
        self, key: str, default: float | None = None, scale: float = 1.0, positive: bool = False, non_negative: bool = False
    ) -> float:
        """A finite number (times ``scale``); ``positive``/``non_negative`` refuse periods, rates and sigmas that make no sense."""
        self.used.add(key)
        if key not in self.data:
            if default is None:
                raise ModelError(f"{self.lines.get(self.path, self.where)}: missing key {key!r}")
            return default
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            if not is_number(value):  # plain decimal text only: float() would also read '1_000'
                raise ModelError(f"{self.at(key)}: {value!r} is not a number")
            value = float(value)
        value = float(value)
        if not math.isfinite(value):
            raise ModelError(f"{self.at(key)}: {value!r} is not finite")
        if positive and not value > 0:
            raise ModelError(f"{self.at(key)}: must be positive, got {value:g}")
        if non_negative and value < 0:
            raise ModelError(f"{self.at(key)}: must not be negative, got {value:g}")
        return value * scale

    def text(self, key: str, default: str | None = None, choices: tuple[str, ...] = ()) -> str:
        """A string value, one of ``choices`` when given."""
        self.used.add(key)
        if key not in self.data:
            if default is None:
                raise ModelError(f"{self.where}: missing key {key!r}")
            return default
        value = str(self.data[key])
        if choices and value not in choices:
            raise ModelError(f"{self.where}.{key}: {value!r} is not one of {', '.join(choices)}")
        return value

    def section(self, key: str) -> "ProfileSection":
        """The nested mapping ``key`` (empty when absent), read with the same rules."""
        self.used.add(key)
        return ProfileSection(self.data.get(key), f"{self.where}.{key}", self.lines, f"{self.path}.{key}" if self.path else key)

    def raw(self, key: str, default: Any = None) -> Any:
        """The value of ``key`` as parsed, unconverted (lists, mappings)."""
        self.used.add(key)
        return self.data.get(key, default)

    def done(self) -> None:
        """Refuse any key of the section that no reader asked for (a typo must not pass silently)."""
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise ModelError(f"{self.where}: unknown key {unknown[0]!r} (known: {', '.join(sorted(self.used))})")


def read_outages(s: ProfileSection, key: str) -> tuple[Outage, ...]:
    """The list ``key`` of {start_s, end_s} windows of a sensor section."""
    raw = s.raw(key, []) or []
    if not isinstance(raw, list):
        raise ModelError(f"{s.where}.{key}: must be a list of {{start_s, end_s}}")
    out = []
    for i, item in enumerate(raw):
        o = ProfileSection(item, f"{s.where}.{key}[{i}]")
        start, end = o.number("start_s"), o.number("end_s")
        o.done()
        if end <= start:
            raise ModelError(f"{o.where}: end_s must be after start_s")
        out.append(Outage(start, end))
    return tuple(out)
