"""The generated Python's cheaper paths give the same results and refuse the same inputs.

update forms the Joseph covariance as P - (G + G^T), G = K (H P - S K^T / 2):
exactly symmetric without a mirroring pass when P is exactly symmetric, and
mirrored (upper triangle) when P is symmetric only within the contract's
tolerance.  The finiteness of every result is tested by one BLAS dasum
(sum of magnitudes, ``_magnitude``), which must show a NaN or an infinity
wherever it is and must not refuse a large finite array whose sum overflows.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from modelgen.codegen.backends.registry import backend
from modelgen.codegen.build import load_python_module
from modelgen.codegen.generate import describe
from modelgen.derivation import reference
from tests.codegen.generated_support import write_files


def python_module(derived, folder):
    write_files(folder, backend("python").render(describe(derived)))
    return load_python_module(folder / f"{derived.model.name}.py")


@pytest.fixture(scope="module", params=["ned_doppler18", "ned_doppler32_augmented"])
def case(request, derived_builtin, tmp_path_factory):
    """A built-in model's module and a filter state with real correlations (P = A A^T / n + 0.1 I)."""
    derived = derived_builtin(request.param)
    module = python_module(derived, tmp_path_factory.mktemp(request.param))
    n, m = derived.n_states, derived.n_measurements
    rng = np.random.default_rng(11)
    A = rng.standard_normal((n, n))
    P = A @ A.T / n + 0.1 * np.eye(n)
    H = rng.standard_normal((m, n)) * (rng.random((m, n)) < 0.2)  # sparse, as a model's H
    H[np.arange(m), np.arange(m)] = 1.0
    return module, {"x": rng.standard_normal(n), "P": P, "z": rng.standard_normal(m), "H": H,
                    "r": rng.uniform(0.5, 2.0, m)}


def test_update_of_an_exactly_symmetric_p_is_the_reference_joseph_update_and_exactly_symmetric(case):
    module, a = case
    x_new, P_new = module.update(a["x"], a["P"], a["z"], a["H"], a["r"])
    x_ref, P_ref = reference.update(a["x"], a["P"], a["z"], a["H"], np.diag(a["r"]))
    np.testing.assert_allclose(x_new, x_ref, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(P_new, P_ref, rtol=0, atol=1e-13 * np.abs(P_ref).max())
    np.testing.assert_array_equal(P_new, P_new.T)


def test_update_of_a_p_symmetric_within_the_tolerance_mirrors_its_upper_triangle(case):
    """No Cholesky factor of an exactly symmetric P: the entry-by-entry test accepts it and the result is mirrored."""
    module, a = case
    P = a["P"].copy()
    P[0, -1] *= 1.0 + 1e-15  # within 16 N eps of P[-1, 0], but not equal
    assert module._factor(P) is None
    x_new, P_new = module.update(a["x"], P, a["z"], a["H"], a["r"])
    upper = np.triu(P) + np.triu(P, 1).T  # the upper triangle is the one used
    _, P_ref = reference.update(a["x"], upper, a["z"], a["H"], np.diag(a["r"]))
    np.testing.assert_allclose(P_new, P_ref, rtol=0, atol=1e-13 * np.abs(P_ref).max())
    np.testing.assert_array_equal(P_new, P_new.T)


def test_update_with_a_state_of_zero_variance_is_exactly_symmetric(case):
    module, a = case
    P = a["P"].copy()
    P[-1, :] = P[:, -1] = 0.0
    assert module._factor(P) is None
    _, P_new = module.update(a["x"], P, a["z"], a["H"], a["r"])
    _, P_ref = reference.update(a["x"], P, a["z"], a["H"], np.diag(a["r"]))
    np.testing.assert_allclose(P_new, P_ref, rtol=0, atol=1e-13 * np.abs(P_ref).max())
    np.testing.assert_array_equal(P_new, P_new.T)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_the_magnitude_sum_shows_a_non_finite_entry_wherever_it_is(case, bad):
    module, _ = case
    for shape in ((1,), (7,), (18, 18), (33, 5)):
        for order in ("C", "F"):
            a = np.ones(shape, order=order)
            for k in range(a.size):
                b = a.copy(order=order)
                b.flat[k] = bad
                assert not math.isfinite(module._magnitude(b)), (shape, order, k)
    assert module._magnitude(np.empty((0, 3))) == 0.0


def test_a_large_finite_array_whose_magnitude_sum_overflows_is_not_refused(case):
    module, _ = case
    big = np.full((4, 4), 1e308)
    assert module._magnitude(big) == math.inf
    module._check_finite("predict", P=big)  # entry by entry: every one is finite
    big[1, 2] = math.nan
    with pytest.raises(ValueError, match="predict: P has a non-finite entry"):
        module._check_finite("predict", P=big)


@pytest.mark.parametrize("argument", ["x", "P", "z", "H", "r"])
def test_a_non_finite_update_argument_is_named_on_the_32_state_model_too(case, argument):
    module, a = case
    for bad in (math.nan, math.inf):
        args = {k: v.copy() for k, v in a.items()}
        args[argument][(0,) * args[argument].ndim] = bad
        with pytest.raises(ValueError, match=f"update: {argument} (has a non-finite entry|is not)"):
            module.update(**args)
