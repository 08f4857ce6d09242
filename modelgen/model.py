"""Error-model definition: states, noises, parameters, equations.

An :class:`ErrorModel` is the single source of truth from which F, G, H, Q and
R are derived (``modelgen.derivation``).  It holds *equations*, never
matrices: the right-hand side of every state's differential equation and the
expression of every measurement, as sympy expressions in declared symbols.

Everything is validated on construction so that a malformed model is refused
with a message naming the problem and where it is, before anything is derived
or written.
"""

from __future__ import annotations

import keyword
import re
from dataclasses import dataclass, field
from typing import Iterable, Mapping

import sympy as sp

from modelgen.errors import ModelError

# C99 keywords: a state called ``double`` would not compile.  Names only ever
# appear in generated code as struct members (params->name) or strings, so no
# other name needs reserving; identifiers starting with an underscore are
# reserved to the C implementation and refused.
C_KEYWORDS = frozenset(
    """auto break case char const continue default do double else enum extern
    float for goto if inline int long register restrict return short signed
    sizeof static struct switch typedef union unsigned void volatile while
    _Bool _Complex _Imaginary""".split()
)
_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

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


def check_identifier(name: str, where: str) -> None:
    """Refuse a name that cannot be a C identifier or Python name."""
    if not isinstance(name, str) or not _IDENTIFIER.match(name):
        raise ModelError(f"{where}: {name!r} is not a valid C identifier")
    if name in C_KEYWORDS or keyword.iskeyword(name):
        raise ModelError(f"{where}: {name!r} is a C or Python keyword")
    if name.startswith("_"):
        raise ModelError(f"{where}: {name!r} starts with an underscore, which C reserves")
    if name in ALLOWED_FUNCTIONS:
        raise ModelError(f"{where}: {name!r} is the name of a function")


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

    def __post_init__(self) -> None:
        if not self.symbol:
            object.__setattr__(self, "symbol", self.name)

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
        check_identifier(name, where("model", "model name"))
        states, noises, parameters = tuple(states), tuple(noises), tuple(parameters)
        measurements = tuple(measurements)
        if not states:
            raise ModelError(f"model {name!r}: declares no states")
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
        for i, w in enumerate(noises):
            _check_not_negative(noise_psd[w.name], where(f"noises[{i}].psd", f"noise {w.name!r} psd"))
        for i, m in enumerate(measurements):
            _check_not_negative(meas_var[m.name], where(f"measurements[{i}].variance", f"measurement {m.name!r} variance"))
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
            notes=tuple(notes),
        )


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
            if value != value or value in (float("inf"), float("-inf")):
                raise ModelError(f"{place}: value {p.value!r} is not finite")


def _check_not_negative(statistic: sp.Expr, where: str) -> None:
    """Refuse a power spectral density or variance that is a negative number."""
    if statistic.is_number and statistic.is_negative:
        raise ModelError(f"{where}: {statistic} is negative (a variance or spectral density must be >= 0)")


#: Operators an equation may contain; anything else (attribute access, indexing,
#: strings, keywords) is refused before the text reaches sympy's eval-based parser.
_ALLOWED_OPERATORS = frozenset({"+", "-", "*", "/", "**", "(", ")", ","})


def _check_tokens(text: str, where: str) -> None:
    """Allow only names, numbers and arithmetic in equation text.

    sympy's ``parse_expr`` evaluates its input as Python, so ``x.subs(...)``
    or ``x.__class__`` in a model file would run.  A model file is data: only
    identifiers, numbers and ``+ - * / ** ( ) ,`` may appear.
    """
    import io
    import tokenize

    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    except (tokenize.TokenError, SyntaxError, IndentationError) as exc:
        raise ModelError(f"{where}: cannot parse {text!r} ({exc})") from None
    skip = {tokenize.NEWLINE, tokenize.NL, tokenize.ENDMARKER, tokenize.INDENT, tokenize.DEDENT}
    for tok in tokens:
        if tok.type in skip or tok.type == tokenize.NUMBER:
            continue
        if tok.type == tokenize.NAME and not keyword.iskeyword(tok.string):
            continue
        if tok.type == tokenize.OP and tok.string in _ALLOWED_OPERATORS:
            continue
        raise ModelError(
            f"{where}: {tok.string!r} is not allowed in {text!r} "
            "(an expression may use only declared names, numbers, + - * / ** ( ) and functions)"
        )


def parse_expression(text: str | sp.Expr | float | int, namespace: Mapping[str, sp.Symbol], where: str) -> sp.Expr:
    """Parse an equation, refusing any symbol not in ``namespace``.

    Names such as ``beta`` or ``gamma`` would be sympy functions under the
    default parser; here only declared symbols and :data:`ALLOWED_FUNCTIONS`
    exist, so every identifier means exactly what the model declared.
    """
    if isinstance(text, sp.Basic):
        expr = text
    elif isinstance(text, (int, float)) and not isinstance(text, bool):
        expr = sp.nsimplify(text) if isinstance(text, int) else sp.Float(text)
    elif isinstance(text, str):
        from sympy.parsing.sympy_parser import parse_expr, standard_transformations

        _check_tokens(text, where)
        local = dict(namespace)
        global_ns = {
            "Integer": sp.Integer,
            "Float": sp.Float,
            "Rational": sp.Rational,
            "Symbol": sp.Symbol,
            "Function": sp.Function,  # unknown calls parse, then are refused below
            **ALLOWED_FUNCTIONS,
        }
        try:
            expr = parse_expr(text, local_dict=local, global_dict=global_ns, transformations=standard_transformations)
        except (SyntaxError, TypeError, NameError, AttributeError, ValueError) as exc:
            raise ModelError(f"{where}: cannot parse {text!r} ({exc})") from None
    else:
        raise ModelError(f"{where}: expected an expression, got {type(text).__name__}")
    if not isinstance(expr, sp.Expr):
        raise ModelError(f"{where}: {text!r} is not a scalar expression")
    known = set(namespace.values())
    unknown = sorted(str(s) for s in expr.free_symbols if s not in known)
    if unknown:
        raise ModelError(f"{where}: unknown symbol(s) {', '.join(unknown)} in {str(text)!r}")
    bad_functions = sorted(
        {type(f).__name__ for f in expr.atoms(sp.Function) if type(f).__name__ not in ALLOWED_FUNCTIONS}
    )
    if bad_functions:
        raise ModelError(f"{where}: unknown function(s) {', '.join(bad_functions)}")
    return expr
