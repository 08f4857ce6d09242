"""What the perturbation engine is given and what it returns, as sympy objects (no YAML).

Given: a :class:`NavigationProblem` (the computed navigation state's symbols, the
:class:`ErrorDefinition` of the declared error states, the :class:`InertialSensorErrors`
of the gyros and accelerometers, the :class:`MeasurementFunction` of each measurement,
the approximations by name).  Returned: the :class:`ErrorEquations` (F, G, H and each
:class:`NeglectedTerm` an approximation removed) and, for closed-loop feedback, the
:class:`AttitudeReset` of the attitude error.  :class:`Stage` holds the matrices between
the derivation's steps (:mod:`modelgen.model.perturbation`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.mechanizations.local_level import EarthSymbols, LocalLevel, _vector, skew

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
    lever_arm_position: sp.Matrix | None = None  # where a lever arm's metres become (dL, dlambda, dh) (None: the state's own)


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


@dataclass(frozen=True)
class Stage:
    """Matrices with the Earth functions still unevaluated (between approximations)."""

    F: sp.Matrix
    G: sp.Matrix
    H: sp.Matrix


def sensed_navigation_force(problem: NavigationProblem) -> sp.Matrix:
    """C f~ (or f~ when the model gives the sensed specific force in navigation axes)."""
    if problem.specific_force_axes == "navigation":
        return problem.specific_force
    return problem.attitude * problem.specific_force


def declared_navigation_states(problem: NavigationProblem) -> tuple[sp.Symbol, ...]:
    e = problem.errors
    return (*e.attitude_states, *e.velocity_states, *e.position_states)
