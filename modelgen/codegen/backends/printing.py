"""What the expression printers of every backend share.

Small integer powers print as products: ``x*x`` and ``1.0/(x*x)`` are cheaper
than ``pow`` on every target and bit for bit the same in the C and the Python
outputs.  Parameters print under the name the backend gives them (a struct
member, a local, a vector entry): :class:`RenamedSymbols`.  A number prints
as its value in the scalar type (:func:`scalar_value`): one too small for
the type is 0 there (as a C compiler would make it, with a warning that
-Werror refuses), one too large is refused before any file is written.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np
import sympy as sp

from modelgen.errors import ModelError


class RenamedSymbols:
    """Printer mix-in: a symbol in ``renames`` prints as its new name, any other as sympy prints it."""

    renames: dict[sp.Symbol, str]

    def _init_renames(self, renames: Mapping[sp.Symbol, str] | None) -> None:
        self.renames = dict(renames or {})

    def _print_Symbol(self, expr: sp.Symbol) -> str:
        if expr in self.renames:
            return self.renames[expr]
        return super()._print_Symbol(expr)  # type: ignore[misc]

    def _print_Mul(self, expr: sp.Mul) -> str:
        text = small_power_quotient(self, expr)
        return text if text is not None else super()._print_Mul(expr)  # type: ignore[misc]


def small_power(printer, expr: sp.Pow, one: str) -> str | None:
    """Print x**k for |k| <= 4 as repeated products, or None to fall back to the printer's own."""
    base, exp = expr.as_base_exp()
    if not (exp.is_Integer and 1 <= abs(int(exp)) <= 4):
        return None
    text = printer.parenthesize(base, sp.printing.precedence.PRECEDENCE["Mul"] + 1)
    product = "*".join([text] * abs(int(exp)))
    if int(exp) > 0:
        return product
    return f"{one}/({product})" if abs(int(exp)) > 1 else f"{one}/{text}"


def small_power_quotient(printer, expr: sp.Mul) -> str | None:
    """``a/(x*x*x)`` for a product whose only denominator is x**-k, 2 <= k <= 4; None to print it as sympy does.

    sympy prints a single denominator factor unparenthesized (``a/x**3`` is right as Python), which the
    product form of :func:`small_power` would make ``a/x*x*x``.
    """
    factors = expr.args
    below = [f for f in factors if f.is_Pow and f.exp.is_Rational and f.exp.is_negative]
    if len(below) != 1 or not (below[0].is_Pow and below[0].exp.is_Integer and 2 <= -int(below[0].exp) <= 4):
        return None
    denominator = printer._print(sp.Pow(below[0].base, -below[0].exp, evaluate=False))
    numerator = sp.Mul(*[f for f in factors if f is not below[0]])
    sign = ""
    if numerator.could_extract_minus_sign():
        sign, numerator = "-", -numerator
    top = printer._print(sp.Float(1.0)) if numerator == 1 else printer.parenthesize(numerator, sp.printing.precedence.PRECEDENCE["Mul"], strict=True)
    return f"{sign}{top}/({denominator})"


def scalar_value(number: object, scalar: str) -> float:
    """``number`` (a sympy Float, a float) rounded to the scalar type (IEEE ``double`` or ``float``).

    A nonzero value below the type's smallest subnormal rounds to 0 (printed
    as 0, where the literal would fail a strict compile: "floating constant
    truncated to zero"); a value beyond the type's range is refused
    (ModelError: the literal would not compile, and no filter can hold it).
    """
    value = float(number)
    if scalar == "float":
        with np.errstate(over="ignore", under="ignore"):
            value = float(np.float32(value))
    if not math.isfinite(value):
        raise ModelError(f"the constant {sp.Float(number, 4)} is outside the range of the C {scalar} type of the generated filter")
    return value
