"""The numerical reference: a plain, dense numpy Kalman filter.

Generated Python and C are checked against this module.  It is written for
clarity, not speed, and shares no code with the code generator.
"""

from __future__ import annotations

import numpy as np


def predict_covariance(P: np.ndarray, phi: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """P(k+1/k) = Phi P(k/k) Phi^T + Gamma Q Gamma^T (the core paper, eq. (12))."""
    return phi @ P @ phi.T + qd


def kalman_gain(P: np.ndarray, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """K = P H^T (H P H^T + R)^-1 (eq. (12))."""
    S = H @ P @ H.T + R
    return np.linalg.solve(S, H @ P).T


def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """State and Joseph-form covariance update (eq. (12))."""
    K = kalman_gain(P, H, R)
    x_new = x + K @ (z - H @ x)
    A = np.eye(P.shape[0]) - K @ H
    P_new = A @ P @ A.T + K @ R @ K.T
    return x_new, P_new
