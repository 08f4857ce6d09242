"""Observability of a derived model over a scenario: rank and weak directions.

For the discrete system x_{k+1} = Phi_k x_k, z_k = H_k x_k (Phi_k = e^{F T}
at the operating point of the segment step k belongs to), the observability
matrix over N steps is

    O = [H_0; H_1 Phi_0; H_2 Phi_1 Phi_0; ...; H_{N-1} Phi_{N-2} ... Phi_0].

x_0 can be recovered from noise-free measurements z_0..z_{N-1} exactly when O
has full column rank; a vector v with O v = 0 is an error the measurements
cannot see (e.g. a longitude error under velocity-only aiding: nothing in F
depends on longitude, and H does not measure it).  A scenario is one or more
piecewise-constant segments (operating point + number of steps), so that a
manoeuvre (a turn: a new attitude matrix) can be analysed the way
Goshen-Meskin & Bar-Itzhack's piecewise-constant systems are: O is built
with the true transition across segments, not by stacking separate segment
matrices.

The states have different units (rad, m/s, rad/s), so O is scaled column by
column before its SVD: by default every column to unit norm (a state's
column norm is how strongly the measurements see it alone); optionally by
typical state magnitudes (``scales``, e.g. initial standard deviations).  A
singular value s_i is then read relative to the largest one:

* s_i / s_max <= ``unobservable_rtol``  -> an unobservable direction (counted
  out of the rank).  The default 1e-11 sits between rounding (exact null
  directions come out at 1e-17..1e-15) and the weakest observable
  directions of the library's models over a window of n steps (~1e-8);
* s_i / s_max <= ``weak_rtol``          -> a weakly observable direction.

Each such direction is reported as a combination of named states (its right
singular vector, in the scaled coordinates) listing the dominant components.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from modelgen.derivation.symbolic import DerivedModel
from modelgen.derivation.discretization import van_loan_discretization
from modelgen.fileio.datafiles import read_yaml_with_lines
from modelgen.errors import ModelError

DEFAULT_UNOBSERVABLE_RTOL = 1e-11
DEFAULT_WEAK_RTOL = 1e-3


@dataclass(frozen=True)
class Segment:
    """A stretch of constant operating point: parameter values held for ``steps`` steps."""

    values: Mapping[str, float]
    steps: int


@dataclass(frozen=True)
class ObservabilityScenario:
    """Step length T (s) and the piecewise-constant segments, in time order."""

    step: float
    segments: tuple[Segment, ...]

    @property
    def n_steps(self) -> int:
        return sum(s.steps for s in self.segments)


@dataclass(frozen=True)
class Direction:
    """A direction in state space, with its relative singular value.

    ``components`` lists (state name, coefficient) for the dominant
    components, largest first, of the unit vector in scaled coordinates.
    """

    relative_singular_value: float
    components: tuple[tuple[str, float], ...]

    def describe(self) -> str:
        terms = " ".join(f"{c:+.3f}*{name}" for name, c in self.components)
        if self.relative_singular_value == 0.0:
            return terms
        return f"s/s_max = {self.relative_singular_value:.1e}: {terms}"


@dataclass(frozen=True)
class ObservabilityReport:
    """Rank of the observability matrix and its unobservable / weak directions."""

    model: str
    state_names: tuple[str, ...]
    n_steps: int
    rank: int
    relative_singular_values: tuple[float, ...]
    unobservable: tuple[Direction, ...]
    weak: tuple[Direction, ...]
    #: per state: norm of its unit vector's projection on the unobservable subspace
    #: (0: observable; 1: nothing about it is observable).
    unobservable_share: Mapping[str, float] = field(default_factory=dict)

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    def unobservable_states(self, threshold: float = 0.5) -> list[str]:
        """States mostly inside the unobservable subspace.

        A share strictly between 0 and 1 is a statement in the scaled
        coordinates and changes with the scaling; shares of exactly 0 or 1
        (a state entirely observable, or entirely unobservable like
        longitude under velocity aiding) do not.
        """
        return [n for n in self.state_names if self.unobservable_share[n] > threshold]


# -- scenarios -------------------------------------------------------------------
def single_segment(values: Mapping[str, float], step: float, steps: int) -> ObservabilityScenario:
    """A scenario with one constant operating point."""
    return ObservabilityScenario(step=float(step), segments=(Segment(dict(values), int(steps)),))


def scenario_from_data(data: Any, where: str = "scenario", lines: dict[str, str] | None = None) -> ObservabilityScenario:
    """Build a scenario from plain data (as read from YAML).

    Keys: ``step`` (s, required), ``parameters`` (values shared by all
    segments), and either ``steps`` (one segment) or ``segments`` (a list of
    ``{steps: N, parameters: {...}}`` that override the shared values).
    ``lines`` (key -> ``file:line``) puts the line into messages.
    """
    lines = lines or {}

    def at(key: str) -> str:
        return f"{lines[key]}: {key}" if key in lines else f"{where}: {key}"

    if not isinstance(data, dict):
        raise ModelError(f"{where}: a scenario must be a mapping with keys step, parameters, steps or segments")
    allowed = {"step", "parameters", "steps", "segments", "description"}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ModelError(f"{where}: unknown key {unknown[0]!r} (expected one of {sorted(allowed)})")
    step = _positive_number(data.get("step"), at("step"))
    shared = _values(data.get("parameters") or {}, at("parameters"))
    if ("segments" in data) == ("steps" in data):
        raise ModelError(f"{where}: give either 'steps' (one segment) or 'segments', not both or neither")
    if "steps" in data:
        return ObservabilityScenario(step, (Segment(shared, _positive_int(data["steps"], at("steps"))),))
    raw = data["segments"]
    if not isinstance(raw, list) or not raw:
        raise ModelError(f"{where}: 'segments' must be a non-empty list")
    segments = []
    for i, seg in enumerate(raw):
        place = at(f"segments[{i}]")
        if not isinstance(seg, dict) or set(seg) - {"steps", "parameters"} or "steps" not in seg:
            raise ModelError(f"{place}: a segment is a mapping with 'steps' and optional 'parameters'")
        values = {**shared, **_values(seg.get("parameters") or {}, f"{place}.parameters")}
        segments.append(Segment(values, _positive_int(seg["steps"], f"{place}.steps")))
    return ObservabilityScenario(step, tuple(segments))


def load_scenario(path: str | Path) -> ObservabilityScenario:
    """Read a scenario YAML file (see :func:`scenario_from_data`)."""
    data, lines = read_yaml_with_lines(path, "scenario file")
    return scenario_from_data(data, str(path), lines)


def command_line_scenario(
    path: str | Path | None,
    assignments: Sequence[str] = (),
    step: float | None = None,
    steps: int | None = None,
    default_steps: int = 1,
    base_values: Mapping[str, float] | None = None,
) -> ObservabilityScenario:
    """The scenario of ``modelgen observability``: a file, overridden by options.

    ``assignments`` are ``NAME=VALUE`` strings applied to every segment;
    ``step`` and ``steps`` replace the file's (``steps`` only for a
    one-segment scenario).  Without a file: one segment of ``default_steps``
    steps of 60 s unless given, at ``base_values`` (e.g. the paper's level
    flight) overridden by the assignments.
    """
    overrides: dict[str, float] = {}
    for text in assignments:
        name, sep, value = text.partition("=")
        try:
            if not sep or not name.strip():
                raise ValueError
            overrides[name.strip()] = float(value)
        except ValueError:
            raise ModelError(f"--set {text!r}: expected NAME=VALUE with a number as VALUE") from None
    base = load_scenario(path) if path is not None else single_segment(dict(base_values or {}), 60.0, default_steps)
    if steps is not None and len(base.segments) > 1:
        raise ModelError("--steps applies to a one-segment scenario; this scenario has segments")
    new_step = _positive_number(step, "--step") if step is not None else base.step
    segments = tuple(
        Segment({**seg.values, **overrides}, _positive_int(steps, "--steps") if steps is not None else seg.steps)
        for seg in base.segments
    )
    return ObservabilityScenario(new_step, segments)


def _positive_number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
        raise ModelError(f"{where} must be a positive number, not {value!r}")
    return float(value)


def _positive_int(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ModelError(f"{where} must be a positive integer, not {value!r}")
    return value


def _values(data: Any, where: str) -> dict[str, float]:
    if not isinstance(data, dict):
        raise ModelError(f"{where} must map parameter names to numbers")
    out = {}
    for key, value in data.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ModelError(f"{where}.{key}: {value!r} is not a number")
        out[str(key)] = float(value)
    return out


# -- the observability matrix ------------------------------------------------------
def observability_matrix(derived: DerivedModel, scenario: ObservabilityScenario) -> np.ndarray:
    """O = [H_0; H_1 Phi_0; ...] over all steps of the scenario (see module doc)."""
    if derived.n_measurements == 0:
        raise ModelError(f"model {derived.model.name!r} has no measurements: nothing is observable")
    n = derived.n_states
    blocks = []
    transition = np.eye(n)  # Phi_{k-1} ... Phi_0
    for segment in scenario.segments:
        num = derived.numeric(segment.values)
        phi, _ = van_loan_discretization(num["F"], num["G"], num["Q"], scenario.step)
        for _ in range(segment.steps):
            blocks.append(num["H"] @ transition)
            transition = phi @ transition
    return np.vstack(blocks)


#: Rows of O (steps x measurements) above which the analysis is refused: ~1 GB of doubles
#: for a 100-state model, and far more steps than any direction needs to show up.
MAX_OBSERVABILITY_ROWS = 1_000_000


def analyse(
    derived: DerivedModel,
    scenario: ObservabilityScenario,
    scales: Mapping[str, float] | None = None,
    unobservable_rtol: float = DEFAULT_UNOBSERVABLE_RTOL,
    weak_rtol: float = DEFAULT_WEAK_RTOL,
    max_components: int = 4,
    min_component: float = 0.05,
) -> ObservabilityReport:
    """Rank and unobservable / weakly observable directions (see module doc)."""
    if not 0 < unobservable_rtol < weak_rtol < 1:
        raise ModelError(f"need 0 < unobservable_rtol < weak_rtol < 1, got {unobservable_rtol}, {weak_rtol}")
    names = tuple(derived.model.state_names)
    rows = scenario.n_steps * max(derived.n_measurements, 1)
    if rows > MAX_OBSERVABILITY_ROWS:
        raise ModelError(
            f"scenario of {scenario.n_steps} steps: the observability matrix would have {rows} rows "
            f"(limit {MAX_OBSERVABILITY_ROWS}); use fewer steps or a longer step"
        )
    O = observability_matrix(derived, scenario)
    column_scale = _column_scales(O, names, scales)
    _, s, vt = np.linalg.svd(O * column_scale, full_matrices=True)
    s_full = np.zeros(len(names))
    s_full[: len(s)] = s
    s_max = s_full.max()
    relative = s_full / s_max if s_max > 0 else s_full
    unobservable_idx = [i for i, r in enumerate(relative) if r <= unobservable_rtol]
    weak_idx = [i for i, r in enumerate(relative) if unobservable_rtol < r <= weak_rtol]

    def direction(i: int) -> Direction:
        v = vt[i] / np.linalg.norm(vt[i])
        v = v * np.sign(v[np.argmax(np.abs(v))])
        order = np.argsort(-np.abs(v))
        comps = tuple((names[j], float(v[j])) for j in order[:max_components] if abs(v[j]) >= min_component)
        return Direction(float(relative[i]), comps)

    null_basis = vt[unobservable_idx] if unobservable_idx else np.zeros((0, len(names)))
    share = {name: float(np.linalg.norm(null_basis[:, j])) for j, name in enumerate(names)}
    unobservable = []
    for vector in _readable_basis(null_basis):
        order = np.argsort(-np.abs(vector))
        comps = tuple((names[j], float(vector[j])) for j in order[:max_components] if abs(vector[j]) >= min_component)
        unobservable.append(Direction(0.0, comps))
    return ObservabilityReport(
        model=derived.model.name,
        state_names=names,
        n_steps=scenario.n_steps,
        rank=len(names) - len(unobservable_idx),
        relative_singular_values=tuple(float(r) for r in relative),
        unobservable=tuple(unobservable),
        weak=tuple(direction(i) for i in weak_idx),
        unobservable_share=share,
    )


def _readable_basis(basis: np.ndarray) -> list[np.ndarray]:
    """A basis of the same subspace in which as many vectors as possible are single states.

    The SVD's null-space basis is arbitrary within the subspace when several
    singular values are zero.  Gauss-Jordan elimination with the largest
    remaining entry as pivot (reduced row echelon form) gives the basis in
    which each vector has its own pivot state and zeros at the others'
    pivots: a state alone in the subspace (longitude under velocity aiding)
    comes out as that state alone.  Vectors are normalized, largest
    component positive.
    """
    rows = [r.astype(float).copy() for r in basis]
    out: list[np.ndarray] = []
    used: set[int] = set()
    while rows:
        k, j = max(
            ((k, j) for k, r in enumerate(rows) for j in range(r.size) if j not in used),
            key=lambda kj: abs(rows[kj[0]][kj[1]]),
        )
        pivot = rows.pop(k)
        pivot = pivot / pivot[j]
        rows = [r - r[j] * pivot for r in rows]
        out = [o - o[j] * pivot for o in out]
        out.append(pivot)
        used.add(j)
    result = []
    for v in out:
        v = np.where(np.abs(v) < 1e-12, 0.0, v)
        v = v / np.linalg.norm(v)
        result.append(v * np.sign(v[np.argmax(np.abs(v))]))
    return result


def _column_scales(O: np.ndarray, names: Sequence[str], scales: Mapping[str, float] | None) -> np.ndarray:
    """Per-column factors: given state magnitudes, or 1/column norm (zero columns stay 1)."""
    if scales is not None:
        unknown = sorted(set(scales) - set(names))
        if unknown:
            raise ModelError(f"scales given for unknown state(s) {', '.join(unknown)}")
        missing = [n for n in names if n not in scales]
        if missing:
            raise ModelError(f"no scale given for state(s) {', '.join(missing)}")
        out = np.array([float(scales[n]) for n in names])
        if np.any(~np.isfinite(out)) or np.any(out <= 0):
            raise ModelError("state scales must be positive numbers")
        return out
    norms = np.linalg.norm(O, axis=0)
    return np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)


def format_report(report: ObservabilityReport) -> str:
    """The report as text for the command line."""
    lines = [
        f"model {report.model}: {report.n_states} states, {report.n_steps} steps",
        f"rank of the observability matrix: {report.rank} of {report.n_states}",
        "relative singular values: " + " ".join(f"{r:.1e}" for r in report.relative_singular_values),
    ]
    if report.unobservable:
        lines.append(f"unobservable directions ({len(report.unobservable)}):")
        lines += [f"  {d.describe()}" for d in report.unobservable]
        states = report.unobservable_states()
        if states:
            lines.append("states (mostly) unobservable: " + ", ".join(states))
    else:
        lines.append("no unobservable direction")
    if report.weak:
        lines.append(f"weakly observable directions ({len(report.weak)}):")
        lines += [f"  {d.describe()}" for d in report.weak]
    return "\n".join(lines)
