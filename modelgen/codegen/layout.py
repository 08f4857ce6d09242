"""Memory layout of the generated C structs, decided once for C and Python (ctypes).

The header template renders these field lists and ``build.CompiledFilter``
rebuilds the same structs with ctypes from them, so the two can never
disagree whatever the options.  Every array has a compile-time size; a
dimension that would be zero (a model without noises or measurements) is
rounded up to one so that the C stays valid.

Packed storage keeps the upper triangle row by row:
``(i, j), i <= j -> i (2N - i - 1) / 2 + j`` (``packed_index``).  The
transition's Q_d is always stored so, whatever P's storage: discretize
writes and predict reads each pair i <= j once, and the transition is
N (N - 1) / 2 entries smaller than a full one.  The UD form
keeps the strictly upper part of U the same way:
``(i, j), i < j -> i (2N - i - 3) / 2 + j - 1`` (``upper_index``).

The transition's Phi is compressed to its structural pattern
(``phi_entries``): the structural nonzeros of e^{F T} (the closure of F's
pattern with the identity, ``modelgen.codegen.structure``), row by row, a
row of random constants holding its diagonal 1 alone.  Every discretization
(Taylor, its doublings, the compact kernels, Van Loan) gives zero elsewhere,
so the other N^2 - nnz entries are not stored; the generated C exports the
(row, column) of each stored entry and expands it for callers
(``<prefix>_get_transition_matrix``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.structure import reachability


@dataclass(frozen=True)
class ModelSizes:
    """The sizes that fix every struct: states, noises, measurements, nonzeros."""

    n: int
    nw: int
    nm: int
    nnz_f: int
    nnz_g: int
    nnz_h: int
    nnz_phi: int  # structural nonzeros of Phi, the entries of the transition's compressed Phi

    @classmethod
    def of(cls, derived) -> "ModelSizes":
        """Sizes of a ``DerivedModel``."""
        return cls(
            n=derived.n_states,
            nw=derived.n_noises,
            nm=derived.n_measurements,
            nnz_f=int(np.count_nonzero(derived.structure("F"))),
            nnz_g=int(np.count_nonzero(derived.structure("G"))),
            nnz_h=int(np.count_nonzero(derived.structure("H"))),
            nnz_phi=int(np.count_nonzero(reachability(derived.structure("F"), derived.n_states))),
        )

    @property
    def packed(self) -> int:
        return self.n * (self.n + 1) // 2

    @property
    def upper(self) -> int:
        return self.n * (self.n - 1) // 2


def phi_entries(pattern: np.ndarray) -> list[tuple[int, int]]:
    """(row, column) of each stored entry of the transition's Phi, in storage order (row-major)."""
    return [(int(i), int(j)) for i, j in zip(*np.nonzero(np.asarray(pattern, dtype=bool)))]


def phi_positions(pattern: np.ndarray) -> dict[tuple[int, int], int]:
    """Storage index of each structural nonzero (i, j) of Phi (``phi_entries``' order)."""
    return {entry: k for k, entry in enumerate(phi_entries(pattern))}


def packed_index(n: int, i: int, j: int) -> int:
    """Index of (i, j) of a symmetric N x N matrix in packed upper storage."""
    if i > j:
        i, j = j, i
    return i * (2 * n - i - 1) // 2 + j


def upper_index(n: int, i: int, j: int) -> int:
    """Index of U(i, j), i < j, in packed strictly-upper storage."""
    if not i < j:
        raise ValueError(f"U({i}, {j}) is not strictly upper")
    return i * (2 * n - i - 3) // 2 + j - 1


@dataclass(frozen=True)
class Dim:
    """One array dimension: its symbolic name (the generated size macro where one exists) and its value."""

    text: str
    value: int


@dataclass(frozen=True)
class Field:
    """One struct member: scalar array of the given dimensions."""

    name: str
    dims: tuple[Dim, ...]
    comment: str = ""



@dataclass(frozen=True)
class CLayout:
    """Members of the matrices, transition, filter and scratch structs.

    The workspace is a union of two scratch structs: the discretization's and
    the filter steps' (predict, update, set_covariance).  They never run at the
    same time, so the caller keeps only the larger of the two.
    """

    matrices: tuple[Field, ...]
    transition: tuple[Field, ...]
    filter: tuple[Field, ...]
    discretize_scratch: tuple[Field, ...]
    filter_scratch: tuple[Field, ...]


@dataclass(frozen=True)
class UnrolledDiscretizeSizes:
    """Compressed scratch of the unrolled discretize (modelgen.codegen.discretize_kernels).

    ``terms``: entries of each of the two term arrays; ``active``: entries of
    S (``DiscretizePlan.segment_size``: each block row's dense segment over
    its span of Phi's pattern, padded to an even length, and one entry per
    diagonal row; the rows e_i are not stored); ``balancing``: whether
    discretize can balance F at run time (F has an off-diagonal entry: with
    no scaling fixed at generation time, or to retake a plan on a fixed D
    that needs a doubling) and so needs the row and column sums.
    """

    terms: int
    active: int
    balancing: bool = True


def _unrolled_discretize_scratch(prefix: str, sizes: ModelSizes, unrolled: UnrolledDiscretizeSizes, N: Dim, nnz_f: Dim) -> tuple[Field, ...]:
    """Members of the unrolled discretize's scratch: compressed terms, S, F h and (run-time balancing) its sums."""
    fields = (
        Field("term", (Dim("2", 2), Dim(f"{prefix}_N_TERMS", unrolled.terms)),
              "the Horner chain's odd levels R_k (term[1]) and F h (term[0], each entry twice); the doubling's new values; S G"),
        Field("S", (Dim(f"{prefix}_N_ACTIVE_ENTRIES", unrolled.active),), "S = sum (F h)^k / (k + 1)! (and the even levels R_k): each block row's dense segment, then the diagonal rows"),
    )
    if not unrolled.balancing:
        return fields
    return fields + (
        Field("row_sum", (N,), "balancing: off-diagonal row sums of D^-1 |F| D"),
        Field("col_sum", (N,), "balancing: off-diagonal column sums of D^-1 |F| D"),
    )


@dataclass(frozen=True)
class CompactDiscretizeSizes:
    """Sizes of the compact discretize's scratch (modelgen.codegen.compact_discretize).

    ``closure``: structural nonzeros of Phi; ``gamma``: of Gamma; ``row``:
    entries of a stored row of R (N rounded up to a multiple of 4).
    """

    closure: int
    gamma: int
    row: int


def _compact_discretize_scratch(sizes: ModelSizes, compact: CompactDiscretizeSizes | None, N: Dim, nnz_f: Dim, ud: bool) -> tuple[Field, ...]:
    """Members of the compact discretize's scratch: two level arrays of N rows (only the spans used), compressed rest.

    Without ``compact`` the compressed sizes are their bounds (N^2, N noises
    per state), so that a caller that only needs the workspace's size gets
    one never smaller than the C's.
    """
    closure = compact.closure if compact else sizes.n * sizes.n
    gamma = compact.gamma if compact else sizes.n * sizes.nw
    width = compact.row if compact else -(-sizes.n // 4) * 4
    n_closure = Dim(str(max(closure, 1)), max(closure, 1))
    n_gamma = Dim(str(max(gamma, 1)), max(gamma, 1))
    row = Dim(str(width), width)
    fields = (
        Field("R", (Dim("2", 2), N, row), "Horner levels R_k over each row's span (k even in R[0], odd in R[1]): S = R_0 in R[0], E = A S in R[1]"),
        Field("fh", (nnz_f,), "A = F h, F's nonzeros in the order of the A_entry table"),
        Field("E_row", (row,), "one row of E^2 (the doubling), over its span"),
        Field("S_row", (row,), "one row of E S (the doubling), over its span"),
        Field("E_next", (n_closure,), "the doubling's new E at the nonzeros of Phi, row by row"),
        Field("S_next", (n_closure,), "the doubling's new S at the nonzeros of Phi, row by row"),
        Field("acc", (N,), "one row of S G or of Q_d, by column"),
        Field("gamma", (n_gamma,), "S G at the nonzeros of Gamma, row by row"),
    )
    if not ud:
        fields += (Field("gamma_q", (n_gamma,), "T S G diag(q) at the nonzeros of Gamma"),)
    return fields + (
        Field("row_sum", (N,), "balancing: off-diagonal row sums of D^-1 |F| D"),
        Field("col_sum", (N,), "balancing: off-diagonal column sums of D^-1 |F| D"),
    )


def _van_loan_scratch(N: Dim, dim_w: Dim) -> tuple[Field, ...]:
    """Members of Van Loan's discretize (modelgen.codegen.van_loan): Phi dense while it is squared, two terms, E12's sum, rows, balancing sums."""
    N2 = Dim(f"2 * {N.text}", 2 * N.value)
    return (
        Field("Phi", (N, N), "Phi(h) dense (E22(h)^T), then its doublings; stored compressed at the end"),
        Field("B", (N, N), "upper-right term B_k of e^{M h}; the doubling's products"),
        Field("C", (N, N), "lower-right term (F^T h)^k / k!; then Q_d of each doubling"),
        Field("S", (N, N), "W, then the sum of the B terms (E12), then the doubling's new Q_d"),
        Field("row", (N,), "one row of a new term"),
        Field("col", (N,), "column i of C: row i of the upper-left term"),
        Field("g", (dim_w,), "one row times G diag(q)"),
        Field("scale", (N2,), "balancing: d of ||M||_D = ||D^-1 M D||"),
        Field("row_sum", (N2,), "balancing: off-diagonal row sums of D^-1 |M| D"),
        Field("col_sum", (N2,), "balancing: off-diagonal column sums of D^-1 |M| D"),
    )


def _recompute_fields(options: CodegenOptions, nnz_f: Dim, dim_g: Dim, dim_w: Dim) -> tuple[Field, ...]:
    """The inputs the transition was computed from, when discretize may keep it (``recompute_threshold``)."""
    if options.recompute_threshold is None:
        return ()
    return (
        Field("F_used", (nnz_f,), "F the transition was computed from"),
        Field("G_used", (dim_g,), "G the transition was computed from"),
        Field("q_used", (dim_w,), "q the transition was computed from"),
        Field("T_used", (Dim("1", 1),), "the step it was computed for; 0 (a zeroed struct) means none yet"),
    )


def c_layout(
    sizes: ModelSizes,
    options: CodegenOptions,
    prefix: str,
    unrolled: UnrolledDiscretizeSizes | None = None,
    compact: CompactDiscretizeSizes | None = None,
) -> CLayout:
    """The struct members for ``options``; ``prefix`` is the upper-case model name.

    ``unrolled`` (the header's case for models below the compact-kernel
    threshold) gives discretize its compressed scratch; ``compact`` (above it)
    the sizes of the compact discretize's compressed arrays.  Without either
    the scratch is the compact one at its bounds, never smaller, so a caller
    that only needs the workspace's size (``build.CompiledFilter``, which
    passes it to C and never reads it) may leave them out.
    """
    N = Dim(f"{prefix}_N_STATES", sizes.n)
    NP = Dim(f"{prefix}_N_PACKED", sizes.packed)
    NU = Dim(f"{prefix}_N_UPPER", max(sizes.upper, 1))
    NWT = Dim(f"{prefix}_N_WEIGHTS", sizes.n + sizes.nw)
    nnz_f = Dim(f"{prefix}_NNZ_F", sizes.nnz_f) if sizes.nnz_f else Dim("1", 1)  # C has no zero-size arrays
    dim_g = Dim(str(max(sizes.nnz_g, 1)), max(sizes.nnz_g, 1))
    dim_h = Dim(str(max(sizes.nnz_h, 1)), max(sizes.nnz_h, 1))
    dim_w = Dim(str(max(sizes.nw, 1)), max(sizes.nw, 1))
    dim_m = Dim(str(max(sizes.nm, 1)), max(sizes.nm, 1))
    symmetric = (NP,) if options.packed else (N, N)
    phi = Field("Phi", (Dim(f"{prefix}_N_PHI", max(sizes.nnz_phi, 1)),),
                f"transition matrix, its structural nonzeros row by row: entry k is (i, j) = ({prefix.lower()}_Phi_row[k], "
                f"{prefix.lower()}_Phi_col[k]), every other entry is 0 ({prefix.lower()}_get_transition_matrix expands it)")

    matrices = (
        Field("F", (nnz_f,)),
        Field("G", (dim_g,)),
        Field("q", (dim_w,), "continuous noise PSD, diag(Q)"),
        Field("H", (dim_h,)),
        Field("r", (dim_m,), "measurement variance, diag(R)"),
    )
    if options.ud:
        transition = (
            phi,
            Field("Gamma", (N, dim_w), "noise input matrix of the step"),
            Field("qw", (dim_w,), "discrete noise weights q / T: Q_d = Gamma diag(qw) Gamma^T"),
        ) + _recompute_fields(options, nnz_f, dim_g, dim_w)
        filt = (
            Field("x", (N,)),
            Field("U", (NU,), "strictly upper part of the unit upper triangular U, packed by rows"),
            Field("D", (N,), "diagonal of D: P = U D U^T"),
        )
        discretize_scratch = _compact_discretize_scratch(sizes, compact, N, nnz_f, ud=True)
        if unrolled is not None:
            discretize_scratch = _unrolled_discretize_scratch(prefix, sizes, unrolled, N, nnz_f)
        filter_scratch = (
            Field("W", (N, NWT), "Thornton: [Phi U, Gamma]"),
            Field("Dw", (NWT,), "Thornton: weights [D, qw]"),
            Field("Wd", (NWT,), "Thornton: one row of W times the weights"),
            Field("Un", (NU,)),
            Field("Dn", (N,)),
            Field("xn", (N,)),
            Field("f", (N,), "Bierman: U^T h"),
            Field("v", (N,), "Bierman: D U^T h"),
            Field("b", (N,), "Bierman: unscaled gain"),
            Field("nu0", (dim_m,), "innovation z - H x before the update"),
        )
        return CLayout(matrices, transition, filt, discretize_scratch, filter_scratch)

    qd_kind = "int_0^T e^{F s} G Q G^T e^{F^T s} ds (Van Loan)" if options.van_loan else "Gamma (Q/T) Gamma^T"
    transition = (  # Q_d packed whatever P's storage (module doc)
        phi,
        Field("Qd", (NP,), qd_kind + ", packed upper triangle: (i, j), i <= j, at i (2N - i - 1) / 2 + j"),
    ) + _recompute_fields(options, nnz_f, dim_g, dim_w)
    filt = (
        Field("x", (N,)),
        Field("P", symmetric, "covariance" + (", packed upper triangle" if options.packed else "")),
    )
    discretize_scratch = _compact_discretize_scratch(sizes, compact, N, nnz_f, ud=False)
    if unrolled is not None:
        discretize_scratch = _unrolled_discretize_scratch(prefix, sizes, unrolled, N, nnz_f)
    if options.van_loan:
        discretize_scratch = _van_loan_scratch(N, dim_w)
    filter_scratch = [
        Field("M", (N,), "one row of Phi P (predict works row by row)"),
        Field("Pn", (NP,), "new covariance before it is committed, packed upper triangle"),
        Field("xn", (N,)),
    ]
    if options.update == "vector":
        filter_scratch += [
            Field("HP", (dim_m, N)),
            Field("L", (dim_m, dim_m), "Cholesky factor of the innovation covariance"),
            Field("K", (N, dim_m)),
            Field("C", (N, dim_m), "K S (Joseph form)"),
            Field("S_innovation", (dim_m, dim_m), "innovation covariance H P H^T + R"),
            Field("nu", (dim_m,)),
            Field("y", (dim_m,), "L^-1 nu, for the NIS"),
        ]
    else:
        filter_scratch += [
            Field("ph", (N,), "P h^T of one scalar measurement"),
            Field("k", (N,), "gain of one scalar measurement"),
        ]
    filter_scratch.append(Field("nu0", (dim_m,), "innovation z - H x before the update"))
    return CLayout(matrices, transition, filt, discretize_scratch, tuple(filter_scratch))
