"""The filter loop: a Kalman filter against a navigator, in the three correction modes.

Correction modes (the accumulated-correction paper §1; the core paper §2; the INS/GPS paper §3.2):

* ``open_loop`` -- output compensation: the INS runs free, the filter estimates
  its whole error x^ and the output is INS (-) x^.
* ``closed_loop`` -- feedback: after each update the estimated navigation
  errors and random-constant sensor errors are fed back into the mechanization
  (attitude, velocity, position, gyro/accelerometer compensation, Doppler
  compensation) and those filter states are reset to zero.  Markov states are
  not fed back (a fed-back Markov estimate would have to decay inside the
  mechanization); they stay in the filter.
* ``accumulated`` -- the accumulated-correction paper's accumulated-error correction: the INS and the
  sensors run free as in open loop, but the fed-back part of every estimate is
  added to an accumulator A and reset in the filter as in closed loop; A is
  carried between updates by the same transition matrix as the errors
  (A(k) = Phi A(k-1), which is the accumulated-correction paper's extrapolation of accumulated velocity
  corrections into position, eq. (10)), the sensor outputs are corrected by A
  before they enter the filter (eq. (3)) and the output is INS (-) A.  The
  theorem of the accumulated-correction paper: in the linear case this output equals the closed-loop
  output; ``tests/simulation`` checks it to numerical precision.

Faults: a measurement marked invalid (outage) skips the update; an innovation
whose normalized square nu^T S^-1 nu exceeds the chi-square quantile of the
gate probability is rejected and counted; a non-finite measurement is refused
(counted, the filter state untouched; the filters themselves raise ModelError).

The loop is written against two small protocols: a navigator (the system
whose errors are estimated, with its aiding sensor's measurement function:
:class:`~modelgen.simulation.ins_aiding.StrapdownNavigator` and
:class:`~modelgen.simulation.pseudorange.PseudorangeNavigator` for the
simulated flight, a linear error system in the tests) and a filter
(:mod:`modelgen.simulation.filters`).  It knows nothing of flights or sensors.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation.filters import KalmanFilter

MODES = ("open_loop", "closed_loop", "accumulated")


# -- protocols -------------------------------------------------------------------------


@dataclass(frozen=True)
class Measurement:
    """z (model measurement rows ``rows``) or, when ``valid`` is False, an outage."""

    z: np.ndarray
    rows: np.ndarray
    valid: bool = True


class Navigator(Protocol):
    """The system whose errors the filter estimates, with its aiding sensor."""

    def advance(self, cycle: int) -> None:
        """Run the system (the INS) on to filter cycle ``cycle``."""

    def output(self) -> np.ndarray:
        """Its own navigation output, uncorrected."""

    def correct_output(self, output: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """``output`` with the estimated errors ``dx`` (model states) removed."""

    def feedback(self, dx: np.ndarray) -> None:
        """Closed loop: correct the system itself by ``dx``."""

    def parameters(self, corrected_output: np.ndarray) -> dict[str, float]:
        """The model's parameters at the operating point of ``corrected_output``."""

    def measurement(self, cycle: int, corrected_output: np.ndarray, accumulated: np.ndarray) -> Measurement | None:
        """The aiding sensor's z at ``cycle`` (None between its epochs): its measurement function."""

    def estimation_error(self, cycle: int, corrected_output: np.ndarray, estimate: np.ndarray) -> np.ndarray:
        """True error state minus the estimate (model states)."""


@dataclass
class RunResult:
    """Records of one filtered run: one row per recorded cycle (row 0 = t = 0, before any step).

    Every cycle is recorded unless the run was asked to keep every
    ``record_every``-th (:func:`recorded_cycles`: those and the last); ``times``
    says which.  The counters cover every cycle whatever was recorded.
    """

    mode: str
    filter_name: str
    times: np.ndarray
    outputs: np.ndarray  # corrected navigation output
    raw_outputs: np.ndarray  # the navigator's own output (INS, before output correction)
    estimation_error: np.ndarray  # true error state minus estimate, model states
    sigma: np.ndarray  # sqrt(diag(P))
    nees: np.ndarray  # e^T P^-1 e (NaN where P is singular)
    updates: int = 0
    skipped: int = 0  # outage
    rejected: list[float] = field(default_factory=list)  # gate, times
    refused: list[float] = field(default_factory=list)  # non-finite, times
    innovations: list[tuple[float, float]] = field(default_factory=list)  # (time, normalized squared innovation)


@functools.lru_cache(maxsize=64)
def gate_threshold(probability: float, dimension: int) -> float:
    """chi-square quantile for the gate; infinity when gating is off (cached: asked every update)."""
    if probability <= 0:
        return math.inf
    # scipy.stats.chi2.ppf is 2 gammaincinv(k/2, p) (its _ppf); scipy.special alone costs 26 MB of
    # resident memory where scipy.stats costs 72 MB, which a streamed flight's budget notices
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(dimension / 2.0, probability))


def nees(error: np.ndarray, covariance: np.ndarray) -> float:
    """e^T P^-1 e, or NaN if P is singular (e.g. zero initial variances at t = 0)."""
    try:
        L = np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        return math.nan
    y = np.linalg.solve(L, error)
    return float(y @ y)


def recorded_cycles(n_cycles: int, record_every: int) -> np.ndarray:
    """The cycles a run records: every ``record_every``-th from 0, and always the last one."""
    cycles = np.arange(0, n_cycles + 1, record_every)
    return cycles if cycles[-1] == n_cycles else np.r_[cycles, n_cycles]


class FilterLoop:
    """The correction-mode loop (module docstring), one filter cycle per :meth:`step`.

    Stepping lets a driver run several loops in lockstep over one stream of
    sensor data (:mod:`modelgen.simulation.streaming`) and stop between
    pieces; :func:`run_filter` steps one loop through every cycle.  Histories
    are kept at the cycles :func:`recorded_cycles` names (``record_every``)
    and, if given, each recorded row also goes to ``sink(cycle, result, row)``
    (an incremental writer) as it is made.
    """

    def __init__(self, navigator: Navigator, kalman: KalmanFilter,
                 measurement_matrices: Callable[[dict], tuple[np.ndarray, np.ndarray]], mode: str, n_cycles: int,
                 period: float, fed_back: np.ndarray, gate_probability: float = 0.0, filter_name: str = "",
                 progress: Callable[[int, int], None] | None = None, propagate_accumulator: bool = True,
                 record_every: int = 1, sink: Callable[[int, "RunResult", int], None] | None = None):
        if mode not in MODES:
            raise ModelError(f"filter loop: unknown correction mode {mode!r} (choose from {', '.join(MODES)})")
        if record_every < 1:
            raise ModelError(f"filter loop: record_every must be a positive whole number, got {record_every}")
        self.navigator, self.kalman, self.measurement_matrices = navigator, kalman, measurement_matrices
        self.mode, self.n_cycles, self.period, self.fed_back = mode, n_cycles, period, fed_back
        self.gate_probability, self.progress, self.propagate_accumulator = gate_probability, progress, propagate_accumulator
        self.record_every, self.sink = record_every, sink
        n = len(kalman.state)
        self.accumulated = np.zeros(n)
        rows = len(recorded_cycles(n_cycles, record_every))
        first = navigator.output()
        self.result = RunResult(mode, filter_name, np.zeros(rows), np.zeros((rows, len(first))),
                                np.zeros((rows, len(first))), np.zeros((rows, n)), np.zeros((rows, n)),
                                np.full(rows, math.nan))
        self.row = 0
        self._record(0)

    def _total_estimate(self) -> np.ndarray:
        return self.accumulated + self.kalman.state

    def _record(self, k: int) -> None:
        navigator, result, row = self.navigator, self.result, self.row
        raw = navigator.output()
        estimate = self._total_estimate()
        corrected = navigator.correct_output(raw, estimate)
        error = navigator.estimation_error(k, corrected, estimate)
        P = self.kalman.covariance
        result.times[row] = k * self.period
        result.outputs[row] = corrected
        result.raw_outputs[row] = raw
        result.estimation_error[row] = error
        result.sigma[row] = np.sqrt(np.maximum(np.diag(P), 0.0))
        result.nees[row] = nees(error, P)
        if self.sink is not None:
            self.sink(k, result, row)
        self.row += 1

    def step(self, k: int) -> None:
        """Filter cycle ``k`` (1, 2, ... n_cycles, in order): advance, predict, update, correct, record."""
        navigator, kalman, result, mode = self.navigator, self.kalman, self.result, self.mode
        navigator.advance(k)
        raw = navigator.output()
        parameters = navigator.parameters(navigator.correct_output(raw, self._total_estimate()))
        phi, qd = kalman.transition(parameters, self.period)
        kalman.predict(phi, qd)
        if mode == "accumulated" and self.propagate_accumulator:
            self.accumulated = phi @ self.accumulated
        accumulated = self.accumulated
        corrected_for_filter = navigator.correct_output(raw, accumulated) if mode == "accumulated" else raw
        measurement = navigator.measurement(k, corrected_for_filter, accumulated)
        if measurement is not None:
            t = k * self.period
            if not measurement.valid:
                result.skipped += 1
            elif not np.all(np.isfinite(measurement.z)):
                result.refused.append(t)
            else:
                H_all, R_all = self.measurement_matrices(parameters)
                rows = measurement.rows
                H, R = H_all[rows], R_all[np.ix_(rows, rows)]
                x, P = kalman.state, kalman.covariance
                innovation = measurement.z - H @ x
                S = H @ P @ H.T + R
                d2 = float(innovation @ np.linalg.solve(S, innovation))
                result.innovations.append((t, d2))
                if d2 > gate_threshold(self.gate_probability, len(rows)):
                    result.rejected.append(t)
                else:
                    try:
                        kalman.update(measurement.z, H, R)
                    except ModelError:
                        result.refused.append(t)
                    else:
                        result.updates += 1
                        if mode != "open_loop":
                            dx = np.where(self.fed_back, kalman.state, 0.0)
                            if mode == "closed_loop":
                                navigator.feedback(dx)
                            else:
                                self.accumulated = accumulated + dx
                            kalman.set_state(kalman.state - dx)
        if k % self.record_every == 0 or k == self.n_cycles:
            self._record(k)
        if self.progress is not None:
            self.progress(k, self.n_cycles)


    @property
    def recorded(self) -> int:
        """Rows of ``result`` recorded so far."""
        return self.row

    def run(self, first: int, last: int) -> None:
        """Filter cycles ``first``..``last`` in order (a piece of the flight)."""
        for k in range(first, last + 1):
            self.step(k)


def run_filter(navigator: Navigator, kalman: KalmanFilter, measurement_matrices: Callable[[dict], tuple[np.ndarray, np.ndarray]],
               mode: str, n_cycles: int, period: float, fed_back: np.ndarray, gate_probability: float = 0.0,
               filter_name: str = "", progress: Callable[[int, int], None] | None = None,
               propagate_accumulator: bool = True, record_every: int = 1) -> RunResult:
    """The correction-mode loop (module docstring) over ``n_cycles`` filter cycles.

    ``propagate_accumulator=False`` holds the accumulator constant between
    updates instead of carrying it by Phi -- the naive accumulation that seed
    003 warns against (section 2, after the proof); only for demonstrating
    that the extrapolation is needed.  ``record_every``: keep the histories
    every that many cycles (and at the last one).
    """
    loop = FilterLoop(navigator, kalman, measurement_matrices, mode, n_cycles, period, fed_back, gate_probability,
                      filter_name, progress, propagate_accumulator, record_every)
    for k in range(1, n_cycles + 1):
        loop.step(k)
    return loop.result
