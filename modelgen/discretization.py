"""Continuous -> discrete: transition matrix Phi and process noise.

Two methods, so that each checks the other:

* the paper's truncated Taylor series (seed 000, eqs. (10)-(11)),
  Phi = sum_{k=0..N} (F T)^k / k!,  Gamma = T sum_{k=0..N} (F T)^k / (k+1)! G,
  with the discrete noise covariance Gamma (Q/T) Gamma^T.  Dividing the
  continuous power spectral density Q by T turns it into the covariance of the
  equivalent white sequence W(k) held over one step, so that
  Gamma Q_k Gamma^T ~ T G Q G^T to first order;
* the exact matrix exponential, with Van Loan's method for
  Q_d = int_0^T e^{F s} G Q G^T e^{F^T s} ds.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

DEFAULT_TAYLOR_ORDER = 9  # seed 000, eq. (10): terms up to F^9 T^9 / 9!


def taylor_discretization(F: np.ndarray, G: np.ndarray, T: float, order: int = DEFAULT_TAYLOR_ORDER) -> tuple[np.ndarray, np.ndarray]:
    """Phi and Gamma by the truncated series of eqs. (10) and (11)."""
    if order < 1:
        raise ValueError(f"Taylor order must be at least 1, got {order}")
    n = F.shape[0]
    FT = F * T
    term = np.eye(n)  # (F T)^k / k!
    phi = np.eye(n)
    gamma_sum = np.eye(n)  # sum (F T)^k / (k+1)!
    for k in range(1, order + 1):
        term = term @ FT / k
        phi = phi + term
        gamma_sum = gamma_sum + term / (k + 1)
    return phi, T * gamma_sum @ G


def taylor_process_noise(gamma: np.ndarray, Q: np.ndarray, T: float) -> np.ndarray:
    """Gamma (Q/T) Gamma^T: the discrete process noise of eq. (9)."""
    qd = gamma @ (Q / T) @ gamma.T
    return 0.5 * (qd + qd.T)


def van_loan_discretization(F: np.ndarray, G: np.ndarray, Q: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact Phi = e^{F T} and Q_d by Van Loan's block exponential (1978)."""
    n = F.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = -F
    block[:n, n:] = G @ Q @ G.T
    block[n:, n:] = F.T
    e = expm(block * T)
    phi = e[n:, n:].T
    qd = phi @ e[:n, n:]
    return phi, 0.5 * (qd + qd.T)
