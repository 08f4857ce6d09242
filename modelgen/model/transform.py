"""Transformations that make a new error model from an existing one.

Each transformation is a pure function ``ErrorModel -> ErrorModel``.  The
result is assembled from declarations and equations (never from matrices) and
goes through :meth:`ErrorModel.build`, so it is validated exactly like a model
read from a file and can be derived, discretized and generated in the same
way.  Every result carries a note saying how it was made.

* :func:`keep_states` -- a subset of the states (e.g. the 16-state
  pure-inertial form of the core paper's 18-state model, or the reduced-order
  suboptimal filters of its section 5);
* :func:`markov_to_white` -- a first-order Markov state replaced by white noise
  of equivalent low-frequency strength (section 5: "simplified to white noise");
* :func:`augment` -- new error states (scale factors, misalignments) with their
  equations and the terms they add to existing equations and measurements.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Iterable, Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Measurement, Noise, Parameter, State
from modelgen.model.expression import parse_expression


# -- helpers ------------------------------------------------------------------
def _resolve_states(model: ErrorModel, names: Iterable[str], what: str) -> list[State]:
    """The model's states named (by name or symbol) in ``names``, in the model's order."""
    names = [names] if isinstance(names, str) else list(names)
    unknown = [n for n in names if not any(n in (s.name, s.symbol) for s in model.states)]
    if unknown:
        raise ModelError(f"{what}: model {model.name!r} has no state named {', '.join(map(repr, unknown))}")
    wanted = set(names)
    chosen = [s for s in model.states if s.name in wanted or s.symbol in wanted]
    if len(chosen) != len(set(names)):
        # a state given both by name and by symbol, or twice
        raise ModelError(f"{what}: a state of model {model.name!r} is named twice in {names}")
    return chosen


def _used_symbols(exprs: Iterable[sp.Expr]) -> set[sp.Symbol]:
    used: set[sp.Symbol] = set()
    for e in exprs:
        used |= e.free_symbols
    return used


def _rebuild(
    model: ErrorModel,
    name: str,
    states: Iterable[State],
    noises: Iterable[Noise],
    dynamics: Mapping[str, sp.Expr],
    measurements: Iterable[Measurement],
    note: str,
    extra_parameters: Iterable[Parameter] = (),
    title: str | None = None,
) -> ErrorModel:
    """Build the new model, keeping only the parameters it still uses.

    A parameter no equation, noise strength or measurement refers to any more
    (e.g. the accelerometer correlation rate once the accelerometer states are
    gone) is dropped, so that generated code asks only for what it needs.
    """
    states, noises, measurements = tuple(states), tuple(noises), tuple(measurements)
    parameters = (*model.parameters, *extra_parameters)
    namespace = {q.symbol: q.sym for q in (*states, *parameters)}
    texts: list[sp.Expr] = list(dynamics.values())
    for w in noises:
        texts.append(parse_expression(w.psd, {p.symbol: p.sym for p in parameters}, f"noise {w.name!r} psd"))
    for m in measurements:
        texts.append(parse_expression(m.expression, namespace, f"measurement {m.name!r}"))
        texts.append(parse_expression(m.variance, {p.symbol: p.sym for p in parameters}, f"measurement {m.name!r}"))
    used = _used_symbols(texts)
    kept_parameters = [p for p in parameters if p.sym in used]
    return ErrorModel.build(
        name=name,
        states=states,
        noises=noises,
        parameters=kept_parameters,
        dynamics=dict(dynamics),
        measurements=measurements,
        title=title if title is not None else model.title,
        source=model.source,
        frame=model.frame,
        notes=(*model.notes, note),
    )


# -- keep a subset of the states ----------------------------------------------
def keep_states(
    model: ErrorModel,
    names: Iterable[str],
    name: str | None = None,
    measurements: Iterable[str] | None = None,
    title: str | None = None,
) -> ErrorModel:
    """The model restricted to the states in ``names`` (names or symbols).

    What happens to everything else, and why:

    * a dropped state is taken as zero wherever it entered a kept state's
      equation, so the new F is exactly the kept rows and columns of the old F
      (the reduced filter simply does not model that error source);
    * a noise that no kept equation uses any more disappears, as does a
      parameter nothing refers to any more;
    * measurements: by default a measurement survives only if it refers to no
      dropped state (its meaning would change silently otherwise: Z = dV_n -
      dV_dn without dV_dn is not the same measurement) and still depends on
      some state.  Dropping the Doppler biases of the 18-state model therefore
      also drops both Doppler measurements, which is the 16-state
      pure-inertial form (the core paper, section 3).  Passing ``measurements``
      (names or symbols) keeps exactly those, with dropped states set to zero;
      a kept measurement whose row would vanish is refused.
    """
    where = f"keep_states({model.name!r})"
    kept = _resolve_states(model, names, where)
    if not kept:
        raise ModelError(f"{where}: no states kept")
    kept_names = {s.name for s in kept}
    dropped = [s for s in model.states if s.name not in kept_names]
    zero = {s.sym: 0 for s in dropped}
    dropped_syms = set(zero)
    kept_syms = {s.sym for s in kept}

    dynamics = {s.name: sp.expand(model.dynamics[s.name].subs(zero)) for s in kept}
    used = _used_symbols(dynamics.values())
    noises = [w for w in model.noises if w.sym in used]

    chosen: list[Measurement] = []
    if measurements is None:
        for m in model.measurements:
            syms = model.measurement_expressions[m.name].free_symbols
            if not (syms & dropped_syms) and (syms & kept_syms):
                chosen.append(m)
    else:
        wanted = list(measurements)
        for key in wanted:
            match = [m for m in model.measurements if key in (m.name, m.symbol)]
            if not match:
                raise ModelError(f"{where}: model {model.name!r} has no measurement named {key!r}")
            m = match[0]
            expr = sp.expand(model.measurement_expressions[m.name].subs(zero))
            if not (expr.free_symbols & kept_syms):
                raise ModelError(f"{where}: measurement {m.name!r} depends on no kept state ({model.measurement_expressions[m.name]})")
            chosen.append(replace(m, expression=str(expr)))

    dropped_text = ", ".join(s.name for s in dropped) or "none"
    lost = [m.name for m in model.measurements if m.name not in {c.name for c in chosen}]
    note = (
        f"keep_states from {model.name}: dropped states {dropped_text} (taken as zero in the remaining equations)"
        + (f"; dropped measurements {', '.join(lost)}" if lost else "")
    )
    return _rebuild(
        model,
        name or f"{model.name}_{len(kept)}states",
        kept,
        noises,
        dynamics,
        chosen,
        note,
        title=title,
    )


# -- replace first-order Markov states by white noise ---------------------------
def _markov_structure(model: ErrorModel, state: State) -> tuple[sp.Expr, Noise, sp.Expr]:
    """(mu, driving noise, noise gain b) of dx/dt = -mu x + b w, or ModelError."""
    where = f"markov_to_white({model.name!r}), state {state.name!r}"
    rhs = sp.expand(model.dynamics[state.name])
    x = state.sym
    if rhs == 0:
        raise ModelError(
            f"{where}: is a random constant (d/dt = 0), not a first-order Markov process; "
            "its white-noise equivalent 2 sigma^2/mu is unbounded (mu = 0). Drop it with keep_states "
            "and account for its variance elsewhere."
        )
    mu = -sp.diff(rhs, x)
    rest = sp.expand(rhs + mu * x)
    others = {s.sym for s in model.states} | {w.sym for w in model.noises}
    if mu == 0 or (mu.free_symbols & others):
        raise ModelError(f"{where}: equation {rhs} is not of the form -mu*x + b*w (no constant decay rate)")
    drivers = [w for w in model.noises if rest.has(w.sym)]
    if len(drivers) != 1:
        raise ModelError(f"{where}: equation {rhs} must be driven by exactly one white noise, found {len(drivers)}")
    w = drivers[0]
    b = sp.diff(rest, w.sym)
    if sp.expand(rest - b * w.sym) != 0 or (b.free_symbols & others):
        raise ModelError(f"{where}: equation {rhs} has terms other than -mu*x + b*w")
    for other, other_rhs in model.dynamics.items():
        if other != state.name and other_rhs.has(w.sym):
            raise ModelError(f"{where}: its driving noise {w.name!r} also enters the equation of {other!r}")
    for m in model.measurements:
        if model.measurement_expressions[m.name].has(x):
            raise ModelError(
                f"{where}: enters measurement {m.name!r}; a continuous white noise cannot be part of a "
                "sampled measurement (its variance would be infinite)"
            )
    return mu, w, b


WHITENING_STRENGTHS = ("low_frequency", "driving_noise")


def markov_to_white(
    model: ErrorModel,
    states: Iterable[str],
    name: str | None = None,
    title: str | None = None,
    strength: str = "low_frequency",
) -> ErrorModel:
    """Replace first-order Markov states by white noise of equivalent strength.

    For dx/dt = -mu x + b w with E[w(t) w(s)] = q delta(t - s) the power
    spectral density of x is S(f) = b^2 q / (mu^2 + omega^2).  A process whose
    correlation time 1/mu is short compared with the dynamics it drives (the
    Schuler and earth-rate loops, hours) acts on them through its
    low-frequency content, so it is replaced by the white noise with the same
    density at zero frequency:

        PSD_white = S(0) = b^2 q / mu^2   (= 2 sigma^2 / mu for q = 2 mu sigma^2, eq. (5))

    This "low-frequency equivalent" keeps the long-term random walk that x
    causes where it is integrated (e.g. the velocity error driven by an
    accelerometer bias): int_0^t x ds has variance -> (2 sigma^2/mu) t for
    t >> 1/mu.  The alternative (matching the variance of x over one filter
    step) would depend on T and overstate high-frequency power.

    ``strength="driving_noise"`` is offered for comparison only: the new
    noise gets the driving noise's own strength b^2 q (= 2 mu sigma^2), i.e. a
    designer keeps the Q(t) of eq. (7) unchanged and feeds it straight into
    the equations x entered.  It understates the low-frequency power by the
    factor 1/mu^2 (3.2e6 s^2 for a 0.5 h correlation time): in effect the
    filter ignores the error source.

    The state and its driving noise disappear; wherever x entered another
    equation, one new noise ``<state name>_white`` (symbol ``<symbol>_w``)
    enters with the same coefficient -- one noise per replaced state, shared
    by all the equations x entered, since it is one physical error.  A state
    that is a random constant, that shares its driving noise, or that enters a
    measurement is refused.
    """
    where = f"markov_to_white({model.name!r})"
    if strength not in WHITENING_STRENGTHS:
        raise ModelError(f"{where}: strength {strength!r} is not one of {WHITENING_STRENGTHS}")
    chosen = _resolve_states(model, states, where)
    if not chosen:
        raise ModelError(f"{where}: no states given")
    replaced = {s.name for s in chosen}
    substitutions: dict[sp.Symbol, sp.Symbol] = {}
    new_noises: list[Noise] = []
    gone_noises: set[str] = set()
    for s in chosen:
        mu, w, b = _markov_structure(model, s)
        divisor = mu**2 if strength == "low_frequency" else 1
        psd = sp.simplify(b**2 * model.noise_psd[w.name] / divisor)
        white = Noise(
            name=f"{s.name}_white",
            symbol=f"{s.symbol}_w",
            unit=f"({s.unit})*sqrt(s)",
            psd=str(psd),
            description=f"white-noise equivalent of {s.name} ({strength.replace('_', '-')} strength)",
        )
        substitutions[s.sym] = white.sym
        new_noises.append(white)
        gone_noises.add(w.name)

    states_left = [s for s in model.states if s.name not in replaced]
    dynamics = {s.name: sp.expand(model.dynamics[s.name].subs(substitutions)) for s in states_left}
    used = _used_symbols(dynamics.values())
    noises = [w for w in model.noises if w.name not in gone_noises] + [w for w in new_noises if w.sym in used]
    note = f"markov_to_white from {model.name}: " + ", ".join(
        f"{s.name} -> white noise {n.name} (PSD {n.psd})" for s, n in zip(chosen, new_noises)
    )
    return _rebuild(
        model,
        name or f"{model.name}_white",
        states_left,
        noises,
        dynamics,
        model.measurements,
        note,
        title=title,
    )


# -- add error states ----------------------------------------------------------
def augment(
    model: ErrorModel,
    new_states: Iterable[State],
    equations: Mapping[str, str | sp.Expr],
    noises: Iterable[Noise] = (),
    parameters: Iterable[Parameter] = (),
    name: str | None = None,
    measurement_terms: Mapping[str, str | sp.Expr] | None = None,
    title: str | None = None,
) -> ErrorModel:
    """Add error states, with their equations and the terms they add elsewhere.

    ``equations`` maps

    * each new state (name or symbol) to its full right-hand side, e.g.
      ``{"k_d": "0"}`` for a random-constant Doppler scale factor, and
    * an existing state (name or symbol) to a term *added* to its right-hand
      side, e.g. ``{"alpha": "c11*omega_bx*k_gx"}``.

    ``measurement_terms`` likewise maps an existing measurement to a term
    added to its expression (``{"Z_n": "-V_n*k_d"}``).  New noises and
    parameters are declared in ``noises`` and ``parameters``; every expression
    may use old and new symbols.  New states are appended after the old ones.
    """
    new_states, noises, parameters = tuple(new_states), tuple(noises), tuple(parameters)
    where = f"augment({model.name!r})"
    if not new_states:
        raise ModelError(f"{where}: no new states given")
    all_states = (*model.states, *new_states)
    all_noises = (*model.noises, *noises)
    all_parameters = (*model.parameters, *parameters)
    namespace = {q.symbol: q.sym for q in (*all_states, *all_noises, *all_parameters)}
    old = {k: s for s in model.states for k in (s.name, s.symbol)}
    new = {k: s for s in new_states for k in (s.name, s.symbol)}

    dynamics: dict[str, sp.Expr] = dict(model.dynamics)
    given_new: set[str] = set()
    for key, text in equations.items():
        expr = parse_expression(text, namespace, f"{where}: equation for {key!r}")
        if key in new:
            given_new.add(new[key].name)
            dynamics[new[key].name] = expr
        elif key in old:
            dynamics[old[key].name] = dynamics[old[key].name] + expr
        else:
            raise ModelError(f"{where}: equation given for {key!r}, which is neither an existing nor a new state")
    missing = [s.name for s in new_states if s.name not in given_new]
    if missing:
        raise ModelError(f"{where}: no equation for new state(s) {', '.join(missing)}")

    measurements = list(model.measurements)
    for key, text in (measurement_terms or {}).items():
        idx = [i for i, m in enumerate(measurements) if key in (m.name, m.symbol)]
        if not idx:
            raise ModelError(f"{where}: term given for measurement {key!r}, which the model does not have")
        m = measurements[idx[0]]
        states_params = {q.symbol: q.sym for q in (*all_states, *all_parameters)}
        term = parse_expression(text, states_params, f"{where}: term for measurement {key!r}")
        measurements[idx[0]] = replace(m, expression=str(sp.expand(model.measurement_expressions[m.name] + term)))

    note = f"augment from {model.name}: added states {', '.join(s.name for s in new_states)}"
    return _rebuild(
        model,
        name or f"{model.name}_augmented",
        all_states,
        all_noises,
        dynamics,
        measurements,
        note,
        extra_parameters=parameters,
        title=title,
    )
