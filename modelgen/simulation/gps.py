"""GPS receivers: a position/velocity receiver and a pseudo-range receiver.

* :func:`simulate_position_velocity` -- the loosely coupled receiver of the INS/GPS paper:
  latitude, longitude, height and NED velocity with white noise; outages mark
  measurements invalid (the INS/GPS paper §3.2: "when GPS is invalid, no correction").
* :func:`simulate_pseudoranges` -- the receiver of the accumulated-correction paper: ranges to the
  satellites above an elevation mask plus the receiver clock bias b (metres) and
  white noise; b and the clock drift d follow the two-state clock model
  b' = d + w_b, d' = w_d (the accumulated-correction paper's "clock-bias distance I_t" and
  "frequency-difference distance I_f").
* :class:`Constellation` -- a simple Walker 24/6/1 constellation (55 deg,
  26 560 km circular orbits) in earth-fixed axes; signal travel time and
  earth rotation during it are ignored (metre-level, irrelevant here).

:data:`GPS` is the position/velocity receiver's plug-in (:class:`GpsAiding`);
the pseudo-range receiver's is in :mod:`modelgen.simulation.pseudorange`
with its navigator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.ins_aiding import NavigationQuantitySensor
from modelgen.simulation.profile_keys import Outage, ProfileSection, read_outages, valid_mask


@dataclass(frozen=True)
class GpsSettings:
    period: float = 1.0
    position_noise: float = 5.0  # m rms, north and east
    height_noise: float = 8.0  # m rms
    velocity_noise: float = 0.05  # m/s rms per NED axis
    outages: tuple[Outage, ...] = ()

    def __post_init__(self) -> None:
        if not self.period > 0:
            raise ModelError(f"gps: period must be positive, got {self.period}")


@dataclass(frozen=True)
class GpsRecord:
    """Receiver output at its measurement times (columns: lat, lon [rad], h [m]; v_NED)."""

    times: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    valid: np.ndarray


def simulate_position_velocity(times: np.ndarray, position: np.ndarray, velocity: np.ndarray,
                               settings: GpsSettings, rng: np.random.Generator) -> GpsRecord:
    """Noisy fixes from the true (lat, lon, h) and NED velocity at ``times``."""
    n = len(times)
    meridian, prime_vertical = np.vectorize(earth.radii_of_curvature)(position[:, 0])
    noise = rng.standard_normal((n, 3))
    measured = position.copy()
    measured[:, 0] += settings.position_noise * noise[:, 0] / (meridian + position[:, 2])
    measured[:, 1] += settings.position_noise * noise[:, 1] / ((prime_vertical + position[:, 2]) * np.cos(position[:, 0]))
    measured[:, 2] += settings.height_noise * noise[:, 2]
    measured_velocity = velocity + settings.velocity_noise * rng.standard_normal((n, 3))
    return GpsRecord(times, measured, measured_velocity, valid_mask(times, settings.outages))


@dataclass(frozen=True)
class Constellation:
    """Walker delta constellation T/P/F with circular orbits."""

    satellites: int = 24
    planes: int = 6
    phasing: int = 1
    inclination: float = math.radians(55.0)
    radius: float = 26_559_700.0

    def positions(self, t: float) -> np.ndarray:
        """ECEF positions (satellites, 3) [m] at time t [s] (t = 0: plane 0 ascending node on Greenwich)."""
        per_plane = self.satellites // self.planes
        if per_plane * self.planes != self.satellites:
            raise ModelError(f"constellation: {self.satellites} satellites do not fill {self.planes} planes")
        mean_motion = math.sqrt(earth.GRAVITATIONAL_CONSTANT / self.radius**3)
        plane = np.repeat(np.arange(self.planes), per_plane)
        slot = np.tile(np.arange(per_plane), self.planes)
        node = 2 * math.pi * plane / self.planes - earth.EARTH_RATE * t  # node longitude in ECEF
        u = 2 * math.pi * slot / per_plane + 2 * math.pi * self.phasing * plane / self.satellites + mean_motion * t
        ci, si = math.cos(self.inclination), math.sin(self.inclination)
        x = self.radius * (np.cos(u) * np.cos(node) - np.sin(u) * ci * np.sin(node))
        y = self.radius * (np.cos(u) * np.sin(node) + np.sin(u) * ci * np.cos(node))
        z = self.radius * np.sin(u) * si
        return np.stack([x, y, z], axis=1)


@dataclass(frozen=True)
class PseudorangeSettings:
    period: float = 1.0
    noise: float = 3.0  # m rms per range
    clock_bias: float = 3.0e4  # m rms initial receiver clock bias (0.1 ms)
    clock_drift: float = 3.0  # m/s rms initial drift (1e-8)
    clock_bias_psd: float = 0.1  # m^2/s, white noise on b' (white frequency noise)
    clock_drift_psd: float = 0.01  # m^2/s^3, white noise on d' (random-walk frequency)
    elevation_mask: float = math.radians(10.0)
    constellation: Constellation = field(default_factory=Constellation)


@dataclass(frozen=True)
class PseudorangeRecord:
    """Pseudo-ranges (times, satellites) [m], NaN where a satellite is below the mask."""

    times: np.ndarray
    pseudoranges: np.ndarray
    satellites: np.ndarray  # (times, satellites, 3) ECEF [m]
    clock_bias: np.ndarray  # true receiver clock bias [m]
    clock_drift: np.ndarray  # true drift [m/s]


def clock_sequence(n: int, dt: float, settings: PseudorangeSettings, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Exact discrete samples of b' = d + w_b, d' = w_d."""
    qb, qd = settings.clock_bias_psd, settings.clock_drift_psd
    cov = np.array([[qb * dt + qd * dt**3 / 3, qd * dt**2 / 2], [qd * dt**2 / 2, qd * dt]])
    chol = np.linalg.cholesky(cov + 1e-30 * np.eye(2))
    bias, drift = np.empty(n), np.empty(n)
    b, d = settings.clock_bias * rng.standard_normal(), settings.clock_drift * rng.standard_normal()
    for k in range(n):
        bias[k], drift[k] = b, d
        w = chol @ rng.standard_normal(2)
        b, d = b + d * dt + w[0], d + w[1]
    return bias, drift


def elevation(user: np.ndarray, satellite: np.ndarray) -> np.ndarray:
    """Elevation angles [rad] of satellites (..., 3) seen from an ECEF user position (3,)."""
    lat, lon, _ = earth.ecef_to_geodetic(user)
    up = earth.ned_to_ecef_matrix(float(lat), float(lon))[:, 2] * -1.0
    los = satellite - user
    return np.arcsin(los @ up / np.linalg.norm(los, axis=-1))


def simulate_pseudoranges(times: np.ndarray, position: np.ndarray, settings: PseudorangeSettings,
                          rng: np.random.Generator, constellation: Constellation | None = None) -> PseudorangeRecord:
    """rho = |r_sat - r_user| + b + noise for every visible satellite at ``times`` (default: the settings' constellation)."""
    constellation = settings.constellation if constellation is None else constellation
    n = len(times)
    dt = float(times[1] - times[0]) if n > 1 else settings.period
    bias, drift = clock_sequence(n, dt, settings, rng)
    user = earth.geodetic_to_ecef(position[:, 0], position[:, 1], position[:, 2])
    sats = np.stack([constellation.positions(float(t)) for t in times])
    ranges = np.linalg.norm(sats - user[:, None, :], axis=-1)
    rho = ranges + bias[:, None] + settings.noise * rng.standard_normal(ranges.shape)
    for k in range(n):
        rho[k, elevation(user[k], sats[k]) < settings.elevation_mask] = np.nan
    return PseudorangeRecord(times, rho, sats, bias, drift)


def solve_position(pseudoranges: np.ndarray, satellites: np.ndarray, guess: np.ndarray | None = None,
                   iterations: int = 10) -> tuple[np.ndarray, float]:
    """Least-squares ECEF position and clock bias [m] from one epoch's pseudo-ranges (Gauss-Newton)."""
    use = np.isfinite(pseudoranges)
    if use.sum() < 4:
        raise ModelError(f"gps: {int(use.sum())} satellites visible, at least 4 are needed for a fix")
    rho, sats = pseudoranges[use], satellites[use]
    x = np.zeros(4) if guess is None else np.concatenate([guess, [0.0]])
    for _ in range(iterations):
        diff = x[:3] - sats
        dist = np.linalg.norm(diff, axis=1)
        H = np.hstack([diff / dist[:, None], np.ones((len(rho), 1))])
        dx = np.linalg.lstsq(H, rho - (dist + x[3]), rcond=None)[0]
        x = x + dx
        if np.linalg.norm(dx) < 1e-6:
            break
    return x[:3], float(x[3])


class GpsAiding(NavigationQuantitySensor):
    """The position/velocity receiver as an aiding-sensor plug-in (profile section ``gps``, ``filter.aiding: gps``)."""

    name = "gps"

    def read_settings(self, section: ProfileSection) -> GpsSettings:
        settings = GpsSettings(
            period=section.number("period_s", 1.0, positive=True),
            position_noise=section.number("position_noise_m", 5.0, non_negative=True),
            height_noise=section.number("height_noise_m", 8.0, non_negative=True),
            velocity_noise=section.number("velocity_noise_mps", 0.05, non_negative=True),
            outages=read_outages(section, "outages"),
        )
        section.done()
        return settings

    def period(self, settings: GpsSettings) -> float:
        return settings.period

    def noise_parameters(self, settings: GpsSettings) -> dict[str, float]:
        return {
            "gps_velocity_sigma_east": settings.velocity_noise, "gps_velocity_sigma_north": settings.velocity_noise,
            "gps_velocity_sigma_up": settings.velocity_noise,
            "gps_position_sigma_north": settings.position_noise, "gps_position_sigma_east": settings.position_noise,
            "gps_position_sigma_up": settings.height_noise,
        }

    def simulate_at(self, settings: GpsSettings, truth: np.ndarray, rng: np.random.Generator) -> GpsRecord:
        return simulate_position_velocity(truth[:, 0], truth[:, 1:4], truth[:, 4:7], settings, rng)

    def fix(self, record: GpsRecord, epoch: int, navigation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return record.velocity[epoch], record.position[epoch]

    def fix_table(self, record: GpsRecord) -> tuple[np.ndarray, np.ndarray, bool]:
        """:meth:`fix` for every epoch, for the compiled loop: NED velocity and (lat, lon, h)."""
        return record.velocity, record.position, False


#: the registry entry (modelgen.simulation.sensors)
GPS = GpsAiding()
