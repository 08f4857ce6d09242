"""The compressed patterns of the unrolled discretize: which entries of S, the levels and Phi are stored where.

:class:`DiscretizePlan` says, for one structure and highest order, which rows
of Phi are block rows (dense segments over the closure's columns), diagonal
rows (a Markov state) and leaf rows (read by no row of F), which columns are
lone (unit and leaf columns, known without a product), and where each entry
of S and of every Horner level is stored (:attr:`DiscretizePlan.s_position`).
:class:`SegmentAssign` is the dense row segment the C prints as one
fixed-trip loop; :class:`DiscretizeBlock` one generated function.  The
package docstring (``modelgen.codegen.discretize_kernels``) explains the
algorithm these serve.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from modelgen.codegen.kernels import Assign, KernelBlock, Ref
from modelgen.codegen.layout import phi_positions
from modelgen.codegen.structure import FilterStructure

LOCAL = "local"


def local(name: str) -> Ref:
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


def entry_index(entries: list[tuple[int, int]]) -> dict[tuple[int, int], int]:
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
        """Entries of each of the two term arrays: the odd levels of the chain, the doubling's new values (active entries), S G and T q.

        During the chain term[0] holds F h, each entry twice from its first 16-byte
        aligned entry (a lane pair: the C reads it broadcast with one aligned load),
        so it has room for those too.
        """
        return max(self.segment_size, len(self.active), len(self.gamma_entries) + self.structure.G.shape[1],
                   2 * len(self.f_entries) + 1, 1)

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


def s_ref(plan: DiscretizePlan, i: int, j: int) -> Ref | None:
    """S(i, j): stored in an active row, None (meaning delta_ij) in a unit row."""
    return Ref("scratch", "S", (plan.s_position[(i, j)],)) if i not in set(plan.structure.unit_rows) else None
