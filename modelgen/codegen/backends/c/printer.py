"""The C printer: sympy expressions and the language-neutral kernels as C99 text.

Parameters are struct members (``params->latitude``); a kernel ``Ref`` is a
member of the filter (``f``), the transition (``t``) or the scratch (``w``)
reached through the pointer the generated function takes.
"""

from __future__ import annotations

from typing import Callable, Mapping

import sympy as sp
from sympy.codegen.ast import float32, float64, real
from sympy.printing.c import C99CodePrinter

from modelgen.codegen.backends.printing import small_power
from modelgen.codegen.kernels import Assign, CheckedAssign, Ref, Statement, Term

SCALAR_TYPES = {"double": float64, "float": float32}

#: The pointer through which a generated C function reaches each kernel owner.
POINTERS = {"filter": "f", "transition": "t", "scratch": "w"}


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
        text = small_power(self, expr, one)
        return text if text is not None else super()._print_Pow(expr)


def c_ref(ref: Ref) -> str:
    """``t->Phi[3][4]``: a kernel entry through its owner's pointer."""
    return f"{POINTERS[ref.owner]}->{ref.array}" + "".join(f"[{i}]" for i in ref.index)


def c_sum(terms: tuple[Term, ...]) -> str:
    """A sum of products, ``0`` when empty."""
    return " + ".join("*".join(c_ref(r) for r in term) for term in terms) if terms else "0"


def c_statement(statement: Statement) -> str:
    """One kernel statement as one line of C."""
    if isinstance(statement, Assign):
        return f"{c_ref(statement.target)} = {c_sum(statement.terms)};"
    assert isinstance(statement, CheckedAssign)
    stores = " ".join(f"{c_ref(t)} = v;" for t in statement.targets)
    return f"v = {c_sum(statement.terms)}; {stores} check += v - v;"


def accessors(packed: bool) -> tuple[Callable[[str, str, str], str], Callable[[str, str, str], str]]:
    """C text for entry (i, j) of a symmetric matrix: (i <= j only, any i, j), for the loop templates."""
    if packed:
        return (lambda base, i, j: f"{base}[PACKED_UPPER({i}, {j})]", lambda base, i, j: f"{base}[PACKED_ANY({i}, {j})]")
    return (lambda base, i, j: f"{base}[{i}][{j}]", lambda base, i, j: f"{base}[{i}][{j}]")
