"""The filter kernels: what each generated function computes, with its cost.

Everything structural is decided here, in Python, so that the templates only
lay out text.  The kernels are language-neutral descriptions (``Ref``,
``Assign``, ``CheckedAssign``, ``KernelBlock``: targets, sums of products,
row blocks); each backend prints them (``backends/c/printer.py``).  The
covariance prediction P = Phi P Phi^T + Q_d is unrolled for C over the
structural nonzeros of Phi, skips rows of Phi that are exactly e_i, and
computes each (i, j) pair of the symmetric result once, in full or packed
storage; its dot products (and x_n = Phi x) are summed in two lanes
(``lane_split``), which the C prints as vector code.  The UD form's product
Phi U is unrolled the same way; its Gram-Schmidt sweep and the measurement
updates are loops in the templates, and their costs are counted here.  The
Python kernel does the same work vectorized by row class (unit, diagonal,
general).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from modelgen.codegen.layout import packed_index, phi_positions, upper_index
from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.structure import FilterStructure


@dataclass(frozen=True)
class OperationCount:
    """Floating-point multiplications and additions of one kernel."""

    multiplications: int
    additions: int

    @property
    def total(self) -> int:
        return self.multiplications + self.additions

    def __str__(self) -> str:
        return f"{self.multiplications} mul + {self.additions} add = {self.total} flops"


@dataclass(frozen=True)
class Ref:
    """One entry of an array that a kernel reads or writes, in a language-neutral form.

    ``owner`` names the object the array lives in (``filter``, ``transition``,
    ``scratch``), ``array`` the member, ``index`` its storage indices (already
    flattened for packed storage).  A backend prints it (C: ``t->Phi[i][k]``).
    """

    owner: str
    array: str
    index: tuple[int, ...]


#: A product of factors; an empty sum of terms is zero.
Term = tuple[Ref, ...]


@dataclass(frozen=True)
class Assign:
    """``target = sum of terms``."""

    target: Ref
    terms: tuple[Term, ...]


@dataclass(frozen=True)
class CheckedAssign:
    """``v = sum of terms``, stored into every target and added to its block's sum.

    The value is added while in a register, or, in a ``read_back`` block, read
    back after all of the block's stores.  The block returns ``sum - sum``: 0
    when the sum is finite, and then every value is; otherwise (a value that is
    not finite, or an overflow of the sum of finite values) the caller decides
    entry by entry.  One addition per value where ``check += v - v`` took two.
    """

    targets: tuple[Ref, ...]
    terms: tuple[Term, ...]


Statement = Assign | CheckedAssign

#: The fewest pairs of products summed in two lanes: with one pair, adding the lanes costs
#: what the two-lane product saves.
MIN_LANE_PAIRS = 2


def lane_split(terms: tuple[Term, ...]) -> tuple[tuple[tuple[Term, Term], ...], tuple[Term, ...]]:
    """The two-lane order of a sum: (pairs of products, the terms added after the lanes).

    The leading products of two factors pair up by position, (t0, t1),
    (t2, t3), ...: t0 + t2 + ... is summed in one lane and t1 + t3 + ... in
    the other, the two lanes are added, then the terms left (an odd last
    product, a Q_d entry) in order.  With fewer than ``MIN_LANE_PAIRS`` pairs
    the sum keeps its plain left-to-right order (no pairs).  The compact
    propagate sums in the same order, so that it gives the unrolled one's bits.
    """
    products = 0
    while products < len(terms) and len(terms[products]) == 2:
        products += 1
    if products < 2 * MIN_LANE_PAIRS:
        return (), terms
    pairs = tuple((terms[k], terms[k + 1]) for k in range(0, products - 1, 2))
    return pairs, terms[2 * len(pairs):]


def _symmetric(owner: str, array: str, n: int, packed: bool, i: int, j: int) -> Ref:
    """Entry (i, j) of a symmetric matrix in full or packed storage."""
    if packed:
        return Ref(owner, array, (packed_index(n, i, j),))
    return Ref(owner, array, (i, j))


def phi_reference(structure: FilterStructure) -> Callable[[int, int], Ref]:
    """Entry (i, k) of the transition's Phi, stored compressed to its structural pattern (``layout.phi_entries``)."""
    positions = phi_positions(structure.Phi)

    def phi(i: int, k: int) -> Ref:
        return Ref("transition", "Phi", (positions[(i, k)],))

    return phi


def state_predict(structure: FilterStructure) -> tuple[KernelBlock, list[Assign], OperationCount]:
    """Unrolled x_n = Phi x over the structural nonzeros of Phi, its dot products in two lanes.

    Returns (the block of assignments into the scratch ``xn``, commit
    assignments into the filter's ``x``, cost); rows of Phi that are e_i
    leave their state as it is, so they appear in neither.
    """
    rows = structure.rows("Phi")
    unit = set(structure.unit_rows)
    _phi = phi_reference(structure)
    mul = add = 0
    lines, commit = [], []
    for i in range(structure.n_states):
        if i in unit:
            continue
        terms = tuple((_phi(i, k), Ref("filter", "x", (k,))) for k in rows[i])
        mul += len(terms)
        add += len(terms) - 1
        lines.append(Assign(Ref("scratch", "xn", (i,)), terms))
        commit.append(Assign(Ref("filter", "x", (i,)), ((Ref("scratch", "xn", (i,)),),)))
    return KernelBlock("state_predict", tuple(lines), two_lanes=True), commit, OperationCount(mul, add)


@dataclass(frozen=True)
class KernelBlock:
    """Straight-line statements that become one small function of the generated code.

    The unrolled kernels are split row by row so that each C function stays
    short: static analysers (cppcheck's value flow) slow down sharply on one
    function of thousands of statements, and compilers inline the pieces back
    into their single caller anyway.
    """

    name: str
    statements: tuple[Statement, ...]
    checked: bool = False  # CheckedAssign statements: the function sums and returns the check
    # the values are summed after all the stores, read back, not between them: gcc -O2 then pairs
    # consecutive stores (and their products) into vector instructions (the Q_d rows)
    read_back: bool = False
    # each sum of products in the two-lane order of ``lane_split`` (the printer makes vector code of it)
    two_lanes: bool = False

    def owners(self) -> set[str]:
        """The objects (``filter``, ``transition``, ``scratch``) the statements read or write."""
        refs = set()
        for s in self.statements:
            refs.update(s.targets if isinstance(s, CheckedAssign) else (s.target,))
            refs.update(r for term in s.terms for r in term)
        return {r.owner for r in refs}

    def uses(self, owner: str) -> bool:
        """Whether the statements read or write an array of ``owner``."""
        return owner in self.owners()


def kept_pairs(structure: FilterStructure, packed: bool) -> list[tuple[int, int]]:
    """The pairs i <= j that the prediction leaves in P as they are (full storage only; row-major).

    Where rows i and j of Phi are both e_i (random constants) and Q_d(i, j)
    is structurally zero, P_n(i, j) = P(i, j) exactly: the unrolled
    prediction neither computes nor commits them (P keeps them in both
    triangles), it only sums them to check that they are finite, as it
    checks what it computes.  Packed storage commits Pn whole, so keeps none.
    """
    if packed:
        return []
    unit = sorted(structure.unit_rows)
    return [(i, j) for i in unit for j in unit if j >= i and not structure.Qd[i, j]]


def kept_pairs_to_check(structure: FilterStructure, kept: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The kept pairs whose finiteness the prediction must check itself: both constants read by no other row of Phi.

    A value that is not finite in P(i, j) = P(j, i), with a row k of Phi
    that is not e_k reading column i, reaches M(k, j) = sum_c Phi(k, c) P(c, j),
    and so P_n(k, j) (computed: row k is not e_k), or P_n(j, k) = sum_c P(j, c)
    Phi(k, c) when j < k; a NaN or an infinity stays one through sums and
    products, so predict refuses it by the check of what it computes.  Only
    where neither i nor j is read so does it sum the pair itself.
    """
    unit = set(structure.unit_rows)
    read = {c for k, c in structure.entries("Phi") if k not in unit and c in unit}
    return [(i, j) for i, j in kept if i not in read and j not in read]


def covariance_predict(structure: FilterStructure, packed: bool) -> tuple[list[KernelBlock], OperationCount]:
    """Unrolled P_n = Phi P Phi^T + Q_d (upper triangle), row by row.

    Row i of the result needs only row i of ``M`` = Phi P (P_n(i, j) =
    M(i, :) Phi(j, :)^T + Q_d(i, j)), so ``M`` is one row of scratch (N
    entries, not N x N): each row of Phi that is not e_i gets its
    ``phi_times_p_row_i`` block right before the ``propagate_row_i`` that
    reads it (for a unit row, M's row is P's row, read in place).  ``Pn``
    gets each (i, j), i <= j, once, packed whatever P's storage (``packed``
    is P's, which M reads), but the :func:`kept_pairs`, which P keeps.
    """
    n = structure.n_states
    rows = structure.rows("Phi")
    unit = set(structure.unit_rows)
    kept = set(kept_pairs(structure, packed))
    _phi = phi_reference(structure)
    mul = add = 0
    blocks = []

    def P(i: int, j: int) -> Ref:
        return _symmetric("filter", "P", n, packed, i, j)

    def m_ref(i: int, col: int) -> Ref:
        return P(i, col) if i in unit else Ref("scratch", "M", (col,))

    for i in range(n):
        if i not in unit:  # row i of M = Phi P
            lines = []
            for col in range(n):
                terms = tuple((_phi(i, k), P(k, col)) for k in rows[i])
                mul += len(terms)
                add += len(terms) - 1
                lines.append(Assign(Ref("scratch", "M", (col,)), terms))
            blocks.append(KernelBlock(f"phi_times_p_row_{i}", tuple(lines)))
        lines = []
        for j in range(i, n):  # row i of Pn = M Phi^T + Q_d, upper triangle only
            if (i, j) in kept:
                continue
            if j in unit:
                terms = [(m_ref(i, j),)]
            else:
                terms = [(m_ref(i, col), _phi(j, col)) for col in rows[j]]
                mul += len(terms)
            add += len(terms) - 1
            if structure.Qd[i, j]:
                terms.append((_symmetric("transition", "Qd", n, True, i, j),))  # always packed (layout)
                add += 1
            # the new value is stored into Pn, the packed upper triangle whatever
            # P's storage (the commit mirrors it), and added to the row's sum
            # while in a register (predict rescans Pn if a sum is not finite)
            lines.append(CheckedAssign((_symmetric("scratch", "Pn", n, True, i, j),), tuple(terms)))
        if lines:
            blocks.append(KernelBlock(f"propagate_row_{i}", tuple(lines), checked=True, two_lanes=True))
    return blocks, OperationCount(mul, add)


@dataclass(frozen=True)
class CommitRow:
    """Row ``row`` of the commit (predict, updates) in full storage: P(row, row:) from Pn's packed row, then mirrored.

    ``start`` is the packed index of (row, row) and ``length`` N - row: the
    copy is one contiguous block on both sides; ``mirrored`` are the columns
    j > row whose P(j, row) is then set from P(row, j).
    """

    row: int
    start: int
    length: int
    mirrored: tuple[int, ...]
    # the copies of the row: (first column, packed index, length); one run from the diagonal unless given
    runs: tuple[tuple[int, int, int], ...] = ()

    @property
    def copies(self) -> tuple[tuple[int, int, int], ...]:
        return self.runs or ((self.row, self.start, self.length),)


def covariance_commit(n: int) -> list[CommitRow]:
    """The unrolled commit of predict and the updates in full storage: both triangles of P from Pn's packed upper one.

    Row by row, each row's upper part is one block copy (gcc -O2 inlines it
    as vector moves) and its column is mirrored from the row just written, so
    nothing is kept in registers across rows: 7,243 instructions per
    prediction at 18 states (callgrind, bench/bench_cycle.py (a)) against
    7,595 for one assignment per entry, whose loads gcc schedules first and
    spills (1.5 kB of stack), and 8,696 for a loop over the packed index.
    """
    return [CommitRow(i, packed_index(n, i, i), n - i, tuple(range(i + 1, n))) for i in range(n)]


def predict_commit(n: int, kept: list[tuple[int, int]]) -> list[CommitRow]:
    """:func:`covariance_commit` of the prediction: the :func:`kept_pairs` are neither copied nor mirrored.

    Each row's other entries from the diagonal on are copied as runs of
    consecutive columns (one block copy each); a row with none is left out.
    """
    skip = set(kept)
    out = []
    for i in range(n):
        columns = [j for j in range(i, n) if (i, j) not in skip]
        runs: list[tuple[int, int, int]] = []
        for j in columns:
            if runs and runs[-1][0] + runs[-1][2] == j:
                runs[-1] = (runs[-1][0], runs[-1][1], runs[-1][2] + 1)
            else:
                runs.append((j, packed_index(n, i, j), 1))
        if runs:
            out.append(CommitRow(i, packed_index(n, i, i), n - i, tuple(j for j in columns if j > i), tuple(runs)))
    return out


def unrolled_predict_flops(structure: FilterStructure) -> int:
    """Flops of the fully unrolled covariance prediction without its Q_d additions, without building it.

    M = Phi P costs 2 nnz_i N - N per non-unit row i of Phi; the upper
    triangle of M Phi^T costs 2 nnz_j - 1 for each of the j + 1 pairs (i, j),
    i <= j, of a non-unit row j.  Cheap, so that the choice between unrolled
    and compact kernels is made before any kernel is built.
    """
    n = structure.n_states
    unit = set(structure.unit_rows)
    flops = 0
    for i, row in enumerate(structure.rows("Phi")):
        if i not in unit:
            flops += (2 * len(row) - 1) * n + (2 * len(row) - 1) * (i + 1)
    return flops


#: Above this many unrolled flops in the covariance prediction the generated C gets compact
#: kernels (loops over the CSR pattern of Phi, ``compact_kernels``; discretize follows the same
#: switch) instead of straight-line code.  Measured by bench/bench_large_models.py (gcc -O2,
#: x86-64, bench/results/large_models.md): unrolled against compact, compile time of the
#: filter, .text, instructions and wall time per prediction --
#:   18 states (4,700 flops):            24 s, 204 kB,  7,600 instr, 1.25 us  against 0.6 s, 14 kB,  18,600, 1.60 us;
#:   32 states augmented (13,700 flops): 14 s, 397 kB, 20,500 instr, 2.30 us  against 0.5 s, 18 kB,  47,700, 3.24 us;
#:   48 states (32,100 flops):           49 s, 772 kB, 62,300 instr, 5.15 us  against 1.5 s, 25 kB, 123,400, 7.16 us.
#: The unrolled code is 1.3-1.4x faster per call (2-2.5x fewer instructions: no index loads),
#: and costs compile time and .text in proportion to its flops (both include discretize, which
#: switches with it): at 48 states a minute of compiling and 0.77 MB of object code, most of a
#: Cortex-M4's flash, for that factor.  The threshold sits between the 32- and the 48-state
#: models, so every built-in model (at most 13,700 flops) keeps its unrolled code.
COMPACT_ABOVE_FLOPS = 20_000


def compact_kernels(structure: FilterStructure) -> bool:
    """Whether the generated C predicts by loops over Phi's sparsity pattern (see :data:`COMPACT_ABOVE_FLOPS`)."""
    return unrolled_predict_flops(structure) > COMPACT_ABOVE_FLOPS


def compact_predict_tables(structure: FilterStructure) -> dict[str, list[int]]:
    """The CSR pattern of Phi over every row (a unit row holds its diagonal) and the unit-row flags.

    Entry e of the pattern is entry e of the transition's compressed Phi
    (``layout.phi_entries``: the same row-major order), so the loops read
    ``t->Phi[e]``.  The compact kernels (C templates ``c_predict_covariance.c.j2``,
    ``c_predict_ud.c.j2``) loop over these tables in the same order as the
    unrolled code adds its terms, so both give the same bits.
    """
    rows = structure.rows("Phi")
    start = [0]
    for row in rows:
        start.append(start[-1] + len(row))
    unit = set(structure.unit_rows)
    return {
        "row_start": start,
        "col": [int(k) for row in rows for k in row],
        "unit": [1 if i in unit else 0 for i in range(structure.n_states)],
    }


def compact_covariance_cost(structure: FilterStructure) -> OperationCount:
    """Flops of the compact covariance prediction: the same products and sums as the unrolled kernel.

    The loops add each structural Q_d entry and a zero for the others (an
    exact no-op): counted as an addition for every pair, i <= j.
    """
    n = structure.n_states
    unit = set(structure.unit_rows)
    mul = add = 0
    rows = structure.rows("Phi")
    for i, row in enumerate(rows):
        if i not in unit:
            mul += len(row) * n
            add += (len(row) - 1) * n
            mul += len(row) * (i + 1)
            add += (len(row) - 1) * (i + 1)
    add += n * (n + 1) // 2
    return OperationCount(mul, add)


def ud_weights(structure: FilterStructure) -> tuple[list[KernelBlock], OperationCount]:
    """Unrolled W[:, :N] = Phi U for Thornton's time update (U unit upper, packed), by row.

    W(i, k) = sum over l in row i of Phi with l <= k of Phi(i, l) U(l, k),
    U(l, l) = 1: entries with no term are zero, a unit row of Phi copies U.
    """
    n = structure.n_states
    rows = structure.rows("Phi")
    _phi = phi_reference(structure)
    mul = add = 0
    blocks = []
    for i in range(n):
        lines = []
        for k in range(n):
            terms = []
            for l in rows[i]:
                if l > k:
                    continue
                if l == k:  # the unit diagonal of U
                    terms.append((_phi(i, l),))
                else:
                    terms.append((_phi(i, l), Ref("filter", "U", (upper_index(n, l, k),))))
                    mul += 1
            add += max(len(terms) - 1, 0)
            lines.append(Assign(Ref("scratch", "W", (i, k)), tuple(terms)))
        blocks.append(KernelBlock(f"phi_times_u_row_{i}", tuple(lines)))
    return blocks, OperationCount(mul, add)


def ud_weights_cost(structure: FilterStructure) -> OperationCount:
    """Flops of W[:, :N] = Phi U (``ud_weights``'s count) without building the statements (compact kernels)."""
    n = structure.n_states
    mul = add = 0
    for row in structure.rows("Phi"):
        for k in range(n):
            below = sum(1 for l in row if l <= k)
            mul += sum(1 for l in row if l < k)
            add += max(below - 1, 0)
    return OperationCount(mul, add)


def thornton_cost(structure: FilterStructure) -> OperationCount:
    """Flops of the modified weighted Gram-Schmidt over W = [Phi U, Gamma]."""
    n, nw = structure.n_states, structure.G.shape[1]
    width = n + nw
    mul = add = 0
    for i in range(n):
        mul += 2 * width  # weighted row and its squared norm
        add += width
        mul += i * (2 * width + 1)  # dot product, scaling, elimination
        add += i * 2 * width
    return OperationCount(mul, add)


def _row_classes(structure: FilterStructure) -> tuple[list[int], list[int], list[int]]:
    """Split Phi's rows into exact unit rows, diagonal-only rows and general rows."""
    n = structure.n_states
    unit = list(structure.unit_rows)
    diagonal = [i for i in range(n) if i not in unit and list(np.flatnonzero(structure.Phi[i])) == [i]]
    general = [i for i in range(n) if i not in unit and i not in diagonal]
    return unit, diagonal, general


def python_predict_plan(structure: FilterStructure) -> dict[str, list[int]]:
    """Index sets for the vectorized Python prediction (see module doc)."""
    unit, diagonal, general = _row_classes(structure)
    columns = sorted({int(c) for i in general for c in np.flatnonzero(structure.Phi[i])})
    return {"unit": unit, "diagonal": diagonal, "general": general, "general_columns": columns}


def python_predict_cost(structure: FilterStructure) -> OperationCount:
    """Flops of the vectorized Python prediction (dense within each row class)."""
    n = structure.n_states
    plan = python_predict_plan(structure)
    g, c, d = len(plan["general"]), len(plan["general_columns"]), len(plan["diagonal"])
    mul = 2 * g * c * n + 2 * d * n
    add = 2 * g * (c - 1) * n + n * n
    return OperationCount(mul, add)


def dense_predict_cost(n_states: int) -> OperationCount:
    """Flops of the dense x = Phi x, P = Phi P Phi^T + Q_d (the baseline of the Python kernel choice)."""
    n = n_states
    return OperationCount(2 * n**3 + n * n, 2 * n * n * (n - 1) + n * (n - 1) + n * n)


#: Flops the structured Python prediction (by row class of Phi: D P D elementwise plus one
#: product of the general rows) must save over the dense products to be chosen instead of the
#: factored one (the Cholesky factor of the contract's check reused: P_n = (Phi L)(Phi L)^T + Q_d
#: by BLAS trmm and syrk).  bench/bench_python_module.py times both (CPU time per call, one BLAS
#: thread, bench/results/python_module.md, after the dasum finiteness test): factored wins at 18
#: states (saving 15k flops: 7.5 against 14.7 us), 32 (106k: 13.0 against 18.1 us), 40 (215k: 18.1
#: against 22.2 us) and 48 (383k: 24.2 against 26.3 us); structured wins at 64 (939k: 35.1 against
#: 40.4 us), 80 (1.9M: 47.2 against 65.4 us) and 100 (3.7M: 69.2 against 109.1 us).  The threshold
#: sits between 48 and 64.
PYTHON_STRUCTURED_SAVING_FLOPS = 500_000


def python_predict_kernel(structure: FilterStructure) -> str:
    """``factored`` (Cholesky factor, BLAS trmm and syrk) or ``structured`` (by row class) for the Python predict."""
    saving = dense_predict_cost(structure.n_states).total - python_predict_cost(structure).total
    return "structured" if saving > PYTHON_STRUCTURED_SAVING_FLOPS else "factored"


#: The same choice for the generated ``Filter`` class, whose P is trusted (proven once, in
#: set_covariance): no Cholesky factor to reuse, so the dense form is M = Phi P then one dgemm
#: (M Phi^T + Q_d) on Fortran views.  bench/bench_python_module.py times both forms of the class
#: (CPU time per call, one BLAS thread, each call restoring x and P): dense wins at 18 states
#: (saving 15k flops: 5.2 against 11.6 us), 32 (8.0 against 13.0 us) and 40 (215k: 12.0 against
#: 14.9 us); 48 is a tie (383k: 16.2 against 16.3 us); by row class wins at 64 (939k: 20.4 against
#: 31.0 us) and 80 (1.9M: 25.3 against 53.3 us).  The threshold sits between 40 and 48 states.
PYTHON_FILTER_STRUCTURED_SAVING_FLOPS = 300_000


def python_filter_predict_kernel(structure: FilterStructure) -> str:
    """``dense`` (Phi P, then one BLAS dgemm) or ``structured`` (by row class) for the Filter class's predict."""
    saving = dense_predict_cost(structure.n_states).total - python_predict_cost(structure).total
    return "structured" if saving > PYTHON_FILTER_STRUCTURED_SAVING_FLOPS else "dense"


def discretize_cost(structure: FilterStructure, order: int) -> OperationCount:
    """Flops of the Taylor series over CSR F, Gamma = T S G and Q_d (upper triangle)."""
    n = structure.n_states
    nnz_f = int(structure.F.sum())
    nnz_g = int(structure.G.sum())
    nw = structure.G.shape[1]
    mul = order * (n * nnz_f + n * n)  # (F A) and the 1/k scaling
    add = order * (n * max(nnz_f - n, 0) + 2 * n * n)  # row sums, Phi and S accumulation
    mul += n * nnz_g + n * nw  # Gamma
    pairs = n * (n + 1) // 2
    mul += pairs * 2 * nw
    add += pairs * nw
    if np.any(structure.F):  # up to 8 balancing sweeps and the norm over F (modelgen.derivation.discretization)
        off = nnz_f - int(np.trace(structure.F.astype(int)))
        mul += 8 * 2 * off + 2 * nnz_f
        add += 8 * 2 * off + nnz_f
    return OperationCount(mul, add)


def doubling_cost(structure: FilterStructure) -> OperationCount:
    """Flops of one doubling of discretize: Phi^2 and (S + Phi S) / 2 over the active entries of Phi."""
    n = structure.n_states
    unit = set(structure.unit_rows)
    active = sum(1 for i, _ in structure.entries("Phi") if i not in unit)
    return OperationCount(active * (2 * n + 1), active * (2 * n))


def update_cost(structure: FilterStructure, options: CodegenOptions | None = None) -> OperationCount:
    """Flops of the measurement update chosen by ``options`` (default: vector, Joseph)."""
    options = options or CodegenOptions()
    n = structure.n_states
    m = structure.H.shape[0]
    nnz_h = int(structure.H.sum())
    pairs = n * (n + 1) // 2
    if options.ud:  # Bierman, per scalar measurement
        mul = add = 0
        for a in range(m):
            cols = list(np.flatnonzero(structure.H[a]))
            mul += sum(n - c for c in cols) + n + len(cols)  # f = U^T h, v = D f, H x
            add += sum(n - c for c in cols) + len(cols)
            mul += n * 3 + (n * (n - 1) // 2) * 2 + n  # alpha, lambda, D; U and b; gain times innovation
            add += n + (n * (n - 1) // 2) * 2 + n
        return OperationCount(mul, add)
    if options.update == "sequential":
        per_pair = 3 if options.covariance_update == "joseph" else 1
        mul = nnz_h * n + 2 * nnz_h + m * (2 * n + pairs * per_pair + (n if per_pair == 3 else 0))
        add = nnz_h * n + 2 * nnz_h + m * (n + pairs * per_pair)
        return OperationCount(mul, add)
    mul = nnz_h * n  # H P
    mul += m * nnz_h  # S
    mul += m * m * m // 3 + m * m * n  # Cholesky + solves
    mul += nnz_h + n * m  # innovation, state
    if options.covariance_update == "joseph":
        mul += n * m * m  # K S
        mul += pairs * 3 * m  # (K S) K^T - K (H P) - (H P)^T K^T
    else:
        mul += pairs * m  # P - K (H P), upper triangle
    add = mul  # one addition per multiplication, to within m terms
    return OperationCount(mul, add)


#: Bytes of generated text per unrolled flop of the covariance prediction (which the unrolled
#: discretize, Horner's rule over dense row segments of the fill-in of Phi, grows with too), per
#: flop of the rows of M = Phi P printed as loops over column pairs (rows of Phi with two or more
#: nonzeros: one line per term, not per entry), and the rest (templates, tables, evaluation):
#: least squares of the relative error on the built-in models, which it predicts within 7 %
#: (ned_doppler18: 331 kB estimated, 329 kB written; ned_doppler32_augmented: 480 kB, 481 kB).
BYTES_PER_PREDICT_FLOP = 101
BYTES_PER_LOOPED_FLOP = 9
FIXED_BYTES = 197_000


def looped_predict_flops(structure: FilterStructure) -> int:
    """The flops of :func:`unrolled_predict_flops` in the rows of M = Phi P that the C prints as loops (two or more terms)."""
    n = structure.n_states
    unit = set(structure.unit_rows)
    return sum((2 * len(row) - 1) * n for i, row in enumerate(structure.rows("Phi")) if i not in unit and len(row) > 1)


#: With compact kernels (large models) the generated text grows with the states (names,
#: indices, struct members), the nonzeros of F, G, H (their expressions, in C and Python) and
#: those of Phi (index tables): bytes per state, per F/G/H nonzero, per Phi nonzero and the
#: rest, fitted on the augmented models of 64, 100 and 200 states (144, 187, 313 kB written;
#: estimated within 3 %).
COMPACT_BYTES_PER_STATE = 600
COMPACT_BYTES_PER_MATRIX_NONZERO = 250
COMPACT_BYTES_PER_PHI_NONZERO = 10
COMPACT_FIXED_BYTES = 60_000


def estimated_code_bytes(structure: FilterStructure) -> int:
    """Expected size of all generated files, from the structural nonzeros of Phi alone.

    Unrolled code grows with the flops of the covariance prediction
    (:func:`unrolled_predict_flops`: about n multiply-adds per nonzero of a
    non-unit row of Phi, and (n + 1) / 2 more for the upper triangle of
    M Phi^T).  Compact kernels (large models) grow with the nonzeros
    themselves.  Cheap (no kernel is built),
    so that a large model is reported before any time is spent on it.
    """
    if compact_kernels(structure):
        matrix_nonzeros = int(structure.F.sum() + structure.G.sum() + structure.H.sum())
        return (
            COMPACT_FIXED_BYTES
            + COMPACT_BYTES_PER_STATE * structure.n_states
            + COMPACT_BYTES_PER_MATRIX_NONZERO * matrix_nonzeros
            + COMPACT_BYTES_PER_PHI_NONZERO * int(structure.Phi.sum())
        )
    looped = looped_predict_flops(structure)
    return FIXED_BYTES + BYTES_PER_PREDICT_FLOP * (unrolled_predict_flops(structure) - looped) + BYTES_PER_LOOPED_FLOP * looped
