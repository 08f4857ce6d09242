"""The numpy/scipy RTS backward pass the generated ones are held to (the test reference, not used by the replay).

The recursion of :mod:`modelgen.navigator.smoother` with the identity reset (s + sum of dx, P^s unchanged):
what every model the navigator flies (phi-angle attitude) has.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve


def smoothing_gain(P_posterior: np.ndarray, Phi_next: np.ndarray, P_prior_next: np.ndarray) -> np.ndarray:
    """A_k = P_k^+ Phi_{k+1}^T (P_{k+1}^-)^-1 through the Cholesky factor of P_{k+1}^- (symmetric)."""
    factor = cho_factor(P_prior_next, lower=True, check_finite=True)
    return cho_solve(factor, Phi_next @ P_posterior).T  # A^T = (P^-)^-1 Phi P^+ (P^-, P^+ symmetric)


class NumpyReference:
    """The reference as a backward pass (the interface of the generated ones: smooth, refer)."""

    name = "numpy reference"

    def smooth(self, arrays) -> tuple[np.ndarray, np.ndarray]:
        steps, n = arrays.P_post.shape[:2]
        error = np.zeros((steps, n))
        covariance = np.empty((steps, n, n))
        covariance[-1] = arrays.P_post[-1]
        for k in range(steps - 2, -1, -1):
            gain = smoothing_gain(arrays.P_post[k], arrays.Phi[k + 1], arrays.P_prior[k + 1])
            dx = arrays.corrections[arrays.start[k + 1]:arrays.start[k + 2]]
            before_corrections = error[k + 1] + (dx.sum(axis=0) if len(dx) else 0.0)
            error[k] = gain @ before_corrections
            P = arrays.P_post[k] + gain @ (covariance[k + 1] - arrays.P_prior[k + 1]) @ gain.T
            covariance[k] = 0.5 * (P + P.T)
        return error, covariance

    def refer(self, s, Ps, corrections) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(s, float) + np.sum(corrections, axis=0), np.array(Ps, float)
