"""The navigation library: Earth model and rotation helpers usable inside model files.

Every function takes sympy symbols or numbers and returns a sympy scalar or a
``sympy.Matrix`` (3-vectors are 3x1 columns), so the same formula serves a
model equation (``earth_rate_ned(L)`` in terms of the latitude symbol ``L``)
and a number (``float(meridian_radius(0.7))``).  Model expressions reach these
functions by name (:data:`NAVLIB_FUNCTIONS`, :data:`NAVLIB_CONSTANTS`); a name
the model declares itself (a parameter ``R_M``) shadows the library's.

Constants are WGS-84's, from :mod:`modelgen.model.wgs84` (the one source of
truth, NIMA TR8350.2); :mod:`modelgen.simulation.earth` evaluates the same
formulas on floats, and ``tests/model/test_navlib.py`` proves both agree.

Conventions: latitude ``L`` and longitude in radians, height ``h`` in metres
above the ellipsoid; NED = north, east, down; ENU = east, north, up; Euler
angles roll, pitch, yaw rotate body to navigation axes in the order yaw (z),
pitch (y), roll (x); quaternions are Hamilton, scalar first, body to
navigation.  The formulas are those of Groves, *Principles of GNSS, Inertial,
and Multisensor Integrated Navigation Systems* (2nd ed., 2013), chapters 2
and 5, and Titterton & Weston, *Strapdown Inertial Navigation Technology*
(2nd ed., 2004), chapter 3.
"""

from __future__ import annotations

from typing import Any, Callable

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model import wgs84

Scalar = Any  # a sympy expression or a number
Vector = sp.Matrix

#: WGS-84 constants by the names a model expression may use (sympy Floats).
NAVLIB_CONSTANTS: dict[str, sp.Expr] = {
    "wgs84_semi_major_axis": sp.Float(wgs84.SEMI_MAJOR_AXIS),
    "wgs84_semi_minor_axis": sp.Float(wgs84.SEMI_MINOR_AXIS),
    "wgs84_flattening": sp.Float(wgs84.FLATTENING),
    "wgs84_eccentricity_squared": sp.Float(wgs84.ECCENTRICITY_SQUARED),
    "wgs84_earth_rate": sp.Float(wgs84.EARTH_RATE),
    "wgs84_gravitational_constant": sp.Float(wgs84.GRAVITATIONAL_CONSTANT),
    "wgs84_equatorial_gravity": sp.Float(wgs84.EQUATORIAL_GRAVITY),
    "wgs84_somigliana_k": sp.Float(wgs84.SOMIGLIANA_K),
    "wgs84_gravity_ratio_m": sp.Float(wgs84.GRAVITY_RATIO_M),
}

_A = NAVLIB_CONSTANTS["wgs84_semi_major_axis"]
_E2 = NAVLIB_CONSTANTS["wgs84_eccentricity_squared"]
_F = NAVLIB_CONSTANTS["wgs84_flattening"]
_OMEGA = NAVLIB_CONSTANTS["wgs84_earth_rate"]
_GAMMA_E = NAVLIB_CONSTANTS["wgs84_equatorial_gravity"]
_K = NAVLIB_CONSTANTS["wgs84_somigliana_k"]
_M = NAVLIB_CONSTANTS["wgs84_gravity_ratio_m"]


def _scalar(value: Any, function: str, argument: str) -> sp.Expr:
    """``value`` as a sympy scalar; a vector or matrix is refused naming the function and argument."""
    if isinstance(value, sp.MatrixBase):
        raise ModelError(f"{function}() needs a scalar {argument}, got {value.shape[0]}x{value.shape[1]}")
    return sp.sympify(value)


def _vector3(value: Any, function: str, argument: str) -> sp.Matrix:
    """``value`` as a 3x1 Matrix (a 3-vector or a sequence of three); anything else is refused."""
    if isinstance(value, sp.MatrixBase):
        if value.shape == (3, 1):
            return value
        raise ModelError(f"{function}() needs a 3-vector {argument}, got {value.shape[0]}x{value.shape[1]}")
    if isinstance(value, (list, tuple)) and len(value) == 3:
        return sp.Matrix([sp.sympify(v) for v in value])
    raise ModelError(f"{function}() needs a 3-vector {argument}, got scalar")


# -- radii of curvature --------------------------------------------------------------
def meridian_radius(L: Scalar) -> sp.Expr:
    """R_M(L) = a (1 - e^2) / (1 - e^2 sin^2 L)^(3/2): meridian (north-south) radius of curvature [m].

    Source: Groves (2013) ch. 2 (who names it R_N, for north); Titterton & Weston (2004) ch. 3.
    Published values: 6,335,439.327 m at the equator, 6,399,593.626 m at the poles.
    """
    L = _scalar(L, "meridian_radius", "latitude")
    return _A * (1 - _E2) / (1 - _E2 * sp.sin(L) ** 2) ** sp.Rational(3, 2)


def prime_vertical_radius(L: Scalar) -> sp.Expr:
    """R_N(L) = a / (1 - e^2 sin^2 L)^(1/2): prime-vertical (east-west) radius of curvature [m].

    Source: Groves (2013) ch. 2 (who names it R_E, for east); Titterton & Weston (2004) ch. 3.
    Published values: 6,378,137 m (= a) at the equator, 6,399,593.626 m at the poles.
    """
    L = _scalar(L, "prime_vertical_radius", "latitude")
    return _A / sp.sqrt(1 - _E2 * sp.sin(L) ** 2)


# -- gravity ---------------------------------------------------------------------------
def normal_gravity(L: Scalar, h: Scalar = 0) -> sp.Expr:
    """Magnitude of normal gravity (gravitation plus centrifugal) at latitude L, height h [m/s^2].

    On the ellipsoid, Somigliana's closed formula
    g0 = gamma_e (1 + k sin^2 L) / sqrt(1 - e^2 sin^2 L)   (NIMA TR8350.2 eq. 4-1);
    above it, the second-order free-air (height) term of TR8350.2 eq. 4-3:
    g = g0 (1 - 2 h/a (1 + f + m - 2 f sin^2 L) + 3 h^2/a^2).
    Published values: 9.7803253359 at the equator, 9.8321849378 at the poles.
    The same formula as :func:`modelgen.simulation.earth.normal_gravity`.
    """
    L = _scalar(L, "normal_gravity", "latitude")
    h = _scalar(h, "normal_gravity", "height")
    s2 = sp.sin(L) ** 2
    g0 = _GAMMA_E * (1 + _K * s2) / sp.sqrt(1 - _E2 * s2)
    return g0 * (1 - 2 * h / _A * (1 + _F + _M - 2 * _F * s2) + 3 * h**2 / _A**2)


def gravity_ned(L: Scalar, h: Scalar = 0) -> Vector:
    """g^n = [0, 0, g(L, h)]: the normal gravity vector in NED (pointing down), from :func:`normal_gravity`."""
    return sp.Matrix([0, 0, normal_gravity(L, h)])


def gravity_enu(L: Scalar, h: Scalar = 0) -> Vector:
    """g^n = [0, 0, -g(L, h)]: the normal gravity vector in ENU (pointing down), from :func:`normal_gravity`."""
    return sp.Matrix([0, 0, -normal_gravity(L, h)])


# -- rotation rates --------------------------------------------------------------------
def earth_rate_ned(L: Scalar, rate: Scalar = _OMEGA) -> Vector:
    """omega_ie^n = Omega [cos L, 0, -sin L]: the Earth's rotation seen in NED axes [rad/s].

    ``rate`` defaults to WGS-84's Omega = 7.292115e-5 rad/s; a model may pass
    its own (a parameter ``omega_ie``).  Source: Groves (2013) ch. 5.
    """
    L, rate = _scalar(L, "earth_rate_ned", "latitude"), _scalar(rate, "earth_rate_ned", "rate")
    return sp.Matrix([rate * sp.cos(L), 0, -rate * sp.sin(L)])


def earth_rate_enu(L: Scalar, rate: Scalar = _OMEGA) -> Vector:
    """omega_ie^n = Omega [0, cos L, sin L]: the Earth's rotation seen in ENU axes [rad/s].

    The NED vector of :func:`earth_rate_ned` with north and east swapped and down negated.
    """
    L, rate = _scalar(L, "earth_rate_enu", "latitude"), _scalar(rate, "earth_rate_enu", "rate")
    return sp.Matrix([0, rate * sp.cos(L), rate * sp.sin(L)])


def _radii(L: sp.Expr, radii: tuple[Scalar, ...], function: str) -> tuple[sp.Expr, sp.Expr]:
    """(R_M, R_N): given by the caller (two scalars), or from WGS-84 at L."""
    if not radii:
        return meridian_radius(L), prime_vertical_radius(L)
    if len(radii) != 2:
        raise ModelError(f"{function}() takes either no radii or both R_M and R_N, got {len(radii)} extra argument(s)")
    return _scalar(radii[0], function, "R_M"), _scalar(radii[1], function, "R_N")


def transport_rate_ned(L: Scalar, h: Scalar, v: Any, *radii: Scalar) -> Vector:
    """omega_en^n = [v_E/(R_N+h), -v_N/(R_M+h), -v_E tan L/(R_N+h)]: rotation of NED over the ellipsoid [rad/s].

    ``v`` = [v_N, v_E, v_D]; the radii are WGS-84's at L, or ``R_M, R_N``
    given as two more arguments.  Source: Groves (2013) ch. 5;
    Titterton & Weston (2004) ch. 3.
    """
    L, h = _scalar(L, "transport_rate_ned", "latitude"), _scalar(h, "transport_rate_ned", "height")
    v = _vector3(v, "transport_rate_ned", "velocity")
    RM, RN = _radii(L, radii, "transport_rate_ned")
    return sp.Matrix([v[1] / (RN + h), -v[0] / (RM + h), -v[1] * sp.tan(L) / (RN + h)])


def transport_rate_enu(L: Scalar, h: Scalar, v: Any, *radii: Scalar) -> Vector:
    """omega_en^n = [-v_N/(R_M+h), v_E/(R_N+h), v_E tan L/(R_N+h)] in ENU axes [rad/s].

    ``v`` = [v_E, v_N, v_U]: the NED transport rate of :func:`transport_rate_ned`
    with north and east swapped and down negated.
    """
    L, h = _scalar(L, "transport_rate_enu", "latitude"), _scalar(h, "transport_rate_enu", "height")
    v = _vector3(v, "transport_rate_enu", "velocity")
    RM, RN = _radii(L, radii, "transport_rate_enu")
    return sp.Matrix([-v[1] / (RM + h), v[0] / (RN + h), v[0] * sp.tan(L) / (RN + h)])


def position_rate_ned(L: Scalar, h: Scalar, v: Any, *radii: Scalar) -> Vector:
    """[dL/dt, dlambda/dt, dh/dt] = [v_N/(R_M+h), v_E/((R_N+h) cos L), -v_D] from NED velocity.

    Source: Groves (2013) ch. 2; radii as in :func:`transport_rate_ned`.
    """
    L, h = _scalar(L, "position_rate_ned", "latitude"), _scalar(h, "position_rate_ned", "height")
    v = _vector3(v, "position_rate_ned", "velocity")
    RM, RN = _radii(L, radii, "position_rate_ned")
    return sp.Matrix([v[0] / (RM + h), v[1] / ((RN + h) * sp.cos(L)), -v[2]])


# -- rotations -------------------------------------------------------------------------
def euler_to_dcm(roll: Scalar, pitch: Scalar, yaw: Scalar) -> sp.Matrix:
    """C_b^n = R_z(yaw) R_y(pitch) R_x(roll): body to NED from Euler angles (z-y-x order).

    Source: Groves (2013) ch. 2 (C_b^n is the transpose of C_n^b);
    Titterton & Weston (2004) ch. 3.
    """
    r = _scalar(roll, "euler_to_dcm", "roll")
    p = _scalar(pitch, "euler_to_dcm", "pitch")
    y = _scalar(yaw, "euler_to_dcm", "yaw")
    cr, sr, cp, sp_, cy, sy = sp.cos(r), sp.sin(r), sp.cos(p), sp.sin(p), sp.cos(y), sp.sin(y)
    return sp.Matrix(
        [
            [cp * cy, -cr * sy + sr * sp_ * cy, sr * sy + cr * sp_ * cy],
            [cp * sy, cr * cy + sr * sp_ * sy, -sr * cy + cr * sp_ * sy],
            [-sp_, sr * cp, cr * cp],
        ]
    )


def dcm_to_euler(C: Any) -> Vector:
    """[roll, pitch, yaw] of a body-to-NED matrix C_b^n (inverse of :func:`euler_to_dcm`).

    roll = atan2(C_32, C_33), pitch = -asin(C_31), yaw = atan2(C_21, C_11);
    valid away from pitch = +-90 deg.  Source: Groves (2013) ch. 2.
    """
    if not (isinstance(C, sp.MatrixBase) and C.shape == (3, 3)):
        got = f"{C.shape[0]}x{C.shape[1]}" if isinstance(C, sp.MatrixBase) else "scalar"
        raise ModelError(f"dcm_to_euler() needs a 3x3 matrix, got {got}")
    return sp.Matrix([sp.atan2(C[2, 1], C[2, 2]), -sp.asin(C[2, 0]), sp.atan2(C[1, 0], C[0, 0])])


def quaternion_to_dcm(*q: Any) -> sp.Matrix:
    """C_b^n of a unit quaternion q = q0 + q1 i + q2 j + q3 k (Hamilton, scalar first, body to navigation).

    Called with four scalars ``quaternion_to_dcm(q0, q1, q2, q3)`` (model
    files hold 3-vectors, not 4-vectors) or with one 4-vector:
    C = [[q0^2+q1^2-q2^2-q3^2, 2(q1q2-q0q3), 2(q1q3+q0q2)],
         [2(q1q2+q0q3), q0^2-q1^2+q2^2-q3^2, 2(q2q3-q0q1)],
         [2(q1q3-q0q2), 2(q2q3+q0q1), q0^2-q1^2-q2^2+q3^2]].
    Source: Groves (2013) ch. 2; Titterton & Weston (2004) ch. 3.
    """
    if len(q) == 1 and isinstance(q[0], sp.MatrixBase) and q[0].shape in ((4, 1), (1, 4)):
        q = tuple(q[0])
    if len(q) != 4 or any(isinstance(c, sp.MatrixBase) for c in q):
        raise ModelError(f"quaternion_to_dcm() needs four scalars q0, q1, q2, q3 (scalar first), got {len(q)} argument(s)")
    q0, q1, q2, q3 = (sp.sympify(c) for c in q)
    return sp.Matrix(
        [
            [q0**2 + q1**2 - q2**2 - q3**2, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
            [2 * (q1 * q2 + q0 * q3), q0**2 - q1**2 + q2**2 - q3**2, 2 * (q2 * q3 - q0 * q1)],
            [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0**2 - q1**2 - q2**2 + q3**2],
        ]
    )


#: Short aliases, as the field writes them.
R_M = meridian_radius
R_N = prime_vertical_radius

#: Functions a model expression may call, by name (``R_M``/``R_N`` are short aliases).
NAVLIB_FUNCTIONS: dict[str, Callable[..., Any]] = {
    "meridian_radius": meridian_radius,
    "prime_vertical_radius": prime_vertical_radius,
    "R_M": meridian_radius,
    "R_N": prime_vertical_radius,
    "normal_gravity": normal_gravity,
    "gravity_ned": gravity_ned,
    "gravity_enu": gravity_enu,
    "earth_rate_ned": earth_rate_ned,
    "earth_rate_enu": earth_rate_enu,
    "transport_rate_ned": transport_rate_ned,
    "transport_rate_enu": transport_rate_enu,
    "position_rate_ned": position_rate_ned,
    "euler_to_dcm": euler_to_dcm,
    "dcm_to_euler": dcm_to_euler,
    "quaternion_to_dcm": quaternion_to_dcm,
}
