"""The WGS-84 earth: the one set of ellipsoid, rotation and gravity constants.

Values from NIMA TR8350.2, "Department of Defense World Geodetic System 1984"
(3rd ed., amendment 1, 2000): the defining parameters a, 1/f, omega and GM
(Table 3.1) and Somigliana's normal gravity on the ellipsoid (eq. 4-1, with
gamma_e and k of Table 3.4); e^2, b and m are derived from the defining
parameters as TR8350.2 derives them (Table 3.3).

Two earth rates are in use and both are named here, so that no module keeps
its own copy:

* :data:`EARTH_RATE` = 7.292115e-5 rad/s is WGS-84's defining value (the
  simulation's truth and strapdown mechanization, the navigator);
* :data:`GPS_EARTH_RATE` = 7.2921151467e-5 rad/s is the value of the GPS
  interface specification IS-GPS-200 (section 20.3.3.4.3.3), which the
  built-in model files, the paper's scenario (``data/scenario_000.yaml``) and
  the models built in code (:mod:`modelgen.model.pseudorange`) carry.  They
  differ by 2e-8 relative, far below anything the covariance analysis resolves.

Pure Python, no imports from the rest of modelgen: every layer may use it.
"""

from __future__ import annotations

import math

#: a: semi-major axis [m] (defining).
SEMI_MAJOR_AXIS = 6378137.0
#: f: flattening, 1/298.257223563 (defining).
FLATTENING = 1.0 / 298.257223563
#: omega: angular velocity of the earth [rad/s] (defining).
EARTH_RATE = 7.292115e-5
#: GM: earth's gravitational constant, atmosphere included [m^3/s^2] (defining).
GRAVITATIONAL_CONSTANT = 3.986004418e14
#: e^2 = f (2 - f): first eccentricity squared.
ECCENTRICITY_SQUARED = FLATTENING * (2.0 - FLATTENING)
#: b = a (1 - f): semi-minor axis [m].
SEMI_MINOR_AXIS = SEMI_MAJOR_AXIS * (1.0 - FLATTENING)
#: gamma_e: normal gravity at the equator [m/s^2] (Somigliana).
EQUATORIAL_GRAVITY = 9.7803253359
#: k = b gamma_p / (a gamma_e) - 1: Somigliana's constant.
SOMIGLIANA_K = 0.00193185265241
#: m = omega^2 a^2 b / GM, in the free-air height correction of normal gravity.
GRAVITY_RATIO_M = EARTH_RATE**2 * SEMI_MAJOR_AXIS**2 * SEMI_MINOR_AXIS / GRAVITATIONAL_CONSTANT
#: Earth rotation rate of IS-GPS-200 [rad/s] (the value the built-in model files carry).
GPS_EARTH_RATE = 7.2921151467e-5
#: J2: the second zonal harmonic of WGS-84's gravitational field, as Groves (2013) eq. 2.142 and table 2.1 give it
#: (the e-frame gravity model of the ecef mechanization).
J2 = 1.082627e-3


def earth_radii(latitude: float) -> tuple[float, float]:
    """Meridian and prime-vertical radii of curvature (R_M, R_N) in metres at ``latitude`` (rad).

    R_M = a (1 - e^2) / (1 - e^2 sin^2 L)^(3/2),  R_N = a / (1 - e^2 sin^2 L)^(1/2).
    """
    w = 1.0 - ECCENTRICITY_SQUARED * math.sin(latitude) ** 2
    return SEMI_MAJOR_AXIS * (1.0 - ECCENTRICITY_SQUARED) / w**1.5, SEMI_MAJOR_AXIS / math.sqrt(w)
