"""discretize as straight-line code that follows the structure of F, Phi, Gamma and Q_d.

The Taylor series of modelgen.derive.discretization is summed over
compressed storage: the k-th power B_k = (F h)^k is kept only at the
structural nonzeros of F^k (row-major order), which grow with k and saturate
at the closure (the fill-in of Phi; for the paper's model 32, 53, 70, 72 of
324 entries), so each order multiplies only where a product can be nonzero:

    B_1 = F h,   B_k(i, j) = sum over c of (F h)(i, c) B_{k-1}(c, j),
    Phi += B_k / k!,   S += B_k / (k + 1)!,

with 1/k! and 1/(k+1)! compile-time constants (no division in the series).
Rows of F that are empty (random constants) give rows e_i of Phi and S and
appear in no sum.  Each order is one small function; discretize calls order
k only when the accuracy rule asked for it (``taylor_plan``), so one
generated file serves every step T.  The doublings
Phi(2h) = Phi(h)^2 and S(2h) = (S(h) + Phi(h) S(h)) / 2 run over the active
entries of Phi (rows that are not e_i) with the same structure.  Then
S G (the pattern of Gamma), and Q_d = T (S G) diag(q) (S G)^T over the
upper-triangle pairs that can be nonzero, which is the paper's
Gamma (Q/T) Gamma^T with Gamma = T S G.

The scratch is compressed too: two term arrays of the largest pattern (they
also hold the doubling's new values and S G), S over the active entries,
F h, and the balancing's three vectors, far below the two N x N arrays of
the filter's own scratch (the workspace union keeps the larger).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from modelgen.codegen.kernels import Assign, CheckedAssign, KernelBlock, OperationCount, Ref
from modelgen.codegen.layout import packed_index
from modelgen.codegen.structure import FilterStructure

#: Scalars a discretize block receives by value (printed as the parameter's name).
LOCAL = "local"


def _local(name: str) -> Ref:
    return Ref(LOCAL, name, ())


@dataclass(frozen=True)
class DiscretizeBlock:
    """One generated function of the unrolled discretize.

    ``block`` holds the statements; ``constants`` the compile-time scalars it
    names (name, exact rational as numerator/denominator); ``scalars`` the
    run-time scalars it takes by value (``h``, ``T``).
    """

    block: KernelBlock
    constants: tuple[tuple[str, int, int], ...] = ()
    scalars: tuple[str, ...] = ()


def _index(entries: list[tuple[int, int]]) -> dict[tuple[int, int], int]:
    return {entry: k for k, entry in enumerate(entries)}


def _pattern_entries(pattern: np.ndarray) -> list[tuple[int, int]]:
    return [(int(i), int(j)) for i, j in zip(*np.nonzero(pattern))]


@dataclass(frozen=True)
class DiscretizePlan:
    """The compressed patterns of the unrolled discretize, for one structure and highest order."""

    structure: FilterStructure
    order: int

    @cached_property
    def f_entries(self) -> list[tuple[int, int]]:
        return self.structure.entries("F")

    @cached_property
    def powers(self) -> list[list[tuple[int, int]]]:
        """Structural nonzeros of F^k, k = 1..order, row-major (index 0 is F itself)."""
        step = self.structure.F.astype(np.int64)
        power = step.copy()
        out = [_pattern_entries(power > 0)]
        for _ in range(2, self.order + 1):
            power = ((step @ (power > 0).astype(np.int64)) > 0).astype(np.int64)
            out.append(_pattern_entries(power > 0))
        return out

    @cached_property
    def active(self) -> list[tuple[int, int]]:
        """Entries of Phi (and S) in rows that are not e_i, row-major."""
        unit = set(self.structure.unit_rows)
        return [(i, j) for i, j in self.structure.entries("Phi") if i not in unit]

    @cached_property
    def gamma_entries(self) -> list[tuple[int, int]]:
        return self.structure.entries("Gamma")

    @cached_property
    def qd_pairs(self) -> list[tuple[int, int]]:
        return [(i, j) for i, j in self.structure.entries("Qd") if i <= j]

    @property
    def term_size(self) -> int:
        """Entries of each of the two term arrays: the largest power, the active entries, S G."""
        return max([len(p) for p in self.powers[1:]] + [len(self.active), len(self.gamma_entries), 1])

    @property
    def active_size(self) -> int:
        return max(len(self.active), 1)


def _term(order: int, index: int) -> Ref:
    """B_order at its compressed index: F h for order 1, then the two term arrays in turn."""
    if order == 1:
        return Ref("scratch", "fh", (index,))
    return Ref("scratch", "term", (order % 2, index))


def _phi(i: int, j: int) -> Ref:
    return Ref("transition", "Phi", (i, j))


def _s(active: dict[tuple[int, int], int], unit: set[int], i: int, j: int) -> Ref | None:
    """S(i, j): compressed in an active row, None (meaning delta_ij) in a unit row."""
    return Ref("scratch", "S", (active[(i, j)],)) if i not in unit else None


def series_blocks(plan: DiscretizePlan) -> list[DiscretizeBlock]:
    """One block per order: B_k, Phi += B_k / k!, S += B_k / (k + 1)!."""
    f_index = plan.f_entries
    active = _index(plan.active)
    blocks = []
    # order 1: F h, S = I + F h / 2 over the active entries, Phi += F h
    lines: list = [Assign(Ref("scratch", "fh", (e,)), ((Ref("matrices", "F", (e,)), _local("h")),)) for e in range(len(f_index))]
    in_f = _index(f_index)
    for a, (i, j) in enumerate(plan.active):
        terms = [(_local("one"),)] if i == j else []
        if (i, j) in in_f:
            terms.append((_term(1, in_f[(i, j)]), _local("c2")))
        lines.append(Assign(Ref("scratch", "S", (a,)), tuple(terms)))
    for e, (i, j) in enumerate(f_index):
        lines.append(Assign(_phi(i, j), ((_phi(i, j),), (_term(1, e),))))
    blocks.append(DiscretizeBlock(KernelBlock("taylor_order_1", tuple(lines)), (("one", 1, 1), ("c2", 1, 2)), ("h",)))
    f_rows: dict[int, list[tuple[int, int]]] = {}
    for e, (i, c) in enumerate(f_index):
        f_rows.setdefault(i, []).append((c, e))
    for k in range(2, plan.order + 1):
        previous = _index(plan.powers[k - 2])
        lines = []
        for p, (i, j) in enumerate(plan.powers[k - 1]):
            terms = tuple(
                (Ref("scratch", "fh", (e,)), _term(k - 1, previous[(c, j)])) for c, e in f_rows.get(i, []) if (c, j) in previous
            )
            lines.append(Assign(_term(k, p), terms))
        for p, (i, j) in enumerate(plan.powers[k - 1]):
            lines.append(Assign(_phi(i, j), ((_phi(i, j),), (_term(k, p), _local("ck")))))
            lines.append(Assign(Ref("scratch", "S", (active[(i, j)],)), ((Ref("scratch", "S", (active[(i, j)],)),), (_term(k, p), _local("cs")))))
        constants = (("ck", 1, math.factorial(k)), ("cs", 1, math.factorial(k + 1)))
        blocks.append(DiscretizeBlock(KernelBlock(f"taylor_order_{k}", tuple(lines)), constants))
    return blocks


def doubling_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """Phi(2h) = Phi(h)^2 and S(2h) = (S(h) + Phi(h) S(h)) / 2 over the active entries, then committed."""
    unit = set(plan.structure.unit_rows)
    active = _index(plan.active)
    rows: dict[int, list[int]] = {}
    for i, c in plan.active:
        rows.setdefault(i, []).append(c)
    lines: list = []
    for a, (i, j) in enumerate(plan.active):
        phi_terms, psi_terms = [], [(Ref("scratch", "S", (a,)),)]
        for c in rows[i]:
            if c in unit:  # row c of Phi and of S is e_c
                if c == j:
                    phi_terms.append((_phi(i, c),))
                    psi_terms.append((_phi(i, c),))
                continue
            if (c, j) in active:
                phi_terms.append((_phi(i, c), _phi(c, j)))
                psi_terms.append((_phi(i, c), _s(active, unit, c, j)))
        lines.append(Assign(Ref("scratch", "term", (0, a)), tuple(phi_terms)))
        lines.append(Assign(Ref("scratch", "term", (1, a)), tuple(psi_terms)))
    for a, (i, j) in enumerate(plan.active):
        lines.append(Assign(_phi(i, j), ((Ref("scratch", "term", (0, a)),),)))
        lines.append(Assign(Ref("scratch", "S", (a,)), ((_local("half"), Ref("scratch", "term", (1, a))),)))
    return DiscretizeBlock(KernelBlock("doubling", tuple(lines)), (("half", 1, 2),))


def noise_blocks(plan: DiscretizePlan, packed: bool, ud: bool) -> list[DiscretizeBlock]:
    """S G over Gamma's pattern, then Q_d = T (S G) diag(q) (S G)^T (or Gamma = T S G for the UD form).

    The Q_d block is checked: it returns the sum of v - v over its values.
    """
    structure = plan.structure
    n = structure.n_states
    unit = set(structure.unit_rows)
    active = _index(plan.active)
    g_entries = structure.entries("G")
    g_cols: dict[int, list[tuple[int, int]]] = {}
    for e, (c, w) in enumerate(g_entries):
        g_cols.setdefault(w, []).append((c, e))
    gamma = _index(plan.gamma_entries)
    lines: list = []
    for g, (i, w) in enumerate(plan.gamma_entries):
        terms = []
        for c, e in g_cols.get(w, []):
            if i in unit:
                if c == i:
                    terms.append((Ref("matrices", "G", (e,)),))
            elif (i, c) in active:
                terms.append((_s(active, unit, i, c), Ref("matrices", "G", (e,))))
        lines.append(Assign(Ref("scratch", "term", (0, g)), tuple(terms)))
    blocks = [DiscretizeBlock(KernelBlock("noise_input", tuple(lines)))]
    if ud:
        lines = [
            Assign(Ref("transition", "Gamma", (i, w)), ((_local("T"), Ref("scratch", "term", (0, g))),))
            for g, (i, w) in enumerate(plan.gamma_entries)
        ]
        blocks.append(DiscretizeBlock(KernelBlock("noise_input_times_step", tuple(lines)), (), ("T",)))
        return blocks
    lines = [
        Assign(Ref("scratch", "term", (1, g)), ((Ref("scratch", "term", (0, g)), _local("T"), Ref("matrices", "q", (w,))),))
        for g, (i, w) in enumerate(plan.gamma_entries)
    ]
    by_row: dict[int, list[int]] = {}
    for i, w in plan.gamma_entries:
        by_row.setdefault(i, []).append(w)
    for i, j in plan.qd_pairs:
        terms = tuple(
            (Ref("scratch", "term", (1, gamma[(i, w)])), Ref("scratch", "term", (0, gamma[(j, w)])))
            for w in by_row.get(i, [])
            if (j, w) in gamma
        )
        if packed:
            targets = (Ref("transition", "Qd", (packed_index(n, i, j),)),)
        else:
            targets = (Ref("transition", "Qd", (i, j)),) + ((Ref("transition", "Qd", (j, i)),) if i != j else ())
        lines.append(CheckedAssign(targets, terms))
    blocks.append(DiscretizeBlock(KernelBlock("process_noise", tuple(lines), checked=True), (), ("T",)))
    return blocks


def transition_check_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """The sum of v - v over the active entries of Phi (0 when all are finite)."""
    lines = [CheckedAssign((_phi(i, j),), ((_phi(i, j),),)) for i, j in plan.active]
    return DiscretizeBlock(KernelBlock("transition_check", tuple(lines), checked=True))


def unrolled_discretize_cost(plan: DiscretizePlan, ud: bool) -> tuple[OperationCount, OperationCount, list[int]]:
    """(flops at the highest order without doubling, flops of one doubling, flops of each order k >= 2).

    Counted from the emitted statements, so that the header states what the
    code does (the balancing's sweeps, at most 8 over the off-diagonal
    entries of F, and the plan's bound are included in the first count).
    """
    def count(blocks: list[DiscretizeBlock]) -> OperationCount:
        mul = add = 0
        for b in blocks:
            for s in b.block.statements:
                terms = s.terms
                mul += sum(len(t) - 1 for t in terms)
                add += max(len(terms) - 1, 0)
        return OperationCount(mul, add)

    series = series_blocks(plan)
    per_order = [count([b]).total for b in series[1:]]
    total = count(series + noise_blocks(plan, packed=False, ud=ud))
    structure = plan.structure
    nnz_f = int(structure.F.sum())
    off = nnz_f - int(np.trace(structure.F.astype(int)))
    balancing = OperationCount(8 * 2 * off + nnz_f, 8 * 2 * off + nnz_f) if nnz_f else OperationCount(0, 0)
    bound = OperationCount(3 * plan.order + 6, plan.order + 2)
    first = OperationCount(total.multiplications + balancing.multiplications + bound.multiplications,
                           total.additions + balancing.additions + bound.additions)
    return first, count([doubling_block(plan)]), per_order
