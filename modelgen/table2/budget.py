"""The error budget (the core paper, Table 1): initial covariance and error statistics."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from modelgen.fileio.datafiles import data_path, read_yaml, require
from modelgen.model.units import to_si
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel

BUDGET_FILE = "error_budget_000.yaml"


@dataclass(frozen=True)
class ErrorBudget:
    """Initial 1-sigma of each state and the values of the statistic parameters (SI)."""

    name: str
    initial_sigma: Mapping[str, float]
    parameters: Mapping[str, float]
    inferred: Mapping[str, str] = field(default_factory=dict)  # parameter -> what it was inferred from

    def initial_covariance(self, model: ErrorModel) -> np.ndarray:
        """Diagonal P(0) in the model's state order; every state must be budgeted."""
        missing = [s for s in model.state_names if s not in self.initial_sigma]
        if missing:
            raise ModelError(f"error budget {self.name!r}: no initial sigma for state(s) {', '.join(missing)} of model {model.name!r}")
        return np.diag([self.initial_sigma[s] ** 2 for s in model.state_names])

    def with_parameters(self, **values: float) -> "ErrorBudget":
        """The same budget with some parameter values replaced (SI)."""
        unknown = sorted(set(values) - set(self.parameters))
        if unknown:
            raise ModelError(f"error budget {self.name!r}: no parameter named {', '.join(unknown)}")
        return ErrorBudget(self.name, self.initial_sigma, {**self.parameters, **values}, self.inferred)


def _parameter_value(name: str, entry: Mapping, where: str) -> float:
    """SI value of one parameter entry: ``{value, unit}`` or ``{correlation_time, unit}``."""
    if not isinstance(entry, Mapping):
        raise ModelError(f"{where}: parameter {name!r} must be a mapping with a value and a unit")
    unit = require(entry, "unit", f"{where}: parameters.{name}")
    if "correlation_time" in entry:
        tau = to_si(entry["correlation_time"], unit, f"{where}: parameters.{name}.correlation_time")
        if tau <= 0:
            raise ModelError(f"{where}: parameters.{name}.correlation_time must be positive")
        return 1.0 / tau  # the model's inverse correlation time mu
    value = to_si(require(entry, "value", f"{where}: parameters.{name}"), unit, f"{where}: parameters.{name}.value")
    if value < 0:
        raise ModelError(f"{where}: parameters.{name}.value must not be negative")
    return value


def load_error_budget(path: str | Path | None = None) -> ErrorBudget:
    """Read an error-budget file (default: the core paper's, ``error_budget_000.yaml``)."""
    path = Path(path) if path is not None else data_path(BUDGET_FILE)
    data = read_yaml(path)
    where = str(path)
    sigmas = {}
    for state, entry in require(data, "initial_sigma", where).items():
        sw = f"{where}: initial_sigma.{state}"
        if not isinstance(entry, Mapping):
            raise ModelError(f"{sw}: must be a mapping with a value and a unit")
        value = to_si(require(entry, "value", sw), require(entry, "unit", sw), sw)
        if value < 0:
            raise ModelError(f"{sw}: a standard deviation cannot be negative")
        sigmas[state] = value
    raw = require(data, "parameters", where)
    parameters = {name: _parameter_value(name, entry, where) for name, entry in raw.items()}
    inferred = {name: str(entry["inferred_from"]) for name, entry in raw.items() if "inferred_from" in entry}
    return ErrorBudget(str(require(data, "budget", where)), sigmas, parameters, inferred)
