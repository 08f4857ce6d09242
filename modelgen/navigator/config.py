"""The navigator configuration (YAML): logs, mounting, noise in data-sheet units, switches.

A configuration is untrusted data: it is read with ``yaml.safe_load``
semantics (no tags, nothing runs), every key is checked against the schema
below, and every refusal names the file and line.  Noise densities are given
in the units of the data sheet (``deg/s/sqrt(Hz)``, ``ug/sqrt(Hz)``,
``deg/sqrt(h)`` ...) together with an explicit multiplying ``factor``; the
SI value the filter uses is ``value * unit * factor``, and the report prints
all three.  See ``modelgen/data/replay_drive_0708.yaml`` for a complete,
commented example.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path
from modelgen.navigator.config_bases import closest_key, origin_of, read_config_with_bases
from modelgen.navigator.config_schema import key_sets, validate
from modelgen.navigator.logs import GAP_ACTIONS, STANDARD_GRAVITY, ImuColumns, LogSource, source_from_config
from modelgen.navigator.logs.imu_csv import columns_of

DEG = math.pi / 180.0
MICRO_G = 1e-6 * STANDARD_GRAVITY

# Accepted units of each noise density, as the factor to the SI unit the model uses.
NOISE_UNITS: dict[str, dict[str, float]] = {
    # gyro white noise (angle random walk) -> rad/sqrt(s)
    "gyro_white": {"rad/sqrt(s)": 1.0, "rad/s/sqrt(Hz)": 1.0, "deg/s/sqrt(Hz)": DEG,
                   "deg/sqrt(h)": DEG / 60.0, "deg/h/sqrt(Hz)": DEG / 3600.0},
    # accelerometer white noise (velocity random walk) -> m/s/sqrt(s)
    "accel_white": {"m/s/sqrt(s)": 1.0, "m/s^2/sqrt(Hz)": 1.0, "ug/sqrt(Hz)": MICRO_G,
                    "mg/sqrt(Hz)": 1e3 * MICRO_G, "m/s/sqrt(h)": 1.0 / 60.0},
    # gyro bias random-walk driving noise -> rad/s/sqrt(s)
    "gyro_bias_driving": {"rad/s/sqrt(s)": 1.0, "rad/s^2/sqrt(Hz)": 1.0, "deg/s^2/sqrt(Hz)": DEG,
                          "deg/h/sqrt(s)": DEG / 3600.0},
    # accelerometer bias random-walk driving noise -> m/s^2/sqrt(s)
    "accel_bias_driving": {"m/s^2/sqrt(s)": 1.0, "m/s^3/sqrt(Hz)": 1.0, "ug/s/sqrt(Hz)": MICRO_G,
                           "ug/sqrt(Hz)": MICRO_G},
}

#: Every mapping's known keys by dotted path, from the JSON schema (modelgen/data/replay_config.schema.json), which
#: lists every key once with its type, unit, default and meaning (modelgen.navigator.config_schema).
SCHEMA: dict[str, set[str]] = key_sets()


@dataclass(frozen=True)
class NoiseEntry:
    """One noise density: data-sheet value and unit, the stated factor, and the SI result."""

    value: float
    unit: str
    factor: float
    si: float
    why: str


@dataclass(frozen=True)
class NavigatorConfig:
    """Everything the navigator needs, validated and in SI units (angles in radians)."""

    path: str
    name: str
    model: str
    imu_file: Path
    imu_columns: ImuColumns | None  # the csv format's column map (None for other formats)
    time_offset: float
    gap_factor: float
    rotation_to_body: tuple[float, float, float]  # roll, pitch, yaw [rad]
    gnss_file: Path
    lever_arm: tuple[float, float, float]  # IMU to antenna, body axes [m]
    velocity_latency: float  # GNSS velocity is the velocity this long before its epoch [s]
    quality_factor: dict[int, float]
    minimum_sigma_position: float
    minimum_sigma_velocity: float
    noise: dict[str, NoiseEntry]
    roll_pitch_sigma: float
    heading_extra_sigma: float
    velocity_sigma: float
    position_sigma: float
    height_sigma: float
    gyro_bias_sigma: float
    accel_bias_sigma: float
    rest_speed: float
    rest_window: float
    heading_speed: float
    predict_period: float
    nis_gate_probability: float
    gate_action: str  # "reject" or "deweight" an update above the gate
    gate_release_epochs: int
    zupt_enabled: bool
    zupt_window: float
    zupt_gyro_max: float
    zupt_accel_std_max: float
    zupt_speed_max: float
    zupt_sigma: float
    nhc_enabled: bool
    nhc_sigma_lateral: float
    nhc_sigma_vertical: float
    nhc_speed_min: float
    nhc_rate_max: float  # NHC only while the bias-corrected angular rate is below this [rad/s]
    outage_schedule: dict[str, float] | None
    outage_windows: list[tuple[float, float]] | None
    imu_source: LogSource | None = None  # the imu: section as the log readers take it (format, file, options)
    gnss_source: LogSource | None = None
    gap_action: str = "refuse"  # imu.gap_action: refuse a log with an IMU gap, or propagate across it
    #: nhc.lever_arm_m: IMU to the point the constraint holds at (the rear axle's centre on the ground), body axes [m]
    nhc_lever_arm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: the alignment's still detector and shortest usable rest window (modelgen.navigator.alignment)
    still_window: float = 0.5  # alignment.still_window_s [s]
    still_gyro_std_max: float = 1.0 * DEG  # alignment.gyro_std_max_deg_s [rad/s]
    still_accel_std_max: float = 0.2  # alignment.accel_std_max_m_s2 [m/s^2]
    rest_min: float = 2.0  # alignment.rest_min_s [s]
    #: evaluation.schedules: further outage schedules flown on the same log for the consistency statistics
    evaluation_schedules: tuple[EvaluationSchedule, ...] = ()
    target_end_rms_m: float | None = None  # evaluation.target_end_rms_m: for the configured schedule
    target_nees_mean: tuple[float, float] | None = None  # pooled over all schedules
    target_inside_95_fraction: float | None = None  # pooled over all schedules
    #: replay --smooth, configured schedule: horizontal RMS over every outage epoch, and each outage's maximum [m]
    target_smoothed_outage_rms_m: float | None = None
    target_smoothed_outage_max_m: float | None = None


    #: initial.gyro/accel_scale_factor_sigma_ppm (as a fraction; used only by models with scale-factor states)
    gyro_scale_factor_sigma: float | None = None
    accel_scale_factor_sigma: float | None = None
    #: parameters: model parameters the navigator does not set, by name, in the model's units
    parameters: dict[str, float] = field(default_factory=dict)
    #: output.folder: the report folder when the command line gives none (relative paths from the configuration's
    #: folder), or None
    output_folder: Path | None = None
    #: the aiding sensors' own logs by section (odometer, barometer): enabled, file, columns, unit, sigma, lever arm
    aiding: dict[str, AidingSettings] = field(default_factory=dict)
    #: gnss.position/velocity_variance_factor: R x factor on the GNSS position and velocity rows (errors correlated
    #: over several epochs; modelgen.navigator.tuning measures the factor from the innovations with GNSS present)
    gnss_position_variance_factor: float = 1.0
    gnss_velocity_variance_factor: float = 1.0
    #: tuning: dotted key -> how its value was obtained (printed in the summary)
    tuning: dict[str, str] = field(default_factory=dict)
    #: dotted key -> 'file:line' that gave it (a base's line for a value inherited through extends:)
    key_lines: dict[str, str] = field(default_factory=dict, repr=False, compare=False)

    def where(self, key: str) -> str:
        """'file:line' of a key path (or its closest enclosing key), or the configuration file."""
        return _Reader(Path(self.path), {}, self.key_lines).where(key)

    def origin(self, key: str) -> Path:
        """The configuration file that gives ``key`` (a base's, for a value inherited through extends:)."""
        return origin_of(self.key_lines, key, Path(self.path))

    @property
    def rest_span_min(self) -> float:
        """The shortest still span the alignment levels from [s]: rest_min, but never more than the rest window
        itself (a 1-s rest window cannot hold 2 s of still data; asking for it would refuse every log)."""
        return min(self.rest_min, self.rest_window)


@dataclass(frozen=True)
class AidingSettings:
    """An aiding sensor's own log and noise (the odometer: and barometer: sections; modelgen.navigator.sensors)."""

    section: str
    enabled: bool
    file: Path | None
    time_column: int = 1
    value_column: int = 2
    unit: str = ""
    time_offset: float = 0.0  # added to the log's time stamps [s]
    sigma: float = 1.0  # [m/s] or [m]
    lever_arm: tuple[float, float, float] | None = None  # odometer: IMU to the wheel contact, body axes [m]


@dataclass(frozen=True)
class EvaluationSchedule:
    """One further outage schedule of ``evaluation.schedules`` (a schedule or windows) and its optional target."""

    name: str
    schedule: dict[str, float] | None
    windows: list[tuple[float, float]] | None
    target_end_rms_m: float | None = None


class _Reader:
    """Typed access to the loaded mapping, every error naming file:line and key."""

    def __init__(self, path: Path, data: dict[str, Any], lines: dict[str, str]):
        self.path, self.data, self.lines = path, data, lines

    def where(self, key: str) -> str:
        """'file:line' of a key path, or of the closest enclosing key that has a line, else the file's first line
        (a top-level key that neither the file nor any base gives)."""
        probe = closest_key(self.lines, key)
        return self.lines[probe] if probe else f"{self.path}:1"

    def get(self, key: str, default: Any = ...) -> Any:
        """The raw value at a key path; ModelError if missing and no default."""
        node: Any = self.data
        for part in key.split("."):
            if not isinstance(node, dict) or part not in node:
                if default is ...:
                    raise ModelError(f"{self.where(key)}: missing key {key!r}")
                return default
            node = node[part]
        return node

    def number(self, key: str, default: Any = ..., positive: bool = False, non_negative: bool = False) -> float:
        """A finite float at a key path (optionally > 0 or >= 0)."""
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ModelError(f"{self.where(key)}: {key} must be a finite number, got {value!r}")
        if positive and value <= 0:
            raise ModelError(f"{self.where(key)}: {key} must be positive, got {value!r}")
        if non_negative and value < 0:
            raise ModelError(f"{self.where(key)}: {key} must not be negative, got {value!r}")
        return float(value)

    def integer(self, key: str, default: Any = ..., minimum: int = 0) -> int:
        """An int at a key path, at least ``minimum``."""
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise ModelError(f"{self.where(key)}: {key} must be an integer >= {minimum}, got {value!r}")
        return value

    def flag(self, key: str, default: Any = ...) -> bool:
        """A boolean at a key path."""
        value = self.get(key, default)
        if not isinstance(value, bool):
            raise ModelError(f"{self.where(key)}: {key} must be true or false, got {value!r}")
        return value

    def text(self, key: str, default: Any = ...) -> str:
        """A string at a key path."""
        value = self.get(key, default)
        if not isinstance(value, str):
            raise ModelError(f"{self.where(key)}: {key} must be text, got {value!r}")
        return value

    def vector(self, key: str, length: int) -> tuple[float, ...]:
        """A list of ``length`` finite numbers."""
        value = self.get(key)
        if (not isinstance(value, list) or len(value) != length
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
            raise ModelError(f"{self.where(key)}: {key} must be a list of {length} finite numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def lever_arm(self, key: str) -> tuple[float, float, float]:
        """A lever arm (3 finite numbers, body axes [m]) at a key path; (0, 0, 0) when absent: no lever-arm term."""
        if self.get(key, None) is None:
            return (0.0, 0.0, 0.0)
        return self.vector(key, 3)  # type: ignore[return-value]

    def folder(self, key: str) -> Path:
        """The folder relative paths at ``key`` start from: that of the file that wrote it (a base's, if inherited)."""
        return origin_of(self.lines, key, self.path).parent

    def file(self, key: str) -> Path:
        """A data file path, relative to the folder of the configuration that gives it; it must exist."""
        name = self.text(key)
        path = (self.folder(key) / name) if not Path(name).is_absolute() else Path(name)
        if not path.is_file():
            raise ModelError(f"{self.where(key)}: {key}: no such file {str(path)!r}")
        return path


def _check_keys(reader: _Reader) -> None:
    """Refuse any key the schema does not know, naming it and its line."""
    def walk(node: Any, prefix: str) -> None:
        if prefix not in SCHEMA:
            return
        if not isinstance(node, dict):
            raise ModelError(f"{reader.where(prefix)}: {prefix or 'the file'} must be a mapping")
        for key, value in node.items():
            path = f"{prefix}.{key}" if prefix else str(key)
            if key not in SCHEMA[prefix]:
                known = ", ".join(sorted(SCHEMA[prefix]))
                raise ModelError(f"{reader.where(path)}: unknown key {key!r} in {prefix or 'the configuration'} "
                                 f"(known: {known})")
            walk(value, path)
    walk(reader.data, "")


def _noise(reader: _Reader, kind: str) -> NoiseEntry:
    """One noise density converted to SI with its stated factor."""
    key = f"noise.{kind}"
    unit = reader.text(f"{key}.unit")
    if unit not in NOISE_UNITS[kind]:
        raise ModelError(f"{reader.where(key + '.unit')}: {key}.unit {unit!r} cannot be parsed "
                         f"(accepted: {', '.join(NOISE_UNITS[kind])})")
    value = reader.number(f"{key}.value", positive=True)
    factor = reader.number(f"{key}.factor", positive=True)
    return NoiseEntry(value, unit, factor, value * NOISE_UNITS[kind][unit] * factor, reader.text(f"{key}.why", ""))


def _outages(reader: _Reader, key: str = "outages",
             raw: Any = ...) -> tuple[dict[str, float] | None, list[tuple[float, float]] | None]:
    """Either a schedule (first_after_s, length_s, period_s, end_margin_s) or a list of windows, or none."""
    if raw is ...:
        raw = reader.get(key, None)
    if raw is None:
        return None, None
    if not isinstance(raw, dict):
        raise ModelError(f"{reader.where(key)}: {key} must be a mapping")
    if "windows" in raw:
        if set(raw) != {"windows"}:
            raise ModelError(f"{reader.where(key)}: {key}: give either windows or a schedule, not both")
        windows = raw["windows"]
        if not isinstance(windows, list):
            raise ModelError(f"{reader.where(key)}: {key}.windows must be a list of [start_s, length_s]")
        out = []
        for item in windows:
            if (not isinstance(item, list) or len(item) != 2
                    or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in item)
                    or item[1] <= 0):
                raise ModelError(f"{reader.where(key)}: each outage window is [start_s, length_s > 0], "
                                 f"got {item!r}")
            out.append((float(item[0]), float(item[1])))
        return None, out
    names = ("first_after_s", "length_s", "period_s", "end_margin_s")
    unknown = sorted(set(raw) - set(names))
    if unknown:
        raise ModelError(f"{reader.where(key)}: unknown key {unknown[0]!r} in {key} (known: {', '.join(names)}, windows)")
    schedule = {}
    for k in names:
        value = raw.get(k)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0 \
                or (value == 0 and k in ("length_s", "period_s")):
            raise ModelError(f"{reader.where(key)}: {key}.{k} must be a "
                             f"{'positive' if k in ('length_s', 'period_s') else 'non-negative'} number, got {value!r}")
        schedule[k] = float(value)
    if schedule["length_s"] >= schedule["period_s"]:
        raise ModelError(f"{reader.where(key)}: {key}.length_s must be shorter than period_s")
    return schedule, None


def _evaluation(reader: _Reader) -> dict[str, Any]:
    """evaluation: further schedules (each a name, a schedule or windows, an optional target) and the targets."""
    raw = reader.get("evaluation", None)
    if raw is None:
        return {}
    entries = reader.get("evaluation.schedules", [])
    if not isinstance(entries, list):
        raise ModelError(f"{reader.where('evaluation.schedules')}: evaluation.schedules must be a list of schedules")
    schedules = []
    for index, entry in enumerate(entries):
        key = f"evaluation.schedules[{index}]"
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str) or not entry["name"]:
            raise ModelError(f"{reader.where('evaluation.schedules')}: {key} must be a mapping with a name")
        target = entry.get("target_end_rms_m")
        if target is not None and (isinstance(target, bool) or not isinstance(target, (int, float))
                                   or not math.isfinite(target) or target <= 0):
            raise ModelError(f"{reader.where('evaluation.schedules')}: {key}.target_end_rms_m must be a positive "
                             f"number, got {target!r}")
        rest = {k: v for k, v in entry.items() if k not in ("name", "target_end_rms_m")}
        schedule, windows = _outages(reader, "evaluation.schedules", rest)
        if schedule is None and windows is None:
            raise ModelError(f"{reader.where('evaluation.schedules')}: {key} ({entry['name']!r}) gives no outages")
        schedules.append(EvaluationSchedule(entry["name"], schedule, windows,
                                            float(target) if target is not None else None))
    names = [s.name for s in schedules]
    if len(set(names)) != len(names):
        raise ModelError(f"{reader.where('evaluation.schedules')}: evaluation.schedules: names must differ")
    nees = reader.get("evaluation.target_nees_mean", None)
    if nees is not None:
        low, high = reader.vector("evaluation.target_nees_mean", 2)
        if not 0 <= low < high:
            raise ModelError(f"{reader.where('evaluation.target_nees_mean')}: evaluation.target_nees_mean must be "
                             f"[low, high] with 0 <= low < high, got {nees!r}")
        nees = (low, high)
    inside = reader.get("evaluation.target_inside_95_fraction", None)
    if inside is not None:
        inside = _probability(reader, "evaluation.target_inside_95_fraction")
    rms = reader.get("evaluation.target_end_rms_m", None)
    smoothed = {f"target_smoothed_outage_{kind}_m": (reader.number(f"evaluation.target_smoothed_outage_{kind}_m",
                                                                   positive=True)
                                                     if reader.get(f"evaluation.target_smoothed_outage_{kind}_m", None)
                                                     is not None else None) for kind in ("rms", "max")}
    return {"evaluation_schedules": tuple(schedules),
            "target_end_rms_m": reader.number("evaluation.target_end_rms_m", positive=True) if rms is not None else None,
            "target_nees_mean": nees, "target_inside_95_fraction": inside, **smoothed}


def _probability(reader: _Reader, key: str) -> float:
    """A probability in (0, 1]; 1 means no gate."""
    value = reader.number(key, positive=True)
    if value > 1.0:
        raise ModelError(f"{reader.where(key)}: {key} must be a probability in (0, 1], got {value!r}")
    return value


def _choice(reader: _Reader, key: str, choices: tuple[str, ...]) -> str:
    """A text value that must be one of ``choices``."""
    value = reader.text(key)
    if value not in choices:
        raise ModelError(f"{reader.where(key)}: {key} must be one of {', '.join(choices)}, got {value!r}")
    return value


def key_place(config_path: str | Path, key: str) -> str:
    """``file:line`` of ``key`` (or of its closest enclosing key) in the configuration at ``config_path``, its bases
    included, for a refusal made where only the configuration's path is at hand; the file alone if it cannot be read
    again."""
    try:
        data, lines = read_config_with_bases(config_path)  # an inherited key: the line of the base that gives it
    except (ModelError, OSError):
        return str(config_path)
    return _Reader(Path(config_path), data, lines).where(key)


def load_config(path: str | Path) -> NavigatorConfig:
    """Read and validate a navigator configuration file."""
    path = Path(path)
    data, lines = read_config_with_bases(path)
    r = _Reader(path, data, lines)
    _check_keys(r)
    imu_source = source_from_config("imu", r.get("imu"), r.where, r.folder("imu.file"))
    columns = columns_of(imu_source) if imu_source.format == "csv" else None
    gap_action = r.text("imu.gap_action", "refuse")
    if gap_action not in GAP_ACTIONS:
        raise ModelError(f"{r.where('imu.gap_action')}: imu.gap_action must be one of {', '.join(GAP_ACTIONS)}, "
                         f"got {gap_action!r}")
    gnss_source = source_from_config("gnss", r.get("gnss"), r.where, r.folder("gnss.file"))
    quality_raw = r.get("gnss.quality_factor")
    if not isinstance(quality_raw, dict) or not quality_raw:
        raise ModelError(f"{r.where('gnss.quality_factor')}: gnss.quality_factor must map RTKLIB Q values to factors")
    quality = {}
    for q, factor in quality_raw.items():
        if isinstance(q, bool) or not isinstance(q, int) or isinstance(factor, bool) or not isinstance(factor, (int, float)) \
                or not math.isfinite(factor) or factor <= 0:
            raise ModelError(f"{r.where('gnss.quality_factor')}: gnss.quality_factor entry {q!r}: {factor!r} must be "
                             "an integer Q and a positive factor")
        quality[q] = float(factor)
    rotation = r.get("imu.rotation_to_body_deg", None)  # optional: IMU axes are body axes
    schedule, windows = _outages(r)
    config = NavigatorConfig(
        path=str(path), name=r.text("navigator"), model=r.text("model"),
        imu_file=imu_source.path, imu_columns=columns,
        time_offset=r.number("imu.time_offset_s", 0.0), gap_factor=r.number("imu.gap_factor", 3.0, positive=True),
        rotation_to_body=tuple(r.number(f"imu.rotation_to_body_deg.{k}") * DEG for k in ("roll", "pitch", "yaw"))
        if rotation is not None else (0.0, 0.0, 0.0),  # type: ignore[arg-type]
        gnss_file=gnss_source.path, lever_arm=r.vector("gnss.lever_arm_m", 3),  # type: ignore[arg-type]
        velocity_latency=r.number("gnss.velocity_latency_s", 0.0, non_negative=True), quality_factor=quality,
        minimum_sigma_position=r.number("gnss.minimum_sigma_position_m", non_negative=True),
        minimum_sigma_velocity=r.number("gnss.minimum_sigma_velocity_m_s", non_negative=True),
        noise={kind: _noise(r, kind) for kind in NOISE_UNITS},
        roll_pitch_sigma=r.number("initial.roll_pitch_sigma_deg", positive=True) * DEG,
        heading_extra_sigma=r.number("initial.heading_extra_sigma_deg", non_negative=True) * DEG,
        velocity_sigma=r.number("initial.velocity_sigma_m_s", positive=True),
        position_sigma=r.number("initial.position_sigma_m", positive=True),
        height_sigma=r.number("initial.height_sigma_m", positive=True),
        gyro_bias_sigma=r.number("initial.gyro_bias_sigma_deg_s", positive=True) * DEG,
        accel_bias_sigma=r.number("initial.accel_bias_sigma_ug", positive=True) * MICRO_G,
        rest_speed=r.number("alignment.rest_speed_m_s", positive=True),
        rest_window=r.number("alignment.rest_window_s", positive=True),
        heading_speed=r.number("alignment.heading_speed_m_s", positive=True),
        still_window=r.number("alignment.still_window_s", 0.5, positive=True),
        still_gyro_std_max=r.number("alignment.gyro_std_max_deg_s", 1.0, positive=True) * DEG,
        still_accel_std_max=r.number("alignment.accel_std_max_m_s2", 0.2, positive=True),
        rest_min=r.number("alignment.rest_min_s", 2.0, positive=True),
        predict_period=r.number("filter.predict_period_s", positive=True),
        nis_gate_probability=_probability(r, "filter.nis_gate_probability"),
        gate_action=_choice(r, "filter.gate_action", ("reject", "deweight")),
        gate_release_epochs=r.integer("filter.gate_release_epochs", minimum=1),
        zupt_enabled=r.flag("zupt.enabled"), zupt_window=r.number("zupt.window_s", positive=True),
        zupt_gyro_max=r.number("zupt.gyro_max_deg_s", positive=True) * DEG,
        zupt_accel_std_max=r.number("zupt.accel_std_max_m_s2", positive=True),
        zupt_speed_max=r.number("zupt.speed_max_m_s", positive=True),
        zupt_sigma=r.number("zupt.sigma_m_s", positive=True),
        nhc_enabled=r.flag("nhc.enabled"), nhc_sigma_lateral=r.number("nhc.sigma_lateral_m_s", positive=True),
        nhc_sigma_vertical=r.number("nhc.sigma_vertical_m_s", positive=True),
        nhc_speed_min=r.number("nhc.speed_min_m_s", non_negative=True),
        nhc_rate_max=r.number("nhc.rate_max_deg_s", 1e9, positive=True) * DEG,
        nhc_lever_arm=r.lever_arm("nhc.lever_arm_m"),
        outage_schedule=schedule, outage_windows=windows,
        imu_source=imu_source, gnss_source=gnss_source, gap_action=gap_action, **_evaluation(r),
        gyro_scale_factor_sigma=_ppm(r, "initial.gyro_scale_factor_sigma_ppm"),
        accel_scale_factor_sigma=_ppm(r, "initial.accel_scale_factor_sigma_ppm"),
        parameters=_model_parameters(r),
        output_folder=_output_folder(r),
        aiding={section: _aiding(r, section) for section in AIDING_SECTIONS},
        gnss_position_variance_factor=r.number("gnss.position_variance_factor", 1.0, positive=True),
        gnss_velocity_variance_factor=r.number("gnss.velocity_variance_factor", 1.0, positive=True),
        tuning={str(k): str(v) for k, v in (r.get("tuning", None) or {}).items()},
        key_lines=dict(lines),
    )
    validate(data, r.where)  # and what the checks above leave to the schema (types, ranges, required keys)
    return config


#: the sections of the aiding sensors that read a log of their own: section -> (sigma key, has a lever arm)
AIDING_SECTIONS = {"odometer": ("sigma_m_s", True), "barometer": ("sigma_m", False)}


def _aiding(reader: _Reader, section: str) -> AidingSettings:
    """An aiding sensor's section: off when absent; when enabled its file must exist and its sigma be given."""
    from modelgen.navigator.logs.scalar_csv import STREAMS

    sigma_key, has_lever_arm = AIDING_SECTIONS[section]
    if reader.get(section, None) is None:
        return AidingSettings(section, False, None, unit=next(iter(STREAMS[section].units)))
    enabled = reader.flag(f"{section}.enabled", False)
    file = None
    if enabled:
        if reader.get(f"{section}.file", None) is None:
            raise ModelError(f"{reader.where(section + '.enabled')}: {section} is enabled but {section}.file names no "
                             "log (give the CSV of time and value, or enabled: false)")
        file = reader.file(f"{section}.file")
        if reader.get(f"{section}.{sigma_key}", None) is None:
            raise ModelError(f"{reader.where(section + '.enabled')}: {section} is enabled but {section}.{sigma_key} "
                             "is not given")
    units = STREAMS[section].units
    unit = reader.text(f"{section}.units", next(iter(units)))
    if unit not in units:
        raise ModelError(f"{reader.where(section + '.units')}: {section}.units {unit!r} is not one of "
                         f"{', '.join(units)}")
    columns = [reader.integer(f"{section}.columns.{k}", d, minimum=1) for k, d in (("time", 1), ("value", 2))]
    if columns[0] == columns[1]:
        raise ModelError(f"{reader.where(section + '.columns')}: {section}.columns: time and value are both "
                         f"column {columns[0]}")
    lever = reader.lever_arm(f"{section}.lever_arm_m") if has_lever_arm else None
    sigma = reader.number(f"{section}.{sigma_key}", positive=True) if reader.get(f"{section}.{sigma_key}", None) \
        is not None else 1.0
    return AidingSettings(section, enabled, file, columns[0], columns[1], unit,
                          reader.number(f"{section}.time_offset_s", 0.0), sigma, lever)  # type: ignore[arg-type]


def _output_folder(reader: _Reader) -> Path | None:
    """output.folder as a path (relative to the configuration's folder), or None."""
    name = reader.get("output.folder", None)
    if name is None:
        return None
    name = reader.text("output.folder")
    return Path(name) if Path(name).is_absolute() else reader.folder("output.folder") / name


def _ppm(reader: _Reader, key: str) -> float | None:
    """An optional sigma in ppm, as a fraction."""
    return None if reader.get(key, None) is None else reader.number(key, positive=True) * 1e-6


def _model_parameters(reader: _Reader) -> dict[str, float]:
    """parameters: name -> a finite number (the model's unit); the navigator checks the names against the model."""
    raw = reader.get("parameters", None)
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise ModelError(f"{reader.where('parameters')}: parameters must map model parameter names to numbers")
    return {str(name): reader.number(f"parameters.{name}") for name in raw}


def builtin_config_path() -> Path:
    """The configuration that flies the built-in drive (``modelgen replay`` with no arguments)."""
    return data_path("replay_drive_0708.yaml")
