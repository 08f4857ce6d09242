"""Reading a trade-study file: every key, unit and value checked before any case is run.

A study file is data (YAML, no code).  Its keys:

``study``, ``title``
    name and one-line description.
``model``, ``scenario``, ``budget``
    the truth model (built-in name or file; default ``ned_doppler18``), the
    analysis scenario and the error budget (data files; default the core
    paper's ``scenario_000.yaml`` and ``error_budget_000.yaml``).  Relative
    paths are relative to the study file.
``parameters``
    what varies.  Each entry has a ``unit``, the budget entries it ``sets``
    (a parameter of the budget, ``PARAMETER.correlation_time``,
    ``initial_sigma.STATE``, ``scenario.latitude`` or ``scenario.speed_east``;
    default: the entry's own name) and, for a grid, its ``values`` (a list) or
    a ``range: {from, to, count, spacing: linear | log}``.  ``profile`` lists
    the flight-profile keys it sets for Monte Carlo (``imu.gyro_markov_drift_dph``).
``cases``
    instead of a grid: a list of cases, each a mapping parameter -> value.
``filters``
    the filters compared on every case: names of the paper's filters
    (``optimal``, ``suboptimal_1`` ... ``suboptimal_4``) and ``pure_inertial``,
    or a mapping name -> ``{like: PAPER_FILTER, gain_period, manoeuvre_gain_period,
    whitening}`` for variants.
``monte_carlo``
    optional: ``profile``, ``hours``, ``imu_rate_hz``, ``runs``, ``seed`` and
    the ``cases`` to fly (parameter values; the flight's filter is the
    profile's full model, so only the ``optimal`` filter has a Monte Carlo).
``plot``
    optional: ``x`` (a parameter; default the first) and ``metric`` (a column
    of the table; default ``position_cep``).

Anything unknown, a unit that does not fit what it sets, an empty grid, a
value out of range (a negative sigma, a latitude at a pole...) is a
:class:`~modelgen.errors.ModelError` naming the file and line.
"""

from __future__ import annotations

import functools
import itertools
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from modelgen.table2.budget import BUDGET_FILE, ErrorBudget, load_error_budget
from modelgen.table2.metrics import REPORTED_STATES
from modelgen.table2.scenario import SCENARIO_FILE, AnalysisScenario, load_analysis_scenario
from modelgen.table2.suboptimal import PAPER_FILTERS, FilterDesign
from modelgen.table2.systems import PURE_INERTIAL
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path, read_yaml_with_lines
from modelgen.model.declaration import ErrorModel
from modelgen.model.file_fields import is_number
from modelgen.model.loading import builtin_model_path, load_model
from modelgen.model.units import to_si
from modelgen.simulation.profile_keys import check_flight_size

#: A study larger than this is refused (a typo in a range's count must not fill a cluster for days).
MAX_CASES = 100_000
#: At most this many values in one range.
MAX_RANGE_COUNT = 10_000
#: Monte Carlo runs per selected case, at most.
MAX_RUNS = 100_000
#: A parameter's name: it names a table column and a figure axis (never a path: no ``/``).
PARAMETER_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.]{0,99}")

DEFAULT_MODEL = "ned_doppler18"

#: What each unit measures: a parameter's unit must measure what its targets are.
DIMENSIONS: dict[str, str] = {
    "rad": "angle", "deg": "angle", "arcmin": "angle", "arcsec": "angle",
    "rad/s": "angular rate", "deg/h": "angular rate",
    "m/s": "speed", "km/h": "speed", "nmile/h": "speed",
    "m/s^2": "acceleration", "g": "acceleration",
    "m": "length", "km": "length", "nmile": "length",
    "s": "time", "h": "time",
    "1/s": "rate", "1": "number",
}

#: Scenario targets: what they measure.
SCENARIO_TARGETS = {"scenario.latitude": "angle", "scenario.speed_east": "speed"}

#: Flight-profile key suffixes (modelgen.simulation.profile_keys) and the unit each one means.
PROFILE_SUFFIX_UNITS = {
    "_dph": "deg/h", "_deg": "deg", "_arcsec": "arcsec", "_arcmin": "arcmin", "_kmh": "km/h", "_mps": "m/s",
    "_g": "g", "_m": "m", "_s": "s", "_h": "h",
}

#: The table's metric columns: the final value of each reported error (name, unit).
METRICS: tuple[tuple[str, str], ...] = (
    *((key, unit) for _, key, unit in REPORTED_STATES),
    ("position_error_north", "nmile"),
    ("position_error_east", "nmile"),
    ("position_cep", "nmile"),
    ("average_drift_rate", "nmile/h"),
)

_TOP_KEYS = ("study", "title", "model", "scenario", "budget", "parameters", "cases", "filters", "monte_carlo", "plot")
_PARAMETER_KEYS = ("unit", "sets", "values", "range", "profile")
_RANGE_KEYS = ("from", "to", "count", "spacing")
_VARIANT_KEYS = ("like", "gain_period", "manoeuvre_gain_period", "whitening")
_MONTE_CARLO_KEYS = ("profile", "hours", "imu_rate_hz", "runs", "seed", "cases")
_PLOT_KEYS = ("x", "metric")
_WHITENINGS = ("low_frequency", "driving_noise")


@dataclass(frozen=True)
class Parameter:
    """One varied quantity: its unit, the budget entries it sets and (for a grid) its values in ``unit``."""

    name: str
    unit: str
    sets: tuple[str, ...]
    values: tuple[float, ...]
    profile_keys: tuple[str, ...] = ()
    log_spaced: bool = False


@dataclass(frozen=True)
class FilterChoice:
    """A filter of the study: a design (a paper's filter or a variant), or None for the pure-inertial system."""

    name: str
    design: FilterDesign | None


@dataclass(frozen=True)
class MonteCarloChoice:
    """Which cases are also flown as Monte Carlo, and how."""

    profile: str
    hours: float | None
    imu_rate: float | None
    runs: int
    seed: int
    cases: tuple[tuple[float, ...], ...]  # values in the order of Study.parameters


@dataclass(frozen=True)
class Study:
    """A checked study: the inputs of every case, and what to plot."""

    name: str
    title: str
    source_file: str
    model: ErrorModel  # the truth model's declaration (plain data a worker derives)
    scenario: AnalysisScenario
    budget: ErrorBudget
    parameters: tuple[Parameter, ...]
    points: tuple[tuple[float, ...], ...]  # one value per parameter, in its unit
    filters: tuple[FilterChoice, ...]
    monte_carlo: MonteCarloChoice | None
    plot_x: str
    metric: str

    @property
    def case_count(self) -> int:
        """Covariance cases: every point with every filter."""
        return len(self.points) * len(self.filters)

    def parameter(self, name: str) -> Parameter:
        return next(p for p in self.parameters if p.name == name)


class _Reader:
    """Where each key is (file:line) and the checks every section shares."""

    def __init__(self, path: Path, lines: Mapping[str, str]):
        self.path, self.lines = path, lines

    def at(self, key_path: str) -> str:
        """``file:line: key.path`` (the nearest enclosing key's line when this one has none)."""
        probe = key_path
        while probe and probe not in self.lines:
            probe = probe.rpartition(".")[0] if "." in probe else ""
        where = self.lines.get(probe, str(self.path)) if probe else str(self.path)
        return f"{where}: {key_path}" if key_path else where

    def mapping(self, value: Any, key_path: str, allowed: Sequence[str]) -> dict:
        if not isinstance(value, dict):
            raise ModelError(f"{self.at(key_path)}: must be a mapping, got {type(value).__name__}")
        unknown = [k for k in value if k not in allowed]
        if unknown:
            raise ModelError(f"{self.at(_join(key_path, str(unknown[0])))}: unknown key {unknown[0]!r} "
                             f"(known: {', '.join(allowed)})")
        return value

    def number(self, value: Any, key_path: str) -> float:
        if isinstance(value, str) and is_number(value):  # YAML 1.1 reads 1e9 (no dot) as text: a number, as in profiles
            value = float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ModelError(f"{self.at(key_path)}: {value!r} is not a number")
        if not math.isfinite(value):
            raise ModelError(f"{self.at(key_path)}: {value!r} is not finite")
        return float(value)

    def whole(self, value: Any, key_path: str, minimum: int, maximum: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ModelError(f"{self.at(key_path)}: {value!r} is not a whole number")
        if not minimum <= value <= maximum:
            raise ModelError(f"{self.at(key_path)}: {value} is out of range [{minimum}, {maximum}]")
        return value

    def text(self, value: Any, key_path: str, choices: Sequence[str] = ()) -> str:
        if not isinstance(value, str) or not value:
            raise ModelError(f"{self.at(key_path)}: must be a non-empty string, got {value!r}")
        if choices and value not in choices:
            raise ModelError(f"{self.at(key_path)}: {value!r} is not one of {', '.join(choices)}")
        return value


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _resolve(reference: str, study_dir: Path, builtin: Path | None) -> str:
    """A built-in name (or data file) as is, else a path relative to the study file's folder."""
    if builtin is not None and builtin.is_file():
        return str(builtin)
    path = Path(reference)
    return str(path if path.is_absolute() else study_dir / path)


def _data_file(reference: str, study_dir: Path) -> str:
    name = reference if reference.endswith(".yaml") else f"{reference}.yaml"
    return _resolve(reference, study_dir, data_path(name) if "/" not in reference else None)


def target_dimension(target: str, budget_units: Mapping[str, str], budget_rates: set[str],
                     initial_units: Mapping[str, str]) -> str | None:
    """What a ``sets`` target measures, or None when the budget has no such entry."""
    if target in SCENARIO_TARGETS:
        return SCENARIO_TARGETS[target]
    if target.startswith("initial_sigma."):
        unit = initial_units.get(target.partition(".")[2])
        return DIMENSIONS.get(unit) if unit else None
    if target.endswith(".correlation_time"):
        name = target.rpartition(".")[0]
        return "time" if name in budget_rates else None
    if target in budget_units and target not in budget_rates:
        return DIMENSIONS.get(budget_units[target])
    return None


def check_value(target: str, value_si: float, where: str) -> None:
    """Refuse a value a target cannot take: negative sigmas, non-positive correlation times, a latitude at a pole."""
    if target == "scenario.latitude":
        if not abs(value_si) < math.pi / 2:
            raise ModelError(f"{where}: latitude {math.degrees(value_si):g} deg is out of range (-90, 90) deg")
    elif target == "scenario.speed_east":
        return
    elif target.endswith(".correlation_time"):
        if not value_si > 0:
            raise ModelError(f"{where}: a correlation time must be positive, got {value_si:g} s")
    elif value_si < 0:
        raise ModelError(f"{where}: {target} is a standard deviation and cannot be negative, got {value_si:g} (SI)")


def _budget_units(path: str) -> tuple[dict[str, str], set[str], dict[str, str]]:
    """Units of the budget file's parameters and initial sigmas, and which parameters are correlation rates."""
    data, _ = read_yaml_with_lines(path, "error-budget file")
    params = data.get("parameters") or {}
    units = {k: str(v.get("unit")) for k, v in params.items() if isinstance(v, dict)}
    rates = {k for k, v in params.items() if isinstance(v, dict) and "correlation_time" in v}
    initial = {k: str(v.get("unit")) for k, v in (data.get("initial_sigma") or {}).items() if isinstance(v, dict)}
    return units, rates, initial


def _values(r: _Reader, entry: dict, key_path: str) -> tuple[tuple[float, ...], bool]:
    """A parameter's grid values (from ``values`` or ``range``) and whether they are log-spaced."""
    if "values" in entry and "range" in entry:
        raise ModelError(f"{r.at(key_path)}: give either values or range, not both")
    if "values" in entry:
        raw = entry["values"]
        if not isinstance(raw, list):
            raise ModelError(f"{r.at(key_path + '.values')}: must be a list of numbers")
        if not raw:
            raise ModelError(f"{r.at(key_path + '.values')}: empty grid: give at least one value")
        if len(raw) > MAX_RANGE_COUNT:
            raise ModelError(f"{r.at(key_path + '.values')}: {len(raw)} values; a parameter may have at most "
                             f"{MAX_RANGE_COUNT}")
        return tuple(r.number(v, f"{key_path}.values[{i}]") for i, v in enumerate(raw)), False
    if "range" in entry:
        rng = r.mapping(entry["range"], key_path + ".range", _RANGE_KEYS)
        for key in ("from", "to", "count"):
            if key not in rng:
                raise ModelError(f"{r.at(key_path + '.range')}: missing key {key!r}")
        low, high = r.number(rng["from"], key_path + ".range.from"), r.number(rng["to"], key_path + ".range.to")
        count = r.whole(rng["count"], key_path + ".range.count", 1, MAX_RANGE_COUNT)
        spacing = r.text(rng.get("spacing", "linear"), key_path + ".range.spacing", ("linear", "log"))
        if spacing == "log":
            if not (low > 0 and high > 0):
                raise ModelError(f"{r.at(key_path + '.range')}: a log-spaced range needs from > 0 and to > 0")
            return tuple(float(v) for v in np.geomspace(low, high, count)), True
        return tuple(float(v) for v in np.linspace(low, high, count)), False
    return (), False


def _parameters(r: _Reader, raw: Any, budget: ErrorBudget, budget_file: str, grid: bool) -> tuple[Parameter, ...]:
    if not isinstance(raw, dict) or not raw:
        raise ModelError(f"{r.at('parameters')}: must be a non-empty mapping of the parameters to vary")
    units, rates, initial_units = _budget_units(budget_file)
    for name in raw:
        if not isinstance(name, str) or not PARAMETER_NAME.fullmatch(name):
            raise ModelError(f"{r.at(f'parameters.{name}')}: parameter name {name!r} must be letters, digits, '_' "
                             f"and '.' (starting with a letter or '_', at most 100 characters)")
    out = []
    grid_points = 1
    for name, entry in raw.items():
        key_path = f"parameters.{name}"
        entry = r.mapping(entry, key_path, _PARAMETER_KEYS)
        if "unit" not in entry:
            raise ModelError(f"{r.at(key_path)}: missing key 'unit'")
        unit = r.text(entry["unit"], key_path + ".unit", tuple(DIMENSIONS))
        sets = entry.get("sets", [name])
        if isinstance(sets, str):
            sets = [sets]
        if not isinstance(sets, list) or not sets:
            raise ModelError(f"{r.at(key_path + '.sets')}: must be a non-empty list of budget entries")
        for i, target in enumerate(sets):
            target = r.text(target, f"{key_path}.sets[{i}]")
            dimension = target_dimension(target, units, rates, initial_units)
            if dimension is None:
                known = sorted([*(k for k in units if k not in rates), *(f"{k}.correlation_time" for k in rates),
                                *(f"initial_sigma.{k}" for k in initial_units), *SCENARIO_TARGETS])
                raise ModelError(f"{r.at(f'{key_path}.sets[{i}]')}: unknown parameter {target!r} of budget "
                                 f"{budget.name!r} (known: {', '.join(known)})")
            if dimension != DIMENSIONS[unit]:
                raise ModelError(f"{r.at(key_path + '.unit')}: {unit!r} measures {DIMENSIONS[unit]}, but {target} "
                                 f"is {'an' if dimension[0] in 'aeiou' else 'a'} {dimension}")
        profile_keys = entry.get("profile", [])
        if isinstance(profile_keys, str):
            profile_keys = [profile_keys]
        if not isinstance(profile_keys, list):
            raise ModelError(f"{r.at(key_path + '.profile')}: must be a list of flight-profile keys")
        for i, key in enumerate(profile_keys):
            key = r.text(key, f"{key_path}.profile[{i}]")
            suffix = next((s for s in PROFILE_SUFFIX_UNITS if key.endswith(s)), None)
            if suffix is None or "." not in key:
                raise ModelError(f"{r.at(f'{key_path}.profile[{i}]')}: {key!r} is not a SECTION.KEY of a flight "
                                 f"profile with a unit suffix ({', '.join(PROFILE_SUFFIX_UNITS)})")
            if DIMENSIONS[PROFILE_SUFFIX_UNITS[suffix]] != DIMENSIONS[unit]:
                raise ModelError(f"{r.at(f'{key_path}.profile[{i}]')}: {key} is in {PROFILE_SUFFIX_UNITS[suffix]}, "
                                 f"which does not measure {DIMENSIONS[unit]} ({unit})")
        values, log_spaced = _values(r, entry, key_path)
        if grid and not values:
            raise ModelError(f"{r.at(key_path)}: a grid parameter needs values or a range (or give the study cases)")
        if not grid and values:
            raise ModelError(f"{r.at(key_path)}: the study lists its cases: give the values there, not here")
        grid_points *= max(len(values), 1)
        if grid_points > MAX_CASES:  # from the counts alone: the grid is never built
            raise ModelError(f"{r.at('parameters')}: the grid has more than {MAX_CASES} points already at parameter "
                             f"{name!r} ({' x '.join(str(len(p.values)) for p in out)} x {len(values)}); a study may "
                             f"have at most {MAX_CASES} cases")
        parameter = Parameter(str(name), unit, tuple(sets), values, tuple(profile_keys), log_spaced)
        for i, v in enumerate(values):
            check_point_value(parameter, v, r.at(f"{key_path}.{'values' if 'values' in entry else 'range'}[{i}]"))
        out.append(parameter)
    return tuple(out)


def check_point_value(parameter: Parameter, value: float, where: str) -> None:
    """Refuse ``value`` (in the parameter's unit) if any of its targets cannot take it."""
    for target in parameter.sets:
        check_value(target, to_si(value, parameter.unit, where), f"{where}: {parameter.name} = {value:g} {parameter.unit}")


def _case_points(r: _Reader, raw: Any, parameters: Sequence[Parameter], key_path: str,
                 extra: Sequence[str] = ()) -> list[tuple[tuple[float, ...], dict[str, Any]]]:
    """A list of cases: each a mapping parameter -> value (every parameter given), plus ``extra`` keys."""
    if not isinstance(raw, list):
        raise ModelError(f"{r.at(key_path)}: must be a list of cases (mappings parameter -> value)")
    if not raw:
        raise ModelError(f"{r.at(key_path)}: empty list: give at least one case")
    if len(raw) > MAX_CASES:
        raise ModelError(f"{r.at(key_path)}: {len(raw)} cases; a study may have at most {MAX_CASES}")
    names = [p.name for p in parameters]
    out = []
    for i, case in enumerate(raw):
        case_path = f"{key_path}[{i}]"
        case = r.mapping(case, case_path, [*names, *extra])
        missing = [n for n in names if n not in case]
        if missing:
            raise ModelError(f"{r.at(case_path)}: no value for parameter {missing[0]!r}")
        point = tuple(r.number(case[n], f"{case_path}.{n}") for n in names)
        for p, v in zip(parameters, point):
            check_point_value(p, v, r.at(f"{case_path}.{p.name}"))
        out.append((point, {k: case[k] for k in extra if k in case}))
    return out


def _filters(r: _Reader, raw: Any) -> tuple[FilterChoice, ...]:
    paper = {d.key: d for d in PAPER_FILTERS}
    names = [*paper, PURE_INERTIAL]
    if raw is None:
        raw = names
    if isinstance(raw, list):
        if not raw:
            raise ModelError(f"{r.at('filters')}: empty list: name at least one filter ({', '.join(names)})")
        out = []
        for i, name in enumerate(raw):
            name = r.text(name, f"filters[{i}]", names)
            out.append(FilterChoice(name, paper.get(name)))
    elif isinstance(raw, dict):
        if not raw:
            raise ModelError(f"{r.at('filters')}: empty mapping: name at least one filter")
        out = []
        for name, entry in raw.items():
            key_path = f"filters.{name}"
            entry = r.mapping(entry or {}, key_path, _VARIANT_KEYS)
            like = r.text(entry.get("like", name), key_path + ".like", names)
            if like == PURE_INERTIAL:
                if len(entry) > (1 if "like" in entry else 0):
                    raise ModelError(f"{r.at(key_path)}: the pure-inertial system has no filter settings")
                out.append(FilterChoice(str(name), None))
                continue
            changes: dict[str, Any] = {"key": str(name)}
            for key in ("gain_period", "manoeuvre_gain_period"):
                if key in entry:
                    changes[key] = r.whole(entry[key], f"{key_path}.{key}", 1, 10_000)
            if "whitening" in entry:
                changes["whitening"] = r.text(entry["whitening"], key_path + ".whitening", _WHITENINGS)
            design = replace(paper[like], **changes)
            if "label" not in changes and name != like:
                design = replace(design, label=f"{paper[like].label}, {name}")
            out.append(FilterChoice(str(name), design))
    else:
        raise ModelError(f"{r.at('filters')}: must be a list of filter names or a mapping of variants")
    seen = set()
    for f in out:
        if f.name in seen:
            raise ModelError(f"{r.at('filters')}: filter {f.name!r} named twice")
        seen.add(f.name)
    return tuple(out)


def _monte_carlo(r: _Reader, raw: Any, parameters: Sequence[Parameter], filters: Sequence[FilterChoice],
                 study_dir: Path) -> MonteCarloChoice:
    mc = r.mapping(raw, "monte_carlo", _MONTE_CARLO_KEYS)
    for key in ("profile", "runs", "cases"):
        if key not in mc:
            raise ModelError(f"{r.at('monte_carlo')}: missing key {key!r}")
    profile = r.text(mc["profile"], "monte_carlo.profile")
    builtin = data_path(f"{profile}.yaml") if "/" not in profile and not profile.endswith(".yaml") else None
    profile = _resolve(profile, study_dir, builtin)
    if not Path(profile).is_file():
        raise ModelError(f"{r.at('monte_carlo.profile')}: no such flight-profile file {profile}")
    hours = r.number(mc["hours"], "monte_carlo.hours") if "hours" in mc else None
    if hours is not None and not hours > 0:
        raise ModelError(f"{r.at('monte_carlo.hours')}: must be a positive number of hours, got {hours:g}")
    rate = r.number(mc["imu_rate_hz"], "monte_carlo.imu_rate_hz") if "imu_rate_hz" in mc else None
    if rate is not None and not rate > 0:
        raise ModelError(f"{r.at('monte_carlo.imu_rate_hz')}: must be a positive rate, got {rate:g}")
    check_flight_size(hours, rate, r.at("monte_carlo.hours"), r.at("monte_carlo.imu_rate_hz"))
    runs = r.whole(mc["runs"], "monte_carlo.runs", 1, MAX_RUNS)
    seed = r.whole(mc.get("seed", 0), "monte_carlo.seed", 0, 2**63 - 1)
    lacking = [p.name for p in parameters if not p.profile_keys]
    if lacking:
        raise ModelError(f"{r.at('parameters.' + lacking[0])}: the study has a monte_carlo section, so every "
                         f"parameter needs the flight-profile keys it sets (profile: [SECTION.KEY_unit, ...])")
    cases = _case_points(r, mc["cases"], parameters, "monte_carlo.cases", extra=("filter",))
    for i, (_, extra) in enumerate(cases):
        name = extra.get("filter", "optimal")
        choice = next((f for f in filters if f.name == name), None)
        if choice is None or choice.design is None or choice.design.reduced or choice.design.gain_period != 1 \
                or choice.design.manoeuvre_gain_period != 1:
            raise ModelError(f"{r.at(f'monte_carlo.cases[{i}]')}: filter {name!r}: the Monte Carlo flies the "
                             f"profile's full-model filter with a gain every cycle (an 'optimal' filter of the study)")
    return MonteCarloChoice(profile, hours, rate, runs, seed, tuple(p for p, _ in cases))


@functools.lru_cache(maxsize=None)
def _builtin_truth(name: str) -> ErrorModel:
    """The built-in model ``name``, loaded once in this process (a model is frozen, a package file fixed)."""
    return load_model(name)


def _truth_model(model: str) -> ErrorModel:
    """The study's truth model: a built-in one (its name, no file of that name here) loaded once per process, else the file."""
    if not Path(model).exists() and builtin_model_path(model) is not None:
        return _builtin_truth(model)
    return load_model(model)


def load_study(path: str | Path) -> Study:
    """Read and check a study file (module docstring); nothing is run."""
    path = Path(path)
    if not path.is_file() and path.suffix == "" and data_path(f"studies/{path.name}.yaml").is_file():
        path = data_path(f"studies/{path.name}.yaml")
    data, lines = read_yaml_with_lines(path, "study file")
    r = _Reader(path, lines)
    r.mapping(data, "", _TOP_KEYS)
    study_dir = path.parent
    for key in ("study", "parameters"):
        if key not in data:
            raise ModelError(f"{path}: missing key {key!r}")
    name = r.text(data["study"], "study")
    model = r.text(data.get("model", DEFAULT_MODEL), "model")
    if "/" in model or model.endswith(".yaml"):
        model = _resolve(model, study_dir, None)
    scenario_file = _data_file(r.text(data.get("scenario", SCENARIO_FILE), "scenario"), study_dir)
    budget_file = _data_file(r.text(data.get("budget", BUDGET_FILE), "budget"), study_dir)
    scenario = load_analysis_scenario(scenario_file)
    budget = load_error_budget(budget_file)
    truth = _truth_model(model)
    budget.initial_covariance(truth)  # every state budgeted, or refused now
    missing = [s for s in ("latitude_error", "longitude_error") if s not in truth.state_names]
    if missing:
        raise ModelError(f"{r.at('model')}: model {truth.name!r} has no state {missing[0]!r}: the trade study "
                         f"reports the paper's navigation errors (CEP from latitude_error, longitude_error)")
    grid = "cases" not in data
    parameters = _parameters(r, data["parameters"], budget, budget_file, grid)
    filters = _filters(r, data.get("filters"))
    if grid:
        count = math.prod(len(p.values) for p in parameters)  # from the counts, before the grid is built
    else:
        count = len(data["cases"]) if isinstance(data["cases"], list) else 0
    if count * len(filters) > MAX_CASES:
        raise ModelError(f"{r.at('parameters' if grid else 'cases')}: {count} points x {len(filters)} filters = "
                         f"{count * len(filters)} cases; a study may have at most {MAX_CASES}")
    if grid:
        points = list(itertools.product(*(p.values for p in parameters)))
    else:
        points = [p for p, _ in _case_points(r, data["cases"], parameters, "cases")]
    plot = r.mapping(data.get("plot") or {}, "plot", _PLOT_KEYS)
    plot_x = r.text(plot.get("x", parameters[0].name), "plot.x", [p.name for p in parameters])
    metric = r.text(plot.get("metric", "position_cep"), "plot.metric", [m for m, _ in METRICS])
    monte_carlo = _monte_carlo(r, data["monte_carlo"], parameters, filters, study_dir) if "monte_carlo" in data else None
    return Study(name, str(data.get("title", name)), str(path), truth, scenario, budget, parameters,
                 tuple(tuple(p) for p in points), filters, monte_carlo, plot_x, metric)
