"""The local-level mechanization (NED or ENU axes, geodetic position): today's navigation equations.

Groves (2013), eqs. 5.44-5.56: C' = C [w_ib x] - [w_in x] C,
v' = f^n - (2 w_ie + w_en) x v + g^n, (L', lambda', h') from v.  The frame
helpers (Earth rate, transport rate, position rates, gravity, metres per
radian of latitude and longitude) are the equations of this mechanization;
:mod:`modelgen.model.perturbation` derives its error model through the
:class:`~modelgen.model.mechanizations.Mechanization` protocol.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import sympy as sp

#: Annotations name the engine's NavigationState (modelgen.model.perturbation) as text: the engine imports this
#: module, never the other way round (tests/test_architecture.py refuses a cycle).
NavigationState = "modelgen.model.perturbation.problem.NavigationState"

#: Navigation frames and their axes, in component order.
FRAME_AXES: dict[str, tuple[str, str, str]] = {"NED": ("north", "east", "down"), "ENU": ("east", "north", "up")}

# Earth quantities as undefined functions of position while deriving (module doc).
MeridianRadius = sp.Function("MeridianRadius")
PrimeVerticalRadius = sp.Function("PrimeVerticalRadius")
Gravity = sp.Function("Gravity")
#: the Earth functions this mechanization's equations hold (the engine differentiates them by their rules)
EARTH_FUNCTIONS = (MeridianRadius, PrimeVerticalRadius, Gravity)

# -- vector helpers ---------------------------------------------------------------
def skew(a: sp.Matrix) -> sp.Matrix:
    """[a x], the matrix of the cross product a x (.)."""
    return sp.Matrix([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def _vector(items: Sequence[sp.Expr]) -> sp.Matrix:
    return sp.Matrix(list(items))


@dataclass(frozen=True)
class EarthSymbols:
    """Parameter symbols that stand for the Earth quantities in the result."""

    earth_rate: sp.Symbol
    meridian_radius: sp.Symbol
    prime_vertical_radius: sp.Symbol
    gravity: sp.Symbol
    earth_radius: sp.Symbol | None = None  # used only by the single_earth_radius approximation
    geocentric_radius: sp.Symbol | None = None  # |r^e| of the ecef mechanization's gravity


def earth_rate_vector(frame: str, latitude: sp.Expr, earth_rate: sp.Expr) -> sp.Matrix:
    """w_ie^n: NED (W cos L, 0, -W sin L), ENU (0, W cos L, W sin L)."""
    c, s = earth_rate * sp.cos(latitude), earth_rate * sp.sin(latitude)
    return _vector((c, 0, -s)) if frame == "NED" else _vector((0, c, s))


def position_angle_rates(frame: str, latitude: sp.Expr, latitude_rate: sp.Expr, longitude_rate: sp.Expr) -> sp.Matrix:
    """Rotation rate of the local-level frame for given rates of L and lambda.

    NED (lambda' cos L, -L', -lambda' sin L); ENU (-L', lambda' cos L, lambda' sin L).
    With the position rates this is the transport rate w_en^n; with position
    errors (dL, dlambda) it is the small angle d(theta) between the true and
    the computed local-level frames.
    """
    c, s = sp.cos(latitude), sp.sin(latitude)
    if frame == "NED":
        return _vector((longitude_rate * c, -latitude_rate, -longitude_rate * s))
    return _vector((-latitude_rate, longitude_rate * c, longitude_rate * s))


def north_east_vertical(frame: str, vector: sp.Matrix) -> tuple[sp.Expr, sp.Expr, sp.Expr]:
    """(north, east, up) components of a navigation-frame vector."""
    if frame == "NED":
        return vector[0], vector[1], -vector[2]
    return vector[1], vector[0], vector[2]


def position_rate(frame: str, position: sp.Matrix, velocity: sp.Matrix) -> sp.Matrix:
    """(L', lambda', h') = (v_N/(R_M + h), v_E/((R_N + h) cos L), v_up)."""
    latitude, _, height = position
    north, east, up = north_east_vertical(frame, velocity)
    return _vector(
        (
            north / (MeridianRadius(latitude) + height),
            east / ((PrimeVerticalRadius(latitude) + height) * sp.cos(latitude)),
            up,
        )
    )


def gravity_vector(frame: str, position: sp.Matrix) -> sp.Matrix:
    """g^n = g(L, h) along the down axis (plumb-line gravity, no deflection of the vertical)."""
    g = Gravity(position[0], position[2])
    return _vector((0, 0, g)) if frame == "NED" else _vector((0, 0, -g))


def metres_matrix_inverse(frame: str, position: sp.Matrix) -> sp.Matrix:
    """M^-1: (dL, dlambda, dh) from navigation-frame metres (M is a signed permutation of a diagonal)."""
    M = metres_matrix(frame, position)
    return M.T.applyfunc(lambda e: 1 / e if e != 0 else sp.S.Zero)


def metres_matrix(frame: str, position: sp.Matrix) -> sp.Matrix:
    """M with (navigation-frame metres) = M (dL, dlambda, dh): north (R_M + h) dL, east (R_N + h) cos L dlambda."""
    latitude, _, height = position
    north = MeridianRadius(latitude) + height
    east = (PrimeVerticalRadius(latitude) + height) * sp.cos(latitude)
    if frame == "NED":
        return sp.Matrix([[north, 0, 0], [0, east, 0], [0, 0, -1]])
    return sp.Matrix([[0, east, 0], [north, 0, 0], [0, 0, 1]])


@dataclass(frozen=True)
class LocalLevel:
    """The local-level mechanization in ``frame`` (Groves 2013, eqs. 5.44-5.56):

    C' = C [w_ib x] - [w_in x] C,  v' = f^n - (2 w_ie + w_en) x v + g^n,
    (L', lambda', h') = :func:`position_rate`.

    A model may write the velocity or position equation itself
    (``velocity_equation``, ``position_equation``: functions of the state and
    this mechanization); the attitude kinematics keep their form, with w_in
    from :meth:`navigation_rate`.
    """

    frame: str
    rotation_rate: sp.Symbol  # the Earth's rotation rate (parameter symbol)
    velocity_equation: Callable[["NavigationState", "LocalLevel"], sp.Matrix] | None = None
    position_equation: Callable[["NavigationState", "LocalLevel"], sp.Matrix] | None = None

    def earth_rate(self, state: NavigationState) -> sp.Matrix:
        """w_ie^n at the state's (or the approximation's) latitude."""
        return earth_rate_vector(self.frame, state.earth_rate_position[0], self.rotation_rate)

    def transport_rate(self, state: NavigationState) -> sp.Matrix:
        """w_en^n from the state's velocity at its (or the approximation's) position."""
        rates = position_rate(self.frame, state.transport_rate_position, state.velocity)
        return position_angle_rates(self.frame, state.transport_rate_position[0], rates[0], rates[1])

    def navigation_rate(self, state: NavigationState) -> sp.Matrix:
        """w_in^n = w_ie^n + w_en^n."""
        return self.earth_rate(state) + self.transport_rate(state)

    def velocity_rate(self, state: NavigationState) -> sp.Matrix:
        if self.velocity_equation is not None:
            return self.velocity_equation(state, self)
        coriolis = (2 * self.earth_rate(state) + self.transport_rate(state)).cross(state.velocity)
        return state.specific_force - coriolis + gravity_vector(self.frame, state.position)

    def error_frame_angle(self, position: sp.Matrix, position_error: sp.Matrix) -> sp.Matrix:
        """d(theta): the small angle between the true and the computed local-level frames for a geodetic position error."""
        return position_angle_rates(self.frame, position[0], position_error[0], position_error[1])

    def metres(self, position: sp.Matrix) -> sp.Matrix:
        """M with (navigation-frame metres) = M (dL, dlambda, dh) at ``position``."""
        return metres_matrix(self.frame, position)

    def metres_inverse(self, position: sp.Matrix) -> sp.Matrix:
        """M^-1: (dL, dlambda, dh) from navigation-frame metres at ``position``."""
        return metres_matrix_inverse(self.frame, position)

    def gravity(self, state: NavigationState) -> sp.Matrix:
        """g^n at the state's position."""
        return gravity_vector(self.frame, state.position)

    def position_rate(self, state: NavigationState) -> sp.Matrix:
        if self.position_equation is not None:
            return self.position_equation(state, self)
        return position_rate(self.frame, state.position, state.velocity)




#: Latitude (deg) beyond which the local-level mechanization is refused: 1/cos(L) in the longitude
#: rate and tan(L) in the transport rate grow without bound at the poles (89.9 deg: 1/cos L = 573).
POLAR_LIMIT_DEG = 89.0
