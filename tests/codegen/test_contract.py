"""One contract for both languages: the generated Python refuses exactly what the generated C refuses.

The same bad inputs go to the Python module (ValueError naming the
argument) and to the C of every option family -- double and float, the
covariance form in full and packed storage with vector and sequential
updates, and the UD form -- which must return an error status and leave
the filter exactly as it was.
"""

import math

import numpy as np
import pytest

from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import parameter_vector
from tests.codegen.generated_support import build

pytestmark = pytest.mark.compile

FAMILIES = [
    CodegenOptions(),
    CodegenOptions(storage="packed"),
    CodegenOptions(update="sequential"),
    CodegenOptions(update="sequential", storage="packed", covariance_update="standard"),
    CodegenOptions(form="ud"),
    CodegenOptions(scalar="float"),
    CodegenOptions(scalar="float", form="ud"),
    CodegenOptions(scalar="float", storage="packed", update="sequential"),
]


def correlated(n: int) -> np.ndarray:
    """A valid P: variances 1..n, correlation 0.3 between neighbours."""
    sigma = np.sqrt(np.arange(1.0, n + 1))
    C = np.eye(n) + 0.3 * (np.eye(n, k=1) + np.eye(n, k=-1))
    return C * np.outer(sigma, sigma)


def bad_covariances(n: int) -> dict[str, np.ndarray]:
    """P matrices the contract refuses, by what is wrong with them."""
    P = correlated(n)
    out = {}
    out["nan"] = P.copy()
    out["nan"][1, 2] = out["nan"][2, 1] = math.nan
    out["nan_lower_triangle_only"] = P.copy()
    out["nan_lower_triangle_only"][3, 0] = math.nan
    out["negative_variance"] = P.copy()
    out["negative_variance"][2, 2] = -1.0
    out["zero_variance_with_correlation"] = P.copy()
    out["zero_variance_with_correlation"][n - 1, n - 1] = 0.0  # the UD form used to drop the correlation silently
    out["correlation_above_one"] = P.copy()
    out["correlation_above_one"][0, 1] = out["correlation_above_one"][1, 0] = 1.01 * math.sqrt(P[0, 0] * P[1, 1])
    indefinite = np.eye(n)
    indefinite[0, 1] = indefinite[1, 0] = indefinite[1, 2] = indefinite[2, 1] = 0.9  # pairwise fine, jointly not
    out["indefinite"] = indefinite
    out["not_symmetric"] = P.copy()
    out["not_symmetric"][0, 1] += 0.1
    return out


@pytest.fixture(scope="module")
def builds(paper_derived, tmp_path_factory):
    root = tmp_path_factory.mktemp("contract")
    return {o.slug(): build(paper_derived, root / o.slug(), o) for o in FAMILIES}


@pytest.fixture(scope="module")
def operating_point(paper_derived, level_flight):
    return dict(zip(paper_derived.model.parameter_names, parameter_vector(paper_derived.model, level_flight)))


def ready_c_filter(built, options, operating_point):
    c = built.c_filter(options)
    assert c.set_parameters(operating_point) == 0
    assert c.discretize(60.0) == 0
    assert c.set_state(np.zeros(built.derived.n_states), correlated(built.derived.n_states)) == 0
    return c


def snapshot(c) -> bytes:
    return bytes(c.filter)


def python_inputs(py, operating_point, n):
    p = py.parameter_vector(operating_point)
    phi, qd = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), 60.0)
    return p, phi, qd, np.zeros(n), correlated(n)


@pytest.mark.parametrize("options", FAMILIES, ids=lambda o: o.slug())
def test_an_invalid_covariance_is_refused_by_c_set_covariance_and_python_predict_and_update(builds, options, operating_point):
    built = builds[options.slug()]
    n = built.derived.n_states
    c = ready_c_filter(built, options, operating_point)
    py = built.python
    p, phi, qd, x, _ = python_inputs(py, operating_point, n)
    H, r = py.measurement_matrix(p), py.measurement_variance(p)
    for what, P in bad_covariances(n).items():
        before = snapshot(c)
        assert c.set_state(np.zeros(n), P) != 0, what
        assert snapshot(c) == before, what
        with pytest.raises(ValueError, match=r"predict: P"):
            py.predict(x, P, phi, qd)
        with pytest.raises(ValueError, match=r"update: P"):
            py.update(x, P, np.zeros(len(r)), H, r)
        with pytest.raises(ValueError, match=r"set_covariance: P"):  # the Filter class, as the C's set_covariance
            py.Filter(x, P)
        f = py.Filter(x, correlated(n))
        with pytest.raises(ValueError, match=r"set_covariance: P"):
            f.set_covariance(P)
        assert np.array_equal(f.get_covariance(), correlated(n)), what


@pytest.mark.parametrize("options", FAMILIES, ids=lambda o: o.slug())
def test_a_bad_step_is_refused_by_both(builds, options, operating_point):
    built = builds[options.slug()]
    c = ready_c_filter(built, options, operating_point)
    py = built.python
    p = py.parameter_vector(operating_point)
    F, G, q = py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p)
    for T in (0.0, -60.0, math.nan, math.inf, 1e300):
        assert c.discretize(T) != 0, T
        with pytest.raises(ValueError, match="discretize: T|not representable"):
            py.discretize(F, G, q, T)
    q_negative = q.copy()
    q_negative[0] = -1.0
    with pytest.raises(ValueError, match="discretize: q"):
        py.discretize(F, G, q_negative, 60.0)
    np.ctypeslib.as_array(c.matrices.q)[0] = -1.0
    assert c.discretize(60.0) == 2  # ERR_NOT_POSITIVE


@pytest.mark.parametrize("options", FAMILIES, ids=lambda o: o.slug())
def test_bad_measurements_and_states_are_refused_by_both_and_leave_the_c_filter_unchanged(builds, options, operating_point):
    built = builds[options.slug()]
    n = built.derived.n_states
    c = ready_c_filter(built, options, operating_point)
    py = built.python
    p, phi, qd, x, P = python_inputs(py, operating_point, n)
    H, r = py.measurement_matrix(p), py.measurement_variance(p)
    z = np.zeros(len(r))

    before = snapshot(c)
    assert c.update(np.array([math.nan] + [0.0] * (len(r) - 1))) != 0
    assert snapshot(c) == before
    with pytest.raises(ValueError, match="update: z"):
        py.update(x, P, np.array([math.nan] + [0.0] * (len(r) - 1)), H, r)

    r_c = np.ctypeslib.as_array(c.matrices.r)
    saved = r_c[0]
    r_c[0] = -1.0
    assert c.update(z) != 0
    assert snapshot(c) == before
    r_c[0] = saved
    r_negative = r.copy()
    r_negative[0] = -1.0
    with pytest.raises(ValueError, match="update: r"):
        py.update(x, P, z, H, r_negative)

    x_nan = x.copy()
    x_nan[0] = math.nan
    c.set_estimate(x_nan)
    before = snapshot(c)
    assert c.predict() != 0
    assert snapshot(c) == before
    with pytest.raises(ValueError, match="predict: x"):
        py.predict(x_nan, P, phi, qd)
    with pytest.raises(ValueError, match="update: x"):
        py.update(x_nan, P, z, H, r)
    with pytest.raises(ValueError, match="set_state: x"):  # the Filter class refuses it, as the C's set_state does
        py.Filter(x_nan, P)


@pytest.mark.parametrize("options", FAMILIES, ids=lambda o: o.slug())
def test_a_process_noise_with_a_negative_variance_is_refused_by_both_and_changes_nothing(builds, options, operating_point):
    """Q_d(i, i) < 0 (UD form: a negative weight qw) is refused by predict as set_covariance refuses such a P (issue 28)."""
    from modelgen.codegen.layout import packed_index

    built = builds[options.slug()]
    n = built.derived.n_states
    c = ready_c_filter(built, options, operating_point)
    py = built.python
    p, phi, qd, x, P = python_inputs(py, operating_point, n)
    f = py.Filter(x, P)
    state = (f.get_state().tobytes(), f.get_covariance().tobytes())
    for k in (0, n - 1):
        stored = np.ctypeslib.as_array(c.transition.qw if options.ud else c.transition.Qd)
        index = min(k, len(stored) - 1) if options.ud else packed_index(n, k, k)
        saved = stored[index]
        stored[index] = -1e-6
        before = snapshot(c)
        assert c.predict() == 2, k  # ERR_NOT_POSITIVE
        assert snapshot(c) == before, k
        stored[index] = saved
        negative = qd.copy()
        negative[k, k] = -1e-6
        with pytest.raises(ValueError, match=rf"predict: Qd has a negative variance Qd\[{k}, {k}\]"):
            py.predict(x, P, phi, negative)
        with pytest.raises(ValueError, match=rf"predict: Qd has a negative variance Qd\[{k}, {k}\]"):
            f.predict(phi, negative)
        assert (f.get_state().tobytes(), f.get_covariance().tobytes()) == state, k
    assert c.predict() == 0  # the transition restored: accepted again


@pytest.mark.parametrize("options", [FAMILIES[0], FAMILIES[4]], ids=lambda o: o.slug())
def test_the_python_filter_class_refuses_what_the_c_filter_refuses_and_is_then_unchanged(builds, options, operating_point):
    """The stateful API of both languages: set_covariance, update and update_masked on the same bad inputs."""
    built = builds[options.slug()]
    n = built.derived.n_states
    c = ready_c_filter(built, options, operating_point)
    py = built.python
    p, phi, qd, x, P = python_inputs(py, operating_point, n)
    H, r = py.measurement_matrix(p), py.measurement_variance(p)
    f = py.Filter(x, P)
    f.predict(phi, qd)
    assert c.predict() == 0
    state = (f.get_state().tobytes(), f.get_covariance().tobytes())
    cases = {
        "z": (np.array([math.nan] + [0.0] * (len(r) - 1)), None),
        "r": (np.zeros(len(r)), -1.0),
    }
    r_c = np.ctypeslib.as_array(c.matrices.r)
    for what, (z, r0) in cases.items():
        before = snapshot(c)
        saved = r_c[0]
        if r0 is not None:
            r_c[0] = r0
        assert c.update(z) != 0, what
        status, _, _ = c.update_masked(z, None)
        assert status != 0, what
        r_c[0] = saved
        assert snapshot(c) == before, what
        r_py = r if r0 is None else np.concatenate([[r0], r[1:]])
        with pytest.raises(ValueError, match=f"update: {what}"):
            f.update(z, H, r_py)
        with pytest.raises(ValueError, match=f"update: {what}"):
            f.update_masked(z, H, r_py)
        assert (f.get_state().tobytes(), f.get_covariance().tobytes()) == state, what


@pytest.mark.parametrize("latitude_deg", [90.0, -90.0])
@pytest.mark.parametrize("options", [FAMILIES[0], FAMILIES[4], FAMILIES[5]], ids=lambda o: o.slug())
def test_a_singular_operating_point_is_refused_by_both_and_leaves_the_c_filter_unchanged(builds, options, operating_point, latitude_deg):
    """At latitude +-90 degrees cos is 6e-17, not 0: tan and sec are finite and meaningless, so both refuse."""
    built = builds[options.slug()]
    c = ready_c_filter(built, options, operating_point)
    before, phi_before = snapshot(c), c.Phi.copy()
    pole = {**operating_point, "latitude": math.radians(latitude_deg)}
    assert c.set_parameters(pole) == 1  # ERR_NONFINITE
    assert snapshot(c) == before and np.array_equal(c.Phi, phi_before)
    with pytest.raises(ValueError, match=r"system_matrix: cos\(latitude\) .* singular"):
        built.python.system_matrix(built.python.parameter_vector(pole))
    near = {**operating_point, "latitude": math.radians(89.9)}
    assert c.set_parameters(near) == 0  # close to the pole is still a valid operating point
    built.python.system_matrix(built.python.parameter_vector(near))


def test_a_parameter_that_makes_an_expression_infinite_is_refused_by_both(builds, operating_point):
    built = builds[FAMILIES[0].slug()]
    c = ready_c_filter(built, FAMILIES[0], operating_point)
    flat = {**operating_point, "earth_radius": 0.0}  # 1/R
    assert c.set_parameters(flat) == 1
    with pytest.raises(ValueError, match="system_matrix"):
        built.python.system_matrix(built.python.parameter_vector(flat))


def test_the_contract_table_is_written_into_the_python_docstring_and_the_readme(builds):
    from modelgen.codegen.contract import CONTRACT, contract_markdown

    built = builds[FAMILIES[0].slug()]
    docstring = " ".join(built.python.__doc__.split())
    readme = built.code.files["README.md"]
    for function, refused, status in CONTRACT:
        assert f"{function}: {refused} -> C {status}" in docstring
    for row in contract_markdown():
        assert row in readme
        assert row.count("|") == 4  # no cell holds a pipe


@pytest.mark.parametrize("options", FAMILIES, ids=lambda o: o.slug())
def test_a_measurement_whose_innovation_squared_overflows_is_refused_by_both(builds, options, operating_point):
    """z = +-1e308: nu^T S^-1 nu overflows, a non-finite result refused by C and Python alike (issue 28: Python returned x ~ 8.6e307)."""
    built = builds[options.slug()]
    n = built.derived.n_states
    c = ready_c_filter(built, options, operating_point)
    py = built.python
    p, phi, qd, x, P = python_inputs(py, operating_point, n)
    H, r = py.measurement_matrix(p), py.measurement_variance(p)
    f = py.Filter(x, P)
    state = (f.get_state().tobytes(), f.get_covariance().tobytes())
    for value in (1e308, -1e308):
        z = np.zeros(len(r))
        z[0] = value
        before = snapshot(c)
        assert c.update(z) == 1, value  # ERR_NONFINITE
        assert c.update_masked(z, None)[0] == 1, value
        assert snapshot(c) == before, value
        for update in (lambda: py.update(x, P, z, H, r), lambda: py.update_masked(x, P, z, H, r),
                       lambda: f.update(z, H, r), lambda: f.update_masked(z, H, r)):
            with pytest.raises(ValueError, match="update: the normalized innovation squared"):
                update()
        assert (f.get_state().tobytes(), f.get_covariance().tobytes()) == state, value


@pytest.mark.parametrize("options", [o for o in FAMILIES if o.scalar == "double"], ids=lambda o: o.slug())
def test_a_large_but_finite_innovation_squared_is_accepted_by_both_and_agrees(builds, options, operating_point):
    """z = 1e200 with r = 1e300: nu^2 overflows but nu^T S^-1 nu = 1e100 does not; every update accepts it (the
    sequential and Bierman updates summed nu * nu / s, which overflowed, where the vector update's |L^-1 nu|^2 did not)."""
    built = builds[options.slug()]
    n = built.derived.n_states
    c = ready_c_filter(built, options, operating_point)
    py = built.python
    p, phi, qd, x, P = python_inputs(py, operating_point, n)
    H, r = py.measurement_matrix(p), py.measurement_variance(p)
    r = r.copy()
    r[0] = 1e300
    np.ctypeslib.as_array(c.matrices.r)[0] = 1e300
    z = np.zeros(len(r))
    z[0] = 1e200
    status, _, nis = c.update_masked(z, None)
    assert status == 0
    _, _, _, py_nis = py.update_masked(x, P, z, H, r)
    assert nis == pytest.approx(1e100, rel=1e-9) and py_nis == pytest.approx(nis, rel=1e-12)


@pytest.mark.parametrize("options", FAMILIES, ids=lambda o: o.slug())
def test_a_step_so_short_that_q_over_T_overflows_is_refused_by_both(builds, options, operating_point):
    """T = 1e-320: q / T, the weights of Gamma (Q/T) Gamma^T, overflows; C and Python refuse it alike (issue 28: the
    covariance C accepted it, the Python refused it); T = 1e-300 (q / T finite) both accept in double."""
    built = builds[options.slug()]
    c = ready_c_filter(built, options, operating_point)
    py = built.python
    p = py.parameter_vector(operating_point)
    F, G, q = py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p)
    assert c.discretize(1e-320) == (1 if options.scalar == "double" else 2)  # a float T of 1e-320 is 0: not positive
    with pytest.raises(ValueError, match="discretize: T = 1e-320 is so short that q / T"):
        py.discretize(F, G, q, 1e-320)
    if options.scalar == "double":
        assert c.discretize(1e-300) == 0
        phi, _ = py.discretize(F, G, q, 1e-300)
        np.testing.assert_array_equal(phi, c.Phi)  # one term of the series: I + F T rounds to I


def test_a_step_that_is_not_a_real_number_is_refused_by_the_python(builds, operating_point):
    """'60', True and complex steps are refused as the C's double would never hold them (issue 28); real types are taken."""
    py = builds[FAMILIES[0].slug()].python
    p = py.parameter_vector(operating_point)
    F, G, q = py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p)
    for T in ("60", True, False, np.bool_(True), 60 + 0j, np.complex128(60.0), None, [60.0]):
        with pytest.raises(ValueError, match="discretize: T is not a real number"):
            py.discretize(F, G, q, T)
    reference = py.discretize(F, G, q, 60.0)
    for T in (60, np.float64(60.0), np.int64(60), np.float32(60.0)):
        np.testing.assert_array_equal(py.discretize(F, G, q, T)[0], reference[0])
