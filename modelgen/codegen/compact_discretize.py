"""Index tables of the compact discretize (large models): Horner's rule as row-by-row products over row spans.

Above the compact threshold (``kernels.compact_kernels``) the C discretize
sums the same Horner scheme as the unrolled code
(modelgen.codegen.discretize_kernels), A = F h:

    R_m = I / (m+1)!,   R_k = I / (k+1)! + A R_(k+1),   S = R_0,   E = A S,

then the doublings E(2h) = 2 E + E^2, S(2h) = S + E S / 2, Gamma = T S G and
Q_d = T (S G) diag(q) (S G)^T, by loops over these tables instead of
straight-line code, so that the tables (and the code) grow with the
structural nonzeros only.  Each product is Gustavson's: row i of A R is the
sum over the nonzeros F(i, c) of F(i, c) h times row c of R.  Every row of
R is kept in an N x N array over its span, the columns from the first to
the last of its row of Phi's pattern (the closure: R_k's pattern is within
it at every level), padded to a multiple of 4: so row c of R is added into
row i (whose span covers that of c before padding, the closure of c lying
within that of i where F(i, c) is nonzero; what the padding adds past row
i's span is never read) by one loop over contiguous entries, four per step,
which gcc -O2 vectorizes (two pairs); the structural zeros inside a span are
stored zeros (a span is cleared before a row is summed into it).  A row c
of R that is its diagonal alone (F's row c empty or F_cc alone) adds one
product; A = F h is stored with those columns last in each row (``A_entry``),
so the two kinds run in two loops.  The two top levels, R_(m-1) = I/m! +
A/(m+1)! and R_(m-2), are summed over their own patterns (I + F, I + F +
F^2), the rest over the spans.  An augmented
model's rows are the core's, nearly dense over the states they reach, and
the diagonal rows of its sensor errors, so the spans hold few structural
zeros (5 % more products than the exact patterns for the 100-state bench
model).  The doubling runs over each row's entries (``closure_col``: the
columns whose row is a span first, the diagonal rows after), S G over them too, Q_d over the columns of Gamma (CSC)
from the row's own entry down, so each pair i <= j is summed once.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from modelgen.codegen.kernels import OperationCount
from modelgen.codegen.structure import FilterStructure


def _row_starts(rows: list[list[int]]) -> list[int]:
    """CSR row starts of the given rows."""
    start = [0]
    for row in rows:
        start.append(start[-1] + len(row))
    return start


@dataclass(frozen=True)
class CompactDiscretizeTables:
    """The compact discretize's index tables for one structure."""

    structure: FilterStructure

    @cached_property
    def closure_rows(self) -> list[list[int]]:
        """Columns of each row of Phi's pattern, ascending."""
        return [[int(j) for j in row] for row in self.structure.rows("Phi")]

    @cached_property
    def spans(self) -> list[tuple[int, int]]:
        """[start, end) of each row's span: its first to last column of Phi's pattern, padded to a multiple of 4.

        The padding goes to the right while the span stays within the
        storage's rows (N rounded up to a multiple of 4), else to the left.
        """
        width = self.row_width
        out = []
        for row in self.closure_rows:
            start = row[0]
            length = -(-(row[-1] + 1 - start) // 4) * 4
            start = min(start, width - length)
            out.append((start, start + length))
        return out

    @property
    def row_width(self) -> int:
        """Entries of each stored row of R: N rounded up to a multiple of 4 (every span fits)."""
        return -(-self.structure.n_states // 4) * 4

    @property
    def closure_start(self) -> list[int]:
        return _row_starts(self.closure_rows)

    @property
    def f_row_start(self) -> list[int]:
        return _row_starts(self.structure.rows("F"))

    @property
    def g_row_start(self) -> list[int]:
        return _row_starts(self.structure.rows("G"))

    @cached_property
    def gamma_entries(self) -> list[tuple[int, int]]:
        return self.structure.entries("Gamma")

    @property
    def gamma_row_start(self) -> list[int]:
        return _row_starts(self.structure.rows("Gamma"))

    @cached_property
    def gamma_by_column(self) -> list[int]:
        """Entries of Gamma (their index in row-major storage) column by column, rows ascending (CSC)."""
        return sorted(range(len(self.gamma_entries)), key=lambda g: (self.gamma_entries[g][1], self.gamma_entries[g][0]))

    @property
    def gamma_column_start(self) -> list[int]:
        nw = self.structure.G.shape[1]
        counts = [0] * nw
        for _, w in self.gamma_entries:
            counts[w] += 1
        return _row_starts([[0] * c for c in counts])

    @property
    def gamma_column_position(self) -> list[int]:
        """For each entry of Gamma (row-major), its position in the column-by-column order."""
        position = [0] * len(self.gamma_entries)
        for p, g in enumerate(self.gamma_by_column):
            position[g] = p
        return position

    @cached_property
    def qd_rows(self) -> list[list[int]]:
        """Columns j >= i of each row of Q_d's pattern."""
        return [[int(j) for j in row if j >= i] for i, row in enumerate(self.structure.rows("Qd"))]

    @cached_property
    def qd_lower_rows(self) -> list[list[int]]:
        """Columns j < i of each row of Q_d's pattern (mirrored from the upper triangle)."""
        return [[int(j) for j in row if j < i] for i, row in enumerate(self.structure.rows("Qd"))]

    @cached_property
    def a_entries(self) -> list[int]:
        """F's entries row by row, in each row those whose column c has more than its diagonal in Phi first.

        A = F h is stored in this order: a row of R that is its diagonal alone
        (F's row c empty or F_cc alone) adds one product, the others a span,
        and the two kinds run in two loops without a test per entry.
        """
        f_entries = self.structure.entries("F")
        wide = [len(row) > 1 for row in self.closure_rows]
        order = sorted(range(len(f_entries)), key=lambda e: (f_entries[e][0], not wide[f_entries[e][1]], e))
        return order

    @property
    def a_diagonal_from(self) -> list[int]:
        """Where row i's entries whose column is a diagonal row of R start in ``a_entries``."""
        f_entries = self.structure.entries("F")
        wide = [len(row) > 1 for row in self.closure_rows]
        start = self.f_row_start
        return [start[i] + sum(1 for e in range(len(f_entries)) if f_entries[e][0] == i and wide[f_entries[e][1]])
                for i in range(self.structure.n_states)]

    @cached_property
    def closure_by_kind(self) -> list[list[int]]:
        """Each row of Phi's pattern with the columns whose row is more than its diagonal first (each kind ascending)."""
        wide = [len(row) > 1 for row in self.closure_rows]
        return [sorted(row, key=lambda j: (not wide[j], j)) for row in self.closure_rows]

    @property
    def closure_diagonal_from(self) -> list[int]:
        """Where row i's columns that are diagonal rows start in ``closure_col``."""
        start = self.closure_start
        return [start[i] + sum(1 for j in row if len(self.closure_rows[j]) > 1) for i, row in enumerate(self.closure_rows)]

    def tables(self) -> dict[str, list[int]]:
        """Every table by its C name (see the module docstring and the compact branch of c_discretize.c.j2)."""
        return {
            "F_row_start": self.f_row_start,
            "A_entry": self.a_entries or [0],
            "A_col": [self.structure.entries("F")[e][1] for e in self.a_entries] or [0],
            "A_diagonal_from": self.a_diagonal_from,
            "closure_start": self.closure_start,
            "closure_col": [j for row in self.closure_by_kind for j in row],
            "closure_diagonal_from": self.closure_diagonal_from,
            "span_start": [start for start, _ in self.spans],
            "span_end": [end for _, end in self.spans],
            "G_row_start": self.g_row_start,
            "gamma_row_start": self.gamma_row_start,
            "gamma_col": [w for _, w in self.gamma_entries],
            "gamma_column_start": self.gamma_column_start,
            "gamma_column_row": [self.gamma_entries[g][0] for g in self.gamma_by_column],
            "gamma_column_entry": self.gamma_by_column,
            "gamma_column_position": self.gamma_column_position,
            "qd_row_start": _row_starts(self.qd_rows),
            "qd_col": [j for row in self.qd_rows for j in row],
            "qd_lower_start": _row_starts(self.qd_lower_rows),
            "qd_lower_col": [j for row in self.qd_lower_rows for j in row] or [0],
        }

    def index_type(self) -> str:
        """The narrowest unsigned C type that holds every table entry."""
        largest = max([self.row_width, *(v for t in self.tables().values() for v in t)])
        if largest < 256:
            return "unsigned char"
        return "unsigned short" if largest < 65536 else "uint32_t"


@dataclass(frozen=True)
class CompactDiscretizeCost:
    """Flops of the compact discretize, counted from its tables (:func:`compact_discretize_cost`).

    ``series``: at each order 1..N (A = F h, the Horner levels, E = A S and
    the identity added to Phi); ``doubling``: one doubling; ``noise``: S G
    and Q_d (or Gamma and q / T in the UD form); ``norm``: the balancing's
    sweeps (at most 8), ||F||_D and the plan's bound.
    """

    series: tuple[OperationCount, ...]
    doubling: OperationCount
    noise: OperationCount
    norm: OperationCount

    def first(self, order: int) -> OperationCount:
        """One call at ``order`` without doubling: norm, series and noise."""
        parts = (self.norm, self.series[order - 1], self.noise)
        return OperationCount(sum(c.multiplications for c in parts), sum(c.additions for c in parts))


def _same(count: int) -> OperationCount:
    """``count`` products each summed once (a ``+= a * b``)."""
    return OperationCount(count, count)


def horner_level_flops(tables: CompactDiscretizeTables) -> int:
    """Products (each with its sum) of one ``horner_level`` call: a span of row c per wide entry F(i, c), one per other."""
    t = tables.tables()
    count = 0
    for i in range(tables.structure.n_states):
        for x in range(t["F_row_start"][i], t["F_row_start"][i + 1]):
            c = t["A_col"][x]
            count += t["span_end"][c] - t["span_start"][c] if x < t["A_diagonal_from"][i] else 1
    return count


def compact_discretize_cost(tables: CompactDiscretizeTables, order: int, ud: bool, fixed_scaling: bool) -> CompactDiscretizeCost:
    """The flops the compact C (c_discretize.c.j2's compact branch) runs, counted over the tables it runs over.

    Every ``*`` and ``+`` of a loop body counts once per trip, whatever the
    values (the stored zeros of a span are multiplied too); the finiteness
    probes (``check += v - v``) are not counted, q / T counts as a
    multiplication.  The series at order m: A = F h, the top level (one
    product per nonzero of F), the second (m >= 2: per nonzero F(i, c), its
    diagonal and row c's off-diagonal entries of F), m - 2 span levels and
    E = A S (each :func:`horner_level_flops`), then Phi = I + E.  The norm:
    with D fixed at generation time (``fixed_scaling``) one product and sum
    per nonzero of F and one sum per row (the rows' total, F's finiteness
    test); otherwise also up to 8 sweeps, each a product and two
    sums per off-diagonal nonzero; the plan's bound as the unrolled count's
    (3 m + 6 products, m + 2 sums).
    """
    t, structure = tables.tables(), tables.structure
    n = structure.n_states
    f_row_start, a_col = t["F_row_start"], t["A_col"]
    nnz_f = f_row_start[n]
    closure_start, closure_col = t["closure_start"], t["closure_col"]
    g_row_start = t["G_row_start"]
    noise = OperationCount(0, 0)
    if structure.G.shape[1]:
        products = sum(g_row_start[j + 1] - g_row_start[j] for i in range(n)
                       for j in closure_col[closure_start[i]:closure_start[i + 1]])
        noise = _same(products)  # S G
        n_gamma = t["gamma_row_start"][n]
        if ud:
            noise = OperationCount(noise.multiplications + n_gamma + structure.G.shape[1], noise.additions)  # T S G, q / T
        elif tables.qd_rows and any(tables.qd_rows):
            column = t["gamma_column_start"]
            pairs = sum(k * (k + 1) // 2 for k in (column[w + 1] - column[w] for w in range(len(column) - 1)))
            noise = OperationCount(noise.multiplications + 2 * n_gamma + pairs, noise.additions + pairs)  # T q S G, Q_d
    if not nnz_f:
        return CompactDiscretizeCost(tuple(OperationCount(0, 0) for _ in range(order)), OperationCount(0, 0), noise, OperationCount(0, 0))
    level = horner_level_flops(tables)
    off_diagonal = [sum(1 for x in range(f_row_start[c], f_row_start[c + 1]) if a_col[x] != c) for c in range(n)]
    second = sum(1 + off_diagonal[a_col[x]] for x in range(nnz_f))
    series = []
    for m in range(1, order + 1):
        products = nnz_f + (second if m >= 2 else 0) + (max(m - 2, 0) + 1) * level
        series.append(OperationCount(nnz_f + products, products + n))  # A = F h; + I on Phi's diagonal
    doubling_products = 0
    entries = 0
    for i in range(n):
        if f_row_start[i] == f_row_start[i + 1]:
            continue  # a row of random constants: E = 0, S = e_i
        for c in range(closure_start[i], closure_start[i + 1]):
            j = closure_col[c]
            wide = c < t["closure_diagonal_from"][i]
            doubling_products += 2 * (t["span_end"][j] - t["span_start"][j] if wide else 1)  # E^2 and E S
            entries += 1
    doubling = OperationCount(doubling_products + entries, doubling_products + 3 * entries)  # 2 E + E^2, S + E S / 2
    sweeps = 0 if fixed_scaling else 8 * sum(off_diagonal)
    rows_sum = n if fixed_scaling else 0  # the sum of the rows' sums, discretize's test of F
    norm = OperationCount(sweeps + nnz_f + 3 * order + 6, 2 * sweeps + nnz_f + order + 2 + rows_sum)
    return CompactDiscretizeCost(tuple(series), doubling, noise, norm)
