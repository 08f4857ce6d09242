"""Covariance recursions: open loop, optimal filter, true covariance of a suboptimal filter.

All three work on time-invariant discrete systems (the paper evaluates F at
one level-flight operating point, so Phi and Gamma Q Gamma^T are computed
once per parameter set and reused for all 240 steps).

* :func:`propagate_covariance` -- eq. (9), pure inertial;
* :func:`optimal_filter_covariance` -- eq. (12): with open-loop compensation
  the residual error after compensation is the estimation error, so the
  filter's own P(k/k) is the accuracy of the integrated system;
* :func:`filter_gains` -- the gain sequence a (possibly reduced-order,
  possibly piecewise-constant-gain) filter computes from its own model;
* :func:`true_error_covariance` -- the covariance of the actual estimation
  error when that gain sequence runs against the full truth model (the
  standard suboptimal-filter sensitivity recursion on the joint vector of
  truth state and filter error).  A suboptimal filter's own covariance is
  not its accuracy; this is.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from modelgen.derivation.symbolic import DerivedModel
from modelgen.derivation.discretization import taylor_discretization, taylor_process_noise
from modelgen.derivation.reference import kalman_gain
from modelgen.errors import ModelError


@dataclass(frozen=True)
class DiscreteSystem:
    """x(k+1) = Phi x(k) + Gamma W(k),  z(k+1) = H x(k+1) + V(k+1)  (eq. (8))."""

    state_names: tuple[str, ...]
    transition: np.ndarray  # Phi(k+1/k), eq. (10)
    process_noise: np.ndarray  # Gamma Q(k) Gamma^T, eqs. (9), (11)
    measurement: np.ndarray  # H
    measurement_noise: np.ndarray  # R

    @property
    def n_states(self) -> int:
        return self.transition.shape[0]


def model_values(derived: DerivedModel, values: Mapping[str, float]) -> dict[str, float]:
    """The entries of ``values`` that are parameters of this model.

    Reduced models (``modelgen.model.transform``) drop parameters they no longer
    use, so one value set for the full model serves all of them.
    """
    names = set(derived.model.parameter_names)
    return {k: v for k, v in values.items() if k in names}


def discretize(derived: DerivedModel, values: Mapping[str, float], step_s: float, order: int) -> DiscreteSystem:
    """Phi, Gamma Q Gamma^T, H, R at one operating point (eqs. (10), (11))."""
    m = derived.numeric(model_values(derived, values))
    phi, gamma = taylor_discretization(m["F"], m["G"], step_s, order)
    qd = taylor_process_noise(gamma, m["Q"], step_s) if m["G"].shape[1] else np.zeros_like(phi)
    return DiscreteSystem(tuple(derived.model.state_names), phi, qd, m["H"], m["R"])


def propagate_covariance(system: DiscreteSystem, P0: np.ndarray, steps: int) -> np.ndarray:
    """P(k+1) = Phi P(k) Phi^T + Gamma Q Gamma^T (eq. (9)); history of shape (steps+1, n, n)."""
    phi, qd = system.transition, system.process_noise
    out = np.empty((steps + 1, *P0.shape))
    out[0] = P = P0
    for k in range(steps):
        P = phi @ P @ phi.T + qd
        out[k + 1] = P
    return out


def _joseph(P_pred: np.ndarray, K: np.ndarray, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(I - K H) P (I - K H)^T + K R K^T: correct for any gain K (eq. (12))."""
    A = np.eye(P_pred.shape[0]) - K @ H
    P = A @ P_pred @ A.T + K @ R @ K.T
    return 0.5 * (P + P.T)


def optimal_filter_covariance(system: DiscreteSystem, P0: np.ndarray, steps: int) -> np.ndarray:
    """P(k/k) of the Kalman filter of eq. (12); history of shape (steps+1, n, n), P(0/0) first."""
    _, history = filter_gains(system, P0, steps, np.ones(steps, dtype=bool))
    return history


def filter_gains(
    system: DiscreteSystem, P0: np.ndarray, steps: int, recompute: Sequence[bool]
) -> tuple[np.ndarray, np.ndarray]:
    """Gains K(k+1), k = 0..steps-1, and the filter's own P(k/k) history.

    ``recompute[k]`` says whether the gain for the update at step k+1 is
    computed afresh from P(k+1/k) (eqs. (13)-(14)) or the previous gain is
    held (piecewise-constant gain, section 5.2).  The filter's covariance is
    propagated every step in Joseph form, which is exact for the gain actually
    used, so each recomputed gain starts from the filter's honest P(jN/jN).
    """
    recompute = np.asarray(recompute, dtype=bool)
    if recompute.shape != (steps,) or (steps and not recompute[0]):
        raise ModelError(f"gain schedule must have {steps} entries and recompute at the first step")
    phi, qd, H, R = system.transition, system.process_noise, system.measurement, system.measurement_noise
    if H.shape[0] == 0:
        raise ModelError(f"model with states {system.state_names[:3]}...: has no measurements to filter")
    gains = np.empty((steps, system.n_states, H.shape[0]))
    history = np.empty((steps + 1, *P0.shape))
    history[0] = P = P0
    K = None
    for k in range(steps):
        P_pred = phi @ P @ phi.T + qd
        if recompute[k]:
            K = kalman_gain(P_pred, H, R)  # eq. (14)
        gains[k] = K
        P = _joseph(P_pred, K, H, R)
        history[k + 1] = P
    return gains, history


def selection_matrix(truth_states: Sequence[str], filter_states: Sequence[str]) -> np.ndarray:
    """S with (S x)_j = the truth state that filter state j estimates (same name)."""
    index = {name: i for i, name in enumerate(truth_states)}
    unknown = [s for s in filter_states if s not in index]
    if unknown:
        raise ModelError(f"filter state(s) {', '.join(unknown)} are not states of the truth model")
    S = np.zeros((len(filter_states), len(truth_states)))
    for j, name in enumerate(filter_states):
        S[j, index[name]] = 1.0
    return S


def true_error_covariance(
    truth: DiscreteSystem, filt: DiscreteSystem, P0: np.ndarray, gains: np.ndarray
) -> np.ndarray:
    """Covariance of the actual error of a filter run against the truth model.

    Joint vector y = [x; e], x the truth state (n), e = S x - x_hat the error
    of the filter's estimate (m states).  The filter predicts with its own Phi_f
    and updates with the given gains using the real measurement
    z = H x + v (true R):

        predict:  x' = Phi x + w,  e' = (S Phi - Phi_f S) x + Phi_f e + S w
        update:   e+ = (I - K H_f) e' - K (H - H_f S) x - K v

    Open-loop compensation (section 2): the truth errors are never reset, the
    output is corrected by the estimate, so the error of the compensated
    output is e for estimated states and x itself for states the filter does
    not carry (their estimate is zero).  Returned: that error's covariance in
    truth coordinates, shape (steps+1, n, n); x_hat(0) = 0, so e(0) = S x(0).
    """
    S = selection_matrix(truth.state_names, filt.state_names)
    n, m = truth.n_states, filt.n_states
    steps = gains.shape[0]
    phi, phi_f = truth.transition, filt.transition
    H, H_f, R = truth.measurement, filt.measurement, truth.measurement_noise
    if H.shape[0] != H_f.shape[0]:
        raise ModelError(f"truth has {H.shape[0]} measurements, filter {H_f.shape[0]}")

    A_pred = np.zeros((n + m, n + m))
    A_pred[:n, :n] = phi
    A_pred[n:, :n] = S @ phi - phi_f @ S
    A_pred[n:, n:] = phi_f
    L = np.vstack([np.eye(n), S])
    Q_joint = L @ truth.process_noise @ L.T
    H_gap = H - H_f @ S

    # E maps y to the error of the compensated output, in truth coordinates
    E = np.zeros((n, n + m))
    estimated = S.argmax(axis=1)
    E[np.arange(n), np.arange(n)] = 1.0
    E[estimated, estimated] = 0.0
    E[estimated, n + np.arange(m)] = 1.0

    Y = L @ P0 @ L.T
    out = np.empty((steps + 1, n, n))
    out[0] = E @ Y @ E.T
    A_upd = np.eye(n + m)
    for k in range(steps):
        Y = A_pred @ Y @ A_pred.T + Q_joint
        K = gains[k]
        A_upd[n:, :n] = -K @ H_gap
        A_upd[n:, n:] = np.eye(m) - K @ H_f
        B = np.zeros((n + m, K.shape[1]))
        B[n:] = -K
        Y = A_upd @ Y @ A_upd.T + B @ R @ B.T
        Y = 0.5 * (Y + Y.T)
        out[k + 1] = E @ Y @ E.T
    return out
