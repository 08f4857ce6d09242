"""One deterministic simplification of a derived entry, for people to read.

Derived entries are stored expanded (``modelgen.derivation.symbolic`` expands
them so that equal entries print identically), which prints denominators
such as ``R_M**2 + 2*R_M*h + h**2``.  :func:`readable` undoes that for
display only: each term's denominator is factored (``(R_M + h)**2``), the
numerators of terms with the same denominator are added and factored (so that
``(R_N*x + h*x)/(R_N + h)`` becomes ``x``), then common factors are pulled out
of the sum (``-(omega_ie*cos(L) + v_E/(R_N + h))``).
The result is the same function (factoring is exact), the pipeline is fixed,
and sympy's printer is deterministic, so the same model always prints the
same text.
"""

from __future__ import annotations

import sympy as sp

MATRIX_NAMES = ("F", "G", "H", "Q", "R")
#: Largest expression factored, in tree nodes: sympy's multivariate factoring
#: grows steeply with the generators (a 10-factor product's derivative, 1,243
#: nodes: 2.6 s per entry; 40 factors ran for minutes in the hostile-input audit).  The built-in
#: models' largest is 40 nodes; a larger one is shown as it is (display only).
MAX_FACTORED_NODES = 500


def _factor(expr: sp.Expr) -> sp.Expr:
    """``sp.factor(expr)``, or ``expr`` itself when it has more than :data:`MAX_FACTORED_NODES` nodes."""
    from modelgen.model.vectors import tree_size

    return expr if tree_size(expr, MAX_FACTORED_NODES) > MAX_FACTORED_NODES else sp.factor(expr)


def readable(expr: sp.Expr) -> sp.Expr:
    """``expr`` with factored denominators, like fractions combined, common factors pulled out (see module doc)."""
    expr = sp.sympify(expr)
    if expr.is_Atom:
        return expr
    groups: dict[sp.Expr, list[sp.Expr]] = {}  # factored denominator -> numerators, in the order met
    for term in sp.Add.make_args(expr):
        numerator, denominator = sp.fraction(term)
        groups.setdefault(_factor(denominator) if denominator != 1 else sp.S.One, []).append(numerator)
    terms = []
    for denominator, numerators in groups.items():
        if denominator == 1 or len(numerators) == 1:
            terms += [n / denominator for n in numerators]
        else:  # R_N*x + h*x over (R_N + h)*y: factored, the common factor cancels
            terms.append(_factor(sp.Add(*numerators)) / denominator)
    return sp.factor_terms(sp.Add(*terms))


def nonzero_entries(matrix: sp.Matrix) -> list[tuple[int, int, sp.Expr]]:
    """The structurally nonzero entries of ``matrix`` as (row, column, entry), 1-based, row by row."""
    rows, columns = matrix.shape
    return [(i + 1, j + 1, matrix[i, j]) for i in range(rows) for j in range(columns) if matrix[i, j] != 0]
