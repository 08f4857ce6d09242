"""The covariance prediction keeps one row of M = Phi P, not N x N (issue 14, item 6: memory).

Row i of P_n = M Phi^T + Q_d needs only row i of M, so the unrolled kernel
computes row i of M right before row i of P_n and the scratch holds one row.
These tests prove the kernel never reads a row of M other than the one just
computed (the conformance checks prove the numbers), and that the filter
steps' scratch has no N x N array but the new covariance Pn.
"""

from __future__ import annotations

import pytest

from modelgen.codegen.kernels import CheckedAssign, covariance_predict
from modelgen.codegen.layout import ModelSizes, c_layout
from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.generate import describe


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


def test_the_filter_steps_scratch_has_no_square_array_but_the_new_covariance(paper_derived):
    sizes = ModelSizes.of(paper_derived)
    for options in (CodegenOptions(), CodegenOptions(update="sequential"), CodegenOptions(storage="packed")):
        layout = c_layout(sizes, options, "NED_DOPPLER18")
        square = [f.name for f in layout.filter_scratch if len(f.dims) == 2 and all(d.value == sizes.n for d in f.dims)]
        assert square == ([] if options.packed else ["Pn"])
        (m,) = [f for f in layout.filter_scratch if f.name == "M"]
        assert [d.value for d in m.dims] == [sizes.n]
