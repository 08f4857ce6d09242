"""Steps 1 and 2 of the perturbation: the primitive error equations F_0, G_0, H_0.

*Perturb*: the true navigation state is the computed one composed with the
primitive errors (phi, dv, dp): v_t = v - dv, p_t = p - dp, C_t = (I + [phi x]) C,
and the true sensor inputs invert the sensor models.  *Differentiate*: the
error rates are computed-minus-true rates of the mechanization's equations (for
the attitude the exact first-order phi-angle kinematics), and F_0, G_0, H_0 are
their Jacobians at zero error, with the Earth's radii and gravity differentiated
by the chain rule as functions of position (Shin 2005 ch. 4; Groves 2013 ch. 14).
"""

from __future__ import annotations

from typing import Mapping, Sequence

import sympy as sp

from modelgen.model.mechanizations import EARTH_FUNCTIONS
from modelgen.model.mechanizations.local_level import _vector, skew
from modelgen.model.perturbation.problem import (
    Mechanization,
    NavigationProblem,
    NavigationState,
    Stage,
    declared_navigation_states,
    sensed_navigation_force,
)

def _make_primitive_symbols() -> tuple[sp.Matrix, sp.Matrix, sp.Matrix]:
    """phi, dv, dp: the primitive errors (attitude, velocity, position coordinates: 3, or 4 for wander azimuth's chart)."""
    make = lambda prefix, n=3: _vector(sp.symbols(f"{prefix}0:{n}", real=True, cls=sp.Dummy))  # noqa: E731
    return make("primitive_phi"), make("primitive_dv"), make("primitive_dp", 4)


def _states(problem: NavigationProblem, approximations: set[str]) -> tuple[NavigationState, NavigationState, dict]:
    """The computed state, the true state (in true-state symbols) and those true-state symbols.

    True attitude (I + [phi x]) C; true specific force in navigation axes
    (I + [phi x]) (C f~ - C df), df = measured - true from the sensor model.
    The true state's earth and transport rates take the computed position
    under the approximations named for that, and so does the conversion of a
    measurement's lever arm from metres to (dL, dlambda, dh) under
    ``lever_arm_at_computed_position`` (otherwise it is taken at the true position).
    """
    phi, _, _ = primitive_symbols()
    true_v = _vector(sp.symbols("true_v0:3", real=True, cls=sp.Dummy))
    true_p = _vector(_TRUE_POSITION[: problem.position.rows])
    C = problem.attitude
    body_input = problem.specific_force if problem.specific_force_axes == "body" else None
    force_error = problem.accelerometer.error(body_input, "accelerometer")
    sensed = sensed_navigation_force(problem)
    true_force = (sp.eye(3) + skew(phi)) * (sensed - C * force_error - problem.accelerometer.navigation_noise())
    p = problem.position
    computed = NavigationState(C, problem.velocity, p, sensed, problem.body_rate, p, p)
    earth_at = p if "no_earth_rate_position_terms" in approximations else true_p
    transport_at = p if "no_transport_rate_position_terms" in approximations else true_p
    true_rate = None if problem.body_rate is None else problem.body_rate - problem.gyro.error(problem.body_rate, "gyro")
    gravity_at = p if "no_gravity_gradient" in approximations else None
    lever_arm_at = p if "lever_arm_at_computed_position" in approximations else None
    true = NavigationState((sp.eye(3) + skew(phi)) * C, true_v, true_p, true_force, true_rate, earth_at, transport_at, gravity_at, lever_arm_at)
    return computed, true, {"v": true_v, "p": true_p}


#: The primitive error symbols, one set for the module, so that every stage of a derivation shares them.
_PRIMITIVES = _make_primitive_symbols()
_TRUE_POSITION = sp.symbols("true_p0:4", real=True, cls=sp.Dummy)


def primitive_symbols(position_size: int = 3) -> tuple[sp.Matrix, sp.Matrix, sp.Matrix]:
    """phi, dv, dp of this module (:data:`_PRIMITIVES`), dp with one entry per position coordinate."""
    phi, dv, dp = _PRIMITIVES
    return phi, dv, dp[:position_size, :]


def primitive_stage(problem: NavigationProblem, equation_approximations: set[str]) -> Stage:
    """F_0, G_0, H_0 over (phi, dv, dp, other declared states) at zero error (steps 1-2)."""
    phi, dv, dp = primitive_symbols(problem.position.rows)
    mech = problem.mechanization()
    computed, true, true_symbols = _states(problem, equation_approximations)
    w_in_c = mech.navigation_rate(computed)
    gyro_error = problem.gyro.error(problem.body_rate, "gyro")
    rates = sp.Matrix.vstack(
        -w_in_c.cross(phi) + (w_in_c - mech.navigation_rate(true)) - problem.attitude * gyro_error - problem.gyro.navigation_noise(),
        mech.velocity_rate(computed) - mech.velocity_rate(true),
        mech.position_rate(computed) - mech.position_rate(true),
    )
    others = [s for s in problem.state_order if s not in declared_navigation_states(problem)]
    aux = _vector([problem.auxiliary_dynamics[s] for s in others]) if others else sp.zeros(0, 1)
    rates = sp.Matrix.vstack(rates, aux)
    to_true = {**dict(zip(true_symbols["v"], problem.velocity)), **dict(zip(true_symbols["p"], problem.position))}
    by = [*phi, *true_symbols["v"], *true_symbols["p"], *others]
    zero = {s: 0 for s in (*phi, *others, *problem.noises)}
    # d/d(dv) = -d/d(v_t) because v_t = v - dv (and the same for position).
    sign = sp.diag(*([1] * 3 + [-1] * (3 + problem.position.rows) + [1] * len(others)))
    F0 = _at(_jacobian(rates, by), zero, to_true) * sign
    G0 = _at(rates.jacobian(list(problem.noises)), zero, to_true) if problem.noises else sp.zeros(rates.rows, 0)
    H0 = _measurement_jacobian(problem, mech, computed, true, by, zero, to_true) * sign
    return Stage(F0, G0, H0)


def _jacobian(matrix: sp.Matrix, by: Sequence[sp.Symbol]) -> sp.Matrix:
    """``matrix.jacobian(by)``, with the Earth functions differentiated by the chain rule.

    Each R_M(L), R_N(L), g(L, h) whose arguments are in ``by`` stands in as a
    plain symbol while differentiating (sympy builds Derivative objects of
    applied functions slowly); its partial derivatives are added once, as
    ``Derivative(R_M(L), L)`` terms, for the rules of :func:`earth_derivative_rules`.
    """
    variables = set(by)
    applied = sorted(
        (a for a in matrix.atoms(*EARTH_FUNCTIONS) if variables & set(a.args)),
        key=sp.default_sort_key,
    )
    stand_in = {a: sp.Dummy(f"earth_{k}", real=True) for k, a in enumerate(applied)}
    plain = matrix.xreplace(stand_in)
    result = plain.jacobian(list(by))
    for function, symbol in stand_in.items():
        partial = plain.diff(symbol)
        if partial.is_zero_matrix:
            continue
        for argument in function.args:
            if argument in variables:
                column = list(by).index(argument)
                result[:, column] = result[:, column] + partial * sp.Derivative(function, argument)
    return result.xreplace({v: k for k, v in stand_in.items()})


def _at(matrix: sp.Matrix, zero: Mapping, to_true: Mapping) -> sp.Matrix:
    """A Jacobian at zero error: errors and noises 0, the true state equal to the computed one."""
    return matrix.xreplace(zero).xreplace(to_true)


def _measurement_jacobian(
    problem: NavigationProblem, mech: Mechanization, computed: NavigationState, true: NavigationState,
    by: Sequence[sp.Symbol], zero: Mapping, to_true: Mapping,
) -> sp.Matrix:
    """H_0: rows of z = scale (h(computed) - h(true)) + extra, differentiated by ``by``."""
    rows = []
    for m in problem.measurements:
        difference = m.function(computed, computed, mech) - m.function(true, computed, mech)
        if m.scale is not None:
            difference = m.scale(computed) * difference
        if m.extra is not None:
            difference = difference - m.extra
        if m.measured_minus_computed:
            difference = -difference
        rows.append(_at(_jacobian(difference, by), zero, to_true))
    return sp.Matrix.vstack(*rows) if rows else sp.zeros(0, len(by))
