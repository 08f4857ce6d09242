"""The e-frame side of the navigator: a model with ``mechanization: ecef`` is flown in r^e, v^e, C_b^e.

The navigation state array keeps its layout (:data:`modelgen.navigator.mechanization.NAV_SIZE`):
the body-to-frame quaternion, the frame's velocity and the position, which for the ecef
mechanization are C_b^e, v^e [m/s] and r^e [m].  What the navigator takes in (the alignment, the
GNSS fixes) and gives out (trajectory.csv, .pos: geodetic, NED velocity, roll/pitch/yaw against
NED, north/east/up sigmas) stays geodetic; these functions convert, with the package's own WGS-84
conversions (:mod:`modelgen.simulation.earth`).  The C navigator's ``ecef_*`` functions
(navigator_source.c.j2) do the same arithmetic in the same order.
"""

from __future__ import annotations

import numpy as np

from modelgen.simulation.earth import ecef_to_geodetic, geodetic_to_ecef, ned_to_ecef_matrix
from modelgen.navigator.mechanization import dcm_to_quaternion, quaternion_to_dcm


__all__ = ["covariance_to_ned", "geodetic", "geodetic_to_ecef", "local_view", "ned_to_ecef", "state_from_ned"]


def geodetic(r: np.ndarray) -> tuple[float, float, float]:
    """Latitude, longitude [rad] and height [m] of an e-frame position."""
    lat, lon, h = ecef_to_geodetic(np.asarray(r, float))
    return float(lat), float(lon), float(h)


def ned_to_ecef(lat: float, lon: float) -> np.ndarray:
    """C_n^e at a geodetic position."""
    return ned_to_ecef_matrix(lat, lon)


def state_from_ned(nav: np.ndarray) -> np.ndarray:
    """The e-frame state (q_b^e, v^e, r^e) of a local-level NED state (q_b^n, v^n, latitude, longitude, height)."""
    c_ne = ned_to_ecef(nav[7], nav[8])
    out = np.empty_like(nav)
    out[0:4] = dcm_to_quaternion(c_ne @ quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3]))
    out[4:7] = c_ne @ nav[4:7]
    out[7:10] = geodetic_to_ecef(nav[7], nav[8], nav[9])
    return out


def local_view(nav: np.ndarray) -> tuple[float, float, float, np.ndarray, np.ndarray, np.ndarray]:
    """(latitude, longitude, height, C_n^e, C_b^n, v^n) of an e-frame state (at its own position)."""
    lat, lon, h = geodetic(nav[7:10])
    c_ne = ned_to_ecef(lat, lon)
    c_be = quaternion_to_dcm(nav[0], nav[1], nav[2], nav[3])
    return lat, lon, h, c_ne, c_ne.T @ c_be, c_ne.T @ nav[4:7]


def covariance_to_ned(P_e: np.ndarray, c_ne: np.ndarray) -> np.ndarray:
    """A 3x3 e-frame covariance in NED axes: C_e^n P C_n^e."""
    return c_ne.T @ P_e @ c_ne
