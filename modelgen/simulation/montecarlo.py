"""Monte Carlo: N independent simulated flights, ensemble statistics, NEES test.

Each run draws its own sensor errors and initial errors from a per-run
generator (``numpy.random.SeedSequence(seed).spawn(N)``: run i's stream
depends only on the study seed and i), so results do not depend on where or
in which order runs are flown.  Runs are dask tasks (:mod:`modelgen.cluster`):
on the caller's client (a local cluster sized to the machine, or an existing
scheduler), else one after another in this process.  A task carries only
plain data (:class:`MonteCarloSetup`: the flight profile, the filter model's
outline (names and matrix structure), the seed and, for the generated
filter, the generated code as text, made once by the caller, and the error
layout, made by the caller from the flight's first filter cycle; the
caller's derived model travels pickled, unpickled only by a worker whose
runs need the symbolic matrices: one that flies the generated C in the
compiled loop never imports sympy); each worker takes the
trajectory (truth and ideal IMU increments) from its machine's trajectory
cache (:mod:`modelgen.simulation.trajectory_cache`: mapped read-only, made
and kept there by the first worker that needs it) and writes and compiles
the code once (the compile itself is skipped when the compile cache of
:mod:`modelgen.codegen.build` holds the library, e.g. after ``modelgen
simulate``'s own flight or an earlier study), and keeps them for all its
runs of the study.  Fresh workers import this module side by side as the
study starts (:func:`modelgen.cluster.import_on_workers`), asked first thing, so that they import while the
caller makes the set-up.  With a journal
(:class:`modelgen.cluster.Journal`) each completed run is kept on disk as it
arrives and a rerun of the same study flies only the runs missing from it.

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

import dataclasses
import hashlib
import math
import pickle
import tempfile
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping

import numpy as np

from modelgen.cluster import (Journal, dask_client, describe_client, forget_cached, held, import_on_workers, run_tasks,
                              worker_cached)
from modelgen.errors import ModelError
from modelgen.simulation.error_layout import ErrorLayout
from modelgen.simulation.filters import IMPLEMENTATIONS, filter_factory, generated_filter_files
from modelgen.simulation.flight import fly_profile, profile_layout, simulate_sensors
from modelgen.simulation.jit import load_compiled_machinery
from modelgen.simulation.model_outline import ModelOutline
from modelgen.simulation.streaming import flies_compiled_loop as streaming_compiled_loop
from modelgen.simulation.scenario import FlightProfile
from modelgen.simulation.trajectory import Trajectory, generate_trajectory

if TYPE_CHECKING:  # sympy-based: a worker flying the compiled loop never imports them (module docstring)
    from modelgen.derivation.symbolic import DerivedModel
    from modelgen.model.declaration import ErrorModel


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
    where: str = "this process"  # what ran the runs (modelgen.cluster.describe_client)

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
        from scipy.stats import chi2  # here, not at import: scipy.stats costs a worker 0.6 s to import

        keep = self.times >= start_time
        n, N = self.errors.shape[2], self.runs
        alpha = 1.0 - confidence
        lower = chi2.ppf(alpha / 2, N * n) / N
        upper = chi2.ppf(1 - alpha / 2, N * n) / N
        return NeesTest(self.times[keep], np.mean(self.nees[:, keep], axis=0), float(lower), float(upper), n, N,
                        confidence)


# -- runs as tasks -------------------------------------------------------------------


@dataclass(frozen=True)
class MonteCarloSetup:
    """What every run of a study shares, as plain data a worker can receive.

    ``key`` names the set-up in a worker's cache (computed once by the
    caller from everything else here).  ``outline``: the filter model's names
    and matrix structure (:class:`~modelgen.simulation.model_outline.ModelOutline`),
    all that a run flown in the compiled loop (the generated C filter, a
    sensor with a fix table) reads of the model: such a worker unpickles no
    sympy expression and never imports sympy (0.2 s of its start).  ``code``
    is the generated filter's files (name -> text) for the ``c`` and
    ``python`` implementations, generated once by the caller; None for the
    reference.  ``derived``: the caller's derived model (:func:`symbolic_only`:
    its symbolic matrices, 12 kB), pickled, for the runs that need the
    symbolic matrices (the Python filter loop evaluates H and R with them,
    the reference filter F, G and Q): a worker unpickles it only then
    (:func:`received_model`), instead of deriving the model again (0.13 s).
    ``layout``: the error layout of the flight (its ``derived`` is ``outline``),
    made by the caller (:func:`caller_layout`), so that a worker need not make
    it (30 ms, and sympy: the model's matrices lambdified to evaluate them
    once); without it the worker makes it with the derived model.
    """

    profile: FlightProfile
    truth_profile: FlightProfile | None
    outline: ModelOutline
    mode: str
    store_every: int
    implementation: str
    key: str
    code: Mapping[str, str] | None = None
    derived: bytes | None = None
    layout: ErrorLayout | None = None


def symbolic_only(derived: DerivedModel) -> DerivedModel:
    """The same derived model without what it caches of its own (its lambdified functions: code, not data)."""
    return dataclasses.replace(derived)


def flight_start(profile: FlightProfile) -> Trajectory:
    """The trajectory of the flight's first filter cycle only: its initial state is the whole flight's.

    What the error layout needs of a flight (the sign conventions are read at
    its initial state), for a few milliseconds instead of the whole flight.
    """
    period = profile.filter.period
    return generate_trajectory(profile.path.truncated(period), profile.imu_rate, 1.0 / period)


def caller_layout(profile: FlightProfile, derived: DerivedModel, shipped: ModelOutline) -> ErrorLayout:
    """The error layout of ``profile`` for ``derived``, made here, holding ``shipped`` (what the workers receive).

    The layout's groups and conventions (indices and signs) are plain data;
    ``derived`` evaluates the model's matrices (with the functions it keeps
    from earlier flights of this process), ``shipped`` (the model's outline:
    the layout reads only its number of states and names) travels instead.
    """
    return dataclasses.replace(profile_layout(profile, derived, flight_start(profile)), derived=shipped)


@dataclass(frozen=True)
class RunOutput:
    """One run's stored history (every ``store_every`` filter cycles) and counts."""

    times: np.ndarray
    errors: np.ndarray
    sigma: np.ndarray
    nees: np.ndarray
    rejected: int
    updates: int

    def to_json(self) -> dict:
        """JSON data (a journal line); floats as their shortest exact text, so :meth:`of_json` gives them back bit for bit."""
        return {"times": self.times.tolist(), "errors": self.errors.tolist(), "sigma": self.sigma.tolist(),
                "nees": self.nees.tolist(), "rejected": int(self.rejected), "updates": int(self.updates)}

    @classmethod
    def of_json(cls, data: Any) -> "RunOutput":
        """The run :meth:`to_json` wrote (KeyError / TypeError / ValueError on anything else)."""
        arrays = [np.asarray(data[name], dtype=float) for name in ("times", "errors", "sigma", "nees")]
        times, errors, sigma, nees = arrays
        if errors.ndim != 2 or sigma.shape != errors.shape or times.shape != nees.shape or len(times) != len(errors):
            raise ValueError("arrays of inconsistent shapes")
        return cls(times, errors, sigma, nees, int(data["rejected"]), int(data["updates"]))


def setup_key(profile: FlightProfile, truth_profile: FlightProfile | None, model: ErrorModel, mode: str,
              store_every: int, implementation: str) -> str:
    """A digest of the set-up: equal set-ups share a worker's derived model, trajectory and compiled filter.

    The model enters by its canonical declaration hash (:func:`modelgen.codegen.description.model_hash`), not by
    its pickle: a model's pickle changes once the process has derived it (what the derivation carries on it and
    sympy's caches), so the same study got another key in a process that had loaded the model before, and a
    journal of it was refused as another study's.
    """
    from modelgen.codegen.description import model_hash

    blob = pickle.dumps((profile, truth_profile, model_hash(model), mode, store_every, implementation))
    return "montecarlo-" + hashlib.sha256(blob).hexdigest()[:16]


def worker_setup(profile: FlightProfile, truth_profile: FlightProfile | None, derived: DerivedModel, mode: str,
                 store_every: int, implementation: str, key: str) -> MonteCarloSetup:
    """The set-up the workers receive: the code generated here; the model's outline, derived model and layout."""
    code = generated_filter_files(derived) if implementation != "reference" else None
    outline = ModelOutline.of(derived)
    symbolic = pickle.dumps(symbolic_only(derived), protocol=pickle.HIGHEST_PROTOCOL)
    return MonteCarloSetup(profile, truth_profile, outline, mode, store_every, implementation, key, code, symbolic,
                           caller_layout(profile, derived, outline))


def study_setup(profile: FlightProfile, derived: DerivedModel, implementation: str, mode: str | None = None,
                store_every: int | None = None, truth_profile: FlightProfile | None = None) -> MonteCarloSetup:
    """The set-up :func:`run_monte_carlo` ships to its workers for this study (made ahead of it, and handed to it
    as ``setup``, by a caller that keeps no derived model: :mod:`modelgen.simulation.model_process`)."""
    mode = mode or profile.filter.mode
    store_every = store_every or default_store_every(profile)
    key = setup_key(profile, truth_profile, derived.model, mode, store_every, implementation)
    return worker_setup(profile, truth_profile, derived, mode, store_every, implementation, key)


def default_store_every(profile: FlightProfile) -> int:
    """A Monte Carlo run keeps every this many filter cycles: one row per aiding measurement."""
    return max(1, int(round(profile.aiding_period / profile.filter.period)))


def flies_compiled_loop(profile: FlightProfile, make_filter: Any) -> bool:
    """Whether :func:`fly_profile` flies ``profile`` with ``make_filter`` in the compiled loop.

    The compiled loop (:mod:`modelgen.simulation.native_loop`) reads only the
    model's outline; the Python loop evaluates the symbolic H and R.  The
    rule of :func:`modelgen.simulation.streaming.fly_modes` (default glue, no sinks).
    """
    sensor = profile.aiding_sensor
    return hasattr(sensor, "filter_loop") and streaming_compiled_loop(sensor, make_filter)


def received_model(setup: MonteCarloSetup) -> DerivedModel:
    """The caller's derived model sent with ``setup`` (unpickling it imports sympy), for runs that need it."""
    if setup.derived is None:
        raise ModelError(f"Monte Carlo set-up {setup.key}: its runs (filter {setup.implementation!r}, sensor "
                         f"{setup.profile.aiding_sensor.name!r}) need the derived model, and the set-up carries none")
    return pickle.loads(setup.derived)


def _prepare(setup: MonteCarloSetup, derived: DerivedModel | None = None,
             mark: Callable[[str], None] = lambda step: None) -> dict:
    """What a worker builds once per set-up: trajectory, filter maker, the model its runs need, error layout.

    The trajectory comes from the trajectory cache (made and kept there on a
    miss); the shipped code is written to a folder the context owns (removed
    with it) and compiled through the compile cache.  The model is
    ``derived`` if given (the caller's own, in its process), else the
    set-up's outline when the runs fly the compiled loop, else the derived
    model the set-up carries (:func:`received_model`).  ``mark(step)`` is
    called after each step (the benchmark times a worker's set-up with it).
    """
    profile = setup.profile
    # streamed: the truth rows only, each run making its ideal increments piece by piece (0.4 s of CPU for
    # 4 h at 300 Hz), so a worker's memory does not grow with the flight (a held one maps 207 MB at 4 h)
    trajectory = generate_trajectory(profile.path, profile.imu_rate, 1.0 / profile.filter.period, True)
    mark("trajectory (truth rows; the ideal IMU increments are made piece by piece in each run)")
    model: DerivedModel | ModelOutline | None = derived
    if model is None and (setup.implementation == "reference" or setup.layout is None):
        # the reference filter and a layout made here evaluate the symbolic matrices
        model = received_model(setup)
        mark("the model: the caller's derived model, unpickled (sympy)")
    code_dir = tempfile.TemporaryDirectory(prefix="modelgen-montecarlo-")
    make_filter = filter_factory(model if model is not None else setup.outline, setup.implementation, code_dir.name,
                                 setup.code)
    mark(f"filter: write the shipped code, compile or take from the cache ({setup.implementation})")
    if model is None and flies_compiled_loop(profile, make_filter):
        model = setup.outline
        mark("the model: its outline, received with the set-up (the compiled loop needs no sympy)")
    elif model is None:
        model = received_model(setup)
        mark("the model: the caller's derived model, unpickled (the Python loop evaluates H and R; sympy)")
    layout = setup.layout if setup.layout is not None else profile_layout(profile, model, trajectory)
    mark("error layout (the caller's, received with the set-up)" if setup.layout is not None else "error layout")
    return {"setup": setup, "derived": model, "trajectory": trajectory, "layout": layout, "make_filter": make_filter,
            "code_dir": code_dir}


def fly_one_run(key: str, sent: MonteCarloSetup | bytes, seed: np.random.SeedSequence) -> RunOutput:
    """One Monte Carlo run (a dask task): the flight of the set-up ``key`` with the sensors drawn from ``seed``.

    ``sent`` is the set-up or, as it travels to workers, its pickle: a worker
    unpickles it once, for its first run of the study, and another worker
    serves it as the bytes they are (nothing to pickle again).
    """
    c = worker_cached(key, lambda: _prepare(pickle.loads(sent) if isinstance(sent, bytes) else sent))
    setup = c["setup"]
    rng = np.random.default_rng(seed)
    # the run's IMU errors streamed piece by piece over the shared trajectory: memory independent of the
    # flight's length (a held copy of the measured increments was 207 MB at 4 h, 300 Hz); the same draws
    sensors = simulate_sensors(setup.truth_profile or setup.profile, c["trajectory"], rng, stream_errors=True)
    result = fly_profile(setup.profile, c["derived"], c["trajectory"], rng, c["make_filter"],
                         mode=setup.mode, sensors=sensors, layout=c["layout"], truth_profile=setup.truth_profile)
    rows = slice(None, None, setup.store_every)
    return RunOutput(result.times[rows], result.estimation_error[rows], result.sigma[rows], result.nees[rows],
                     len(result.rejected), result.updates)


def warm_worker() -> None:
    """What a fresh worker's first run would otherwise pay for, done in its import thread (:func:`import_on_workers`).

    numba's registries (loaded by a process's first compiled call, 0.2 s) and
    scipy.special (the innovation gate's chi-square quantile,
    :func:`modelgen.simulation.filter_loop.gate_threshold`, 0.14 s), while
    the caller still makes the set-up.
    """
    import scipy.special  # noqa: F401  (the gate's, imported at a run's start otherwise)

    load_compiled_machinery()


def run_monte_carlo(profile: FlightProfile, derived: DerivedModel, runs: int, seed: int = 0, mode: str | None = None,
                    workers: int = 1, client: Any = None, store_every: int | None = None,
                    progress: Callable[[int, int], None] | None = None,
                    truth_profile: FlightProfile | None = None, implementation: str = "reference",
                    on_run: Callable[[int, RunOutput], None] | None = None,
                    journal: str | Path | None = None, setup: MonteCarloSetup | None = None) -> MonteCarloResult:
    """``runs`` independent flights of ``profile`` with the filter model ``derived`` (module docstring).

    ``client``: a ``distributed.Client`` (:func:`modelgen.cluster.dask_client`)
    to run on; without one, ``workers`` > 1 starts a local cluster of that
    many worker processes for this call (for two runs or more), 1 runs here.
    ``truth_profile`` (same flight) draws the sensors from a different error
    budget than the filter assumes: a mis-modelled filter.  ``implementation`` is the filter flown (the numpy
    ``reference``, or the generated ``c`` / ``python``, built once per
    worker).  ``on_run(i, output)`` receives each run as it completes.
    ``journal``: a file that keeps each completed run (:func:`run_journal`);
    a study stopped part-way is taken up again from it, flying only the
    missing runs, and a journal of another study is refused.  ``setup``: the study's set-up made ahead
    (:func:`study_setup`, same profile, mode, filter and truth profile); ``derived`` may then be its
    outline, and no symbolic model is needed here.
    """
    if runs < 1:
        raise ModelError(f"Monte Carlo: need at least one run, got {runs}")
    if implementation not in IMPLEMENTATIONS:
        raise ModelError(f"Monte Carlo: unknown filter implementation {implementation!r} "
                         f"(choose from {', '.join(IMPLEMENTATIONS)})")
    mode = mode or profile.filter.mode
    store_every = store_every or default_store_every(profile)
    key = study_key(profile, derived, mode, store_every, implementation, truth_profile, setup)
    kept = run_journal(journal, key, seed, runs) if journal is not None else None
    finished = kept is not None and len(kept.completed()) == runs  # all in the journal: nothing to build or ship
    if client is None and workers > 1 and runs > 1 and not finished:  # (and no local cluster to start)
        with dask_client(workers=min(workers, runs)) as local:
            return run_monte_carlo(profile, derived, runs, seed, mode, client=local, store_every=store_every,
                                   progress=progress, truth_profile=truth_profile, implementation=implementation,
                                   on_run=on_run, journal=journal, setup=setup)
    seeds = np.random.SeedSequence(seed).spawn(runs)
    start = time.perf_counter()
    shared: Any
    if client is not None and not finished:
        # first: fresh workers import (and warm up) side by side while the set-up is made here
        import_on_workers(client, __name__, warm_up="warm_worker")
        if setup is None:
            setup = worker_setup(profile, truth_profile, derived, mode, store_every, implementation, key)
        # the set-up (the code: ~400 kB of text) travels once, pickled, as a task of its own, not once per run
        shared = client.submit(held, pickle.dumps(setup, protocol=pickle.HIGHEST_PROTOCOL), pure=False,
                               key=f"modelgen-montecarlo-setup-{key}-{uuid.uuid4().hex[:8]}")
    elif setup is not None:  # this process flies the set-up made ahead (its code, layout and model)
        shared = setup
        if not finished:
            made = setup
            worker_cached(key, lambda: _prepare(made))
    else:  # this process flies with the caller's derived model (and makes the layout with the whole trajectory)
        code = generated_filter_files(derived) if implementation != "reference" and not finished else None
        setup = shared = MonteCarloSetup(profile, truth_profile, ModelOutline.of(derived), mode, store_every,
                                         implementation, key, code)
        if not finished:
            worker_cached(key, lambda: _prepare(setup, derived))
    try:
        outputs = run_tasks(fly_one_run, [(key, shared, s) for s in seeds], client, progress=progress, on_result=on_run,
                            label="montecarlo", journal=kept)
    finally:
        if client is None:
            forget_cached(key)
        elif shared is not setup:
            shared.release()
    return MonteCarloResult(
        scenario=profile.name,
        mode=mode,
        state_names=list(derived.model.state_names),
        times=outputs[0].times,
        errors=np.stack([o.errors for o in outputs]),
        sigma=np.stack([o.sigma for o in outputs]),
        nees=np.stack([o.nees for o in outputs]),
        rejected=np.array([o.rejected for o in outputs]),
        updates=np.array([o.updates for o in outputs]),
        seconds=time.perf_counter() - start,
        where=describe_client(client),
    )


def study_key(profile: FlightProfile, derived: DerivedModel | ModelOutline | None, mode: str, store_every: int,
              implementation: str, truth_profile: FlightProfile | None = None, setup: MonteCarloSetup | None = None) -> str:
    """The set-up digest of a study (:func:`setup_key`): ``setup``'s own when given (it must be for this mode, cycle
    count and filter), else that of ``derived``'s model."""
    if setup is not None:
        if (setup.mode, setup.store_every, setup.implementation) != (mode, store_every, implementation):
            raise ModelError(f"Monte Carlo: the set-up {setup.key} is for mode {setup.mode!r}, every {setup.store_every} "
                             f"cycles, filter {setup.implementation!r}, not {mode!r}, {store_every}, {implementation!r}")
        return setup.key
    return setup_key(profile, truth_profile, derived.model, mode, store_every, implementation)


def check_journal(journal: str | Path, profile: FlightProfile, derived: DerivedModel | ModelOutline | None, runs: int,
                  seed: int = 0, implementation: str = "reference", setup: MonteCarloSetup | None = None) -> int:
    """Refuse now a journal that :func:`run_monte_carlo` (same arguments, default mode and cycle count) would refuse,
    before a flight or a cluster is started (:meth:`modelgen.cluster.Journal.check`; nothing is written); how many
    of the runs it holds."""
    mode, store_every = profile.filter.mode, default_store_every(profile)
    return run_journal(journal, study_key(profile, derived, mode, store_every, implementation, setup=setup), seed,
                       runs).check()


def run_journal(path: str | Path, key: str, seed: int, runs: int) -> Journal:
    """The journal of a Monte Carlo study: named by its set-up digest (profile, model, mode, filter) and seed, ``runs`` tasks."""
    return Journal(path, f"{key}-seed-{seed}", runs, encode=RunOutput.to_json, decode=RunOutput.of_json)
