"""Expression printers for the generated languages.

The printers only turn sympy expressions into source text; what to compute
is decided in ``modelgen.codegen.kernels`` and where text goes in the
templates.  Small integer powers are printed as products (``x*x``,
``1.0/(x*x)``): cheaper than ``pow`` on every target and bit-for-bit the
same in the C and Python outputs.
"""

from __future__ import annotations

from typing import Mapping

import sympy as sp
from sympy.codegen.ast import float32, float64, real
from sympy.printing.c import C99CodePrinter
from sympy.printing.pycode import PythonCodePrinter

SCALAR_TYPES = {"double": float64, "float": float32}


def _small_power(printer, expr: sp.Pow, one: str) -> str | None:
    """Print x**k for |k| <= 4 as repeated products, or None to fall back."""
    base, exp = expr.as_base_exp()
    if not (exp.is_Integer and 1 <= abs(int(exp)) <= 4):
        return None
    text = printer.parenthesize(base, sp.printing.precedence.PRECEDENCE["Mul"] + 1)
    product = "*".join([text] * abs(int(exp)))
    if int(exp) > 0:
        return product if abs(int(exp)) == 1 else product
    return f"{one}/({product})" if abs(int(exp)) > 1 else f"{one}/{text}"


class CPrinter(C99CodePrinter):
    """C99 printer with parameters renamed to struct members."""

    def __init__(self, scalar: str = "double", renames: Mapping[sp.Symbol, str] | None = None):
        super().__init__({"type_aliases": {real: SCALAR_TYPES[scalar]}})
        self.scalar = scalar
        self.renames = dict(renames or {})

    def _print_Symbol(self, expr: sp.Symbol) -> str:
        if expr in self.renames:
            return self.renames[expr]
        return super()._print_Symbol(expr)

    def _print_Pow(self, expr: sp.Pow) -> str:
        one = "1.0F" if self.scalar == "float" else "1.0"
        text = _small_power(self, expr, one)
        return text if text is not None else super()._print_Pow(expr)


class PyPrinter(PythonCodePrinter):
    """Python printer (math module) with parameters renamed to vector entries."""

    def __init__(self, renames: Mapping[sp.Symbol, str] | None = None):
        super().__init__({"fully_qualified_modules": True})
        self.renames = dict(renames or {})

    def _print_Symbol(self, expr: sp.Symbol) -> str:
        if expr in self.renames:
            return self.renames[expr]
        return super()._print_Symbol(expr)

    def _print_Pow(self, expr: sp.Pow) -> str:
        text = _small_power(self, expr, "1.0")
        return text if text is not None else super()._print_Pow(expr)
