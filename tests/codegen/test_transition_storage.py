"""The transition's Phi is stored compressed to its structural pattern (issue 14, item 6).

The C keeps only the structural nonzeros of Phi, row by row (``layout.phi_entries``):
get_transition_matrix expands them, set_transition_matrix takes a full Phi and
refuses one that predict could not represent; discretize and predict agree with
the full matrix they stand for.
"""

from __future__ import annotations

import numpy as np
import pytest

from modelgen.codegen.build import CompiledFilter, compile_shared_library
from modelgen.codegen.layout import ModelSizes, phi_entries
from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.generate import generate_code
from modelgen.codegen.structure import filter_structure, reachability

from generated_support import write_files

pytestmark = pytest.mark.compile

OK, ERR_NONFINITE, ERR_STRUCTURE = 0, 1, 3
VALUES = {"latitude": 0.6}


@pytest.fixture(scope="module", params=[CodegenOptions(), CodegenOptions(form="ud", scalar="float")], ids=lambda o: o.slug())
def compiled(request, paper_derived, tmp_path_factory) -> CompiledFilter:
    options = request.param
    folder = write_files(tmp_path_factory.mktemp(options.slug()), generate_code(paper_derived, options).files)
    library = compile_shared_library([folder / "ned_doppler18.c"], folder / "libned_doppler18.so", cache=True)
    model = paper_derived.model
    c = CompiledFilter(library, model.name, ModelSizes.of(paper_derived), model.parameter_names, options=options)
    values = {q.name: VALUES.get(q.name, 20.0) for q in model.parameters if q.value is None}
    assert c.set_parameters(values) == OK
    assert c.discretize(60.0) == OK
    return c


def test_the_sizes_count_the_structure_modules_pattern_of_phi(paper_derived):
    """ModelSizes.nnz_phi (the struct's size) counts the pattern the kernels index: 117 entries for the paper's model."""
    structure = filter_structure(paper_derived.structure("F"), paper_derived.structure("G"), paper_derived.structure("H"), 9)
    assert ModelSizes.of(paper_derived).nnz_phi == 117 == len(phi_entries(structure.Phi))


def test_the_transition_stores_only_the_structural_nonzeros_of_phi(compiled, paper_derived):
    """117 of 324 entries for the paper's model; the C's own layout is the row-major pattern of layout.phi_entries."""
    rows, cols = compiled.phi_entries
    assert list(zip(rows.tolist(), cols.tolist())) == phi_entries(reachability(paper_derived.structure("F"), paper_derived.n_states))
    assert np.ctypeslib.as_array(compiled.transition.Phi).shape == (117,)


def test_get_expands_and_set_round_trips_a_discretized_phi(compiled):
    """The expanded Phi is zero off the pattern; setting it back leaves the stored entries bit for bit."""
    phi = compiled.Phi
    rows, cols = compiled.phi_entries
    off = np.ones(phi.shape, bool)
    off[rows, cols] = False
    assert not phi[off].any() and phi[rows, cols].any()
    stored = np.ctypeslib.as_array(compiled.transition.Phi).copy()
    assert compiled.set_transition_matrix(phi) == OK
    assert np.array_equal(np.ctypeslib.as_array(compiled.transition.Phi), stored)


def test_set_refuses_an_entry_outside_the_pattern_and_leaves_the_transition(compiled):
    """A nonzero structural zero, a random constant's row that is not e_i, a NaN: refused, nothing written."""
    phi = compiled.Phi
    stored = np.ctypeslib.as_array(compiled.transition.Phi).copy()
    rows, cols = compiled.phi_entries
    off_pattern = next((i, j) for i in range(18) for j in range(18) if phi[i, j] == 0 and not ((rows == i) & (cols == j)).any())
    for (i, j), value, status in ((off_pattern, 1e-9, ERR_STRUCTURE), ((7, 7), 1.5, ERR_STRUCTURE), ((0, 0), np.nan, ERR_NONFINITE)):
        bad = phi.copy()
        bad[i, j] = value
        assert compiled.set_transition_matrix(bad) == status, (i, j)
        assert np.array_equal(np.ctypeslib.as_array(compiled.transition.Phi), stored)


def test_predict_with_a_set_phi_is_the_dense_prediction(compiled):
    """A Phi set from outside (scaled inside its pattern) drives predict exactly as the full matrix would."""
    rng = np.random.default_rng(5)
    A = rng.normal(size=(18, 18))
    P0 = A @ A.T * 1e-3 + np.eye(18) * 1e-2
    x0 = rng.normal(size=18) * 0.1
    phi = compiled.Phi
    rows, cols = compiled.phi_entries
    unit = [i for i in range(18) if np.array_equal(phi[i], np.eye(18)[i]) and ((rows == i).sum() == 1)]
    scale = np.ones((18, 18))
    scale[[i for i in range(18) if i not in unit]] = 1.25
    assert compiled.set_transition_matrix(phi * scale) == OK
    qd = compiled.Qd
    assert compiled.set_state(x0, P0) == OK and compiled.predict() == OK
    phi = compiled.Phi
    tol = 1e-12 if compiled.dtype == np.float64 else 1e-4
    for actual, expected in ((compiled.x, phi @ x0), (compiled.P, phi @ P0 @ phi.T + qd)):
        np.testing.assert_allclose(actual, expected, rtol=tol, atol=tol * np.abs(expected).max())


def test_a_covariance_whose_row_sum_overflows_is_predicted_not_refused(compiled):
    """Predict checks each row's values by their sum; a sum that overflows although every value is finite is decided entry by entry.

    P = c (I + J / 2) with c = max / 6 is positive definite with finite entries
    (the largest 1.5 c), but the sum of its first row (10 c) is beyond the
    largest value: with Phi = I, P' = P + Q_d is finite and must be accepted.
    """
    big = float(np.finfo(compiled.dtype).max) / 6
    P0 = big * (np.eye(18) + 0.5 * np.ones((18, 18)))
    with np.errstate(over="ignore"):
        assert np.isinf(P0[0].astype(compiled.dtype).sum(dtype=compiled.dtype)) and np.isfinite(P0).all()
    assert compiled.set_transition_matrix(np.eye(18)) == OK
    assert compiled.set_state(np.zeros(18), P0) == OK
    qd = compiled.Qd
    assert compiled.predict() == OK
    np.testing.assert_allclose(compiled.P, P0 + qd, rtol=1e-6)


def test_a_covariance_that_overflows_is_still_refused_and_left_unchanged(compiled):
    """The entry-by-entry fallback refuses a predicted value that is itself infinite, and the filter keeps its P."""
    big = 1e308 if compiled.dtype == np.float64 else 3e38
    P0 = big * np.eye(18)
    phi = compiled.Phi
    phi[0, 0] = 2.0  # P'(0, 0) = 4 big: beyond the largest value
    assert compiled.set_transition_matrix(phi) == OK
    assert compiled.set_state(np.zeros(18), P0) == OK
    before = compiled.P
    assert compiled.predict() == ERR_NONFINITE
    assert np.array_equal(compiled.P, before)


def test_model_matrices_whose_sum_overflows_are_discretized_not_refused(compiled):
    """discretize checks F, G and q by their sum: noise densities whose sum overflows, each finite, are discretized.

    q = max / 4 per noise (the sum of six overflows) at T = 1 s: Q_d ~ T q stays finite, and so do the
    weights q / T (a T so short that q / T overflows is refused by the contract: tests/codegen/test_contract.py).
    """
    if compiled.options.ud:
        pytest.skip("the UD form keeps q / T, which overflows for such q at any step that keeps Q_d finite")
    big = float(np.finfo(compiled.dtype).max) / 4
    q = np.ctypeslib.as_array(compiled.matrices.q)
    saved = q.copy()
    try:
        q[:] = big
        with np.errstate(over="ignore"):
            assert np.isinf(q.sum(dtype=compiled.dtype))
        assert compiled.discretize(1.0) == OK  # Q_d ~ T q: finite
        assert np.isfinite(compiled.Qd).all()
        q[0] = np.inf
        assert compiled.discretize(1.0) == ERR_NONFINITE
    finally:
        q[:] = saved
        assert compiled.discretize(60.0) == OK


def test_each_non_finite_entry_of_F_is_refused_by_discretize(compiled):
    """F is tested by the sum of its balanced norm's rows (no pass of its own): a NaN or an infinity in any entry is refused."""
    F = np.ctypeslib.as_array(compiled.matrices.F)
    saved = F.copy()
    try:
        for k in range(F.size):
            for bad in (np.nan, np.inf, -np.inf):
                F[k] = bad
                assert compiled.discretize(1.0) == ERR_NONFINITE, (k, bad)
                F[k] = saved[k]
    finally:
        F[:] = saved
        assert compiled.discretize(60.0) == OK


def test_a_process_noise_that_overflows_is_refused(compiled):
    """Each row of Q_d is checked by its sum; an entry that is itself infinite is found by the entry-by-entry rescan."""
    if compiled.options.ud:
        pytest.skip("the UD form keeps Gamma and q / T, not Q_d")
    q = np.ctypeslib.as_array(compiled.matrices.q)
    saved = q.copy()
    try:
        q[:] = float(np.finfo(compiled.dtype).max) / 2
        assert compiled.discretize(10.0) == ERR_NONFINITE  # Q_d ~ T q: beyond the largest value
    finally:
        q[:] = saved
        assert compiled.discretize(60.0) == OK


def test_a_process_noise_whose_row_sum_overflows_is_discretized_not_refused(compiled):
    """A row of Q_d whose values are finite but whose sum overflows is decided entry by entry, and accepted.

    Q_d is linear in q: q scaled so that Q_d's largest entry is a third of the
    largest value makes some row's sum overflow while every entry stays finite.
    """
    if compiled.options.ud:
        pytest.skip("the UD form keeps Gamma and q / T, not Q_d")
    T = 1.0
    assert compiled.discretize(T) == OK
    nominal = compiled.Qd
    q = np.ctypeslib.as_array(compiled.matrices.q)
    saved = q.copy()
    try:
        scale = float(np.finfo(compiled.dtype).max) / 3 / np.abs(nominal).max()
        q[:] = saved * scale
        with np.errstate(over="ignore"):
            row_sums = [np.triu(nominal * scale)[i].astype(compiled.dtype).sum(dtype=compiled.dtype) for i in range(18)]
        assert np.isinf(row_sums).any()
        assert compiled.discretize(T) == OK
        assert np.isfinite(compiled.Qd).all()
        np.testing.assert_allclose(compiled.Qd, nominal * scale, rtol=1e-9)
    finally:
        q[:] = saved
        assert compiled.discretize(60.0) == OK
