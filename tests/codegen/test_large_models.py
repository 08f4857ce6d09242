"""Compact prediction kernels for large models: the same bits as the unrolled code, code that grows with the nonzeros.

Above ``kernels.COMPACT_ABOVE_FLOPS`` the generated C predicts by loops over
the CSR pattern of Phi instead of straight-line code.  The loops add the same
products in the same order as the unrolled statements, so forcing them on the
paper's model must reproduce the unrolled filter bit for bit from the same
transition (Phi, Q_d), in every form (full and packed covariance, UD).  A
64-state augmented model then gets compact code that compiles strictly and
passes the conformance check.
"""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from modelgen.checks.code_check import check_generated
from modelgen.codegen import kernels
from modelgen.codegen.generate import describe, generate_code
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.discretization import DEFAULT_TOLERANCE, nominal_scaling, taylor_discretization, taylor_process_noise
from modelgen.derivation.symbolic import derive
from modelgen.fileio.datafiles import package_path
from modelgen.jobs import synthetic_scenario
from modelgen.model.loading import load_model_text
from tests.codegen.generated_support import build, write_files
from tests.codegen.large_model_support import large_model

FORMS = {
    "full": CodegenOptions(),
    "packed": CodegenOptions(storage="packed", update="sequential"),
    "ud": CodegenOptions(form="ud"),
}


def builtin_names() -> list[str]:
    return sorted(p.stem for p in package_path("models").glob("*.yaml"))


@pytest.mark.parametrize("name", builtin_names())
def test_builtin_models_stay_below_the_compact_threshold(name, derived_builtin):
    """Every built-in model keeps its unrolled prediction (and so its byte-identical C)."""
    derived = derived_builtin(name)
    description = describe(derived)
    assert not description.compact
    assert kernels.unrolled_predict_flops(description.structure) < kernels.COMPACT_ABOVE_FLOPS


def run_filter(built, options: CodegenOptions, transition: bytes | None = None, steps: int = 6) -> list[np.ndarray]:
    """P (and x) after each predict and update of the C filter, from a full-rank initial covariance.

    ``transition``: the raw transition struct (Phi, Q_d or Gamma) to predict
    with instead of this build's own discretize (which may differ in its last
    bits: the compact threshold also switches discretize to loops); the
    first item returned is this build's transition.
    """
    derived = built.derived
    scenario = synthetic_scenario(derived, steps=steps)
    filt = built.c_filter(options)
    filt.set_parameters(dict(zip(derived.model.parameter_names, built.python.parameter_vector(scenario.parameters))))
    assert filt.discretize(scenario.step) == 0
    if transition is not None:
        ctypes.memmove(ctypes.addressof(filt.transition), transition, ctypes.sizeof(filt.transition))
    out = [bytes(filt.transition)]
    n = derived.n_states
    rng = np.random.default_rng(1)
    A = rng.normal(size=(n, n))
    assert filt.set_state(rng.normal(size=n), A @ A.T / n + np.eye(n)) == 0
    for k in range(steps):
        assert filt.predict() == 0
        out += [filt.x.copy(), filt.P.copy()]
        assert filt.update(np.full(derived.n_measurements, 0.1 * (k + 1))) == 0
        out += [filt.x.copy(), filt.P.copy()]
    return out


@pytest.mark.compile
@pytest.mark.parametrize("form", FORMS)
def test_compact_kernels_give_the_unrolled_bits(form, paper_derived, tmp_path, monkeypatch):
    """The paper's model forced onto the compact loops predicts exactly as its unrolled code does."""
    options = FORMS[form]
    unrolled = build(paper_derived, tmp_path / "unrolled", options)
    assert "_row_0(" in (unrolled.folder / "ned_doppler18.c").read_text()
    monkeypatch.setattr(kernels, "COMPACT_ABOVE_FLOPS", 0)
    compact = build(paper_derived, tmp_path / "compact", options)
    source = (compact.folder / "ned_doppler18.c").read_text()
    assert "_row_0(" not in source and "phi_row_start" in source
    expected = run_filter(unrolled, options)
    got = run_filter(compact, options, transition=expected[0])
    for a, b in zip(expected[1:], got[1:], strict=True):
        np.testing.assert_array_equal(a, b)


def discretized(built, options: CodegenOptions, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Phi and Q_d of the C discretize at step T (Q_d as Gamma diag(qw) Gamma^T in the UD form).

    The transition struct is filled with NaN bits first: every entry must be written.
    """
    derived = built.derived
    scenario = synthetic_scenario(derived)
    filt = built.c_filter(options)
    filt.set_parameters(dict(zip(derived.model.parameter_names, built.python.parameter_vector(scenario.parameters))))
    ctypes.memset(ctypes.addressof(filt.transition), 0xFF, ctypes.sizeof(filt.transition))
    assert filt.discretize(T) == 0
    if options.ud:
        gamma = np.ctypeslib.as_array(filt.transition.Gamma)[:, : derived.n_noises]
        qw = np.ctypeslib.as_array(filt.transition.qw)[: derived.n_noises]
        return filt.Phi.copy(), gamma @ np.diag(qw) @ gamma.T
    return filt.Phi.copy(), filt.Qd.copy()


def reference_discretized(derived, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Phi and Q_d of the checks' reference (numpy, modelgen.derivation.discretization) at the same operating point."""
    m = derived.numeric(synthetic_scenario(derived).parameters)
    phi, gamma = taylor_discretization(m["F"], m["G"], T, 9, DEFAULT_TOLERANCE, nominal_scaling(derived))
    return phi, taylor_process_noise(gamma, m["Q"], T)


@pytest.mark.compile
@pytest.mark.parametrize("form", [*FORMS, "float"])
def test_compact_discretize_matches_the_reference_at_every_order_and_doubling(form, paper_derived, tmp_path, monkeypatch):
    """The compact discretize (loops over Phi's pattern) gives the reference's Phi and Q_d to the rounding of the arithmetic.

    The steps cover order 2 (the two top levels over their own patterns
    alone), order 9 without doublings, and 10 and 16 doublings.
    The bound, 50 units of roundoff of the largest entry of Phi - I (plus the
    rounding of 1 + E on the diagonal) and of Q_d, is far below any error of
    the scheme (a missed or doubled term is of the size of the entries).
    """
    options = CodegenOptions(scalar="float", storage="packed", update="sequential") if form == "float" else FORMS[form]
    monkeypatch.setattr(kernels, "COMPACT_ABOVE_FLOPS", 0)
    compact = build(paper_derived, tmp_path / "compact", options)
    assert "horner_series(w, order);" in (compact.folder / "ned_doppler18.c").read_text()
    eps = np.finfo(np.float32 if form == "float" else np.float64).eps
    for T in (1e-7, 0.1778, 60.0, 3600.0):
        phi, qd = discretized(compact, options, T)
        phi_ref, qd_ref = reference_discretized(paper_derived, T)
        step = phi_ref - np.eye(18)
        assert (np.abs(phi - phi_ref) <= 50 * eps * np.abs(step).max() + eps * np.eye(18)).all(), T  # + the rounding of 1 + E
        assert np.abs(qd - qd_ref).max() <= 50 * eps * np.abs(qd_ref).max(), T


DEGENERATE = {
    "constants": "model: constants\nstates:\n  - {name: bias_a, symbol: a, unit: m}\n  - {name: bias_b, symbol: b, unit: m}\n"
    "dynamics: {a: \"0\", b: \"0\"}\nmeasurements:\n  - {name: z, symbol: z, expression: a + b, variance: \"1e-2\"}\n",
    "walk": "model: walk\nstates:\n  - {name: bias, symbol: b, unit: m}\n  - {name: drift, symbol: d, unit: m}\n"
    "noises:\n  - {name: bias_noise, symbol: w, psd: \"1e-4\"}\ndynamics: {b: w, d: \"0\"}\n"
    "measurements:\n  - {name: z, symbol: z, expression: b + d, variance: \"1e-2\"}\n",
    "chain": "model: chain\nstates:\n  - {name: p, symbol: p, unit: m}\n  - {name: v, symbol: v, unit: m/s}\n  - {name: a, symbol: a, unit: m/s^2}\n"
    "noises:\n  - {name: jerk, symbol: w, psd: \"1e-4\"}\ndynamics: {p: v, v: a, a: \"-a/100 + w\"}\n"
    "measurements:\n  - {name: z, symbol: z, expression: p, variance: \"1e-2\"}\n",
}


@pytest.mark.compile
@pytest.mark.parametrize("name", DEGENERATE)
@pytest.mark.parametrize("form", ["full", "ud"])
def test_degenerate_models_forced_compact_conform(name, form, tmp_path, monkeypatch):
    """The compact discretize's edge cases conform: F without a nonzero, a noise on an empty row of F, a chain of 3."""
    monkeypatch.setattr(kernels, "COMPACT_ABOVE_FLOPS", -1)
    derived = derive(load_model_text(DEGENERATE[name], filename="m.yaml"))
    folder = write_files(tmp_path / "gen", generate_code(derived, FORMS[form]).files)
    assert "phi_row_start" in (folder / f"{name}.c").read_text()
    for result in check_generated(folder, derived, synthetic_scenario(derived, steps=10), options=FORMS[form]):
        assert result.passed(), result


@pytest.fixture(scope="module")
def derived_64():
    return derive(large_model(64))


@pytest.mark.compile
def test_a_64_state_model_gets_compact_code_that_conforms(derived_64, tmp_path):
    """64 states (above the threshold): compact C, far smaller than its unrolled code (1.3 MB) that passes the check."""
    code = generate_code(derived_64)
    source = code.files["ned_doppler64_large.c"]
    assert "_row_0(" not in source and "check += propagate(f, t, w);" in source
    assert len(source) < 200_000
    folder = write_files(tmp_path / "gen", code.files)
    for result in check_generated(folder, derived_64, synthetic_scenario(derived_64, steps=20)):
        assert result.passed(), result
