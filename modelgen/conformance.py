"""Checking generated code against the numpy reference, step by step.

Both the generated Python module and the compiled C library run the same
scenario as ``modelgen.reference`` (derived matrices, Taylor discretization,
predict, Joseph update): a fixed operating point, ``steps`` steps of ``T``
seconds with a measurement update after every prediction and measurements
drawn from a seeded generator.

Two measures of agreement are kept.  The *scaled* difference divides each
|Delta P_ij| by sqrt(P_ii P_jj) (and |Delta x_i| by sqrt(P_ii)): for a diagonal
entry it is the plain relative difference, for an off-diagonal entry the error
of the correlation coefficient.  The *elementwise* relative difference
|Delta P_ij| / |P_ij| is also reported; it is ill-conditioned for entries whose
correlation coefficient is tiny (1e-6), where it measures the rounding of a
nearly cancelling sum rather than a disagreement, so the pass criterion is
the scaled one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from modelgen import reference
from modelgen.codegen.build import build_c_filter, load_python_module
from modelgen.codegen.layout import ModelSizes
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation import DerivedModel, parameter_vector
from modelgen.discretization import DEFAULT_TAYLOR_ORDER, taylor_discretization, taylor_process_noise
from modelgen.errors import ModelError


@dataclass(frozen=True)
class Scenario:
    """A constant operating point flown for ``steps`` filter cycles."""

    parameters: Mapping[str, float]
    initial_covariance: np.ndarray
    step: float = 60.0
    steps: int = 240
    seed: int = 0
    initial_state: np.ndarray | None = None  # zeros when None

    def x0(self) -> np.ndarray:
        n = self.initial_covariance.shape[0]
        return np.zeros(n) if self.initial_state is None else np.asarray(self.initial_state, dtype=float).copy()


@dataclass(frozen=True)
class ConformanceResult:
    """Largest relative differences between an implementation and the reference."""

    implementation: str
    steps: int
    max_scaled_P: float  # max |dP_ij| / sqrt(P_ii P_jj)
    max_scaled_x: float  # max |dx_i| / sqrt(P_ii)
    max_elementwise_P: float  # max |dP_ij| / |P_ij|, for information
    symmetric: bool
    positive_definite: bool

    def passed(self, tolerance: float) -> bool:
        """Scaled differences below ``tolerance``, P symmetric and positive definite."""
        return self.max_scaled_P < tolerance and self.max_scaled_x < tolerance and self.symmetric and self.positive_definite


def relative_difference(value: np.ndarray, ref: np.ndarray) -> float:
    """max |value - ref| / |ref| over entries; an exact zero must stay zero."""
    diff = np.abs(value - ref)
    scale = np.abs(ref)
    nonzero = scale > 0
    worst = float(np.max(diff[nonzero] / scale[nonzero])) if nonzero.any() else 0.0
    if np.any(diff[~nonzero] > 0):
        worst = float("inf")
    return worst


def scaled_differences(x: np.ndarray, P: np.ndarray, x_ref: np.ndarray, P_ref: np.ndarray) -> tuple[float, float]:
    """(max |dP_ij|/sqrt(P_ii P_jj), max |dx_i|/sqrt(P_ii)) against the reference."""
    sigma = np.sqrt(np.diag(P_ref))
    dP = np.abs(P - P_ref) / np.outer(sigma, sigma)
    dx = np.abs(x - x_ref) / sigma
    return float(dP.max()), float(dx.max())


def is_positive_definite(P: np.ndarray) -> bool:
    """Cholesky of the correlation matrix succeeds.

    The states mix radians and metres per second, so the raw eigenvalues of P
    span 20 orders of magnitude and rounding makes the smallest one's sign
    meaningless; the correlation matrix D^-1/2 P D^-1/2 is scale-free.
    """
    d = np.diag(P)
    if np.any(d <= 0) or not np.all(np.isfinite(P)):
        return False
    s = 1 / np.sqrt(d)
    try:
        np.linalg.cholesky(P * np.outer(s, s))
    except np.linalg.LinAlgError:
        return False
    return True


def measurement_sequence(derived: DerivedModel, scenario: Scenario) -> np.ndarray:
    """Seeded measurements, scaled by the measurement noise, one row per step."""
    rng = np.random.default_rng(scenario.seed)
    r = np.diag(derived.numeric(scenario.parameters)["R"])
    return rng.standard_normal((scenario.steps, derived.n_measurements)) * np.sqrt(np.maximum(r, 0.0))


Stepper = Callable[[int, np.ndarray], tuple[np.ndarray, np.ndarray]]


def reference_run(derived: DerivedModel, scenario: Scenario, order: int = DEFAULT_TAYLOR_ORDER) -> list[tuple[np.ndarray, np.ndarray]]:
    """x and P after every step, by the dense numpy reference."""
    m = derived.numeric(scenario.parameters)
    phi, gamma = taylor_discretization(m["F"], m["G"], scenario.step, order)
    qd = taylor_process_noise(gamma, m["Q"], scenario.step)
    x = scenario.x0()
    P = scenario.initial_covariance.copy()
    out = []
    for z in measurement_sequence(derived, scenario):
        x = phi @ x
        P = reference.predict_covariance(P, phi, qd)
        if derived.n_measurements:
            x, P = reference.update(x, P, z, m["H"], m["R"])
        out.append((x, P))
    return out


def python_run(module_path: Path, derived: DerivedModel, scenario: Scenario) -> list[tuple[np.ndarray, np.ndarray]]:
    """x and P after every step, by the generated Python module."""
    gen = load_python_module(module_path)
    p = gen.parameter_vector(_named_parameters(derived, scenario))
    F, G, H = gen.system_matrix(p), gen.noise_input_matrix(p), gen.measurement_matrix(p)
    q, r = gen.noise_psd(p), gen.measurement_variance(p)
    phi, qd = gen.discretize(F, G, q, scenario.step)
    x = scenario.x0()
    P = scenario.initial_covariance.copy()
    out = []
    for z in measurement_sequence(derived, scenario):
        x, P = gen.predict(x, P, phi, qd)
        if derived.n_measurements:
            x, P = gen.update(x, P, z, H, r)
        out.append((x, P))
    return out


def c_run(
    folder: Path,
    derived: DerivedModel,
    scenario: Scenario,
    build_dir: Path | None = None,
    options: CodegenOptions | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """x and P after every step, by the compiled generated C (generated with ``options``)."""
    model = derived.model
    filt = build_c_filter(Path(folder), model.name, ModelSizes.of(derived), model.parameter_names, build_dir, options=options)
    filt.set_parameters(_named_parameters(derived, scenario))
    if filt.discretize(scenario.step) != 0:
        raise ModelError(f"generated C for {model.name!r} refused the step T = {scenario.step}")
    filt.set_state(scenario.x0(), scenario.initial_covariance)
    out = []
    for z in measurement_sequence(derived, scenario):
        filt.predict()
        if derived.n_measurements:
            status = filt.update(z)
            if status != 0:
                raise ModelError(f"generated C update returned status {status}")
        out.append((filt.x, filt.P))
    return out


def _named_parameters(derived: DerivedModel, scenario: Scenario) -> dict[str, float]:
    """Every parameter by its spelled-out name, defaults filled in."""
    values = parameter_vector(derived.model, scenario.parameters)
    return dict(zip(derived.model.parameter_names, values))


def compare(name: str, run: list[tuple[np.ndarray, np.ndarray]], ref: list[tuple[np.ndarray, np.ndarray]]) -> ConformanceResult:
    """Worst relative differences of ``run`` against ``ref`` over all steps."""
    scaled = [scaled_differences(x, P, xr, Pr) for (x, P), (xr, Pr) in zip(run, ref)]
    elementwise = max(relative_difference(P, Pr) for (_, P), (_, Pr) in zip(run, ref))
    symmetric = all(np.array_equal(P, P.T) for _, P in run)
    positive = all(is_positive_definite(P) for _, P in run)
    return ConformanceResult(
        name, len(run), max(s[0] for s in scaled), max(s[1] for s in scaled), elementwise, symmetric, positive
    )


def check_generated(
    folder: Path,
    derived: DerivedModel,
    scenario: Scenario,
    build_dir: Path | None = None,
    options: CodegenOptions | None = None,
) -> list[ConformanceResult]:
    """Run reference, generated Python and generated C; compare each to the reference.

    ``options`` must be those the code was generated with (Taylor order,
    storage, update form); the scalar type must be double.
    """
    options = options or CodegenOptions()
    if options.scalar != "double":
        raise ModelError("the reference check needs double-precision code; float is checked by `modelgen embedded`")
    folder = Path(folder)
    ref = reference_run(derived, scenario, options.taylor_order)
    name = derived.model.name
    return [
        compare("python", python_run(folder / f"{name}.py", derived, scenario), ref),
        compare("c", c_run(folder, derived, scenario, build_dir, options), ref),
    ]
