"""Step 4 of the perturbation: the approximations a model may declare, by name.

Each approximation is a pure function of the derivation's :class:`~modelgen.model.perturbation.problem.Stage`
(:data:`APPROXIMATIONS`), except those of :data:`EQUATION_APPROXIMATIONS`,
which change the perturbed equations (or measurements) themselves; :func:`scoped` applies one to
the rows its ``in:`` names only.  Their first docstring lines are the
descriptions the model's notes print (:data:`APPROXIMATION_DESCRIPTIONS`).
"""

from __future__ import annotations

from typing import Callable, Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.mechanizations.local_level import Gravity, MeridianRadius, PrimeVerticalRadius
from modelgen.model.perturbation.problem import NavigationProblem, Stage


def _derivative_of(function: sp.FunctionClass, stage: Stage, variable_index: int | None = None) -> set:
    found = set()
    for m in (stage.F, stage.G, stage.H):
        for d in m.atoms(sp.Derivative):
            if isinstance(d.expr, sp.Function) and d.expr.func == function:
                if variable_index is None or d.variables[0] == d.expr.args[variable_index]:
                    found.add(d)
    return found


def _substitute(stage: Stage, mapping: Mapping) -> Stage:
    return Stage(stage.F.xreplace(mapping), stage.G.xreplace(mapping), stage.H.xreplace(mapping))


def constant_radii(stage: Stage, problem: NavigationProblem) -> Stage:
    """R_M and R_N do not vary with latitude: every dR/dL term is dropped."""
    found = _derivative_of(MeridianRadius, stage) | _derivative_of(PrimeVerticalRadius, stage)
    return _substitute(stage, {d: 0 for d in found})


def single_earth_radius(stage: Stage, problem: NavigationProblem) -> Stage:
    """One spherical Earth of radius R: R_M = R_N = R, constant (its parameter ``earth_radius``)."""
    stage = constant_radii(stage, problem)
    if problem.earth.earth_radius is None:
        raise ModelError("single_earth_radius needs an earth_radius parameter")
    radius = problem.earth.earth_radius
    replaced = {f: radius for m in (stage.F, stage.G, stage.H) for f in m.atoms(MeridianRadius, PrimeVerticalRadius)}
    return _substitute(stage, replaced)


def no_height_in_radii(stage: Stage, problem: NavigationProblem) -> Stage:
    """R + h ~ R: the computed height is dropped beside the Earth radii (h << R); gravity keeps its own height."""
    h = problem.position[2]
    out = []
    for m in (stage.F, stage.G, stage.H):
        kept = {a: sp.Dummy("gravity_term") for a in m.atoms(sp.Derivative) | m.atoms(Gravity)}
        dropped = m.xreplace(kept).xreplace({h: 0})
        out.append(dropped.xreplace({v: k for k, v in kept.items()}))
    return Stage(*out)


def constant_gravity(stage: Stage, problem: NavigationProblem) -> Stage:
    """Gravity does not vary with position: dg/dL and dg/dh are dropped."""
    return _substitute(stage, {d: 0 for d in _derivative_of(Gravity, stage)})


def gravity_height_only(stage: Stage, problem: NavigationProblem) -> Stage:
    """Gravity varies with height only: dg/dL is dropped (normal gravity changes 0.5 % pole to equator)."""
    return _substitute(stage, {d: 0 for d in _derivative_of(Gravity, stage, 0)})


def free_air_gradient(stage: Stage, problem: NavigationProblem) -> Stage:
    """dg/dh = -2 g / (R_N + h), the inverse-square free-air gradient, instead of WGS-84's normal-gravity gradient."""
    mapping = {}
    for d in _derivative_of(Gravity, stage, 1):
        L, h = d.expr.args
        mapping[d] = -2 * d.expr / (PrimeVerticalRadius(L) + h)
    return _substitute(stage, mapping)


def free_vertical_channel(stage: Stage, problem: NavigationProblem) -> Stage:
    """No gravity feedback on the height error: dg/dh is dropped (the vertical channel integrates freely)."""
    return _substitute(stage, {d: 0 for d in _derivative_of(Gravity, stage, 1)})


def no_vertical_channel(stage: Stage, problem: NavigationProblem) -> Stage:
    """No vertical channel: the vertical velocity and height errors are not states (their couplings are dropped)."""
    vertical = {problem.errors.velocity_states[2], problem.errors.position_states[2]}
    keep = [0 if s in vertical else 1 for s in problem.state_order]
    mask = sp.diag(*keep)
    return Stage(mask * stage.F * mask, mask * stage.G, stage.H * mask)


def damped_vertical_channel(stage: Stage, problem: NavigationProblem) -> Stage:
    """A baro-damped vertical channel: h' = v_up - k_1 (h - h_baro), v_up' = ... - k_2 (h - h_baro), h_baro taken as true.

    The second-order loop of Titterton & Weston (2004) ch. 3: the height error
    obeys dh' = dv_up - k_1 dh, dv_up' = (2 g/R - k_2) dh + ..., stable for
    k_1 > 0, k_2 > 2 g/R.  The listed terms are the feedback with the opposite
    sign (full minus damped); the baro's own errors are not modelled.
    """
    k1, k2 = problem.vertical_damping_gains
    e = problem.errors
    height, vertical_velocity = e.position_states[2], e.velocity_states[2]
    height_sign = -1 if (e.position == "metres" and problem.frame == "NED") else 1  # d(h) = sign * height state
    velocity_sign = -1 if problem.frame == "NED" else 1  # vertical velocity state = sign * d(v_up)
    i, j = problem.state_order.index(height), problem.state_order.index(vertical_velocity)
    F = stage.F.copy()
    F[i, i] -= k1
    F[j, i] -= k2 * velocity_sign * height_sign
    return Stage(F, stage.G, stage.H)


def level_flight(stage: Stage, problem: NavigationProblem) -> Stage:
    """No vertical velocity: v_down (v_up) = 0."""
    return _substitute(stage, {problem.velocity[2]: 0})


def _applied_while_perturbing(stage: Stage, problem: NavigationProblem) -> Stage:
    """An approximation of :data:`EQUATION_APPROXIMATIONS`: it changes the perturbed equations
    (:func:`_states`), so there is nothing left to do to the result."""
    return stage


#: Approximations a model may declare, by name: each transforms the derivation;
#: those of :data:`EQUATION_APPROXIMATIONS` act on the equations (and measurements) themselves.
APPROXIMATIONS: dict[str, Callable[[Stage, NavigationProblem], Stage]] = {
    "constant_radii": constant_radii,
    "single_earth_radius": single_earth_radius,
    "no_height_in_radii": no_height_in_radii,
    "constant_gravity": constant_gravity,
    "gravity_height_only": gravity_height_only,
    "free_air_gradient": free_air_gradient,
    "free_vertical_channel": free_vertical_channel,
    "level_flight": level_flight,
    "no_vertical_channel": no_vertical_channel,
    "damped_vertical_channel": damped_vertical_channel,
    "no_earth_rate_position_terms": _applied_while_perturbing,
    "no_transport_rate_position_terms": _applied_while_perturbing,
    "no_gravity_gradient": _applied_while_perturbing,
    "lever_arm_at_computed_position": _applied_while_perturbing,
    "pseudorange_at_computed_position": _applied_while_perturbing,
}
#: Approximations that change the perturbed equations rather than the result.
EQUATION_APPROXIMATIONS = frozenset(
    {"no_earth_rate_position_terms", "no_transport_rate_position_terms", "no_gravity_gradient", "lever_arm_at_computed_position",
     "pseudorange_at_computed_position"}
)

APPROXIMATION_DESCRIPTIONS: dict[str, str] = {
    "no_earth_rate_position_terms": "the true state's earth rate w_ie is taken at the computed latitude (no dL terms from it)",
    "no_transport_rate_position_terms": "the true state's transport rate w_en is taken at the computed position (no dL, dh terms from it)",
    "no_gravity_gradient": "the true state's gravity g^e is taken at the computed position (ecef: no dg/dr coupling of the position error)",
    "lever_arm_at_computed_position": (
        "a position measurement's lever arm is turned from metres into (dL, dlambda, dh) at the computed position"
        " (no O(l/R) d(1/(R + h))/dh, dR/dL or tan L terms from it)"
    ),
    "pseudorange_at_computed_position": (
        "a pseudo-range's (and pseudo-range rate's) displacement from the computed receiver is M (computed) times the"
        " position difference, M the metres per (dL, dlambda, dh) at the computed position, not the exact displacement"
        " over the curved Earth (exact to first order: no term of H is dropped; the range itself is off at second order)"
    ),
    **{name: (function.__doc__ or "").strip().split("\n")[0] for name, function in APPROXIMATIONS.items() if function is not _applied_while_perturbing},
}


def scoped(name: str, approximated: Stage, exact: Stage, problem: NavigationProblem) -> Stage:
    """``approximated`` in the rows the approximation is scoped to (``in:``), ``exact`` elsewhere; all of it if unscoped."""
    within = problem.approximation_scopes.get(name)
    if not within:
        return approximated
    e = problem.errors
    states = {"attitude": e.attitude_states, "velocity": e.velocity_states, "position": e.position_states}
    rows = {problem.state_order.index(s) for q in within if q in states for s in states[q] if s in problem.state_order}

    def pick(a: sp.Matrix, b: sp.Matrix, take: set[int]) -> sp.Matrix:
        out = b.copy()
        for i in take:
            out[i, :] = a[i, :]
        return out

    H_rows = set(range(exact.H.rows)) if "measurements" in within else set()
    return Stage(pick(approximated.F, exact.F, rows), pick(approximated.G, exact.G, rows), pick(approximated.H, exact.H, H_rows))
