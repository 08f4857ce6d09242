"""The ``check:`` section of a model file: the scenario ``--check`` flies.

A model file may declare the operating point and filter set-up that the
generated code is checked over (``modelgen generate --check``, ``modelgen
run``, ``modelgen embedded``)::

    check:
      step_s: 1.0                 # filter step T in seconds
      steps: 120                  # predict + update cycles
      parameters:                 # values for the parameters without a default
        latitude: {value: 45, unit: deg}     # a number (SI) or {value, unit}
        c11: 0.866
      initial_sigma:              # 1-sigma of every state at t = 0 (uncorrelated) ...
        position_error_north: {value: 5, unit: m}
      # initial_covariance: [[...], ...]   # ... or the full P(0), in state order
      seed: 0                     # optional: seed of the measurement noise

The measurement noise is drawn with the variances the model's own
parameters give, so realistic sensor statistics make realistic innovations.
Values are plain data: numbers, or a number with one of the units of
``modelgen.model.units``; nothing in the section is evaluated.

A transform file (``base:``) inherits its base model's section; a ``check:``
section in the transform file is laid over it key by key (``parameters`` and
``initial_sigma`` entry by entry), so an augmented model only adds what its new
states and parameters need.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from modelgen.model.units import to_si
from modelgen.errors import ModelError

CHECK_KEYS = frozenset({"step_s", "steps", "parameters", "initial_sigma", "initial_covariance", "seed"})
#: More steps than this make --check slow without checking more code.
MAX_CHECK_STEPS = 100_000


@dataclass(frozen=True)
class CheckSpec:
    """A model's declared check scenario, in SI, not yet tied to a state order."""

    step_s: float
    steps: int
    parameters: tuple[tuple[str, float], ...]
    initial_sigma: tuple[tuple[str, float], ...] = ()
    initial_covariance: tuple[tuple[float, ...], ...] | None = None
    seed: int = 0
    #: Where the section is (``file:line``), for the messages about the scenario; no part of the declaration.
    where: str = field(default="", compare=False)

    def parameter_values(self) -> dict[str, float]:
        return dict(self.parameters)

    def as_section(self) -> dict[str, Any]:
        """The spec as a parsed section again, for a transform file to lay its own over."""
        out: dict[str, Any] = {"step_s": self.step_s, "steps": self.steps, "seed": self.seed, "parameters": dict(self.parameters)}
        if self.initial_covariance is not None:
            out["initial_covariance"] = self.initial_covariance
        else:
            out["initial_sigma"] = dict(self.initial_sigma)
        return out

    def covariance(self, state_names: list[str], model: str) -> np.ndarray:
        """P(0) in the given state order: the full matrix, or diag(sigma^2)."""
        if self.initial_covariance is not None:
            return np.array(self.initial_covariance, dtype=float)
        sigma = dict(self.initial_sigma)
        missing = [s for s in state_names if s not in sigma]
        if missing:
            raise ModelError(f"model {model!r}: check scenario gives no initial_sigma for state(s) {', '.join(missing)}")
        return np.diag([sigma[s] ** 2 for s in state_names])


def _si(value: Any, where: str) -> float:
    """A finite number, given plainly (SI) or as ``{value, unit}``."""
    if isinstance(value, Mapping):
        extra = sorted(set(value) - {"value", "unit"})
        if extra or "value" not in value:
            raise ModelError(f"{where}: expected a number or {{value: <number>, unit: <unit>}}, got keys {sorted(value)}")
        if isinstance(value["value"], bool):
            raise ModelError(f"{where}: {value['value']!r} is not a number")
        return to_si(value["value"], str(value.get("unit", "1")), where)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ModelError(f"{where}: {value!r} is not a number")
    if not math.isfinite(value):
        raise ModelError(f"{where}: {value!r} is not finite")
    return float(value)


def _named_values(raw: Any, key: str, lines: Mapping[str, str], place: str, positive: bool = False, lists: bool = False) -> dict[str, Any]:
    """Names to SI numbers; with ``lists`` a name may also take a list (per axis of a vector stem, :func:`expand_stems`)."""
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        raise ModelError(f"{place}: check.{key} must map names to values")
    out: dict[str, Any] = {}
    for name, value in raw.items():
        where = f"{lines.get(f'check.{key}.{name}', place)}: check.{key}.{name}"
        if lists and isinstance(value, Mapping) and isinstance(value.get("value"), list):  # {value: [..], unit: u}
            value = [{"value": v, "unit": value.get("unit", "1")} for v in value["value"]]
        numbers = [_si(v, f"{where}[{i}]") for i, v in enumerate(value)] if lists and isinstance(value, list) else [_si(value, where)]
        for number in numbers:
            if positive and number < 0:
                raise ModelError(f"{where}: a standard deviation cannot be negative ({number!r})")
        out[str(name)] = numbers if isinstance(value, list) and lists else numbers[0]
    return out


def expand_stems(values: Mapping[str, Any], state_names: Sequence[str], place: str) -> dict[str, float]:
    """``initial_sigma`` entries by vector stem: ``gyro_bias: 0.01`` (every axis) or ``gyro_bias: [a, b, c]`` (per axis)
    for the states ``gyro_bias_x, gyro_bias_y, gyro_bias_z``; a state's own entry wins over its stem's
    (an augmented model's section may set one axis over its base's stem).

    Refused: a list for a single state and a list of the wrong length; a key that is neither a state
    nor a stem is kept, for the caller to name as unknown.
    """
    names = list(state_names)
    out: dict[str, float] = {}
    for key, value in values.items():
        if key in names:
            if isinstance(value, list):
                raise ModelError(f"{place}: check.initial_sigma.{key}: {key!r} is one state; give one number, not a list of {len(value)}")
            out[key] = value
            continue
        members = [n for n in names if n.startswith(f"{key}_") and "_" not in n[len(key) + 1:]]
        if not members:
            out[key] = value  # unknown: build_check_spec names it
            continue
        numbers = value if isinstance(value, list) else [value] * len(members)
        if len(numbers) != len(members):
            raise ModelError(
                f"{place}: check.initial_sigma.{key} lists {len(numbers)} values for the {len(members)} states {', '.join(members)}"
            )
        for member, number in zip(members, numbers):
            if member not in values:
                out[member] = number
    return out


def parse_check_section(raw: Any, lines: Mapping[str, str], filename: str) -> dict[str, Any]:
    """The ``check:`` mapping validated for form and turned into SI (not yet against a model)."""
    place = lines.get("check", filename)
    if not isinstance(raw, Mapping):
        raise ModelError(f"{place}: 'check' must be a mapping with keys {sorted(CHECK_KEYS)}")
    unknown = sorted(set(raw) - CHECK_KEYS)
    if unknown:
        raise ModelError(f"{lines.get(f'check.{unknown[0]}', place)}: unknown key check.{unknown[0]} (expected one of {sorted(CHECK_KEYS)})")
    out: dict[str, Any] = {}
    if "step_s" in raw:
        where = f"{lines.get('check.step_s', place)}: check.step_s"
        step = _si(raw["step_s"], where)
        if not step > 0:
            raise ModelError(f"{where}: the step must be positive (got {step!r})")
        out["step_s"] = step
    for key in ("steps", "seed"):
        if key in raw:
            value = raw[key]
            where = f"{lines.get(f'check.{key}', place)}: check.{key}"
            if isinstance(value, bool) or not isinstance(value, int) or value < (1 if key == "steps" else 0):
                raise ModelError(f"{where}: expected a {'positive' if key == 'steps' else 'non-negative'} integer, got {value!r}")
            if key == "steps" and value > MAX_CHECK_STEPS:
                raise ModelError(f"{where}: {value} steps is more than the limit of {MAX_CHECK_STEPS}")
            out[key] = value
    if "parameters" in raw:
        out["parameters"] = _named_values(raw["parameters"], "parameters", lines, place)
    if "initial_sigma" in raw:
        out["initial_sigma"] = _named_values(raw["initial_sigma"], "initial_sigma", lines, place, positive=True, lists=True)
    if "initial_covariance" in raw:
        out["initial_covariance"] = _matrix(raw["initial_covariance"], f"{lines.get('check.initial_covariance', place)}: check.initial_covariance")
    if "initial_sigma" in out and "initial_covariance" in out:
        raise ModelError(f"{place}: check gives both initial_sigma and initial_covariance; give one")
    return out


def _matrix(raw: Any, where: str) -> tuple[tuple[float, ...], ...]:
    """A square, symmetric, positive semidefinite matrix of plain numbers."""
    if not isinstance(raw, list) or not raw or not all(isinstance(row, list) and len(row) == len(raw) for row in raw):
        raise ModelError(f"{where}: expected a square matrix (a list of equally long rows)")
    rows = tuple(tuple(_si(v, f"{where}[{i}][{j}]") for j, v in enumerate(row)) for i, row in enumerate(raw))
    P = np.array(rows)
    if not np.array_equal(P, P.T):
        raise ModelError(f"{where}: the initial covariance is not symmetric")
    if np.linalg.eigvalsh(P).min() < -1e-12 * max(1.0, float(np.abs(P).max())):
        raise ModelError(f"{where}: the initial covariance is not positive semidefinite")
    return rows


def merge_check_sections(base: Mapping[str, Any] | None, over: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """``over`` laid on ``base`` key by key; parameters and sigmas entry by entry."""
    if base is None and over is None:
        return None
    merged = dict(base or {})
    for key, value in (over or {}).items():
        if key in ("parameters", "initial_sigma"):
            merged[key] = {**merged.get(key, {}), **value}
        else:
            merged[key] = value
    if "initial_covariance" in (over or {}):
        merged.pop("initial_sigma", None)
    if "initial_sigma" in (over or {}):
        merged.pop("initial_covariance", None)
    return merged


def build_check_spec(
    section: Mapping[str, Any] | None, model: Any, place: str, inherited: bool = False, partial: bool = False
) -> CheckSpec | None:
    """The section checked against ``model`` (an ErrorModel): every name known, nothing missing.

    Refused: a parameter or state the model does not declare (unless the
    section is ``inherited`` from a base model whose states a transform
    removed: those entries are dropped; with ``partial`` only names are
    checked), a parameter
    without a default that is not given, a state without a sigma, a matrix of
    the wrong size, a missing step or number of steps.
    """
    if section is None:
        return None
    for key in ("step_s", "steps"):
        if key not in section:
            raise ModelError(f"{place}: model {model.name!r}: check section has no {key!r}")
    params = dict(section.get("parameters", {}))
    known = set(model.parameter_names)
    if inherited:
        params = {k: v for k, v in params.items() if k in known}
    unknown = sorted(set(params) - known)
    if unknown:
        raise ModelError(f"{place}: model {model.name!r}: check.parameters names unknown parameter(s) {', '.join(unknown)}")
    missing = [p.name for p in model.parameters if p.value is None and p.name not in params]
    if partial:  # only the names are checked (a section to be laid over an inherited one)
        unknown = sorted(set(expand_stems(section.get("initial_sigma", {}), model.state_names, place)) - set(model.state_names))
        if unknown:
            raise ModelError(f"{place}: model {model.name!r}: check.initial_sigma names unknown state(s) {', '.join(unknown)}")
        return None
    if missing:
        raise ModelError(f"{place}: model {model.name!r}: check.parameters gives no value for {', '.join(missing)} (no default)")
    n = len(model.states)
    cov = section.get("initial_covariance")
    sigma = expand_stems(dict(section.get("initial_sigma", {})), model.state_names, place)
    if inherited:
        sigma = {k: v for k, v in sigma.items() if k in set(model.state_names)}
    if cov is not None and len(cov) != n:
        raise ModelError(f"{place}: model {model.name!r}: check.initial_covariance is {len(cov)}x{len(cov)}, the model has {n} states")
    if cov is None:
        unknown = sorted(set(sigma) - set(model.state_names))
        missing = [s for s in model.state_names if s not in sigma]
        if unknown or missing:
            what = f"unknown state(s) {', '.join(unknown)}" if unknown else f"no sigma for state(s) {', '.join(missing)}"
            raise ModelError(f"{place}: model {model.name!r}: check.initial_sigma: {what}")
    return CheckSpec(
        step_s=float(section["step_s"]),
        steps=int(section["steps"]),
        parameters=tuple(sorted(params.items())),
        initial_sigma=tuple((s, sigma[s]) for s in model.state_names) if cov is None else (),
        initial_covariance=cov,
        seed=int(section.get("seed", 0)),
        where=place,
    )
