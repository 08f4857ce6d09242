"""discretize as straight-line code that follows the structure of F, Phi, Gamma and Q_d.

The Taylor series of modelgen.derive.discretization is summed by Horner's
rule over compressed storage, A = F h:

    R_m = I / (m+1)!,   R_k = I / (k+1)! + A R_(k+1),   S = R_0,   E = Phi - I = A S,

so each order is one sparse product A R_(k+1) and the constants 1/(k+1)!
land on the diagonal only (no per-entry scaling, no Phi += / S += sums).
The rows that are not e_i are of two kinds: block rows, whose closure (the
fill-in of Phi; R_k's pattern grows from I + F to it and then stays) has
more than the diagonal, and diagonal rows (a Markov state: F's row is F_ii).
A block row is stored as one dense segment over its closure's columns,
padded to an even length; its structural zeros are stored zeros.  The
segments leave out the lone columns (``DiscretizePlan.lone_columns``): a
unit column j (F's row j empty) has R_k(:, j) = e_j / (k+1)! + R_(k+1) A(:, j)
and no level reads it, so it is summed at k = 0 only, S(:, j) = R_1 A(:, j),
and E(:, j) = S A(:, j); a leaf column (read by no row of F) holds its
diagonal constant alone.  On the paper's model that takes the segments from
16 columns to 12 (columns 6-9 out).  Then
every level below the top is the same function: for each block row i,
R_k(i, span) = sum over the block rows c of A(i, c) R_(k+1)(c, span), one
fixed-trip loop over k for all rows that gcc -O2 vectorizes (even length,
contiguous rows: two doubles per instruction; 1.1 instructions per flop on
the paper's model against 1.9 for scalar statements over the exact
patterns, bench/bench_cycle.py), then
the sparse terms: c_out on the diagonal, A(i, c) c_in for a row c of
random constants (R_(k+1) = c_in e_c there), A(i, c) R_(k+1)(c, c) for a
diagonal row c.  A row that no row of F reads (``leaf_rows``) is summed at
k = 0 only.  The padding and the not yet saturated levels cost 10 % more
flops than the exact patterns on the paper's model at order 5, 6 % at
order 9 (:func:`structural_series_cost`, the benchmark's floor).  The top level R_(m-1) = c_out I + A c_in is scalar
(its pattern, I + F, is sparse) and sets the rest of the segments to zero.
Each function comes in two copies (R_k into S for even k, into the second
term array for odd k, so that S = R_0 lands in S).  The order m is chosen
at run time by the accuracy rule (``taylor_plan``): the chain reads the
coefficients 1/(k+1)! from a static table, so one generated file serves
every step T.  Rows of F that are empty (random constants) give rows e_i of
Phi and S and appear in no sum.

The doublings E(2h) = 2 E + E^2 and S(2h) = S + E S / 2 run over the active
entries of Phi (rows that are not e_i) with the same structure; working on
E = Phi - I keeps the small part of Phi(h) that adding I would round away
(in float, s times over).  The identity is added at the end.  Then S G (the
pattern of Gamma), and Q_d = T (S G) diag(q) (S G)^T over the upper-triangle
pairs that can be nonzero, which is the paper's Gamma (Q/T) Gamma^T with
Gamma = T S G.

The scratch is compressed too: two arrays of the stored entries (S and the
odd levels; the doubling's new values; S G), F h, and the balancing's two
vectors, far below the two N x N arrays of the filter's own scratch (the
workspace union keeps the larger).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from modelgen.codegen.kernels import Assign, CheckedAssign, KernelBlock, OperationCount, Ref
from modelgen.codegen.layout import packed_index, phi_positions
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
    def phi_position(self) -> dict[tuple[int, int], int]:
        """Where entry (i, j) of Phi is stored in the transition (its structural pattern, ``layout.phi_entries``)."""
        return phi_positions(self.structure.Phi)

    def phi(self, i: int, j: int) -> Ref:
        """Entry (i, j) of the transition's compressed Phi (a structural nonzero)."""
        return Ref("transition", "Phi", (self.phi_position[(i, j)],))

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
    def active_columns(self) -> dict[int, list[int]]:
        """The columns of each active row's closure, in the order of :attr:`active`."""
        rows: dict[int, list[int]] = {}
        for i, j in self.active:
            rows.setdefault(i, []).append(j)
        return rows

    @cached_property
    def block_rows(self) -> list[int]:
        """Active rows whose closure has more than the diagonal: kept as dense rows over the column span."""
        return [i for i, cols in self.active_columns.items() if cols != [i]]

    @cached_property
    def diagonal_rows(self) -> list[int]:
        """Active rows whose closure is the diagonal alone (F's row is F_ii: a Markov state), kept as scalars."""
        blocks = set(self.block_rows)
        return sorted({i for i, _ in self.active} - blocks)

    @cached_property
    def leaf_rows(self) -> list[int]:
        """Active rows that no row of F reads (F(r, i) = 0 for every r): R_k there is needed at k = 0 only (S)."""
        read = {c for _, c in self.f_entries}
        return [i for i in self.block_rows + self.diagonal_rows if i not in read]

    @cached_property
    def lone_columns(self) -> set[int]:
        """Columns of R_k that the segments leave out: their column of every level is known without a product.

        A unit column j (a row of random constants: F's row j is empty) has
        R_k(:, j) = e_j / (k+1)! + R_(k+1) F(:, j) h, and no level reads it
        (A R_(k+1) reads column j of R_(k+1) for column j only), so it is
        summed at k = 0 alone, S(:, j) = R_1 A(:, j) (:func:`unit_column_terms`),
        and E(:, j) = S A(:, j).  A leaf column j (a row that no row of F reads:
        F(:, j) = 0) has R_k(:, j) = e_j / (k+1)!: only R_k(j, j), a scalar.
        """
        return set(self.structure.unit_rows) | set(self.leaf_rows)

    @cached_property
    def segment_columns(self) -> list[int]:
        """The columns the block rows' dense segments cover, ascending: the closure's columns but the lone ones.

        Position p of a segment holds column ``segment_columns[p]``, so that
        the segments skip the lone columns (E's segment is cut into runs of
        consecutive columns of Phi).
        """
        blocks = set(self.block_rows)
        lone = self.lone_columns
        return sorted({j for i, j in self.active if i in blocks and j not in lone})

    def position_column(self, position: int) -> int:
        """The column a segment position holds (past the last: a padding position, numbered from N on)."""
        columns = self.segment_columns
        return columns[position] if position < len(columns) else self.structure.n_states + position - len(columns)

    @cached_property
    def spans(self) -> dict[int, tuple[int, int]]:
        """(first position, even length) of each block row's dense segment over :attr:`segment_columns`.

        The positions of the row's closure columns (but the lone ones), widened
        to an even length (so that the segment loops have no odd remainder:
        gcc -O2 vectorizes them two doubles at a time) and kept inside the
        segment columns where they fit.
        """
        width = len(self.segment_columns)
        position = {j: p for p, j in enumerate(self.segment_columns)}
        lone = self.lone_columns
        out = {}
        for i in self.block_rows:
            positions = [position[j] for j in self.active_columns[i] if j not in lone]
            if not positions:  # only lone columns (its diagonal, unit columns): an empty segment
                out[i] = (0, 0)
                continue
            first, last = min(positions), max(positions)
            length = last - first + 1 + (last - first + 1) % 2
            out[i] = (max(0, min(first, width - length)), length)
        return out

    @cached_property
    def lone_entries(self) -> list[tuple[int, int]]:
        """Entries of the block rows in lone columns (stored as scalars after the diagonal rows), row-major."""
        blocks = set(self.block_rows)
        lone = self.lone_columns
        return [(i, j) for i, j in self.active if i in blocks and j in lone]

    @cached_property
    def unit_entries(self) -> list[tuple[int, int]]:
        """The lone entries in unit columns: S there is R_1 A(:, j) at k = 0, E there S A(:, j)."""
        unit = set(self.structure.unit_rows)
        return [(i, j) for i, j in self.lone_entries if j in unit]

    @cached_property
    def s_position(self) -> dict[tuple[int, int], int]:
        """Where entry (i, j) of S (and of each level R_k) is stored: the block rows' segments, the diagonal rows, the lone entries."""
        out, base = {}, 0
        for i in self.block_rows:
            first, length = self.spans[i]
            out.update({(i, self.position_column(first + k)): base + k for k in range(length)})
            base += length
        out.update({(i, i): base + d for d, i in enumerate(self.diagonal_rows)})
        base += len(self.diagonal_rows)
        out.update({entry: base + d for d, entry in enumerate(self.lone_entries)})
        return out

    @property
    def noise_reads_unit_columns(self) -> bool:
        """Whether S G reads S in a unit column (a row of random constants driven by noise)."""
        unit = set(self.structure.unit_rows)
        return any(c in unit for c, _ in self.structure.entries("G"))

    @property
    def unit_columns_deferred(self) -> bool:
        """Whether S's unit columns are summed only where the doublings read them (:data:`HORNER_UNIT_COLUMNS`).

        E's unit columns are S A(:, j), from S's other columns; S's own unit
        columns are read by the doublings and by S G where G has a row there.
        """
        return bool(self.unit_entries) and not self.noise_reads_unit_columns

    @property
    def needs_last_level(self) -> bool:
        """Whether k = 0 has its own function: some rows are read by no row of F, or S's unit columns are summed there."""
        return bool(self.leaf_rows or (self.unit_entries and not self.unit_columns_deferred))

    @property
    def needs_first_level(self) -> bool:
        """Whether k = 1 has its own function (every row): a leaf row has entries in unit columns, which read R_1 there."""
        leaves = set(self.leaf_rows)
        return any(i in leaves for i, _ in self.unit_entries)

    @property
    def segment_size(self) -> int:
        """Entries of S and of each level: the block rows' segments, the diagonal rows and the lone entries."""
        return sum(length for _, length in self.spans.values()) + len(self.diagonal_rows) + len(self.lone_entries)

    @cached_property
    def gamma_entries(self) -> list[tuple[int, int]]:
        return self.structure.entries("Gamma")

    @cached_property
    def qd_pairs(self) -> list[tuple[int, int]]:
        return [(i, j) for i, j in self.structure.entries("Qd") if i <= j]

    @property
    def term_size(self) -> int:
        """Entries of each of the two term arrays: the odd levels of the chain, the doubling's new values (active entries), S G and T q."""
        return max(self.segment_size, len(self.active), len(self.gamma_entries) + self.structure.G.shape[1], 1)

    @property
    def active_size(self) -> int:
        """Entries of S (the even levels of the chain): :attr:`segment_size`."""
        return max(self.segment_size, 1)


@dataclass(frozen=True)
class SegmentAssign:
    """``target[k] = sum_t factor_t * source_t[k]`` for k = 0 .. length - 1: a dense row of a level, or part of one.

    ``target`` and each source name the segment's first entry (its last index
    is the offset); each factor is a scalar; ``accumulate`` adds the sum to
    the target instead (a source row whose span is narrower than the
    target's).  The C prints one fixed-trip loop of even length over
    contiguous rows, which gcc -O2 vectorizes (two doubles per instruction);
    :meth:`expand` gives the scalar statements it stands for (for counts and
    for running it in Python).
    """

    target: Ref
    terms: tuple[tuple[Ref, Ref], ...]
    length: int
    accumulate: bool = False

    def expand(self) -> tuple[Assign, ...]:
        out = []
        for k in range(self.length):
            target = _shifted(self.target, k)
            products = tuple((f, _shifted(s, k)) for f, s in self.terms)
            out.append(Assign(target, ((target,),) + products if self.accumulate else products))
        return tuple(out)


def _shifted(ref: Ref, k: int) -> Ref:
    return Ref(ref.owner, ref.array, ref.index[:-1] + (ref.index[-1] + k,))


def scalar_statements(statements) -> list:
    """The statements with every :class:`SegmentAssign` expanded into its scalar assignments."""
    return [e for s in statements for e in (s.expand() if isinstance(s, SegmentAssign) else (s,))]


def _s(plan: DiscretizePlan, i: int, j: int) -> Ref | None:
    """S(i, j): stored in an active row, None (meaning delta_ij) in a unit row."""
    return Ref("scratch", "S", (plan.s_position[(i, j)],)) if i not in set(plan.structure.unit_rows) else None


def _horner_array(parity: int, index: int) -> Ref:
    """Where R_k lives at a stored index (:attr:`DiscretizePlan.s_position`): S for even k (so that S = R_0 lands there), term[1] for odd k."""
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
    f_rows = _f_rows(plan)
    lines = []
    for (i, j), index in sorted(plan.s_position.items(), key=lambda item: item[1]):
        terms: list[tuple[Ref, ...]] = []
        if (i, j) in pattern:
            terms = [(_local("c_out"),)] if i == j else []
            terms += [(Ref("scratch", "fh", (e,)), _local("c_in")) for c, e in f_rows.get(i, []) if c == j]
        lines.append(Assign(_horner_array(parity, index), tuple(terms)))
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
    f_rows = _f_rows(plan)
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
        return _local("c_in") if c in unit else _horner_array(1 - parity, plan.s_position[(c, j)])

    def target(i: int, j: int) -> Ref:
        return _horner_array(parity, plan.s_position[(i, j)])

    skip = frozenset() if final or first else frozenset(plan.leaf_rows)
    lines = _product_rows(plan, target, source, _local("c_out"), False, skip)
    if final and not plan.unit_columns_deferred:
        lines += unit_column_terms(plan, target, lambda i, c: _horner_array(1, plan.s_position[(i, c)]))
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
        Assign(_phi(i, j), ((_local("one"),),) if i == j and i in unit else ())  # a unit row is e_i of Phi now
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
        plan, lambda i, j: _horner_array(0, plan.s_position[(i, j)]), lambda i, c: _horner_array(1, plan.s_position[(i, c)])
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
            product.append((plan.phi(i, c), _s(plan, c, j)))
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
        sums[1].append(SegmentAssign(Ref("scratch", "term", (1, lo)), tuple((plan.phi(i, c), _s(plan, c, j)) for c in wide), hi - lo))
        for a in range(lo, hi):
            for parity, terms in enumerate(_doubling_terms(plan, *plan.active[a], rows[i], sparse_only=True)):
                target = Ref("scratch", "term", (parity, a))
                added[parity].extend(Assign(target, ((target,), term)) for term in terms)
    lines: list = sums[0] + sums[1] + added[0] + added[1]
    lines += [Assign(plan.phi(i, j), ((plan.phi(i, j),), (plan.phi(i, j),), (Ref("scratch", "term", (0, a)),)))
              for a, (i, j) in enumerate(plan.active)]
    for a, (i, j) in enumerate(plan.active):
        stored = Ref("scratch", "S", (plan.s_position[(i, j)],))
        lines.append(Assign(stored, ((stored,), (_local("half"), Ref("scratch", "term", (1, a))))))
    return DiscretizeBlock(KernelBlock("doubling", tuple(lines)), (("half", 1, 2),))


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
                terms.append((_s(plan, i, c), Ref("matrices", "G", (e,))))
        lines.append(Assign(Ref("scratch", "term", (0, g)), tuple(terms)))
    blocks = [DiscretizeBlock(KernelBlock("noise_input", tuple(lines)))]
    if ud:
        lines = [
            Assign(Ref("transition", "Gamma", (i, w)), ((_local("T"), Ref("scratch", "term", (0, g))),))
            for g, (i, w) in enumerate(plan.gamma_entries)
        ]
        blocks.append(DiscretizeBlock(KernelBlock("noise_input_times_step", tuple(lines)), (), ("T",)))
        return blocks
    base = len(plan.gamma_entries)  # T q_w once per noise, after the values (S G) T q_w
    noises = sorted({w for _, w in plan.gamma_entries})
    lines = [Assign(Ref("scratch", "term", (1, base + w)), ((_local("T"), Ref("matrices", "q", (w,))),)) for w in noises]
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
    lines: list = [Assign(_phi(i, i), ((_phi(i, i),), (_local("one"),))) for i, j in plan.active if i == j]
    lines.append(CheckedAssign((Ref("scratch", "term", (0, 0)),), tuple((_phi(i, j),) for i, j in plan.active)))
    return DiscretizeBlock(KernelBlock("transition_check", tuple(lines), checked=True), (("one", 1, 1),))


def block_cost(blocks: list[DiscretizeBlock]) -> OperationCount:
    """Multiplications and additions of the emitted statements, segments entry by entry (a zero fill costs nothing)."""
    mul = add = 0
    for b in blocks:
        for s in scalar_statements(b.block.statements):
            mul += sum(len(t) - 1 for t in s.terms)
            add += max(len(s.terms) - 1, 0)
    return OperationCount(mul, add)


def series_block_costs(plan: DiscretizePlan) -> dict[str, OperationCount]:
    """Flops of each function of the Horner chain, by name (built once, then summed per order)."""
    return {b.block.name: block_cost([b]) for b in series_blocks(plan)}


def series_cost(plan: DiscretizePlan, order: int, costs: dict[str, OperationCount] | None = None, doubling: bool = False) -> OperationCount:
    """Flops of Phi and S by the Horner chain of ``order`` (A = F h, the levels it calls, Phi = I + A S).

    ``costs``: :func:`series_block_costs` of ``plan``, when the caller counts several orders;
    ``doubling``: the levels of a step that is then doubled (:func:`horner_schedule`).
    """
    costs = series_block_costs(plan) if costs is None else costs
    called = [costs[name] for name in ("horner_input", *horner_schedule(plan, order, doubling), "horner_transition")]
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
    doubling = block_cost([doubling_block(plan)])
    if plan.unit_columns_deferred:  # a halved step also sums S's unit columns (once): counted in each doubling, a bound
        extra = series_cost(plan, plan.order, costs, doubling=True)
        extra = OperationCount(extra.multiplications - series.multiplications + costs[HORNER_UNIT_COLUMNS].multiplications,
                               extra.additions - series.additions + costs[HORNER_UNIT_COLUMNS].additions)
        doubling = OperationCount(doubling.multiplications + extra.multiplications, doubling.additions + extra.additions)
    return first, doubling, per_order


def structural_series_cost(plan: DiscretizePlan, order: int) -> OperationCount:
    """Flops of Phi and S by Horner's rule of ``order`` over the structural nonzeros of each level alone.

    The floor the dense segments approach (the benchmark's flop floor): R_k
    over the pattern of I + F + ... + F^(m-k) (the closure once it stops
    growing), each entry a product only where F(i, c) and R_(k+1)(c, j) can
    both be nonzero, plus A = F h and E = A S over the active entries.  A
    unit column j (a row of random constants) is summed where it is needed
    only, as the emitted chain does: E(:, j) = S A(:, j), and S(:, j) = R_1
    A(:, j) at k = 0 (below the top level) where S G reads it (a step that is
    not halved needs it nowhere else); a row that no row of F reads at k = 0
    only.
    """
    unit = set(plan.structure.unit_rows)
    f_rows = _f_rows(plan)
    f_columns: dict[int, list[int]] = {}
    for c, j in plan.f_entries:
        f_columns.setdefault(j, []).append(c)
    patterns = plan.horner_patterns
    mul, add = len(plan.f_entries), 0

    def count(entries, inputs: set | None, constant: bool) -> None:
        """R_k (``constant``: plus c_out I) or E over ``entries``; ``inputs`` the pattern of R_(k+1) (None: R_m = c_in I)."""
        nonlocal mul, add
        for i, j in entries:
            terms = int(constant and i == j)
            for c, _ in f_rows.get(i, []):
                if c in unit or inputs is None:  # R_(k+1)(c, j) = c_in delta_cj (times c_in; E: S(c, c) = 1)
                    products = int(c == j)
                    mul += products if constant else 0
                else:
                    products = int((c, j) in inputs)
                    mul += products
                terms += products
            add += max(terms - 1, 0)

    def count_unit_columns(entries, left: set) -> None:
        """X(i, j) = sum_c left(i, c) A(c, j) over the entries in unit columns."""
        nonlocal mul, add
        for i, j in entries:
            products = sum(1 for c in f_columns.get(j, []) if (i, c) in left)
            mul += products
            add += max(products - 1, 0)

    leaves = set(plan.leaf_rows)
    first_needed = plan.needs_first_level and not plan.unit_columns_deferred  # R_1 of the leaf rows: S's unit columns read it
    for level in range(1, order + 1):
        inputs = None if level == 1 else set(patterns[min(level - 1, len(patterns)) - 1])
        entries = patterns[min(level, len(patterns)) - 1]
        if level < order and not (level == order - 1 and first_needed):  # a row no row reads: needed at k = 0 only
            entries = [(i, j) for i, j in entries if i not in leaves]
        if inputs is None:
            count(entries, inputs, True)
        else:
            count([(i, j) for i, j in entries if j not in unit], inputs, True)
            if level == order and not plan.unit_columns_deferred:  # k = 0: S(:, j) = R_1 A(:, j), where S G reads it
                count_unit_columns([(i, j) for i, j in entries if j in unit], inputs)
    active = set(plan.active)
    count([(i, j) for i, j in plan.active if j not in unit], active, False)
    count_unit_columns([(i, j) for i, j in plan.active if j in unit], active)
    return OperationCount(mul, add)
