"""Error models derived from the navigation equations, by symbolic perturbation.

Instead of typing the linear error equations, a model states the nonlinear
local-level mechanization (attitude C_b^n, velocity v^n, geodetic position
L, lambda, h), the sensor models, the definition of each error state and the
measurements as functions of the navigation state.  This module derives

    d(x)/dt = F x + G w,   z = H x + v

exactly to first order:

1. *Perturb.*  The true navigation state is written as the computed one
   composed with the error: v_t = v - dv, p_t = p - dp and
   C_t = (I + [phi x]) C (the phi-angle: the computed attitude is
   C = (I - [phi x]) C_t).  The true sensor inputs come from inverting the
   sensor model, e.g. measured rate = (I + diag(s_g)) w + b_g + w_g.
2. *Differentiate.*  The error rates are computed-minus-true rates of the same
   equations, d(dv)/dt = f_v(computed) - f_v(true); for the attitude the exact
   first-order kinematics of the phi-angle, d(phi)/dt = -w_in x phi + dw_in -
   C dw_ib (the one step that needs C C^T = I, done once here).  F, G and H
   are Jacobians at zero error (``sympy.Matrix.jacobian``).
3. *Change variables.*  Declared error states that are linear, position-
   dependent combinations of those primitive errors (position in metres,
   psi-angle, velocity error in the computed frame) follow from
   F = (T F_0 + dT/dt) T^-1, G = T G_0, H = H_0 T^-1, with dT/dt along the
   computed trajectory.
4. *Approximate, by name.*  Each declared approximation is a pure function of
   the derivation (:data:`APPROXIMATIONS`); the terms it removes are kept as
   :class:`NeglectedTerm` records (matrix, row, column, the symbolic term),
   so that nothing is dropped silently.
5. *Simplify* with one fixed pipeline (:func:`simplify_entry`), so that the
   result is the same text run to run.

The Earth's radii and gravity are carried as functions of position
(``R_M(L)``, ``R_N(L)``, ``g(L, h)``) while deriving, so that their derivatives
are visible as terms; at the end they become the model's parameters
(``meridian_radius`` ...) and their derivatives the WGS-84 formulas of
:func:`earth_derivative_rules`.

Sources: Shin (2005), "Estimation techniques for low-cost inertial
navigation", ch. 4 (phi-angle NED error model); Groves (2013), "Principles of
GNSS, Inertial, and Multisensor Integrated Navigation Systems", ch. 5 and 14;
Benson (1975), "A comparison of two approaches to pure-inertial and Doppler-
inertial error analysis" (psi-angle); NIMA TR8350.2 (WGS-84 radii and normal
gravity).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Sequence

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model import wgs84
from modelgen.model.mechanizations.ecef import GeocentricRadius
from modelgen.model.mechanizations.local_level import (  # noqa: F401  (the engine's names for them, re-exported)
    FRAME_AXES,
    Gravity,
    LocalLevel,
    MeridianRadius,
    PrimeVerticalRadius,
    earth_rate_vector,
    gravity_vector,
    metres_matrix,
    metres_matrix_inverse,
    north_east_vertical,
    position_angle_rates,
    position_rate,
    EarthSymbols,
    _vector,
    skew,
)

ATTITUDE_FORMS = ("phi", "psi", "rotation_vector")
#: Axes a rotation-vector attitude error may be resolved in.
ATTITUDE_AXES = ("navigation", "body")
VELOCITY_FORMS = ("difference", "computed_frame")
POSITION_FORMS = ("geodetic", "metres")


@dataclass(frozen=True)
class NavigationState:
    """One navigation solution: attitude C_b^n, velocity, geodetic position and what it senses."""

    attitude: sp.Matrix
    velocity: sp.Matrix
    position: sp.Matrix
    specific_force: sp.Matrix  # resolved in the navigation frame
    body_rate: sp.Matrix | None  # w_ib^b in body axes, if the model has it
    earth_rate_position: sp.Matrix  # where w_ie takes its latitude (the state's own unless approximated)
    transport_rate_position: sp.Matrix  # where w_en takes its position (the state's own unless approximated)
    gravity_position: sp.Matrix | None = None  # where the ecef mechanization's g^e takes its position (None: the state's own)


#: The local-level mechanization, by its former name (the engine's default).
Mechanization = LocalLevel


# -- what the model file declares ------------------------------------------------
@dataclass(frozen=True)
class InertialSensorErrors:
    """measured = (I + diag(scale_factor)) true + bias + noise; any part may be absent (None).

    ``noise_axes`` ``navigation``: the white noise is given resolved in the
    navigation frame (C w_body, a model that assumes equal noise on every axis),
    so it enters the navigation equations without the attitude matrix.
    """

    bias: sp.Matrix | None = None
    scale_factor: sp.Matrix | None = None
    noise: sp.Matrix | None = None
    noise_axes: str = "body"

    def error(self, measured: sp.Matrix | None, what: str) -> sp.Matrix:
        """measured - true in body axes, with true = (measured - bias - noise) / (1 + scale_factor) per axis (exact)."""
        body_noise = self.noise if self.noise_axes == "body" else None
        parts = [p for p in (self.bias, body_noise) if p is not None]
        offset = sum(parts, sp.zeros(3, 1)) if parts else sp.zeros(3, 1)
        if self.scale_factor is None:
            return offset
        if measured is None:
            raise ModelError(f"the {what} scale factor needs the sensed {what} input in body axes")
        return _vector([measured[i] - (measured[i] - offset[i]) / (1 + self.scale_factor[i]) for i in range(3)])

    def navigation_noise(self) -> sp.Matrix:
        """The white noise resolved in the navigation frame (zero when it is given in body axes)."""
        return self.noise if self.noise is not None and self.noise_axes == "navigation" else sp.zeros(3, 1)


@dataclass(frozen=True)
class ErrorDefinition:
    """How the declared navigation error states are defined (computed minus true).

    attitude ``phi``: C = (I - [phi x]) C_t; ``psi``: phi = psi + d(theta), the
    attitude error against the computed local-level frame (Benson 1975).
    velocity ``difference``: dv = v - v_t; ``computed_frame``: v - C_n^c v_t =
    dv + d(theta) x v.  position ``geodetic``: (dL, dlambda, dh); ``metres``:
    :func:`metres_matrix` times them, in the frame's axes.
    """

    attitude: str
    attitude_states: tuple[sp.Symbol, ...]
    velocity: str
    velocity_states: tuple[sp.Symbol, ...]
    position: str
    position_states: tuple[sp.Symbol, ...]
    #: ``rotation_vector`` only: ``navigation`` (C = exp(-[theta x]) C_true, left, = phi to first order) or
    #: ``body`` (C = C_true exp([theta x]), right, as the MEKF / error-state filters: theta = -C^T phi to first order).
    attitude_axes: str = "navigation"


@dataclass(frozen=True)
class AttitudeReset:
    """The attitude error's reset Jacobian for closed-loop feedback: P+ = G P G^T over the attitude states.

    After the filter's estimate ``correction`` (the attitude states' estimate, same
    symbols with ``_estimate``) is fed back into the computed attitude and the error
    states are zeroed, the new error is theta+ = theta - correction - 1/2 correction x
    theta + O(|theta|^2) for a rotation vector in either axes, in this file's
    computed-minus-true convention (second-order Baker-Campbell-Hausdorff): G = I + 1/2
    [correction x] (Markley 2003, Sola 2017 eq. 287, whose true-minus-computed sign
    gives I - 1/2 [dtheta x]).  phi and psi are fed back additively to first order: G = I.
    """

    form: str
    axes: str
    states: tuple[str, ...]  # the attitude error states' names, in model order
    correction: tuple[sp.Symbol, ...]  # the fed-back estimate of each
    matrix: sp.Matrix


def attitude_reset(errors: ErrorDefinition, names: Sequence[str]) -> AttitudeReset:
    """The :class:`AttitudeReset` of an error definition (``names``: the attitude states' names)."""
    correction = tuple(sp.Symbol(f"{s}_estimate", real=True) for s in errors.attitude_states)
    if errors.attitude == "rotation_vector":
        matrix = sp.eye(3) + skew(_vector(correction)) / 2
    else:
        matrix = sp.eye(3)
    return AttitudeReset(errors.attitude, errors.attitude_axes, tuple(names), correction, matrix)


@dataclass(frozen=True)
class MeasurementFunction:
    """A measurement as a function of the navigation state.

    z = scale (h(computed) - h(true)) - extra, or its negative when
    ``measured_minus_computed``; ``extra`` is what the measured value has on
    top of h(true), linear in declared error states (a receiver clock bias).  ``h(state, computed)`` sees the true (or computed)
    state and the computed one.
    """

    symbols: tuple[sp.Symbol, ...]
    function: Callable[[NavigationState, NavigationState, Mechanization], sp.Matrix]
    scale: Callable[[NavigationState], sp.Matrix] | None = None
    extra: sp.Matrix | None = None
    measured_minus_computed: bool = False


@dataclass(frozen=True)
class NavigationProblem:
    """Everything :func:`derive_error_equations` needs, as sympy objects (no YAML)."""

    frame: str
    attitude: sp.Matrix  # computed C_b^n (symbols)
    velocity: sp.Matrix
    position: sp.Matrix  # (L, lambda, h)
    specific_force: sp.Matrix  # sensed specific force (symbols)
    specific_force_axes: str  # "body" or "navigation"
    body_rate: sp.Matrix | None
    earth: EarthSymbols
    errors: ErrorDefinition
    gyro: InertialSensorErrors
    accelerometer: InertialSensorErrors
    state_order: tuple[sp.Symbol, ...]  # every declared error state, in model order
    auxiliary_dynamics: Mapping[sp.Symbol, sp.Expr]  # d/dt of the non-navigation states (biases, clock)
    noises: tuple[sp.Symbol, ...]
    measurements: tuple[MeasurementFunction, ...] = ()
    approximations: tuple[str, ...] = ()
    equations: Mapping[str, Callable[[NavigationState, Mechanization], sp.Matrix]] = field(default_factory=dict)
    #: Gains (k_1 [1/s], k_2 [1/s^2]) of the baro-damped vertical channel (approximation damped_vertical_channel).
    vertical_damping_gains: tuple[sp.Symbol, sp.Symbol] = (sp.Symbol("k_v1", real=True), sp.Symbol("k_v2", real=True))
    #: The mechanization's name in :data:`modelgen.model.mechanizations.MECHANIZATIONS`.
    mechanization_name: str = "local_level"
    #: Approximations that apply to some rows only (``{name: constant_radii, in: [velocity]}``): name -> the
    #: quantities (attitude, velocity, position: their error states' rows of F and G; measurements: H).
    approximation_scopes: Mapping[str, tuple[str, ...]] = field(default_factory=dict)

    def mechanization(self) -> Mechanization:
        """The named mechanization (modelgen.model.mechanizations), with the equations the model writes itself."""
        from modelgen.model.mechanizations import mechanization_named

        return mechanization_named(self.mechanization_name)(
            self.frame, self.earth.earth_rate, self.equations.get("velocity"), self.equations.get("position")
        )


@dataclass(frozen=True)
class NeglectedTerm:
    """One term an approximation removed: ``matrix[row, column]`` lost ``term``."""

    approximation: str
    matrix: str
    row: int
    column: int
    term: sp.Expr


@dataclass(frozen=True)
class ErrorEquations:
    """The derived F, G, H (in parameter symbols) and what the approximations removed."""

    F: sp.Matrix
    G: sp.Matrix
    H: sp.Matrix
    states: tuple[sp.Symbol, ...]
    noises: tuple[sp.Symbol, ...]
    measurements: tuple[sp.Symbol, ...]
    neglected: tuple[NeglectedTerm, ...] = field(default_factory=tuple)
    #: Each neglected term as a person reads it: R_M, R_N, g and their derivatives (dR_M/dL ...) by name.
    readable: tuple[str, ...] = ()


# -- step 1 and 2: primitive error equations ----------------------------------------
@dataclass(frozen=True)
class _Stage:
    """Matrices with the Earth functions still unevaluated (between approximations)."""

    F: sp.Matrix
    G: sp.Matrix
    H: sp.Matrix


def _primitive_symbols() -> tuple[sp.Matrix, sp.Matrix, sp.Matrix]:
    """phi, dv, dp: the primitive errors (attitude, velocity, geodetic position)."""
    make = lambda prefix: _vector(sp.symbols(f"{prefix}0:3", real=True, cls=sp.Dummy))  # noqa: E731
    return make("primitive_phi"), make("primitive_dv"), make("primitive_dp")


def _sensed_navigation_force(problem: NavigationProblem) -> sp.Matrix:
    """C f~ (or f~ when the model gives the sensed specific force in navigation axes)."""
    if problem.specific_force_axes == "navigation":
        return problem.specific_force
    return problem.attitude * problem.specific_force


def _states(problem: NavigationProblem, approximations: set[str]) -> tuple[NavigationState, NavigationState, dict]:
    """The computed state, the true state (in true-state symbols) and those true-state symbols.

    True attitude (I + [phi x]) C; true specific force in navigation axes
    (I + [phi x]) (C f~ - C df), df = measured - true from the sensor model.
    The true state's earth and transport rates take the computed position
    under the approximations named for that.
    """
    phi, _, _ = _primitive_symbols_cached()
    true_v = _vector(sp.symbols("true_v0:3", real=True, cls=sp.Dummy))
    true_p = _vector(sp.symbols("true_p0:3", real=True, cls=sp.Dummy))
    C = problem.attitude
    body_input = problem.specific_force if problem.specific_force_axes == "body" else None
    force_error = problem.accelerometer.error(body_input, "accelerometer")
    sensed = _sensed_navigation_force(problem)
    true_force = (sp.eye(3) + skew(phi)) * (sensed - C * force_error - problem.accelerometer.navigation_noise())
    p = problem.position
    computed = NavigationState(C, problem.velocity, p, sensed, problem.body_rate, p, p)
    earth_at = p if "no_earth_rate_position_terms" in approximations else true_p
    transport_at = p if "no_transport_rate_position_terms" in approximations else true_p
    true_rate = None if problem.body_rate is None else problem.body_rate - problem.gyro.error(problem.body_rate, "gyro")
    gravity_at = p if "no_gravity_gradient" in approximations else None
    true = NavigationState((sp.eye(3) + skew(phi)) * C, true_v, true_p, true_force, true_rate, earth_at, transport_at, gravity_at)
    return computed, true, {"v": true_v, "p": true_p}


#: The primitive error symbols, one set for the module, so that every stage of a derivation shares them.
_PRIMITIVES = _primitive_symbols()


def _primitive_symbols_cached() -> tuple[sp.Matrix, sp.Matrix, sp.Matrix]:
    """phi, dv, dp of this module (:data:`_PRIMITIVES`)."""
    return _PRIMITIVES


def _primitive_stage(problem: NavigationProblem, equation_approximations: set[str]) -> _Stage:
    """F_0, G_0, H_0 over (phi, dv, dp, other declared states) at zero error (steps 1-2)."""
    phi, dv, dp = _primitive_symbols_cached()
    mech = problem.mechanization()
    computed, true, true_symbols = _states(problem, equation_approximations)
    w_in_c = mech.navigation_rate(computed)
    gyro_error = problem.gyro.error(problem.body_rate, "gyro")
    rates = sp.Matrix.vstack(
        -w_in_c.cross(phi) + (w_in_c - mech.navigation_rate(true)) - problem.attitude * gyro_error - problem.gyro.navigation_noise(),
        mech.velocity_rate(computed) - mech.velocity_rate(true),
        mech.position_rate(computed) - mech.position_rate(true),
    )
    others = [s for s in problem.state_order if s not in _declared_navigation_states(problem)]
    aux = _vector([problem.auxiliary_dynamics[s] for s in others]) if others else sp.zeros(0, 1)
    rates = sp.Matrix.vstack(rates, aux)
    to_true = {**dict(zip(true_symbols["v"], problem.velocity)), **dict(zip(true_symbols["p"], problem.position))}
    by = [*phi, *true_symbols["v"], *true_symbols["p"], *others]
    zero = {s: 0 for s in (*phi, *others, *problem.noises)}
    # d/d(dv) = -d/d(v_t) because v_t = v - dv (and the same for position).
    sign = sp.diag(*([1] * 3 + [-1] * 6 + [1] * len(others)))
    F0 = _at(_jacobian(rates, by), zero, to_true) * sign
    G0 = _at(rates.jacobian(list(problem.noises)), zero, to_true) if problem.noises else sp.zeros(rates.rows, 0)
    H0 = _measurement_jacobian(problem, mech, computed, true, by, zero, to_true) * sign
    return _Stage(F0, G0, H0)


def _jacobian(matrix: sp.Matrix, by: Sequence[sp.Symbol]) -> sp.Matrix:
    """``matrix.jacobian(by)``, with the Earth functions differentiated by the chain rule.

    Each R_M(L), R_N(L), g(L, h) whose arguments are in ``by`` stands in as a
    plain symbol while differentiating (sympy builds Derivative objects of
    applied functions slowly); its partial derivatives are added once, as
    ``Derivative(R_M(L), L)`` terms, for the rules of :func:`earth_derivative_rules`.
    """
    variables = set(by)
    applied = sorted(
        (a for a in matrix.atoms(MeridianRadius, PrimeVerticalRadius, Gravity, GeocentricRadius) if variables & set(a.args)),
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


def _declared_navigation_states(problem: NavigationProblem) -> tuple[sp.Symbol, ...]:
    e = problem.errors
    return (*e.attitude_states, *e.velocity_states, *e.position_states)


# -- step 3: change of variables --------------------------------------------------------
def _change_of_variables(problem: NavigationProblem) -> tuple[sp.Matrix, sp.Matrix]:
    """(T, T^-1) with declared = T primitive, as Jacobians of the forward and inverse maps."""
    phi, dv, dp = _primitive_symbols_cached()
    e = problem.errors
    others = [s for s in problem.state_order if s not in _declared_navigation_states(problem)]
    mech = problem.mechanization()
    M = mech.metres(problem.position)
    L = problem.position[0]
    theta = lambda d: mech.error_frame_angle(L, d)  # noqa: E731  d(theta) of a position error
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
    computed = NavigationState(problem.attitude, problem.velocity, p, _sensed_navigation_force(problem), problem.body_rate, p, p)
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


def _declared_stage(problem: NavigationProblem, primitive: _Stage) -> _Stage:
    """Step 3: F = (T F_0 + T') T^-1, G = T G_0, H = H_0 T^-1."""
    T, T_inv = _change_of_variables(problem)
    if T == sp.eye(T.rows):
        return primitive
    T_dot = _time_derivative(T, problem)
    return _Stage((T * primitive.F + T_dot) * T_inv, T * primitive.G, primitive.H * T_inv)


# -- step 4: approximations ---------------------------------------------------------------
def _derivative_of(function: sp.FunctionClass, stage: _Stage, variable_index: int | None = None) -> set:
    found = set()
    for m in (stage.F, stage.G, stage.H):
        for d in m.atoms(sp.Derivative):
            if isinstance(d.expr, sp.Function) and d.expr.func == function:
                if variable_index is None or d.variables[0] == d.expr.args[variable_index]:
                    found.add(d)
    return found


def _substitute(stage: _Stage, mapping: Mapping) -> _Stage:
    return _Stage(stage.F.xreplace(mapping), stage.G.xreplace(mapping), stage.H.xreplace(mapping))


def constant_radii(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """R_M and R_N do not vary with latitude: every dR/dL term is dropped."""
    found = _derivative_of(MeridianRadius, stage) | _derivative_of(PrimeVerticalRadius, stage)
    return _substitute(stage, {d: 0 for d in found})


def single_earth_radius(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """One spherical Earth of radius R: R_M = R_N = R, constant (its parameter ``earth_radius``)."""
    stage = constant_radii(stage, problem)
    if problem.earth.earth_radius is None:
        raise ModelError("single_earth_radius needs an earth_radius parameter")
    radius = problem.earth.earth_radius
    replaced = {f: radius for m in (stage.F, stage.G, stage.H) for f in m.atoms(MeridianRadius, PrimeVerticalRadius)}
    return _substitute(stage, replaced)


def no_height_in_radii(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """R + h ~ R: the computed height is dropped beside the Earth radii (h << R); gravity keeps its own height."""
    h = problem.position[2]
    out = []
    for m in (stage.F, stage.G, stage.H):
        kept = {a: sp.Dummy("gravity_term") for a in m.atoms(sp.Derivative) | m.atoms(Gravity)}
        dropped = m.xreplace(kept).xreplace({h: 0})
        out.append(dropped.xreplace({v: k for k, v in kept.items()}))
    return _Stage(*out)


def constant_gravity(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """Gravity does not vary with position: dg/dL and dg/dh are dropped."""
    return _substitute(stage, {d: 0 for d in _derivative_of(Gravity, stage)})


def gravity_height_only(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """Gravity varies with height only: dg/dL is dropped (normal gravity changes 0.5 % pole to equator)."""
    return _substitute(stage, {d: 0 for d in _derivative_of(Gravity, stage, 0)})


def free_air_gradient(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """dg/dh = -2 g / (R_N + h), the inverse-square free-air gradient, instead of WGS-84's normal-gravity gradient."""
    mapping = {}
    for d in _derivative_of(Gravity, stage, 1):
        L, h = d.expr.args
        mapping[d] = -2 * d.expr / (PrimeVerticalRadius(L) + h)
    return _substitute(stage, mapping)


def free_vertical_channel(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """No gravity feedback on the height error: dg/dh is dropped (the vertical channel integrates freely)."""
    return _substitute(stage, {d: 0 for d in _derivative_of(Gravity, stage, 1)})


def no_vertical_channel(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """No vertical channel: the vertical velocity and height errors are not states (their couplings are dropped)."""
    vertical = {problem.errors.velocity_states[2], problem.errors.position_states[2]}
    keep = [0 if s in vertical else 1 for s in problem.state_order]
    mask = sp.diag(*keep)
    return _Stage(mask * stage.F * mask, mask * stage.G, stage.H * mask)


def damped_vertical_channel(stage: _Stage, problem: NavigationProblem) -> _Stage:
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
    return _Stage(F, stage.G, stage.H)


def level_flight(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """No vertical velocity: v_down (v_up) = 0."""
    return _substitute(stage, {problem.velocity[2]: 0})


def _applied_while_perturbing(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """An approximation of :data:`EQUATION_APPROXIMATIONS`: it changes the perturbed equations
    (:func:`_states`), so there is nothing left to do to the result."""
    return stage


#: Approximations a model may declare, by name: each transforms the derivation;
#: the two whose names say "position terms" act on the equations themselves.
APPROXIMATIONS: dict[str, Callable[[_Stage, NavigationProblem], _Stage]] = {
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
}
#: Approximations that change the perturbed equations rather than the result.
EQUATION_APPROXIMATIONS = frozenset({"no_earth_rate_position_terms", "no_transport_rate_position_terms", "no_gravity_gradient"})

APPROXIMATION_DESCRIPTIONS: dict[str, str] = {
    "no_earth_rate_position_terms": "the true state's earth rate w_ie is taken at the computed latitude (no dL terms from it)",
    "no_transport_rate_position_terms": "the true state's transport rate w_en is taken at the computed position (no dL, dh terms from it)",
    "no_gravity_gradient": "the true state's gravity g^e is taken at the computed position (ecef: no dg/dr coupling of the position error)",
    **{name: (function.__doc__ or "").strip().split("\n")[0] for name, function in APPROXIMATIONS.items() if function is not _applied_while_perturbing},
}


# -- step 5: parameters and simplification -----------------------------------------------
def earth_derivative_rules(latitude: sp.Symbol, height: sp.Symbol, earth: EarthSymbols) -> dict:
    """dR_M/dL, dR_N/dL, dg/dL, dg/dh of WGS-84 (TR8350.2), in the parameter symbols.

    R_M = a (1 - e^2) / w^(3/2), R_N = a / w^(1/2), w = 1 - e^2 sin^2 L:
    dR_M/dL = 3 e^2 sin L cos L R_M / w, dR_N/dL = e^2 sin L cos L R_N / w.
    Normal gravity g = gamma(L) eta(L, h) with Somigliana's gamma =
    gamma_e (1 + k sin^2 L) / w^(1/2) and eta = 1 - 2 h (1 + f + m - 2 f sin^2 L) / a
    + 3 h^2 / a^2 (TR8350.2 eq. 4-3): dg/dL = g sin L cos L (2 k / (1 + k sin^2 L)
    + e^2 / w + 8 f h / (a eta)), dg/dh = g (-2 (1 + f + m - 2 f sin^2 L) / a + 6 h / a^2) / eta.
    """
    L, h = latitude, height
    e2, a = sp.Float(wgs84.ECCENTRICITY_SQUARED), sp.Float(wgs84.SEMI_MAJOR_AXIS)
    f, m, k = sp.Float(wgs84.FLATTENING), sp.Float(wgs84.GRAVITY_RATIO_M), sp.Float(wgs84.SOMIGLIANA_K)
    s, c = sp.sin(L), sp.cos(L)
    w = 1 - e2 * s**2
    eta = 1 - 2 * h * (1 + f + m - 2 * f * s**2) / a + 3 * h**2 / a**2
    g = earth.gravity
    return {
        sp.Derivative(MeridianRadius(L), L): 3 * e2 * s * c * earth.meridian_radius / w,
        sp.Derivative(PrimeVerticalRadius(L), L): e2 * s * c * earth.prime_vertical_radius / w,
        sp.Derivative(Gravity(L, h), L): g * s * c * (2 * k / (1 + k * s**2) + e2 / w + 8 * f * h / (a * eta)),
        sp.Derivative(Gravity(L, h), h): g * (-2 * (1 + f + m - 2 * f * s**2) / a + 6 * h / a**2) / eta,
        MeridianRadius(L): earth.meridian_radius,
        PrimeVerticalRadius(L): earth.prime_vertical_radius,
        Gravity(L, h): g,
    }


def simplify_entry(expr: sp.Expr) -> sp.Expr:
    """The one simplification pipeline: ``expand`` (sums of products; equal bases combine).

    Deterministic and fast (no heuristic ``simplify``): the same expression
    gives the same text on every run, and what ``modelgen.derive.symbolic``
    does to every model's entries (``expand``) leaves it unchanged.
    """
    return sp.expand(expr) if expr != 0 else sp.S.Zero


def _finish(stage: _Stage, problem: NavigationProblem) -> _Stage:
    """Earth functions to parameters, derivatives to formulas (with (L, h) shown in the Derivative objects), simplified."""
    rules = earth_derivative_rules(problem.position[0], problem.position[2], problem.earth)
    mech = problem.mechanization()
    if hasattr(mech, "earth_function_rules"):  # the mechanization's own Earth functions (ecef: |r^e|)
        rules.update(mech.earth_function_rules(problem.position, problem.earth.geocentric_radius))
    derivatives = {k: v for k, v in rules.items() if isinstance(k, sp.Derivative)}
    values = {k: v for k, v in rules.items() if not isinstance(k, sp.Derivative)}
    out = []
    for m in (stage.F, stage.G, stage.H):
        m = m.xreplace(derivatives).xreplace(values)
        leftover = m.atoms(sp.Derivative)
        if leftover:
            raise ModelError(f"derivation left derivatives it has no rule for: {sorted(map(str, leftover))}")
        out.append(m.applyfunc(simplify_entry))
    return _Stage(*out)


# -- the whole derivation -------------------------------------------------------------------
def check_problem(problem: NavigationProblem) -> None:
    """Refuse an inconsistent problem before deriving: frame, forms, approximation names, states without equations."""
    from modelgen.model.mechanizations import MECHANIZATION_APPROXIMATIONS, MECHANIZATION_ERROR_FORMS, MECHANIZATION_FRAMES, mechanization_named

    mechanization_named(problem.mechanization_name)
    frames = MECHANIZATION_FRAMES[problem.mechanization_name]
    if problem.frame not in frames:
        raise ModelError(f"navigation frame {problem.frame!r} is not one of {', '.join(frames)} (the {problem.mechanization_name} mechanization's)")
    e = problem.errors
    own_forms = MECHANIZATION_ERROR_FORMS[problem.mechanization_name] or {}
    for what, form, forms in (("attitude", e.attitude, ATTITUDE_FORMS), ("velocity", e.velocity, VELOCITY_FORMS), ("position", e.position, POSITION_FORMS)):
        forms = own_forms.get(what, forms)
        if form not in forms:
            raise ModelError(f"{what} error form {form!r} is not one of {', '.join(forms)} (the {problem.mechanization_name} mechanization's)")
    accepted = MECHANIZATION_APPROXIMATIONS[problem.mechanization_name]
    foreign = [a for a in problem.approximations if a in APPROXIMATIONS and accepted is not None and a not in accepted]
    if foreign:
        raise ModelError(
            f"approximation {foreign[0]!r} does not apply to the {problem.mechanization_name} mechanization "
            f"(it has: {', '.join(sorted(accepted)) or 'none'})"
        )
    if accepted is None and "no_gravity_gradient" in problem.approximations:
        raise ModelError("approximation 'no_gravity_gradient' is the ecef mechanization's (local level: constant_gravity, free_vertical_channel)")
    expected = 2 if "no_vertical_channel" in problem.approximations else 3
    for what, states, count in (("attitude", e.attitude_states, 3), ("velocity", e.velocity_states, expected), ("position", e.position_states, expected)):
        if len(states) != count:
            reason = " (no_vertical_channel: the horizontal components only)" if count == 2 else ""
            raise ModelError(f"the {what} error has {len(states)} states, {count} expected{reason}")
    scoped_equations = sorted(set(problem.approximation_scopes) & EQUATION_APPROXIMATIONS)
    if scoped_equations:
        raise ModelError(f"approximation {scoped_equations[0]!r} changes the perturbed equations and cannot be scoped ('in:')")
    unknown = [a for a in problem.approximations if a not in APPROXIMATIONS]
    if unknown:
        raise ModelError(f"unknown approximation(s) {', '.join(unknown)} (known: {', '.join(sorted(APPROXIMATIONS))})")
    navigation = set(_declared_navigation_states(problem))
    missing = [str(s) for s in problem.state_order if s not in navigation and s not in problem.auxiliary_dynamics]
    if missing:
        raise ModelError(f"error state(s) {', '.join(missing)} have no equation")


def derive_error_equations(problem: NavigationProblem) -> ErrorEquations:
    """F, G, H of the declared error states, exact to first order except the declared approximations.

    Each approximation is applied in the order declared; the entries it
    changes become :class:`NeglectedTerm` records (the removed term =
    before - after, in parameter symbols).
    """
    check_problem(problem)
    problem, placeholders = _with_vertical_placeholders(problem)
    equation_flags: set[str] = set()
    stage = _declared_stage(problem, _primitive_stage(problem, equation_flags))
    finished = _finish(stage, problem)
    neglected: list[NeglectedTerm] = []
    readable: list[str] = []
    for name in problem.approximations:
        before = stage
        if name in EQUATION_APPROXIMATIONS:  # never scoped (check_problem)
            equation_flags.add(name)
            stage = _declared_stage(problem, _primitive_stage(problem, equation_flags))
            for other in problem.approximations[: problem.approximations.index(name)]:
                if other not in EQUATION_APPROXIMATIONS:
                    stage = _scoped(other, APPROXIMATIONS[other](stage, problem), stage, problem)
        else:
            stage = _scoped(name, APPROXIMATIONS[name](stage, problem), stage, problem)
        after = _finish(stage, problem)
        found = _differences(name, finished, after)
        neglected.extend(found)
        readable.extend(readable_term(getattr(before, t.matrix)[t.row, t.column] - getattr(stage, t.matrix)[t.row, t.column], problem) for t in found)
        finished = after
    return _without_states(
        ErrorEquations(
            F=finished.F,
            G=finished.G,
            H=finished.H,
            states=tuple(problem.state_order),
            noises=tuple(problem.noises),
            measurements=tuple(s for m in problem.measurements for s in m.symbols),
            neglected=tuple(neglected),
            readable=tuple(readable),
        ),
        placeholders,
    )


def _scoped(name: str, approximated: _Stage, exact: _Stage, problem: NavigationProblem) -> _Stage:
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
    return _Stage(pick(approximated.F, exact.F, rows), pick(approximated.G, exact.G, rows), pick(approximated.H, exact.H, H_rows))


def readable_term(term: sp.Expr, problem: NavigationProblem) -> str:
    """A neglected term with the Earth quantities by name: ``R_M``, ``dR_M/dL``, ``g``, ``dg/dh``."""
    L, h = problem.position[0], problem.position[2]
    names = {
        sp.Derivative(MeridianRadius(L), L): "dR_M/dL", sp.Derivative(PrimeVerticalRadius(L), L): "dR_N/dL",
        sp.Derivative(Gravity(L, h), L): "dg/dL", sp.Derivative(Gravity(L, h), h): "dg/dh",
        MeridianRadius(L): str(problem.earth.meridian_radius), PrimeVerticalRadius(L): str(problem.earth.prime_vertical_radius),
        Gravity(L, h): str(problem.earth.gravity),
    }
    shown = term.xreplace({k: sp.Symbol(v) for k, v in names.items()})
    return sp.sstr(sp.factor_terms(sp.cancel(sp.together(shown))))


def _with_vertical_placeholders(problem: NavigationProblem) -> tuple[NavigationProblem, tuple[sp.Symbol, ...]]:
    """Under ``no_vertical_channel`` the model declares horizontal velocity and position errors (2 each);
    the derivation runs with the vertical ones as placeholder states, removed at the end."""
    e = problem.errors
    if "no_vertical_channel" not in problem.approximations:
        return problem, ()
    velocity, height = sp.Dummy("vertical_velocity_error", real=True), sp.Dummy("vertical_position_error", real=True)
    errors = ErrorDefinition(e.attitude, e.attitude_states, e.velocity, (*e.velocity_states, velocity), e.position, (*e.position_states, height))
    order: list[sp.Symbol] = []
    for s in problem.state_order:
        order.append(s)
        if s == e.velocity_states[-1]:
            order.append(velocity)
        if s == e.position_states[-1]:
            order.append(height)
    return replace(problem, errors=errors, state_order=tuple(order)), (velocity, height)


def _without_states(equations: ErrorEquations, removed: Sequence[sp.Symbol]) -> ErrorEquations:
    """``equations`` without the ``removed`` states; a neglected term in a removed row or column gets index -1."""
    if not removed:
        return equations
    kept = [i for i, s in enumerate(equations.states) if s not in removed]
    new_index = {old: new for new, old in enumerate(kept)}

    def moved(term: NeglectedTerm) -> NeglectedTerm:
        row = new_index.get(term.row, -1) if term.matrix in ("F", "G") else term.row
        column = new_index.get(term.column, -1) if term.matrix in ("F", "H") else term.column
        return NeglectedTerm(term.approximation, term.matrix, row, column, term.term)

    return ErrorEquations(
        F=equations.F.extract(kept, kept),
        G=equations.G.extract(kept, list(range(equations.G.cols))) if equations.G.cols else sp.zeros(len(kept), 0),
        H=equations.H.extract(list(range(equations.H.rows)), kept) if equations.H.rows else sp.zeros(0, len(kept)),
        states=tuple(equations.states[i] for i in kept),
        noises=equations.noises,
        measurements=equations.measurements,
        neglected=tuple(moved(t) for t in equations.neglected),
        readable=equations.readable,
    )


def _differences(name: str, before: _Stage, after: _Stage) -> list[NeglectedTerm]:
    """The entries ``name`` changed, as NeglectedTerm records (term = before - after)."""
    out = []
    for label in ("F", "G", "H"):
        a, b = getattr(before, label), getattr(after, label)
        for i in range(a.rows):
            for j in range(a.cols):
                if a[i, j] != b[i, j]:
                    difference = simplify_entry(a[i, j] - b[i, j])
                    if difference != 0 and not _is_zero_function(difference):
                        out.append(NeglectedTerm(name, label, i, j, difference))
    return out


def _is_zero_function(expr: sp.Expr) -> bool:
    """Whether ``expr`` is identically zero, e.g. x/(R cos L + h cos L) - x/((R + h) cos L).

    A value at a fixed generic point (each symbol 0.2 + 0.0137 k, deterministic)
    that is not small decides quickly; otherwise rational functions are cancelled.
    """
    symbols = sorted(expr.free_symbols, key=str)
    point = {s: sp.Float(0.2 + 0.0137 * k) for k, s in enumerate(symbols)}
    value = expr.xreplace(point)
    scale = sum(abs(t.xreplace(point)) for t in sp.Add.make_args(expr))
    if value.is_number and scale.is_number and abs(float(value)) > 1e-9 * float(scale):
        return False
    return sp.cancel(sp.together(expr)) == 0
