"""Scenario files (modelgen/data/profile_*.yaml): flight profile, sensors, filter.

A scenario file is data: the flight profile (start state and segments), the IMU
error budget, initial errors, the aiding sensors and the filter set-up, every
number with its unit in its key name (``_deg``, ``_kmh``, ``_dph``...).  This
module turns it into SI dataclasses and refuses unknown keys, missing keys and
non-numbers with a message naming the file and the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any


from modelgen.fileio.datafiles import read_yaml_with_lines
from modelgen.errors import ModelError
from modelgen.simulation.doppler import DopplerSettings, JanusBeams, Outage
from modelgen.simulation.gps import Constellation, GpsSettings, PseudorangeSettings
from modelgen.simulation.imu import ImuErrorBudget
from modelgen.simulation.strapdown import ALGORITHMS, VerticalDamping
from modelgen.simulation.trajectory import FlightProfile, Segment

DEG = math.pi / 180.0
ARCSEC = DEG / 3600.0
ARCMIN = DEG / 60.0
HOUR = 3600.0
KMH = 1000.0 / 3600.0
DPH = DEG / HOUR  # deg/h -> rad/s

MODES = ("open_loop", "closed_loop", "accumulated")
STATE_ROLES = ("attitude", "velocity", "position", "gyro_constant", "gyro_markov", "accelerometer_constant",
               "accelerometer_markov", "doppler_bias")
AXES = {
    "attitude": ("north", "east", "down", "up"),
    "velocity": ("north", "east", "down", "up"),
    "position": ("latitude", "longitude", "height"),
    "gyro_constant": ("x", "y", "z"),
    "gyro_markov": ("x", "y", "z"),
    "accelerometer_constant": ("x", "y", "z"),
    "accelerometer_markov": ("x", "y", "z"),
    "doppler_bias": ("north", "east", "down", "up"),
}
SENSOR_QUANTITIES = ("velocity_north", "velocity_east", "velocity_down", "velocity_up", "latitude", "longitude",
                     "height", "position_north", "position_east")


@dataclass(frozen=True)
class InitialErrors:
    """rms initial errors: attitude about N, E, D [rad], velocity [m/s], position [m] per axis."""

    attitude: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity: float = 0.0
    position: float = 0.0


@dataclass(frozen=True)
class FilterSettings:
    model: str = "ned_doppler18"
    aiding: str = "doppler"
    period: float = 1.0
    mode: str = "closed_loop"
    gate_probability: float = 0.9999
    states: dict[str, dict[str, str]] = field(default_factory=dict)
    measurements: dict[str, dict[str, str]] = field(default_factory=dict)


@dataclass(frozen=True)
class Scenario:
    name: str
    title: str
    profile: FlightProfile
    imu_rate: float
    coning: str
    imu_budget: ImuErrorBudget
    initial_errors: InitialErrors
    altitude_noise: float
    vertical_damping: VerticalDamping
    doppler: DopplerSettings
    gps: GpsSettings
    filter: FilterSettings
    source_file: str = ""
    pseudorange: PseudorangeSettings = field(default_factory=PseudorangeSettings)  # aiding: pseudorange
    constellation: Constellation = field(default_factory=Constellation)

    @property
    def aiding_period(self) -> float:
        """Seconds between two measurements of the aiding sensor the filter uses."""
        return {"doppler": self.doppler.period, "gps": self.gps.period,
                "pseudorange": self.pseudorange.period}[self.filter.aiding]

    def with_changes(self, **changes: Any) -> "Scenario":
        """A copy with some fields replaced (``hours=`` truncates the flight)."""
        hours = changes.pop("hours", None)
        if hours is not None and not (math.isfinite(hours) and hours > 0):
            raise ModelError(f"--hours: must be a positive number of hours, got {hours:g}")
        if "imu_rate" in changes and not (math.isfinite(changes["imu_rate"]) and changes["imu_rate"] > 0):
            raise ModelError(f"--imu-rate: must be a positive rate in Hz, got {changes['imu_rate']:g}")
        out = replace(self, **changes)
        if hours is not None:
            out = replace(out, profile=out.profile.truncated(hours * HOUR))
        return out


class _Section:
    """Reads one mapping of the file, converting units and refusing what is unknown."""

    def __init__(self, data: Any, where: str, lines: dict[str, str] | None = None, path: str = ""):
        self.lines, self.path = lines or {}, path
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise ModelError(f"{self.lines.get(path, where)}: {path or where} must be a mapping, got {type(data).__name__}")
        self.data, self.where, self.used = data, where, set()

    def at(self, key: str) -> str:
        """Where ``key`` of this section is, for messages: ``file:line: doppler.period_s`` when the line is known."""
        full = f"{self.path}.{key}" if self.path else key
        line = self.lines.get(full)
        return f"{line}: {full}" if line else f"{self.where}.{key}"

    def number(
        self, key: str, default: float | None = None, scale: float = 1.0, positive: bool = False, non_negative: bool = False
    ) -> float:
        """A finite number (times ``scale``); ``positive``/``non_negative`` refuse periods, rates and sigmas that make no sense."""
        self.used.add(key)
        if key not in self.data:
            if default is None:
                raise ModelError(f"{self.lines.get(self.path, self.where)}: missing key {key!r}")
            return default
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            try:
                value = float(str(value))
            except ValueError:
                raise ModelError(f"{self.at(key)}: {value!r} is not a number") from None
        value = float(value)
        if not math.isfinite(value):
            raise ModelError(f"{self.at(key)}: {value!r} is not finite")
        if positive and not value > 0:
            raise ModelError(f"{self.at(key)}: must be positive, got {value:g}")
        if non_negative and value < 0:
            raise ModelError(f"{self.at(key)}: must not be negative, got {value:g}")
        return value * scale

    def text(self, key: str, default: str | None = None, choices: tuple[str, ...] = ()) -> str:
        self.used.add(key)
        if key not in self.data:
            if default is None:
                raise ModelError(f"{self.where}: missing key {key!r}")
            return default
        value = str(self.data[key])
        if choices and value not in choices:
            raise ModelError(f"{self.where}.{key}: {value!r} is not one of {', '.join(choices)}")
        return value

    def section(self, key: str) -> "_Section":
        self.used.add(key)
        return _Section(self.data.get(key), f"{self.where}.{key}", self.lines, f"{self.path}.{key}" if self.path else key)

    def raw(self, key: str, default: Any = None) -> Any:
        self.used.add(key)
        return self.data.get(key, default)

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise ModelError(f"{self.where}: unknown key {unknown[0]!r} (known: {', '.join(sorted(self.used))})")


def _duration(s: _Section) -> float:
    has_h, has_s = "duration_h" in s.data, "duration_s" in s.data
    if has_h == has_s:
        raise ModelError(f"{s.where}: give exactly one of duration_h, duration_s")
    value = s.number("duration_h", scale=HOUR) if has_h else s.number("duration_s")
    if value <= 0:
        raise ModelError(f"{s.where}: duration must be positive")
    return value


def _outages(s: _Section, key: str) -> tuple[Outage, ...]:
    raw = s.raw(key, []) or []
    if not isinstance(raw, list):
        raise ModelError(f"{s.where}.{key}: must be a list of {{start_s, end_s}}")
    out = []
    for i, item in enumerate(raw):
        o = _Section(item, f"{s.where}.{key}[{i}]")
        start, end = o.number("start_s"), o.number("end_s")
        o.done()
        if end <= start:
            raise ModelError(f"{o.where}: end_s must be after start_s")
        out.append(Outage(start, end))
    return tuple(out)


def _mapping(s: _Section, key: str, allowed: dict[str, tuple[str, ...]]) -> dict[str, dict[str, str]]:
    raw = s.raw(key, {}) or {}
    if not isinstance(raw, dict):
        raise ModelError(f"{s.where}.{key}: must be a mapping")
    out: dict[str, dict[str, str]] = {}
    for group, entries in raw.items():
        where = f"{s.where}.{key}.{group}"
        if group not in allowed:
            raise ModelError(f"{where}: unknown group {group!r} (known: {', '.join(allowed)})")
        if not isinstance(entries, dict):
            raise ModelError(f"{where}: must map model names to {', '.join(allowed[group])}")
        for name, axis in entries.items():
            if str(axis) not in allowed[group]:
                raise ModelError(f"{where}.{name}: {axis!r} is not one of {', '.join(allowed[group])}")
        out[str(group)] = {str(k): str(v) for k, v in entries.items()}
    return out


def _pseudorange(s: _Section) -> tuple[PseudorangeSettings, Constellation]:
    """The pseudo-range receiver (seed 003) and its constellation; defaults when the section is absent."""
    c = s.section("constellation")
    constellation = Constellation(
        satellites=int(c.number("satellites", 24.0)),
        planes=int(c.number("planes", 6.0)),
        phasing=int(c.number("phasing", 1.0)),
        inclination=c.number("inclination_deg", 55.0 * DEG, DEG),  # defaults are SI
        radius=c.number("orbit_radius_m", 26_559_700.0),
    )
    c.done()
    if constellation.satellites < 1 or constellation.planes < 1 or constellation.satellites % constellation.planes:
        raise ModelError(f"{c.where}: {constellation.satellites} satellites do not fill {constellation.planes} planes")
    settings = PseudorangeSettings(
        period=s.number("period_s", 1.0, positive=True),
        noise=s.number("noise_m", 3.0),
        clock_bias=s.number("clock_bias_m", 3.0e4),
        clock_drift=s.number("clock_drift_mps", 3.0),
        clock_bias_psd=s.number("clock_bias_psd_m2ps", 0.1),
        clock_drift_psd=s.number("clock_drift_psd_m2ps3", 0.01),
        elevation_mask=s.number("elevation_mask_deg", 10.0 * DEG, DEG),
    )
    s.done()
    if not settings.period > 0:
        raise ModelError(f"{s.where}.period_s: must be positive, got {settings.period}")
    for key, value in (("noise_m", settings.noise), ("clock_bias_m", settings.clock_bias), ("clock_drift_mps", settings.clock_drift),
                       ("clock_bias_psd_m2ps", settings.clock_bias_psd), ("clock_drift_psd_m2ps3", settings.clock_drift_psd)):
        if value < 0:
            raise ModelError(f"{s.where}.{key}: must not be negative, got {value}")
    if not 0 <= settings.elevation_mask < math.pi / 2:
        raise ModelError(f"{s.where}.elevation_mask_deg: must be in [0, 90)")
    return settings, constellation


def load_scenario_data(data: Any, filename: str, lines: dict[str, str] | None = None) -> Scenario:
    """Build a :class:`Scenario` from parsed YAML (see the module docstring); ``lines`` locates keys for messages."""
    top = _Section(data, filename, lines)
    name = top.text("profile")
    title = top.text("title", "")
    top.text("source", "")

    start = top.section("start")
    segments = []
    raw_segments = top.raw("segments")
    if not isinstance(raw_segments, list) or not raw_segments:
        raise ModelError(f"{filename}: 'segments' must be a non-empty list")
    for i, raw in enumerate(raw_segments):
        s = _Section(raw, f"{filename}: segments[{i}]", lines, f"segments[{i}]")
        segments.append(Segment(
            name=s.text("name", f"segment {i + 1}"),
            duration=_duration(s),
            horizontal_acceleration=s.number("horizontal_acceleration_mps2", 0.0),
            turn_rate=s.number("turn_rate_dps", 0.0, DEG),
            vertical_acceleration=s.number("vertical_acceleration_mps2", 0.0),
            roll_rate=s.number("roll_rate_dps", 0.0, DEG),
        ))
        s.done()
    profile = FlightProfile(
        name=name,
        latitude=start.number("latitude_deg", scale=DEG),
        longitude=start.number("longitude_deg", scale=DEG),
        height=start.number("height_m", 0.0),
        ground_speed=start.number("ground_speed_kmh", scale=KMH),
        heading=start.number("heading_deg", scale=DEG),
        velocity_down=start.number("velocity_down_kmh", 0.0, KMH),
        roll=start.number("roll_deg", 0.0, DEG),
        segments=tuple(segments),
    )
    start.done()

    imu = top.section("imu")
    g = imu.number("g_mps2", 9.80665)
    imu_rate = imu.number("rate_hz", positive=True)
    coning = imu.text("coning", "two", tuple(ALGORITHMS))
    budget = ImuErrorBudget(
        gyro_constant_drift=imu.number("gyro_constant_drift_dph", 0.0, DPH),
        gyro_markov_drift=imu.number("gyro_markov_drift_dph", 0.0, DPH),
        gyro_markov_correlation_time=imu.number("gyro_markov_correlation_time_h", math.inf, HOUR, positive=True),
        gyro_white_noise=imu.number("gyro_white_noise_dpsh", 0.0, DEG / math.sqrt(HOUR), non_negative=True),
        gyro_scale_factor=imu.number("gyro_scale_factor_ppm", 0.0, 1e-6),
        accel_constant_bias=imu.number("accelerometer_constant_bias_g", 0.0, g),
        accel_markov_bias=imu.number("accelerometer_markov_bias_g", 0.0, g),
        accel_markov_correlation_time=imu.number("accelerometer_markov_correlation_time_h", math.inf, HOUR, positive=True),
        accel_white_noise=imu.number("accelerometer_white_noise_mps_per_sqrt_h", 0.0, 1.0 / math.sqrt(HOUR), non_negative=True),
        accel_scale_factor=imu.number("accelerometer_scale_factor_ppm", 0.0, 1e-6),
    )
    imu.done()

    ie = top.section("initial_errors")
    initial = InitialErrors(
        attitude=(ie.number("attitude_north_arcsec", 0.0, ARCSEC), ie.number("attitude_east_arcsec", 0.0, ARCSEC),
                  ie.number("heading_arcmin", 0.0, ARCMIN)),
        velocity=ie.number("velocity_mps", 0.0),
        position=ie.number("position_m", 0.0),
    )
    ie.done()

    alt = top.section("altitude_reference")
    altitude_noise = alt.number("noise_m", 0.0, non_negative=True)
    tau = alt.number("loop_time_constant_s", 100.0)
    if tau <= 0:
        raise ModelError(f"{alt.where}.loop_time_constant_s: must be positive")
    damped = alt.text("vertical_channel", "damped", ("damped", "free"))
    damping = VerticalDamping(k1=2 * 0.707 / tau, k2=1.0 / tau**2) if damped == "damped" else VerticalDamping(0.0, 0.0)
    alt.done()

    dop = top.section("doppler")
    beams = dop.section("beams")
    configuration = beams.text("configuration", "janus4", ("janus4",))
    janus = JanusBeams(
        azimuth=beams.number("azimuth_deg", 45.0, DEG),
        depression=beams.number("depression_deg", 65.0, DEG),
        wavelength=beams.number("wavelength_m", 0.0225, positive=True),
        frequency_noise=beams.number("frequency_noise_hz", 10.0, non_negative=True),
        frequency_bias=beams.number("frequency_bias_hz", 0.0),
        mounting_error=beams.number("mounting_error_arcmin", 0.0, ARCMIN),
    )
    del configuration
    beams.done()
    doppler = DopplerSettings(
        period=dop.number("period_s", 60.0, positive=True),
        measurement=dop.text("measurement", "ned", ("ned", "beams")),
        bias=dop.number("bias_kmh", 0.0, KMH),
        white_noise=dop.number("white_noise_mps", 0.0, non_negative=True),
        beams=janus,
        outages=_outages(dop, "outages"),
    )
    dop.done()

    gp = top.section("gps")
    gps = GpsSettings(
        period=gp.number("period_s", 1.0, positive=True),
        position_noise=gp.number("position_noise_m", 5.0, non_negative=True),
        height_noise=gp.number("height_noise_m", 8.0, non_negative=True),
        velocity_noise=gp.number("velocity_noise_mps", 0.05, non_negative=True),
        outages=_outages(gp, "outages"),
    )
    gp.done()

    pseudorange, constellation = _pseudorange(top.section("pseudorange"))

    fi = top.section("filter")
    filt = FilterSettings(
        model=fi.text("model"),
        aiding=fi.text("aiding", "doppler", ("doppler", "gps", "pseudorange")),
        period=fi.number("period_s", 1.0, positive=True),
        mode=fi.text("mode", "closed_loop", MODES),
        gate_probability=fi.number("gate_probability", 0.9999),
        states=_mapping(fi, "states", {k: AXES[k] for k in STATE_ROLES}),
        measurements=_mapping(fi, "measurements", {"doppler": SENSOR_QUANTITIES, "gps": SENSOR_QUANTITIES}),
    )
    if not 0 <= filt.gate_probability < 1:
        raise ModelError(f"{fi.where}.gate_probability: must be in [0, 1)")
    fi.done()
    top.done()
    return Scenario(name, title, profile, imu_rate, coning, budget, initial, altitude_noise, damping, doppler, gps,
                    filt, filename, pseudorange, constellation)


def builtin_scenarios() -> list[str]:
    folder = resources.files("modelgen") / "data"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.startswith("profile_") and p.name.endswith(".yaml"))


def load_scenario(path: str | Path) -> Scenario:
    """Load a scenario file, or a built-in one by name (``profile_000``)."""
    p = Path(path)
    if not p.exists() and p.suffix == "":
        candidate = resources.files("modelgen") / "data" / f"{p.name}.yaml"
        if candidate.is_file():
            p = Path(str(candidate))
    if not p.exists():
        raise ModelError(f"{path}: no such scenario file, and not a built-in one ({', '.join(builtin_scenarios())})")
    data, lines = read_yaml_with_lines(p, "scenario file")
    return load_scenario_data(data, str(p), lines)
