"""The cross-check: a hand-written error model against its twin derived from the navigation equations.

Each built-in hand-written model (``ned_doppler18``, ``ins_gps15`` ...) has a
twin that declares the navigation equations instead of the error equations
(``<model>_twin.yaml``, same states in the same order); modelgen derives the
twin's error model.  This module compares the two F, G, H entry by entry and
says, for every entry, whether they agree and, where they do not, why:

``equal``
    the hand entry is the derived one;
``convention``
    they agree once a declared sign convention is applied (a state or noise
    the hand model defines with the opposite sign, e.g. gyro drift as
    "true minus measured": x_hand = -x_twin negates its row and column);
``approximation``
    the hand entry is the derived one without terms that a named
    approximation the twin declares drops (single Earth radius, no gravity
    variation ...); ``term`` is the dropped part, ``magnitude`` its size at
    the hand model's check scenario;
``hand_model_error``
    the difference is declared an error of the hand model in the pair's data
    (fixed there, or reported when the hand model is the paper's);
``unexplained``
    none of these: the report shows automatic hints
    (:mod:`modelgen.checks.hints`).

``derived`` is always the full first-order linearization: the twin's entry
plus every term its declared approximations drop.  What explains a
difference is data (``modelgen/data/crosscheck.yaml``: conventions,
hand-model errors, the mapping of the twin's parameters onto the hand
model's) and the derivation engine's list of neglected terms; nothing is
matched by the name of a model.

Public API (used by ``modelgen run`` and the tests)::

    pairs = load_pairs()                          # modelgen/data/crosscheck.yaml
    result = cross_check(pairs[0], hand, twin, neglected)   # two DerivedModels
    write_crosscheck_report([result, ...], folder)         # crosscheck.md + .json
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import sympy as sp

from modelgen.checks.hints import difference_hints, same
from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path, read_yaml_with_lines
from modelgen.fileio.output import write_text_atomically
from modelgen.model import navlib
from modelgen.model.declaration import ErrorModel

#: The data file listing every (hand-written model, twin) pair and what explains their differences.
PAIRS_FILE = "crosscheck.yaml"
MATRICES = ("F", "G", "H")
STATUSES = ("equal", "approximation", "convention", "hand_model_error", "unexplained")
#: Fields of every record of crosscheck.json, in this order.
RECORD_FIELDS = ("model", "matrix", "row", "column", "hand", "derived", "status", "term", "magnitude", "reason")
#: Most neglected terms of one entry tried together when matching a hand entry (subsets, smallest first).
MAX_COMBINED_APPROXIMATIONS = 4

_PAIR_KEYS = {"hand", "twin", "symbols", "states", "unmodelled", "conventions", "hand_model_errors"}
_UNMODELLED_KEYS = {"states", "noises", "approximation", "reason"}
_CONVENTION_KEYS = {"name", "states", "noises", "reason"}
_ERROR_KEYS = {"matrix", "row", "column", "reason", "fixed"}


# -- the data ------------------------------------------------------------------
@dataclass(frozen=True)
class Convention:
    """A stated convention: the hand model defines these states/noises with the opposite sign to the twin's."""

    name: str
    states: tuple[str, ...]
    noises: tuple[str, ...]
    reason: str


@dataclass(frozen=True)
class Unmodelled:
    """Twin states (or noises) the hand model leaves out altogether, under a named approximation.

    The twin's couplings from them into the hand model's states are the terms
    that approximation drops (e.g. the paper's "no vertical channel": the
    twin has dV_d and dh, the hand model has neither).
    """

    states: tuple[str, ...]
    noises: tuple[str, ...]
    approximation: str
    reason: str


@dataclass(frozen=True)
class HandModelError:
    """An entry of the hand model declared wrong (row/column by symbol); ``fixed`` if the hand model was corrected."""

    matrix: str
    row: str
    column: str
    reason: str
    fixed: bool = False


@dataclass(frozen=True)
class Pair:
    """One hand-written model and its twin, with what may explain their differences.

    ``symbols`` renames a parameter symbol of the hand model to the twin's
    and ``states`` a state or noise symbol (same spelling needs no entry):
    quantities are matched by symbol, not by position.  ``unmodelled`` lists
    the twin's states and noises the hand model leaves out.
    """

    hand: str
    twin: str
    symbols: Mapping[str, str] = field(default_factory=dict)
    states: Mapping[str, str] = field(default_factory=dict)
    unmodelled: tuple[Unmodelled, ...] = ()
    conventions: tuple[Convention, ...] = ()
    hand_model_errors: tuple[HandModelError, ...] = ()


@dataclass(frozen=True)
class NeglectedTerm:
    """A term of the full first-order derivation that a declared approximation drops.

    ``row`` and ``column`` are 0-based indices into the twin's F, G or H;
    ``term`` is in the twin's parameter symbols (the derivation engine's
    :class:`modelgen.model.perturbation.problem.NeglectedTerm` has the same fields).
    """

    matrix: str
    row: int
    column: int
    term: sp.Expr
    approximation: str


def load_pairs(path: str | Path | None = None) -> list[Pair]:
    """The pairs of ``modelgen/data/crosscheck.yaml`` (or ``path``), validated (errors name file:line)."""
    path = Path(path) if path is not None else data_path(PAIRS_FILE)
    data, lines = read_yaml_with_lines(path, "cross-check file")
    where = path.name
    unknown = sorted(set(data) - {"pairs"})
    if unknown:
        raise ModelError(f"{where}: unknown key {unknown[0]!r} (expected 'pairs')")
    items = data.get("pairs")
    if not isinstance(items, list) or not items:
        raise ModelError(f"{where}: 'pairs' must be a non-empty list")
    pairs = [_pair(item, f"{lines.get(f'pairs[{i}]', where)}: pairs[{i}]") for i, item in enumerate(items)]
    twins = [p.twin for p in pairs]
    duplicates = sorted({t for t in twins if twins.count(t) > 1})
    if duplicates:
        raise ModelError(f"{where}: twin {duplicates[0]!r} is listed in more than one pair")
    return pairs


def _mapping(value: Any, where: str, allowed: set[str], required: set[str]) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ModelError(f"{where}: expected a mapping")
    unknown = sorted(set(value) - allowed)
    if unknown:
        raise ModelError(f"{where}: unknown key {unknown[0]!r} (expected one of {sorted(allowed)})")
    missing = sorted(required - set(value))
    if missing:
        raise ModelError(f"{where}: missing key {missing[0]!r}")
    return value


def _names(value: Any, where: str) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ModelError(f"{where}: expected a list of names")
    return tuple(value)


def _pair(item: Any, where: str) -> Pair:
    item = _mapping(item, where, _PAIR_KEYS, {"hand", "twin"})
    symbols = item.get("symbols") or {}
    if not isinstance(symbols, dict):
        raise ModelError(f"{where}.symbols: expected a mapping hand-model symbol -> twin symbol")
    conventions = []
    for k, c in enumerate(item.get("conventions") or []):
        place = f"{where}.conventions[{k}]"
        c = _mapping(c, place, _CONVENTION_KEYS, {"name", "reason"})
        conventions.append(Convention(
            name=str(c["name"]),
            states=_names(c.get("states") or [], f"{place}.states"),
            noises=_names(c.get("noises") or [], f"{place}.noises"),
            reason=str(c["reason"]),
        ))
    renames = item.get("states") or {}
    if not isinstance(renames, dict):
        raise ModelError(f"{where}.states: expected a mapping hand-model state or noise symbol -> twin symbol")
    unmodelled = []
    for k, u in enumerate(item.get("unmodelled") or []):
        place = f"{where}.unmodelled[{k}]"
        u = _mapping(u, place, _UNMODELLED_KEYS, {"approximation", "reason"})
        unmodelled.append(Unmodelled(
            states=_names(u.get("states") or [], f"{place}.states"), noises=_names(u.get("noises") or [], f"{place}.noises"),
            approximation=str(u["approximation"]), reason=str(u["reason"]),
        ))
    errors = []
    for k, e in enumerate(item.get("hand_model_errors") or []):
        e = _mapping(e, f"{where}.hand_model_errors[{k}]", _ERROR_KEYS, {"matrix", "row", "column", "reason"})
        if e["matrix"] not in MATRICES:
            raise ModelError(f"{where}.hand_model_errors[{k}]: matrix must be one of {', '.join(MATRICES)}")
        errors.append(HandModelError(str(e["matrix"]), str(e["row"]), str(e["column"]), str(e["reason"]), bool(e.get("fixed", False))))
    return Pair(
        str(item["hand"]), str(item["twin"]), {str(k): str(v) for k, v in symbols.items()},
        {str(k): str(v) for k, v in renames.items()}, tuple(unmodelled), tuple(conventions), tuple(errors),
    )


# -- the hand model in the twin's terms ---------------------------------------------
def hand_substitution(pair: Pair, hand: ErrorModel, twin: ErrorModel) -> dict[sp.Symbol, sp.Symbol]:
    """Each hand parameter symbol renamed to the twin's (the pair's ``symbols``; same spelling by default).

    The comparison is made in the twin's symbols because the twin has the
    richer set (R_M, R_N, h ... where the hand model may have one R): the
    terms its approximations drop are written in them.  A hand parameter with
    no twin counterpart is refused, naming it.
    """
    theirs = {p.symbol: p.sym for p in twin.parameters}
    out: dict[sp.Symbol, sp.Symbol] = {}
    missing = []
    for p in hand.parameters:
        target = pair.symbols.get(p.symbol, p.symbol)
        if target in theirs:
            out[p.sym] = theirs[target]
        else:
            missing.append(p.symbol if target == p.symbol else f"{p.symbol} -> {target}")
    if missing:
        raise ModelError(
            f"{PAIRS_FILE}: pair {pair.hand}/{pair.twin}: hand parameter(s) {', '.join(missing)} have no parameter of "
            f"that name in {pair.twin} (map them in 'symbols')"
        )
    return out


@dataclass(frozen=True)
class Layout:
    """Where each hand-model state, noise and measurement sits in the twin (0-based twin indices)."""

    states: tuple[int, ...]
    noises: tuple[int, ...]
    measurements: tuple[int, ...]
    unmodelled_states: Mapping[int, Unmodelled]  # twin index -> why the hand model leaves it out
    unmodelled_noises: Mapping[int, Unmodelled]

    def index(self, matrix: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """Twin row and column indices of the hand model's rows and columns of ``matrix``."""
        return {"F": (self.states, self.states), "G": (self.states, self.noises), "H": (self.measurements, self.states),
                "Q": (self.noises, self.noises)}[matrix]


def layout(pair: Pair, hand: ErrorModel, twin: ErrorModel) -> Layout:
    """Match the hand model's quantities with the twin's by symbol (renamed by the pair's ``states``).

    Measurements match by symbol when every hand symbol is the twin's, else by
    order.  A hand quantity the twin lacks, or a twin quantity the hand model
    lacks without an ``unmodelled`` declaration, is refused, naming both lists.
    """
    def match(kind: str, mine, theirs, declared: dict[str, Unmodelled]) -> tuple[tuple[int, ...], dict[int, Unmodelled]]:
        where = {q.symbol: k for k, q in enumerate(theirs)}
        wanted = [pair.states.get(q.symbol, q.symbol) for q in mine]
        missing = [w for w in wanted if w not in where]
        extra = [q.symbol for q in theirs if q.symbol not in wanted and q.symbol not in declared]
        if missing or extra:
            raise ModelError(
                f"pair {pair.hand}/{pair.twin}: {kind} do not match (hand: {', '.join(q.symbol for q in mine) or '-'}; "
                f"twin: {', '.join(q.symbol for q in theirs) or '-'}); missing in the twin: {', '.join(missing) or '-'}; "
                f"in the twin only, not declared unmodelled: {', '.join(extra) or '-'}"
            )
        return tuple(where[w] for w in wanted), {where[s]: u for s, u in declared.items() if s in where}

    unmodelled_states = {s: u for u in pair.unmodelled for s in u.states}
    unmodelled_noises = {s: u for u in pair.unmodelled for s in u.noises}
    states, lost_states = match("states", hand.states, twin.states, unmodelled_states)
    noises, lost_noises = match("noises", hand.noises, twin.noises, unmodelled_noises)
    theirs = [m.symbol for m in twin.measurements]
    if all(m.symbol in theirs for m in hand.measurements) and len(theirs) == len(hand.measurements):
        measurements = tuple(theirs.index(m.symbol) for m in hand.measurements)
    elif len(theirs) == len(hand.measurements):
        measurements = tuple(range(len(theirs)))
    else:
        raise ModelError(
            f"pair {pair.hand}/{pair.twin}: {len(hand.measurements)} hand measurements "
            f"({', '.join(m.symbol for m in hand.measurements)}) against {len(theirs)} in the twin ({', '.join(theirs)})"
        )
    return Layout(states, noises, measurements, lost_states, lost_noises)


def signs(pair: Pair, hand: ErrorModel) -> tuple[list[int], list[int]]:
    """The sign s_i of each hand state and noise relative to the twin's (x_hand = s x_twin), from the conventions."""
    state_sign = {s.symbol: 1 for s in hand.states}
    noise_sign = {w.symbol: 1 for w in hand.noises}
    for c in pair.conventions:
        for table, names, kind in ((state_sign, c.states, "state"), (noise_sign, c.noises, "noise")):
            for name in names:
                if name not in table:
                    raise ModelError(f"{PAIRS_FILE}: convention {c.name!r} names {kind} {name!r}, not a {kind} of {hand.name}")
                table[name] = -table[name]
    return [state_sign[s.symbol] for s in hand.states], [noise_sign[w.symbol] for w in hand.noises]


def with_conventions(matrix: str, value: sp.Expr, i: int, j: int, state_signs: Sequence[int], noise_signs: Sequence[int]) -> sp.Expr:
    """A twin entry as the hand model's convention writes it (x_hand = s x_twin, w_hand = n w_twin)."""
    if matrix == "F":
        return state_signs[i] * state_signs[j] * value
    if matrix == "G":
        return state_signs[i] * noise_signs[j] * value
    return state_signs[j] * value  # H: measurements keep their sign


# -- the comparison ------------------------------------------------------------------
#: A twin entry -> the same entry under the hand model's sign conventions.
Transform = Callable[[sp.Expr], sp.Expr]
#: (matrix, twin row, twin column) -> the terms declared approximations dropped there, with the approximation's name.
Dropped = Mapping[tuple[str, int, int], Sequence[tuple[sp.Expr, str]]]
#: Parameter symbol -> its value at the scenario.
Values = Mapping[sp.Symbol, float]


@dataclass(frozen=True)
class EntryRecord:
    """One (matrix, row, column) of the cross-check; row/column are the hand model's symbols."""

    model: str
    matrix: str
    row: str
    column: str
    hand: str
    derived: str
    status: str
    term: str | None
    magnitude: float | None
    reason: str

    def record(self) -> dict[str, Any]:
        """The entry as a JSON-ready dict with exactly :data:`RECORD_FIELDS`."""
        return {name: getattr(self, name) for name in RECORD_FIELDS}


@dataclass(frozen=True)
class CrossCheckResult:
    """The cross-check of one pair: every entry that is nonzero on either side, in matrix order."""

    hand: str
    twin: str
    scenario: str
    entries: tuple[EntryRecord, ...]

    def counts(self) -> dict[str, int]:
        """Entries per status (all statuses present)."""
        return {s: sum(e.status == s for e in self.entries) for s in STATUSES}

    @property
    def unexplained(self) -> list[EntryRecord]:
        return [e for e in self.entries if e.status == "unexplained"]

    @property
    def differences(self) -> list[EntryRecord]:
        return [e for e in self.entries if e.status != "equal"]


def _quantities(model: ErrorModel, matrix: str) -> tuple[list[str], list[str]]:
    states = [s.symbol for s in model.states]
    if matrix == "F":
        return states, states
    if matrix == "G":
        return states, [w.symbol for w in model.noises]
    return [m.symbol for m in model.measurements], states


def scenario_values(model: ErrorModel) -> tuple[dict[sp.Symbol, float], str]:
    """Numbers for every parameter of ``model`` (its defaults and check scenario) and a label; empty if incomplete."""
    values: dict[str, float] = model.parameter_defaults()
    label = "parameter defaults"
    if model.check is not None:
        values.update(model.check.parameter_values())
        label = f"the check scenario of {model.name}"
    out = {}
    for p in model.parameters:
        value = values.get(p.name, p.value)
        if value is None:
            return {}, f"no value for {p.name}: magnitudes not computed"
        out[p.sym] = float(value)
    return with_earth_quantities(out, model), label


#: Symbols the derivation engine writes the Earth quantities with (modelgen.model.navigation_model's defaults).
EARTH_SYMBOLS = ("R_M", "R_N", "g", "h")


def with_earth_quantities(values: dict[sp.Symbol, float], model: ErrorModel) -> dict[sp.Symbol, float]:
    """``values`` plus R_M, R_N, normal gravity g and height h where the model does not declare them.

    A twin's declared approximations remove these from its matrices, so the
    engine does not declare them as parameters; the terms they dropped still
    use them.  They are WGS-84's at the scenario's latitude (the parameter
    named ``latitude``) and height (``height``, else 0: sea level), from
    :mod:`modelgen.model.navlib`.  Without a latitude nothing is added.
    """
    by_name = {p.name: values.get(p.sym) for p in model.parameters}
    latitude = by_name.get("latitude")
    if latitude is None:
        return values
    height = by_name.get("height") or 0.0
    earth = {
        "R_M": float(navlib.meridian_radius(latitude)),
        "R_N": float(navlib.prime_vertical_radius(latitude)),
        "g": float(navlib.normal_gravity(latitude, height)),
        "h": float(height),
    }
    declared = {p.symbol for p in model.parameters}
    return {**values, **{sp.Symbol(k, real=True): v for k, v in earth.items() if k not in declared}}


def magnitude(term: sp.Expr, values: Mapping[sp.Symbol, float]) -> float | None:
    """|term| at the scenario values (None without values, or if it is not a finite real number there)."""
    if not values:
        return None
    numbers = {k: sp.Float(v) for k, v in values.items()}
    term = sp.sympify(term)
    if term.xreplace(numbers).free_symbols:
        term = sp.cancel(sp.together(term))  # a symbol may cancel out (f - f): no value needed for it
    try:
        number = complex(sp.N(term.xreplace(numbers)))
    except (TypeError, ValueError):
        return None
    if abs(number.imag) > 1e-12 * max(1.0, abs(number.real)) or not math.isfinite(number.real):
        return None
    return float(f"{abs(number.real):.6g}")


def _explained_by_approximation(
    hand: sp.Expr, full: sp.Expr, neglected: Sequence[tuple[sp.Expr, str]], transform: Transform
) -> tuple[sp.Expr, list[str]] | None:
    """The smallest set of neglected terms whose removal from ``full`` gives ``hand`` (after the conventions)."""
    for size in range(1, min(MAX_COMBINED_APPROXIMATIONS, len(neglected)) + 1):
        for subset in combinations(neglected, size):
            dropped = sp.Add(*(t for t, _ in subset))
            if same(hand, transform(full - dropped)):
                return dropped, sorted({name for _, name in subset})
    return None


def cross_check(
    pair: Pair, hand: DerivedModel, twin: DerivedModel, neglected: Iterable[NeglectedTerm] = ()
) -> CrossCheckResult:
    """Compare the hand-written model's F, G, H with its twin's, entry by entry (see module doc)."""
    where = layout(pair, hand.model, twin.model)
    to_twin = hand_substitution(pair, hand.model, twin.model)
    state_signs, noise_signs = signs(pair, hand.model)
    values, label = scenario_values(twin.model)
    if not values:
        values, label = scenario_values(hand.model)
        values = {to_twin.get(k, k): v for k, v in values.items()}
    errors = {(e.matrix, e.row, e.column): e for e in pair.hand_model_errors}
    dropped: dict[tuple[str, int, int], list[tuple[sp.Expr, str]]] = {}
    for n in neglected:
        dropped.setdefault((n.matrix, n.row, n.column), []).append((n.term, n.approximation))

    records = []
    for matrix in MATRICES:
        H = getattr(hand, matrix)
        T = getattr(twin, matrix)
        rows, columns = _quantities(hand.model, matrix)
        twin_rows, twin_columns = where.index(matrix)
        for i in range(H.shape[0]):
            for j in range(H.shape[1]):
                terms = dropped.get((matrix, twin_rows[i], twin_columns[j]), [])
                full = T[twin_rows[i], twin_columns[j]] + sp.Add(*(t for t, _ in terms))
                written = H[i, j].xreplace(to_twin)
                if written == 0 and full == 0 and not terms:
                    continue

                def transform(value: sp.Expr, i: int = i, j: int = j, matrix: str = matrix) -> sp.Expr:
                    return with_conventions(matrix, value, i, j, state_signs, noise_signs)

                records.append(_classify(
                    pair, matrix, rows[i], columns[j], written, full, terms, transform, errors, values,
                ))
        records += _unmodelled_couplings(pair, matrix, twin, where, rows, twin_rows, dropped, values)
        records += _removed_state_couplings(pair, matrix, rows, twin_rows, dropped, values)
    return CrossCheckResult(pair.hand, pair.twin, label, tuple(records))


#: What a record's column says for a term whose state the twin's approximation removed (engine index -1).
REMOVED_STATE = "(a state the approximation removes)"


def _removed_state_couplings(
    pair: Pair, matrix: str, rows: Sequence[str], twin_rows: Sequence[int], dropped: Dropped, values: Values
) -> list[EntryRecord]:
    """Records for the terms coupling a removed state (e.g. under no_vertical_channel: dV_d, dh) into the model's rows.

    The engine gives such a term column -1 (the state no longer exists);
    rows of removed states are not part of the model and are not listed.
    """
    if matrix == "G":
        return []
    out = []
    for i, row in zip(twin_rows, rows):
        for term, approximation in dropped.get((matrix, i, -1), []):
            out.append(EntryRecord(
                model=pair.hand, matrix=matrix, row=row, column=REMOVED_STATE, hand="0", derived=short(term),
                status="approximation", term=short(term), magnitude=magnitude(term, values),
                reason=f"declared approximation {approximation} removes the state this term couples in",
            ))
    return out


def _unmodelled_couplings(
    pair: Pair, matrix: str, twin: DerivedModel, where: Layout, rows: Sequence[str], twin_rows: Sequence[int],
    dropped: Dropped, values: Values,
) -> list[EntryRecord]:
    """Records for the twin's couplings into the hand model's rows from quantities the hand model leaves out."""
    lost = where.unmodelled_noises if matrix == "G" else where.unmodelled_states
    T = getattr(twin, matrix)
    names = [w.symbol for w in twin.model.noises] if matrix == "G" else [s.symbol for s in twin.model.states]
    out = []
    for i, row in zip(twin_rows, rows):
        for j in sorted(lost):
            full = T[i, j] + sp.Add(*(t for t, _ in dropped.get((matrix, i, j), [])))
            if full == 0:
                continue
            u = lost[j]
            out.append(EntryRecord(
                model=pair.hand, matrix=matrix, row=row, column=names[j], hand="0", derived=short(full),
                status="approximation", term=short(full), magnitude=magnitude(full, values),
                reason=f"{u.approximation}: {names[j]} is not a state of {pair.hand} ({u.reason})",
            ))
    return out


def short(expr: sp.Expr) -> str:
    """``expr`` as text with its floating-point constants to 6 significant digits (WGS-84 e^2 and the like)."""
    expr = sp.sympify(expr)
    return sp.sstr(expr.xreplace({f: sp.Float(f, 6) for f in expr.atoms(sp.Float)}))


def _classify(
    pair: Pair, matrix: str, row: str, column: str, written: sp.Expr, full: sp.Expr, terms: Sequence[tuple[sp.Expr, str]],
    transform: Transform, errors: Mapping[tuple[str, str, str], HandModelError], values: Values,
) -> EntryRecord:
    """The status, term, magnitude and reason of one entry (the rules of the module doc, in order)."""
    derived_text = short(full) if full != 0 else "0"
    base = dict(model=pair.hand, matrix=matrix, row=row, column=column, hand=sp.sstr(written) if written != 0 else "0", derived=derived_text)
    if same(written, full):
        return EntryRecord(**base, status="equal", term=None, magnitude=None, reason="")
    conventional = transform(full)
    if same(written, conventional):
        names = [c.name for c in pair.conventions if _convention_touches(c, row, column)]
        reasons = [c.reason for c in pair.conventions if _convention_touches(c, row, column)]
        return EntryRecord(
            **base, status="convention", term=short(full - written), magnitude=magnitude(full - written, values),
            reason=f"{', '.join(names)}: {' '.join(reasons)}",
        )
    approximation = _explained_by_approximation(written, full, terms, transform)
    if approximation is not None:
        term, names = approximation
        extra = " (with the sign convention applied)" if not same(written, full - term) else ""
        return EntryRecord(
            **base, status="approximation", term=short(term), magnitude=magnitude(term, values),
            reason=f"declared approximation {', '.join(names)} drops this term{extra}",
        )
    difference = full - written
    error = errors.get((matrix, row, column))
    if error is not None:
        state = "fixed in the hand model" if error.fixed else "reported"
        return EntryRecord(
            **base, status="hand_model_error", term=short(sp.expand(difference)), magnitude=magnitude(difference, values),
            reason=f"error in the hand model ({state}): {error.reason}",
        )
    hints = difference_hints(written, full)
    return EntryRecord(
        **base, status="unexplained", term=short(sp.expand(difference)), magnitude=magnitude(difference, values),
        reason="; ".join(h.text for h in hints) or "no declared approximation, convention or hand-model error explains it",
    )


def _convention_touches(c: Convention, row: str, column: str) -> bool:
    """Whether the convention changes the sign of the entry's row or column quantity."""
    return bool({row, column} & (set(c.states) | set(c.noises)))


# -- the report ------------------------------------------------------------------------
def crosscheck_json(results: Sequence[CrossCheckResult]) -> str:
    """``crosscheck.json``: a summary per pair and one record per entry (fields :data:`RECORD_FIELDS`)."""
    data = {
        "record_fields": list(RECORD_FIELDS),
        "pairs": [
            {"model": r.hand, "twin": r.twin, "scenario": r.scenario, "counts": r.counts(), "unexplained": len(r.unexplained)}
            for r in results
        ],
        "entries": [e.record() for r in results for e in r.entries],
    }
    return json.dumps(data, indent=2, sort_keys=True, ensure_ascii=False) + "\n"


def _cell(text: Any) -> str:
    if text is None or text == "":
        return "—"
    return " ".join(str(text).split()).replace("|", "\\|")


def crosscheck_markdown(results: Sequence[CrossCheckResult]) -> str:
    """``crosscheck.md``: per pair, the counts and every entry that is not ``equal``."""
    lines = [
        "# Cross-check: hand-written models against their twins derived from the navigation equations",
        "",
        "Every nonzero entry of F, G and H of each hand-written model is compared with the full first-order "
        "linearization of its twin (the twin's entry plus every term its declared approximations drop). "
        "Statuses: `equal`; `convention` (a declared sign convention of a state or noise); `approximation` "
        "(the hand entry drops a term a declared approximation names; `term` is that term, `magnitude` its "
        "size at the hand model's check scenario); `hand_model_error`; `unexplained`.",
        "",
        "| model | twin | " + " | ".join(STATUSES) + " |",
        "|---|---|" + "---|" * len(STATUSES),
    ]
    for r in results:
        counts = r.counts()
        lines.append(f"| {r.hand} | {r.twin} | " + " | ".join(str(counts[s]) for s in STATUSES) + " |")
    lines += ["", f"Unexplained differences: **{sum(len(r.unexplained) for r in results)}**."]
    for r in results:
        lines += ["", f"## {r.hand} against {r.twin}", "", f"Magnitudes at {r.scenario}.", ""]
        if not r.differences:
            lines.append("Every entry equal.")
            continue
        lines += ["| entry | status | hand | derived | term | magnitude | reason |", "|---|---|---|---|---|---|---|"]
        for e in r.differences:
            size = "—" if e.magnitude is None else f"{e.magnitude:.3g}"
            lines.append(
                f"| {e.matrix}({e.row}, {e.column}) | {e.status} | `{_cell(e.hand)}` | `{_cell(e.derived)}` "
                f"| `{_cell(e.term)}` | {size} | {_cell(e.reason)} |"
            )
    lines += ["", "`crosscheck.json` holds one record per compared entry with fields " + ", ".join(f"`{f}`" for f in RECORD_FIELDS) + ".", ""]
    return "\n".join(lines)


def write_crosscheck_report(results: Sequence[CrossCheckResult], folder: str | Path) -> tuple[Path, Path]:
    """Write ``crosscheck.md`` and ``crosscheck.json`` into ``folder`` atomically; returns both paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    markdown, data = folder / "crosscheck.md", folder / "crosscheck.json"
    write_text_atomically(markdown, crosscheck_markdown(results))
    write_text_atomically(data, crosscheck_json(results))
    return markdown, data
