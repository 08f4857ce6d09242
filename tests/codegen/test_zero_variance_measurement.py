"""A measurement of variance 0 is legal: the filter's own P after such an update passes its own contract (issue 28).

The update pins what it measures: exactly, its variance is 0 and so is its
correlation; rounding left a residue in its row (P[0, 1] = -2.8e-17 beside
P[0, 0] = 0) that the next predict refused as not positive semidefinite.
Both languages clear the row and column of a state whose updated variance
is not positive, so the chain update -> predict, and the C's
get_covariance -> set_covariance, keep going.
"""

import numpy as np
import pytest

from modelgen.codegen.options import CodegenOptions
from tests.codegen.generated_support import build_text

pytestmark = pytest.mark.compile

CLOCK = """model: pinned_clock
parameters:
  - {name: sigma_bias, symbol: sb, value: 2.0}
states:
  - {name: clock_bias, symbol: b, unit: m}
  - {name: clock_drift, symbol: d, unit: m/s}
noises:
  - {name: bias_noise, symbol: wb, psd: "sb**2"}
  - {name: drift_noise, symbol: wd, psd: "0.01"}
dynamics: {b: d + wb, d: wd}
measurements:
  - {name: pseudorange, symbol: z, expression: b, variance: "0"}
"""

COVARIANCE_FAMILIES = [
    CodegenOptions(),
    CodegenOptions(storage="packed"),
    CodegenOptions(update="sequential"),
    CodegenOptions(covariance_update="standard"),
    CodegenOptions(update="sequential", storage="packed", covariance_update="standard"),
]
STEPS = 100  # main refused the Python's own P at step 13
INITIAL_P = np.array([[1.0, 0.0], [0.0, 1.0]])


def measurements(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal(STEPS) * 3.0


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    root = tmp_path_factory.mktemp("zero_variance")
    return {o.slug(): build_text(CLOCK, root / o.slug(), o) for o in COVARIANCE_FAMILIES}


def test_the_python_functions_accept_their_own_covariance_after_updates_of_variance_zero(built):
    py = built[CodegenOptions().slug()].python
    p = py.parameter_vector({"sigma_bias": 2.0})
    H, r = py.measurement_matrix(p), py.measurement_variance(p)
    assert r.tolist() == [0.0]
    phi, qd = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), 0.5)
    x, P = np.zeros(2), INITIAL_P.copy()
    for k, z in enumerate(measurements()):
        x, P = py.predict(x, P, phi, qd)  # refused its own P on main
        x, P = py.update(x, P, np.array([z]), H, r)
        assert P[0, 0] == 0.0 and P[0, 1] == 0.0 and P[1, 0] == 0.0, k
        assert P[1, 1] > 0.0, k
        assert x[0] == pytest.approx(z, abs=1e-12), k


def test_the_python_filter_class_takes_updates_of_variance_zero(built):
    py = built[CodegenOptions().slug()].python
    p = py.parameter_vector({"sigma_bias": 2.0})
    H, r = py.measurement_matrix(p), py.measurement_variance(p)
    phi, qd = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), 0.5)
    f = py.Filter(np.zeros(2), INITIAL_P)
    for z in measurements():
        f.predict(phi, qd)
        f.update(np.array([z]), H, r)
        py.Filter(f.get_state(), f.get_covariance())  # its P passes set_covariance's test


@pytest.mark.parametrize("options", COVARIANCE_FAMILIES, ids=lambda o: o.slug())
def test_the_c_filter_pins_the_measured_state_and_its_covariance_passes_set_covariance(built, options):
    c = built[options.slug()].c_filter(options)
    assert c.set_parameters({"sigma_bias": 2.0}) == 0
    assert c.discretize(0.5) == 0
    assert c.set_state(np.zeros(2), INITIAL_P) == 0
    for k, z in enumerate(measurements()):
        assert c.predict() == 0, k
        assert c.update(np.array([z])) == 0, k
        P = c.P
        assert 0.0 <= P[0, 0] <= 4 * np.finfo(float).eps, k  # 0, or a rounding residue (the standard form: 4.4e-16)
        assert c.set_state(c.x, P) == 0, k  # the contract's own test takes what the update left
