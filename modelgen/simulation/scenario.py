"""Flight profiles (modelgen/data/profile_*.yaml): the flight, the IMU, the aiding sensor, the filter.

A flight-profile file is data: the flight path (start state and segments),
the IMU error budget, initial errors, the aiding sensors' sections and the
filter set-up, every number with its unit in its key name (``_deg``,
``_kmh``, ``_dph``...).  :func:`load_profile` turns it into a
:class:`FlightProfile` (SI dataclasses) and refuses unknown keys, missing keys
and non-numbers with a message naming the file and the key.  Each aiding
sensor reads its own section (:mod:`modelgen.simulation.sensors`): the
sections and ``filter.aiding`` names this loader accepts are the registry's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path, read_yaml_with_lines
from modelgen.simulation.aiding import AidingSensor
from modelgen.simulation.imu import ImuErrorBudget
from modelgen.simulation.profile_keys import ARCMIN, ARCSEC, DEG, DPH, HOUR, KMH, ProfileSection, check_flight_size
from modelgen.simulation.sensors import SENSORS
from modelgen.simulation.strapdown import ALGORITHMS, VerticalDamping
from modelgen.simulation.trajectory import FlightPath, Segment

__all__ = ["ARCMIN", "ARCSEC", "DEG", "DPH", "HOUR", "KMH", "FilterSettings", "FlightProfile", "InitialErrors",
           "builtin_profiles", "load_profile", "load_profile_data"]

MODES = ("open_loop", "closed_loop", "accumulated")
NED_AXES = ("north", "east", "down", "up")
AXES = {
    "attitude": NED_AXES,
    "velocity": NED_AXES,
    "position": ("latitude", "longitude", "height"),
    "gyro_constant": ("x", "y", "z"),
    "gyro_markov": ("x", "y", "z"),
    "accelerometer_constant": ("x", "y", "z"),
    "accelerometer_markov": ("x", "y", "z"),
}


@dataclass(frozen=True)
class InitialErrors:
    """rms initial errors: attitude about N, E, D [rad], velocity [m/s], position [m] per axis."""

    attitude: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity: float = 0.0
    position: float = 0.0


@dataclass(frozen=True)
class FilterSettings:
    """The filter's model, its aiding sensor (a registry name), cycle, correction mode, gate and state mapping."""

    model: str = "ned_doppler18"
    aiding: str = "doppler"
    period: float = 1.0
    mode: str = "closed_loop"
    gate_probability: float = 0.9999
    states: dict[str, dict[str, str]] = field(default_factory=dict)
    measurements: dict[str, dict[str, str]] = field(default_factory=dict)
    #: ``filter.parameters``: model parameters the simulation does not compute, held at these values
    parameters: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class FlightProfile:
    """One flight-profile file: the flight path, the IMU, every registered sensor's settings, the filter."""

    name: str
    title: str
    path: FlightPath
    imu_rate: float
    coning: str
    imu_budget: ImuErrorBudget
    initial_errors: InitialErrors
    altitude_noise: float
    vertical_damping: VerticalDamping
    filter: FilterSettings
    sensors: Mapping[str, Any]  # registry name -> that sensor's settings (defaults when its section is absent)
    source_file: str = ""

    @property
    def aiding_sensor(self) -> AidingSensor:
        """The plug-in of the sensor the filter uses (``filter.aiding``)."""
        return SENSORS[self.filter.aiding]

    @property
    def aiding_settings(self) -> Any:
        """The settings of the sensor the filter uses."""
        return self.sensors[self.filter.aiding]

    @property
    def aiding_period(self) -> float:
        """Seconds between two measurements of the aiding sensor the filter uses."""
        return self.aiding_sensor.period(self.aiding_settings)

    def noise_parameters(self) -> dict[str, float]:
        """Every sensor's noise as model parameter values (a model picks the names it has); where two
        sensors set the same name, the aiding sensor's value holds."""
        out: dict[str, float] = {}
        for name, settings in self.sensors.items():
            if name != self.filter.aiding:
                out.update(SENSORS[name].noise_parameters(settings))
        out.update(self.aiding_sensor.noise_parameters(self.aiding_settings))
        return out

    def constant_parameters(self) -> dict[str, float]:
        """The model parameter values held for the whole flight: every sensor's noise, then the
        filter's own ``parameters`` (which hold over the noise of the same name)."""
        return {**self.noise_parameters(), **self.filter.parameters}

    def with_sensor(self, name: str, settings: Any) -> "FlightProfile":
        """A copy with one sensor's settings replaced."""
        return replace(self, sensors={**self.sensors, name: settings})

    def with_changes(self, **changes: Any) -> "FlightProfile":
        """A copy with some fields replaced (``hours=`` truncates the flight, ``model=`` names another filter model)."""
        hours = changes.pop("hours", None)
        if hours is not None and not (math.isfinite(hours) and hours > 0):
            raise ModelError(f"--hours: must be a positive number of hours, got {hours:g}")
        if "imu_rate" in changes and not (math.isfinite(changes["imu_rate"]) and changes["imu_rate"] > 0):
            raise ModelError(f"--imu-rate: must be a positive rate in Hz, got {changes['imu_rate']:g}")
        model = changes.pop("model", None)
        out = replace(self, **changes)
        if model is not None:
            out = replace(out, filter=replace(out.filter, model=str(model)))
        if hours is not None:
            out = replace(out, path=out.path.truncated(hours * HOUR))
        check_flight_size(out.path.duration / HOUR, out.imu_rate,
                          "--hours" if hours is not None else f"{self.source_file}: segments",
                          "--imu-rate" if "imu_rate" in changes else f"{self.source_file}: imu.rate_hz")
        return out


def _duration(s: ProfileSection) -> float:
    """A segment's duration from exactly one of duration_h, duration_s."""
    has_h, has_s = "duration_h" in s.data, "duration_s" in s.data
    if has_h == has_s:
        raise ModelError(f"{s.where}: give exactly one of duration_h, duration_s")
    value = s.number("duration_h", scale=HOUR) if has_h else s.number("duration_s")
    if value <= 0:
        raise ModelError(f"{s.where}: duration must be positive")
    return value


def _mapping(s: ProfileSection, key: str, allowed: dict[str, tuple[str, ...]]) -> dict[str, dict[str, str]]:
    """``filter.states`` / ``filter.measurements``: group -> {model name: axis or quantity}, checked against ``allowed``."""
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


def _constants(section: ProfileSection) -> dict[str, float]:
    """``filter.parameters``: model parameter name -> a finite number, held for the whole flight."""
    return {str(name): section.number(str(name)) for name in section.data}


def load_profile_data(data: Any, filename: str, lines: dict[str, str] | None = None) -> FlightProfile:
    """Build a :class:`FlightProfile` from parsed YAML (module docstring); ``lines`` locates keys for messages."""
    top = ProfileSection(data, filename, lines)
    name = top.text("profile")
    title = top.text("title", "")
    top.text("source", "")

    start = top.section("start")
    segments = []
    raw_segments = top.raw("segments")
    if not isinstance(raw_segments, list) or not raw_segments:
        raise ModelError(f"{filename}: 'segments' must be a non-empty list")
    for i, raw in enumerate(raw_segments):
        s = ProfileSection(raw, f"{filename}: segments[{i}]", lines, f"segments[{i}]")
        segments.append(Segment(
            name=s.text("name", f"segment {i + 1}"),
            duration=_duration(s),
            horizontal_acceleration=s.number("horizontal_acceleration_mps2", 0.0),
            turn_rate=s.number("turn_rate_dps", 0.0, DEG),
            vertical_acceleration=s.number("vertical_acceleration_mps2", 0.0),
            roll_rate=s.number("roll_rate_dps", 0.0, DEG),
        ))
        s.done()
    latitude = start.number("latitude_deg", scale=DEG)
    if not abs(latitude) < math.pi / 2:  # 100 deg is no latitude; at +-90 the north and east axes are undefined
        raise ModelError(f"{start.at('latitude_deg')}: latitude {latitude / DEG:g} deg is not between -90 and 90 deg "
                         "(the poles themselves are excluded: the NED axes and tan(latitude) are undefined there)")
    path = FlightPath(
        name=name,
        latitude=latitude,
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
    check_flight_size(path.duration / HOUR, imu_rate, f"{filename}: segments", imu.at("rate_hz"))
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

    sensors = {sensor_name: sensor.read_settings(top.section(sensor_name)) for sensor_name, sensor in SENSORS.items()}

    fi = top.section("filter")
    filt = FilterSettings(
        model=fi.text("model"),
        aiding=fi.text("aiding", "doppler", tuple(SENSORS)),
        period=fi.number("period_s", 1.0, positive=True),
        mode=fi.text("mode", "closed_loop", MODES),
        gate_probability=fi.number("gate_probability", 0.9999),
        states=_mapping(fi, "states", state_roles()),
        measurements=_mapping(fi, "measurements", {n: s.quantities for n, s in SENSORS.items() if s.quantities}),
        parameters=_constants(fi.section("parameters")),
    )
    if not 0 <= filt.gate_probability < 1:
        raise ModelError(f"{fi.where}.gate_probability: must be in [0, 1)")
    fi.done()
    top.done()
    return FlightProfile(name, title, path, imu_rate, coning, budget, initial, altitude_noise, damping, filt, sensors,
                         filename)


def state_roles() -> dict[str, tuple[str, ...]]:
    """The groups ``filter.states`` may name, with their axes: navigation and IMU errors, and each
    registered sensor's own bias group (NED axes)."""
    roles = dict(AXES)
    for sensor in SENSORS.values():
        group = getattr(sensor, "bias_group", None)
        if group:
            roles[group] = NED_AXES
    return roles


def builtin_profiles() -> list[str]:
    """Names of the flight profiles shipped in modelgen/data (``profile_000``...)."""
    folder = data_path()
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.startswith("profile_") and p.name.endswith(".yaml"))


def load_profile(path: str | Path) -> FlightProfile:
    """Load a flight-profile file, or a built-in one by name (``profile_000``)."""
    p = Path(path)
    if not p.is_file() and p.suffix == "":
        candidate = data_path(f"{p.name}.yaml")
        if candidate.is_file():
            p = candidate
    if not p.exists():
        raise ModelError(f"{path}: no such scenario file, and not a built-in one ({', '.join(builtin_profiles())})")
    data, lines = read_yaml_with_lines(p, "scenario file")
    return load_profile_data(data, str(p), lines)
