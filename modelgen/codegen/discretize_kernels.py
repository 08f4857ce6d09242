"""discretize as straight-line code that follows the structure of F, Phi, Gamma and Q_d.

The Taylor series of modelgen.derive.discretization is summed by Horner's
rule over compressed storage, A = F h:

    R_m = I / (m+1)!,   R_k = I / (k+1)! + A R_(k+1),   S = R_0,   E = Phi - I = A S,

so each order is one sparse product A R_(k+1) and the constants 1/(k+1)!
land on the diagonal only (no per-entry scaling, no Phi += / S += sums).
R_(m-j) has the pattern of I + F + ... + F^j, which grows with j and
saturates at the closure (the fill-in of Phi; for the paper's model 59, 98,
112 entries in the rows that are not e_i), so there is one function per level
until the pattern stops growing and one saturated function for every further
level, each in two copies (R_k into S for even k, into the second term array
for odd k, so that S = R_0 lands in S).  The order m is chosen at run time by
the accuracy rule (``taylor_plan``): the chain starts at level 1 with the
coefficients 1/(k+1)! read from a static table, so one generated file serves
every step T.  Rows of F that are empty (random constants) give rows e_i of
Phi and S and appear in no sum (their R_k(c, c) = 1/(k+1)! is a scalar).

The doublings E(2h) = 2 E + E^2 and S(2h) = S + E S / 2 run over the active
entries of Phi (rows that are not e_i) with the same structure; working on
E = Phi - I keeps the small part of Phi(h) that adding I would round away
(in float, s times over).  The identity is added at the end.  Then S G (the
pattern of Gamma), and Q_d = T (S G) diag(q) (S G)^T over the upper-triangle
pairs that can be nonzero, which is the paper's Gamma (Q/T) Gamma^T with
Gamma = T S G.

The scratch is compressed too: two arrays of the active entries (S and the
odd levels; the doubling's new values; S G), F h, and the balancing's two
vectors, far below the two N x N arrays of the filter's own scratch (the
workspace union keeps the larger).
"""

from __future__ import annotations

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
    def horner_patterns(self) -> list[list[tuple[int, int]]]:
        """Structural nonzeros of R_(m-j), j = 1..J, in the rows that are not e_i (row-major).

        R_(m-j) = sum_(i=0..j) A^i / (m-j+i+1)! has the pattern of I + F + ... + F^j;
        the last pattern is the first that the next level leaves unchanged (the
        closure, Phi's fill-in), which every further level keeps.
        """
        n = self.structure.n_states
        unit = set(self.structure.unit_rows)
        step = self.structure.F.astype(np.int64)
        identity = np.eye(n, dtype=bool)
        pattern = identity
        out: list[list[tuple[int, int]]] = []
        while True:
            pattern = identity | ((step @ pattern.astype(np.int64)) > 0)
            entries = [(i, j) for i, j in _pattern_entries(pattern) if i not in unit]
            if out and entries == out[-1]:
                return out
            out.append(entries)

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
        """Entries of each of the two term arrays: the odd levels of the chain and the doubling's new values (active entries), S G."""
        return max(len(self.active), len(self.gamma_entries), 1)

    @property
    def active_size(self) -> int:
        return max(len(self.active), 1)


def _phi(i: int, j: int) -> Ref:
    return Ref("transition", "Phi", (i, j))


def _s(active: dict[tuple[int, int], int], unit: set[int], i: int, j: int) -> Ref | None:
    """S(i, j): compressed in an active row, None (meaning delta_ij) in a unit row."""
    return Ref("scratch", "S", (active[(i, j)],)) if i not in unit else None


def _horner_array(parity: int, index: int) -> Ref:
    """Where R_k lives at a compressed (active) index: S for even k (so that S = R_0 lands there), term[1] for odd k."""
    return Ref("scratch", "S", (index,)) if parity == 0 else Ref("scratch", "term", (1, index))


def _f_rows(plan: DiscretizePlan) -> dict[int, list[tuple[int, int]]]:
    """Row i of F as (column, index of the entry in F's storage) pairs."""
    rows: dict[int, list[tuple[int, int]]] = {}
    for e, (i, c) in enumerate(plan.f_entries):
        rows.setdefault(i, []).append((c, e))
    return rows


def horner_input_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """A = F h at the nonzeros of F (the only run-time scaling of the series)."""
    lines = tuple(Assign(Ref("scratch", "fh", (e,)), ((Ref("matrices", "F", (e,)), _local("h")),)) for e in range(len(plan.f_entries)))
    return DiscretizeBlock(KernelBlock("horner_input", lines), (), ("h",))


def horner_level_name(level: int, parity: int, saturated: bool = False) -> str:
    """The function computing R_k at distance ``level`` below the top order (or any level past saturation), into S (k even) or term (k odd)."""
    into = "S" if parity == 0 else "term"
    return f"horner_saturated_into_{into}" if saturated else f"horner_level_{level}_into_{into}"


def horner_level_block(plan: DiscretizePlan, level: int, parity: int, saturated: bool = False) -> DiscretizeBlock:
    """R_k = c_out I + A R_(k+1) over the pattern of R_k, for k = m - ``level`` of parity ``parity``.

    ``c_out`` = 1/(k+1)! and ``c_in`` = 1/(k+2)! are passed at run time (the
    order m is chosen at run time); ``c_in`` is the value of R_(k+1) on the
    rows of random constants (and everywhere on its diagonal at level 1,
    where R_(k+1) = R_m = c_in I is not stored).  Level ``level`` reads the
    pattern of level - 1 only; the saturated block reads and writes the
    closure.  Written into S, the active entries outside the pattern are set
    to zero, so that S is complete whatever order the chain stopped at.
    """
    patterns = plan.horner_patterns
    unit = set(plan.structure.unit_rows)
    active = _index(plan.active)
    out_pattern = patterns[-1] if saturated else patterns[level - 1]
    in_pattern = set(patterns[-1] if saturated else (patterns[level - 2] if level >= 2 else ()))
    f_rows = _f_rows(plan)
    lines: list = []
    for i, j in out_pattern:
        terms: list[tuple[Ref, ...]] = [(_local("c_out"),)] if i == j else []
        for c, e in f_rows.get(i, []):
            a = Ref("scratch", "fh", (e,))
            if c in unit or (level == 1 and not saturated):  # R_(k+1) is c_in there on the diagonal, zero elsewhere
                if c == j:
                    terms.append((a, _local("c_in")))
            elif (c, j) in in_pattern:
                terms.append((a, _horner_array(1 - parity, active[(c, j)])))
        lines.append(Assign(_horner_array(parity, active[(i, j)]), tuple(terms)))
    if parity == 0:
        written = set(out_pattern)
        lines += [Assign(_horner_array(0, a), ()) for a, entry in enumerate(plan.active) if entry not in written]
    used = {r.array for line in lines for term in line.terms for r in term if r.owner == LOCAL}
    scalars = tuple(name for name in ("c_out", "c_in") if name in used)  # c_in is unused where no row reaches a random constant
    return DiscretizeBlock(KernelBlock(horner_level_name(level, parity, saturated), tuple(lines)), (), scalars)


def horner_transition_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """E = Phi - I = A S over the active entries, into Phi (S = 1 on the diagonal of a row of random constants).

    The identity is added after the doublings (:func:`doubling_block`).
    """
    unit = set(plan.structure.unit_rows)
    active = _index(plan.active)
    f_rows = _f_rows(plan)
    lines = []
    for i, j in plan.active:
        terms: list[tuple[Ref, ...]] = []
        for c, e in f_rows.get(i, []):
            a = Ref("scratch", "fh", (e,))
            if c in unit:
                if c == j:
                    terms.append((a,))
            elif (c, j) in active:
                terms.append((a, _horner_array(0, active[(c, j)])))
        lines.append(Assign(_phi(i, j), tuple(terms)))
    return DiscretizeBlock(KernelBlock("horner_transition", tuple(lines)))


def series_blocks(plan: DiscretizePlan) -> list[DiscretizeBlock]:
    """The Horner chain: A = F h, levels 1..J into either array, the saturated level into either, then Phi = I + A S."""
    blocks = [horner_input_block(plan)]
    for level in range(1, len(plan.horner_patterns) + 1):
        blocks += [horner_level_block(plan, level, parity) for parity in (0, 1)]
    blocks += [horner_level_block(plan, 0, parity, saturated=True) for parity in (0, 1)]
    return blocks + [horner_transition_block(plan)]


def horner_schedule(plan: DiscretizePlan, order: int) -> list[str]:
    """The level functions an order-``order`` chain calls, top (k = order - 1) to bottom (k = 0)."""
    levels = len(plan.horner_patterns)
    return [horner_level_name(min(order - k, levels + 1), k % 2, order - k > levels) for k in range(order - 1, -1, -1)]


def doubling_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """E(2h) = 2 E(h) + E(h)^2 and S(2h) = S(h) + E(h) S(h) / 2 over the active entries, then committed.

    E = Phi - I: Phi(2h) = Phi(h)^2 and S(2h) = (S(h) + Phi(h) S(h)) / 2
    without adding the identity, whose rounding would swamp the small part of
    Phi(h) (in float, 2^s times over).  A row of random constants is zero in
    E and e_c in S.
    """
    unit = set(plan.structure.unit_rows)
    active = _index(plan.active)
    rows: dict[int, list[int]] = {}
    for i, c in plan.active:
        rows.setdefault(i, []).append(c)
    lines: list = []
    for a, (i, j) in enumerate(plan.active):
        square, product = [], []
        for c in rows[i]:
            if c in unit:  # row c of E is zero, of S e_c
                if c == j:
                    product.append((_phi(i, c),))
                continue
            if (c, j) in active:
                square.append((_phi(i, c), _phi(c, j)))
                product.append((_phi(i, c), _s(active, unit, c, j)))
        lines.append(Assign(Ref("scratch", "term", (0, a)), tuple(square)))
        lines.append(Assign(Ref("scratch", "term", (1, a)), tuple(product)))
    for a, (i, j) in enumerate(plan.active):
        lines.append(Assign(_phi(i, j), ((_phi(i, j),), (_phi(i, j),), (Ref("scratch", "term", (0, a)),))))
        lines.append(Assign(Ref("scratch", "S", (a,)), ((Ref("scratch", "S", (a,)),), (_local("half"), Ref("scratch", "term", (1, a))))))
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
    """The sum of v - v over the active entries of E = Phi - I (0 when all are finite)."""
    lines = [CheckedAssign((_phi(i, j),), ((_phi(i, j),),)) for i, j in plan.active]
    return DiscretizeBlock(KernelBlock("transition_check", tuple(lines), checked=True))


def block_cost(blocks: list[DiscretizeBlock]) -> OperationCount:
    """Multiplications and additions of the emitted statements (a zero fill costs nothing)."""
    mul = add = 0
    for b in blocks:
        for s in b.block.statements:
            mul += sum(len(t) - 1 for t in s.terms)
            add += max(len(s.terms) - 1, 0)
    return OperationCount(mul, add)


def series_block_costs(plan: DiscretizePlan) -> dict[str, OperationCount]:
    """Flops of each function of the Horner chain, by name (built once, then summed per order)."""
    return {b.block.name: block_cost([b]) for b in series_blocks(plan)}


def series_cost(plan: DiscretizePlan, order: int, costs: dict[str, OperationCount] | None = None) -> OperationCount:
    """Flops of Phi and S by the Horner chain of ``order`` (A = F h, the levels it calls, Phi = I + A S).

    ``costs``: :func:`series_block_costs` of ``plan``, when the caller counts several orders.
    """
    costs = series_block_costs(plan) if costs is None else costs
    called = [costs[name] for name in ("horner_input", *horner_schedule(plan, order), "horner_transition")]
    return OperationCount(sum(c.multiplications for c in called), sum(c.additions for c in called))


def unrolled_discretize_cost(plan: DiscretizePlan, ud: bool, fixed_scaling: bool = False) -> tuple[OperationCount, OperationCount, list[int]]:
    """(flops at the highest order without doubling, flops of one doubling, flops of the series at each order 1..N).

    Counted from the emitted statements, so that the header states what the
    code does (the norm and the plan's bound are included in the first count:
    with D fixed at generation time, ``fixed_scaling``, one product and sum
    per nonzero of F; otherwise also the balancing's sweeps, at most 8 over
    the off-diagonal entries of F).
    """
    costs = series_block_costs(plan)
    per_order = [series_cost(plan, m, costs).total for m in range(1, plan.order + 1)]
    series = series_cost(plan, plan.order, costs)
    noise = block_cost(noise_blocks(plan, packed=False, ud=ud))
    structure = plan.structure
    nnz_f = int(structure.F.sum())
    off = nnz_f - int(np.trace(structure.F.astype(int)))
    sweeps = 0 if fixed_scaling else 8 * 2 * off
    balancing = OperationCount(sweeps + nnz_f, sweeps + nnz_f) if nnz_f else OperationCount(0, 0)
    bound = OperationCount(3 * plan.order + 6, plan.order + 2)
    parts = (series, noise, balancing, bound)
    first = OperationCount(sum(c.multiplications for c in parts), sum(c.additions for c in parts))
    return first, block_cost([doubling_block(plan)]), per_order
