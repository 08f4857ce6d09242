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
``predict``), and the backward recursion itself is the model's generated code
(:mod:`modelgen.codegen.smoother`): the generated Python module's ``smooth``
and ``smooth_refer`` (:class:`GeneratedPython`) or the generated C's
``<model>_smooth`` and ``<model>_smooth_refer`` in the compiled navigator library
(:class:`modelgen.navigator.cnav.GeneratedC`), on the forward record of the
navigator that flew: the Python's :class:`ForwardRecord`, or the C navigator's
(``<model>_navigator_set_record``: caller-provided buffers sized from the log and
the configuration, :func:`modelgen.navigator.cnav.fly_c` with ``record=True``).  The reset of a correction
is the model's derived one (the identity for the phi-angle attitude the
navigator flies, I + [dtheta x]/2 for a rotation vector).  A numpy version of
the recursion is kept in the tests as the reference the generated code is held to.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

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


class GeneratedPython:
    """The generated Python module's backward pass (``smooth``, ``smooth_refer`` of the model's filter module)."""

    def __init__(self, module):
        self.module = module
        self.name = f"generated Python ({module.MODEL}.smooth)"

    def smooth(self, arrays: "RecordArrays") -> tuple[np.ndarray, np.ndarray]:
        try:
            return self.module.smooth(arrays.Phi, arrays.P_prior, arrays.P_post, arrays.corrections, arrays.start)
        except ValueError as exc:
            raise ModelError(f"smoother: the generated backward pass refused the forward record ({exc})") from None

    def refer(self, s: np.ndarray, Ps: np.ndarray, corrections: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        try:
            return self.module.smooth_refer(s, Ps, corrections)
        except ValueError as exc:
            raise ModelError(f"smoother: the generated backward pass refused a correction ({exc})") from None


@dataclass
class RecordArrays:
    """A forward record as the generated backward pass takes it: per step Phi, P^-, P^+; the corrections, CSR."""

    Phi: np.ndarray  # (steps, n, n); Phi[0] (the alignment's) is zero, never read
    P_prior: np.ndarray
    P_post: np.ndarray
    corrections: np.ndarray  # (M, n), in the order they were fed back
    start: np.ndarray  # (steps + 1,): step k's corrections are rows start[k] .. start[k + 1] - 1


def record_arrays(record: ForwardRecord) -> RecordArrays:
    """The record's lists as contiguous arrays (what the generated Python and C backward passes read)."""
    if record.steps == 0:
        raise ModelError("smoother: the forward record is empty (the forward pass was not recorded)")
    n = len(record.priors[0])
    Phi = np.zeros((record.steps, n, n))
    for k, transition in enumerate(record.transitions):
        if transition is not None:
            Phi[k] = transition
    counts = [len(c) for c in record.corrections]
    corrections = np.array([dx for step in record.corrections for dx in step], float).reshape(-1, n)
    return RecordArrays(Phi, np.array(record.priors, float), np.array(record.posteriors, float), corrections,
                        np.concatenate([[0], np.cumsum(counts)]).astype(np.int64))


def backward_pass(record: ForwardRecord, backward) -> SmoothedSteps:
    """The RTS recursion of the module docstring over every recorded step, last to first, by generated code.

    ``backward``: :class:`GeneratedPython` or :class:`modelgen.navigator.cnav.GeneratedC`.
    """
    error, covariance = backward.smooth(record_arrays(record))
    return SmoothedSteps(np.asarray(error, float), np.asarray(covariance, float))


def smoothed_at_output(record: ForwardRecord, steps: SmoothedSteps, snapshot: OutputSnapshot,
                       backward) -> tuple[np.ndarray, np.ndarray]:
    """s and P^s referred to the output's own nominal: back through the corrections made at its step after it."""
    later = record.corrections[snapshot.step][snapshot.corrections_before:]
    if not later:
        return steps.error[snapshot.step], steps.covariance[snapshot.step]
    return backward.refer(steps.error[snapshot.step], steps.covariance[snapshot.step], later)


def smoothed_nominals(record: ForwardRecord, backward,
                      steps: SmoothedSteps | None = None) -> list[tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]]:
    """Per output epoch: the smoothed navigation vector, sensor estimates, and P^s (the feedback applied to a copy)."""
    steps = backward_pass(record, backward) if steps is None else steps
    result = []
    for snapshot in record.outputs:
        nav = snapshot.nav.copy()
        sensors = {k: v.copy() for k, v in snapshot.sensors.items()}
        s, Ps = smoothed_at_output(record, steps, snapshot, backward)
        record.feedback(nav, sensors, s)
        result.append((nav, sensors, Ps))
    return result


def smoothed_outputs(record: ForwardRecord, backward, steps: SmoothedSteps | None = None) -> np.ndarray:
    """The output rows of the smoothed trajectory (same epochs and columns as the forward outputs)."""
    rows = [snapshot.row(nav, sensors, P)
            for snapshot, (nav, sensors, P) in zip(record.outputs, smoothed_nominals(record, backward, steps))]
    return np.array(rows, float)


def smooth_flight(flight, backward, steps: SmoothedSteps | None = None):
    """The flight with its outputs replaced by the smoothed ones (a flight flown with a ``record``).

    ``backward``: the generated backward pass to run (:class:`GeneratedPython`, or the C's
    :class:`modelgen.navigator.cnav.GeneratedC`); ``steps``: its result, if it was run already.
    """
    record = getattr(flight, "forward_record", None)
    if record is None or record.feedback is None:
        raise ModelError("smoother: the flight was flown without its forward record (fly(..., record=ForwardRecord()) "
                         "or fly_c(..., record=True))")
    outputs = smoothed_outputs(record, backward, steps)
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
                      target_outage_max_m: float | None = None, backward_name: str | None = None,
                      backward_seconds: float | None = None) -> dict[str, object]:
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
        "method": "fixed-interval Rauch-Tung-Striebel smoother in error-state form over the reported navigator's "
                  "recorded forward pass (the generated filter's transitions and covariances; the model's generated "
                  "backward pass)",
        "backward_pass": backward_name,
        "backward_pass_s": backward_seconds,
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
