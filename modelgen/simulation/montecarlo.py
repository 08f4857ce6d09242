"""Monte Carlo: N independent simulated flights, ensemble statistics, NEES test.

Each run draws its own sensor errors and initial errors from a per-run
generator (``numpy.random.SeedSequence(seed).spawn(N)``), so results do not
depend on how runs are spread over processes.  Runs go to a
``ProcessPoolExecutor`` (two workers by default: the machine's two cores); each
worker builds the trajectory once and takes the derived model from the caller.

Consistency (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, 2001, §5.4): with e the estimation error and P the
filter covariance, the normalized estimation error squared e^T P^-1 e of a
consistent filter is chi-square with n degrees of freedom; the ensemble mean
over N runs, times N, is chi-square with N n.  At each time the mean NEES must
lie in the two-sided interval [chi2(a/2, Nn), chi2(1 - a/2, Nn)] / N; a
consistent filter leaves about 1 - a of the times inside, a mis-modelled one
falls out.
"""

from __future__ import annotations

import math
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.stats import chi2

from modelgen.derive.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.simulation.filters import ReferenceFilter
from modelgen.simulation.flight import fly_profile, profile_layout
from modelgen.simulation.scenario import FlightProfile
from modelgen.simulation.trajectory import generate_trajectory


@dataclass
class NeesTest:
    """Per-time ensemble NEES against its chi-square interval."""

    times: np.ndarray
    mean_nees: np.ndarray
    lower: float
    upper: float
    dimension: int
    runs: int
    confidence: float

    @property
    def fraction_inside(self) -> float:
        ok = np.isfinite(self.mean_nees)
        inside = (self.mean_nees[ok] >= self.lower) & (self.mean_nees[ok] <= self.upper)
        return float(inside.mean()) if ok.any() else math.nan

    def passed(self, minimum_fraction: float | None = None) -> bool:
        """At least ``minimum_fraction`` of the times inside (default: confidence - 0.1)."""
        minimum = self.confidence - 0.1 if minimum_fraction is None else minimum_fraction
        return self.fraction_inside >= minimum


@dataclass
class MonteCarloResult:
    """Ensemble of runs, stored every ``store_every`` filter cycles."""

    scenario: str
    mode: str
    state_names: list[str]
    times: np.ndarray  # (T,)
    errors: np.ndarray  # (runs, T, n): true error state minus estimate
    sigma: np.ndarray  # (runs, T, n): filter sqrt(diag P)
    nees: np.ndarray  # (runs, T)
    rejected: np.ndarray  # (runs,) gate rejections
    updates: np.ndarray  # (runs,)
    seconds: float = 0.0

    @property
    def runs(self) -> int:
        return self.errors.shape[0]

    def ensemble_rms(self) -> np.ndarray:
        """sqrt(mean over runs of error^2), (T, n)."""
        return np.sqrt(np.mean(self.errors**2, axis=0))

    def mean_sigma(self) -> np.ndarray:
        """Filter sigma averaged (in variance) over runs, (T, n)."""
        return np.sqrt(np.mean(self.sigma**2, axis=0))

    def nees_test(self, confidence: float = 0.95, start_time: float = 0.0) -> NeesTest:
        """The chi-square test of the module docstring, over times >= start_time."""
        keep = self.times >= start_time
        n, N = self.errors.shape[2], self.runs
        alpha = 1.0 - confidence
        lower = chi2.ppf(alpha / 2, N * n) / N
        upper = chi2.ppf(1 - alpha / 2, N * n) / N
        return NeesTest(self.times[keep], np.mean(self.nees[:, keep], axis=0), float(lower), float(upper), n, N,
                        confidence)


# -- workers ------------------------------------------------------------------------

_WORKER: dict = {}


def _prepare(profile: FlightProfile, derived: DerivedModel, truth_profile: FlightProfile | None = None) -> dict:
    """What every run of a worker shares: the trajectory and the error layout."""
    trajectory = generate_trajectory(profile.path, profile.imu_rate, 1.0 / profile.filter.period)
    layout = profile_layout(profile, derived, trajectory)
    return {"profile": profile, "truth_profile": truth_profile, "derived": derived, "trajectory": trajectory,
            "layout": layout}


def _init_worker(profile: FlightProfile, derived: DerivedModel, truth_profile: FlightProfile | None) -> None:
    _WORKER.clear()
    _WORKER.update(_prepare(profile, derived, truth_profile))


def _one_run(seed: np.random.SeedSequence, mode: str, store_every: int, context: dict | None = None) -> tuple:
    c = context if context is not None else _WORKER
    derived = c["derived"]
    result = fly_profile(c["profile"], derived, c["trajectory"], np.random.default_rng(seed),
                         lambda x, P: ReferenceFilter(derived, x, P), mode=mode, layout=c["layout"],
                         truth_profile=c["truth_profile"])
    rows = slice(None, None, store_every)
    return (result.times[rows], result.estimation_error[rows], result.sigma[rows], result.nees[rows],
            len(result.rejected), result.updates)


def run_monte_carlo(profile: FlightProfile, derived: DerivedModel, runs: int, seed: int = 0, mode: str | None = None,
                    workers: int = 2, store_every: int | None = None, progress: Callable[[int, int], None] | None = None,
                    truth_profile: FlightProfile | None = None) -> MonteCarloResult:
    """``runs`` independent flights of ``profile`` with the filter model ``derived`` (module docstring).

    ``truth_profile`` (same flight) draws the sensors from a different error
    budget than the filter assumes: a mis-modelled filter.
    """
    import time

    if runs < 1:
        raise ModelError(f"Monte Carlo: need at least one run, got {runs}")
    mode = mode or profile.filter.mode
    store_every = store_every or max(1, int(round(profile.aiding_period / profile.filter.period)))
    seeds = np.random.SeedSequence(seed).spawn(runs)
    start = time.perf_counter()
    outputs = []
    if workers <= 1:
        context = _prepare(profile, derived, truth_profile)
        for i, s in enumerate(seeds):
            outputs.append(_one_run(s, mode, store_every, context))
            if progress:
                progress(i + 1, runs)
    else:
        method = "fork" if "fork" in multiprocessing.get_all_start_methods() else None
        ctx = multiprocessing.get_context(method)
        with ProcessPoolExecutor(max_workers=min(workers, runs, os.cpu_count() or 1), mp_context=ctx,
                                 initializer=_init_worker, initargs=(profile, derived, truth_profile)) as pool:
            futures = [pool.submit(_one_run, s, mode, store_every) for s in seeds]
            for i, f in enumerate(futures):
                outputs.append(f.result())
                if progress:
                    progress(i + 1, runs)
    seconds = time.perf_counter() - start
    return MonteCarloResult(
        scenario=profile.name,
        mode=mode,
        state_names=list(derived.model.state_names),
        times=outputs[0][0],
        errors=np.stack([o[1] for o in outputs]),
        sigma=np.stack([o[2] for o in outputs]),
        nees=np.stack([o[3] for o in outputs]),
        rejected=np.array([o[4] for o in outputs]),
        updates=np.array([o[5] for o in outputs]),
        seconds=seconds,
    )
