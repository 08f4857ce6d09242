"""Doppler radar velocity sensor (the core paper and 002).

Principle (the Doppler error thesis, eqs. (2-9)-(2-10)): a beam leaving the aircraft along the
unit vector b and scattered back by the ground is shifted by

    f_d = 2 V cos(gamma) / lambda = 2 (v . b) / lambda,

gamma being the angle between the ground velocity v and the beam.  With four
beams in the Janus configuration (two forward at azimuth +-a, two aft at
180 deg +- a, all depressed by d below the body x-y plane) the three body-axis
velocity components follow from the four frequencies by least squares,
v^b = lambda/2 (B^T B)^-1 B^T f.  Tool errors (the Doppler error thesis §3.3.1): a random
constant frequency bias per beam (beam asymmetry), frequency noise, and an
antenna mounting misalignment (the real beams are rotated from the nominal
ones the solution assumes).  The attitude-induced error (§3.3.2) appears when
the body velocity is resolved in navigation axes with an attitude that has an
error psi: C~ v^b = (I - psi x) C v^b, an error of -psi x v^n.

Two measurement models are offered:

* ``ned`` -- the core paper eq. (6): the Doppler delivers the NED ground velocity
  with a random-constant bias and white noise per axis.  This is exactly the
  18-state model's measurement, used for the consistency (NEES) tests.
* ``beams`` -- the physical four-beam radar above; its body velocity is
  resolved with the INS attitude by the navigator, so the attitude-induced
  error is present (and not modelled by the 18-state filter).

:data:`DOPPLER` is the sensor's plug-in (:class:`DopplerAiding`): its profile
keys, noise, simulation and measurement function.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation.ins_aiding import NavigationQuantitySensor
from modelgen.simulation.profile_keys import ARCMIN, DEG, KMH, Outage, ProfileSection, read_outages, valid_mask
from modelgen.simulation.rotation import quaternion_to_dcm, rotation_vectors_to_quaternions


@dataclass(frozen=True)
class JanusBeams:
    """Four-beam Janus geometry and radar errors (angles in rad, SI units)."""

    azimuth: float = math.radians(45.0)
    depression: float = math.radians(65.0)
    wavelength: float = 0.0225
    frequency_noise: float = 10.0  # Hz rms per measurement
    frequency_bias: float = 0.0  # Hz rms per beam, random constant
    mounting_error: float = 0.0  # rad rms per axis, random constant

    def directions(self) -> np.ndarray:
        """Nominal beam unit vectors in body axes, one row per beam."""
        cd, sd = math.cos(self.depression), math.sin(self.depression)
        az = np.array([self.azimuth, -self.azimuth, math.pi - self.azimuth, math.pi + self.azimuth])
        return np.stack([cd * np.cos(az), cd * np.sin(az), np.full(4, sd)], axis=1)


@dataclass(frozen=True)
class DopplerSettings:
    period: float = 60.0
    measurement: str = "ned"
    bias: float = 0.0  # m/s rms per NED axis, random constant ("ned" model)
    white_noise: float = 0.0  # m/s rms per NED axis ("ned" model)
    beams: JanusBeams = field(default_factory=JanusBeams)
    outages: tuple[Outage, ...] = ()

    def __post_init__(self) -> None:
        if self.measurement not in ("ned", "beams"):
            raise ModelError(f"doppler: measurement must be 'ned' or 'beams', got {self.measurement!r}")
        if not self.period > 0:
            raise ModelError(f"doppler: period must be positive, got {self.period}")


@dataclass(frozen=True)
class DopplerRecord:
    """Doppler output at its measurement times.

    ``velocity`` is NED ("ned") or body axes ("beams"); ``bias`` is the true
    NED bias of the "ned" model (zeros for "beams"); ``valid`` marks outages.
    """

    times: np.ndarray
    velocity: np.ndarray
    bias: np.ndarray
    valid: np.ndarray
    frame: str


def doppler_shift(velocity_body: np.ndarray, directions: np.ndarray, wavelength: float) -> np.ndarray:
    """f_d = 2 (v . b) / lambda for every beam (the Doppler error thesis, eq. (2-10)); rows of v give rows of f."""
    return 2.0 * np.asarray(velocity_body) @ directions.T / wavelength


def velocity_from_shifts(frequencies: np.ndarray, directions: np.ndarray, wavelength: float) -> np.ndarray:
    """Least-squares body velocity from the beams' Doppler shifts (inverse of :func:`doppler_shift`)."""
    solve = 0.5 * wavelength * np.linalg.pinv(directions)  # (3, beams)
    return np.asarray(frequencies) @ solve.T


def attitude_induced_error(velocity_ned: np.ndarray, attitude_error: np.ndarray) -> np.ndarray:
    """-psi x v^n: the NED velocity error from resolving body velocity with a wrong attitude."""
    return -np.cross(attitude_error, velocity_ned)


def simulate_doppler(times: np.ndarray, velocity_ned: np.ndarray, attitude: np.ndarray, settings: DopplerSettings,
                     rng: np.random.Generator) -> DopplerRecord:
    """Doppler outputs at ``times`` from the true NED velocity and true attitude q_b^n."""
    n = len(times)
    valid = valid_mask(times, settings.outages)
    if settings.measurement == "ned":
        bias = np.zeros(3)
        bias[:2] = settings.bias * rng.standard_normal(2)
        noise = np.zeros((n, 3))
        noise[:, :2] = settings.white_noise * rng.standard_normal((n, 2))
        return DopplerRecord(times, velocity_ned + bias + noise, np.tile(bias, (n, 1)), valid, "ned")
    beams = settings.beams
    nominal = beams.directions()
    mounting = quaternion_to_dcm(rotation_vectors_to_quaternions(beams.mounting_error * rng.standard_normal(3)))
    actual = nominal @ mounting.T
    body_velocity = np.einsum("kji,kj->ki", quaternion_to_dcm(attitude), velocity_ned)  # C_n^b v^n
    shifts = doppler_shift(body_velocity, actual, beams.wavelength)
    shifts = shifts + beams.frequency_bias * rng.standard_normal(4) + beams.frequency_noise * rng.standard_normal((n, 4))
    return DopplerRecord(times, velocity_from_shifts(shifts, nominal, beams.wavelength), np.zeros((n, 3)), valid, "body")


class DopplerAiding(NavigationQuantitySensor):
    """The Doppler radar as an aiding-sensor plug-in (profile section ``doppler``, ``filter.aiding: doppler``).

    Its bias is a random constant per NED axis ("ned" model) with model states
    in the error-layout group ``doppler_bias``; the "beams" model's body
    velocity is resolved with the INS attitude (the attitude-induced error).
    """

    name = "doppler"
    bias_group = "doppler_bias"

    def read_settings(self, section: ProfileSection) -> DopplerSettings:
        beams = section.section("beams")
        beams.text("configuration", "janus4", ("janus4",))
        janus = JanusBeams(
            azimuth=beams.number("azimuth_deg", 45.0, DEG),
            depression=beams.number("depression_deg", 65.0, DEG),
            wavelength=beams.number("wavelength_m", 0.0225, positive=True),
            frequency_noise=beams.number("frequency_noise_hz", 10.0, non_negative=True),
            frequency_bias=beams.number("frequency_bias_hz", 0.0),
            mounting_error=beams.number("mounting_error_arcmin", 0.0, ARCMIN),
        )
        beams.done()
        settings = DopplerSettings(
            period=section.number("period_s", 60.0, positive=True),
            measurement=section.text("measurement", "ned", ("ned", "beams")),
            bias=section.number("bias_kmh", 0.0, KMH),
            white_noise=section.number("white_noise_mps", 0.0, non_negative=True),
            beams=janus,
            outages=read_outages(section, "outages"),
        )
        section.done()
        return settings

    def period(self, settings: DopplerSettings) -> float:
        return settings.period

    def noise_parameters(self, settings: DopplerSettings) -> dict[str, float]:
        return {"doppler_noise_sigma_north": settings.white_noise, "doppler_noise_sigma_east": settings.white_noise}

    reads_truth_position = False  # velocity and attitude only

    def simulate_at(self, settings: DopplerSettings, truth: np.ndarray, rng: np.random.Generator) -> DopplerRecord:
        return simulate_doppler(truth[:, 0], truth[:, 4:7], truth[:, 7:11], settings, rng)

    def fix(self, record: DopplerRecord, epoch: int, navigation: np.ndarray) -> tuple[np.ndarray, None]:
        velocity = record.velocity[epoch]
        if record.frame == "body":  # resolve with the INS attitude (attitude-induced error)
            velocity = quaternion_to_dcm(navigation[6:10]) @ velocity
        return velocity, None

    def fix_table(self, record: DopplerRecord) -> tuple[np.ndarray, np.ndarray, bool]:
        """:meth:`fix` for every epoch, for the compiled loop: velocity (NED or body axes), no position."""
        return record.velocity, np.full((len(record.times), 3), np.nan), record.frame == "body"

    def true_bias(self, record: DopplerRecord) -> np.ndarray:
        return record.bias[0]

    def bias_sigma(self, settings: DopplerSettings) -> float:
        return settings.bias


#: the registry entry (modelgen.simulation.sensors)
DOPPLER = DopplerAiding()
