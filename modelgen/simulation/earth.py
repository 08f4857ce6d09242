"""The WGS-84 earth: radii of curvature, normal gravity, earth rate, transport rate.

Everything here is in the local-level North-East-Down navigation frame (the
frame of the core paper's model, the core paper) and in SI units.  The functions are
scalar and compiled (:mod:`modelgen.simulation.jit`) because the trajectory
generator and the strapdown mechanization call them at every IMU step; both call
the *same* functions, so that a mechanization fed with ideal increments follows
the truth up to its own algorithm errors, not up to a mismatch of earth models.
The formulas are those of the navigation library that model files use
(:mod:`modelgen.model.navlib`, in sympy) with the same WGS-84 constants;
``tests/model/test_navlib.py`` proves both give the same numbers.
"""

from __future__ import annotations

import math

import numpy as np

from modelgen.model.wgs84 import (  # noqa: F401  (the one WGS-84 module: modelgen.model.wgs84)
    EARTH_RATE,
    ECCENTRICITY_SQUARED,
    EQUATORIAL_GRAVITY,
    FLATTENING,
    GRAVITATIONAL_CONSTANT,
    GRAVITY_RATIO_M,
    SEMI_MAJOR_AXIS,
    SEMI_MINOR_AXIS,
    SOMIGLIANA_K,
)
from modelgen.simulation.jit import compiled

SPEED_OF_LIGHT = 299792458.0  # [m/s]


@compiled
def radii_of_curvature(latitude: float) -> tuple[float, float]:
    """Meridian radius R_M and prime-vertical radius R_N at a geodetic latitude [m]."""
    s = math.sin(latitude)
    w2 = 1.0 - ECCENTRICITY_SQUARED * s * s
    w = math.sqrt(w2)
    prime_vertical = SEMI_MAJOR_AXIS / w
    meridian = SEMI_MAJOR_AXIS * (1.0 - ECCENTRICITY_SQUARED) / (w2 * w)
    return meridian, prime_vertical


@compiled
def normal_gravity(latitude: float, height: float) -> float:
    """Magnitude of normal gravity (gravitation + centrifugal), along +Down [m/s^2].

    Somigliana's closed formula on the ellipsoid with the second-order free-air
    correction g(h) = g0 (1 - 2 h/a (1 + f + m - 2 f sin^2 L) + 3 h^2/a^2).
    """
    g0, slope = gravity_latitude_terms(latitude)
    return gravity_at_height(g0, slope, height)


@compiled
def gravity_latitude_terms(latitude: float) -> tuple[float, float]:
    """The terms of :func:`normal_gravity` in the latitude alone: g0 on the ellipsoid and the free-air slope
    factor (1 + f + m - 2 f sin^2 L); a caller that meets one latitude again may keep them."""
    s2 = math.sin(latitude) ** 2
    g0 = EQUATORIAL_GRAVITY * (1.0 + SOMIGLIANA_K * s2) / math.sqrt(1.0 - ECCENTRICITY_SQUARED * s2)
    return g0, 1.0 + FLATTENING + GRAVITY_RATIO_M - 2.0 * FLATTENING * s2


@compiled
def gravity_at_height(g0: float, slope: float, height: float) -> float:
    """:func:`normal_gravity` from its latitude terms (:func:`gravity_latitude_terms`) at ``height``."""
    a = SEMI_MAJOR_AXIS
    factor = 1.0 - 2.0 * height / a * slope
    return g0 * (factor + 3.0 * height * height / (a * a))


@compiled
def earth_rate_ned(latitude: float) -> tuple[float, float, float]:
    """omega_ie^n = Omega [cos L, 0, -sin L] (earth rate seen in NED) [rad/s]."""
    return EARTH_RATE * math.cos(latitude), 0.0, -EARTH_RATE * math.sin(latitude)


@compiled
def transport_rate_ned(
    latitude: float, height: float, velocity_north: float, velocity_east: float
) -> tuple[float, float, float]:
    """omega_en^n, the rotation of NED over the ellipsoid caused by the motion [rad/s].

    omega_en^n = [V_e/(R_N+h), -V_n/(R_M+h), -V_e tan L/(R_N+h)].
    """
    meridian, prime_vertical = radii_of_curvature(latitude)
    return transport_rate_from_radii(meridian, prime_vertical, math.tan(latitude), height, velocity_north, velocity_east)


@compiled
def transport_rate_from_radii(
    meridian: float, prime_vertical: float, tan_latitude: float, height: float, velocity_north: float,
    velocity_east: float
) -> tuple[float, float, float]:
    """:func:`transport_rate_ned` from the radii of curvature and tangent of the latitude."""
    rn = prime_vertical + height
    return (
        velocity_east / rn,
        -velocity_north / (meridian + height),
        -velocity_east * tan_latitude / rn,
    )


@compiled
def position_rates(
    latitude: float, height: float, velocity_north: float, velocity_east: float, velocity_down: float
) -> tuple[float, float, float]:
    """d(latitude)/dt, d(longitude)/dt [rad/s] and d(height)/dt [m/s] from NED velocity.

    The cosine is taken before the radii's sine of the same latitude, with no
    branch between them (a division's zero check would be one), so the compiler
    makes the two one ``sincos`` call: the same numbers, one libm call fewer
    (the trajectory's RK4 takes four of these per IMU sample).
    """
    cos_latitude = math.cos(latitude)
    meridian, prime_vertical = radii_of_curvature(latitude)
    return position_rates_from_radii(meridian, prime_vertical, cos_latitude, height, velocity_north, velocity_east,
                                     velocity_down)


@compiled
def position_rates_from_radii(
    meridian: float, prime_vertical: float, cos_latitude: float, height: float, velocity_north: float,
    velocity_east: float, velocity_down: float
) -> tuple[float, float, float]:
    """:func:`position_rates` from the radii of curvature and cosine of the latitude (a caller may keep them)."""
    return (
        velocity_north / (meridian + height),
        velocity_east / ((prime_vertical + height) * cos_latitude),
        -velocity_down,
    )


def geodetic_to_ecef(latitude, longitude, height) -> np.ndarray:
    """Earth-centred earth-fixed coordinates [m] of geodetic points (array-friendly)."""
    latitude, longitude, height = np.broadcast_arrays(
        np.asarray(latitude, float), np.asarray(longitude, float), np.asarray(height, float)
    )
    s, c = np.sin(latitude), np.cos(latitude)
    prime_vertical = SEMI_MAJOR_AXIS / np.sqrt(1.0 - ECCENTRICITY_SQUARED * s * s)
    return np.stack(
        [
            (prime_vertical + height) * c * np.cos(longitude),
            (prime_vertical + height) * c * np.sin(longitude),
            (prime_vertical * (1.0 - ECCENTRICITY_SQUARED) + height) * s,
        ],
        axis=-1,
    )


def ecef_to_geodetic(position: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geodetic latitude, longitude [rad] and height [m] of ECEF points (fixed-point iteration)."""
    position = np.asarray(position, float)
    x, y, z = position[..., 0], position[..., 1], position[..., 2]
    longitude = np.arctan2(y, x)
    p = np.hypot(x, y)
    latitude = np.arctan2(z, p * (1.0 - ECCENTRICITY_SQUARED))
    height = np.zeros_like(p)
    for _ in range(8):  # converges to < 1e-12 rad for any height below 1e5 km
        s = np.sin(latitude)
        prime_vertical = SEMI_MAJOR_AXIS / np.sqrt(1.0 - ECCENTRICITY_SQUARED * s * s)
        height = p / np.cos(latitude) - prime_vertical
        latitude = np.arctan2(z, p * (1.0 - ECCENTRICITY_SQUARED * prime_vertical / (prime_vertical + height)))
    return latitude, longitude, height


def ned_to_ecef_matrix(latitude: float, longitude: float) -> np.ndarray:
    """C_n^e: rotates a NED vector at (latitude, longitude) into ECEF axes."""
    sl, cl = math.sin(latitude), math.cos(latitude)
    so, co = math.sin(longitude), math.cos(longitude)
    return np.array(
        [
            [-sl * co, -so, -cl * co],
            [-sl * so, co, -cl * so],
            [cl, 0.0, -sl],
        ]
    )
