"""The compact discretize's flop counts (file headers) agree with an independent count over the patterns.

``compact_discretize.compact_discretize_cost`` walks the index tables the C
loops run over (F_row_start, A_col, A_diagonal_from, span_start/end,
closure_col, closure_diagonal_from, gamma_column_start).  Here the same
operations are counted from the structure alone (F, G, Phi's, Gamma's and
Q_d's patterns, each row's span recomputed from Phi's pattern), loop by
loop of c_discretize.c.j2's compact branch, so a table or a cost that
drifts from the other fails.  An instrumented run checks the C itself: gcov's
line counts of the generated compact C times each statement's flops equal
the count at the order and doublings the run chose.  The header of a large
model must print these counts, not the old dense-loop formula.
"""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

from modelgen.codegen import kernels
from modelgen.codegen.compact_discretize import CompactDiscretizeTables, compact_discretize_cost
from modelgen.codegen.generate import describe, generate_code
from modelgen.codegen.kernels import OperationCount, discretize_cost
from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.structure import FilterStructure, filter_structure
from modelgen.derivation.discretization import nominal_scaling
from modelgen.derivation.symbolic import derive
from modelgen.model.loading import load_model_text
from tests.codegen.generated_support import write_files
from tests.codegen.large_model_support import large_model
from tests.codegen.test_large_models import DEGENERATE

ORDER = 9


def pattern_count(structure: FilterStructure, order: int, ud: bool, fixed_scaling: bool) -> tuple[list[OperationCount], OperationCount, OperationCount]:
    """(series at each order 1..``order``, one doubling, the first call at ``order``) from the patterns alone."""
    F, G, phi = structure.F.astype(bool), structure.G.astype(bool), structure.Phi.astype(bool)
    n, nw = G.shape
    f_entries = list(zip(*np.nonzero(F)))
    nnz = len(f_entries)

    def span(c: int) -> int:
        """Products of one row c of R added into another: its span rounded up to 4, or its diagonal alone."""
        cols = np.flatnonzero(phi[c])
        return 1 if len(cols) == 1 else -(-(cols[-1] - cols[0] + 1) // 4) * 4

    level = sum(span(c) for _, c in f_entries)
    second = sum(1 + int(F[c].sum()) - int(F[c, c]) for _, c in f_entries)
    series = []
    for m in range(1, order + 1):
        products = nnz + (second if m >= 2 else 0) + (max(m - 2, 0) + 1) * level if nnz else 0
        series.append(OperationCount(nnz + products if nnz else 0, products + n if nnz else 0))
    busy = [(i, j) for i, j in zip(*np.nonzero(phi)) if F[i].any()]
    products = sum(2 * span(j) for _, j in busy)
    doubling = OperationCount(products + len(busy), products + 3 * len(busy))
    sg = sum(int(G[j].sum()) for _, j in zip(*np.nonzero(phi))) if nw else 0
    gamma = structure.Gamma.astype(bool)
    mul, add = sg, sg
    if nw and ud:
        mul += int(gamma.sum()) + nw
    elif nw and structure.Qd.astype(bool).any():
        pairs = sum(k * (k + 1) // 2 for k in gamma.sum(axis=0))
        mul, add = mul + 2 * int(gamma.sum()) + pairs, add + pairs
    off = nnz - int(np.trace(F))
    sweeps = 0 if fixed_scaling or not nnz else 8 * off
    rows_sum = structure.n_states if fixed_scaling else 0  # the fixed-D norm's total of its rows: F's finiteness test
    norm = OperationCount(sweeps + nnz + 3 * order + 6, 2 * sweeps + nnz + order + 2 + rows_sum) if nnz else OperationCount(0, 0)
    first = OperationCount(norm.multiplications + series[-1].multiplications + mul, norm.additions + series[-1].additions + add)
    return series, doubling, first


#: The structures counted: the degenerate models' (no F, an empty row of F, a chain) and a 40-state augmented model's.
STRUCTURE_NAMES = (*DEGENERATE, "large_40")


@pytest.fixture(scope="session")
def structures() -> dict[str, FilterStructure]:
    """Each of :data:`STRUCTURE_NAMES` derived once per session (at collection it cost every run 1.5 s)."""
    out = {}
    for name, text in DEGENERATE.items():
        derived = derive(load_model_text(text, filename="m.yaml"))
        out[name] = filter_structure(derived.structure("F"), derived.structure("G"), derived.structure("H"), ORDER)
    derived = derive(large_model(40))
    out["large_40"] = filter_structure(derived.structure("F"), derived.structure("G"), derived.structure("H"), ORDER)
    assert tuple(out) == STRUCTURE_NAMES
    return out


@pytest.mark.parametrize("name", STRUCTURE_NAMES)
@pytest.mark.parametrize("ud", [False, True])
@pytest.mark.parametrize("fixed", [False, True])
def test_counts_from_the_tables_are_the_counts_over_the_patterns(name, ud, fixed, structures):
    """Every order's series, one doubling and the first call: the tables' count is the patterns' count."""
    structure = structures[name]
    cost = compact_discretize_cost(CompactDiscretizeTables(structure), ORDER, ud, fixed)
    series, doubling, first = pattern_count(structure, ORDER, ud, fixed)
    assert list(cost.series) == series
    assert cost.doubling == doubling
    assert cost.first(ORDER) == first


def test_the_count_sees_a_wider_span(structures):
    """A span one block of 4 wider in the tables changes the count: it is read from the tables, not assumed."""
    structure = structures["large_40"]
    tables = CompactDiscretizeTables(structure)
    before = compact_discretize_cost(tables, ORDER, False, False)
    wide = next(c for c in range(structure.n_states) if len(tables.closure_rows[c]) > 1)
    spans = list(tables.spans)
    spans[wide] = (spans[wide][0], spans[wide][1] + 4)
    object.__setattr__(tables, "spans", spans)  # the cached_property's slot
    after = compact_discretize_cost(tables, ORDER, False, False)
    readers = sum(1 for i, c in structure.entries("F") if c == wide)
    assert after.series[-1].multiplications - before.series[-1].multiplications == 4 * readers * (ORDER - 1)
    assert after.doubling != before.doubling


def test_a_large_model_header_prints_the_compact_count():
    """Above the threshold the header's discretize lines are the tables' count, far below the old dense-loop formula."""
    derived = derive(large_model(40))
    for options in (CodegenOptions(), CodegenOptions(form="ud")):
        description = describe(derived, options)
        assert description.compact and not description.discretize_unrolled
        cost = description.compact_discretize_cost
        assert description.costs["discretize"] == cost.first(options.taylor_order)
        assert description.costs["discretize, each doubling (long steps)"] == cost.doubling
        assert f"discretize: {cost.first(options.taylor_order)}" in description.cost_lines()
        assert cost.first(options.taylor_order).total < discretize_cost(description.structure, options.taylor_order).total / 2


# --- an instrumented run: gcov's line counts of the generated C, times each line's flops ---------------

#: The compact discretize's functions whose arithmetic the count covers (the plan's bound, taylor_plan,
#: and the balancing's integer steps are not floating-point work of the series).
COUNTED = ("add_scaled_span", "horner_level", "horner_top_level", "horner_second_level", "doubling",
           "noise_input", "process_noise", "balanced_norm", "_discretize")

MAIN = """#include <stdio.h>
#include <stdlib.h>
#include "{name}.h"
static {name}_matrices m;
static {name}_transition t;
static {name}_workspace w;
int main(int argc, char **argv)
{{
    int e;
    (void)argc;
    for (e = 0; e < {P}_NNZ_F; ++e) m.F[e] = 0.01 * ((e % 5) + 1) * ((e % 2) ? 1.0 : -1.0);
    for (e = 0; e < {P}_NNZ_G; ++e) m.G[e] = 1.0 + 0.1 * e;
    for (e = 0; e < {P}_N_NOISES; ++e) m.q[e] = 1.0;
    printf("%d\\n", {name}_discretize(&m, atof(argv[1]), &t, &w));
    return 0;
}}
"""


def _strip(text: str) -> str:
    """``text`` without index brackets and call arguments (integer arithmetic, or counted in the callee)."""
    out, stack = [], []
    for k, ch in enumerate(text):
        if ch in "[(":
            call = ch == "(" and k > 0 and (text[k - 1].isalnum() or text[k - 1] == "_")
            stack.append(ch == "[" or call or (stack and stack[-1]))
            if not stack[-1]:
                out.append(ch)
            continue
        if ch in "])":
            hidden = stack.pop()
            if not hidden:
                out.append(ch)
            continue
        if not (stack and stack[-1]):
            out.append(ch)
    return "".join(out)


def line_flops(source: str) -> tuple[int, int]:
    """(mul, add) of one C statement: ``*`` and ``/`` are products, binary ``+`` and ``-`` and ``+=`` sums.

    Loop and branch headers, declarations without a value and the finiteness
    probes (``check += v - v``, the sums of the model matrices' check
    ``sums[0] += m->F[e]``) count nothing.
    """
    text = re.sub(r"/\*.*?(\*/|$)", "", source).strip()
    if not text.endswith(";") or text.startswith(("for ", "if ", "} else", "return", "check +=", "sums[")) or "check += " in text:
        return 0, 0
    if re.fullmatch(r"[^=]+ \+= (.+) - \1;", text):  # a finiteness probe: v - v is 0 or NaN
        return 0, 0
    text = _strip(text[:-1])
    if " += " in text:
        rhs, add = text.split(" += ", 1)[1], 1
    elif " = " in text:
        rhs, add = text.split(" = ", 1)[1], 0
    else:
        return 0, 0
    if "?" in rhs:
        return 0, 0
    return rhs.count(" * ") + rhs.count(" / "), add + rhs.count(" + ") + rhs.count(" - ")


def measured_run(folder, name: str, T: float) -> dict[str, object]:
    """Run ``<name>_discretize`` at step T under gcov: its flops, order, doublings and balancing sweeps."""
    (folder / "main.c").write_text(MAIN.format(name=name, P=name.upper()))
    for stale in folder.glob("*.gcda"):
        stale.unlink()
    cc = ["gcc", "-std=c99", "-O0", "--coverage", "-c"]
    subprocess.run([*cc, f"{name}.c"], cwd=folder, check=True)
    subprocess.run([*cc, "main.c"], cwd=folder, check=True)
    subprocess.run(["gcc", "--coverage", "-o", "run", f"{name}.o", "main.o", "-lm"], cwd=folder, check=True)
    assert subprocess.run(["./run", repr(T)], cwd=folder, check=True, capture_output=True, text=True).stdout.strip() == "0"
    subprocess.run(["gcov", f"{name}.c"], cwd=folder, check=True, capture_output=True)
    mul = add = 0
    function = ""
    calls: dict[str, int] = {}
    by_function: dict[str, int] = {}
    pending, pending_count = "", ""
    for line in (folder / f"{name}.c.gcov").read_text().splitlines():
        count_text, _, rest = line.partition(":")
        source = rest.partition(":")[2]
        if source and not source[0].isspace() and "(" in source and not source.rstrip().endswith(";"):
            function = source.split("(")[0].split()[-1]
        if pending:  # a statement continued on this line: counted once, with its first line's count
            source, count_text, pending = pending + " " + source.strip(), pending_count, ""
        elif source.startswith(" ") and source.rstrip().endswith(("*", "+", "-", ",", "(")):
            pending, pending_count = source.rstrip(), count_text
            continue
        count_text = count_text.strip().rstrip("*")
        if not count_text.isdigit():
            continue
        count = int(count_text)
        for marker in ("horner_second_level(w", "horner_level(w->R[k", "doubling(w);", "changed |= modelgen_balance_step(",
                       "if (taylor_plan(norm, T, &halvings, &order) == "):
            if marker in source:
                calls[marker] = calls.get(marker, 0) + count
        if function.endswith(COUNTED) and not (function.endswith("_discretize") and function != f"{name}_discretize"):
            m, a = line_flops(source)
            mul, add = mul + m * count, add + a * count
            by_function[function] = by_function.get(function, 0) + (m + a) * count
    second, levels = calls.get("horner_second_level(w", 0), calls.get("horner_level(w->R[k", 0)
    return {
        "flops": OperationCount(mul, add),
        "order": 1 if not second else (2 if not levels else levels + 2),
        "halvings": calls.get("doubling(w);", 0),
        "sweeps": calls.get("changed |= modelgen_balance_step(", 0),
        "sweep_norms": calls.get("if (taylor_plan(norm, T, &halvings, &order) == ", 0),  # a rebalancing sweep's norm
        "by_function": by_function,
    }


def test_the_line_rule_counts_the_template_statements():
    """The rule of the instrumented count on the statements it meets: index arithmetic and calls' arguments are not flops."""
    assert line_flops("        target[j + 1] += a * source[j + 1];") == (1, 1)
    assert line_flops("            w->E_next[c] = E[i][j] + E[i][j] + w->E_row[j];") == (0, 2)
    assert line_flops("            v = fabs(m->F[c]) * power_of_two(exponent[x_F_col[c]] - exponent[i]);") == (1, 0)
    assert line_flops("        check += store_transition_row(t->Phi[i], w->R[1][i], span_start[i], span_end[i]);") == (0, 0)
    assert line_flops("    for (j = start; j < end; j += 4) {") == (0, 0)
    assert line_flops("        norm = v > norm ? v : norm;") == (0, 0)
    assert line_flops("        t->qw[c] = m->q[c] / T;") == (1, 0)
    assert line_flops("            out[i][c] += fh[x] * in[c][c]; /* row c of R is its diagonal */") == (1, 1)
    assert line_flops("            out[i][c] += fh[x] * in[c][c]; /* a comment that goes on") == (1, 1)
    assert line_flops("        sums[1] += m->F[e + 1] - m->F[e + 1];") == (0, 0)
    assert line_flops("            sums[1] += m->F[e + 1];") == (0, 0)
    assert line_flops("        sums[0] = (sums[0] + sums[1]) + (sums[2] + sums[3]);") == (0, 0)
    assert line_flops("        w->E[1] += m->F[e + 1] - m->F[e];") == (0, 2)


@pytest.mark.compile
@pytest.mark.parametrize("model", ["paper", "chain"])
@pytest.mark.parametrize("form", ["full", "ud"])
def test_an_instrumented_run_of_the_c_does_the_counted_flops(model, form, paper_derived, tmp_path, monkeypatch):
    """gcov's count of every executed flop of the compact C equals the tables' count at the order and doublings it ran.

    The paper's model (D fixed at generation time) and a chain of 3 (D
    balanced at run time) forced onto the compact loops, at a short step
    (no doubling) and a long one (several).  The balancing runs as many
    sweeps as it needs (at most 8, the count's bound; with the fixed D only
    when the plan on it needs a doubling, then from that D): the expectation uses
    the sweeps that ran; the plan's bound (taylor_plan) is left out of both.
    """
    if shutil.which("gcov") is None:
        pytest.skip("gcov is not installed")
    derived = paper_derived if model == "paper" else derive(load_model_text(DEGENERATE[model], filename="m.yaml"))
    name = derived.model.name
    options = CodegenOptions(form="ud") if form == "ud" else CodegenOptions()
    monkeypatch.setattr(kernels, "COMPACT_ABOVE_FLOPS", 0)
    description = describe(derived, options)
    assert not description.discretize_unrolled
    fixed = nominal_scaling(derived) is not None
    folder = write_files(tmp_path / "gen", generate_code(derived, options).files)
    cost = description.compact_discretize_cost
    structure = description.structure
    nnz = int(structure.F.sum())
    off = nnz - int(np.trace(structure.F.astype(int)))
    n = structure.n_states
    seen_doublings = set()
    for T in (1e-7, 600.0):
        run = measured_run(folder, name, T)
        sweeps = run["sweeps"] // n
        series, h = cost.series[run["order"] - 1], run["halvings"]
        # a fixed D: the sweeps (from that D) and their norm run only when the plan on it needs a doubling (step_plan);
        # each sweep that moved D takes its norm (the sweeps stop at one that leaves no doubling, which then is the
        # norm returned: no doubling in the end), and F's test is the sum of the fixed-D norm's rows
        rebalanced = fixed and sweeps > 0
        assert run["sweeps"] == sweeps * n and (sweeps == 0 if fixed and h == 0 else 1 <= sweeps <= 8)
        assert run["sweep_norms"] <= sweeps and (run["sweep_norms"] == 0 or rebalanced)
        norms = nnz * (1 + run["sweep_norms"] + (1 if rebalanced and h > 0 else 0))
        expected = OperationCount(
            series.multiplications + h * cost.doubling.multiplications + cost.noise.multiplications + norms + sweeps * off,
            series.additions + h * cost.doubling.additions + cost.noise.additions + norms + 2 * sweeps * off + (n if fixed else 0),
        )
        assert run["flops"] == expected, (T, run)
        seen_doublings.add(h > 0)
    assert seen_doublings == {False, True}
