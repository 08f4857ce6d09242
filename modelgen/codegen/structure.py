"""Sparsity structure of the filter matrices, known at generation time.

The generated code multiplies only where a product can be nonzero.  Which
entries can be nonzero follows from the symbolic F, G, H alone: an entry of
Phi = e^{F T} can be nonzero only if state j reaches state i along a path of
nonzero F entries.  The Taylor series of order N alone reaches paths of at
most N entries, but its doublings (scaling and squaring, see
modelgen.derivation.discretization) reach any length, so the pattern is the closure.  A state whose row of F is
empty (a random constant) has Phi row e_i exactly: its products are copies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FilterStructure:
    """Boolean patterns of F, G, H, Phi, Gamma and Q_d for one model."""

    F: np.ndarray
    G: np.ndarray
    H: np.ndarray
    Phi: np.ndarray
    Gamma: np.ndarray
    Qd: np.ndarray
    unit_rows: tuple[int, ...]  # rows of Phi that are exactly e_i

    @property
    def n_states(self) -> int:
        return self.F.shape[0]

    def rows(self, matrix: str) -> list[list[int]]:
        """Column indices of the nonzeros of each row (CSR without values)."""
        m = getattr(self, matrix)
        return [list(np.flatnonzero(m[i])) for i in range(m.shape[0])]

    def entries(self, matrix: str) -> list[tuple[int, int]]:
        """Nonzero (row, column) pairs in row-major order."""
        m = getattr(self, matrix)
        return [(int(i), int(j)) for i, j in zip(*np.nonzero(m))]


def reachability(F: np.ndarray, order: int) -> np.ndarray:
    """Pattern of sum_{k<=order} F^k: which states can drive which in one step."""
    n = F.shape[0]
    step = F.astype(bool)
    total = np.eye(n, dtype=bool)
    power = np.eye(n, dtype=bool)
    # float products (BLAS; integer matmul is not): the sums count paths, exact far beyond any model size.
    # Once a power adds no new entry, no later one does (F^(k+1) = F^k F lies in the union of F F^j, j < k).
    step_f = step.astype(np.float64)
    for _ in range(order):
        power = (power.astype(np.float64) @ step_f) > 0
        if not power.any():
            break
        grown = total | power
        if np.array_equal(grown, total):
            break
        total = grown
    return total


def filter_structure(F: np.ndarray, G: np.ndarray, H: np.ndarray, order: int) -> FilterStructure:
    """Patterns for a Taylor discretization of the given ``order``."""
    F = np.asarray(F, dtype=bool)
    G = np.asarray(G, dtype=bool)
    H = np.asarray(H, dtype=bool)
    phi = reachability(F, max(order, F.shape[0]))  # the closure: doublings reach paths longer than the order
    # Gamma = T sum_{k<=order} (F T)^k/(k+1)! G has the pattern of Phi G.
    gamma = (phi.astype(np.int64) @ G.astype(np.int64)) > 0 if G.size else np.zeros((F.shape[0], 0), bool)
    qd = (gamma.astype(np.int64) @ gamma.T.astype(np.int64)) > 0 if G.size else np.zeros_like(F)
    unit_rows = tuple(int(i) for i in range(F.shape[0]) if not F[i].any())
    return FilterStructure(F=F, G=G, H=H, Phi=phi, Gamma=gamma, Qd=qd, unit_rows=unit_rows)
