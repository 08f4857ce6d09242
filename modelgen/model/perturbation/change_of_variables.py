"""Step 3 of the perturbation: from the primitive errors to the declared error states.

Declared error states that are linear, position-dependent combinations of the
primitive errors (position in metres, the psi-angle of Benson 1975, velocity
error in the computed frame, a body-axis rotation vector) follow from
F = (T F_0 + dT/dt) T^-1, G = T G_0, H = H_0 T^-1, with dT/dt along the
computed trajectory.
"""

from __future__ import annotations

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.mechanizations.local_level import _vector, skew
from modelgen.model.perturbation.linearization import primitive_symbols
from modelgen.model.perturbation.problem import (
    NavigationProblem,
    NavigationState,
    Stage,
    declared_navigation_states,
    sensed_navigation_force,
)


def _change_of_variables(problem: NavigationProblem) -> tuple[sp.Matrix, sp.Matrix]:
    """(T, T^-1) with declared = T primitive, as Jacobians of the forward and inverse maps."""
    phi, dv, dp = primitive_symbols(problem.position.rows)
    e = problem.errors
    others = [s for s in problem.state_order if s not in declared_navigation_states(problem)]
    mech = problem.mechanization()
    M = mech.metres(problem.position)
    theta = lambda d: mech.error_frame_angle(problem.position, d)  # noqa: E731  d(theta) of a position error
    # forward: declared errors from primitive ones
    position = M * dp if e.position == "metres" else dp
    C = problem.attitude
    body_axes = e.attitude == "rotation_vector" and e.attitude_axes == "body"
    attitude = phi - theta(dp) if e.attitude == "psi" else -C.T * phi if body_axes else phi
    velocity = dv + theta(dp).cross(problem.velocity) if e.velocity == "computed_frame" else dv
    forward = {**dict(zip(e.attitude_states, attitude)), **dict(zip(e.velocity_states, velocity)), **dict(zip(e.position_states, position))}
    # inverse: primitive errors from declared ones
    d_pos, d_att, d_vel = _vector(e.position_states), _vector(e.attitude_states), _vector(e.velocity_states)
    dp_of = mech.metres_inverse(problem.position) * d_pos if e.position == "metres" else d_pos
    phi_of = d_att + theta(dp_of) if e.attitude == "psi" else -C * d_att if body_axes else d_att
    dv_of = d_vel - theta(dp_of).cross(problem.velocity) if e.velocity == "computed_frame" else d_vel
    primitive = [*phi, *dv, *dp, *others]
    declared = list(problem.state_order)
    forward_rows = _vector([forward.get(s, s) for s in declared])
    inverse_rows = sp.Matrix.vstack(phi_of, dv_of, dp_of, _vector(others) if others else sp.zeros(0, 1))
    return forward_rows.jacobian(primitive), inverse_rows.jacobian(declared)


def _time_derivative(matrix: sp.Matrix, problem: NavigationProblem) -> sp.Matrix:
    """dT/dt along the computed trajectory (T depends on the computed velocity and position)."""
    mech = problem.mechanization()
    p = problem.position
    computed = NavigationState(problem.attitude, problem.velocity, p, sensed_navigation_force(problem), problem.body_rate, p, p)
    variables = [*problem.velocity, *problem.position]
    rates = [*mech.velocity_rate(computed), *mech.position_rate(computed)]
    C = problem.attitude
    if any(not matrix.diff(c).is_zero_matrix for c in C):  # a body-axis attitude error: T holds C^T
        if problem.body_rate is None:
            raise ModelError("a body-axis attitude error needs the body rate (navigation.body_rate) for the rate of C_b^n")
        attitude_rate = C * skew(problem.body_rate) - skew(mech.navigation_rate(computed)) * C  # C' = C [w_ib x] - [w_in x] C
        variables += list(C)
        rates += list(attitude_rate)
    out = sp.zeros(*matrix.shape)
    for variable, rate in zip(variables, rates):
        partial = matrix.diff(variable)
        if partial.is_zero_matrix:
            continue
        out += partial * rate
    return out


def declared_stage(problem: NavigationProblem, primitive: Stage) -> Stage:
    """Step 3: F = (T F_0 + T') T^-1, G = T G_0, H = H_0 T^-1."""
    T, T_inv = _change_of_variables(problem)
    if T == sp.eye(T.rows):
        return primitive
    T_dot = _time_derivative(T, problem)
    mech = problem.mechanization()
    if not hasattr(mech, "declared_products"):
        return Stage((T * primitive.F + T_dot) * T_inv, T * primitive.G, primitive.H * T_inv)
    # a mechanization whose position is a chart about the operating point (wander azimuth): the products there,
    # reduced exactly (its K^-1 K = I: polynomials in 1/det K, reduced by (1/det K) det K = 1 and the ellipsoid's relations)
    return Stage(*mech.declared_products((T, T_dot, T_inv, primitive.F, primitive.G, primitive.H), problem.position))
