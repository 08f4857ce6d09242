"""Dimensional check of a model's equations, term by term, with the declared units (pint).

Every state equation d(x)/dt = sum of terms, every measurement z = sum of
terms, every noise PSD and every measurement variance is checked: each term's
unit, composed from the declared units of the symbols in it, must be the
equation's own (the state's unit per second, the measurement's unit, the
square of the noise's amplitude spectral density unit or of the measurement's
unit).  Units agree when their dimension *and* their size agree
(:class:`~modelgen.model.units.UnitOf`): a term in rad/s in the equation of a
state declared in deg is refused, as is a length in the equation of an angle.
Arguments of sin, cos, tan, exp and log must be plain numbers or angles in rad.

Conventions (those of every shipped model):

* a noise's declared unit is that of its amplitude spectral density (the
  square root of its PSD): gyro white noise ``rad/sqrt(s)``; the white noise
  itself, as it stands in an equation, is that unit per sqrt(s) (rad/s);
* a symbol whose unit the file does not declare is not checked (terms with it
  are skipped), so a model may leave units out;
* a constant written as a number (``6371000``, ``9.81``, ``7.292115e-5``, the
  WGS-84 semi-major axis in the derived Earth formulas) carries whatever unit
  its author meant, so a term with one is not checked either; small whole
  numbers and fractions (2, -1, 1/2, 3/2: numerator and denominator at most 12)
  are plain numbers;
* angles are dimensionless with the radian as their size 1.

A mismatch is a ModelError ``file:line: model 'm', <equation>: term 'T' is in U1,
but the equation is in U2``.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Iterable, Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.units import DIMENSIONLESS, SECOND, UnitOf, parse_unit

#: Functions that take a plain number (or an angle in rad) and give one.
_OF_A_NUMBER = (sp.sin, sp.cos, sp.tan, sp.sec, sp.csc, sp.cot, sp.exp, sp.log, sp.asin, sp.acos, sp.atan,
                sp.sinh, sp.cosh, sp.tanh)


class _Mismatch(Exception):
    """Two parts of one expression that should share a unit do not."""

    def __init__(self, term: sp.Expr, unit: UnitOf, expected: UnitOf, what: str):
        super().__init__(what)
        self.term, self.unit, self.expected, self.what = term, unit, expected, what


def unit_of(expr: sp.Expr, units: Mapping[sp.Symbol, UnitOf]) -> UnitOf | None:
    """The unit of ``expr`` from its symbols' units; None if a symbol's unit is unknown.

    Raises :class:`_Mismatch` when a sum inside it mixes units or a function's
    argument is not a plain number.
    """
    if expr.is_Float or (expr.is_Rational and (abs(expr.p) > 12 or expr.q > 12)):
        return None  # a physical constant (6371000, 9.81, 7.292115e-5, WGS-84's a) carries the unit its author meant: not checked
    if expr.is_Number or expr.is_NumberSymbol or expr is sp.S.ImaginaryUnit:
        return DIMENSIONLESS
    if expr.is_Symbol:
        return units.get(expr)
    if expr.is_Mul:
        out = DIMENSIONLESS
        for factor in expr.args:
            unit = unit_of(factor, units)
            if unit is None:
                return None
            out = out * unit
        return out
    if expr.is_Pow:
        base, exponent = expr.args
        unit = unit_of(base, units)
        if exponent.is_Rational:
            return None if unit is None else unit ** Fraction(int(exponent.p), int(exponent.q))
        if exponent.is_Number:
            return None if unit is None else unit ** Fraction(float(exponent)).limit_denominator(1000)
        _require_number(exponent, units, f"the exponent of {sp.sstr(expr)}")
        _require_number(base, units, f"the base of {sp.sstr(expr)} (raised to a symbolic power)")
        return DIMENSIONLESS
    if expr.is_Add:
        first: tuple[sp.Expr, UnitOf] | None = None
        for term in expr.args:
            unit = unit_of(term, units)
            if unit is None:
                continue
            if first is None:
                first = (term, unit)
            elif not unit.agrees(first[1]):
                raise _Mismatch(term, unit, first[1], f"the sum {_short(expr)} adds {_short(first[0])} ({first[1].shown()}) and")
        return None if first is None else first[1]
    if isinstance(expr, _OF_A_NUMBER):
        for argument in expr.args:
            _require_number(argument, units, f"the argument of {type(expr).__name__}")
        return DIMENSIONLESS
    if isinstance(expr, sp.atan2):
        y, x = (unit_of(a, units) for a in expr.args)
        if y is not None and x is not None and not y.agrees(x):
            raise _Mismatch(expr.args[0], y, x, f"atan2's two arguments in {_short(expr)} differ:")
        return DIMENSIONLESS
    if isinstance(expr, (sp.Abs, sp.sign)) and len(expr.args) == 1:
        unit = unit_of(expr.args[0], units)
        return DIMENSIONLESS if isinstance(expr, sp.sign) else unit
    return None  # anything else (an undefined function, Piecewise ...) is not checked


def _require_number(expr: sp.Expr, units: Mapping[sp.Symbol, UnitOf], what: str) -> None:
    unit = unit_of(expr, units)
    if unit is not None and not unit.is_radian:
        raise _Mismatch(expr, unit, UnitOf(1.0, (), "rad"), f"{what} must be a plain number or an angle in rad;")


def _short(expr: sp.Expr, limit: int = 80) -> str:
    text = sp.sstr(expr)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _difference(unit: UnitOf, expected: UnitOf) -> str:
    """How two units differ: by a factor (same dimension) or in dimension."""
    if unit.dimension == expected.dimension:
        return f"the same dimension, but {unit.shown()} is {unit.factor / expected.factor:.6g} {expected.shown()}"
    return f"dimensions {unit.si_text()} and {expected.si_text()}"


def check_terms(expr: sp.Expr, expected: UnitOf | None, units: Mapping[sp.Symbol, UnitOf], where: str, what: str) -> None:
    """Every top-level term of ``expr`` in ``expected`` (None: only the inside of each term is checked)."""
    if expr == 0:
        return
    for term in sp.Add.make_args(expr):
        if term.is_number:  # a term that is only a number (variance: "1", a constant rate) is in the author's unit
            continue
        try:
            unit = unit_of(term, units)
        except _Mismatch as bad:
            raise ModelError(
                f"{where}: {what}: units do not match in term {_short(term)!r}: {bad.what} {_short(bad.term)!r} is in "
                f"{bad.unit.shown()}, expected {bad.expected.shown()} ({_difference(bad.unit, bad.expected)})"
            ) from None
        if unit is None or expected is None or unit.agrees(expected):
            continue
        raise ModelError(
            f"{where}: {what}: term {_short(term)!r} is in {unit.shown()}, but the equation is in {expected.shown()} "
            f"({_difference(unit, expected)})"
        )


def declared_units(model, undeclared: Iterable[str] = (), where=None) -> dict[sp.Symbol, UnitOf]:
    """Symbol -> parsed unit of every declared quantity (noises: their ASD unit per sqrt(s), as in the equations)."""
    skip = set(undeclared)
    units: dict[sp.Symbol, UnitOf] = {}
    for kind, items in (("states", model.states), ("parameters", model.parameters), ("noises", model.noises), ("measurements", model.measurements)):
        for i, q in enumerate(items):
            if q.name in skip:
                continue
            place = where(f"{kind}[{i}]", f"{kind[:-1]} {q.name!r} unit") if where else f"{kind[:-1]} {q.name!r} unit"
            unit = parse_unit(q.unit, place)
            units[q.sym] = unit / SECOND ** Fraction(1, 2) if kind == "noises" else unit
    return units


def check_model_units(model, locations: Mapping[str, str] | None = None, undeclared: Iterable[str] = ()) -> None:
    """Refuse a model whose equations, measurements, PSDs or variances mix units (module doc)."""
    from modelgen.model.declaration import Locator  # the same file:line prefixes as the model's other checks

    where = Locator(model.name, locations or {})
    skip = set(undeclared)
    units = declared_units(model, skip, where)
    by_symbol = {**{s.sym: s for s in model.states}, **{n.sym: n for n in model.noises}, **{m.sym: m for m in model.measurements}}

    def own(symbol: sp.Symbol) -> UnitOf | None:
        return units.get(symbol)

    for i, state in enumerate(model.states):
        unit = own(state.sym)
        expected = None if unit is None else unit / SECOND
        key = f"dynamics.{state.symbol}" if f"dynamics.{state.symbol}" in (locations or {}) else f"dynamics.{state.name}"
        check_terms(model.dynamics[state.name], expected, units, where(key, f"d({state.name})/dt"),
                    f"the state is in {state.unit}, its rate in {expected.shown() if expected else 'an undeclared unit'}")
    for i, noise in enumerate(model.noises):
        asd = None if noise.name in skip else parse_unit(noise.unit)
        check_terms(model.noise_psd[noise.name], None if asd is None else asd ** 2, units, where(f"noises[{i}].psd", f"noise {noise.name!r} psd"),
                    f"a PSD is in the square of the noise's unit {noise.unit}")
    for i, m in enumerate(model.measurements):
        unit = own(m.sym)
        check_terms(model.measurement_expressions[m.name], unit, units, where(f"measurements[{i}].expression", f"measurement {m.name!r}"),
                    f"the measurement is in {m.unit}")
        check_terms(model.measurement_variance[m.name], None if unit is None else unit ** 2, units,
                    where(f"measurements[{i}].variance", f"measurement {m.name!r} variance"), f"a variance is in the square of {m.unit}")
    del by_symbol
