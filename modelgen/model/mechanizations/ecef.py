"""The Earth-centred Earth-fixed mechanization: e-frame position r^e, velocity v^e and attitude C_b^e.

Groves (2013), section 5.3 and eqs. 14.18-14.20 (the ECEF error model the
ECEF filters run):

    C' = C [w_ib x] - [w_ie x] C,   v' = C f - 2 w_ie x v + g^e(r),   r' = v,

with w_ie^e = (0, 0, W) and no transport rate (the e-frame does not turn with
the vehicle).  Gravity is WGS-84's J2 model of the gravitational field plus
the centrifugal term (Groves eqs. 2.133, 2.142):

    g^e = -mu/|r|^3 (r + 3/2 J2 a^2/|r|^2 ((1 - 5 z^2/|r|^2) x, (1 - 5 z^2/|r|^2) y, (3 - 5 z^2/|r|^2) z))
          + W^2 (x, y, 0),

written out in r^e, so that its gradient dg/dr (the gravity coupling of the
position error into the velocity error) is derived exactly, not with Groves'
approximation 2 g_0 r r^T / (r_eS |r|^2) of eq. 14.18.  There is no
singularity anywhere (the poles included): nothing divides by cos(latitude).

The error states are resolved in the e-frame: the phi-angle phi^e
(C = (I - [phi x]) C_true), the velocity difference dv^e and the position
difference dr^e in metres; the local-level psi-angle, computed-frame and
geodetic forms have no meaning here (the frame does not depend on position)
and are refused by the reader.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import sympy as sp

from modelgen.model import wgs84

#: Annotations name the engine's NavigationState (modelgen.model.perturbation) as text (no import cycle).
NavigationState = "modelgen.model.perturbation.problem.NavigationState"

#: |r^e|, the geocentric radius, as an undefined function of the position while deriving (like the local-level
#: radii of curvature): the gravity gradient then reads in r = |r^e| (parameter ``geocentric_radius``), with
#: d|r|/dx = x/|r| by the chain rule, instead of (x^2 + y^2 + z^2)^(7/2) expanded into polynomials.
GeocentricRadius = sp.Function("GeocentricRadius")
#: the Earth functions this mechanization's equations hold (the engine differentiates them by their rules)
EARTH_FUNCTIONS = (GeocentricRadius,)

#: The frame of every vector of this mechanization, and its axes in component order.
FRAME = "ECEF"
AXES = ("x", "y", "z")
#: Error forms the e-frame has: the local-level ones that depend on the frame's turning with position do not apply.
ERROR_FORMS = {"attitude": ("phi", "rotation_vector"), "velocity": ("difference",), "position": ("metres",)}


def gravity_ecef(position: sp.Matrix, earth_rate: sp.Expr) -> sp.Matrix:
    """g^e: WGS-84's J2 gravitational acceleration plus the centrifugal acceleration W^2 (x, y, 0) (Groves eqs. 2.133, 2.142)."""
    x, y, z = position
    mu, j2, a = sp.Float(wgs84.GRAVITATIONAL_CONSTANT), sp.Float(wgs84.J2), sp.Float(wgs84.SEMI_MAJOR_AXIS)
    r2 = GeocentricRadius(x, y, z) ** 2
    zonal = sp.Rational(3, 2) * j2 * a**2 / r2
    ratio = 5 * z**2 / r2
    gravitational = -mu / GeocentricRadius(x, y, z) ** 3 * sp.Matrix(
        [x * (1 + zonal * (1 - ratio)), y * (1 + zonal * (1 - ratio)), z * (1 + zonal * (3 - ratio))]
    )
    return gravitational + earth_rate**2 * sp.Matrix([x, y, 0])


@dataclass(frozen=True)
class Ecef:
    """The ECEF mechanization (module doc); a model may write the velocity or position rate itself."""

    frame: str
    rotation_rate: sp.Symbol  # the Earth's rotation rate (parameter symbol)
    velocity_equation: Callable[["NavigationState", "Ecef"], sp.Matrix] | None = None
    position_equation: Callable[["NavigationState", "Ecef"], sp.Matrix] | None = None

    def earth_rate(self, state: NavigationState) -> sp.Matrix:
        """w_ie^e = (0, 0, W): the same everywhere."""
        return sp.Matrix([0, 0, self.rotation_rate])

    def transport_rate(self, state: NavigationState) -> sp.Matrix:
        """w_ee = 0: the e-frame does not turn with the vehicle."""
        return sp.zeros(3, 1)

    def navigation_rate(self, state: NavigationState) -> sp.Matrix:
        """w_ie^e (the rate the attitude kinematics subtract)."""
        return self.earth_rate(state)

    def gravity(self, state: NavigationState) -> sp.Matrix:
        """g^e at the state's position (:func:`gravity_ecef`), or where the approximation no_gravity_gradient takes it."""
        at = state.gravity_position if state.gravity_position is not None else state.position
        return gravity_ecef(at, self.rotation_rate)

    def velocity_rate(self, state: NavigationState) -> sp.Matrix:
        """v' = f^e - 2 w_ie x v + g^e (Groves eq. 5.36)."""
        if self.velocity_equation is not None:
            return self.velocity_equation(state, self)
        return state.specific_force - 2 * self.earth_rate(state).cross(state.velocity) + self.gravity(state)

    def position_rate(self, state: NavigationState) -> sp.Matrix:
        """r' = v^e."""
        if self.position_equation is not None:
            return self.position_equation(state, self)
        return state.velocity

    def error_frame_angle(self, position: sp.Matrix, position_error: sp.Matrix) -> sp.Matrix:
        """0: the e-frame is the same at the true and the computed position."""
        return sp.zeros(3, 1)

    def metres(self, position: sp.Matrix) -> sp.Matrix:
        """I: the position (error) is already in metres along the e-frame axes."""
        return sp.eye(3)

    def metres_inverse(self, position: sp.Matrix) -> sp.Matrix:
        """I (see :meth:`metres`)."""
        return sp.eye(3)

    def earth_function_rules(self, position: sp.Matrix, earth: Any) -> dict:
        """|r^e| and its partial derivatives in the parameter ``earth.geocentric_radius``: d|r|/dx = x/|r| (for the engine's last step)."""
        radius = earth.geocentric_radius
        x, y, z = position
        function = GeocentricRadius(x, y, z)
        return {**{sp.Derivative(function, c): c / radius for c in (x, y, z)}, function: radius}

    def expression_names(self, state: NavigationState) -> dict[str, Any]:
        """The names a written equation or measurement expression may use in the e-frame (README lists them)."""
        return {
            "C_b_e": state.attitude,
            "v_e": state.velocity,
            "r_e": state.position,
            "f_e": state.specific_force,
            "omega_ie_e": self.earth_rate(state),
            "g_e": self.gravity(state),
        }
