"""Units of the core paper (seed 000) and their conversion to SI.

The error model is in SI (rad, m/s, rad/s, m/s^2); the paper quotes inputs in
arc-seconds, arc-minutes, deg/h, g and km/h and results in arc-seconds and
nautical miles (per hour).  All conversions live here so that each factor is
written once.
"""

from __future__ import annotations

import math

from modelgen.errors import ModelError

ARCSEC_PER_RAD = 180.0 * 3600.0 / math.pi  # the paper's M (eq. (7) table)
STANDARD_GRAVITY = 9.80665  # m/s^2; the "g" of "1e-4 g" in Table 1
METRES_PER_NAUTICAL_MILE = 1852.0
SECONDS_PER_HOUR = 3600.0

#: factor turning a value in the unit into SI
_TO_SI: dict[str, float] = {
    "rad": 1.0,
    "deg": math.pi / 180.0,
    "arcmin": math.pi / (180.0 * 60.0),
    "arcsec": 1.0 / ARCSEC_PER_RAD,
    "rad/s": 1.0,
    "deg/h": math.pi / 180.0 / SECONDS_PER_HOUR,
    "m/s": 1.0,
    "km/h": 1000.0 / SECONDS_PER_HOUR,
    "nmile/h": METRES_PER_NAUTICAL_MILE / SECONDS_PER_HOUR,
    "m/s^2": 1.0,
    "g": STANDARD_GRAVITY,
    "m": 1.0,
    "km": 1000.0,
    "nmile": METRES_PER_NAUTICAL_MILE,
    "s": 1.0,
    "h": SECONDS_PER_HOUR,
    "1/s": 1.0,
    "1": 1.0,
}


def to_si(value: float, unit: str, where: str = "value") -> float:
    """``value`` in ``unit`` expressed in SI; ModelError for an unknown unit."""
    try:
        factor = _TO_SI[unit]
    except KeyError:
        raise ModelError(f"{where}: unknown unit {unit!r} (known: {', '.join(sorted(_TO_SI))})") from None
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{where}: {value!r} is not a number") from None
    if not math.isfinite(number):
        raise ModelError(f"{where}: {value!r} is not finite")
    return number * factor


def from_si(value, unit: str):
    """SI ``value`` (scalar or numpy array) expressed in ``unit``."""
    if unit not in _TO_SI:
        raise ModelError(f"unknown unit {unit!r} (known: {', '.join(sorted(_TO_SI))})")
    return value / _TO_SI[unit]
