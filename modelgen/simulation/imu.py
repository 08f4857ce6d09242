"""IMU errors drawn from an error budget and applied to ideal increments.

Per axis of the body (x forward, y right, z down), the measured rates are

    gyro:           omega~ = (1 + s_g) omega + eps_c + eps_r + n_g
    accelerometer:  f~     = (1 + s_a) f     + nabla_c + nabla_r + n_a

with eps_c, nabla_c random constants, eps_r, nabla_r first-order Markov
processes (the core paper eqs. (2)-(5): d eps_r/dt = -mu eps_r + w, E[w w] = 2 mu
sigma^2), n white noise and s optional scale-factor errors.  Every error here
is *measured minus true*; how a model's states relate to that (the core
paper's gyro drift enters its equations as +C eps, i.e. its eps is true minus
measured) is settled in :mod:`modelgen.simulation.error_layout`.

The Markov processes are sampled exactly at the IMU rate
(x_{k+1} = e^{-T/tau} x_k + sigma sqrt(1 - e^{-2T/tau}) n_k, started in steady
state) by a compiled first-order recursion (the arithmetic of
``scipy.signal.lfilter([1], [1, -a])``, bit for bit, without importing scipy's
signal package: 70 MB of resident memory), so a 4-hour 300 Hz record costs a
few hundred milliseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from modelgen.errors import ModelError
from modelgen.simulation.jit import compiled


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


@compiled
def _first_order_recursion(drive, a, previous, out):
    """out[k] = a out[k-1] + drive[k] per column, out[-1] = ``previous``; the last row returned.

    The same operations, in the same order, as ``lfilter([1.0], [1.0, -a])``
    (its state a y[k-1] plus 1.0 x[k]), so the results are identical bit for bit
    (tests/simulation/test_sensors.py compares them).
    """
    y = previous.copy()
    for k in range(drive.shape[0]):
        for j in range(drive.shape[1]):
            y[j] = a * y[j] + drive[k, j]
            out[k, j] = y[j]
    return y


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
    _first_order_recursion(drive, a, np.zeros(axes), drive)
    return drive


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


# -- streamed: the same realization, a piece at a time -------------------------------------------


@compiled
def _measured(ideal, scale, markov, constant, dt, out):
    """out = ideal (1 + scale) + (markov + constant) dt, row by row: :func:`corrupt_increments`' operations
    in its order (each product and sum rounded as numpy rounds it), in one pass instead of six over the piece."""
    for k in range(ideal.shape[0]):
        for j in range(3):
            out[k, j] = ideal[k, j] * (1.0 + scale[j]) + (markov[k, j] + constant[j]) * dt

_SKIP_ROWS = 1 << 16  # rows of normals drawn at a time when passing over a stream (1.5 MB)


def _fresh_generator(rng: np.random.Generator, state: dict) -> np.random.Generator:
    """A generator of ``rng``'s bit-generator type set to ``state`` (a saved position in its stream)."""
    generator = np.random.Generator(type(rng.bit_generator)())
    generator.bit_generator.state = state
    return generator


def _skip_normals(rng: np.random.Generator, rows: int) -> None:
    """Advance ``rng`` past ``rows`` rows of three standard normals, in bounded pieces."""
    while rows > 0:
        m = min(rows, _SKIP_ROWS)
        rng.standard_normal((m, 3))
        rows -= m


class _MarkovCursor:
    """The samples of one :func:`markov_sequence`, produced in order, a piece at a time.

    The drive is re-drawn from the saved generator position and filtered with
    the same recursion (carrying its last value), so the samples are bit
    for bit those of the whole sequence; one sample of look-ahead lets the
    error history be read at the first sample after a piece.
    """

    def __init__(self, rng: np.random.Generator, state: dict | None, scale: float, a: float, start: np.ndarray, n: int):
        self.generator = None if state is None else _fresh_generator(rng, state)
        self.scale, self.a, self.start, self.n = scale, a, start, n
        self.drawn = 0
        self.last = np.zeros(3)
        self.buffer = np.zeros((0, 3))

    def _fill(self, rows: int) -> None:
        while len(self.buffer) < rows and self.drawn < self.n:
            m = min(max(rows - len(self.buffer), 4096), self.n - self.drawn)
            if self.generator is None:
                values = np.zeros((m, 3))
            else:
                values = self.scale * self.generator.standard_normal((m, 3))
                if self.drawn == 0:
                    values[0] = self.start
                self.last = _first_order_recursion(values, self.a, self.last, values)
            self.drawn += m
            self.buffer = np.concatenate([self.buffer, values]) if len(self.buffer) else values

    def take(self, m: int) -> np.ndarray:
        """The next ``m`` samples (keeps one more ready, for :meth:`peek`)."""
        self._fill(m + 1)
        out, self.buffer = self.buffer[:m], self.buffer[m:]
        return out

    def peek(self) -> np.ndarray | None:
        """The next sample without taking it (None at the end of the sequence)."""
        self._fill(1)
        return self.buffer[0] if len(self.buffer) else None


class ImuErrorStream:
    """One realization of the IMU errors, as :func:`corrupt_increments` draws it, replayed piece by piece.

    Constructing it draws from ``rng`` exactly what :func:`corrupt_increments`
    draws (the long Markov drives and white noises are passed over in bounded
    pieces and their starting positions saved), so ``rng`` continues as after
    the whole-flight call.  :meth:`cursor` then replays the measured increments
    of consecutive pieces bit for bit, holding no more than a piece, and fills
    the error history (rows at record times, small) as it goes.
    """

    def __init__(self, budget: ImuErrorBudget, dt: float, n: int, record_every: int, rng: np.random.Generator):
        self.budget, self.dt, self.n, self.record_every, self.rng = budget, dt, n, record_every, rng
        self.gyro_constant = budget.gyro_constant_drift * rng.standard_normal(3)
        self.accel_constant = budget.accel_constant_bias * rng.standard_normal(3)
        self.gyro_scale = budget.gyro_scale_factor * rng.standard_normal(3)
        self.accel_scale = budget.accel_scale_factor * rng.standard_normal(3)
        self.markov = [self._pass_markov(budget.gyro_markov_drift, budget.gyro_markov_correlation_time),
                       self._pass_markov(budget.accel_markov_bias, budget.accel_markov_correlation_time)]
        self.white = [self._pass_white(budget.gyro_white_noise), self._pass_white(budget.accel_white_noise)]
        records = len(range(0, n + 1, record_every))
        self.history = ImuErrorHistory(self.gyro_constant, np.zeros((records, 3)), self.accel_constant,
                                       np.zeros((records, 3)), self.gyro_scale, self.accel_scale)
        # row 0 is read before the first piece (the run's record at t = 0): a Markov sequence starts at its start
        self.history.gyro_markov[0] = self.markov[0][3]
        self.history.accel_markov[0] = self.markov[1][3]

    def _pass_markov(self, sigma: float, correlation_time: float) -> tuple:
        """(saved position, drive scale, a, start) of a Markov sequence; ``rng`` passed over it."""
        if sigma == 0 or self.n == 0:
            return None, 0.0, 0.0, np.zeros(3)
        a = math.exp(-self.dt / correlation_time)
        state = self.rng.bit_generator.state
        _skip_normals(self.rng, self.n)
        start = sigma * self.rng.standard_normal(3)
        return state, sigma * math.sqrt(1.0 - a * a), a, start

    def _pass_white(self, sigma: float) -> tuple:
        """(saved position, sigma) of a white-noise record; ``rng`` passed over it."""
        if not sigma > 0:
            return None, 0.0
        state = self.rng.bit_generator.state
        _skip_normals(self.rng, self.n)
        return state, sigma

    def cursor(self) -> "ImuErrorCursor":
        """A fresh replay from the first sample."""
        return ImuErrorCursor(self)


class ImuErrorCursor:
    """Consecutive pieces of one :class:`ImuErrorStream` (see there)."""

    def __init__(self, stream: ImuErrorStream):
        self.stream = stream
        self.position = 0
        self.markov = [_MarkovCursor(stream.rng, state, scale, a, start, stream.n)
                       for state, scale, a, start in stream.markov]
        self.white = [None if state is None else (_fresh_generator(stream.rng, state), sigma)
                      for state, sigma in stream.white]

    def corrupt(self, delta_theta: np.ndarray, delta_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Measured increments of the next ``len(delta_theta)`` samples (ideal ones given); history rows filled."""
        s = self.stream
        m = len(delta_theta)
        start = self.position
        gyro_markov, accel_markov = self.markov[0].take(m), self.markov[1].take(m)
        self._record_history(start, m, gyro_markov, accel_markov)
        measured_theta, measured_velocity = np.empty((m, 3)), np.empty((m, 3))
        _measured(np.asarray(delta_theta, dtype=float), s.gyro_scale, gyro_markov, s.gyro_constant, s.dt, measured_theta)
        _measured(np.asarray(delta_velocity, dtype=float), s.accel_scale, accel_markov, s.accel_constant, s.dt,
                  measured_velocity)
        for measured, white in zip((measured_theta, measured_velocity), self.white):
            if white is not None:
                generator, sigma = white
                noise = generator.standard_normal((m, 3))
                noise *= sigma * math.sqrt(s.dt)
                measured += noise
        self.position += m
        return measured_theta, measured_velocity

    def _record_history(self, start: int, m: int, gyro_markov: np.ndarray, accel_markov: np.ndarray) -> None:
        """History rows whose sample (clipped to the last) lies in [start, start + m], the end by look-ahead."""
        s = self.stream
        every = s.record_every
        first = -(-start // every)
        for row in range(first, len(s.history.gyro_markov)):
            sample = min(row * every, s.n - 1)
            if sample < start + m:
                s.history.gyro_markov[row] = gyro_markov[sample - start]
                s.history.accel_markov[row] = accel_markov[sample - start]
            elif sample == start + m:
                for target, cursor in ((s.history.gyro_markov, self.markov[0]), (s.history.accel_markov, self.markov[1])):
                    ahead = cursor.peek()
                    target[row] = ahead if ahead is not None else 0.0
                break
            else:
                break
