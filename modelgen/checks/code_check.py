"""Checking generated code against the numpy reference, step by step.

Every registered backend (``modelgen.codegen.backends.registry``: the
generated Python module, the compiled C library, the C++ class) runs the same
scenario as ``modelgen.derivation.reference`` (derived matrices, Taylor discretization,
predict, Joseph update) through its ``Backend.run``: a fixed operating point,
``steps`` steps of ``T`` seconds with a measurement update after every
prediction and measurements drawn from a seeded generator.

Two measures of agreement are kept.  The *scaled* difference divides each
|Delta P_ij| by sqrt(P_ii P_jj) (and |Delta x_i| by sqrt(P_ii)): for a diagonal
entry it is the plain relative difference, for an off-diagonal entry the error
of the correlation coefficient.  The *elementwise* relative difference
|Delta P_ij| / |P_ij| is also reported; it is ill-conditioned for entries whose
correlation coefficient is tiny (1e-6), where it measures the rounding of a
nearly cancelling sum rather than a disagreement, so the pass criterion is
the scaled one.

The tolerance is computed per run (:func:`conformance_tolerance`), from how
much the run's own arithmetic cancels: see :func:`step_conditioning`.
"""

from __future__ import annotations

import warnings
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from modelgen.derivation import reference
from modelgen.codegen.backends.base import BackendUnavailable
from modelgen.codegen.backends.registry import backends
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import DerivedModel
from modelgen.derivation.discretization import (
    DEFAULT_TAYLOR_ORDER,
    DEFAULT_TOLERANCE,
    taylor_discretization,
    taylor_process_noise,
    van_loan_discretization,
)
from modelgen.errors import ModelError


@dataclass(frozen=True)
class CheckScenario:
    """What a code check flies: a constant operating point for ``steps`` filter cycles.

    Built from a model file's ``check:`` section (:mod:`modelgen.model.check_scenario`),
    the paper's scenario, or a synthetic operating point (:mod:`modelgen.jobs`).
    """

    parameters: Mapping[str, float]
    initial_covariance: np.ndarray
    step: float = 60.0
    steps: int = 240
    seed: int = 0
    initial_state: np.ndarray | None = None  # zeros when None
    label: str = "synthetic operating point"  # what the scenario is, for reports
    where: str = ""  # file:line of the model file's check: section it was built from, if any (for messages)

    def x0(self) -> np.ndarray:
        n = self.initial_covariance.shape[0]
        return np.zeros(n) if self.initial_state is None else np.asarray(self.initial_state, dtype=float).copy()

    def measurements(self, derived: DerivedModel) -> np.ndarray:
        """The seeded measurements of every step (:func:`measurement_sequence`), as ``Backend.run`` reads them."""
        return measurement_sequence(derived, self)


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
    tolerance: float = float("nan")  # this run's bound (conformance_tolerance); nan: none computed
    scenario: str = ""  # the scenario's label: what was flown

    def passed(self, tolerance: float | None = None) -> bool:
        """Scaled differences below ``tolerance`` (default: the run's own), P symmetric and positive definite."""
        limit = self.tolerance if tolerance is None else tolerance
        return self.max_scaled_P < limit and self.max_scaled_x < limit and self.symmetric and self.positive_definite


def relative_difference(value: np.ndarray, ref: np.ndarray) -> float:
    """max |value - ref| / |ref| over entries; an exact zero must stay zero."""
    diff = np.abs(value - ref)
    scale = np.abs(ref)
    nonzero = scale > 0
    worst = float(np.max(diff[nonzero] / scale[nonzero])) if nonzero.any() else 0.0
    if np.any(diff[~nonzero] > 0):
        worst = float("inf")
    return worst


def scaled_differences(
    x: np.ndarray, P: np.ndarray, x_ref: np.ndarray, P_ref: np.ndarray, initial_variance: np.ndarray | None = None
) -> tuple[float, float]:
    """(max |dP_ij|/sqrt(P_ii P_jj), max |dx_i|/sqrt(P_ii)) against the reference.

    A state the reference pinned (:func:`pinned_states`: a measurement of
    variance 0) has no sigma of its own; its differences are scaled by its
    sigma at the start, ``initial_variance`` (the scenario's P0 diagonal),
    the scale of the state before it was measured exactly.
    """
    variance = np.diag(P_ref)
    if initial_variance is not None:
        variance = np.where(pinned_states(P_ref, initial_variance), initial_variance, variance)
    sigma = np.sqrt(variance)
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


def pinned_states(P_ref: np.ndarray, initial_variance: np.ndarray | None) -> np.ndarray:
    """The states whose reference variance is below the unit roundoff of their initial variance.

    A measurement of variance 0 pins what it measures: its variance is 0 in
    exact arithmetic, 0 or a rounding residue (2.6e-32 of 1) in floating
    point, which no sum of terms of the initial variance's size resolves.
    """
    variance = np.diag(P_ref)
    if initial_variance is None:
        return np.zeros(variance.shape, dtype=bool)
    return variance <= DOUBLE_UNIT_ROUNDOFF * np.asarray(initial_variance)


def is_positive_semidefinite_within(P: np.ndarray, pinned: np.ndarray) -> bool:
    """P positive definite over the states not ``pinned``; a pinned state's variance 0 or positive (rounding).

    The pinned states (:func:`pinned_states`) have no correlation to judge;
    their rows are compared with the reference's by the scaled differences.
    """
    if np.any(np.diag(P)[pinned] < 0):
        return False
    keep = ~pinned
    return bool(not keep.any() or is_positive_definite(P[np.ix_(keep, keep)]))


def measurement_sequence(derived: DerivedModel, scenario: CheckScenario) -> np.ndarray:
    """Seeded measurements, scaled by the measurement noise, one row per step."""
    rng = np.random.default_rng(scenario.seed)
    r = np.diag(derived.numeric(scenario.parameters)["R"])
    return rng.standard_normal((scenario.steps, derived.n_measurements)) * np.sqrt(np.maximum(r, 0.0))


Stepper = Callable[[int, np.ndarray], tuple[np.ndarray, np.ndarray]]


def reference_run(
    derived: DerivedModel,
    scenario: CheckScenario,
    order: int = DEFAULT_TAYLOR_ORDER,
    tolerance: float | None = DEFAULT_TOLERANCE,
    process_noise: str = "taylor",
) -> list[tuple[np.ndarray, np.ndarray]]:
    """x and P after every step, by the dense numpy reference, discretized as the generated code is.

    ``process_noise`` is the option's (CodegenOptions.process_noise):
    ``taylor`` the Taylor series and Gamma (Q/T) Gamma^T of the given order
    and tolerance, ``van-loan`` scipy's exact exponential of Van Loan's block
    (modelgen.derivation.discretization.van_loan_discretization).
    """
    m = derived.numeric(scenario.parameters)
    if process_noise == "van-loan":
        phi, qd = van_loan_discretization(m["F"], m["G"], m["Q"], scenario.step)
    else:
        phi, gamma = taylor_discretization(m["F"], m["G"], scenario.step, order, tolerance)
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


def compare(
    name: str,
    run: list[tuple[np.ndarray, np.ndarray]],
    ref: list[tuple[np.ndarray, np.ndarray]],
    tolerance: float = float("nan"),
    scenario: str = "",
    initial_variance: np.ndarray | None = None,
) -> ConformanceResult:
    """Worst relative differences of ``run`` against ``ref`` over all steps.

    ``initial_variance``: the scenario's P0 diagonal, the scale of a state
    the reference pinned (:func:`scaled_differences`); a pinned state is
    left out of the test of definiteness.
    """
    scaled = [scaled_differences(x, P, xr, Pr, initial_variance) for (x, P), (xr, Pr) in zip(run, ref)]
    elementwise = max(relative_difference(P, Pr) for (_, P), (_, Pr) in zip(run, ref))
    symmetric = all(np.array_equal(P, P.T) for _, P in run)
    positive = all(is_positive_semidefinite_within(P, pinned_states(Pr, initial_variance)) for (_, P), (_, Pr) in zip(run, ref))
    return ConformanceResult(
        name, len(run), max(s[0] for s in scaled), max(s[1] for s in scaled), elementwise, symmetric, positive, tolerance, scenario
    )


def check_generated(
    folder: Path,
    derived: DerivedModel,
    scenario: CheckScenario,
    build_dir: Path | None = None,
    options: CodegenOptions | None = None,
) -> list[ConformanceResult]:
    """Run every backend's files (``Backend.run``) and the reference; compare each to the reference.

    ``options`` must be those the code was generated with (Taylor order,
    process noise, storage, update form); the scalar type must be double.
    The implementations run first: a scenario the generated code refuses
    (its contract: a step so short that Q/T overflows) is bad input, said
    in one line, before the reference computes anything of it.
    """
    options = options or CodegenOptions()
    if options.scalar != "double":
        raise ModelError("the reference check needs double-precision code; float is checked by `modelgen embedded`")
    _check_ud_variances(derived, scenario, options)
    folder = Path(folder)
    runs = {}
    with ThreadPoolExecutor(1, thread_name_prefix="modelgen-build-ahead") as ahead:
        # a compiled backend's build (a compiler process) goes ahead in another thread while the backends before it
        # run here (the Python's first call compiles its numba kernel); its run then takes it from the compile cache
        building = {b.name: ahead.submit(b.prepare, folder, derived, options, _build_folder(build_dir, b.name))
                    for b in backends() if b.preparer is not None and build_dir is not None}
        for backend in backends():
            if backend.name in building:
                wait([building[backend.name]])  # a build that failed ahead fails again, and is reported, in run
            try:
                runs[backend.name] = backend.run(folder, derived, scenario, options, _build_folder(build_dir, backend.name))
            except BackendUnavailable as missing:  # its toolchain is not installed here: said, not failed
                warnings.warn(str(missing), stacklevel=2)
            except ValueError as error:  # the generated Python refused an input of the scenario (its contract)
                if backend.name != "python":  # the compiled backends refuse with a status (ModelError): a bug
                    raise
                raise ModelError(f"{_located(scenario)}the check scenario ({scenario.label}) is refused by the generated "
                                 f"{backend.name}: {error}") from None
    ref = reference_run(derived, scenario, options.taylor_order, options.taylor_tolerance, options.process_noise)
    tol = scenario_tolerance(derived, scenario, options.taylor_order)
    initial_variance = np.diag(scenario.initial_covariance)
    return [compare(name, run, ref, tol, scenario.label, initial_variance) for name, run in runs.items()]


def _check_ud_variances(derived: DerivedModel, scenario: CheckScenario, options: CodegenOptions) -> None:
    """The UD form's Bierman update divides by each measurement's variance: a variance 0 at the scenario is refused, named."""
    if not (options.ud and derived.n_measurements):
        return
    variances = np.diag(derived.numeric(scenario.parameters)["R"])
    for measurement, variance in zip(derived.model.measurements, variances):
        if not variance > 0.0:
            # the measurement's own variance line (its noise entry); a model built in code has none: the check: section's
            place = measurement.place("variance")
            where, scenario_at = (f"{place}: ", f", from {scenario.where}" if scenario.where else "") if place else (_located(scenario), "")
            raise ModelError(
                f"{where}measurement {measurement.name!r} has variance {variance:g} at the check scenario ({scenario.label}{scenario_at}): "
                "the UD form's Bierman update needs every variance positive (form 'covariance' takes a variance 0)"
            )


def _located(scenario: CheckScenario) -> str:
    """``file:line: `` of the check: section a scenario was built from, or nothing (a synthetic or the paper's)."""
    return f"{scenario.where}: " if scenario.where else ""


def _build_folder(build_dir: Path | None, backend: str) -> Path | None:
    """The C's build folder is ``build_dir`` itself (as before the backends ran in a loop); another compiled backend's is a subfolder."""
    if build_dir is None or backend == "c":
        return build_dir
    folder = Path(build_dir) / backend
    folder.mkdir(parents=True, exist_ok=True)
    return folder


# -- the pass criterion --------------------------------------------------------

#: Unit roundoff of IEEE double and single precision (round to nearest).
DOUBLE_UNIT_ROUNDOFF = 2.0**-53
FLOAT_UNIT_ROUNDOFF = 2.0**-24


def _scaled_magnitude(magnitude: np.ndarray, result_diagonal: np.ndarray) -> float:
    """max_ij magnitude_ij / sqrt(d_i d_j) over the entries whose variances are positive."""
    s = np.sqrt(np.maximum(result_diagonal, 0.0))
    keep = s > 0
    if not keep.any():
        return 0.0
    return float((magnitude[np.ix_(keep, keep)] / np.outer(s[keep], s[keep])).max())


def _scaled_state(magnitude: np.ndarray, result_diagonal: np.ndarray) -> float:
    """max_i magnitude_i / sqrt(d_i) over the states whose variances are positive."""
    s = np.sqrt(np.maximum(result_diagonal, 0.0))
    keep = s > 0
    return float((magnitude[keep] / s[keep]).max()) if keep.any() else 0.0


def step_conditioning(derived: DerivedModel, scenario: CheckScenario, order: int = DEFAULT_TAYLOR_ORDER) -> np.ndarray:
    """rho_k for every step k: how much that step's arithmetic cancels, in scaled units.

    A sum of m products computed in floating point has an error of at most
    gamma_m = m u / (1 - m u) times the sum of the *absolute values* of its
    terms (Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed.,
    sec. 3.1).  Divided by sqrt(P_ii P_jj) of the result, that sum of absolute
    values is the factor by which the step can magnify one rounding:

    * discretization: Phi = sum_k (F T)^k / k! is bounded entrywise by
      |Phi|_abs = sum_k (|F| T)^k / k! (the Taylor order used by the code);
    * prediction P' = Phi P Phi^T + Q_d: |Phi|_abs |P| |Phi|_abs^T + |Q_d|,
      scaled by P';
    * Joseph update P+ = A P' A^T + K R K^T, A = I - K H:
      |A| |P'| |A|^T + |K| |R| |K|^T, scaled by P+ (the Joseph form is
      insensitive to first order to an error in K, so the gain's own
      conditioning does not enter);
    * state: |Phi|_abs |x| / sqrt(P'_ii) and (|x'| + |K| (|z| + |H| |x'|)) / sqrt(P+_ii).

    rho_k is the sum of the three (prediction, update, state): 1 for a step
    without cancellation, large where a measurement removes most of a
    variance or correlations near +-1 make a covariance entry a difference of
    large terms (an ill-conditioned P).
    """
    m = derived.numeric(scenario.parameters)
    F, n = m["F"], derived.n_states
    phi, gamma = taylor_discretization(F, m["G"], scenario.step, order)
    qd = taylor_process_noise(gamma, m["Q"], scenario.step)
    phi_abs = taylor_discretization(np.abs(F), np.zeros((n, 0)), scenario.step, order)[0]
    H, R = m["H"], m["R"]
    x, P = scenario.x0(), scenario.initial_covariance.copy()
    rho = []
    for z in measurement_sequence(derived, scenario):
        x_pred = phi @ x
        P_pred = reference.predict_covariance(P, phi, qd)
        rho_P = _scaled_magnitude(phi_abs @ np.abs(P) @ phi_abs.T + np.abs(qd), np.diag(P_pred))
        rho_x = _scaled_state(phi_abs @ np.abs(x), np.diag(P_pred))
        x, P = x_pred, P_pred
        if derived.n_measurements:
            x, P = reference.update(x_pred, P_pred, z, H, R)
            K = P_pred @ H.T @ np.linalg.inv(H @ P_pred @ H.T + R)
            A = np.eye(n) - K @ H
            rho_P += _scaled_magnitude(np.abs(A) @ np.abs(P_pred) @ np.abs(A).T + np.abs(K) @ np.abs(R) @ np.abs(K).T, np.diag(P))
            x_terms = np.abs(x_pred) + np.abs(K) @ (np.abs(z) + np.abs(H) @ np.abs(x_pred))
            rho_x += _scaled_state(x_terms, np.diag(P))
        rho.append(rho_P + rho_x)
    return np.array(rho)


def conformance_tolerance(rho: np.ndarray, n_states: int, unit_roundoff: float, implementations: int) -> float:
    """Largest scaled difference two correct implementations can show over a run.

    Every entry of P, x is a sum of at most 2n + 1 products per step (Phi P,
    then (Phi P) Phi^T, plus Q_d; the same for A P' A^T + K R K^T), so one step
    adds an error of at most gamma_{2n+1} rho_k ~ (2n + 1) u rho_k in scaled
    units (:func:`step_conditioning`).  The errors of earlier steps are carried
    forward by (I - K H) Phi, which for a stable filter contracts (the
    Joseph-form Riccati recursion is numerically stable: Verhaegen & Van
    Dooren, IEEE TAC 31(10), 1986), so they add up at most linearly:

        tolerance = implementations * (2n + 1) * u * sum_k rho_k.

    ``implementations`` is 2 when two double-precision codes are compared
    (each may be off by the bound) and 1 for float against the double
    reference (whose own error is 2^29 times smaller).  For a step without
    cancellation rho_k ~ 3 and this is cond x unit roundoff x steps with
    cond ~ 1; an ill-conditioned P raises rho_k and the bound with it.  The
    bound is a worst case: rounding errors of random sign grow like
    sqrt(terms), so measured differences sit one to three orders below it.
    """
    return float(implementations * (2 * n_states + 1) * unit_roundoff * float(np.sum(rho)))


def scenario_tolerance(
    derived: DerivedModel, scenario: CheckScenario, order: int = DEFAULT_TAYLOR_ORDER, unit_roundoff: float = DOUBLE_UNIT_ROUNDOFF, implementations: int = 2
) -> float:
    """:func:`conformance_tolerance` of ``scenario``: two double codes by default, (u_float, 1) for float."""
    return conformance_tolerance(step_conditioning(derived, scenario, order), derived.n_states, unit_roundoff, implementations)
