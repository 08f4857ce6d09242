"""The generated Python's Filter class: the C's stateful API, the functional API's refusals and results.

Filter owns x and P as the C's filter struct does: P is proven against the
contract once (constructor, set_covariance) and trusted afterwards, so
predict and update skip the per-call Cholesky proof the functional API
needs.  These tests prove that it refuses what the functional API refuses
(non-finite Phi, Q_d, z, H, r; a negative r; a P outside the contract; an
innovation covariance that is not positive definite), that the filter is
unchanged after every refusal, that its results are the functional API's
(update bit for bit: the same kernel; predict bit for bit where both use
the row-class kernel, else within the rounding bound of two orders of one
matrix product), and that it passes the reference conformance check for
every built-in model.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from modelgen.checks.code_check import compare, measurement_sequence, reference_run, scenario_tolerance
from modelgen.codegen import kernels
from modelgen.codegen.backends.registry import backend
from modelgen.codegen.build import load_python_module
from modelgen.codegen.generate import describe
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import derive, parameter_vector
from modelgen.jobs import check_scenario
from modelgen.model.loading import builtin_models
from tests.codegen.generated_support import write_files
from tests.codegen.test_contract import bad_covariances, correlated

EPS = np.finfo(float).eps


def python_module(derived, folder):
    """The generated Python module alone (no C)."""
    write_files(folder, backend("python").render(describe(derived)))
    return load_python_module(folder / f"{derived.model.name}.py")


@pytest.fixture(scope="module")
def py(paper_derived, tmp_path_factory):
    return python_module(paper_derived, tmp_path_factory.mktemp("filter_class"))


@pytest.fixture(scope="module")
def structured_py(paper_derived, tmp_path_factory):
    """The paper model with both predictions (functional and Filter) by row class of Phi."""
    mp = pytest.MonkeyPatch()
    try:
        mp.setattr(kernels, "PYTHON_STRUCTURED_SAVING_FLOPS", -1)
        mp.setattr(kernels, "PYTHON_FILTER_STRUCTURED_SAVING_FLOPS", -1)
        return python_module(paper_derived, tmp_path_factory.mktemp("filter_class_structured"))
    finally:
        mp.undo()


@pytest.fixture(scope="module")
def arguments(py, paper_derived, level_flight):
    """x, P, Phi, Qd, z, H, r at the paper's level-flight point, T = 60 s."""
    p = py.parameter_vector(dict(zip(paper_derived.model.parameter_names, parameter_vector(paper_derived.model, level_flight))))
    phi, qd = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), 60.0)
    n = paper_derived.n_states
    x = np.linspace(-1.0, 1.0, n) * 1e-3
    H, r = py.measurement_matrix(p), py.measurement_variance(p)
    return {"x": x, "P": correlated(n), "Phi": phi, "Qd": qd, "z": np.full(len(r), 0.05), "H": H, "r": r}


def state_of(f) -> tuple[bytes, bytes]:
    return f.get_state().tobytes(), f.get_covariance().tobytes()


def with_entry(a: np.ndarray, index, value: float) -> np.ndarray:
    out = a.copy()
    out[index] = value
    return out


@pytest.mark.parametrize("what", list(bad_covariances(18)))
def test_a_covariance_outside_the_contract_is_refused_at_construction_and_by_set_covariance(py, arguments, what):
    P = bad_covariances(18)[what]
    with pytest.raises(ValueError, match="set_covariance: P"):
        py.Filter(arguments["x"], P)
    f = py.Filter(arguments["x"], arguments["P"])
    before = state_of(f)
    with pytest.raises(ValueError, match="set_covariance: P"):
        f.set_covariance(P)
    assert state_of(f) == before
    with pytest.raises(ValueError, match="predict: P"):  # the functional API refuses the same P
        py.predict(arguments["x"], P, arguments["Phi"], arguments["Qd"])


def test_a_covariance_symmetric_within_the_tolerance_is_stored_with_its_upper_triangle_mirrored(py, arguments):
    P = arguments["P"].copy()
    P[0, 1] *= 1.0 + 4 * EPS  # within 16 N eps, not exactly symmetric
    f = py.Filter(arguments["x"], P)
    stored = f.get_covariance()
    assert np.array_equal(stored, stored.T)
    assert np.array_equal(np.triu(stored), np.triu(P))


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_non_finite_state_is_refused_by_set_state(py, arguments, value):
    f = py.Filter(arguments["x"], arguments["P"])
    before = state_of(f)
    with pytest.raises(ValueError, match="set_state: x"):
        f.set_state(with_entry(arguments["x"], 3, value))
    assert state_of(f) == before
    with pytest.raises(ValueError, match="set_state: x"):
        py.Filter(with_entry(arguments["x"], 3, value), arguments["P"])


@pytest.mark.parametrize("value", [math.nan, math.inf])
@pytest.mark.parametrize("argument, index", [("Phi", (2, 5)), ("Phi", (17, 0)), ("Qd", (4, 4)), ("Qd", (9, 2)), ("Qd", (2, 9))])
def test_a_non_finite_phi_or_qd_is_refused_naming_it_and_the_filter_is_unchanged(py, structured_py, arguments, argument, index, value):
    """Every entry counts, Q_d's lower triangle (read by neither kernel's result) too, on both Filter kernels."""
    bad = {"Phi": arguments["Phi"], "Qd": arguments["Qd"], argument: with_entry(arguments[argument], index, value)}
    for module in (py, structured_py):
        f = module.Filter(arguments["x"], arguments["P"])
        before = state_of(f)
        with pytest.raises(ValueError, match=f"predict: {argument} has a non-finite entry"):
            f.predict(bad["Phi"], bad["Qd"])
        assert state_of(f) == before
        with pytest.raises(ValueError, match=f"predict: {argument} has a non-finite entry"):
            module.predict(arguments["x"], arguments["P"], bad["Phi"], bad["Qd"])


def test_a_transition_that_overflows_the_covariance_is_refused_as_a_non_finite_result(py, arguments):
    f = py.Filter(arguments["x"], arguments["P"])
    before = state_of(f)
    with pytest.raises(ValueError, match="predict: result has a non-finite entry"):
        f.predict(arguments["Phi"] * 1e160, arguments["Qd"])
    assert state_of(f) == before


def test_arguments_of_the_wrong_shape_are_refused_naming_them(py, arguments):
    f = py.Filter(arguments["x"], arguments["P"])
    before = state_of(f)
    with pytest.raises(ValueError, match="predict: Phi has shape"):
        f.predict(arguments["Phi"][:-1], arguments["Qd"])
    with pytest.raises(ValueError, match="update: H has shape"):
        f.update(arguments["z"], arguments["H"][:, :-1], arguments["r"])
    with pytest.raises(ValueError, match="set_covariance: P has shape"):
        f.set_covariance(arguments["P"][:-1])
    assert state_of(f) == before


@pytest.mark.parametrize("value", [math.nan, math.inf])
@pytest.mark.parametrize("argument, index", [("z", 0), ("H", (1, 3)), ("H", (0, 17)), ("r", 1)])
def test_a_non_finite_measurement_is_refused_naming_it_and_the_filter_is_unchanged(py, arguments, argument, index, value):
    bad = {k: arguments[k] for k in ("z", "H", "r")}
    bad[argument] = with_entry(bad[argument], index, value)
    f = py.Filter(arguments["x"], arguments["P"])
    before = state_of(f)
    with pytest.raises(ValueError, match=f"update: {argument}"):
        f.update(bad["z"], bad["H"], bad["r"])
    assert state_of(f) == before
    with pytest.raises(ValueError, match=f"update: {argument}"):
        f.update_masked(bad["z"], bad["H"], bad["r"], [True, True])
    assert state_of(f) == before
    with pytest.raises(ValueError, match=f"update: {argument}"):
        py.update(arguments["x"], arguments["P"], bad["z"], bad["H"], bad["r"])


def test_a_negative_measurement_variance_is_refused_and_the_filter_is_unchanged(py, arguments):
    f = py.Filter(arguments["x"], arguments["P"])
    before = state_of(f)
    r = with_entry(arguments["r"], 0, -1e-6)
    with pytest.raises(ValueError, match="update: r has a negative measurement variance"):
        f.update(arguments["z"], arguments["H"], r)
    assert state_of(f) == before


def test_an_innovation_covariance_that_is_not_positive_definite_is_refused_and_the_filter_is_unchanged(py, arguments):
    """H = 0 and r = 0 make S = H P H^T + R zero."""
    f = py.Filter(arguments["x"], arguments["P"])
    before = state_of(f)
    with pytest.raises(ValueError, match="update: the innovation covariance H P H\\^T \\+ R is not positive definite"):
        f.update(arguments["z"], np.zeros_like(arguments["H"]), np.zeros_like(arguments["r"]))
    assert state_of(f) == before


def test_an_unused_measurement_may_be_nan_in_update_masked(py, arguments):
    f = py.Filter(arguments["x"], arguments["P"])
    z, H, r = with_entry(arguments["z"], 1, math.nan), with_entry(arguments["H"], (1, 3), math.nan), with_entry(arguments["r"], 1, math.nan)
    innovation, nis = f.update_masked(z, H, r, [True, False])
    x_ref, P_ref, innovation_ref, nis_ref = py.update_masked(arguments["x"], arguments["P"], z, H, r, [True, False])
    assert np.array_equal(f.get_state(), x_ref) and np.array_equal(f.get_covariance(), P_ref)
    assert np.array_equal(innovation, innovation_ref) and nis == nis_ref
    assert innovation[1] == 0.0


def test_update_gives_the_functional_update_bit_for_bit(py, arguments):
    """The same kernel (_joseph_update on an exactly symmetric P) on the same inputs."""
    f = py.Filter(arguments["x"], arguments["P"])
    f.update(arguments["z"], arguments["H"], arguments["r"])
    x_ref, P_ref = py.update(arguments["x"], arguments["P"], arguments["z"], arguments["H"], arguments["r"])
    assert np.array_equal(f.get_state(), x_ref) and np.array_equal(f.get_covariance(), P_ref)


def test_predict_by_row_class_gives_the_functional_predict_bit_for_bit(structured_py, arguments):
    f = structured_py.Filter(arguments["x"], arguments["P"])
    f.predict(arguments["Phi"], arguments["Qd"])
    x_ref, P_ref = structured_py.predict(arguments["x"], arguments["P"], arguments["Phi"], arguments["Qd"])
    assert np.array_equal(f.get_state(), x_ref) and np.array_equal(f.get_covariance(), P_ref)


def test_dense_predict_is_within_the_rounding_bound_of_the_functional_factored_predict(py, arguments, paper_derived):
    """Both sum the same products in different orders (Phi P then Phi^T, against (Phi L)(Phi L)^T).

    Each is within gamma_2n = 2n eps / (1 - 2n eps) of the exact result
    times |Phi| |P| |Phi|^T + |Q_d| (Higham, Accuracy and Stability, 3.5;
    |L||L|^T is bounded by |P|'s scale for a positive definite P:
    |L L^T|_ij <= sqrt(P_ii P_jj)), so they differ by at most twice that,
    with sqrt(P_ii P_jj) in place of |P_ij|.  x = Phi x is the same dot
    product on both: equal bit for bit.
    """
    assert kernels.python_filter_predict_kernel(describe(paper_derived).structure) == "dense"
    f = py.Filter(arguments["x"], arguments["P"])
    f.predict(arguments["Phi"], arguments["Qd"])
    x_ref, P_ref = py.predict(arguments["x"], arguments["P"], arguments["Phi"], arguments["Qd"])
    n = len(x_ref)
    sigma = np.sqrt(np.diag(arguments["P"]))
    scale = np.abs(arguments["Phi"]) @ np.outer(sigma, sigma) @ np.abs(arguments["Phi"]).T + np.abs(arguments["Qd"])
    gamma = 2 * n * EPS / (1 - 2 * n * EPS)
    assert np.array_equal(f.get_state(), x_ref)
    assert (np.abs(f.get_covariance() - P_ref) <= 2 * gamma * scale).all()
    assert not np.array_equal(f.get_covariance(), arguments["P"])  # it did predict


def test_getters_return_copies_so_the_filter_cannot_be_changed_from_outside(py, arguments):
    f = py.Filter(arguments["x"], arguments["P"])
    before = state_of(f)
    f.get_covariance()[0, 1] = 99.0
    f.get_state()[0] = 99.0
    caller_P = arguments["P"].copy()
    g = py.Filter(arguments["x"], caller_P)
    caller_P[0, 1] = 99.0  # the caller's array is not the filter's
    assert state_of(f) == before and np.array_equal(g.get_covariance(), arguments["P"])


def test_reset_error_state_zeroes_x_and_keeps_p(py, arguments):
    f = py.Filter(arguments["x"], arguments["P"])
    P = f.get_covariance()
    f.reset_error_state()
    assert np.array_equal(f.get_state(), np.zeros(len(arguments["x"]))) and np.array_equal(f.get_covariance(), P)


def filter_run(module, derived, scenario) -> list[tuple[np.ndarray, np.ndarray]]:
    """x and P after every step of the scenario, by the generated module's Filter class."""
    named = dict(zip(derived.model.parameter_names, parameter_vector(derived.model, scenario.parameters)))
    p = module.parameter_vector(named)
    phi, qd = module.discretize(module.system_matrix(p), module.noise_input_matrix(p), module.noise_psd(p), scenario.step)
    H, r = module.measurement_matrix(p), module.measurement_variance(p)
    f = module.Filter(scenario.x0(), scenario.initial_covariance)
    out = []
    for z in measurement_sequence(derived, scenario):
        f.predict(phi, qd)
        if derived.n_measurements:
            f.update(z, H, r)
        out.append((f.get_state(), f.get_covariance()))
    return out


@pytest.mark.parametrize("name", builtin_models())
def test_the_filter_class_passes_the_reference_conformance_check_for_every_builtin_model(name, tmp_path, derived_builtin):
    derived = derived_builtin(name)
    options = CodegenOptions()
    scenario = check_scenario(derived)
    module = python_module(derived, tmp_path)
    ref = reference_run(derived, scenario, options.taylor_order, options.taylor_tolerance, options.process_noise)
    result = compare("python Filter", filter_run(module, derived, scenario), ref, scenario_tolerance(derived, scenario, options.taylor_order))
    assert result.passed(), result


@pytest.mark.parametrize("name", ["random_constants_only", "one_state_no_measurement", "nothing_but_a_constant"])
def test_the_filter_class_runs_degenerate_models_as_the_functional_api_does(name, tmp_path):
    """Phi = I, no measurements, no noises: the Filter's steps give the functional API's x and P.

    Within rounding only: the Filter's dense predict and the functional
    factored one add the same products in different orders (4 n eps
    relative), and the updates then start from those P.
    """
    from modelgen.model.loading import load_model_text
    from tests.codegen.test_degenerate_models import MODELS

    derived = derive(load_model_text(MODELS[name], filename=f"{name}.yaml"))
    module = python_module(derived, tmp_path)
    p = module.parameter_vector({})
    phi, qd = module.discretize(module.system_matrix(p), module.noise_input_matrix(p), module.noise_psd(p), 1.0)
    H, r = module.measurement_matrix(p), module.measurement_variance(p)
    n = derived.n_states
    x, P = np.full(n, 0.5), np.eye(n) * 2.0
    f = module.Filter(x, P)
    for _ in range(3):
        x, P = module.predict(x, P, phi, qd)
        f.predict(phi, qd)
        x, P = module.update(x, P, np.ones(len(r)), H, r)
        f.update(np.ones(len(r)), H, r)
        np.testing.assert_allclose(f.get_state(), x, rtol=1e-15, atol=0.0)
        np.testing.assert_allclose(f.get_covariance(), P, rtol=4 * n * EPS, atol=0.0)


def test_a_phi_outside_the_row_classes_is_used_whole_by_the_row_class_predict(structured_py, arguments):
    """A nonzero off the diagonal of a diagonal row (a Phi made elsewhere) is not dropped: both APIs take the dense product, x and P see the same Phi."""
    n = len(arguments["x"])
    diagonal_row = int(np.flatnonzero(structured_py._NOT_GENERAL)[0])
    phi = with_entry(arguments["Phi"], (diagonal_row, (diagonal_row + 1) % n), 0.5)
    dense = phi @ arguments["P"] @ phi.T + arguments["Qd"]
    x_new, P_new = structured_py.predict(arguments["x"], arguments["P"], phi, arguments["Qd"])
    f = structured_py.Filter(arguments["x"], arguments["P"])
    f.predict(phi, arguments["Qd"])
    mirrored = np.triu(dense) + np.triu(dense, 1).T  # the same products as the fallback, upper triangle mirrored
    assert np.array_equal(P_new, mirrored) and np.array_equal(f.get_covariance(), mirrored)
    assert np.array_equal(x_new, phi @ arguments["x"])
