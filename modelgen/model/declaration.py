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

from modelgen.model.file_fields import underflows_to_zero
from modelgen.model.names import C_KEYWORDS, name_collision  # noqa: F401  (C_KEYWORDS: public)

_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

# -- limits on what a model may contain (hostile-input bounds) --------------------
#: Longest expression text accepted, in characters.
MAX_EXPRESSION_LENGTH = 10_000
#: Deepest expression accepted, counted in levels of nesting: the terms of one
#: flat sum ``a + b + c`` (or factors of one flat product) share a level.
MAX_EXPRESSION_DEPTH = 100
#: Most syntax-tree levels accepted, the terms of a flat sum or product each
#: one level (Python's compiler, which sympy's parser calls, recurses through
#: them: about 3,000 exhaust it).
MAX_SYNTAX_DEPTH = 1000
#: Largest constant exponent accepted, in absolute value.
MAX_EXPONENT = 64
#: Longest number literal accepted, in characters.
MAX_NUMBER_LENGTH = 40
#: Most terms an expression may have once multiplied out (derivation expands).
MAX_EXPANDED_TERMS = 10_000
#: Most states, noises, parameters or measurements a model may declare.
MAX_DECLARATIONS = 1000
#: Largest finite double (DBL_MAX): a constant beyond it is infinite in C.
DOUBLE_MAX = 1.7976931348623157e308

#: Functions an equation may use; anything else is an unknown symbol.
ALLOWED_FUNCTIONS: dict[str, object] = {
    "sin": sp.sin,
    "cos": sp.cos,
    "tan": sp.tan,
    "sec": sp.sec,
    "asin": sp.asin,
    "acos": sp.acos,
    "atan": sp.atan,
    "atan2": sp.atan2,
    "sqrt": sp.sqrt,
    "exp": sp.exp,
    "log": sp.log,
    "Abs": sp.Abs,
    "pi": sp.pi,
}


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
        where = _Locator(name, locations or {})
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


class _Locator:
    """Formats the place of an error: ``file.yaml:12: model 'x', states[2]``."""

    def __init__(self, model: str, locations: Mapping[str, str]):
        self.model, self.locations = model, locations

    def __call__(self, key: str, what: str) -> str:
        place = self.locations.get(key) or self.locations.get(key.split(".")[0])
        prefix = f"{place}: " if place else ""
        return f"{prefix}model {self.model!r}, {what}"


def _check_declarations(
    where: _Locator,
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
        raise ModelError(f"{where}: {_excerpt(str(statistic))} is not a number at the parameters' defaults ({at})") from None
    if value.imag != 0 or value.real != value.real:
        raise ModelError(f"{where}: {_excerpt(str(statistic))} is not a real number at the parameters' defaults ({at}); "
                         "a variance or spectral density must be >= 0")
    if value.real < 0:
        raise ModelError(f"{where}: {_excerpt(str(statistic))} is {value.real:.6g} at the parameters' defaults ({at}); "
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
            f"{where}: {expr} has a term, {_excerpt(str(constant))}, that depends on none of the {what}; "
            "a linear error model (F x + G w, H x + v) cannot represent it, and it is not dropped silently"
        )


#: Operators an equation may contain; anything else (attribute access, indexing,
#: strings, keywords) is refused before the text reaches sympy's eval-based parser.
_ALLOWED_OPERATORS = frozenset({"+", "-", "*", "/", "**", "(", ")", ","})
#: A number literal: decimal integer or float, with an optional exponent.  No
#: imaginary (``1j``), hexadecimal, octal, binary or underscored literals.
_DECIMAL_NUMBER = re.compile(r"^(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _check_tokens(text: str, where: str) -> None:
    """Allow only names, decimal numbers and arithmetic in equation text.

    sympy's ``parse_expr`` evaluates its input as Python, so ``x.subs(...)``
    or ``x.__class__`` in a model file would run.  A model file is data: only
    identifiers, numbers and ``+ - * / ** ( ) ,`` may appear.  A number must
    be decimal, at most :data:`MAX_NUMBER_LENGTH` characters long and within
    the range of a double.
    """
    import io
    import tokenize

    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    except (tokenize.TokenError, SyntaxError, IndentationError) as exc:
        raise ModelError(f"{where}: cannot parse {_excerpt(text)} ({exc})") from None
    skip = {tokenize.NEWLINE, tokenize.NL, tokenize.ENDMARKER, tokenize.INDENT, tokenize.DEDENT}
    for tok in tokens:
        if tok.type in skip:
            continue
        if tok.type == tokenize.NUMBER:
            _check_number(tok.string, text, where)
            continue
        if tok.type == tokenize.NAME and not keyword.iskeyword(tok.string):
            continue
        if tok.type == tokenize.OP and tok.string in _ALLOWED_OPERATORS:
            continue
        raise ModelError(
            f"{where}: {tok.string!r} is not allowed in {_excerpt(text)} "
            "(an expression may use only declared names, numbers, + - * / ** ( ) and functions)"
        )


def _check_number(literal: str, text: str, where: str) -> None:
    """Refuse a number literal that is not decimal, is too long, or overflows a double."""
    if not _DECIMAL_NUMBER.match(literal):
        raise ModelError(f"{where}: {literal!r} in {_excerpt(text)} is not a decimal number (no imaginary, hex or other literals)")
    if len(literal) > MAX_NUMBER_LENGTH:
        raise ModelError(
            f"{where}: the number {literal[:20]}... in {_excerpt(text)} has {len(literal)} characters; "
            f"at most {MAX_NUMBER_LENGTH} are accepted"
        )
    if abs(float(literal)) > DOUBLE_MAX:
        raise ModelError(f"{where}: the number {literal} in {_excerpt(text)} is beyond the range of a double")
    if underflows_to_zero(literal):
        raise ModelError(
            f"{where}: the number {literal} in {_excerpt(text)} is nonzero but below the smallest double "
            "(about 4.9e-324): it would be read as 0"
        )


def _excerpt(text: str, limit: int = 80) -> str:
    """``text`` quoted, cut to ``limit`` characters so that a huge expression makes a short message."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text)} characters)"


def _check_syntax(text: str, namespace: Mapping[str, sp.Symbol], where: str) -> None:
    """Check an expression's shape before sympy sees it, so that nothing can hang.

    On the Python syntax tree: depth at most :data:`MAX_EXPRESSION_DEPTH`;
    every name declared (or an allowed function); exponents constant and at
    most :data:`MAX_EXPONENT` in absolute value, or symbolic, and never a
    power of a power (``10**10**10``).
    """
    import ast

    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError) as exc:
        raise ModelError(f"{where}: cannot parse {_excerpt(text)} ({exc.msg if isinstance(exc, SyntaxError) else exc})") from None
    except (RecursionError, MemoryError):
        raise ModelError(f"{where}: {_excerpt(text)} is nested too deeply to parse") from None
    unknown_symbols, unknown_functions = set(), set()
    stack = [(tree.body, 1, 1)]  # (node, nesting depth, syntax-tree depth)
    while stack:
        node, depth, syntax_depth = stack.pop()
        if depth > MAX_EXPRESSION_DEPTH:
            raise ModelError(f"{where}: {_excerpt(text)} is nested more than {MAX_EXPRESSION_DEPTH} levels deep")
        if syntax_depth > MAX_SYNTAX_DEPTH:
            raise ModelError(
                f"{where}: {_excerpt(text)} has a sum or product of more than {MAX_SYNTAX_DEPTH} terms "
                "(or nests sums of many terms more than that deep)"
            )
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id not in ALLOWED_FUNCTIONS and node.func.id not in namespace:
                unknown_functions.add(node.func.id)
            children = list(node.args) + [k.value for k in node.keywords]
        elif isinstance(node, ast.Name):
            if node.id not in namespace and node.id not in ALLOWED_FUNCTIONS:
                unknown_symbols.add(node.id)
            children = []
        else:
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
                _check_exponent(node.right, text, where)
            children = list(ast.iter_child_nodes(node))
        stack.extend((child, depth + (not _continues_chain(node, child)), syntax_depth + 1) for child in children)
    if unknown_symbols:
        raise ModelError(f"{where}: unknown symbol(s) {', '.join(sorted(unknown_symbols))} in {_excerpt(text)}")
    if unknown_functions:
        raise ModelError(f"{where}: unknown function(s) {', '.join(sorted(unknown_functions))}")


def _continues_chain(node: Any, child: Any) -> bool:
    """``child`` is the left operand of ``node`` in one flat sum (``+ -``) or product (``* /``): the same level.

    Python parses ``a + b + c`` as ``(a + b) + c``: the chain's left
    operands nest, but the sum is flat; a right operand or a parenthesized
    sum inside a product is nesting.
    """
    import ast

    additive, multiplicative = (ast.Add, ast.Sub), (ast.Mult, ast.Div)
    if not (isinstance(node, ast.BinOp) and isinstance(child, ast.BinOp) and child is node.left):
        return False
    return any(isinstance(node.op, family) and isinstance(child.op, family) for family in (additive, multiplicative))


def _check_exponent(exponent: Any, text: str, where: str) -> None:
    """Refuse a power tower or a constant exponent beyond :data:`MAX_EXPONENT`."""
    import ast

    nodes = list(ast.walk(exponent))
    if any(isinstance(n, ast.BinOp) and isinstance(n.op, ast.Pow) for n in nodes):
        raise ModelError(f"{where}: a power of a power (such as 10**10**10) is not accepted in {_excerpt(text)}")
    if any(isinstance(n, ast.Name) for n in nodes):
        return  # a symbolic exponent: evaluated at run time, never expanded here
    value = _constant_value(exponent)
    if value is None or not abs(value) <= MAX_EXPONENT:
        raise ModelError(
            f"{where}: exponent {ast.unparse(exponent)[:40]} in {_excerpt(text)} is not a number of at most "
            f"{MAX_EXPONENT} in absolute value"
        )


def _constant_value(node: Any) -> float | None:
    """The value of a constant exponent (numbers, + - * /), or None if it has none (e.g. 1/0)."""
    import ast
    import operator

    binary = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv}
    try:
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return float(node.value)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            inner = _constant_value(node.operand)
            return None if inner is None else (inner if isinstance(node.op, ast.UAdd) else -inner)
        if isinstance(node, ast.BinOp) and type(node.op) in binary:
            left, right = _constant_value(node.left), _constant_value(node.right)
            if left is None or right is None:
                return None
            value = binary[type(node.op)](left, right)
            return value if value == value and abs(value) != float("inf") else None
    except (ArithmeticError, OverflowError):
        return None
    return None


#: Values sympy gives an undefined or infinite expression.
_NON_FINITE = (sp.nan, sp.zoo, sp.oo, -sp.oo)


def _check_defined(expr: sp.Expr, text: str, where: str) -> None:
    """Refuse an expression that is undefined, infinite or complex anywhere.

    Refused: nan, zoo (complex infinity, e.g. ``x/0`` or ``log(0)``), oo, the
    imaginary unit (``sqrt(-4)``), any constant part whose value is not a
    finite real double (``asin(2)``, ``exp(1000)``), a denominator that is
    zero once simplified (``x/(sin(k)**2 + cos(k)**2 - 1)``), and an
    expression that would multiply out to more than :data:`MAX_EXPANDED_TERMS`
    terms.
    """
    def shown() -> str:  # printed only for a message: printing a large expression costs seconds
        return _excerpt(str(text))

    if expr.has(*_NON_FINITE):
        raise ModelError(f"{where}: {shown()} is undefined or infinite (it evaluates to {_excerpt(str(expr))})")
    if expr.has(sp.I):
        raise ModelError(f"{where}: {shown()} is complex (it evaluates to {_excerpt(str(expr))})")
    terms = _expanded_terms(expr)
    if terms > MAX_EXPANDED_TERMS:
        raise ModelError(
            f"{where}: {shown()} multiplies out to more than {MAX_EXPANDED_TERMS} terms; write it in a smaller form"
        )
    power = _largest_power_of_a_sum(expr)
    if power > MAX_EXPONENT:
        raise ModelError(
            f"{where}: {shown()} raises a sum to the power {power} once the definitions or entries it refers to are written out "
            f"(at most {MAX_EXPONENT}: its expansion's coefficients grow with the power, past what sympy multiplies "
            "out in reasonable time)"
        )
    stack = [expr]
    while stack:
        e = stack.pop()
        if e.is_number:
            if not _finite_real(e):
                raise ModelError(f"{where}: {shown()} has a part, {_excerpt(str(e))}, that is not a finite real number")
            continue
        if isinstance(e, sp.Pow) and e.exp.is_negative and _is_zero(e.base):
            raise ModelError(f"{where}: {shown()} divides by {_excerpt(str(e.base))}, which is zero")
        stack.extend(e.args)


def _finite_real(e: sp.Expr) -> bool:
    """Whether a constant expression is a finite real number within the range of a double."""
    try:
        value = e.evalf(20)
        if value.has(*_NON_FINITE) or value.has(sp.I) or not value.is_real or not value.is_finite:
            return False
        return abs(float(value)) <= DOUBLE_MAX
    except (TypeError, ValueError, ArithmeticError, RecursionError):
        return False


def _is_zero(e: sp.Expr) -> bool:
    """Whether a denominator is identically zero (``sin(k)**2 + cos(k)**2 - 1``).

    sympy's assumptions decide most cases.  Otherwise the denominator is
    evaluated at a generic point: a clearly nonzero value proves it is not
    identically zero, without the cost of ``simplify`` (seconds per
    expression).  Only a denominator that vanishes there, and is small, is
    simplified to decide.
    """
    if e.is_zero:
        return True
    if e.is_zero is False:
        return False
    point = {s: sp.Rational(3 + 2 * k, 7 + 3 * k) for k, s in enumerate(sorted(e.free_symbols, key=str))}
    try:
        value = complex(e.subs(point).evalf(30))
        if value == value and abs(value) > 1e-20 and abs(value) != float("inf"):
            return False
    except (TypeError, ValueError, ArithmeticError, RecursionError):
        pass
    return sp.count_ops(e) <= 40 and sp.simplify(e) == 0


def _largest_power_of_a_sum(expr: sp.Expr) -> int:
    """The largest integer exponent |n| of a power whose base is a sum, anywhere in ``expr`` (0 if none).

    A literal exponent is bounded by :data:`MAX_EXPONENT` in the text; powers of definitions that are powers
    themselves (``a1 = (x + y)**64``, ``a2 = a1**64``) combine to (x + y)**4096, which has few terms but binomial
    coefficients of over a thousand digits: the term count does not see it.
    """
    return max((abs(int(e.exp)) for e in sp.preorder_traversal(expr)
                if isinstance(e, sp.Pow) and e.exp.is_Integer and isinstance(e.base, sp.Add)), default=0)


def _expanded_terms(expr: sp.Expr) -> int:
    """An upper bound on the terms of ``sp.expand(expr)`` or any of its parts (capped)."""
    from math import comb

    cap = MAX_EXPANDED_TERMS + 1
    terms: dict[sp.Basic, int] = {}
    worst = 1
    for e in sp.postorder_traversal(expr):
        if e in terms:
            continue
        if isinstance(e, sp.Add):
            n = sum(terms.get(a, 1) for a in e.args)
        elif isinstance(e, sp.Mul):
            n = 1
            for a in e.args:
                n = min(cap, n * terms.get(a, 1))
        elif isinstance(e, sp.Pow) and e.exp.is_Integer:
            base = terms.get(e.base, 1)
            k = min(abs(int(e.exp)), cap)
            n = 1 if base == 1 else min(cap, comb(base + k - 1, k))
        else:
            n = 1
        terms[e] = min(cap, n)
        worst = max(worst, terms[e])
    return worst


def parse_expression(text: str | sp.Expr | float | int, namespace: Mapping[str, sp.Symbol], where: str) -> sp.Expr:
    """Parse an equation, refusing any symbol not in ``namespace``.

    Names such as ``beta`` or ``gamma`` would be sympy functions under the
    default parser; here only declared symbols and :data:`ALLOWED_FUNCTIONS`
    exist, so every identifier means exactly what the model declared.  The
    text is checked (length, tokens, syntax tree) before sympy sees it, and
    the result is refused if it is undefined, infinite or complex anywhere
    (see :func:`_check_defined`).
    """
    if isinstance(text, sp.Basic):
        expr = text
    elif isinstance(text, (int, float)) and not isinstance(text, bool):
        if isinstance(text, float) and not abs(text) <= DOUBLE_MAX:
            raise ModelError(f"{where}: {text!r} is not a finite number")
        expr = sp.nsimplify(text) if isinstance(text, int) else sp.Float(text)
    elif isinstance(text, str):
        from sympy.parsing.sympy_parser import parse_expr, standard_transformations

        if len(text) > MAX_EXPRESSION_LENGTH:
            raise ModelError(
                f"{where}: expression of {len(text)} characters; at most {MAX_EXPRESSION_LENGTH} are accepted"
            )
        _check_tokens(text, where)
        _check_syntax(text, namespace, where)
        local = dict(namespace)
        global_ns = {
            "Integer": sp.Integer,  # what parse_expr turns number literals into
            "Float": sp.Float,
            "Rational": sp.Rational,
            **ALLOWED_FUNCTIONS,
        }
        try:
            expr = parse_expr(text, local_dict=local, global_dict=global_ns, transformations=standard_transformations)
        except (SyntaxError, TypeError, NameError, AttributeError, ValueError) as exc:
            raise ModelError(f"{where}: cannot parse {_excerpt(text)} ({exc})") from None
        except (RecursionError, MemoryError):
            raise ModelError(f"{where}: {_excerpt(text)} is nested too deeply to parse") from None
    else:
        raise ModelError(f"{where}: expected an expression, got {type(text).__name__}")
    if not isinstance(expr, sp.Expr):
        raise ModelError(f"{where}: {_excerpt(str(text))} is not a scalar expression")
    known = set(namespace.values())
    unknown = sorted(str(s) for s in expr.free_symbols if s not in known)
    if unknown:
        raise ModelError(f"{where}: unknown symbol(s) {', '.join(unknown)} in {_excerpt(str(text))}")
    bad_functions = sorted(
        {type(f).__name__ for f in expr.atoms(sp.Function) if type(f).__name__ not in ALLOWED_FUNCTIONS}
    )
    if bad_functions:
        raise ModelError(f"{where}: unknown function(s) {', '.join(bad_functions)}")
    _check_defined(expr, text, where)
    return expr
