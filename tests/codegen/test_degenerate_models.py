"""Degenerate but valid models generate C that compiles in every option combination and filters.

A model whose F has no nonzero entry (only random constants: Phi = I), one
without measurements, one without noises or parameters, one with a single
state: C has no zero-size arrays or empty structs, and -Wextra refuses
unused parameters, so each of these once broke the build.
"""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from modelgen.codegen.build import compile_shared_library
from modelgen.codegen.generate import generate_code
from modelgen.codegen.options import all_combinations
from modelgen.derivation.symbolic import derive
from modelgen.model.loading import load_model_text
from tests.codegen.generated_support import Built, build, write_files
from tests.parallel_support import cores_per_worker

pytestmark = pytest.mark.compile

MODELS = {
    "random_constants_only": """
model: consts
parameters:
  - {name: sigma, symbol: sig, value: 1.0}
states:
  - {name: bias_a, symbol: a, unit: m}
  - {name: bias_b, symbol: b, unit: m}
dynamics: {a: "0", b: "0"}
measurements:
  - {name: sum_measured, symbol: z, expression: a + b, variance: "sig**2"}
""",
    "one_state_no_measurement": """
model: single
parameters:
  - {name: rate, symbol: mu, value: 0.1}
states:
  - {name: bias, symbol: b, unit: m}
noises:
  - {name: bias_noise, symbol: w, psd: mu}
dynamics: {b: -mu*b + w}
""",
    "clock_bias_and_drift": """
model: rx_clock
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
  - {name: pseudorange, symbol: z, expression: b, variance: "1.0"}
""",
    "nothing_but_a_constant": """
model: bare
states:
  - {name: bias, symbol: b, unit: m}
dynamics: {b: "0"}
""",
}


@pytest.mark.parametrize("name", list(MODELS))
def test_every_option_combination_compiles_strictly(name, tmp_path):
    derived = derive(load_model_text(MODELS[name], filename=f"{name}.yaml"))
    model = derived.model.name

    def compile_one(options):
        folder = write_files(tmp_path / options.slug(), generate_code(derived, options).files)
        return compile_shared_library([folder / f"{model}.c"], folder / f"lib{model}.so", ("-O0",))

    with ThreadPoolExecutor(max_workers=cores_per_worker()) as pool:
        libraries = list(pool.map(compile_one, all_combinations("double") + all_combinations("float")))
    assert all(library.exists() for library in libraries)


@pytest.mark.parametrize("name", list(MODELS))
def test_c_and_python_filter_a_degenerate_model_alike(name, tmp_path):
    derived = derive(load_model_text(MODELS[name], filename=f"{name}.yaml"))
    built: Built = build(derived, tmp_path / "out")
    options = all_combinations("double")[0]
    c = built.c_filter(options)
    assert c.set_parameters({}) == 0
    assert c.discretize(2.0) == 0
    n = derived.n_states
    P0 = np.eye(n) * 4.0
    assert c.set_state(np.ones(n), P0) == 0
    py = built.python
    p = py.parameter_vector({})
    phi, qd = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), 2.0)
    x, P = py.predict(np.ones(n), P0, phi, qd)
    assert c.predict() == 0
    if derived.n_measurements:
        z = np.full(derived.n_measurements, 0.5)
        x, P = py.update(x, P, z, py.measurement_matrix(p), py.measurement_variance(p))
        assert c.update(z) == 0
    np.testing.assert_allclose(c.x, x, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(c.P, P, rtol=1e-14, atol=1e-14)
    if not derived.structure("F").any():
        np.testing.assert_array_equal(phi, np.eye(n))  # random constants only: Phi = I exactly
