"""The doublings of the unrolled discretize, E(2h) = 2 E + E^2 and S(2h) = S + E S / 2, and the check of Phi.

Working on E = Phi - I keeps the small part of Phi(h) that adding I would
round away (in float, s times over); :func:`transition_check_block` adds the
identity after the doublings and sums the active entries for the finiteness
check.
"""

from __future__ import annotations

from modelgen.codegen.discretize_kernels.plan import DiscretizeBlock, DiscretizePlan, SegmentAssign, local, s_ref
from modelgen.codegen.kernels import Assign, CheckedAssign, KernelBlock, Ref

def _doubling_terms(plan: DiscretizePlan, i: int, j: int, rows: list[int], sparse_only: bool = False) -> tuple[list, list]:
    """The terms of E^2 (i, j) and (E S)(i, j) over row i of E, columns c ascending (``sparse_only``: not the block rows).

    A row c of random constants is zero in E and e_c in S: it adds E(i, c) to
    (E S)(i, c) alone.
    """
    unit = set(plan.structure.unit_rows)
    blocks = set(plan.block_rows)
    active = set(plan.active)
    square, product = [], []
    for c in rows:
        if sparse_only and c in blocks:
            continue
        if c in unit:
            if c == j:
                product.append((plan.phi(i, c),))
            continue
        if (c, j) in active:
            square.append((plan.phi(i, c), plan.phi(c, j)))
            product.append((plan.phi(i, c), s_ref(plan, c, j)))
    return square, product


def _doubling_runs(plan: DiscretizePlan, rows: dict[int, list[int]]) -> list[tuple[int, int]]:
    """Active entries [lo, hi) of one row over which every block row's term moves one entry on in both Phi and S.

    Along such a run the sums over the block rows c of E(i, c) E(c, j) and
    E(i, c) S(c, j) are one fixed-trip loop over consecutive entries (the
    shape gcc -O2 vectorizes); a run ends where a block row's term starts or
    stops, or where its entries of Phi or S are not the next ones (a lone
    column, a structural zero).
    """
    blocks = set(plan.block_rows)
    active = set(plan.active)

    def key(a: int) -> tuple[int, tuple[tuple[int, int, int], ...]]:
        i, j = plan.active[a]
        return i, tuple((c, plan.phi_position[(c, j)], plan.s_position[(c, j)]) for c in rows[i] if c in blocks and (c, j) in active)

    def continues(before, after) -> bool:
        (i0, t0), (i1, t1) = before, after
        return i0 == i1 and bool(t0) and len(t0) == len(t1) and all(
            c0 == c1 and p1 == p0 + 1 and s1 == s0 + 1 for (c0, p0, s0), (c1, p1, s1) in zip(t0, t1))

    keys = [key(a) for a in range(len(plan.active))]
    runs, start = [], 0
    for a in range(1, len(keys) + 1):
        if a == len(keys) or not continues(keys[a - 1], keys[a]):
            runs.append((start, a))
            start = a
    return runs


def doubling_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """E(2h) = 2 E(h) + E(h)^2 and S(2h) = S(h) + E(h) S(h) / 2 over the active entries, then committed.

    E = Phi - I: Phi(2h) = Phi(h)^2 and S(2h) = (S(h) + Phi(h) S(h)) / 2
    without adding the identity, whose rounding would swamp the small part of
    Phi(h) (in float, 2^s times over).  A row of random constants is zero in
    E and e_c in S.  The new values go to the term arrays in the order of
    the active entries: along a run of entries of one row whose block rows'
    terms are consecutive in Phi and S (:func:`_doubling_runs`) the sums
    over the block rows are segment loops, the diagonal rows' and random
    constants' terms added after them (the compact doubling's order: block
    rows first); an entry outside a run is one sum over c ascending.  On the
    32-state augmented model (3 doublings at T = 0.148 s) the loops take the
    doubling from 9.4k to 7.1k instructions per call (callgrind, gcc -O2;
    all the E^2 sums before the E S ones, then the added terms, then the
    commits of Phi and of S).
    """
    rows: dict[int, list[int]] = {}
    for i, c in plan.active:
        rows.setdefault(i, []).append(c)
    blocks, active = set(plan.block_rows), set(plan.active)
    sums: tuple[list, list] = ([], [])  # E^2 and E S: segment loops and whole sums, in the order of the entries
    added: tuple[list, list] = ([], [])  # the diagonal rows' and random constants' terms after the loops
    for lo, hi in _doubling_runs(plan, rows):
        i, j = plan.active[lo]
        if hi - lo == 1:
            for parity, terms in enumerate(_doubling_terms(plan, i, j, rows[i])):
                sums[parity].append(Assign(Ref("scratch", "term", (parity, lo)), tuple(terms)))
            continue
        wide = [c for c in rows[i] if c in blocks and (c, j) in active]
        sums[0].append(SegmentAssign(Ref("scratch", "term", (0, lo)), tuple((plan.phi(i, c), plan.phi(c, j)) for c in wide), hi - lo))
        sums[1].append(SegmentAssign(Ref("scratch", "term", (1, lo)), tuple((plan.phi(i, c), s_ref(plan, c, j)) for c in wide), hi - lo))
        for a in range(lo, hi):
            for parity, terms in enumerate(_doubling_terms(plan, *plan.active[a], rows[i], sparse_only=True)):
                target = Ref("scratch", "term", (parity, a))
                added[parity].extend(Assign(target, ((target,), term)) for term in terms)
    lines: list = sums[0] + sums[1] + added[0] + added[1]
    lines += [Assign(plan.phi(i, j), ((plan.phi(i, j),), (plan.phi(i, j),), (Ref("scratch", "term", (0, a)),)))
              for a, (i, j) in enumerate(plan.active)]
    for a, (i, j) in enumerate(plan.active):
        stored = Ref("scratch", "S", (plan.s_position[(i, j)],))
        lines.append(Assign(stored, ((stored,), (local("half"), Ref("scratch", "term", (1, a))))))
    return DiscretizeBlock(KernelBlock("doubling", tuple(lines)), (("half", 1, 2),))


def transition_check_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """Phi = I + E on the active rows' diagonal, then the sum of the active entries, v - v of it returned (0 when it is finite).

    The identity is added here, after the doublings (E(i, i) + 1 is finite
    exactly where E(i, i) is); the unit rows' diagonal was stored as 1 by
    :func:`horner_transition_block`.  A finite sum means every entry is
    finite (a NaN or an infinity makes it NaN or infinite); a sum that is not
    finite may be an overflow of finite entries, which the C then decides
    entry by entry: one addition per entry instead of two.
    """
    _phi = plan.phi
    lines: list = [Assign(_phi(i, i), ((_phi(i, i),), (local("one"),))) for i, j in plan.active if i == j]
    lines.append(CheckedAssign((Ref("scratch", "term", (0, 0)),), tuple((_phi(i, j),) for i, j in plan.active)))
    return DiscretizeBlock(KernelBlock("transition_check", tuple(lines), checked=True), (("one", 1, 1),))
