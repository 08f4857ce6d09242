"""Error-model definition: states, noises, parameters, equations.

An :class:`ErrorModel` is the single source of truth from which F, G, H, Q and
R are derived (``modelgen.derivation.symbolic``).  It holds *equations*, never
matrices: the right-hand side of every state's differential equation and the
expression of every measurement, as sympy expressions in declared symbols.

Everything is validated on construction so that a malformed model is refused
with a message naming the problem and where it is, before anything is derived
or written.
"""

from __future__ import annotations

import keyword
import re
from dataclasses import dataclass, field, replace
from typing import Any, Iterable, Mapping

import sympy as sp

from modelgen.errors import ModelError

from modelgen.model.expression import ALLOWED_FUNCTIONS, excerpt, parse_expression
from modelgen.model.names import C_KEYWORDS, name_collision  # noqa: F401  (C_KEYWORDS: public)

_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

# -- limits on what a model may contain (hostile-input bounds) --------------------
#: Most states, noises, parameters or measurements a model may declare.
MAX_DECLARATIONS = 1000

def check_identifier(name: str, where: str, model_name: bool = False) -> None:
    """Refuse a name that cannot be a C identifier and Python name, or that collides.

    Collisions (C and Python keywords, C library and platform macros, the
    generator's own names; for ``model_name`` also header and module names)
    are listed in :mod:`modelgen.model.names`.
    """
    if not isinstance(name, str) or not _IDENTIFIER.match(name):
        raise ModelError(f"{where}: {name!r} is not a valid C identifier")
    if name in C_KEYWORDS or keyword.iskeyword(name):
        raise ModelError(f"{where}: {name!r} is a C or Python keyword")
    if name.startswith("_"):
        raise ModelError(f"{where}: {name!r} starts with an underscore, which C reserves")
    if name in ALLOWED_FUNCTIONS:
        raise ModelError(f"{where}: {name!r} is the name of a function")
    collision = name_collision(name, model_name=model_name)
    if collision:
        raise ModelError(f"{where}: {name!r} collides with {collision}")


# -- free text (no code in free text) ---------------------------------------------
#: Characters refused in free text besides the C0/C1 controls (Unicode
#: category Cc): bidirectional overrides and isolates, which make text read
#: differently from what a compiler sees ("Trojan Source"), the invisible
#: direction marks, and the Unicode line and paragraph separators.
_INVISIBLE_CONTROLS = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069\u2028\u2029")
#: Free-text fields that may span lines: line feed and tab are allowed there.
MULTILINE_TEXT_FIELDS = frozenset({"description", "notes", "source"})


def check_free_text(text: str, where: str, multiline: bool = False) -> None:
    """Refuse free text (title, unit, description...) carrying control characters.

    Free text is copied into generated comments and docstrings, where a
    carriage return, an escape sequence or a bidirectional override hides or
    changes what the code says.  Line feeds and tabs are allowed where text
    may span lines (``multiline``: descriptions, notes, source); every other
    character of category Cc, and the invisible controls above, is refused.
    Awkward but visible text (``*/``, quotes, backslashes, ``{{``) is data and
    is accepted: the templates render it safely.
    """
    import unicodedata

    if not isinstance(text, str):
        raise ModelError(f"{where}: expected text, got {type(text).__name__}")
    allowed = "\n\t" if multiline else ""
    for position, char in enumerate(text):
        if char in allowed:
            continue
        if char in _INVISIBLE_CONTROLS or unicodedata.category(char) == "Cc":
            name = unicodedata.name(char, "control character")
            raise ModelError(
                f"{where}: contains the control character U+{ord(char):04X} ({name}) at position {position + 1}; "
                "free text may not contain control characters" + (" other than line feed and tab" if multiline else "")
            )


@dataclass(frozen=True)
class Quantity:
    """A named, unit-carrying symbol of the model.

    ``name`` is the spelled-out identifier used in generated code
    (``attitude_error_north``); ``symbol`` is the short name used in the
    equations, as printed in the paper (``alpha``).
    """

    name: str
    unit: str = "1"
    description: str = ""
    symbol: str = ""
    #: Where a model file declared it: ``file:line`` by field (``""`` the entry, ``"psd"``, ``"variance"``,
    #: ``"expression"``, ``"value"``, ``"dynamics"``), set by :meth:`ErrorModel.build` from the loader's line map, so
    #: that a refusal made after loading (code generation, a check, the navigator) names the line; empty for an
    #: item built in code.  No part of the declaration (not compared, not in the model hash).
    places: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False, kw_only=True)

    def __post_init__(self) -> None:
        if not self.symbol:
            object.__setattr__(self, "symbol", self.name)

    def place(self, key: str = "") -> str:
        """``file:line`` of this item's ``key`` field (of the entry if that field has no line of its own), or ``""``."""
        return self.places.get(key) or self.places.get("", "")

    @property
    def sym(self) -> sp.Symbol:
        return sp.Symbol(self.symbol, real=True)


@dataclass(frozen=True)
class State(Quantity):
    """An error state x_i with its differential equation d(x_i)/dt."""


@dataclass(frozen=True)
class Noise(Quantity):
    """A continuous white-noise input w_i with power spectral density ``psd``."""

    psd: str = "1"


@dataclass(frozen=True)
class Parameter(Quantity):
    """A symbolic parameter (operating point or error statistic).

    ``value`` is a default (e.g. earth rate); operating-point parameters such
    as latitude have none and must be supplied by the scenario.
    """

    value: float | None = None


@dataclass(frozen=True)
class Measurement(Quantity):
    """A measurement z = h(x) + v with white noise v of variance ``variance``."""

    expression: str = "0"
    variance: str = "1"


@dataclass(frozen=True)
class ErrorModel:
    """A validated continuous-time error model dx/dt = f(x, w), z = h(x) + v."""

    name: str
    states: tuple[State, ...]
    noises: tuple[Noise, ...]
    parameters: tuple[Parameter, ...]
    dynamics: Mapping[str, sp.Expr]  # state name -> right-hand side
    measurements: tuple[Measurement, ...]
    measurement_expressions: Mapping[str, sp.Expr]
    noise_psd: Mapping[str, sp.Expr]
    measurement_variance: Mapping[str, sp.Expr]
    title: str = ""
    source: str = ""
    frame: str = ""
    notes: tuple[str, ...] = field(default_factory=tuple)
    check: Any = None  # modelgen.model.check_scenario.CheckSpec: the scenario --check flies, if the file declares one
    #: A navigation model's terms its declared approximations dropped (modelgen.model.perturbation.problem.NeglectedTerm), carried
    #: on the model itself; empty for a model written as equations.
    neglected: tuple = field(default_factory=tuple, compare=False)
    #: A navigation model's attitude reset Jacobian for closed-loop feedback
    #: (modelgen.model.perturbation.problem.AttitudeReset), None for a model written as equations.
    attitude_reset: Any = field(default=None, compare=False)
    #: A navigation model's navigation problem (modelgen.model.perturbation.problem.NavigationProblem): the mechanization, frame,
    #: state symbols and sensor model its error model was derived from, so that the navigator's mechanization is
    #: generated from the same equations (modelgen.derivation.mechanization_rates); None for a model written as equations.
    navigation: Any = field(default=None, compare=False)

    def __getstate__(self) -> dict:
        """Pickled without :attr:`navigation`: its measurement functions are closures (not picklable), and a
        worker process (Monte Carlo, figures) needs the matrices, not the mechanization the navigator generates."""
        state = dict(self.__dict__)
        state["navigation"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        """Restore a pickled model (frozen: through object.__setattr__)."""
        for key, value in state.items():
            object.__setattr__(self, key, value)

    def __repr__(self) -> str:
        """One line (the default repr printed every equation: 11,769 characters for the paper's model)."""
        return (f"<ErrorModel {self.name!r}: {len(self.states)} states, {len(self.noises)} noises, "
                f"{len(self.parameters)} parameters, {len(self.measurements)} measurements>")

    # -- convenient views ---------------------------------------------------
    @property
    def state_names(self) -> list[str]:
        return [s.name for s in self.states]

    @property
    def noise_names(self) -> list[str]:
        return [w.name for w in self.noises]

    @property
    def parameter_names(self) -> list[str]:
        return [p.name for p in self.parameters]

    @property
    def measurement_names(self) -> list[str]:
        return [m.name for m in self.measurements]

    @property
    def state_symbols(self) -> list[sp.Symbol]:
        return [s.sym for s in self.states]

    @property
    def noise_symbols(self) -> list[sp.Symbol]:
        return [w.sym for w in self.noises]

    @property
    def parameter_symbols(self) -> list[sp.Symbol]:
        return [p.sym for p in self.parameters]

    def state_index(self, name: str) -> int:
        """Position of a state, by name or equation symbol."""
        for i, s in enumerate(self.states):
            if name in (s.name, s.symbol):
                return i
        raise ModelError(f"model {self.name!r}: no state named {name!r}")

    def parameter_defaults(self) -> dict[str, float]:
        return {p.name: p.value for p in self.parameters if p.value is not None}

    # -- construction -------------------------------------------------------
    @classmethod
    def build(
        cls,
        name: str,
        states: Iterable[State],
        noises: Iterable[Noise],
        parameters: Iterable[Parameter],
        dynamics: Mapping[str, str | sp.Expr],
        measurements: Iterable[Measurement] = (),
        title: str = "",
        source: str = "",
        frame: str = "",
        notes: Iterable[str] = (),
        locations: Mapping[str, str] | None = None,
    ) -> "ErrorModel":
        """Validate declarations and parse every equation; see module doc.

        ``dynamics`` maps each state (by name or symbol) to its right-hand
        side, as a string or a sympy expression in declared symbols.
        ``locations`` maps key paths (``states[2]``, ``dynamics.alpha``,
        ``noises[0].psd``) to a place such as ``model.yaml:14`` so that errors
        from a model file name the line.
        """
        where = Locator(name, locations or {})
        check_identifier(name, where("model", "model name"), model_name=True)
        states, noises, parameters = tuple(states), tuple(noises), tuple(parameters)
        measurements = tuple(measurements)
        notes = tuple(notes)
        if not states:
            raise ModelError(f"model {name!r}: declares no states")
        for kind, items in (("states", states), ("noises", noises), ("parameters", parameters), ("measurements", measurements)):
            if len(items) > MAX_DECLARATIONS:
                raise ModelError(
                    f"{where(kind, kind)}: {len(items)} {kind} declared; at most {MAX_DECLARATIONS} are accepted"
                )
        for key, text in (("title", title), ("source", source), ("frame", frame)):
            check_free_text(text, where(key, key), multiline=key in MULTILINE_TEXT_FIELDS)
        for i, note in enumerate(notes):
            check_free_text(note, where(f"notes[{i}]", f"notes[{i}]"), multiline=True)
        _check_declarations(where, states, noises, parameters, measurements)

        namespace = {q.symbol: q.sym for q in (*states, *noises, *parameters)}
        state_by_key = {}
        for s in states:
            state_by_key[s.name] = s
            state_by_key[s.symbol] = s
        parsed: dict[str, sp.Expr] = {}
        for key, rhs in dynamics.items():
            state = state_by_key.get(key)
            if state is None:
                raise ModelError(
                    f"{where(f'dynamics.{key}', 'dynamics')}: equation given for {key!r}, which is not a declared state"
                )
            if state.name in parsed:
                raise ModelError(f"{where(f'dynamics.{key}', 'dynamics')}: two equations for state {state.name!r}")
            parsed[state.name] = parse_expression(rhs, namespace, where(f"dynamics.{key}", f"equation d({key})/dt"))
        missing = [s.name for s in states if s.name not in parsed]
        if missing:
            raise ModelError(f"{where('dynamics', 'dynamics')}: no equation for state(s) {', '.join(missing)}")

        params_only = {p.symbol: p.sym for p in parameters}
        noise_psd = {
            w.name: parse_expression(w.psd, params_only, where(f"noises[{i}].psd", f"noise {w.name!r} psd"))
            for i, w in enumerate(noises)
        }
        states_params = {q.symbol: q.sym for q in (*states, *parameters)}
        meas_expr = {
            m.name: parse_expression(
                m.expression, states_params, where(f"measurements[{i}].expression", f"measurement {m.name!r}")
            )
            for i, m in enumerate(measurements)
        }
        meas_var = {
            m.name: parse_expression(
                m.variance, params_only, where(f"measurements[{i}].variance", f"measurement {m.name!r} variance")
            )
            for i, m in enumerate(measurements)
        }
        defaults = {p.sym: p.value for p in parameters if p.value is not None}
        for i, w in enumerate(noises):
            _check_not_negative(noise_psd[w.name], where(f"noises[{i}].psd", f"noise {w.name!r} psd"), defaults)
        for i, m in enumerate(measurements):
            _check_not_negative(meas_var[m.name], where(f"measurements[{i}].variance", f"measurement {m.name!r} variance"),
                                defaults)
        # One linearity rule for every command (derive, generate, ...): a linear
        # Kalman filter cannot represent x*y, sin(x) or x**2, so such an equation
        # is refused here rather than silently linearized later.
        errors_and_noises = {q.sym for q in (*states, *noises)}
        for s in states:
            key = s.name if s.name in dynamics else s.symbol
            _check_linear(parsed[s.name], errors_and_noises, where(f"dynamics.{key}", f"equation d({key})/dt"), "error states and noises")
        state_symbols = {s.sym for s in states}
        for i, m in enumerate(measurements):
            _check_linear(
                meas_expr[m.name], state_symbols, where(f"measurements[{i}].expression", f"measurement {m.name!r}"), "error states"
            )
        if locations:
            states, noises = _placed(states, "states", locations), _placed(noises, "noises", locations, ("psd",))
            parameters = _placed(parameters, "parameters", locations, ("value",))
            measurements = _placed(measurements, "measurements", locations, ("expression", "variance"))
        return cls(
            name=name,
            states=states,
            noises=noises,
            parameters=parameters,
            dynamics={s.name: parsed[s.name] for s in states},
            measurements=measurements,
            measurement_expressions=meas_expr,
            noise_psd=noise_psd,
            measurement_variance=meas_var,
            title=title,
            source=source,
            frame=frame,
            notes=notes,
        )


def _placed(items: tuple, kind: str, locations: Mapping[str, str], fields: tuple[str, ...] = ()) -> tuple:
    """``items`` with the lines of ``locations`` (keys ``states[2]``, ``noises[0].psd``, ``dynamics.<state>``) as their
    :attr:`Quantity.places`; an item with no line there keeps its own (one carried over from a base model)."""
    out = []
    for i, q in enumerate(items):
        keys = {"": f"{kind}[{i}]", **{f: f"{kind}[{i}].{f}" for f in fields}}
        if kind == "states":
            keys["dynamics"] = f"dynamics.{q.name}" if f"dynamics.{q.name}" in locations else f"dynamics.{q.symbol}"
        places = {f: locations[k] for f, k in keys.items() if locations.get(k)}
        out.append(replace(q, places=places) if places else q)
    return tuple(out)


class Locator:
    """Formats the place of an error: ``file.yaml:12: model 'x', states[2]``."""

    def __init__(self, model: str, locations: Mapping[str, str]):
        self.model, self.locations = model, locations

    def __call__(self, key: str, what: str) -> str:
        place = self.locations.get(key) or self.locations.get(key.split(".")[0])
        prefix = f"{place}: " if place else ""
        return f"{prefix}model {self.model!r}, {what}"


def _check_declarations(
    where: Locator,
    states: tuple[State, ...],
    noises: tuple[Noise, ...],
    parameters: tuple[Parameter, ...],
    measurements: tuple[Measurement, ...],
) -> None:
    """Every name and symbol is a valid identifier and declared once."""
    seen: dict[str, str] = {}
    groups = (("state", states), ("noise", noises), ("parameter", parameters), ("measurement", measurements))
    for kind, items in groups:
        for i, q in enumerate(items):
            place = where(f"{kind}s[{i}]", f"{kind} {q.name!r}")
            for label, ident in (("name", q.name), ("symbol", q.symbol)):
                check_identifier(ident, f"{place} {label}")
            for label in ("unit", "description"):
                text = getattr(q, label)
                text_place = where(f"{kind}s[{i}].{label}", f"{kind} {q.name!r} {label}")
                check_free_text(str(text), text_place, multiline=label in MULTILINE_TEXT_FIELDS)
            for ident in {q.name, q.symbol}:
                if ident in seen:
                    raise ModelError(f"{place}: {ident!r} is declared twice ({seen[ident]} and {kind})")
                seen[ident] = kind
    for i, p in enumerate(parameters):
        if p.value is not None:
            place = where(f"parameters[{i}]", f"parameter {p.name!r}")
            try:
                value = float(p.value)
            except (TypeError, ValueError):
                raise ModelError(f"{place}: value {p.value!r} is not a number") from None
            except OverflowError:
                raise ModelError(f"{place}: value {str(p.value)[:20]}... is beyond the range of a double") from None
            if value != value or value in (float("inf"), float("-inf")):
                raise ModelError(f"{place}: value {p.value!r} is not finite")


def _check_not_negative(statistic: sp.Expr, where: str, defaults: Mapping[sp.Symbol, float] | None = None) -> None:
    """Refuse a power spectral density or variance that is negative.

    Refused: a negative number, an expression sympy proves nonpositive
    without being zero (``-sigma**2``): it is negative for every nonzero
    sigma, which is always a sign error; and an expression of parameters
    that all have defaults which is negative, or not a real number, at those
    defaults (``-2*mu*sigma**2``, ``-g``, ``sqrt(-g)``: otherwise only
    ``generate --check`` would catch them, naming no file).
    """
    if statistic.is_negative or (statistic.is_nonpositive and statistic.is_zero is not True):
        raise ModelError(f"{where}: {statistic} is negative (a variance or spectral density must be >= 0)")
    symbols = statistic.free_symbols
    if not defaults or not symbols or not symbols <= set(defaults):
        return
    at = ", ".join(f"{s} = {defaults[s]:g}" for s in sorted(symbols, key=str))
    try:
        value = complex(statistic.xreplace({s: sp.Float(defaults[s]) for s in symbols}).evalf())
    except (TypeError, ValueError, OverflowError, ZeroDivisionError):
        raise ModelError(f"{where}: {excerpt(str(statistic))} is not a number at the parameters' defaults ({at})") from None
    if value.imag != 0 or value.real != value.real:
        raise ModelError(f"{where}: {excerpt(str(statistic))} is not a real number at the parameters' defaults ({at}); "
                         "a variance or spectral density must be >= 0")
    if value.real < 0:
        raise ModelError(f"{where}: {excerpt(str(statistic))} is {value.real:.6g} at the parameters' defaults ({at}); "
                         "a variance or spectral density must be >= 0")


def nonlinear_variables(expr: sp.Expr, variables: set[sp.Symbol]) -> list[sp.Symbol]:
    """The variables among ``variables`` that ``expr`` is not linear in (empty if linear).

    ``expr`` is linear in them when every first derivative is free of them:
    ``a*x + b*w`` is, ``x*w``, ``x**2`` and ``sin(x)`` are not.
    """
    present = sorted(expr.free_symbols & variables, key=str)
    bad = []
    for a in present:
        slope = sp.diff(expr, a)
        if any(sp.diff(slope, b) != 0 for b in sorted(slope.free_symbols & variables, key=str)):
            bad.append(a)
    return bad


def _check_linear(expr: sp.Expr, variables: set[sp.Symbol], where: str, what: str) -> None:
    """Refuse an equation that a linear Kalman filter cannot represent.

    Refused: a nonlinear term (see :func:`nonlinear_variables`), and a term
    that depends on none of ``variables`` (``dv + 1``, ``g``): the error model
    dx/dt = F x + G w, z = H x + v has no place for it, and the derivation
    would drop it without a word.
    """
    bad = nonlinear_variables(expr, variables)
    if bad:
        raise ModelError(
            f"{where}: {expr} is not linear in the {what} (nonlinear in {', '.join(map(str, bad))}); "
            "a linear Kalman filter cannot be generated from it, and it is not linearized silently"
        )
    constant = expr.xreplace({v: sp.S.Zero for v in expr.free_symbols & variables})
    if constant != 0:
        raise ModelError(
            f"{where}: {expr} has a term, {excerpt(str(constant))}, that depends on none of the {what}; "
            "a linear error model (F x + G w, H x + v) cannot represent it, and it is not dropped silently"
        )
