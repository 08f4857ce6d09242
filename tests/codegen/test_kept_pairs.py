"""The pairs of random constants that the unrolled C prediction leaves in P (issue 31, C cycle).

Where rows i and j of Phi are e_i and e_j and Q_d(i, j) is structurally
zero, P_n(i, j) = P(i, j): predict neither computes nor commits them, but it
still refuses them when they are not finite, and leaves the filter as it
was then.  A consumer compiled strictly writes a correlated P, predicts once
(the kept pairs must come out bit for bit, the others as the reference's
Phi P Phi^T + Q_d), then puts a NaN or an infinity into one kept pair of the
filter's P and predicts again (refused, P unchanged).
"""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from modelgen.codegen.build import STRICT_FLAGS, compiler
from modelgen.codegen.generate import describe, generate_code
from modelgen.codegen.kernels import kept_pairs, kept_pairs_to_check, predict_commit
from modelgen.codegen.options import CodegenOptions

from generated_support import write_files


def test_kept_pairs_are_the_unit_rows_without_noise_and_the_commit_skips_exactly_them(paper_derived):
    structure = describe(paper_derived, CodegenOptions()).structure
    n = structure.n_states
    unit = set(structure.unit_rows)
    kept = kept_pairs(structure, packed=False)
    assert kept and kept_pairs(structure, packed=True) == []
    assert all(i in unit and j in unit and i <= j and not structure.Qd[i, j] for i, j in kept)
    committed = {(r.row, column + k) for r in predict_commit(n, kept) for column, _, length in r.copies for k in range(length)}
    upper = {(i, j) for i in range(n) for j in range(i, n)}
    assert committed == upper - set(kept) and not committed & set(kept)
    mirrored = {(r.row, j) for r in predict_commit(n, kept) for j in r.mirrored}
    assert mirrored == {(i, j) for i, j in upper - set(kept) if j > i}


def consumer(derived, pair: tuple[int, int], bad: str) -> str:
    p, P = derived.model.name, derived.model.name.upper()
    free = "\n".join(f"    params.{q.name} = 0.5;" for q in derived.model.parameters if q.value is None)
    i, j = pair
    return f"""#include <math.h>
#include <stdio.h>
#include <string.h>
#include "{p}.h"

int main(void)
{{
    static {p}_params params;
    static {p}_matrices m;
    static {p}_transition t;
    static {p}_filter filter, before;
    static {p}_workspace work;
    static {p}_scalar P0[{P}_N_STATES * {P}_N_STATES], Phi[{P}_N_STATES * {P}_N_STATES], Qd[{P}_N_STATES * {P}_N_STATES];
    int a, b;
    {p}_default_params(&params);
{free}
    if ({p}_matrices_evaluate(&params, &m) != {P}_OK) return 1;
    if ({p}_discretize(&m, 1, &t, &work) != {P}_OK) return 1;
    for (a = 0; a < {P}_N_STATES; ++a) {{
        for (b = 0; b < {P}_N_STATES; ++b) {{
            P0[a * {P}_N_STATES + b] = (a == b) ? 1.0 + 0.125 * a : 0.5 / (1.0 + (a - b) * (a - b));
        }}
    }}
    if ({p}_set_covariance(&filter, P0, &work) != {P}_OK) return 2;
    if ({p}_predict(&filter, &t, &work) != {P}_OK) return 3;
    {p}_get_transition_matrix(&t, Phi);
    for (a = 0; a < {P}_N_STATES; ++a) {{
        for (b = 0; b < {P}_N_STATES; ++b) {{
            int lo = a < b ? a : b, hi = a < b ? b : a; /* packed upper, row by row */
            Qd[a * {P}_N_STATES + b] = t.Qd[lo * {P}_N_STATES - lo * (lo - 1) / 2 + (hi - lo)];
        }}
    }}
    for (a = 0; a < {P}_N_STATES * {P}_N_STATES; ++a) printf("P0 %.17g\\n", (double)P0[a]);
    for (a = 0; a < {P}_N_STATES * {P}_N_STATES; ++a) printf("Phi %.17g\\n", (double)Phi[a]);
    for (a = 0; a < {P}_N_STATES * {P}_N_STATES; ++a) printf("Qd %.17g\\n", (double)Qd[a]);
    for (a = 0; a < {P}_N_STATES; ++a) {{
        for (b = 0; b < {P}_N_STATES; ++b) printf("P1 %.17g\\n", (double)filter.P[a][b]);
    }}
    filter.P[{i}][{j}] = {bad};
    filter.P[{j}][{i}] = {bad};
    before = filter;
    if ({p}_predict(&filter, &t, &work) != {P}_ERR_NONFINITE) return 4;
    if (memcmp(&before, &filter, sizeof filter) != 0) return 5;
    return 0;
}}
"""


def test_only_the_pairs_of_constants_read_by_no_other_row_are_checked_by_predict_itself(paper_derived):
    """ned_doppler18: the Doppler scale factor and boresight (16, 17) drive no state; the gyro biases (7-9) do."""
    structure = describe(paper_derived, CodegenOptions()).structure
    kept = kept_pairs(structure, packed=False)
    assert kept_pairs_to_check(structure, kept) == [(16, 16), (16, 17), (17, 17)]
    assert (8, 16) in kept and (7, 9) in kept


@pytest.mark.compile
@pytest.mark.parametrize("bad", ["NAN", "INFINITY"])
@pytest.mark.parametrize("pair", [(16, 17), (8, 16), (7, 9)], ids=["checked", "reaches-computed", "reaches-both"])
def test_c_predict_keeps_the_pairs_bit_for_bit_and_refuses_them_when_not_finite(paper_derived, tmp_path, bad, pair):
    derived = paper_derived
    structure = describe(derived, CodegenOptions()).structure
    n = structure.n_states
    kept = kept_pairs(structure, packed=False)
    assert pair in kept
    folder = write_files(tmp_path, generate_code(derived).files)
    name = derived.model.name
    (folder / "consumer.c").write_text(consumer(derived, pair, bad))
    exe = folder / "consumer"
    subprocess.run([compiler(), *STRICT_FLAGS, "-O2", "-o", str(exe), str(folder / "consumer.c"), str(folder / f"{name}.c"), "-lm"],
                   check=True, capture_output=True, text=True)
    run = subprocess.run([str(exe)], capture_output=True, text=True)
    assert run.returncode == 0, (run.returncode, run.stderr)
    values: dict[str, list[float]] = {}
    for line in run.stdout.splitlines():
        key, value = line.split()
        values.setdefault(key, []).append(float(value))
    P0, Phi, Qd, P1 = (np.array(values[k]).reshape(n, n) for k in ("P0", "Phi", "Qd", "P1"))
    for i, j in kept:
        assert P1[i, j] == P0[i, j] and P1[j, i] == P0[j, i], (i, j)
    expected = Phi @ P0 @ Phi.T + Qd
    assert np.allclose(P1, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    assert np.array_equal(P1, P1.T)
