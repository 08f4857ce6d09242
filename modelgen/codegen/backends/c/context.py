"""The C templates' context: the description's kernels, tables and sizes printed as C."""

from __future__ import annotations

import math
from pathlib import Path

from modelgen.codegen.backends.c.literals import c_number, scalar_bytes, scalar_spellings
from modelgen.codegen.backends.c.printer import (POINTERS, CPrinter, accessors, c_declarator, c_lines, c_pair, c_paired_pointer, c_ref,
                                                c_statement, paired)
from modelgen.codegen.description import FilterDescription, named
from modelgen.codegen.discretize_kernels import HORNER_LAST, DiscretizeBlock, SegmentAssign, horner_level_name, scalar_statements
from modelgen.codegen.kernels import MIN_LANE_PAIRS, Assign, CheckedAssign, KernelBlock, Ref, compact_predict_tables, lane_split
from modelgen.codegen.compact_discretize import CompactDiscretizeTables
from modelgen.codegen.layout import CLayout, CompactDiscretizeSizes, UnrolledDiscretizeSizes, c_layout, packed_index, phi_entries
from modelgen.codegen.smoother import reset_inverse
from modelgen.codegen.structure import FilterStructure
from modelgen.codegen.van_loan import QD_MARGIN
from modelgen.derivation.discretization import DOUBLE_ROUNDOFF, FLOAT_ROUNDOFF, nominal_scaling, series_range, single_step_thresholds
from modelgen.errors import ModelError

BANNER = "/* GENERATED FILE - DO NOT EDIT (modelgen) */"

#: The fixed C runtime (``runtime/``): real C files, copied verbatim into every generated folder and
#: included by its ``<model>.c`` (``modelgen_scalar.h`` by the others).
RUNTIME = Path(__file__).resolve().parent / "runtime"
RUNTIME_FILES = tuple(sorted(RUNTIME.glob("*.h")))
RUNTIME_HEADERS = tuple(path for path in RUNTIME_FILES if path.name != "modelgen_scalar.h")
HASH_BANNER = "# GENERATED FILE - DO NOT EDIT (modelgen)"


def _table(values: list[int]) -> str:
    """An initializer list (``0`` for an empty table: C has no empty arrays)."""
    return ", ".join(str(v) for v in values) if values else "0"


def index_tables(structure: FilterStructure) -> dict[str, object]:
    """Row/column tables of the sparse matrices, CSR row starts, active and unit rows of Phi, Q_d pairs."""
    n = structure.n_states
    f_entries = structure.entries("F")
    h_entries = structure.entries("H")
    row_start = [0]
    for i in range(n):
        row_start.append(row_start[-1] + sum(1 for r, _ in f_entries if r == i))
    h_row_start = [0]
    for a in range(structure.H.shape[0]):
        h_row_start.append(h_row_start[-1] + sum(1 for r, _ in h_entries if r == a))
    unit = set(structure.unit_rows)
    active = [(i, j) for i, j in structure.entries("Phi") if i not in unit]
    qd = [(i, j) for i, j in structure.entries("Qd") if i <= j]
    return {
        "F_row": _table([i for i, _ in f_entries]),
        "F_col": _table([j for _, j in f_entries]),
        "G_row": _table([i for i, _ in structure.entries("G")]),
        "G_col": _table([j for _, j in structure.entries("G")]),
        "H_row": _table([i for i, _ in h_entries]),
        "H_col": _table([j for _, j in h_entries]),
        "F_row_start": _table(row_start),
        "H_row_start": _table(h_row_start),
        "n_active": len(active),
        "active_row": _table([i for i, _ in active]),
        "active_col": _table([j for _, j in active]),
        "n_unit": len(unit),
        "unit_row": _table(sorted(unit)),
        "unit_flags": _table([1 if i in unit else 0 for i in range(n)]),
        "Phi_row": _table([i for i, _ in phi_entries(structure.Phi)]),
        "Phi_col": _table([j for _, j in phi_entries(structure.Phi)]),
        "n_qd": len(qd),
        "qd_row": _table([i for i, _ in qd]),
        "qd_col": _table([j for _, j in qd]),
        "max_index": max([n, len(f_entries), len(active), len(qd)]),
    }


def compact_discretize_context(structure: FilterStructure) -> dict[str, object]:
    """The compact discretize's index tables printed as C initializers, their index type and the scratch's sizes."""
    tables = CompactDiscretizeTables(structure)
    return {
        "tables": {name: _table(values) for name, values in tables.tables().items()},
        "index_type": tables.index_type(),
        "sizes": CompactDiscretizeSizes(len(tables.tables()["closure_col"]), len(tables.gamma_entries), tables.row_width),
    }


#: A block of at most this many terms (a row of a random constant or a Markov state) is left to the
#: compiler to inline: its call would cost more than its work (bench/bench_cycle.py: -133
#: instructions per 18-state cycle); the larger ones are functions of their own (``<M>_BLOCK``).
SMALL_BLOCK_TERMS = 24


def small_block(statements) -> bool:
    """Whether a block is small enough to be inlined (see SMALL_BLOCK_TERMS)."""
    return sum(len(s.terms) for s in scalar_statements(statements)) <= SMALL_BLOCK_TERMS


def two_lane_sums(block: KernelBlock) -> bool:
    """Whether some statement of the block prints as a sum in two lanes (``kernels.lane_split``): it declares ``lane_pair acc``."""
    return block.two_lanes and any(lane_split(s.terms)[0] for s in block.statements if not isinstance(s, SegmentAssign))


#: A row of M = Phi P with fewer terms (a Markov state's, one) stays scalar sums, which gcc -O2 pairs
#: itself: 18 states, the loop for those rows too cost 160 instructions a cycle more.
MIN_BROADCAST_TERMS = 2


def _broadcast_row(block: KernelBlock) -> list[tuple[Ref, int]] | None:
    """(Phi entry, row k of P) of each term when the block is row i of M = Phi P in full storage, else None.

    That is: one statement per column c = 0..N-1, M[c] = sum_q Phi(e_q) P[k_q][c]
    with the same factors and rows for every column (``phi_times_p_row_i``).
    """
    statements = block.statements
    if not statements or not all(isinstance(s, Assign) and s.target.array == "M" and s.target.index == (c,)
                                 for c, s in enumerate(statements)):
        return None
    first = statements[0].terms
    if not first or not all(len(t) == 2 and t[0].owner == "transition" and t[1].owner == "filter" and t[1].array == "P"
                            and len(t[1].index) == 2 and t[1].index[1] == 0 for t in first):
        return None
    row = [(factor, source.index[0]) for factor, source in first]
    for c, s in enumerate(statements):
        if s.terms != tuple((factor, Ref("filter", "P", (k, c))) for factor, k in row):
            return None
    return row


def m_row_lines(block: KernelBlock) -> list[str] | None:
    """Row i of M = Phi P as a loop over column pairs: each factor Phi(i, k) broadcast once, then P's rows two columns a step.

    The sums are those of the scalar statements, term by term in the same
    order in each lane (so the same bits); a lane pair is an SSE2 vector
    (runtime ``modelgen_lane_pair.h``), so each term is one load, one
    multiplication and one addition for two columns (bench/bench_cycle.py,
    32 states: 24,757 -> 22,720 instructions a cycle against the unrolled
    scalar sums, whose 27 factors gcc -O2 spills and copies).  An odd N
    leaves the last column to a scalar sum.  None when the block is not
    such a row (packed storage, the UD form).
    """
    row = _broadcast_row(block)
    if row is None or len(row) < MIN_BROADCAST_TERMS or len(block.statements) < 2:
        return None
    n = len(block.statements)
    lines = ["int c;", f"lane_pair b[{len(row)}];"]
    lines += [f"b[{q}] = lane_pair_of({c_ref(f)}, {c_ref(f)});" for q, (f, _) in enumerate(row)]
    lines.append(f"for (c = 0; c + 1 < {n}; c += 2) {{")
    lines.append(f"    lane_pair acc = lane_pair_product(b[0], lane_pair_load(&f->P[{row[0][1]}][c]));")
    lines += [f"    acc = lane_pair_add_product(acc, b[{q}], lane_pair_load(&f->P[{k}][c]));" for q, (_, k) in enumerate(row) if q]
    lines += ["    lane_pair_store(&w->M[c], acc);", "}"]
    if n % 2:
        lines += c_lines(block.statements[-1])
    return lines


def block_functions(blocks: list[KernelBlock], prefix: str) -> list[dict[str, object]]:
    """Static C functions for the unrolled kernel pieces, with the parameters each uses."""
    types = {"filter": f"const {prefix}_filter", "transition": f"const {prefix}_transition", "scratch": f"{prefix}_filter_scratch"}  # noqa: E501
    out = []
    for block in blocks:
        owners = [o for o in ("filter", "transition") if block.uses(o)] + ["scratch"]
        out.append(
            {
                "name": block.name,
                "signature": ", ".join(f"{types[o]} *restrict {POINTERS[o]}" for o in owners),
                "arguments": ", ".join(POINTERS[o] for o in owners),
                "lines": m_row_lines(block) or [line for s in block.statements for line in c_lines(s, two_lanes=block.two_lanes)],
                "lane_pairs": two_lane_sums(block),
                "checked": block.checked,
                "small": small_block(block.statements),
            }
        )
    return out


def qd_variance_check(n: int, prefix: str, zero: str, compact: bool) -> list[str]:
    """C lines of predict that return ERR_NOT_POSITIVE when a variance Q_d(i, i) of the transition is negative.

    Every diagonal entry is read (not only Q_d's structural nonzeros): the
    Python refuses a negative one wherever it is.  First their sign bits,
    OR'ed (runtime ``modelgen_ieee.h``: one load and one OR per state,
    straight-line where the prediction is unrolled, a loop where it is
    compact); only a set sign bit (a negative entry, or a -0 or a NaN,
    which are not refused here) makes predict compare entry by entry.
    predict declares ``modelgen_bits signs``; the loop index ``d`` is declared
    here, in the narrowest block that uses it (cppcheck's variableScope).
    """
    diagonal = [packed_index(n, i, i) for i in range(n)]
    if compact:
        signs = ["int d;", "signs = 0;", f"for (d = 0; d < {prefix}_N_STATES; ++d) {{",
                 f"    signs |= modelgen_bits_of(t->Qd[{prefix}_PACKED_UPPER(d, d)]);", "}"]
        declare = []
    else:
        signs = [f"signs = modelgen_bits_of(t->Qd[{diagonal[0]}]);"] + [f"signs |= modelgen_bits_of(t->Qd[{k}]);" for k in diagonal[1:]]
        declare = ["    int d;"]
    return signs + ["if (signs & MODELGEN_SIGN_BIT) {", *declare, f"    for (d = 0; d < {prefix}_N_STATES; ++d) {{",
                    f"        if (t->Qd[{prefix}_PACKED_UPPER(d, d)] < {zero}) {{", f"            return {prefix}_ERR_NOT_POSITIVE;",
                    "        }", "    }", "}"]


def _runs(columns: list[int]) -> list[tuple[int, int]]:
    """Consecutive runs (first, past the last) of ascending columns."""
    runs: list[list[int]] = []
    for j in columns:
        if runs and runs[-1][1] == j:
            runs[-1][1] = j + 1
        else:
            runs.append([j, j + 1])
    return [(a, b) for a, b in runs]


def kept_check_lines(kept: list[tuple[int, int]], zero: str) -> list[str]:
    """C lines of predict that check the pairs it leaves in P (``kernels.kept_pairs_to_check``) finite: ``kept_check`` 0 or NaN.

    Their sum in two partial sums (one load and one add per entry) is finite
    only if every entry is; a sum that is not (an entry that is not finite,
    or an overflow of finite ones) is decided entry by entry.  predict
    declares ``kept[2]`` (zero) and ``kept_check``.
    """
    if not kept:
        return []
    rows: dict[int, list[int]] = {}
    for i, j in kept:
        rows.setdefault(i, []).append(j)
    lines = [f"kept[{k % 2}] += f->P[{i}][{j}];" for k, (i, j) in enumerate(kept)]
    lines.append("kept_check = kept[0] + kept[1];")
    lines += [f"if (kept_check - kept_check != {zero}) {{", "    int j;", f"    kept_check = {zero};"]
    for i, columns in rows.items():
        for a, b in _runs(columns):
            lines += [f"    for (j = {a}; j < {b}; ++j) {{", f"        kept_check += f->P[{i}][j] - f->P[{i}][j];", "    }"]
    lines += ["} else {", f"    kept_check = {zero};", "}"]
    return lines


def compact_tables(description: FilterDescription) -> dict[str, list[int]]:
    """Phi's CSR tables for the compact prediction kernels; empty when the prediction is unrolled."""
    return compact_predict_tables(description.structure) if description.compact else {}


def _segment_ref(ref, step: int | None = None) -> str:
    """``w->S[16+k]``: entry k of the segment that starts at ``ref`` (no space inside the index: lines wrap at spaces); entry ``step`` if given."""
    *head, offset = ref.index
    index = f"[{offset + step}]" if step is not None else (f"[{offset}+k]" if offset else "[k]")
    return f"{POINTERS[ref.owner]}->{ref.array}" + "".join(f"[{i}]" for i in head) + index


def _shift(ref: Ref) -> Ref:
    return Ref(ref.owner, ref.array, ref.index[:-1] + (ref.index[-1] + 1,))


def _column_pair(first, second) -> bool:
    """Whether two scalar statements are one in two lanes: x[p] and x[p+1], term by term the same shape.

    Each factor is the same in both statements (broadcast into the two lanes)
    or y[q] in the first and y[q+1] in the second (a pair); a term is a
    product of two factors or one factor.  Then both are one lane-pair sum,
    term by term in the same order in each lane (the same bits): E's unit
    columns S A(:, j), and the sparse terms of the Horner levels such as
    R(i, c) = R(i, c) + A(i, c) R(c, c) over consecutive i and c.  The target
    array is read only as each statement's own target (x[p] = x[p] + ...), so
    the lanes do not alias; two empty sums are a pair of zeros.  Entries e and
    e + 1 of F h (stored as lane pairs, not next to each other) are gathered,
    but not in a sum added to its target, which gcc -O2 pairs better itself
    (bench/bench_cycle.py).
    """
    if not (type(first) is Assign and type(second) is Assign) or len(first.terms) != len(second.terms):
        return False
    if not first.target.index or second.target != _shift(first.target) or paired(first.target):
        return False
    own = (first.target.owner, first.target.array)
    accumulates = any(first.target in t for t in first.terms)
    for a, b in zip(first.terms, second.terms):
        if len(a) != len(b) or not 1 <= len(a) <= 2:
            return False
        for x, y in zip(a, b):
            if (x.owner, x.array) == own and (x, y) != (first.target, second.target):
                return False
            if x != y and (x.owner == "local" or not x.index or y != _shift(x) or (paired(x) and accumulates)):
                return False
    return True


def _lane_operand(x, y) -> str:
    """Factors x (first lane) and y (second lane) of :func:`_column_pair` as one lane pair."""
    if x == y:
        return _broadcast(x)
    return f"lane_pair_of({c_ref(x)}, {c_ref(y)})" if paired(x) else f"lane_pair_load(&{c_ref(x)})"


def _column_pair_lines(first, second) -> list[str]:
    """The C of two statements of :func:`_column_pair`, as one lane-pair sum stored once."""
    if not first.terms:
        return [f"lane_pair_store(&{c_ref(first.target)}, lane_pair_of(0, 0));"]
    lines = ["{"]
    for n, (a, b) in enumerate(zip(first.terms, second.terms)):
        operands = [_lane_operand(x, y) for x, y in zip(a, b)]
        if n == 0:
            value = f"lane_pair_product({operands[0]}, {operands[1]})" if len(operands) == 2 else operands[0]
            lines.append(f"    lane_pair pair = {value};")
        elif len(operands) == 2:
            lines.append(f"    pair = lane_pair_add_product(pair, {operands[0]}, {operands[1]});")
        else:
            lines.append(f"    pair = lane_pair_add(pair, {operands[0]});")
    return lines + [f"    lane_pair_store(&{c_ref(first.target)}, pair);", "}"]


def _broadcast(factor) -> str:
    """A scalar factor in both lanes: one aligned load of a paired entry (its two copies), else the value twice."""
    return c_pair(factor) if paired(factor) else f"lane_pair_of({c_ref(factor)}, {c_ref(factor)})"


def _pair_loop(s) -> bool:
    """Whether a segment is summed as lane pairs, two entries a step: even length, each factor a paired entry.

    The same products summed in the same order in each lane as the scalar loop
    (the same bits); the factor is read broadcast from its two stored copies
    with one aligned load, where gcc -O2 vectorizing the scalar loop itself
    broadcasts every factor on entry to the function and, with more factors
    than registers, spills and reloads them (bench/bench_cycle.py: 70 fewer
    instructions per saturated Horner level on the paper's model).
    """
    return s.length % 2 == 0 and bool(s.terms) and all(paired(factor) for factor, _ in s.terms)


#: Pair segments of at most this many entries are printed step by step, not as a loop: in a loop of so few
#: steps whose stores cannot alias F h (E = A S into Phi), gcc -O2 hoists the factors' loads out of it and
#: spills them to the stack (bench/bench_cycle.py: 47 fewer instructions in horner_transition at 18 states).
UNROLLED_PAIR_LENGTH = 6


def _pair_segment_lines(s, step: int | None = None) -> list[str]:
    """A segment of :func:`_pair_loop` at entries k, k + 1 (``step``, step + 1 if given): one lane-pair sum, stored once."""
    target = _segment_ref(s.target, step)
    products = [(c_pair(factor), f"lane_pair_load(&{_segment_ref(source, step)})") for factor, source in s.terms]
    if s.accumulate:
        lines = [f"lanes = lane_pair_load(&{target});"]
        lines += [f"lanes = lane_pair_add_product(lanes, {a}, {b});" for a, b in products]
    else:
        lines = [f"lanes = lane_pair_product({products[0][0]}, {products[0][1]});"]
        lines += [f"lanes = lane_pair_add_product(lanes, {a}, {b});" for a, b in products[1:]]
    return lines + [f"lane_pair_store(&{target}, lanes);"]


def discretize_lines(statements, read_back: bool = False, two_lanes: bool = False) -> list[str]:
    """C lines of a discretize block: scalar statements one per line, consecutive segments as one fixed-trip loop over k.

    The loop (even length, contiguous rows, no aliasing between targets and
    sources) is the shape gcc -O2 vectorizes with its very cheap cost model;
    one loop for all rows loads each source segment once per step.
    """
    lines: list[str] = []
    loop = None  # the length of the loop being printed (consecutive segments of one length share it)
    statements = list(statements)
    paired_second = set()  # the second statements of column pairs, printed with the first
    short = [isinstance(s, SegmentAssign) and _pair_loop(s) and s.length <= UNROLLED_PAIR_LENGTH for s in statements]
    for n, s in enumerate(statements):
        if n in paired_second:
            continue
        if short[n]:  # with the short pair segments after it of its length, step by step
            if loop is not None:
                lines.append("}")
                loop = None
            run = [n]
            while run[-1] + 1 < len(statements) and short[run[-1] + 1] and statements[run[-1] + 1].length == s.length:
                run.append(run[-1] + 1)
            for step in range(0, s.length, 2):
                lines += ["{", "    lane_pair lanes;"]
                lines += [f"    {line}" for m in run for line in _pair_segment_lines(statements[m], step)]
                lines.append("}")
            paired_second.update(run[1:])
            continue
        if not read_back and n + 1 < len(statements) and _column_pair(s, statements[n + 1]):
            if loop is not None:
                lines.append("}")
                loop = None
            lines += _column_pair_lines(s, statements[n + 1])
            paired_second.add(n + 1)
            continue
        if isinstance(s, SegmentAssign):
            pairs = _pair_loop(s)
            if loop != (s.length, pairs):
                lines += ["}"] if loop is not None else []
                lines.append(f"for (k = 0; k < {s.length}; k += 2) {{" if pairs else f"for (k = 0; k < {s.length}; ++k) {{")
                lines += ["    lane_pair lanes;"] if pairs else []
                loop = (s.length, pairs)
            if pairs:
                lines += [f"    {line}" for line in _pair_segment_lines(s)]
                continue
            value = " + ".join(f"{c_ref(factor)}*{_segment_ref(source)}" for factor, source in s.terms) if s.terms else "0"
            target = _segment_ref(s.target)
            lines.append(f"    {target} = {target + ' + ' if s.accumulate else ''}{value};")
            continue
        if loop is not None:
            lines.append("}")
            loop = None
        lines += c_lines(s, read_back, two_lanes)
    lines += ["}"] if loop is not None else []
    if any(line.startswith("for (k = 0;") for line in lines):
        lines.insert(0, "int k;")
    if read_back:  # the block's check: the sum of what it stored, read back after the stores
        lines.append("check = " + " + ".join(c_ref(s.targets[0]) for s in statements if isinstance(s, CheckedAssign)) + ";")
    return lines


def discretize_functions(blocks: list[DiscretizeBlock], prefix: str, scalar: str) -> list[dict[str, object]]:
    """Static C functions of the unrolled discretize, with the parameters each uses and how it is called.

    An owner is passed const unless the block writes into it; the run-time
    scalars (``h``, ``T``) are passed by value; the compile-time constants
    (1/k!, ...) are declared in the function as exact quotients the compiler folds.
    """
    types = {"matrices": f"{prefix}_matrices", "transition": f"{prefix}_transition", "scratch": f"{prefix}_discretize_scratch"}
    arguments = {"h": "T * modelgen_power_of_two(-halvings)", "T": "T", "c_out": "taylor_coefficient[k]", "c_in": "taylor_coefficient[k + 1]"}
    out = []
    for b in blocks:
        statements = b.block.statements
        scalars = scalar_statements(statements)
        written = {t.owner for s in scalars for t in (s.targets if hasattr(s, "targets") else (s.target,))}
        read = {r.owner for s in scalars for term in s.terms for r in term}
        owners = [o for o in ("matrices", "transition", "scratch") if o in written | read]
        parameters = [f"{'' if o in written else 'const '}{types[o]} *restrict {POINTERS[o]}" for o in owners]
        parameters += [f"const {prefix}_scalar {name}" for name in b.scalars]
        call = f"{b.block.name}({', '.join([POINTERS[o] for o in owners] + [arguments[n] for n in b.scalars])})"
        out.append(
            {
                "name": b.block.name,
                "signature": ", ".join(parameters),
                "call": f"{call};",
                "constants": [
                    (name, c_number(float(num), scalar) + (f" / {c_number(float(den), scalar)}" if den != 1 else ""))
                    for name, num, den in b.constants
                ],
                "lines": _paired_pointers(scalars, prefix) + discretize_lines(statements, b.block.read_back, b.block.two_lanes),
                "lane_pairs": two_lane_sums(b.block),
                "small": small_block(statements),
                "checked": b.block.checked,
                "read_back": b.block.read_back,
            }
        )
    return out


def _paired_pointers(scalars, prefix: str) -> list[str]:
    """The declaration of the pointer to the lane pairs of F h where a block reads or writes them (printer.PAIRED)."""
    targets = [t for s in scalars for t in (s.targets if hasattr(s, "targets") else (s.target,))]
    refs = targets + [r for s in scalars for term in s.terms for r in term]
    first = next((r for r in refs if paired(r)), None)
    return [c_paired_pointer(first, f"{prefix}_scalar", any(paired(t) for t in targets))] if first else []


def _norm_rows(structure: FilterStructure) -> list[tuple[int, list[tuple[int, int]]]]:
    """Rows of F with their (entry, column) pairs, in storage order, for the unrolled ||F||_D."""
    rows: dict[int, list[tuple[int, int]]] = {}
    for e, (i, j) in enumerate(structure.entries("F")):
        rows.setdefault(i, []).append((e, j))
    return sorted(rows.items())


def _scaled_norm_rows(structure: FilterStructure, scaling: tuple[int, ...], scalar: str) -> list[tuple[int, list[tuple[int, str | None]]]]:
    """Rows of F with (entry, d_j / d_i printed, None for 1) for ||F||_D with D = 2^scaling fixed at generation time."""
    return [
        (i, [(e, c_number(2.0 ** (scaling[j] - scaling[i]), scalar) if scaling[j] != scaling[i] else None) for e, j in entries])
        for i, entries in _norm_rows(structure)
    ]


def _balanced_norm_lines(rows: list[tuple[int, list[tuple[int, str | None]]]], scalar: str, scalar_type: str) -> list[str]:
    """The body of the unrolled ||F||_D = max_i sum_j |F_ij| d_j / d_i: two rows at a time, one in each lane.

    Each lane sums its row's terms in the reference's order (the same bits as
    one row at a time); the shorter row's lane adds zeros past its end (exact:
    the terms are not negative) and a factor of 1 multiplies where the other
    lane's term has a factor (exact).  The rows are paired longest first; the
    norm is used only where F is finite (discretize refuses it otherwise), so
    the maximum does not depend on the order of the rows.  One product and one sum per two terms
    (bench/bench_cycle.py: 36 fewer instructions per cycle at 18 states).

    ``*rows_sum`` gets the sum of every row's sum, which discretize tests for
    F's finiteness instead of a pass of its own over F (it is computed
    first; a non-finite F makes it NaN or infinite, as the sum of F's values
    does): one more addition per two rows.
    """
    fabs = "fabsf" if scalar == "float" else "fabs"
    one, zero = c_number(1.0, scalar), c_number(0.0, scalar)
    ordered = sorted(rows, key=lambda row: -len(row[1]))
    lines = ["lane_pair lanes, total;"] if len(ordered) > 1 else []
    for k in range(0, len(ordered) - 1, 2):
        (_, a), (_, b) = ordered[k], ordered[k + 1]
        for n in range(len(a)):
            (ea, fa), (eb, fb) = a[n], b[n] if n < len(b) else (None, None)
            value = f"lane_pair_of({fabs}(m->F[{ea}]), " + (f"{fabs}(m->F[{eb}]))" if eb is not None else f"{zero})")
            if fa is not None or fb is not None:
                factor = f"lane_pair_of({fa or one}, {fb or one})"
                lines.append(f"lanes = lane_pair_product({value}, {factor});" if n == 0 else
                             f"lanes = lane_pair_add_product(lanes, {value}, {factor});")
            else:
                lines.append(f"lanes = {value};" if n == 0 else f"lanes = lane_pair_add(lanes, {value});")
        lines.append("norm = lane_pair_max(lanes, norm);")
        lines.append("total = lanes;" if k == 0 else "total = lane_pair_add(total, lanes);")
    total = "lane_pair_sum(total)" if len(ordered) > 1 else ""
    if len(ordered) % 2:
        _, entries = ordered[-1]
        lines.append(f"const {scalar_type} v = " + " + ".join(f"{fabs}(m->F[{e}])" + (f" * {f}" if f else "") for e, f in entries) + ";")
        lines.append("norm = v > norm ? v : norm;")
        total = f"{total} + v" if total else "v"
    lines.append(f"*rows_sum = {total or zero};")
    return lines


def _balance_states(structure: FilterStructure) -> list[tuple[int, str]]:
    """States with an off-diagonal entry of F in their row and column ('both'), row only or column only.

    A state with neither never moves in Osborne's balancing (its step is 0), so
    the unrolled sweep leaves it out.
    """
    rows = {i for i, j in structure.entries("F") if i != j}
    columns = {j for i, j in structure.entries("F") if i != j}
    out = []
    for i in range(structure.n_states):
        if i in rows and i in columns:
            out.append((i, "both"))
        elif i in rows:
            out.append((i, "row"))
        elif i in columns:
            out.append((i, "column"))
    return out


def _struct_list(layout: CLayout) -> list[dict[str, object]]:
    """The header's structs, in order, with their doc comments and layout fields."""
    return [
        {"name": "matrices", "doc": "Structural nonzeros of F, G, H (row, column pairs in the tables below).", "fields": layout.matrices},
        {"name": "transition", "doc": "The transition over one step T (from discretize).", "fields": layout.transition},
        {"name": "filter", "doc": "The filter state: estimate and covariance (or its factors).", "fields": layout.filter},
        {"name": "discretize_scratch", "doc": "Scratch memory of discretize.", "fields": layout.discretize_scratch},
        {
            "name": "filter_scratch",
            "doc": "Scratch memory of predict, update and set_covariance.",
            "fields": layout.filter_scratch,
        },
    ]


def structs(layout: CLayout) -> list[dict[str, object]]:
    """The header's structs with each member printed as a C declarator."""
    return [
        {**s, "fields": [{"declarator": c_declarator(f), "comment": f.comment} for f in s["fields"]]}
        for s in _struct_list(layout)
    ]


def _struct_bytes(fields, scalar_size: int) -> int:
    total = 0
    for f in fields:
        count = 1
        for d in f.dims:
            count *= d.value
        total += count * scalar_size
    return total


def struct_bytes(layout: CLayout, scalar_size: int) -> dict[str, int]:
    """Bytes of each struct, and of the workspace union (the larger scratch struct)."""
    sizes = {s["name"]: _struct_bytes(s["fields"], scalar_size) for s in _struct_list(layout)}
    sizes["workspace"] = max(sizes["discretize_scratch"], sizes["filter_scratch"])
    return sizes


def source_parts(description: FilterDescription) -> list[str]:
    """Templates included by c_source.c.j2, chosen by the options."""
    options = description.options
    parts = ["c_predict_ud.c.j2" if options.ud else "c_predict_covariance.c.j2"]
    if description.derived.n_measurements:
        if options.ud:
            parts.append("c_update_bierman.c.j2")
        elif options.update == "sequential":
            parts.append("c_update_sequential.c.j2")
        else:
            parts.append("c_update_vector.c.j2")
    parts.append("c_smoother.c.j2")
    return parts


def smoother_context(description: FilterDescription) -> dict[str, object]:
    """The backward pass's reset block: its states and G(dx)^-1 printed row-major over them (None: G = I)."""
    reset = reset_inverse(description.derived)
    if reset is None:
        return {"reset": None}
    printer = CPrinter(description.options.scalar, {symbol: f"dx[{i}]" for symbol, i in zip(reset.symbols, reset.states)})
    size = len(reset.states)
    return {"reset": {"size": size, "states": [str(i) for i in reset.states],
                      "entries": [(a * size + b, printer.doprint(reset.matrix[a, b]))
                                  for a in range(size) for b in range(size)]}}


def _update_doc(description: FilterDescription) -> str:
    options = description.options
    if options.ud:
        return "Bierman, one scalar measurement after another"
    kind = "one scalar measurement after another" if options.update == "sequential" else "all at once, Cholesky solve"
    return kind + (", Joseph form" if options.covariance_update == "joseph" else ", standard form")


def c_context(description: FilterDescription) -> dict[str, object]:
    """Everything the C templates (product and harness) read."""
    model, options, structure, sizes = description.model, description.options, description.structure, description.sizes
    n, nw, nm = sizes.n, sizes.nw, sizes.nm
    prefix = model.name.upper()
    tables = index_tables(structure)
    compact = compact_tables(description)
    if compact:
        tables["max_index"] = max(tables["max_index"], len(compact["col"]) + 1)
    if tables["max_index"] >= 65536:
        raise ModelError(f"model {model.name!r} is too large for 16-bit index tables")
    index_type = "unsigned char" if tables["max_index"] < 256 else "unsigned short"
    spell = scalar_spellings(options.scalar)
    packed = description.packed
    at_upper, at_any = accessors(packed, prefix)
    unrolled = description.discretize_plan if description.discretize_unrolled else None
    compact_discretize = compact_discretize_context(structure) if not unrolled and not options.van_loan else None
    scaling = nominal_scaling(description.derived)  # D of ||F||_D fixed at generation time (None: balanced at run time)
    balancing = any(i != j for i, j in structure.entries("F"))  # the template's run-time sweeps (also from a fixed D: step_plan)
    layout = c_layout(
        sizes, options, prefix,
        UnrolledDiscretizeSizes(unrolled.term_size, unrolled.active_size, balancing) if unrolled else None,
        compact_discretize["sizes"] if compact_discretize else None,
    )
    discretize = discretize_functions(description.discretize_blocks, model.name, options.scalar) if unrolled else []
    calls = {f["name"]: f["call"] for f in discretize}
    printer = CPrinter(options.scalar, {p.sym: f"params->{p.name}" for p in model.parameters})
    targets, _, block = description.evaluation
    state_block, state_commit, _ = description.state_predict
    state_lines = state_block.statements
    state_printed = [line for s in state_lines for line in c_lines(s, two_lanes=state_block.two_lanes)]
    blocks = description.predict_blocks[0]
    predict_functions = block_functions(blocks, model.name)
    parts = source_parts(description)
    roundoff = FLOAT_ROUNDOFF if options.scalar == "float" else DOUBLE_ROUNDOFF
    unit_rows = set(structure.unit_rows)
    probe = next(((i, j) for i, j in structure.entries("Phi") if i not in unit_rows), (0, 0))  # an entry predict reads
    return {
        **description.shared_context(),
        **spell,
        "banner_c": BANNER,
        "banner_hash": HASH_BANNER,
        "p": model.name,
        "P": prefix,
        "guard": f"MODELGEN_{prefix}_H",
        "scalar": options.scalar,
        "parameters": [
            {
                "name": p.name,
                "symbol": p.symbol,
                "unit": p.unit,
                "description": p.description,
                "default": c_number(p.value, options.scalar),
            }
            for p in model.parameters
        ],
        "nnz_f": sizes.nnz_f,
        "nnz_g": sizes.nnz_g,
        "nnz_h": sizes.nnz_h,
        "nnz_phi": sizes.nnz_phi,
        "n_packed": sizes.packed,
        "n_upper": max(sizes.upper, 1),
        "n_upper_real": sizes.upper,
        "n_weights": n + nw,
        "dim_f": max(sizes.nnz_f, 1),
        "dim_w": max(nw, 1),
        "dim_m": max(nm, 1),
        "dim_g": max(sizes.nnz_g, 1),
        "dim_h": max(sizes.nnz_h, 1),
        "index_type": index_type,
        "tables": tables,
        "structs": structs(layout),
        "form_macro": "FORM_UD" if options.ud else "FORM_COVARIANCE",
        "ud": options.ud,
        "sequential": options.sequential,
        "packed": packed,
        "joseph": options.covariance_update == "joseph",
        "at_upper": at_upper,
        "at_any": at_any,
        "pivot_tolerance": f"(16 * {prefix}_N_STATES * {spell['epsilon']})",
        "update_doc": _update_doc(description),
        "part_templates": parts,
        "smoother": smoother_context(description),
        "source_templates": ["c_source.c.j2", *(["c_discretize_van_loan.c.j2"] if options.van_loan else []), *parts],
        "evaluate": {
            "temporaries": [(str(s), printer.doprint(e)) for s, e in block.temporaries],
            "outputs": [(f"{t.matrix}[{t.k}]", printer.doprint(e)) for t, e in zip(targets, block.outputs)],
        },
        "poles": [
            {"text": named(pole.denominator, model), "value": printer.doprint(pole.denominator), "argument": printer.doprint(pole.argument)}
            for pole in description.poles
        ],
        "series_range": c_number(series_range(options.taylor_order, roundoff), options.scalar),
        "taylor_tolerance": c_number(options.taylor_tolerance, options.scalar)
        if options.taylor_tolerance is not None and options.taylor_tolerance > roundoff
        else None,  # a tolerance within the rounding of the arithmetic (any in float): the fixed order
        "recompute_threshold": c_number(options.recompute_threshold, options.scalar) if options.recompute_threshold is not None else None,
        # theta_m of the plan's single-step fast path (double only: the thresholds are of the double bound)
        "single_step_thresholds": [c_number(x, "double") for x in single_step_thresholds(options.taylor_order, options.taylor_tolerance)]
        if options.scalar == "double" and options.taylor_tolerance is not None and options.taylor_tolerance > roundoff
        else None,
        "discretize_unrolled": bool(unrolled),
        "van_loan": options.van_loan,
        "qd_margin": QD_MARGIN,
        "discretize_template": "c_discretize_van_loan.c.j2" if options.van_loan else "c_discretize.c.j2",
        "compact_discretize": compact_discretize,  # the compact Taylor discretize's index tables (None otherwise)
        "balance_entries": [(e, i, j) for e, (i, j) in enumerate(structure.entries("F")) if i != j],
        "balance_rows": sorted({i for i, j in structure.entries("F") if i != j}),
        "balance_columns": sorted({j for i, j in structure.entries("F") if i != j}),
        "balance_states": _balance_states(structure),
        "norm_rows": _norm_rows(structure),
        "balance_scaling": list(scaling) if scaling is not None else None,
        "balanced_norm_lines": _balanced_norm_lines(_scaled_norm_rows(structure, scaling, options.scalar), options.scalar,
                                                    f"{model.name}_scalar") if scaling is not None else [],
        "discretize_sizes": {"terms": unrolled.term_size, "active": unrolled.active_size} if unrolled else {},
        "discretize_blocks": discretize,
        "discretize_calls": {f["name"]: f["call"] for f in discretize},
        "horner_levels": [(calls[horner_level_name(1, 0)], calls[horner_level_name(1, 1)])] if horner_level_name(1, 0) in calls else [],
        # the levels below the top: none where every stored row is read by no row of F (a clock's bias and drift)
        "horner_saturated": tuple(calls[horner_level_name(0, parity, True)] for parity in (0, 1))
        if horner_level_name(0, 0, True) in calls else (),
        "horner_last": calls.get(HORNER_LAST, ""),  # k = 0 where rows that no row of F reads are left out above it
        "taylor_coefficients": [c_number(1.0, options.scalar) + f" / {c_number(float(math.factorial(k + 1)), options.scalar)}"
                                for k in range(options.taylor_order + 1)],
        "discretize_sets_qd": "process_noise" in calls,  # the unrolled Q_d block sets every entry (no zero loop first)
        "discretize_noise_calls": [
            ("qd_check += " if f["checked"] else "") + f["call"]
            for f in discretize
            if f["name"] in ("noise_input", "noise_input_times_step") or f["name"].startswith("process_noise")
        ],
        "predict_state": state_printed,
        "predict_state_pairs": two_lane_sums(state_block),
        "runtime_headers": [path.name for path in RUNTIME_HEADERS],
        "two_lane_sums": any("lane_pair_" in line for line in state_printed + [line for f in [*predict_functions, *discretize] for line in f["lines"]]),
        "min_lane_terms": 2 * MIN_LANE_PAIRS,  # the compact propagate's two-lane order (kernels.lane_split)
        # a row of Phi long enough for it (without one, gcc -Warray-bounds sees the lanes' reads beyond small tables)
        "compact_two_lanes": any(len(row) >= 2 * MIN_LANE_PAIRS for row in structure.rows("Phi")),
        "predict_state_small": small_block(state_lines),
        "predict_state_check": [
            f"check += {ref} - {ref};"
            for ref in [c_ref(s.target) for s in state_lines] + [f"f->x[{i}]" for i in structure.unit_rows]
        ],
        "free_parameters": [p.name for p in model.parameters if p.value is None],
        "probe": probe,
        "predict_state_commit": [c_statement(s) for s in state_commit],
        "probe_entry": structure.entries("Phi").index(probe),
        "covariance_commit_rows": description.covariance_commit,
        "predict_commit_rows": description.predict_commit,
        "predict_keeps": bool(description.kept_pairs),  # Pn's rescan covers the computed entries only
        "kept_check": kept_check_lines(description.kept_pairs_to_check, spell["zero"]),
        "predict_blocks": predict_functions,
        "compact": bool(compact),
        "compact_tables": {**{k: _table(v) for k, v in compact.items()}, "nnz": max(len(compact.get("col", ())), 1)},
        "struct_bytes": struct_bytes(layout, scalar_bytes(options.scalar)),
        "qd_variance_check": [] if options.ud else qd_variance_check(n, prefix, spell["zero"], bool(compact)),
        "first_free_parameter": next((p.name for p in model.parameters if p.value is None), None),
        "example_value": c_number(0.5, options.scalar),
        "example_variance": c_number(1e-4, options.scalar),
        "example_step": c_number(1.0, options.scalar),
        "example_z": ", ".join(c_number(0.1 * (k + 1) * (-1) ** k, options.scalar) for k in range(max(nm, 1))),
    }
