"""One deterministic simplification of a derived entry, for people to read.

Derived entries are stored expanded (``modelgen.derive.symbolic`` expands
them so that equal entries print identically), which prints denominators
such as ``R_M**2 + 2*R_M*h + h**2``.  :func:`readable` undoes that for
display only: each term's denominator is factored (``(R_M + h)**2``), then
common factors are pulled out of the sum (``-(omega_ie*cos(L) + v_E/(R_N + h))``).
The result is the same function (factoring is exact), the pipeline is fixed,
and sympy's printer is deterministic, so the same model always prints the
same text.
"""

from __future__ import annotations

import sympy as sp

MATRIX_NAMES = ("F", "G", "H", "Q", "R")


def readable(expr: sp.Expr) -> sp.Expr:
    """``expr`` with factored denominators and common factors pulled out (see module doc)."""
    expr = sp.sympify(expr)
    if expr.is_Atom:
        return expr
    terms = []
    for term in sp.Add.make_args(expr):
        numerator, denominator = sp.fraction(term)
        terms.append(numerator / sp.factor(denominator) if denominator != 1 else numerator)
    return sp.factor_terms(sp.Add(*terms))


def nonzero_entries(matrix: sp.Matrix) -> list[tuple[int, int, sp.Expr]]:
    """The structurally nonzero entries of ``matrix`` as (row, column, entry), 1-based, row by row."""
    rows, columns = matrix.shape
    return [(i + 1, j + 1, matrix[i, j]) for i in range(rows) for j in range(columns) if matrix[i, j] != 0]
