"""The Horner chain of the unrolled discretize: A = F h, the levels R_k, S = R_0 and E = Phi - I = A S.

Each level is a function of the generated C (:func:`series_blocks`): the
top level R_(m-1) over its sparse pattern, one dense level for every k below
it (into S for even k, into the second term array for odd k), the copies at
k = 0 and k = 1 where leaf rows or unit columns need them, and E = A S into
the compressed Phi.  :func:`horner_schedule` says which function an order-m
chain calls at each k (the C chooses m at run time).
"""

from __future__ import annotations

from modelgen.codegen.discretize_kernels.plan import LOCAL, DiscretizeBlock, DiscretizePlan, SegmentAssign, local, scalar_statements
from modelgen.codegen.kernels import Assign, KernelBlock, Ref

def horner_array(parity: int, index: int) -> Ref:
    """Where R_k lives at a stored index (:attr:`DiscretizePlan.s_position`): S for even k (so that S = R_0 lands there), term[1] for odd k."""
    return Ref("scratch", "S", (index,)) if parity == 0 else Ref("scratch", "term", (1, index))


def f_row_entries(plan: DiscretizePlan) -> dict[int, list[tuple[int, int]]]:
    """Row i of F as (column, index of the entry in F's storage) pairs."""
    rows: dict[int, list[tuple[int, int]]] = {}
    for e, (i, c) in enumerate(plan.f_entries):
        rows.setdefault(i, []).append((c, e))
    return rows


def horner_input_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """A = F h at the nonzeros of F (the only run-time scaling of the series)."""
    lines = tuple(Assign(Ref("scratch", "fh", (e,)), ((Ref("matrices", "F", (e,)), local("h")),)) for e in range(len(plan.f_entries)))
    return DiscretizeBlock(KernelBlock("horner_input", lines), (), ("h",))


#: The function of the chain's last level (k = 0, into S) where some rows are needed there only.
HORNER_LAST = "horner_last_into_S"


def horner_level_name(level: int, parity: int, saturated: bool = False) -> str:
    """The function computing R_k at the top level (``level`` 1) or at any level below it (``saturated``), into S (k even) or term (k odd)."""
    into = "S" if parity == 0 else "term"
    return f"horner_saturated_into_{into}" if saturated else f"horner_level_{level}_into_{into}"


def _scalars_used(lines) -> tuple[str, ...]:
    used = {r.array for line in scalar_statements(lines) for term in line.terms for r in term if r.owner == LOCAL}
    return tuple(name for name in ("c_out", "c_in") if name in used)  # c_in is unused where no row reaches a random constant


def horner_top_block(plan: DiscretizePlan, parity: int) -> DiscretizeBlock:
    """R_(m-1) = c_out I + A c_in (R_m = c_in I is not stored) over its pattern, zero elsewhere in the stored rows.

    ``c_out`` = 1/m! and ``c_in`` = 1/(m+1)! are passed at run time (the order
    m is chosen at run time).  The zeros make every stored entry defined, so
    that the dense levels below read whole rows and S is complete whatever
    order the chain stopped at.
    """
    pattern = set(plan.horner_patterns[0])
    f_rows = f_row_entries(plan)
    lines = []
    for (i, j), index in sorted(plan.s_position.items(), key=lambda item: item[1]):
        terms: list[tuple[Ref, ...]] = []
        if (i, j) in pattern:
            terms = [(local("c_out"),)] if i == j else []
            terms += [(Ref("scratch", "fh", (e,)), local("c_in")) for c, e in f_rows.get(i, []) if c == j]
        lines.append(Assign(horner_array(parity, index), tuple(terms)))
    return DiscretizeBlock(KernelBlock(horner_level_name(1, parity), tuple(lines)), (), _scalars_used(lines))


def _column_runs(plan: DiscretizePlan, lo: int, hi: int, row: int | None = None) -> list[tuple[int, int]]:
    """Segment positions [lo, hi) cut into runs over consecutive columns of the matrix (padding positions left out).

    With ``row`` the runs cover only the structural nonzeros of that row of
    Phi (the stored entries of the compressed transition, consecutive in
    storage along a run); the segment's other columns are structural zeros
    of the row, not stored.
    """
    n = plan.structure.n_states
    pattern = plan.structure.Phi
    runs: list[tuple[int, int]] = []
    for p in range(lo, hi):
        j = plan.position_column(p)
        if j >= n or (row is not None and not pattern[row, j]):
            continue
        if runs and runs[-1][1] == p and plan.position_column(p - 1) == j - 1:
            runs[-1] = (runs[-1][0], p + 1)
        else:
            runs.append((p, p + 1))
    return runs


def _product_rows(plan: DiscretizePlan, target, source, diagonal: Ref | None, into_matrix: bool, skip: frozenset = frozenset()) -> list:
    """target = A source (+ ``diagonal`` I) over the stored rows but the lone columns: the block rows' dense segments, then their sparse terms.

    ``target(i, j)`` and ``source(i, j)`` give the Ref of entry (i, j); a
    block row c of ``source`` is read as a whole segment over the part of its
    span inside the target's (its structural zeros are stored zeros, and the
    closure of c lies within that of i where F(i, c) is nonzero): the sources
    with the target's span in one sum, narrower ones added after it.  A
    diagonal row c contributes A(i, c) source(c, c), added after the segments
    (which C sums in loops over all rows: each source segment is loaded once
    per step).  The unit columns are left to :func:`unit_column_terms`; a leaf
    column's only entry is the diagonal constant.  ``into_matrix``: the target
    is Phi, stored compressed, so each segment is cut into runs of consecutive
    structural nonzeros (no padding, no structural zeros); the rows in
    ``skip`` are not computed.
    """
    blocks = set(plan.block_rows)
    unit = set(plan.structure.unit_rows)
    lone = plan.lone_columns
    f_rows = f_row_entries(plan)
    spans = plan.spans
    column = plan.position_column

    def pieces(i: int, lo: int, hi: int) -> list[tuple[int, int]]:
        return _column_runs(plan, lo, hi, i) if into_matrix else [(lo, hi)]

    rows = [r for r in plan.block_rows if r not in skip]
    whole: list = []
    parts: list = []
    for i in rows:
        first, length = spans[i]
        end = first + length
        if not length:
            continue
        same, narrower = [], {}
        for c, e in f_rows.get(i, []):
            if c not in blocks:
                continue
            lo, hi = max(first, spans[c][0]), min(end, spans[c][0] + spans[c][1])
            if (lo, hi) == (first, end):
                same.append((c, e))
            elif hi > lo:
                narrower.setdefault((lo, hi), []).append((c, e))
        for a, b in pieces(i, first, end):
            terms = tuple((Ref("scratch", "fh", (e,)), source(c, column(a))) for c, e in same)
            whole.append(SegmentAssign(target(i, column(a)), terms, b - a))
        for (lo, hi), sources in narrower.items():
            for a, b in pieces(i, lo, hi):
                terms = tuple((Ref("scratch", "fh", (e,)), source(c, column(a))) for c, e in sources)
                parts.append(SegmentAssign(target(i, column(a)), terms, b - a, accumulate=True))
    lines = whole + parts
    for i in rows:
        if diagonal is not None:
            lines.append(Assign(target(i, i), ((diagonal,),) if i in lone else ((target(i, i),), (diagonal,))))
        for c, e in f_rows.get(i, []):
            if c in blocks or c in unit:
                continue
            lines.append(Assign(target(i, c), ((target(i, c),), (Ref("scratch", "fh", (e,)), source(c, c)))))
    for i in [r for r in plan.diagonal_rows if r not in skip]:
        (_, e), = f_rows[i]
        product = (Ref("scratch", "fh", (e,)), source(i, i))
        lines.append(Assign(target(i, i), ((diagonal,), product) if diagonal is not None else (product,)))
    return lines


def unit_column_terms(plan: DiscretizePlan, target, left) -> list[Assign]:
    """X(i, j) = sum_c left(i, c) A(c, j) at the entries of the block rows in unit columns (:attr:`DiscretizePlan.unit_entries`).

    S(:, j) = R_1 A(:, j) (``left`` R_1, at k = 0) and E(:, j) = S A(:, j)
    (``left`` S): for a row j of random constants R_k(:, j) = e_j / (k+1)!
    + R_(k+1) A(:, j), so the levels above k = 0 need not carry column j.
    """
    columns: dict[int, list[tuple[int, int]]] = {}
    for e, (c, j) in enumerate(plan.f_entries):
        columns.setdefault(j, []).append((c, e))
    active = set(plan.active)
    return [
        Assign(target(i, j), tuple((left(i, c), Ref("scratch", "fh", (e,))) for c, e in columns.get(j, []) if (i, c) in active))
        for i, j in plan.unit_entries
    ]


#: The function of the chain's level k = 1 (into term) where some rows that no row of F reads have entries in unit columns.
HORNER_FIRST = "horner_first_into_term"


def horner_level_block(plan: DiscretizePlan, parity: int, final: bool = False, first: bool = False) -> DiscretizeBlock:
    """R_k = c_out I + A R_(k+1) for every k below the top, into S (k even) or term (k odd), but the lone columns.

    Dense over the stored rows: the block rows' structural zeros are stored
    zeros, so one function serves every level (the pattern grows from I + F
    to the closure and then stays).  The rows no row of F reads
    (:attr:`DiscretizePlan.leaf_rows`) are left out except at k = 0
    (``final``: S = R_0, into S, with its unit columns R_1 A(:, j)) and, where
    a leaf row has entries in unit columns, at k = 1 (``first``: R_1 there).
    """
    unit = set(plan.structure.unit_rows)

    def source(c: int, j: int) -> Ref:
        return local("c_in") if c in unit else horner_array(1 - parity, plan.s_position[(c, j)])

    def target(i: int, j: int) -> Ref:
        return horner_array(parity, plan.s_position[(i, j)])

    skip = frozenset() if final or first else frozenset(plan.leaf_rows)
    lines = _product_rows(plan, target, source, local("c_out"), False, skip)
    if final and not plan.unit_columns_deferred:
        lines += unit_column_terms(plan, target, lambda i, c: horner_array(1, plan.s_position[(i, c)]))
    name = HORNER_LAST if final else HORNER_FIRST if first else horner_level_name(0, parity, True)
    return DiscretizeBlock(KernelBlock(name, tuple(lines)), (), _scalars_used(lines))


def horner_transition_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """E = Phi - I = A S over the stored rows, into Phi (S = e_c on a row c of random constants).

    The block rows' segments are written into Phi's rows as runs of
    consecutive structural nonzeros (Phi is stored compressed to its
    pattern, ``layout.phi_entries``), the unit columns as S A(:, j); every
    other stored entry (a unit row's diagonal 1, a structural nonzero no
    product reaches) is set here by straight-line stores.  The identity is
    added after the doublings (:func:`transition_check_block`).
    """

    def source(c: int, j: int) -> Ref:
        return Ref("scratch", "S", (plan.s_position[(c, j)],))

    _phi = plan.phi
    lines = _product_rows(plan, _phi, source, None, True)
    lines += unit_column_terms(plan, _phi, source)
    written = {s.target.index for s in scalar_statements(lines)}
    unit = set(plan.structure.unit_rows)
    lines += [
        Assign(_phi(i, j), ((local("one"),),) if i == j and i in unit else ())  # a unit row is e_i of Phi now
        for (i, j), k in plan.phi_position.items()
        if (k,) not in written
    ]
    return DiscretizeBlock(KernelBlock("horner_transition", tuple(lines)), (("one", 1, 1),) if unit else ())


def series_blocks(plan: DiscretizePlan) -> list[DiscretizeBlock]:
    """The Horner chain: A = F h, the top level into either array, the dense level into either, then E = A S.

    Where some rows are read by no row of F, or some columns are unit
    columns, the dense level leaves them out and a last copy (k = 0, into S)
    computes every row and the unit columns; where a leaf row has entries in
    unit columns, a copy at k = 1 computes every row too (R_1 for them).
    """
    blocks = [horner_input_block(plan)]
    blocks += [horner_top_block(plan, parity) for parity in (0, 1)]
    blocks += [horner_level_block(plan, parity) for parity in (0, 1)]
    blocks += [horner_level_block(plan, 1, first=True)] if plan.needs_first_level else []
    blocks += [horner_level_block(plan, 0, final=True)] if plan.needs_last_level else []
    blocks += [unit_columns_block(plan)] if plan.unit_columns_deferred else []
    return blocks + [horner_transition_block(plan)]


#: The function that sums S's unit columns after the chain, where only the doublings read them.
HORNER_UNIT_COLUMNS = "horner_unit_columns"


def unit_columns_block(plan: DiscretizePlan) -> DiscretizeBlock:
    """S(:, j) = R_1 A(:, j) for the unit columns j, after the chain (R_1 still in term): the C calls it only before doublings, at order 2 or more."""
    lines = unit_column_terms(
        plan, lambda i, j: horner_array(0, plan.s_position[(i, j)]), lambda i, c: horner_array(1, plan.s_position[(i, c)])
    )
    return DiscretizeBlock(KernelBlock(HORNER_UNIT_COLUMNS, tuple(lines)))


def horner_schedule(plan: DiscretizePlan, order: int, doubling: bool = False) -> list[str]:
    """The level functions an order-``order`` chain calls, top (k = order - 1) to bottom (k = 0).

    ``doubling``: the step is halved, so S's unit columns are needed (where
    they are deferred, k = 1 then computes every row).
    """

    def level(k: int) -> str:
        if k == order - 1:
            return horner_level_name(1, k % 2)
        if k == 0 and plan.needs_last_level:
            return HORNER_LAST
        if k == 1 and plan.needs_first_level and (doubling or not plan.unit_columns_deferred):
            return HORNER_FIRST
        return horner_level_name(1, k % 2, True)

    return [level(k) for k in range(order - 1, -1, -1)]
