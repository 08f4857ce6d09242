"""The filter kernels: what each generated function computes, with its cost.

Everything structural is decided here, in Python, so that the templates only
lay out text.  The covariance prediction P = Phi P Phi^T + Q_d is unrolled for
C over the structural nonzeros of Phi, skips rows of Phi that are exactly
e_i, and computes each (i, j) pair of the symmetric result once.  The Python
kernel does the same work vectorized by row class (unit, diagonal, general).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from modelgen.codegen.structure import FilterStructure


@dataclass(frozen=True)
class OperationCount:
    """Floating-point multiplications and additions of one kernel."""

    multiplications: int
    additions: int

    @property
    def total(self) -> int:
        return self.multiplications + self.additions

    def __str__(self) -> str:
        return f"{self.multiplications} mul + {self.additions} add = {self.total} flops"


def _sum(terms: list[str]) -> str:
    return " + ".join(terms) if terms else "0"


def _row_classes(structure: FilterStructure) -> tuple[list[int], list[int], list[int]]:
    """Split Phi's rows into exact unit rows, diagonal-only rows and general rows."""
    n = structure.n_states
    unit = list(structure.unit_rows)
    diagonal = [i for i in range(n) if i not in unit and list(np.flatnonzero(structure.Phi[i])) == [i]]
    general = [i for i in range(n) if i not in unit and i not in diagonal]
    return unit, diagonal, general


def c_predict(structure: FilterStructure) -> tuple[list[str], list[str], OperationCount]:
    """Unrolled C statements for x = Phi x and P = Phi P Phi^T + Q_d.

    Returns (state lines, covariance lines, cost).  The covariance lines use
    ``M`` (= Phi P, rows that are not unit rows) and ``Pn`` (upper triangle of
    the result) from the caller-owned workspace ``w``.
    """
    n = structure.n_states
    rows = structure.rows("Phi")
    unit = set(structure.unit_rows)
    mul = add = 0
    state_lines = []
    for i in range(n):
        if i in unit:
            continue
        terms = [f"t->Phi[{i}][{k}]*f->x[{k}]" for k in rows[i]]
        mul += len(terms)
        add += len(terms) - 1
        state_lines.append(f"w->xn[{i}] = {_sum(terms)};")
    for i in range(n):
        if i not in unit:
            state_lines.append(f"f->x[{i}] = w->xn[{i}];")

    cov_lines = []
    for i in range(n):  # M = Phi P, only the rows that are not copies of P
        if i in unit:
            continue
        for col in range(n):
            terms = [f"t->Phi[{i}][{k}]*f->P[{k}][{col}]" for k in rows[i]]
            mul += len(terms)
            add += len(terms) - 1
            cov_lines.append(f"w->M[{i}][{col}] = {_sum(terms)};")

    def m_ref(i: int, col: int) -> str:
        return f"f->P[{i}][{col}]" if i in unit else f"w->M[{i}][{col}]"

    for i in range(n):  # Pn = M Phi^T + Q_d, upper triangle only
        for j in range(i, n):
            if j in unit:
                terms = [m_ref(i, j)]
            else:
                terms = [f"{m_ref(i, col)}*t->Phi[{j}][{col}]" for col in rows[j]]
                mul += len(terms)
            add += len(terms) - 1
            if structure.Qd[i, j]:
                terms.append(f"t->Qd[{i}][{j}]")
                add += 1
            cov_lines.append(f"w->Pn[{i}][{j}] = {_sum(terms)};")
    return state_lines, cov_lines, OperationCount(mul, add)


def python_predict_plan(structure: FilterStructure) -> dict[str, list[int]]:
    """Index sets for the vectorized Python prediction (see module doc)."""
    unit, diagonal, general = _row_classes(structure)
    columns = sorted({int(c) for i in general for c in np.flatnonzero(structure.Phi[i])})
    return {"unit": unit, "diagonal": diagonal, "general": general, "general_columns": columns}


def python_predict_cost(structure: FilterStructure) -> OperationCount:
    """Flops of the vectorized Python prediction (dense within each row class)."""
    n = structure.n_states
    plan = python_predict_plan(structure)
    g, c, d = len(plan["general"]), len(plan["general_columns"]), len(plan["diagonal"])
    mul = 2 * g * c * n + 2 * d * n
    add = 2 * g * (c - 1) * n + n * n
    return OperationCount(mul, add)


def discretize_cost(structure: FilterStructure, order: int) -> OperationCount:
    """Flops of the Taylor series over CSR F, Gamma = T S G and Q_d (upper triangle)."""
    n = structure.n_states
    nnz_f = int(structure.F.sum())
    nnz_g = int(structure.G.sum())
    nw = structure.G.shape[1]
    mul = order * (n * nnz_f + n * n)  # (F A) and the 1/k scaling
    add = order * (n * max(nnz_f - n, 0) + 2 * n * n)  # row sums, Phi and S accumulation
    mul += n * nnz_g + n * nw  # Gamma
    pairs = n * (n + 1) // 2
    mul += pairs * 2 * nw
    add += pairs * nw
    return OperationCount(mul, add)


def update_cost(structure: FilterStructure) -> OperationCount:
    """Flops of the vector update with Cholesky solve and factored Joseph form."""
    n = structure.n_states
    m = structure.H.shape[0]
    nnz_h = int(structure.H.sum())
    pairs = n * (n + 1) // 2
    mul = nnz_h * n  # H P
    mul += m * nnz_h  # S
    mul += m * m * m // 3 + m * m * n  # Cholesky + solves
    mul += nnz_h + n * m  # innovation, state
    mul += n * n * m  # B = P - K (H P)
    mul += n * nnz_h  # C = B H^T
    mul += pairs * 3 * m  # C K^T and K R K^T
    add = mul  # one addition per multiplication, to within m terms
    return OperationCount(mul, add)
