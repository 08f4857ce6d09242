"""The compact discretize's flop counts (file headers) agree with an independent count over the patterns.

``compact_discretize.compact_discretize_cost`` walks the index tables the C
loops run over (F_row_start, A_col, A_diagonal_from, span_start/end,
closure_col, closure_diagonal_from, gamma_column_start).  Here the same
operations are counted from the structure alone (F, G, Phi's, Gamma's and
Q_d's patterns, each row's span recomputed from Phi's pattern), loop by
loop of c_discretize.c.j2's compact branch, so a table or a cost that
drifts from the other fails.  The header of a large model must print these
counts, not the old dense-loop formula.
"""

from __future__ import annotations

import numpy as np
import pytest

from modelgen.codegen.compact_discretize import CompactDiscretizeTables, compact_discretize_cost
from modelgen.codegen.generate import describe
from modelgen.codegen.kernels import OperationCount, discretize_cost
from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.structure import FilterStructure, filter_structure
from modelgen.derive.symbolic import derive
from modelgen.model.loading import load_model_text
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
    norm = OperationCount(sweeps + nnz + 3 * order + 6, 2 * sweeps + nnz + order + 2) if nnz else OperationCount(0, 0)
    first = OperationCount(norm.multiplications + series[-1].multiplications + mul, norm.additions + series[-1].additions + add)
    return series, doubling, first


def structures() -> dict[str, FilterStructure]:
    out = {}
    for name, text in DEGENERATE.items():
        derived = derive(load_model_text(text, filename="m.yaml"))
        out[name] = filter_structure(derived.structure("F"), derived.structure("G"), derived.structure("H"), ORDER)
    derived = derive(large_model(40))
    out["large_40"] = filter_structure(derived.structure("F"), derived.structure("G"), derived.structure("H"), ORDER)
    return out


STRUCTURES = structures()


@pytest.mark.parametrize("name", STRUCTURES)
@pytest.mark.parametrize("ud", [False, True])
@pytest.mark.parametrize("fixed", [False, True])
def test_counts_from_the_tables_are_the_counts_over_the_patterns(name, ud, fixed):
    """Every order's series, one doubling and the first call: the tables' count is the patterns' count."""
    structure = STRUCTURES[name]
    cost = compact_discretize_cost(CompactDiscretizeTables(structure), ORDER, ud, fixed)
    series, doubling, first = pattern_count(structure, ORDER, ud, fixed)
    assert list(cost.series) == series
    assert cost.doubling == doubling
    assert cost.first(ORDER) == first


def test_the_count_sees_a_wider_span():
    """A span one block of 4 wider in the tables changes the count: it is read from the tables, not assumed."""
    structure = STRUCTURES["large_40"]
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
