"""The generated C and Python discretize as the reference does, accurate against expm from 1 ms to a day.

Same model, operating points and bounds as tests/derivation/test_discretization.py
(1e-13 of the largest exact entry up to 600 s, 1e-10 up to a day); the
float C is held to 1e-5 for Phi and 1e-4 for Q_d (measured 1.4e-5 at a day),
and must refuse where the exact result exceeds the float range (the INS/GPS
vertical channel grows as e^{sqrt(2 g / R) T}: 1e65 after a day).  Q_d is compared with Gamma (Q/T) Gamma^T built
from the exact Gamma, the paper's definition of the discrete noise.
"""

import numpy as np
import pytest

from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import derive, parameter_vector
from modelgen.derivation.discretization import DEFAULT_TOLERANCE, nominal_scaling, taylor_discretization, taylor_process_noise
from tests.codegen.generated_support import build
from tests.derivation.test_discretization import MODELS, STEPS, bound, exact, relative_error

import yaml

pytestmark = pytest.mark.compile

FLOAT_BOUND = 1e-5
FLOAT_MAX = float(np.finfo(np.float32).max)


@pytest.fixture(scope="module", params=["paper", "ins_gps15"])
def case(request, paper_derived, derived_builtin, level_flight, tmp_path_factory):
    """(derived model, parameter values, {options slug: built code})."""
    if request.param == "paper":
        derived, values = paper_derived, level_flight
    else:
        derived = derived_builtin("ins_gps15")
        values = yaml.safe_load((MODELS / "ins_gps15.yaml").read_text())["check"]["parameters"]
    root = tmp_path_factory.mktemp(request.param)
    options = [CodegenOptions(), CodegenOptions(scalar="float"), CodegenOptions(form="ud")]
    return derived, values, {o.slug(): (o, build(derived, root / o.slug(), o)) for o in options}


def exact_noise(m: dict, T: float) -> tuple[np.ndarray, np.ndarray]:
    phi, gamma = exact(m["F"], m["G"], T)
    return phi, taylor_process_noise(gamma, m["Q"], T)


@pytest.mark.parametrize("T", STEPS)
def test_generated_c_discretize_matches_expm(case, T):
    derived, values, builds = case
    m = derived.numeric(values)
    phi_exact, qd_exact = exact_noise(m, T)
    named = dict(zip(derived.model.parameter_names, parameter_vector(derived.model, values)))
    for options, built in builds.values():
        c = built.c_filter(options)
        assert c.set_parameters(named) == 0
        if options.scalar == "float" and max(np.max(np.abs(phi_exact)), np.max(np.abs(qd_exact))) > FLOAT_MAX:
            assert c.discretize(T) == 1, options.slug()  # ERR_NONFINITE: e^{F T} is not representable in float
            continue
        assert c.discretize(T) == 0, options.slug()
        limit = FLOAT_BOUND if options.scalar == "float" else bound(T, options.taylor_tolerance)
        assert relative_error(c.Phi, phi_exact) < limit, options.slug()
        assert relative_error(c.Qd, qd_exact) < 10 * limit, options.slug()


@pytest.mark.parametrize("T", STEPS)
def test_generated_python_discretize_is_the_reference(case, T):
    derived, values, builds = case
    py = next(iter(builds.values()))[1].python
    m = derived.numeric(values)
    p = py.parameter_vector(values)
    phi, qd = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), T)
    phi_ref, gamma_ref = taylor_discretization(m["F"], m["G"], T, tolerance=DEFAULT_TOLERANCE, scaling=nominal_scaling(derived))
    assert relative_error(phi, phi_ref) < 1e-14
    assert relative_error(qd, taylor_process_noise(gamma_ref, m["Q"], T)) < 1e-13
    phi_exact, qd_exact = exact_noise(m, T)
    assert relative_error(phi, phi_exact) < bound(T, DEFAULT_TOLERANCE)
    assert relative_error(qd, qd_exact) < 10 * bound(T, DEFAULT_TOLERANCE)


def chain_model(n: int) -> str:
    """x_0' = x_1, ..., x_{n-2}' = x_{n-1}, x_{n-1}' = -x_{n-1}/tau: paths up to n - 1 entries long."""
    units = ["m", "m/s", *(f"m/s^{k}" for k in range(2, n))]  # x_k is the k-th derivative of x_0
    states = "\n".join(f"  - {{name: s{k}, symbol: x{k}, unit: {units[k]}}}" for k in range(n))
    dynamics = "\n".join(f"  x{k}: x{k + 1}" for k in range(n - 1))
    return f"""
model: chain
parameters:
  - {{name: tau, symbol: tau, value: 5.0}}
states:
{states}
dynamics:
{dynamics}
  x{n - 1}: -x{n - 1}/tau
"""


def test_paths_longer_than_the_taylor_order_reach_phi_in_c_and_python(tmp_path):
    """A 12-state chain: e^{F T} links the ends by a path of 11 entries, longer than the order 9."""
    from modelgen.model.loading import load_model_text

    derived = derive(load_model_text(chain_model(12), filename="chain.yaml"))
    built = build(derived, tmp_path / "out")
    m = derived.numeric({})
    T = 20.0
    phi_exact = exact(m["F"], m["G"], T)[0]
    c = built.c_filter(CodegenOptions())
    assert c.set_parameters({}) == 0 and c.discretize(T) == 0
    py = built.python
    p = py.parameter_vector({})
    phi_python, _ = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), T)
    for phi in (c.Phi, phi_python):
        assert phi[0, 11] > 0  # the far corner is there
        assert relative_error(phi, phi_exact) < DEFAULT_TOLERANCE


def test_generated_python_balanced_norm_is_the_reference_bit_for_bit(case):
    """Same D (balanced at generation time), same sums in the same order: the module and the reference pick the same plan."""
    from modelgen.derivation.discretization import balanced_norm

    derived, values, builds = case
    py = next(iter(builds.values()))[1].python
    F = derived.numeric(values)["F"]
    scaling = nominal_scaling(derived)
    assert scaling is not None  # both models declare a check operating point
    assert py._balanced_norm(F) == balanced_norm(F, scaling) == balanced_norm(F)  # at that point D is F's own balancing
    rng = np.random.default_rng(1)
    for _ in range(5):  # other operating points on the same structure, values over 20 decades
        G = np.where(F != 0, rng.standard_normal(F.shape) * 10.0 ** rng.integers(-10, 10, F.shape), 0.0)
        assert py._balanced_norm(G) == balanced_norm(G, scaling)


def test_c_and_python_choose_the_reference_plan_away_from_the_nominal_point(case):
    """At other operating points the fixed D still gives all three the same norm, so the same order and doublings."""
    derived, values, builds = case
    py = next(iter(builds.values()))[1].python
    scaling = nominal_scaling(derived)
    F = derived.numeric(values)["F"]
    rng = np.random.default_rng(2)
    for options, built in builds.values():
        if options.scalar != "double" or options.ud:
            continue
        c = built.c_filter(options)
        assert c.set_parameters(dict(zip(derived.model.parameter_names, parameter_vector(derived.model, values)))) == 0
        for _ in range(3):
            G = np.where(F != 0, F * rng.uniform(0.2, 3.0, F.shape), 0.0)
            c.matrices.F[:] = [G[i, j] for i, j in zip(*np.nonzero(derived.structure("F")))]
            assert c.discretize(60.0) == 0
            phi_ref, _ = taylor_discretization(G, derived.numeric(values)["G"], 60.0, tolerance=DEFAULT_TOLERANCE, scaling=scaling)
            p = py.parameter_vector(values)
            phi_py, _ = py.discretize(G, py.noise_input_matrix(p), py.noise_psd(p), 60.0)
            assert relative_error(c.Phi, phi_ref) < 1e-14
            assert relative_error(phi_py, phi_ref) < 1e-14


def test_recompute_threshold_keeps_the_transition_until_the_operating_point_moves(paper_derived, level_flight, tmp_path):
    """CodegenOptions(recompute_threshold=1e-6): a 1e-9 change of latitude keeps Phi bit for bit; 1e-3 or a new T recomputes."""
    options = CodegenOptions(recompute_threshold=1e-6)
    built = build(paper_derived, tmp_path / "threshold", options)
    named = dict(zip(paper_derived.model.parameter_names, parameter_vector(paper_derived.model, level_flight)))
    c = built.c_filter(options)
    assert c.set_parameters(named) == 0 and c.discretize(60.0) == 0
    first = c.Phi.copy()
    assert c.set_parameters(dict(named, latitude=named["latitude"] * (1 + 1e-9))) == 0 and c.discretize(60.0) == 0
    assert np.array_equal(c.Phi, first)
    moved = dict(named, latitude=named["latitude"] * (1 + 1e-3))
    assert c.set_parameters(moved) == 0 and c.discretize(60.0) == 0
    fresh = built.c_filter(options)
    assert fresh.set_parameters(moved) == 0 and fresh.discretize(60.0) == 0
    assert np.array_equal(c.Phi, fresh.Phi) and not np.array_equal(c.Phi, first)
    assert c.discretize(30.0) == 0 and not np.array_equal(c.Phi, fresh.Phi)


def test_a_phi_set_from_outside_makes_the_next_discretize_recompute(paper_derived, level_flight, tmp_path):
    """With recompute_threshold, set_transition_matrix forgets the remembered inputs: discretize at the same point gives e^{F T} again."""
    options = CodegenOptions(recompute_threshold=1e-6)
    built = build(paper_derived, tmp_path / "threshold_set", options)
    named = dict(zip(paper_derived.model.parameter_names, parameter_vector(paper_derived.model, level_flight)))
    c = built.c_filter(options)
    assert c.set_parameters(named) == 0 and c.discretize(60.0) == 0
    computed = c.Phi.copy()
    other = computed.copy()
    off_diagonal = ~np.eye(len(other), dtype=bool)
    other[off_diagonal] *= 0.5  # the same pattern, rows of random constants still e_i
    assert c.set_transition_matrix(other) == 0
    assert not np.array_equal(c.Phi, computed)
    assert c.discretize(60.0) == 0
    assert np.array_equal(c.Phi, computed)
