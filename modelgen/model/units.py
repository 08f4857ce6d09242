"""Units of the core paper (the core paper) and their conversion to SI.

The error model is in SI (rad, m/s, rad/s, m/s^2); the paper quotes inputs in
arc-seconds, arc-minutes, deg/h, g and km/h and results in arc-seconds and
nautical miles (per hour).  All conversions live here so that each factor is
written once.
"""

from __future__ import annotations

import math
import numbers
import re
from dataclasses import dataclass
from typing import Any
from fractions import Fraction

from modelgen.errors import ModelError
from modelgen.model.file_fields import is_number

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
    return _finite_number(value, where) * factor


def _finite_number(value: Any, where: str) -> float:
    """A YAML number, or text that is a plain decimal (``'1.5e-3'``), as a finite float.

    ``float()`` alone also reads ``True``, ``'1_000'`` and text padded with
    white space: lax forms a file may not use.
    """
    if isinstance(value, bool) or not (isinstance(value, numbers.Real) or is_number(value)):
        raise ModelError(f"{where}: {value!r} is not a number")
    number = float(value)
    if not math.isfinite(number):
        raise ModelError(f"{where}: {value!r} is not finite")
    return number


def from_si(value, unit: str):
    """SI ``value`` (scalar or numpy array) expressed in ``unit``."""
    if unit not in _TO_SI:
        raise ModelError(f"unknown unit {unit!r} (known: {', '.join(sorted(_TO_SI))})")
    return value / _TO_SI[unit]


# -- declared units, parsed and compared with pint ------------------------------------------
#
# Every unit a model file declares is parsed by pint (https://pint.readthedocs.io) in a registry
# with the navigation engineer's spellings: ``g`` is standard gravity (9.80665 m/s^2, not the
# gram), ``mg`` and ``ug`` milli- and micro-g, ``nmile`` the nautical mile (pint reads it as a
# nano-mile), ``h`` the hour and ``sqrt(X)`` the square root ``(X)**0.5``.  A model needs no
# mass, so nothing is lost.  Angles are dimensionless with the radian as base (pint's
# convention), so deg and rad have the same dimension but not the same size: the checks compare
# both (:class:`UnitOf`).

#: Spellings a model may use that pint reads differently (or not at all), and what they mean here.
UNIT_ALIASES: dict[str, str] = {
    "g": "g_0", "mg": "milli_gee", "ug": "micro_gee", "µg": "micro_gee", "μg": "micro_gee",
    "nmile": "nautical_mile", "h": "hour",
}
_REGISTRY = None


def unit_registry():
    """pint's UnitRegistry with the two extra definitions milli_gee and micro_gee (made on first use)."""
    global _REGISTRY
    if _REGISTRY is None:
        import pint

        registry = pint.UnitRegistry(autoconvert_offset_to_baseunit=False)
        registry.define("milli_gee = 1e-3 * g_0")
        registry.define("micro_gee = 1e-6 * g_0")
        _REGISTRY = registry
    return _REGISTRY


def _pint_text(text: str) -> str:
    """A declared unit in pint's syntax: aliases replaced, ``sqrt(X)`` as ``(X)**0.5``, ``^`` as ``**``."""
    out = text.strip().replace("^", "**")
    while True:  # innermost sqrt(...) first
        replaced = re.sub(r"\bsqrt\(([^()]*)\)", r"((\1)**0.5)", out)
        if replaced == out:
            break
        out = replaced
    return re.sub(r"[A-Za-zµμ_][A-Za-z0-9_µμ]*", lambda m: UNIT_ALIASES.get(m.group(0), m.group(0)), out)


@dataclass(frozen=True)
class UnitOf:
    """A unit as its size in SI (angles in rad) and its dimension (base dimension -> exponent).

    Two units agree when both agree: ``deg`` and ``rad`` share the dimension
    (none) but not the size, so a term in rad/s in the equation of a state in
    deg is a mismatch.
    """

    factor: float
    dimension: tuple[tuple[str, Fraction], ...]
    text: str = "1"

    def __mul__(self, other: "UnitOf") -> "UnitOf":
        exponents = dict(self.dimension)
        for name, power in other.dimension:
            exponents[name] = exponents.get(name, Fraction(0)) + power
        return UnitOf(self.factor * other.factor, _dimension(exponents), f"({self.text})*({other.text})")

    def __pow__(self, power: Fraction) -> "UnitOf":
        return UnitOf(self.factor ** float(power), _dimension({n: p * power for n, p in self.dimension}), f"({self.text})**({power})")

    def __truediv__(self, other: "UnitOf") -> "UnitOf":
        return self * other ** Fraction(-1)

    def agrees(self, other: "UnitOf") -> bool:
        return self.dimension == other.dimension and math.isclose(self.factor, other.factor, rel_tol=1e-9)

    @property
    def is_radian(self) -> bool:
        """Dimensionless and of size 1: a plain number or an angle in rad (what sin, cos and exp take)."""
        return not self.dimension and math.isclose(self.factor, 1.0, rel_tol=1e-9)

    def shown(self) -> str:
        """The unit as a person reads it, simplified by pint (``deg*m/s**2``), in the model's spellings (g, ug, nmile)."""
        registry = unit_registry()
        try:
            quantity = registry.Quantity(_pint_text(self.text))
            text = f"{quantity.units:~C}" if quantity.units != registry.dimensionless else "1"
            if not math.isclose(float(quantity.magnitude), 1.0, rel_tol=1e-12):
                text = f"{float(quantity.magnitude):g} {text}"
        except Exception:  # noqa: BLE001  (a composed text pint cannot read back: show the SI form)
            return self.si_text()
        for ours, theirs in (("ug", "micro_gee"), ("mg", "milli_gee"), ("g", "g_0"), ("nmile", "nmi")):
            text = re.sub(rf"\b{theirs}\b", ours, text)
        return text

    def si_text(self) -> str:
        """The SI unit of this dimension (``rad`` for none: angles are the dimensionless quantities met here)."""
        symbols = {"[length]": "m", "[time]": "s", "[mass]": "kg", "[temperature]": "K", "[current]": "A", "[substance]": "mol",
                   "[luminosity]": "cd"}
        if not self.dimension:
            return "rad" if self.factor != 1.0 else "1"
        up = [(symbols.get(n, n), p) for n, p in self.dimension if p > 0]
        down = [(symbols.get(n, n), -p) for n, p in self.dimension if p < 0]
        power = lambda s, p: s if p == 1 else f"{s}^{p}" if p.denominator == 1 else f"{s}^({p})"  # noqa: E731
        text = "*".join(power(s, p) for s, p in up) or "1"
        if down:
            text += "/" + ("*".join(power(s, p) for s, p in down) if len(down) == 1 else "(" + "*".join(power(s, p) for s, p in down) + ")")
        return text


def _dimension(exponents: dict[str, Fraction]) -> tuple[tuple[str, Fraction], ...]:
    return tuple(sorted((n, p) for n, p in exponents.items() if p != 0))


#: The unit of a plain number.
DIMENSIONLESS = UnitOf(1.0, (), "1")
SECOND = UnitOf(1.0, (("[time]", Fraction(1)),), "s")


def parse_unit(text: str, where: str = "unit") -> UnitOf:
    """A declared unit (``deg/h``, ``m/s/sqrt(s)``, ``ppm``, ``ug/sqrt(Hz)``), or ModelError naming it."""
    if not isinstance(text, str) or not text.strip():
        raise ModelError(f"{where}: unit {text!r} is not a unit")
    return _parse_unit(text.strip(), where)


def _parse_unit(text: str, where: str) -> UnitOf:
    cached = _PARSED.get(text)
    if cached is not None:
        return cached
    registry = unit_registry()
    try:
        quantity = registry.Quantity(_pint_text(text))
        if not quantity.unitless and not getattr(quantity, "_ok_for_muldiv", lambda: True)():
            raise ValueError("an offset unit (like degC) has no place in an error model")
        base = quantity.to_base_units()
        magnitude = float(base.magnitude)
    except Exception as exc:  # noqa: BLE001  pint raises UndefinedUnitError, DefinitionSyntaxError, TypeError, ...
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ModelError(f"{where}: unknown unit {text!r} (pint cannot read it: {reason})") from None
    if not math.isfinite(magnitude) or magnitude <= 0:
        raise ModelError(f"{where}: unit {text!r} has the size {magnitude!r}, not a positive finite number")
    exponents = {str(name): Fraction(power).limit_denominator(1000) for name, power in base.dimensionality.items()}
    parsed = UnitOf(magnitude, _dimension(exponents), text)
    _PARSED[text] = parsed
    return parsed


_PARSED: dict[str, UnitOf] = {}


def unit_to_si(value: float, unit: str, where: str, expected: str | None = None) -> float:
    """``value`` in any declared ``unit`` in SI (angles in rad); with ``expected``, the unit must measure the same.

    The units of :func:`to_si`'s table keep its factors; every other unit pint reads (ppm, ug, mg,
    deg/sqrt(h), ug/sqrt(Hz) ...) converts by pint's size of it.
    """
    parsed = parse_unit(unit, where)
    if expected is not None:
        target = parse_unit(expected, where)
        if parsed.dimension != target.dimension:
            raise ModelError(
                f"{where}: unit {unit!r} measures {_dimension_words(parsed)}, but the quantity is in {expected!r} "
                f"({_dimension_words(target)})"
            )
        if not math.isclose(target.factor, 1.0, rel_tol=1e-12):
            raise ModelError(f"{where}: the quantity is declared in {expected!r}, not in SI; values given with a unit are converted to SI")
    if unit in _TO_SI:
        return to_si(value, unit, where)
    number = _finite_number(value, where)
    return number * parsed.factor


def _dimension_words(unit: UnitOf) -> str:
    return "an angle or a plain number" if not unit.dimension else unit.si_text()


def si_unit_text(unit: str, where: str = "unit") -> str:
    """The SI form of a declared unit (``deg/h`` -> ``rad/s``, ``ug`` -> ``m/s^2``); the unit itself if it is SI already."""
    parsed = parse_unit(unit, where)
    if math.isclose(parsed.factor, 1.0, rel_tol=1e-12):
        return unit
    base = unit_registry().Quantity(_pint_text(unit)).to_base_units().units
    return f"{base:~C}".replace("**", "^") if base != unit_registry().dimensionless else "1"


def declared_value(value: float, unit: str, where: str) -> tuple[float, str]:
    """A parameter's declared ``value`` in ``unit`` as (SI value, SI unit): ``0.01 deg/h`` -> (4.85e-8, ``rad/s``)."""
    parsed = parse_unit(unit, where)
    if math.isclose(parsed.factor, 1.0, rel_tol=1e-12):
        return value, unit
    return unit_to_si(value, unit, where), si_unit_text(unit, where)
