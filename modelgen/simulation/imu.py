"""IMU errors drawn from an error budget and applied to ideal increments.

Per axis of the body (x forward, y right, z down), the measured rates are

    gyro:           omega~ = (1 + s_g) omega + eps_c + eps_r + n_g
    accelerometer:  f~     = (1 + s_a) f     + nabla_c + nabla_r + n_a

with eps_c, nabla_c random constants, eps_r, nabla_r first-order Markov
processes (seed 000 eqs. (2)-(5): d eps_r/dt = -mu eps_r + w, E[w w] = 2 mu
sigma^2), n white noise and s optional scale-factor errors.  Every error here
is *measured minus true*; how a model's states relate to that (the core
paper's gyro drift enters its equations as +C eps, i.e. its eps is true minus
measured) is settled in :mod:`modelgen.simulation.error_layout`.

The Markov processes are sampled exactly at the IMU rate
(x_{k+1} = e^{-T/tau} x_k + sigma sqrt(1 - e^{-2T/tau}) n_k, started in steady
state) by a vectorized first-order recursion (scipy.signal.lfilter), so a
4-hour 300 Hz record costs a few hundred milliseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from modelgen.errors import ModelError


@dataclass(frozen=True)
class ImuErrorBudget:
    """rms values per axis, SI units (rad/s, m/s^2, s; white noise per sqrt(s))."""

    gyro_constant_drift: float = 0.0
    gyro_markov_drift: float = 0.0
    gyro_markov_correlation_time: float = math.inf
    gyro_white_noise: float = 0.0  # angle random walk [rad/sqrt(s)]
    gyro_scale_factor: float = 0.0
    accel_constant_bias: float = 0.0
    accel_markov_bias: float = 0.0
    accel_markov_correlation_time: float = math.inf
    accel_white_noise: float = 0.0  # velocity random walk [m/s/sqrt(s)]
    accel_scale_factor: float = 0.0

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (value >= 0) or (math.isinf(value) and "correlation" not in name):
                raise ModelError(f"IMU error budget: {name} must be a finite non-negative number, got {value!r}")
        for kind in ("gyro", "accel"):
            if getattr(self, f"{kind}_markov_{'drift' if kind == 'gyro' else 'bias'}") > 0 and not (
                0 < getattr(self, f"{kind}_markov_correlation_time") < math.inf
            ):
                raise ModelError(f"IMU error budget: a {kind} Markov process needs a finite positive correlation time")


@dataclass(frozen=True)
class ImuErrorHistory:
    """One realization of the IMU errors (measured minus true), at record times.

    Arrays are (n_records, 3) except the constants and scale factors (3,).
    """

    gyro_constant: np.ndarray
    gyro_markov: np.ndarray
    accel_constant: np.ndarray
    accel_markov: np.ndarray
    gyro_scale_factor: np.ndarray
    accel_scale_factor: np.ndarray


def markov_sequence(n: int, sigma: float, correlation_time: float, dt: float, rng: np.random.Generator,
                    axes: int = 3) -> np.ndarray:
    """Exact samples of a stationary first-order Markov process, shape (n, axes)."""
    if sigma == 0 or n == 0:
        return np.zeros((n, axes))
    a = math.exp(-dt / correlation_time)
    drive = sigma * math.sqrt(1.0 - a * a) * rng.standard_normal((n, axes))
    start = sigma * rng.standard_normal(axes)
    drive[0] = start
    # x_k = a x_{k-1} + drive_k, x_0 = start
    return lfilter([1.0], [1.0, -a], drive, axis=0)


def corrupt_increments(delta_theta: np.ndarray, delta_velocity: np.ndarray, dt: float, budget: ImuErrorBudget,
                       rng: np.random.Generator, record_every: int) -> tuple[np.ndarray, np.ndarray, ImuErrorHistory]:
    """Measured increments and the error history sampled every ``record_every`` samples.

    The error over a sample interval is the error rate at the interval's start
    times dt (the Markov processes change by ~dt/tau per sample, 1e-6 here).
    """
    n = delta_theta.shape[0]
    gyro_constant = budget.gyro_constant_drift * rng.standard_normal(3)
    accel_constant = budget.accel_constant_bias * rng.standard_normal(3)
    gyro_scale = budget.gyro_scale_factor * rng.standard_normal(3)
    accel_scale = budget.accel_scale_factor * rng.standard_normal(3)
    gyro_markov = markov_sequence(n, budget.gyro_markov_drift, budget.gyro_markov_correlation_time, dt, rng)
    accel_markov = markov_sequence(n, budget.accel_markov_bias, budget.accel_markov_correlation_time, dt, rng)

    rows = np.arange(0, n + 1, record_every)
    last = np.minimum(rows, n - 1)  # the error rate at the final record time is the last sample's
    history = ImuErrorHistory(
        gyro_constant=gyro_constant,
        gyro_markov=gyro_markov[last] if n else np.zeros((len(rows), 3)),
        accel_constant=accel_constant,
        accel_markov=accel_markov[last] if n else np.zeros((len(rows), 3)),
        gyro_scale_factor=gyro_scale,
        accel_scale_factor=accel_scale,
    )
    # in place where the arrays are no longer needed: a 4-h, 300 Hz flight has
    # 100 MB per (n, 3) array, and the result is bit for bit the plain formula
    # delta (1 + k) + (markov + constant) dt + sigma sqrt(dt) noise
    measured_theta = delta_theta * (1.0 + gyro_scale)
    gyro_markov += gyro_constant
    gyro_markov *= dt
    measured_theta += gyro_markov
    del gyro_markov
    measured_velocity = delta_velocity * (1.0 + accel_scale)
    accel_markov += accel_constant
    accel_markov *= dt
    measured_velocity += accel_markov
    del accel_markov
    for measured, sigma in ((measured_theta, budget.gyro_white_noise), (measured_velocity, budget.accel_white_noise)):
        if sigma > 0:
            noise = rng.standard_normal((n, 3))
            noise *= sigma * math.sqrt(dt)
            measured += noise
            del noise
    return measured_theta, measured_velocity, history
