"""The analysis scenario (scenario_000.yaml): operating point (model parameters) and flight phases.

The core paper evaluates F at one level-flight operating point for the whole
run (the core paper, section 3: "we use the level-flight attitude matrix"); the
phases of the printed flight profile only tell when the aircraft manoeuvres
(suboptimal filter II recomputes its gain more often then).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from modelgen.fileio.datafiles import data_path, read_yaml, require
from modelgen.model.units import to_si
from modelgen.errors import ModelError

SCENARIO_FILE = "scenario_000.yaml"
SPECIFIC_FORCE_MODES = ("kinematic", "gravity_only")


@dataclass(frozen=True)
class Phase:
    """One segment of the flight profile."""

    name: str
    start_s: float
    end_s: float
    manoeuvre: bool


@dataclass(frozen=True)
class AnalysisScenario:
    """Everything about the flight that the covariance analysis needs (SI): the analysis scenario."""

    name: str
    latitude: float  # rad
    duration_s: float
    step_s: float
    taylor_order: int
    earth_radius: float  # m
    earth_rate: float  # rad/s
    gravity: float  # m/s^2
    velocity_ned: tuple[float, float, float]  # level flight, m/s
    specific_force: str  # "kinematic" or "gravity_only"
    attitude_matrix: tuple[tuple[float, ...], ...]  # C_b^n, level flight
    phases: tuple[Phase, ...]

    @property
    def steps(self) -> int:
        """Number of filter steps T in the run (240 for 4 h at 60 s)."""
        return int(round(self.duration_s / self.step_s))

    def times_h(self) -> np.ndarray:
        """Times of the covariance history, 0 .. duration, in hours."""
        return np.arange(self.steps + 1) * self.step_s / 3600.0

    def manoeuvring(self, time_s: float) -> bool:
        """True while the profile says the aircraft manoeuvres at ``time_s``."""
        return any(p.manoeuvre and p.start_s <= time_s < p.end_s for p in self.phases)


def specific_force_ned(
    latitude: float, velocity_ned: np.ndarray, earth_radius: float, earth_rate: float, gravity: float
) -> np.ndarray:
    """Specific force (a_n, a_e, a_d) of steady flight at constant ground velocity.

    From dV/dt = f - (2 w_ie + w_en) x V + g = 0 in NED:
    f = (2 w_ie + w_en) x V - g, with w_ie = W (cos phi, 0, -sin phi),
    w_en = (V_e / R, -V_n / R, -V_e tan(phi) / R), g = (0, 0, gravity).
    """
    v_n, v_e, _ = velocity_ned
    w_ie = earth_rate * np.array([math.cos(latitude), 0.0, -math.sin(latitude)])
    w_en = np.array([v_e / earth_radius, -v_n / earth_radius, -v_e * math.tan(latitude) / earth_radius])
    return np.cross(2.0 * w_ie + w_en, velocity_ned) - np.array([0.0, 0.0, gravity])


def operating_point(scenario: AnalysisScenario) -> dict[str, float]:
    """Model parameter values (ned_doppler18 names) of the level-flight point."""
    v = np.asarray(scenario.velocity_ned, dtype=float)
    if scenario.specific_force == "kinematic":
        f = specific_force_ned(scenario.latitude, v, scenario.earth_radius, scenario.earth_rate, scenario.gravity)
    else:
        f = np.array([0.0, 0.0, -scenario.gravity])
    values = {
        "latitude": scenario.latitude,
        "velocity_north": float(v[0]),
        "velocity_east": float(v[1]),
        "velocity_down": float(v[2]),
        "specific_force_north": float(f[0]),
        "specific_force_east": float(f[1]),
        "specific_force_down": float(f[2]),
        "earth_radius": scenario.earth_radius,
        "earth_rate": scenario.earth_rate,
    }
    for i in range(3):
        for j in range(3):
            values[f"c{i + 1}{j + 1}"] = float(scenario.attitude_matrix[i][j])
    return values


def _velocity(entry: dict, where: str) -> tuple[float, float, float]:
    vel = require(entry, "velocity_kmh", where)
    return tuple(to_si(require(vel, k, f"{where}.velocity_kmh"), "km/h", f"{where}.velocity_kmh.{k}") for k in ("north", "east", "down"))  # type: ignore[return-value]


def load_analysis_scenario(path: str | Path | None = None) -> AnalysisScenario:
    """Read a scenario file (default: the core paper's, ``scenario_000.yaml``)."""
    path = Path(path) if path is not None else data_path(SCENARIO_FILE)
    data = read_yaml(path)
    where = str(path)
    start = require(data, "start", where)
    earth = require(data, "earth", where)
    level = require(data, "level_flight", where)
    matrix = require(level, "attitude_matrix", f"{where}: level_flight")
    try:
        attitude = np.array(matrix, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(f"{where}: level_flight.attitude_matrix is not a 3x3 matrix of numbers") from None
    if attitude.shape != (3, 3):
        raise ModelError(f"{where}: level_flight.attitude_matrix must be 3x3, got shape {attitude.shape}")
    if not np.allclose(attitude @ attitude.T, np.eye(3), atol=1e-9) or np.linalg.det(attitude) < 0:
        raise ModelError(f"{where}: level_flight.attitude_matrix is not a rotation matrix")
    mode = level.get("specific_force", "kinematic")
    if mode not in SPECIFIC_FORCE_MODES:
        raise ModelError(f"{where}: level_flight.specific_force {mode!r} is not one of {SPECIFIC_FORCE_MODES}")
    phases = []
    for i, p in enumerate(require(data, "phases", where)):
        pw = f"{where}: phases[{i}]"
        phases.append(
            Phase(
                name=str(require(p, "name", pw)),
                start_s=to_si(require(p, "start_h", pw), "h", f"{pw}.start_h"),
                end_s=to_si(require(p, "end_h", pw), "h", f"{pw}.end_h"),
                manoeuvre=bool(p.get("manoeuvre", False)),
            )
        )
    step = to_si(require(data, "step_s", where), "s", f"{where}: step_s")
    duration = to_si(require(data, "duration_h", where), "h", f"{where}: duration_h")
    if not (0 < step < math.inf and 0 < duration < math.inf) or abs(duration / step - round(duration / step)) > 1e-9:
        raise ModelError(f"{where}: duration_h must be a positive whole number of steps step_s")
    return AnalysisScenario(
        name=str(require(data, "scenario", where)),
        latitude=to_si(require(start, "latitude_deg", f"{where}: start"), "deg", f"{where}: start.latitude_deg"),
        duration_s=duration,
        step_s=step,
        taylor_order=int(require(data, "taylor_order", where)),
        earth_radius=to_si(require(earth, "radius_m", f"{where}: earth"), "m", f"{where}: earth.radius_m"),
        earth_rate=to_si(require(earth, "rate_rad_s", f"{where}: earth"), "rad/s", f"{where}: earth.rate_rad_s"),
        gravity=to_si(require(earth, "gravity_m_s2", f"{where}: earth"), "m/s^2", f"{where}: earth.gravity_m_s2"),
        velocity_ned=_velocity(level, f"{where}: level_flight"),
        specific_force=mode,
        attitude_matrix=tuple(tuple(float(c) for c in row) for row in attitude),
        phases=tuple(phases),
    )
