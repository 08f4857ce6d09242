"""The memory of the filter cycle (issue 14, item 6): one row of M = Phi P, packed Pn and Q_d.

Row i of P_n = M Phi^T + Q_d needs only row i of M, so the unrolled kernel
computes row i of M right before row i of P_n and the scratch holds one row;
the new covariance Pn and the transition's Q_d are packed upper triangles
whatever P's storage, and discretize stores the balancing's sums only when
it balances at run time.  These tests prove the kernel never reads a row of
M other than the one just computed and the layouts (the conformance checks
prove the numbers).
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from modelgen.codegen.generate import describe, generate_code
from modelgen.codegen.kernels import CheckedAssign, covariance_predict
from modelgen.codegen.layout import ModelSizes, c_layout
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import derive


def _m_refs(statement) -> tuple[list, list]:
    """(M entries written, M entries read) by one kernel statement."""
    targets = statement.targets if isinstance(statement, CheckedAssign) else (statement.target,)
    written = [r for r in targets if r.array == "M"]
    read = [r for term in statement.terms for r in term if r.array == "M"]
    return written, read


@pytest.mark.parametrize("packed", [False, True], ids=["full", "packed"])
def test_each_row_of_pn_reads_only_the_row_of_m_computed_just_before_it(paper_derived, packed):
    structure = describe(paper_derived, CodegenOptions()).structure
    n = structure.n_states
    unit = set(structure.unit_rows)
    blocks, _ = covariance_predict(structure, packed)
    holds = None  # the row of Phi P that M holds now
    rows_read = set()
    for block in blocks:
        kind, row = block.name.rsplit("_row_", 1)
        row = int(row)
        for statement in block.statements:
            written, read = _m_refs(statement)
            assert all(len(r.index) == 1 and 0 <= r.index[0] < n for r in written + read), block.name
            if read:
                assert kind == "propagate" and holds == row, f"{block.name} reads M while it holds row {holds}"
                rows_read.add(row)
        if kind == "phi_times_p":
            holds = row
    assert rows_read == set(range(n)) - unit  # a unit row of Phi reads P in place


def test_no_square_array_in_the_filter_steps_scratch_and_q_d_packed_in_the_transition(paper_derived):
    """M is one row, Pn and the transition's Q_d the packed upper triangle whatever P's storage."""
    sizes = ModelSizes.of(paper_derived)
    for options in (CodegenOptions(), CodegenOptions(update="sequential"), CodegenOptions(storage="packed"),
                    CodegenOptions(process_noise="van-loan")):
        layout = c_layout(sizes, options, "NED_DOPPLER18")
        fields = {f.name: [d.value for d in f.dims] for f in layout.filter_scratch}
        assert not [name for name, dims in fields.items() if dims == [sizes.n, sizes.n]], options.slug()
        assert fields["M"] == [sizes.n] and fields["Pn"] == [sizes.packed], options.slug()
        transition = {f.name: [d.value for d in f.dims] for f in layout.transition}
        assert transition["Qd"] == [sizes.packed], options.slug()


def _discretize_scratch(header: str) -> str:
    return header[header.index("/* Scratch memory of discretize. */"):header.index("_discretize_scratch;")]


def test_discretize_keeps_the_balancing_sums_only_where_it_can_balance_at_run_time(paper_model):
    """With a check operating point D is fixed at generation time, and F is rebalanced at run time only before a
    doubling (step_plan), which needs the sums as the run-time balancing of a model without one does; the fixed
    D's one-pass norm needs nothing beside them."""
    fixed = generate_code(derive(paper_model)).files["ned_doppler18.h"]
    assert "row_sum" in _discretize_scratch(fixed) and "col_sum" in _discretize_scratch(fixed)
    assert "rebalanced_norm" in generate_code(derive(paper_model)).files["ned_doppler18.c"]
    balanced = generate_code(derive(replace(paper_model, check=None))).files["ned_doppler18.h"]
    assert "row_sum" in _discretize_scratch(balanced) and "col_sum" in _discretize_scratch(balanced)
    assert _discretize_scratch(fixed) == _discretize_scratch(balanced)  # the same scratch either way
