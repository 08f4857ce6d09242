"""The process noise of the unrolled discretize: S G over Gamma's pattern, then Q_d = T (S G) diag(q) (S G)^T.

The paper's Gamma (Q/T) Gamma^T with Gamma = T S G, over the upper-triangle
pairs of Q_d that can be nonzero, one checked function per row; the UD form
keeps Gamma = T S G and the weights instead.  A row of random constants (a
unit row of Phi, S = e_i) reads G directly, so the blocks serve an F with no
nonzero entry too (a random-walk clock).
"""

from __future__ import annotations

from modelgen.codegen.discretize_kernels.plan import DiscretizeBlock, DiscretizePlan, entry_index, local, s_ref
from modelgen.codegen.kernels import Assign, CheckedAssign, KernelBlock, Ref
from modelgen.codegen.layout import packed_index

def noise_blocks(plan: DiscretizePlan, packed: bool, ud: bool) -> list[DiscretizeBlock]:
    """S G over Gamma's pattern, then Q_d = T (S G) diag(q) (S G)^T (or Gamma = T S G for the UD form).

    ``process_noise`` scales (S G) by T q and sets the entries of Q_d that no
    pair reaches to zero (straight-line stores that gcc pairs into vector
    stores, where a loop becomes ``rep stos``); each ``process_noise_row_i``
    then sets row i's pairs and is checked: it returns 0 when the sum of its
    values, read back after its stores, is finite (discretize rescans Q_d
    entry by entry when one is not: an overflow of finite values).
    """
    structure = plan.structure
    n = structure.n_states
    unit = set(structure.unit_rows)
    active = entry_index(plan.active)
    g_entries = structure.entries("G")
    g_cols: dict[int, list[tuple[int, int]]] = {}
    for e, (c, w) in enumerate(g_entries):
        g_cols.setdefault(w, []).append((c, e))
    gamma = entry_index(plan.gamma_entries)
    lines: list = []
    for g, (i, w) in enumerate(plan.gamma_entries):
        terms = []
        for c, e in g_cols.get(w, []):
            if i in unit:
                if c == i:
                    terms.append((Ref("matrices", "G", (e,)),))
            elif (i, c) in active:
                terms.append((s_ref(plan, i, c), Ref("matrices", "G", (e,))))
        lines.append(Assign(Ref("scratch", "term", (0, g)), tuple(terms)))
    blocks = [DiscretizeBlock(KernelBlock("noise_input", tuple(lines)))]
    if ud:
        lines = [
            Assign(Ref("transition", "Gamma", (i, w)), ((local("T"), Ref("scratch", "term", (0, g))),))
            for g, (i, w) in enumerate(plan.gamma_entries)
        ]
        blocks.append(DiscretizeBlock(KernelBlock("noise_input_times_step", tuple(lines)), (), ("T",)))
        return blocks
    base = len(plan.gamma_entries)  # T q_w once per noise, after the values (S G) T q_w
    noises = sorted({w for _, w in plan.gamma_entries})
    lines = [Assign(Ref("scratch", "term", (1, base + w)), ((local("T"), Ref("matrices", "q", (w,))),)) for w in noises]
    lines += [
        Assign(Ref("scratch", "term", (1, g)), ((Ref("scratch", "term", (0, g)), Ref("scratch", "term", (1, base + w))),))
        for g, (i, w) in enumerate(plan.gamma_entries)
    ]
    by_row: dict[int, list[int]] = {}
    for i, w in plan.gamma_entries:
        by_row.setdefault(i, []).append(w)
    rows: dict[int, list[CheckedAssign]] = {}
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
        rows.setdefault(i, []).append(CheckedAssign(targets, terms))
    written = {t.index for row in rows.values() for s in row for t in s.targets}
    every = [(k,) for k in range(n * (n + 1) // 2)] if packed else [(i, j) for i in range(n) for j in range(n)]
    lines += [Assign(Ref("transition", "Qd", index), ()) for index in every if index not in written]  # the rest of Q_d: zero stores
    blocks.append(DiscretizeBlock(KernelBlock("process_noise", tuple(lines)), (), ("T",)))
    # Q_d row by row, each its own function (as the prediction's rows): inside one function of every
    # row gcc -O2 spills its vector registers; its values are summed after its stores (read_back)
    blocks += [
        DiscretizeBlock(KernelBlock(f"process_noise_row_{i}", tuple(row), checked=True, read_back=True, two_lanes=True))
        for i, row in sorted(rows.items())
    ]
    return blocks
