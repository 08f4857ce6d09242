"""Receiver clocks: an F with no nonzero entry (a random walk) or a nilpotent F (bias and drift) keeps its process noise.

A 1-state random-walk clock once got a C discretize that returned OK with
Q_d = 0 (the unrolled discretize emitted its noise blocks only when F had a
nonzero entry), and the 2-state clock (bias + drift) could not be generated
(its Horner chain has no level below the top: every stored row is read by
no row of F).  Every path is checked here against the reference: the
unrolled and the compact kernels (forced with a zero threshold), every
option family, Taylor and Van Loan's Q_d, both languages, with and without
doublings.
"""

from __future__ import annotations

import numpy as np
import pytest

from modelgen.codegen import kernels
from modelgen.codegen.build import CompiledFilter, compile_shared_library
from modelgen.codegen.generate import generate_code
from modelgen.codegen.layout import ModelSizes
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.discretization import DEFAULT_TOLERANCE, taylor_discretization, taylor_process_noise, van_loan_discretization
from modelgen.derivation.symbolic import derive
from modelgen.model.loading import load_model_text
from tests.codegen.generated_support import write_files

pytestmark = pytest.mark.compile

CLOCKS = {
    "clock_random_walk": """
model: clock_random_walk
parameters:
  - {name: sigma_bias, symbol: sb, value: 2.0}
states:
  - {name: clock_bias, symbol: b, unit: m}
noises:
  - {name: bias_noise, symbol: wb, psd: "sb**2"}
dynamics: {b: wb}
measurements:
  - {name: pseudorange, symbol: z, expression: b, variance: "1.0"}
""",
    "clock_bias_drift": """
model: clock_bias_drift
parameters:
  - {name: sigma_bias, symbol: sb, value: 2.0}
  - {name: sigma_drift, symbol: sd, value: 0.1}
states:
  - {name: clock_bias, symbol: b, unit: m}
  - {name: clock_drift, symbol: d, unit: m/s}
noises:
  - {name: bias_noise, symbol: wb, psd: "sb**2"}
  - {name: drift_noise, symbol: wd, psd: "sd**2"}
dynamics: {b: d + wb, d: wd}
measurements:
  - {name: pseudorange, symbol: z, expression: b, variance: "1.0"}
""",
    "clock_drift_rate": """
model: clock_drift_rate
parameters:
  - {name: sigma_rate, symbol: sr, value: 0.01}
states:
  - {name: clock_bias, symbol: b, unit: m}
  - {name: clock_drift, symbol: d, unit: m/s}
  - {name: clock_drift_rate, symbol: a, unit: m/s^2}
  - {name: other_bias, symbol: c, unit: m}
noises:
  - {name: rate_noise, symbol: wa, psd: "sr**2"}
  - {name: other_noise, symbol: wc, psd: "4.0"}
dynamics: {b: d, d: a, a: wa, c: wc}
measurements:
  - {name: pseudorange, symbol: z, expression: b + c, variance: "1.0"}
""",
}

#: Steps without doublings and with many (||F|| T up to 3600 for the nilpotent clocks).
STEPS = (0.01, 1.0, 60.0, 3600.0)

FAMILIES = (
    CodegenOptions(),
    CodegenOptions(storage="packed", update="sequential"),
    CodegenOptions(form="ud"),
    CodegenOptions(process_noise="van-loan"),
    CodegenOptions(taylor_order=3, taylor_tolerance=None),
)
FAMILY_IDS = ("default", "packed-sequential", "ud", "van-loan", "fixed-order-3")


@pytest.fixture(scope="module")
def clocks():
    return {name: derive(load_model_text(text, filename=f"{name}.yaml")) for name, text in CLOCKS.items()}


def reference(derived, options: CodegenOptions, T: float) -> tuple[np.ndarray, np.ndarray]:
    m = derived.numeric({})
    if options.van_loan:
        return van_loan_discretization(m["F"], m["G"], m["Q"], T)
    phi, gamma = taylor_discretization(m["F"], m["G"], T, options.taylor_order, options.taylor_tolerance)
    return phi, taylor_process_noise(gamma, m["Q"], T)


def built_filter(derived, options: CodegenOptions, folder) -> tuple[CompiledFilter, object]:
    from modelgen.codegen.build import load_python_module

    files = generate_code(derived, options).files
    write_files(folder, files)
    name = derived.model.name
    library = compile_shared_library([folder / f"{name}.c"], folder / f"lib{name}.so", ("-O1",), cache=True)
    c = CompiledFilter(library, name, ModelSizes.of(derived), derived.model.parameter_names, options=options)
    assert c.set_parameters({}) == 0
    return c, load_python_module(folder / f"{name}.py")


@pytest.mark.parametrize("kernel", ["unrolled", "compact"])
@pytest.mark.parametrize("options", FAMILIES, ids=FAMILY_IDS)
@pytest.mark.parametrize("name", list(CLOCKS))
def test_a_clocks_discretize_matches_the_reference_in_c_and_python(clocks, name, options, kernel, tmp_path, monkeypatch):
    if kernel == "compact":
        monkeypatch.setattr(kernels, "COMPACT_ABOVE_FLOPS", -1)  # every model gets the loops over Phi's pattern
    derived = clocks[name]
    c, py = built_filter(derived, options, tmp_path)
    assert ("phi_row_start" in (tmp_path / f"{name}.c").read_text()) == (kernel == "compact")
    m = derived.numeric({})
    for T in STEPS:
        phi, qd = reference(derived, options, T)
        assert c.discretize(T) == 0, T
        np.testing.assert_allclose(c.Phi, phi, rtol=1e-12, atol=1e-15 * np.abs(phi).max(), err_msg=f"C Phi, T = {T}")
        np.testing.assert_allclose(c.Qd, qd, rtol=1e-12, atol=1e-12 * np.abs(qd).max(), err_msg=f"C Q_d, T = {T}")
        assert np.all(np.diag(c.Qd)[np.diag(qd) > 0] > 0), T  # no noise term lost (relative tolerance above: none made up)
        py_phi, py_qd = py.discretize(m["F"], m["G"], np.diag(m["Q"]), T)
        np.testing.assert_allclose(py_phi, phi, rtol=1e-12, atol=1e-15 * np.abs(phi).max(), err_msg=f"Python Phi, T = {T}")
        np.testing.assert_allclose(py_qd, qd, rtol=1e-12, atol=1e-12 * np.abs(qd).max(), err_msg=f"Python Q_d, T = {T}")


@pytest.mark.parametrize("options", FAMILIES, ids=FAMILY_IDS)
def test_a_random_walks_process_noise_is_q_T(clocks, options, tmp_path):
    """Q_d = q T exactly: F = 0, so Phi = I and the integral of the noise is q T (Van Loan agrees)."""
    c, py = built_filter(clocks["clock_random_walk"], options, tmp_path)
    for T in STEPS:
        assert c.discretize(T) == 0
        np.testing.assert_allclose(c.Qd, [[4.0 * T]], rtol=4e-16)
        np.testing.assert_array_equal(c.Phi, [[1.0]])
        _, qd = py.discretize(np.zeros((1, 1)), np.ones((1, 1)), np.array([4.0]), T)
        np.testing.assert_allclose(qd, [[4.0 * T]], rtol=4e-16)
