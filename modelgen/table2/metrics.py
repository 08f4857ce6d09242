"""Navigation errors in the paper's units, and the circular error probable.

Units of Table 2: attitude errors in arc-seconds, velocity errors and Doppler
bias estimation errors in nautical miles per hour, position error as CEP in
nautical miles; the average drift rate is CEP(t) / t in nmile/h (the paper's
pure-inertial 9.29 nmile/h is 37.16 nmile / 4 h).

CEP: the radius of the circle about the true position that contains the
position error with probability 1/2, computed EXACTLY for the horizontal
2x2 covariance (correlation included) of the north and east position errors
R dphi and R cos(phi) dlambda.  With principal standard deviations
s1 >= s2 the CEP is s1 * c(s2/s1), where c(rho) solves

    P(z1^2 + rho^2 z2^2 <= c^2) = 1/2,  z1, z2 independent N(0, 1);

c(1) = sqrt(2 ln 2) = 1.1774 (circular), c(0) = 0.6745 (one axis).  c(rho)
is tabulated once by quadrature and interpolated (error < 1e-6).  The common
approximation 0.5887 (s_N + s_E) overstates it by less than 0.5 % for
rho >= 0.7 (1.5 % at rho = 0.5, 2 % at 0.3); for every system here s_N ~ s_E
(rho > 0.9) and the two agree to the printed digits.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Mapping, Sequence

import numpy as np
from scipy.integrate import quad
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq
from scipy.special import erf

from modelgen.model.units import from_si

#: (state name, output name, unit) of the error standard deviations reported
REPORTED_STATES: tuple[tuple[str, str, str], ...] = (
    ("attitude_error_north", "attitude_error_north", "arcsec"),
    ("attitude_error_east", "attitude_error_east", "arcsec"),
    ("heading_error", "heading_error", "deg"),
    ("velocity_error_north", "velocity_error_north", "nmile/h"),
    ("velocity_error_east", "velocity_error_east", "nmile/h"),
    ("doppler_velocity_bias_north", "doppler_bias_error_north", "nmile/h"),
    ("doppler_velocity_bias_east", "doppler_bias_error_east", "nmile/h"),
)


def _probability_inside(c: float, rho: float) -> float:
    """P(z1^2 + rho^2 z2^2 <= c^2), by conditioning on z2."""
    if rho == 0.0:
        return float(erf(c / np.sqrt(2.0)))
    top = min(c / rho, 40.0)

    def integrand(z2: float) -> float:
        room = c * c - (rho * z2) ** 2
        return np.exp(-0.5 * z2 * z2) / np.sqrt(2.0 * np.pi) * erf(np.sqrt(max(room, 0.0) / 2.0))

    value, _ = quad(integrand, 0.0, top, limit=200, epsabs=1e-13, epsrel=1e-12)
    return 2.0 * value


@lru_cache(maxsize=1)
def _cep_factor_table() -> CubicSpline:
    """c(rho) on rho = 0..1, tabulated once."""
    rhos = np.linspace(0.0, 1.0, 81)
    factors = [brentq(lambda c, r=r: _probability_inside(c, r) - 0.5, 0.5, 1.3, xtol=1e-13) for r in rhos]
    return CubicSpline(rhos, factors)


def cep_factor(rho: np.ndarray | float) -> np.ndarray:
    """c(rho): CEP in units of the larger principal standard deviation."""
    return _cep_factor_table()(np.clip(rho, 0.0, 1.0))


def circular_error_probable(position_covariance: np.ndarray) -> np.ndarray:
    """Exact CEP of zero-mean Gaussian horizontal errors with covariance (..., 2, 2)."""
    cov = np.asarray(position_covariance, dtype=float)
    eig = np.linalg.eigvalsh(0.5 * (cov + np.swapaxes(cov, -1, -2)))
    large = np.sqrt(np.clip(eig[..., 1], 0.0, None))
    small = np.sqrt(np.clip(eig[..., 0], 0.0, None))
    rho = np.divide(small, large, out=np.zeros_like(large), where=large > 0)
    return large * cep_factor(rho)


def cep_approximation(sigma_north: np.ndarray, sigma_east: np.ndarray) -> np.ndarray:
    """The usual 0.5887 (s_N + s_E), for comparison only."""
    return 0.5887 * (np.asarray(sigma_north) + np.asarray(sigma_east))


def navigation_errors(
    covariance: np.ndarray, state_names: Sequence[str], latitude: float, earth_radius: float, times_h: np.ndarray
) -> dict[str, np.ndarray]:
    """Time series of error standard deviations in the paper's units.

    ``covariance`` has shape (steps+1, n, n) in the order of ``state_names``.
    States a system does not have (the Doppler biases of the pure-inertial
    system) are simply absent from the result.
    """
    index = {name: i for i, name in enumerate(state_names)}
    var = np.einsum("kii->ki", covariance)
    out: dict[str, np.ndarray] = {}
    for state, key, unit in REPORTED_STATES:
        if state in index:
            out[key] = from_si(np.sqrt(np.clip(var[:, index[state]], 0.0, None)), unit)
    i, j = index["latitude_error"], index["longitude_error"]
    scale = np.array([earth_radius, earth_radius * np.cos(latitude)])
    pos = covariance[:, [i, j]][:, :, [i, j]] * np.outer(scale, scale)
    out["position_error_north"] = from_si(np.sqrt(pos[:, 0, 0]), "nmile")
    out["position_error_east"] = from_si(np.sqrt(pos[:, 1, 1]), "nmile")
    out["position_cep"] = from_si(circular_error_probable(pos), "nmile")
    hours = np.asarray(times_h, dtype=float)
    out["average_drift_rate"] = np.divide(out["position_cep"], hours, out=np.zeros_like(hours), where=hours > 0)
    return out


def final_values(errors: Mapping[str, np.ndarray]) -> dict[str, float]:
    """The value of each series at the end of the run (the paper's Table 2 values)."""
    return {k: float(v[-1]) for k, v in errors.items()}
