"""Fixed-interval Rauch-Tung-Striebel smoothing of a closed-loop error-state flight (``modelgen replay --smooth``).

The forward pass (:func:`modelgen.navigator.navigator.fly` given a fresh
``record=ForwardRecord()``) appends to the :class:`ForwardRecord`: at every covariance step k the transition
Phi_k (the generated ``discretize`` of the model, from step k-1 to k) and the
prior covariance P_k^- (after the generated ``predict``); at every accepted
update the correction dx fed back into the nominal state and the posterior
P_k^+; at every output epoch a copy of the nominal state and a function that
turns a (corrected) nominal state and a covariance into an output row.

The backward pass, in error-state form
--------------------------------------
Let e be the error of the nominal state in the filter's convention: the
feedback ``apply(nominal, dx)`` removes an error dx, so the error of the
corrected nominal is e - dx.  With the closed-loop reset the forward posterior
mean of e_k, relative to the nominal after the step's corrections, is zero,
and the prior mean of e_{k+1}, relative to the nominal the mechanization
propagates from it, is zero too.  The textbook RTS recursion on that error
state, written relative to those nominals, is

    A_k       = P_k^+ Phi_{k+1}^T (P_{k+1}^-)^-1
    s_k       = A_k (s_{k+1} + sum of the corrections dx applied at k+1)
    P^s_k     = P_k^+ + A_k (P^s_{k+1} - P_{k+1}^-) A_k^T

with s_N = 0 and P^s_N = P_N^+ at the last step: s_{k+1} is the smoothed
error relative to the nominal after the corrections at k+1, and adding those
corrections refers it back to the nominal before them, which is the one the
prior (and so A_k) is about.  The smoothed nominal at an output is
``apply(stored nominal, s)``, with ``s`` referred to that output's nominal in
the same way (plus the corrections made at its step after it).

This is exact for additive error states (velocity, position, biases, scale
factors, lever arm: a correction only shifts them, the reset Jacobian is the
identity) and first order for the phi-angle attitude error (the reset of a
small rotation phi has the Jacobian I - [phi x]/2 = I to first order, the
approximation the error-state filter itself makes).  Several corrections at
one step (a ZUPT or NHC row and a GNSS update at the same IMU sample) add in
the same first-order sense.

What is generated and what is not: the transitions and covariances the
backward pass runs on are those of the generated filter (its ``discretize`` and
``predict``); the backward recursion itself is written here with numpy and
scipy (Cholesky factor of P_{k+1}^- and ``cho_solve``), not generated.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from modelgen.errors import ModelError

#: feedback(nav, sensors, dx): correct a nominal state (navigation vector and sensor estimates) by dx, in place
Feedback = Callable[[np.ndarray, dict, np.ndarray], None]
#: row(nav, sensors, P): one output row from a nominal state and an error covariance
Row = Callable[[np.ndarray, dict, np.ndarray], list]


@dataclass
class OutputSnapshot:
    """The nominal state at one output epoch and how it becomes an output row."""

    step: int  # the covariance step the output was written at
    corrections_before: int  # how many of that step's corrections had been fed back when it was written
    nav: np.ndarray
    sensors: dict[str, np.ndarray]
    row: Row


@dataclass
class ForwardRecord:
    """What the forward pass stores for the smoother (appended to by the navigator's hooks).

    Step 0 is the alignment (prior P0, no transition); every predict opens a
    new step.
    """

    feedback: Feedback | None = None  # set by start(): the navigator's closed-loop feedback
    transitions: list[np.ndarray | None] = field(default_factory=list)
    priors: list[np.ndarray] = field(default_factory=list)
    posteriors: list[np.ndarray] = field(default_factory=list)
    corrections: list[list[np.ndarray]] = field(default_factory=list)
    outputs: list[OutputSnapshot] = field(default_factory=list)

    def start(self, P0: np.ndarray, feedback: Feedback) -> None:
        """Step 0: the initial covariance, before any predict or update, and how a correction is applied."""
        if self.priors:
            raise ModelError("smoother: a forward record holds one flight (this one was already started)")
        self.feedback = feedback
        self._open(None, P0)

    def predicted(self, Phi: np.ndarray, P_prior: np.ndarray) -> None:
        """A covariance step: its transition from the previous step and its prior covariance."""
        self._open(np.array(Phi, float), P_prior)

    def corrected(self, dx: np.ndarray, P_posterior: np.ndarray) -> None:
        """An accepted update at the current step: the correction fed back and the covariance after it."""
        self.corrections[-1].append(np.array(dx, float))
        self.posteriors[-1] = np.array(P_posterior, float)

    def output(self, nav: np.ndarray, sensors: dict[str, np.ndarray], row: Row) -> None:
        """An output epoch at the current step: a copy of the nominal state and its row function."""
        self.outputs.append(OutputSnapshot(len(self.priors) - 1, len(self.corrections[-1]), np.array(nav, float),
                                           {k: np.array(v, float) for k, v in sensors.items()}, row))

    def _open(self, Phi: np.ndarray | None, P: np.ndarray) -> None:
        P = np.array(P, float)
        self.transitions.append(Phi)
        self.priors.append(P)
        self.posteriors.append(P)
        self.corrections.append([])

    @property
    def steps(self) -> int:
        """Number of covariance steps recorded (alignment included)."""
        return len(self.priors)


@dataclass
class SmoothedSteps:
    """Per step: the smoothed error s_k (relative to the nominal after the step's corrections) and P^s_k."""

    error: np.ndarray  # (steps, n)
    covariance: np.ndarray  # (steps, n, n)


def smoothing_gain(P_posterior: np.ndarray, Phi_next: np.ndarray, P_prior_next: np.ndarray) -> np.ndarray:
    """A_k = P_k^+ Phi_{k+1}^T (P_{k+1}^-)^-1 through the Cholesky factor of P_{k+1}^- (symmetric)."""
    try:
        factor = cho_factor(P_prior_next, lower=True, check_finite=True)
    except np.linalg.LinAlgError:
        raise ModelError("smoother: a prior covariance of the forward pass is not positive definite") from None
    # A^T = (P^-)^-1 Phi P^+ because P^- and P^+ are symmetric
    return cho_solve(factor, Phi_next @ P_posterior).T


def backward_pass(record: ForwardRecord) -> SmoothedSteps:
    """The RTS recursion of the module docstring over every recorded step, last to first."""
    n_steps = record.steps
    if n_steps == 0:
        raise ModelError("smoother: the forward record is empty (the forward pass was not recorded)")
    n = len(record.priors[0])
    error = np.zeros((n_steps, n))
    covariance = np.empty((n_steps, n, n))
    covariance[-1] = record.posteriors[-1]
    for k in range(n_steps - 2, -1, -1):
        gain = smoothing_gain(record.posteriors[k], record.transitions[k + 1], record.priors[k + 1])
        before_corrections = error[k + 1] + _total(record.corrections[k + 1], n)
        error[k] = gain @ before_corrections
        P = record.posteriors[k] + gain @ (covariance[k + 1] - record.priors[k + 1]) @ gain.T
        covariance[k] = 0.5 * (P + P.T)
    return SmoothedSteps(error, covariance)


def _total(corrections: list[np.ndarray], n: int) -> np.ndarray:
    """The sum of a step's corrections (first order: the reset Jacobian is the identity)."""
    return np.sum(corrections, axis=0) if corrections else np.zeros(n)


def smoothed_error_at_output(record: ForwardRecord, steps: SmoothedSteps, snapshot: OutputSnapshot) -> np.ndarray:
    """s referred to the output's own nominal: plus the corrections made at its step after it was written."""
    later = record.corrections[snapshot.step][snapshot.corrections_before:]
    return steps.error[snapshot.step] + _total(later, steps.error.shape[1])


def smoothed_nominals(record: ForwardRecord,
                      steps: SmoothedSteps | None = None) -> list[tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]]:
    """Per output epoch: the smoothed navigation vector, sensor estimates, and P^s (the feedback applied to a copy)."""
    steps = backward_pass(record) if steps is None else steps
    result = []
    for snapshot in record.outputs:
        nav = snapshot.nav.copy()
        sensors = {k: v.copy() for k, v in snapshot.sensors.items()}
        record.feedback(nav, sensors, smoothed_error_at_output(record, steps, snapshot))
        result.append((nav, sensors, steps.covariance[snapshot.step]))
    return result


def smoothed_outputs(record: ForwardRecord) -> np.ndarray:
    """The output rows of the smoothed trajectory (same epochs and columns as the forward outputs)."""
    rows = [snapshot.row(nav, sensors, P)
            for snapshot, (nav, sensors, P) in zip(record.outputs, smoothed_nominals(record))]
    return np.array(rows, float)


def smooth_flight(flight):
    """The flight with its outputs replaced by the smoothed ones (a flight flown with a ``record``)."""
    record = getattr(flight, "forward_record", None)
    if record is None or record.feedback is None:
        raise ModelError("smoother: the flight was flown without its forward record (fly(..., record=ForwardRecord()))")
    outputs = smoothed_outputs(record)
    if outputs.shape != flight.outputs.shape:
        raise ModelError("smoother: the forward record does not match the flight's outputs")
    return replace(flight, outputs=outputs, forward_record=None)


def _outage_mask(times: np.ndarray, outages: list[tuple[float, float]]) -> np.ndarray:
    """Output epochs inside any outage window (start inclusive, end exclusive, as the outage records count)."""
    inside = np.zeros(len(times), bool)
    for start, end in outages:
        inside |= (times >= start) & (times < end)
    return inside


def _pass_numbers(flight, errors, reference) -> dict[str, object]:
    """End-of-outage RMS, RMS over every outage epoch, RMS outside, and per-outage end and maximum [m]."""
    from modelgen.navigator.metrics import outage_records

    records = outage_records(flight, errors, reference)
    horizontal = errors.horizontal
    inside = _outage_mask(errors.time, flight.outages)
    ends = np.array([r["horizontal_error_end_m"] for r in records])
    nees = np.array([errors.nees_horizontal(i) for i in np.nonzero(inside)[0]])
    nees = nees[np.isfinite(nees)]
    return {"nees_horizontal_outage_mean": float(nees.mean()) if len(nees) else None,
            "horizontal_error_end_rms_m": float(np.sqrt(np.mean(ends**2))) if len(ends) else None,
            "horizontal_error_outage_rms_m": float(np.sqrt(np.mean(horizontal[inside] ** 2))) if inside.any() else None,
            "horizontal_error_outage_max_m": float(horizontal[inside].max()) if inside.any() else None,
            "horizontal_rms_outside_outages_m": float(np.sqrt(np.mean(horizontal[~inside] ** 2)))
            if (~inside).any() else None,
            "outages": records}


def smoothing_summary(forward, smoothed, reference, target_outage_rms_m: float | None = None,
                      target_outage_max_m: float | None = None) -> dict[str, object]:
    """summary.json's ``smoothed``: the forward pass the smoother ran on beside the smoothed trajectory.

    ``forward`` and ``smoothed`` are flights with the same epochs; errors are
    measured as for the forward report (:func:`modelgen.navigator.metrics.errors_against_reference`).
    """
    from modelgen.navigator.metrics import errors_against_reference

    numbers = {name: _pass_numbers(flight, errors_against_reference(flight, reference), reference)
               for name, flight in (("forward", forward), ("smoothed", smoothed))}
    per_outage = [{"start_s": f["start_s"], "duration_s": f["duration_s"],
                   "forward_horizontal_error_end_m": f["horizontal_error_end_m"],
                   "smoothed_horizontal_error_end_m": s["horizontal_error_end_m"],
                   "forward_horizontal_error_max_m": f["horizontal_error_max_m"],
                   "smoothed_horizontal_error_max_m": s["horizontal_error_max_m"],
                   "forward_sigma_horizontal_end_m": f["sigma_horizontal_end_m"],
                   "smoothed_sigma_horizontal_end_m": s["sigma_horizontal_end_m"]}
                  for f, s in zip(numbers["forward"]["outages"], numbers["smoothed"]["outages"])]
    rms = numbers["smoothed"]["horizontal_error_outage_rms_m"]
    worst = max((o["smoothed_horizontal_error_max_m"] for o in per_outage), default=None)
    return {
        "method": "fixed-interval Rauch-Tung-Striebel smoother in error-state form over the recorded forward pass "
                  "(the generated filter's transitions and covariances; backward recursion in numpy/scipy)",
        "steps": forward.forward_record.steps if getattr(forward, "forward_record", None) is not None else None,
        "forward": {k: v for k, v in numbers["forward"].items() if k != "outages"},
        "smoothed": {k: v for k, v in numbers["smoothed"].items() if k != "outages"},
        "outages": per_outage,
        "target_outage_rms_m": target_outage_rms_m,
        "target_outage_max_m": target_outage_max_m,
        "outage_rms_met": (rms is not None and rms <= target_outage_rms_m) if target_outage_rms_m is not None else None,
        "outage_max_met": ((worst is not None and worst <= target_outage_max_m)
                           if target_outage_max_m is not None else None),
        "outages_over_max": [i + 1 for i, o in enumerate(per_outage)
                             if target_outage_max_m is not None and o["smoothed_horizontal_error_max_m"] > target_outage_max_m],
    }
