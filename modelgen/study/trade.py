"""Running a trade study: covariance analysis of every case, Monte Carlo of the selected ones, as dask tasks.

A *point* is one value of every study parameter; a *case* is a point with
one filter.  The cases of a point share the truth system (its Phi and
Gamma Q Gamma^T), so a task evaluates every filter of a few points
(:func:`evaluate_points`) with :func:`modelgen.table2.systems.analyse_systems`,
the same recursions as the paper's Table 2.  Each worker derives the truth and
filter models once per study (:func:`modelgen.cluster.worker_cached`); tasks
carry plain data only (the model declaration, scenario, budget, values).

Monte Carlo cases fly the study's flight profile with the case's values
written into the profile's keys (``parameters.NAME.profile``), through
:func:`modelgen.simulation.montecarlo.run_monte_carlo` on the same client.
"""

from __future__ import annotations

import copy
import hashlib
import math
import pickle
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence

from modelgen.table2.budget import ErrorBudget
from modelgen.table2.metrics import final_values
from modelgen.table2.scenario import AnalysisScenario
from modelgen.table2.suboptimal import FilterDesign
from modelgen.table2.systems import PURE_INERTIAL, PaperModels, analyse_systems
from modelgen.cluster import Journal, describe_client, run_tasks, worker_cached
from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import read_yaml_with_lines
from modelgen.model.declaration import ErrorModel
from modelgen.model.loading import load_model
from modelgen.model.units import from_si, to_si
from modelgen.simulation.montecarlo import MonteCarloResult, run_monte_carlo
from modelgen.simulation.scenario import FlightProfile, load_profile_data
from modelgen.study.studyfile import METRICS, PROFILE_SUFFIX_UNITS, Parameter, Study

#: How the table names the pure-inertial system (Table 2's row "I").
PURE_INERTIAL_LABEL = "I (inertial)"
#: Points per task: enough to make a task's overhead small, few enough to spread and show progress.
TASKS_PER_WORKER = 8


@dataclass(frozen=True)
class CovarianceSetup:
    """What every covariance task of a study shares (plain data); ``key`` names it in a worker's cache."""

    model: ErrorModel
    designs: tuple[FilterDesign, ...]
    scenario: AnalysisScenario
    budget: ErrorBudget
    parameters: tuple[Parameter, ...]
    key: str


@dataclass(frozen=True)
class CaseResult:
    """One case: the point's values (parameter units), the filter, its final errors (``METRICS`` units)."""

    point: tuple[float, ...]
    filter: str
    label: str
    filter_states: int
    final: dict[str, float]


@dataclass(frozen=True)
class MonteCarloCase:
    """A Monte Carlo of one point: the ensemble and the profile it flew."""

    point: tuple[float, ...]
    result: MonteCarloResult


@dataclass(frozen=True)
class TradeResult:
    """Every case's result, the Monte Carlo ensembles, and how long and where it ran."""

    study: Study
    cases: list[CaseResult]
    monte_carlo: list[MonteCarloCase]
    seconds: float  # the whole study
    covariance_seconds: float  # the covariance cases alone (from submitting the first task)
    where: str


def apply_point(scenario: AnalysisScenario, budget: ErrorBudget, parameters: Sequence[Parameter],
                point: Sequence[float]) -> tuple[AnalysisScenario, ErrorBudget]:
    """The scenario and budget with every target of every parameter set to the point's value (SI)."""
    values, initial = dict(budget.parameters), dict(budget.initial_sigma)
    for parameter, value in zip(parameters, point):
        si = to_si(value, parameter.unit, f"parameter {parameter.name}")
        for target in parameter.sets:
            if target == "scenario.latitude":
                scenario = replace(scenario, latitude=si)
            elif target == "scenario.speed_east":
                north, _, down = scenario.velocity_ned
                scenario = replace(scenario, velocity_ned=(north, si, down))
            elif target.startswith("initial_sigma."):
                initial[target.partition(".")[2]] = si
            elif target.endswith(".correlation_time"):
                values[target.rpartition(".")[0]] = 1.0 / si  # the model's rate mu
            else:
                values[target] = si
    return scenario, ErrorBudget(budget.name, initial, values, budget.inferred)


def _paper_models(setup: CovarianceSetup) -> PaperModels:
    return PaperModels.build(derive(setup.model), setup.designs)


def evaluate_points(setup: CovarianceSetup, points: Sequence[tuple[float, ...]]) -> list[dict[str, dict[str, float]]]:
    """For each point: system key (each design's, and ``pure_inertial``) -> final errors (a dask task)."""
    models = worker_cached(setup.key, lambda: _paper_models(setup))
    out = []
    for point in points:
        scenario, budget = apply_point(setup.scenario, setup.budget, setup.parameters, point)
        results = analyse_systems(models, scenario, budget)
        out.append({key: final_values(r.errors) for key, r in results.items()})
    return out


def covariance_setup(study: Study) -> CovarianceSetup:
    """The shared data of the study's covariance tasks."""
    designs = tuple(f.design for f in study.filters if f.design is not None)
    blob = pickle.dumps((study.model, designs, study.scenario, study.budget, study.parameters))
    key = "trade-" + hashlib.sha256(blob).hexdigest()[:16]
    return CovarianceSetup(study.model, designs, study.scenario, study.budget, study.parameters, key)


def chunks(points: Sequence[tuple[float, ...]], workers: int) -> list[list[tuple[float, ...]]]:
    """Points split into about ``TASKS_PER_WORKER`` tasks per worker, in order."""
    size = max(1, math.ceil(len(points) / (TASKS_PER_WORKER * max(1, workers))))
    return [list(points[i:i + size]) for i in range(0, len(points), size)]


def monte_carlo_profile(profile_file: str, parameters: Sequence[Parameter], point: Sequence[float],
                        hours: float | None, imu_rate: float | None) -> FlightProfile:
    """The flight profile with each parameter's value written into its profile keys (in their units)."""
    data, lines = read_yaml_with_lines(profile_file, "scenario file")
    data = copy.deepcopy(data)
    for parameter, value in zip(parameters, point):
        si = to_si(value, parameter.unit, f"parameter {parameter.name}")
        for key in parameter.profile_keys:
            section, _, name = key.rpartition(".")
            unit = next(u for s, u in PROFILE_SUFFIX_UNITS.items() if name.endswith(s))
            holder = data
            for part in section.split("."):
                if not isinstance(holder.get(part), dict):
                    raise ModelError(f"{profile_file}: parameter {parameter.name} sets {key}, but the profile has "
                                     f"no section {part!r}")
                holder = holder[part]
            holder[name] = float(from_si(si, unit))
    profile = load_profile_data(data, profile_file, lines)
    changes: dict[str, float] = {}
    if hours is not None:
        changes["hours"] = hours
    if imu_rate is not None:
        changes["imu_rate"] = imu_rate
    return profile.with_changes(**changes)


def _worker_count(client: Any) -> int:
    return 1 if client is None else max(1, len(client.scheduler_info().get("workers", {})))


def monte_carlo_profiles(study: Study) -> list[FlightProfile]:
    """The flight profile of each Monte Carlo case (refused here, before any task, if a key does not fit)."""
    mc = study.monte_carlo
    if mc is None:
        return []
    return [monte_carlo_profile(mc.profile, study.parameters, p, mc.hours, mc.imu_rate) for p in mc.cases]


def covariance_journal(path: str | Path, setup: CovarianceSetup, tasks: Sequence[Sequence[tuple[float, ...]]]) -> Journal:
    """The journal of a study's covariance tasks: its name is the digest of the set-up and of the split into tasks."""
    split = hashlib.sha256(repr([list(t) for t in tasks]).encode()).hexdigest()[:16]
    return Journal(path, f"{setup.key}-{split}", len(tasks))


def run_trade(study: Study, client: Any = None, progress: Callable[[str], None] | None = None,
              profiles: Sequence[FlightProfile] | None = None, journal: str | Path | None = None) -> TradeResult:
    """Every case of ``study`` (covariance), then its Monte Carlo cases, on ``client`` (or here without one).

    ``profiles``: :func:`monte_carlo_profiles` of the study, if the caller
    built them already (to refuse a bad one before opening a cluster).
    ``journal``: a file that keeps each completed covariance task (JSON
    lines); a study stopped part-way is taken up again from it (with the
    same number of workers, which sets the split into tasks).
    """
    say = progress or (lambda _: None)
    start = time.perf_counter()
    where = describe_client(client)
    # everything that can be refused is checked before the first task goes out
    profiles = list(profiles) if profiles is not None else monte_carlo_profiles(study)
    setup = covariance_setup(study)
    tasks = chunks(study.points, _worker_count(client))
    say(f"trade study {study.name}: {study.case_count} covariance cases ({len(study.points)} points x "
        f"{len(study.filters)} filters) in {len(tasks)} tasks on {where}")
    state = {"next": 0.1}

    def report(done: int, total: int) -> None:
        if done / total >= state["next"] or done == total:
            say(f"  covariance: {done}/{total} tasks ({time.perf_counter() - start:.1f} s)")
            while state["next"] <= done / total:
                state["next"] += 0.1

    covariance_start = time.perf_counter()
    kept = covariance_journal(journal, setup, tasks) if journal is not None else None
    if kept is not None:
        say(f"  journal {journal}: {len(kept.completed())} of {len(tasks)} tasks already done")
    finals = [f for chunk in run_tasks(evaluate_points, [(setup, c) for c in tasks], client, progress=report,
                                       label="trade", journal=kept) for f in chunk]
    covariance_seconds = time.perf_counter() - covariance_start
    cases = []
    for point, systems in zip(study.points, finals):
        for choice in study.filters:
            key = choice.design.key if choice.design is not None else PURE_INERTIAL
            label = choice.design.label if choice.design is not None else PURE_INERTIAL_LABEL
            states = 0 if choice.design is None else _filter_states(study, choice.design)
            cases.append(CaseResult(point, choice.name, label, states,
                                    {m: systems[key][m] for m, _ in METRICS if m in systems[key]}))
    ensembles = []
    if study.monte_carlo is not None:
        mc = study.monte_carlo
        for i, (point, profile) in enumerate(zip(mc.cases, profiles)):
            say(f"  Monte Carlo {i + 1}/{len(profiles)}: {_point_text(study.parameters, point)}, {mc.runs} runs")
            derived = derive(load_model(profile.filter.model))
            result = run_monte_carlo(profile, derived, mc.runs, seed=mc.seed, client=client,
                                     progress=lambda d, t: _say_run_done(say, d, t))
            ensembles.append(MonteCarloCase(point, result))
    return TradeResult(study, cases, ensembles, time.perf_counter() - start, covariance_seconds, where)


def _say_run_done(say: Callable[[str], None], done: int, total: int) -> None:
    """One line per completed Monte Carlo run (a study's runs are few and long)."""
    say(f"    run {done}/{total} done")


def _filter_states(study: Study, design: FilterDesign) -> int:
    """States of a design's filter model: the truth's less the lumped random constants and whitened Markov states."""
    return len(study.model.state_names) - len(design.lumps) - len(design.white_states)


def _point_text(parameters: Sequence[Parameter], point: Sequence[float]) -> str:
    return ", ".join(f"{p.name} = {v:g} {p.unit}" for p, v in zip(parameters, point))
