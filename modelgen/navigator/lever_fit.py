"""Where the non-holonomic constraint holds: the lever arm from the IMU to it, fitted from GNSS-present data.

A car's wheels neither slide sideways nor leave the road: at the rear axle's
centre on the ground the body velocity has no lateral and no vertical
component.  The IMU sits at a lever arm from that point; with l the point's
position minus the IMU's (body axes x forward, y right, z down, the
``nhc.lever_arm_m`` convention) a rigid body gives v_point = v_imu + omega x l,
and the constraint v_point,y = v_point,z = 0 says the IMU itself moves with

    v_y = -(omega x l)_y = omega_x l_z - omega_z l_x
    v_z = -(omega x l)_z = omega_y l_x - omega_x l_y

(omega the body angular rate).  Flown with GNSS present everywhere and the
constraint effectively off, the filter's own body velocity at the IMU
(:func:`modelgen.navigator.tuning.record_innovations` of the NHC rows with no
lever arm and a sigma so large the updates do nothing) and the bias-corrected
gyro rate give these two rows at every covariance step: :func:`fit` solves
them for l by least squares, together per row with a term proportional to the
forward speed (a residual boresight misalignment: a yaw or pitch error dpsi
makes v_y about -dpsi u) and a constant, which would otherwise leak into l.

The innovations are correlated in time (10 Hz steps, a decorrelation time of
a few tenths of a second and more), so the ordinary least-squares standard
error is too small: :func:`fit` states the heteroscedasticity and
autocorrelation consistent (Newey-West, Bartlett kernel) standard error over
``lags`` steps instead, the OLS one beside it.  No outage is flown and no
outage error is computed here (issue 26: tuning only from innovations with
GNSS present).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the unknowns of :func:`fit`, in order: the lever arm, then per row the speed term and the constant
UNKNOWNS = ("l_x", "l_y", "l_z", "lateral_per_speed", "lateral_offset", "vertical_per_speed", "vertical_offset")
#: the unknowns' units
UNITS = ("m", "m", "m", "rad", "m/s", "rad", "m/s")


@dataclass(frozen=True)
class LeverArmFit:
    """The least-squares lever arm and nuisance terms, with their standard errors (see the module docstring)."""

    estimate: dict[str, float]
    standard_error: dict[str, float]  # Newey-West over ``lags`` steps
    ols_standard_error: dict[str, float]  # as if the steps were independent (stated, not used)
    lags: int
    samples: int
    residual_rms: dict[str, float]  # [m/s] per row, after the fit
    raw_rms: dict[str, float]  # [m/s] per row, of v_y and v_z themselves (the constraint at the IMU)

    @property
    def lever_arm(self) -> tuple[float, float, float]:
        """(l_x, l_y, l_z) [m]."""
        return self.estimate["l_x"], self.estimate["l_y"], self.estimate["l_z"]

    def significance(self, name: str) -> float:
        """|estimate| / Newey-West standard error of one unknown."""
        return abs(self.estimate[name]) / self.standard_error[name]


def design(rate: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """The stacked design matrix (2n, 7): rows v_y then v_z of n steps, columns :data:`UNKNOWNS`.

    ``rate``: (n, 3) body angular rate [rad/s]; ``speed``: (n,) forward speed [m/s].
    """
    rate, speed = np.asarray(rate, float), np.asarray(speed, float)
    n = len(speed)
    wx, wy, wz = rate[:, 0], rate[:, 1], rate[:, 2]
    zero, one = np.zeros(n), np.ones(n)
    lateral = np.column_stack([-wz, zero, wx, speed, one, zero, zero])
    vertical = np.column_stack([wy, -wx, zero, zero, zero, speed, one])
    return np.vstack([lateral, vertical])


def newey_west(A: np.ndarray, residual: np.ndarray, n: int, lags: int) -> np.ndarray:
    """The HAC covariance of the least-squares estimate of ``A`` x = y (A stacked as :func:`design`: two blocks of
    n rows, step k's two rows at k and n + k), Bartlett weights 1 - j / (lags + 1) over lags 1..``lags`` steps.

    The score of step k is the sum of its two rows' a_i e_i, so the two rows' correlation at one step is kept."""
    score = A[:n] * residual[:n, None] + A[n:] * residual[n:, None]
    meat = score.T @ score
    for j in range(1, min(lags, n - 1) + 1):
        gamma = score[j:].T @ score[:-j]
        meat += (1.0 - j / (lags + 1.0)) * (gamma + gamma.T)
    bread = np.linalg.inv(A.T @ A)
    return bread @ meat @ bread


def fit(v_body: np.ndarray, rate: np.ndarray, speed: np.ndarray, lags: int = 50) -> LeverArmFit:
    """The lever arm l (IMU to the constrained point) from the IMU's body velocity rows and the body rate.

    ``v_body``: (n, 2) the body lateral and vertical velocity at the IMU [m/s]; ``rate``: (n, 3) the bias-corrected
    body angular rate [rad/s]; ``speed``: (n,) the forward speed [m/s]; ``lags``: the Newey-West window in steps.
    """
    v_body = np.asarray(v_body, float)
    n = len(v_body)
    A = design(rate, speed)
    y = np.concatenate([v_body[:, 0], v_body[:, 1]])
    x, *_ = np.linalg.lstsq(A, y, rcond=None)
    residual = y - A @ x
    dof = max(1, len(y) - len(x))
    ols = np.linalg.inv(A.T @ A) * float(residual @ residual) / dof
    hac = newey_west(A, residual, n, lags)
    names = UNKNOWNS
    return LeverArmFit(
        estimate={k: float(v) for k, v in zip(names, x)},
        standard_error={k: float(np.sqrt(hac[i, i])) for i, k in enumerate(names)},
        ols_standard_error={k: float(np.sqrt(ols[i, i])) for i, k in enumerate(names)},
        lags=lags, samples=n,
        residual_rms={"lateral": float(np.sqrt(np.mean(residual[:n] ** 2))),
                      "vertical": float(np.sqrt(np.mean(residual[n:] ** 2)))},
        raw_rms={"lateral": float(np.sqrt(np.mean(v_body[:, 0] ** 2))),
                 "vertical": float(np.sqrt(np.mean(v_body[:, 1] ** 2)))})
