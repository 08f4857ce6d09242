"""Van Loan's exact Q_d as generated code: the plan, a numpy model of the C, its operation counts.

``CodegenOptions(process_noise="van-loan")`` makes discretize return Phi and
the exact discrete process noise

    Q_d = int_0^T e^{F s} G Q G^T e^{F^T s} ds

instead of the paper's Gamma (Q/T) Gamma^T (eq. (9)), by Van Loan's block
exponential (C. F. Van Loan, "Computing integrals involving the matrix
exponential", IEEE TAC 23(3), 1978): with W = G Q G^T and

    M = [[-F, W], [0, F^T]],   e^{M T} = [[E11, E12], [0, E22]],

Phi = E22^T and Q_d = Phi E12 (the numpy reference is
modelgen.derivation.discretization.van_loan_discretization).

The generated Python module calls scipy.linalg.expm on the 2N x 2N block:
a library does a dense Pade approximant well.  The generated C has no
library, so it sums a block Taylor series with scaling and squaring, in
compact loops over dense N x N arrays (no unrolling: the code size does not
grow with the model), exploiting the block-triangular form:

* the norm: Osborne-balanced ||M||_D of the whole 2N x 2N block
  (modelgen.derivation.discretization.balanced_norm applies to any square
  matrix; the balancing scales the W block against the two F blocks, so that
  the units of Q do not enter the norm), and the doublings s and the order m
  from the same accuracy rule as the Taylor discretize
  (modelgen.derivation.discretization.taylor_plan, Taylor order and tolerance of
  the options).  So the rule bounds the error of the whole e^{M h} in the
  balanced norm, E12 (hence Q_d) included;
* the series over h = T / 2^s: the k-th term of e^{M h} is
  [[A_k, B_k], [0, C_k]] with C_k = (F^T h)^k / k!,
  A_k = (-F h)^k / k! = (-1)^k C_k^T (so A is never stored) and
  B_k = (A_(k-1) W + B_(k-1) F^T) h / k; row i of B_k and of C_k needs only
  row i of B_(k-1), C_(k-1) and column i of C_(k-1), so both are updated
  in place, row by row, through one row buffer; A W goes through G
  (a G diag(q) G^T, never forming W), F as its sparse entries;
* the doublings: squaring [[E11, E12], [0, E22]] gives E22^2 and
  E11 E12 + E12 E22; with E11 = E22^-T and Q_d = E22^T E12 this is
  Phi(2h) = Phi(h)^2 and Q_d(2h) = Q_d(h) + Phi(h) Q_d(h) Phi(h)^T, the same
  block squaring without E11 (2.5 N^3 multiplications per doubling instead of
  4 N^3, and Q_d stays symmetric: its upper triangle is computed, then
  mirrored).

Scratch: four N x N arrays (Phi, dense while it is squared: the transition
keeps only its structural nonzeros, written at the end; B, C, and S: W for
the norm, then the sum of the B terms), two rows, one noise vector and the
balancing's 2N scales, row and column sums (modelgen.codegen.layout); 11,568
bytes for the paper's model in double against 3,120 for the Taylor
discretize's workspace.  The balancing runs over F's nonzeros (the blocks
-F and F^T) and W, not over the dense 2N x 2N block.  The UD form takes
Gamma and q, not Q_d, so the option is refused with it
(modelgen.codegen.options).
"""

from __future__ import annotations

import math

import numpy as np

from modelgen.codegen.kernels import OperationCount
from modelgen.codegen.structure import FilterStructure
from modelgen.derivation.discretization import (
    DEFAULT_TAYLOR_ORDER,
    DOUBLE_ROUNDOFF,
    balanced_norm,
    check_step,
    taylor_plan,
    van_loan_block,
)
from modelgen.errors import ModelError

#: Orders the block series sums beyond those the Taylor discretize's accuracy rule asks for.
#: Q_d = int e^{F s} W e^{F^T s} ds is reached from W through two exponentials, and its
#: entries between states that W reaches only through a chain of couplings in F start at a
#: higher order.  Measured on the paper's model against the expm reference at T = 1 s: the
#: rule's order 5 leaves Q_d 5.2e-12 off relative to its largest entry (above the 1e-12
#: tolerance) and the latitude-longitude correlation 4.9e-6 off; order 7, two more, 3.9e-16
#: and 1.9e-12.  Phi is unaffected (it only gets more accurate).
QD_MARGIN = 2


def van_loan_plan(
    F: np.ndarray,
    G: np.ndarray,
    q: np.ndarray,
    T: float,
    order: int = DEFAULT_TAYLOR_ORDER,
    tolerance: float | None = None,
    unit_roundoff: float = DOUBLE_ROUNDOFF,
) -> tuple[int, int]:
    """(s, m): doublings and order of the block series: taylor_plan on the balanced norm of M, QD_MARGIN more orders.

    The plan is made for order ``order - QD_MARGIN`` and the order it picks
    raised by QD_MARGIN (at most ``order``); the fixed order (tolerance None,
    or within the rounding) is taylor_plan's, unchanged.
    """
    F, G, q = (np.asarray(a, dtype=float) for a in (F, G, q))
    norm = balanced_norm(van_loan_block(F, (G * q) @ G.T))
    if tolerance is None or tolerance <= unit_roundoff:
        return taylor_plan(norm, T, order, tolerance, unit_roundoff)
    planned = max(order - QD_MARGIN, 1)
    s, m = taylor_plan(norm, T, planned, tolerance, unit_roundoff)
    return s, min(m + QD_MARGIN, order)


def van_loan_series(
    F: np.ndarray, G: np.ndarray, q: np.ndarray, T: float, order: int = DEFAULT_TAYLOR_ORDER, tolerance: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Phi and Q_d as the generated C computes them (module docstring), in numpy.

    The algorithm's model: tests hold it to the exact exponential, and the C
    to it.  ModelError for a non-finite or non-positive T, non-finite F, G, q,
    a negative q, or an e^{M T} that is not representable.
    """
    T = check_step(T)
    F, G, q = (np.asarray(a, dtype=float) for a in (F, G, q))
    if not (np.all(np.isfinite(F)) and np.all(np.isfinite(G)) and np.all(np.isfinite(q))):
        raise ModelError("discretize: F, G or q has a non-finite entry")
    if np.any(q < 0.0):
        raise ModelError("discretize: q has a negative noise PSD")
    s, m = van_loan_plan(F, G, q, T, order, tolerance)
    n = F.shape[0]
    h = math.ldexp(T, -s)
    W = (G * q) @ G.T
    B, C = np.zeros((n, n)), np.eye(n)  # the terms of the upper-right and lower-right blocks
    S, phi_t = np.zeros((n, n)), np.eye(n)  # their sums: E12(h) and E22(h) = Phi(h)^T
    for k in range(1, m + 1):
        A = (-1.0) ** (k - 1) * C.T  # A_(k-1) = (-F h)^(k-1) / (k-1)!
        B = (A @ W + B @ F.T) * (h / k)
        C = (C @ F.T) * (h / k)
        S = S + B
        phi_t = phi_t + C
    phi = phi_t.T
    with np.errstate(over="ignore", invalid="ignore"):
        qd = np.triu(phi @ S)
        qd = qd + np.triu(qd, 1).T
        for _ in range(s):
            qd = np.triu(qd + (phi @ qd) @ phi.T)
            qd = qd + np.triu(qd, 1).T
            phi = phi @ phi
    if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(qd))):
        raise ModelError(f"discretize: e^(M T) overflows at T = {T!r} (is the operating point singular?)")
    return phi, qd


def van_loan_costs(structure: FilterStructure, order: int) -> tuple[OperationCount, OperationCount]:
    """(series at ``order``, Q_d(h), W and the balancing; one doubling): flops of the generated C's loops.

    Divisions count as multiplications.  W: a G diag(q) G^T per row.  The
    balancing: up to 8 sweeps and the final norm, each over the off-diagonal
    nonzeros of F (twice: -F and F^T, a multiplication and a division each)
    and every entry of W.  Per order of the series and row: a G diag(+-q) G^T
    (2 nnz_G + 2 nw multiplications), B F^T and C F^T (nnz_F each), the
    scaling by h / k and the sums (N each).  Q_d(h) = Phi(h) E12 over the
    upper triangle; a doubling is Phi Q_d, the upper triangle of
    (Phi Q_d) Phi^T + Q_d and Phi^2.
    """
    n = structure.n_states
    nnz_f, nnz_g, nw = int(structure.F.sum()), int(structure.G.sum()), structure.G.shape[1]
    off = nnz_f - int(np.trace(structure.F.astype(int)))
    pairs = n * (n + 1) // 2
    w_mul, w_add = n * (2 * nnz_g + nw), n * 2 * nnz_g
    sweep_mul, sweep_add = 8 * off + 2 * n * n, 4 * off + 2 * n * n
    mul = w_mul + 9 * sweep_mul + order * (n * (2 * nnz_g + 2 * nw + 2 * nnz_f + 2 * n) + 1) + pairs * n
    add = w_add + 9 * sweep_add + order * n * (2 * nnz_g + 2 * nnz_f + 2 * n) + pairs * n
    doubling = OperationCount(2 * n**3 + pairs * n, 2 * n**3 + pairs * n)
    return OperationCount(mul, add), doubling
