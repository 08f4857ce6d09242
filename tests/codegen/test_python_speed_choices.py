"""The generated Python's speed choices keep its results and its contract.

The module predicts in factored form (the Cholesky factor of the
contract's check reused: P_n = (Phi L)(Phi L)^T + Q_d), falls back to the
dense products for a P without a factor, may predict by row class of Phi
(``structured``, chosen by ``kernels.python_predict_kernel``; the general
rows as a slice when contiguous, else a list), updates by one rank-m
product onto P (P - (G + G^T), G = K (H P - S K^T / 2)), balances F in plain
Python floats or in numpy (``PYTHON_BALANCING_ENTRIES``), and finds a
non-finite argument through one BLAS sum of magnitudes (dasum) over the
result.  Each choice must give the reference's numbers, and a
NaN or infinity anywhere in any argument must still be refused, naming that
argument, on the factored path as on the fallback.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from modelgen.codegen import kernels
from modelgen.codegen.backends.python import context as python_context
from modelgen.codegen.backends.registry import backend
from modelgen.codegen.build import load_python_module
from modelgen.codegen.generate import describe
from modelgen.derivation import reference
from modelgen.derivation.discretization import balanced_norm, nominal_scaling
from tests.codegen.generated_support import write_files


def python_module(derived, folder, monkeypatch=None, **constants):
    """The generated Python module alone (no C), with module constants of the generator overridden."""
    for owner, name, value in constants.get("overrides", ()):
        monkeypatch.setattr(owner, name, value)
    files = backend("python").render(describe(derived))
    write_files(folder, files)
    return load_python_module(folder / f"{derived.model.name}.py")


@pytest.fixture(scope="module")
def paper_module(paper_derived, tmp_path_factory):
    return python_module(paper_derived, tmp_path_factory.mktemp("py"))


@pytest.fixture(scope="module")
def structured_module(paper_derived, tmp_path_factory):
    """The paper model with the prediction by row class of Phi forced."""
    mp = pytest.MonkeyPatch()
    try:
        return python_module(paper_derived, tmp_path_factory.mktemp("structured"), mp,
                             overrides=[(kernels, "PYTHON_STRUCTURED_SAVING_FLOPS", -1)])
    finally:
        mp.undo()


@pytest.fixture(scope="module")
def inputs(paper_derived, paper_module, level_flight):
    py = paper_module
    p = py.parameter_vector(level_flight)
    phi, qd = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), 60.0)
    n = paper_derived.n_states
    rng = np.random.default_rng(3)
    A = rng.standard_normal((n, n))
    P = A @ A.T / n + 0.1 * np.eye(n)
    return {"x": rng.standard_normal(n), "P": P, "Phi": phi, "Qd": qd, "H": py.measurement_matrix(p),
            "r": py.measurement_variance(p), "z": rng.standard_normal(paper_derived.n_measurements)}


def test_the_paper_model_predicts_in_factored_form(paper_module):
    assert "In factored form" in paper_module.predict.__doc__


def test_factored_prediction_is_the_dense_product(paper_module, inputs):
    x, P, Phi, Qd = (inputs[k] for k in ("x", "P", "Phi", "Qd"))
    x_new, P_new = paper_module.predict(x, P, Phi, Qd)
    want = reference.predict_covariance(P, Phi, Qd)
    np.testing.assert_allclose(P_new, want, rtol=0, atol=1e-14 * np.abs(want).max())
    np.testing.assert_array_equal(P_new, P_new.T)
    assert P_new.flags.c_contiguous
    np.testing.assert_allclose(x_new, Phi @ x, rtol=1e-15)


def test_a_covariance_without_cholesky_factor_takes_the_dense_products(paper_module, inputs):
    """Zero variances (the paper's initial position and velocity): no factor, the dense path, same numbers."""
    x, P, Phi, Qd = (inputs[k] for k in ("x", "P", "Phi", "Qd"))
    P = P.copy()
    P[:4, :] = P[:, :4] = 0.0
    assert paper_module._factor(P) is None
    _, P_new = paper_module.predict(x, P, Phi, Qd)
    want = reference.predict_covariance(P, Phi, Qd)
    np.testing.assert_allclose(P_new, want, rtol=0, atol=1e-14 * np.abs(want).max())
    np.testing.assert_array_equal(P_new, P_new.T)


def test_the_structured_kernel_gives_the_same_prediction(paper_derived, inputs, tmp_path, monkeypatch):
    structured = python_module(paper_derived, tmp_path, monkeypatch,
                               overrides=[(kernels, "PYTHON_STRUCTURED_SAVING_FLOPS", -1)])
    assert "row class" in structured.predict.__doc__
    x, P, Phi, Qd = (inputs[k] for k in ("x", "P", "Phi", "Qd"))
    x_new, P_new = structured.predict(x, P, Phi, Qd)
    want = reference.predict_covariance(P, Phi, Qd)
    np.testing.assert_allclose(P_new, want, rtol=0, atol=1e-14 * np.abs(want).max())
    np.testing.assert_allclose(x_new, Phi @ x, rtol=1e-14)
    bad = Phi.copy()
    bad[0, -1] = math.nan  # a structural zero: the kernel never reads it, the check must
    with pytest.raises(ValueError, match="predict: Phi has a non-finite entry"):
        structured.predict(x, P, bad, Qd)


@pytest.mark.parametrize("in_python", [True, False])
def test_both_balancings_are_the_reference_to_the_bit(paper_derived, inputs, tmp_path, monkeypatch, in_python):
    module = python_module(paper_derived, tmp_path, monkeypatch,
                           overrides=[(python_context, "PYTHON_BALANCING_ENTRIES", 10**6 if in_python else -1)])
    F = paper_derived.numeric({**{p.name: 0.5 for p in paper_derived.model.parameters if p.value is None}})["F"]
    rng = np.random.default_rng(4)
    for _ in range(5):  # values over 20 decades on the model's pattern
        G = np.where(F != 0, rng.standard_normal(F.shape) * 10.0 ** rng.integers(-10, 10, F.shape), 0.0)
        assert module._balanced_norm(G) == balanced_norm(G, nominal_scaling(paper_derived))  # the D baked in at generation time
    G[2, 3] = math.nan if F[2, 3] else G[2, 3]
    G[0, 1] = math.inf
    assert not math.isfinite(module._balanced_norm(G))


def test_scattered_general_rows_are_indexed_by_a_list_and_give_the_same_prediction(paper_derived, inputs, tmp_path,
                                                                                 monkeypatch):
    """A model whose general rows of Phi are not one run indexes them by a list: the same numbers as the slice."""
    assert python_context.index_expression([0, 1, 2]) == "slice(0, 3)"
    assert python_context.index_expression([0, 2, 5]) == "[0, 2, 5]"
    assert python_context.index_expression([]) == "[]"
    module = python_module(paper_derived, tmp_path, monkeypatch,
                           overrides=[(kernels, "PYTHON_STRUCTURED_SAVING_FLOPS", -1),
                                      (python_context, "index_expression", repr)])
    assert isinstance(module._GENERAL, list)
    x, P, Phi, Qd = (inputs[k] for k in ("x", "P", "Phi", "Qd"))
    _, P_new = module.predict(x, P, Phi, Qd)
    want = reference.predict_covariance(P, Phi, Qd)
    np.testing.assert_allclose(P_new, want, rtol=0, atol=1e-14 * np.abs(want).max())
    np.testing.assert_array_equal(P_new, P_new.T)


@pytest.mark.parametrize("kernel", ["factored", "structured"])
def test_only_the_upper_triangle_of_qd_is_used_and_its_lower_one_is_checked(paper_module, structured_module, inputs,
                                                                            kernel):
    module = paper_module if kernel == "factored" else structured_module
    x, P, Phi, Qd = (inputs[k] for k in ("x", "P", "Phi", "Qd"))
    skewed = Qd + np.tril(np.full(Qd.shape, 1e-3), -1)  # a finite lower triangle that differs from the upper
    _, P_new = module.predict(x, P, Phi, skewed)
    np.testing.assert_array_equal(P_new, module.predict(x, P, Phi, Qd)[1])
    skewed[-1, 0] = math.nan
    with pytest.raises(ValueError, match="predict: Qd has a non-finite entry"):
        module.predict(x, P, Phi, skewed)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_non_finite_entry_of_a_positive_definite_p_is_named(paper_module, structured_module, inputs, bad):
    """P with a Cholesky factor: OpenBLAS goes on past a NaN pivot and an infinite variance factors; both are named."""
    n = inputs["P"].shape[0]
    for module in (paper_module, structured_module):
        for i, j in ((0, 0), (n // 2, n // 2), (n - 1, n - 1), (n - 1, 0), (3, 5)):
            args = {k: inputs[k].copy() for k in ("x", "P", "Phi", "Qd", "z", "H", "r")}
            args["P"][i, j] = args["P"][j, i] = bad
            if bad != bad or i != j:  # a NaN, or an infinite covariance: no factor
                assert module._factor(args["P"]) is None
            with pytest.raises(ValueError, match="predict: P (has a non-finite entry|is not)"):
                module.predict(*(args[k] for k in ("x", "P", "Phi", "Qd")))
            with pytest.raises(ValueError, match="update: P (has a non-finite entry|is not)"):
                module.update(*(args[k] for k in ("x", "P", "z", "H", "r")))


def test_the_update_keeps_x_and_p_of_the_caller(paper_module, inputs):
    """The BLAS products write into copies: the caller's arrays are unchanged."""
    args = {k: inputs[k].copy() for k in ("x", "P", "z", "H", "r")}
    paper_module.update(**args)
    for k, v in args.items():
        np.testing.assert_array_equal(v, inputs[k])


def positions(n: int) -> list[tuple[int, ...]]:
    """Corners, the diagonal and an entry in a row of zeros of P (state 0)."""
    return [(0, 0), (0, n - 1), (n - 1, 0), (n // 2, n // 2), (1, 0)]


@pytest.mark.parametrize("kernel", ["factored", "structured"])
@pytest.mark.parametrize("zero_variance", [True, False])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("argument", ["x", "P", "Phi", "Qd"])
def test_a_non_finite_predict_argument_is_named_wherever_it_is(paper_module, structured_module, inputs, argument, bad,
                                                               zero_variance, kernel):
    """Also where it meets zeros (a state with zero variance): NaN and 0 * inf are NaN, so the result shows it.

    With a zero variance P has no Cholesky factor (the dense fallback);
    without, the factored or structured kernel runs and one sum of
    magnitudes over the result before its mirroring must show the culprit.
    """
    module = paper_module if kernel == "factored" else structured_module
    n = inputs["P"].shape[0]
    for where in positions(n):
        args = {k: inputs[k].copy() for k in ("x", "P", "Phi", "Qd")}
        if zero_variance:
            args["P"][0, :] = args["P"][:, 0] = 0.0  # state 0 has no variance: its row of P is zeros
        index = where[:1] if argument == "x" else where
        args[argument][index] = bad
        if argument == "P":
            args["P"][index[::-1]] = bad
        with pytest.raises(ValueError, match=f"predict: {argument} (has a non-finite entry|is not|has a negative)"):
            module.predict(**args)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
@pytest.mark.parametrize("argument", ["x", "z", "H", "r"])
def test_a_non_finite_update_argument_is_named(paper_module, inputs, argument, bad):
    for index in ((0,), (-1,)) if argument in ("x", "z", "r") else ((0, 0), (1, 5), (0, -1)):
        args = {k: inputs[k].copy() for k in ("x", "P", "z", "H", "r")}
        args[argument][index] = bad
        with pytest.raises(ValueError, match=f"update: {argument} has a non-finite entry"):
            paper_module.update(**args)


def test_update_is_the_reference_joseph_update(paper_module, inputs):
    x, P, z, H, r = (inputs[k] for k in ("x", "P", "z", "H", "r"))
    x_new, P_new = paper_module.update(x, P, z, H, r)
    x_ref, P_ref = reference.update(x, P, z, H, np.diag(r))
    np.testing.assert_allclose(x_new, x_ref, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(P_new, P_ref, rtol=0, atol=1e-13 * np.abs(P_ref).max())
    np.testing.assert_array_equal(P_new, P_new.T)
