"""The log formats, one entry each, and the one way to read the configured IMU and GNSS logs.

Adding a format is one module with a ``FORMAT`` entry
(:class:`~modelgen.navigator.logs.formats.LogFormat`) and one line in
:data:`FORMATS`; the configuration's schema, validation and documentation of
its keys follow from the entry.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

from modelgen.errors import ModelError
from modelgen.navigator.logs.checks import GAP_ACTIONS, apply_gap_policy
from modelgen.navigator.logs.formats import LogFormat, LogSource, validate_options
from modelgen.navigator.logs.imu_csv import FORMAT as CSV
from modelgen.navigator.logs.records import GnssLog, ImuLog
from modelgen.navigator.logs.ros2bag import FORMAT as ROS2_BAG
from modelgen.navigator.logs.rtklib_pos import FORMAT as RTKLIB_POS
from modelgen.navigator.logs.scalar_csv import STREAMS as SCALAR_STREAMS
from modelgen.navigator.logs.scalar_csv import ScalarLog, read_scalar_csv
from modelgen.navigator.logs.ulog import FORMAT as ULOG

#: One entry per format, in the order the documentation lists them.
FORMATS: dict[str, LogFormat] = {f.name: f for f in (CSV, RTKLIB_POS, ULOG, ROS2_BAG)}
DEFAULT_FORMAT = {"imu": "csv", "gnss": "rtklib_pos"}
#: The aiding sensors' own logs (odometer, barometer): one time-and-value CSV reader, one entry per stream
#: (modelgen.navigator.logs.scalar_csv.STREAMS: name, quantity, accepted units).
#: Keys of the imu: and gnss: sections that every format shares (the navigator's, not the reader's).
COMMON_KEYS = {
    "imu": {"file", "format", "time_offset_s", "gap_factor", "gap_action", "rotation_to_body_deg"},
    "gnss": {"file", "format", "lever_arm_m", "velocity_latency_s", "quality_factor", "minimum_sigma_position_m",
             "minimum_sigma_velocity_m_s", "position_variance_factor", "velocity_variance_factor"},
}


def formats_for(section: str) -> list[str]:
    """Names of the formats that read the ``imu`` or ``gnss`` section."""
    return [name for name, f in FORMATS.items() if f.reads(section)]


def schema(section: str) -> dict[str, set[str]]:
    """Every key a section may hold (all formats together), nested paths as 'section.sub' -> keys."""
    out: dict[str, set[str]] = {section: set(COMMON_KEYS[section])}
    for fmt in FORMATS.values():
        for option in fmt.options(section):
            parts = option.key.split(".")
            for depth in range(len(parts)):
                prefix = ".".join([section, *parts[:depth]])
                out.setdefault(prefix, set()).add(parts[depth])
    return out


def source_from_config(section: str, raw: Mapping[str, Any], where: Callable[[str], str],
                       folder: Path) -> LogSource:
    """The configuration's ``imu:`` / ``gnss:`` section as a validated LogSource.

    ``where(key)`` gives 'file:line' of a key path; ``folder`` is the
    configuration's folder, which relative ``file`` paths start from.
    """
    name = raw.get("format", DEFAULT_FORMAT[section])
    readers = formats_for(section)
    if name not in readers:
        raise ModelError(f"{where(section + '.format')}: {section}.format {name!r} is not one of "
                         f"{', '.join(readers)}")
    fmt = FORMATS[name]
    own = {o.key.split(".")[0] for o in fmt.options(section)}
    for key in raw:
        if key not in COMMON_KEYS[section] and key not in own:
            users = [f for f, e in FORMATS.items() if key in {o.key.split(".")[0] for o in e.options(section)}]
            raise ModelError(f"{where(section + '.' + key)}: {section}.{key} is a key of the "
                             f"{' and '.join(users)} format(s), not of {name} "
                             f"(its keys: {', '.join(sorted(own)) or 'none'})")
    options = validate_options(fmt, section, raw, where)
    file_key = f"{section}.file"
    text = raw.get("file")
    if not isinstance(text, str) or not text.strip():
        raise ModelError(f"{where(file_key)}: {file_key} must be the log's path, got {text!r}")
    path = Path(text) if Path(text).is_absolute() else folder / text
    if not (path.is_file() or (fmt.folder and path.is_dir())):
        raise ModelError(f"{where(file_key)}: {file_key}: no such file {str(path)!r}")
    return LogSource(section, name, path, options, where)


def read_scalar(stream: str, path: Path, time_column: int, value_column: int, unit: str) -> ScalarLog:
    """Read an aiding sensor's own log (odometer, barometer: :data:`SCALAR_STREAMS`, time and value CSV)."""
    if stream not in SCALAR_STREAMS:
        raise ModelError(f"{path}: no reader for the {stream} stream (known: {', '.join(SCALAR_STREAMS)})")
    return read_scalar_csv(path, stream, time_column, value_column, unit)


def read_imu(source: LogSource, gap_factor: float, gap_action: str) -> ImuLog:
    """Read the IMU log with its format's reader, then apply the gap policy (logs.checks)."""
    if gap_action not in GAP_ACTIONS:
        raise ModelError(f"{source.where('imu.gap_action')}: imu.gap_action {gap_action!r} is not one of "
                         f"{', '.join(GAP_ACTIONS)}")
    reader = FORMATS[source.format].read_imu
    assert reader is not None
    return apply_gap_policy(reader(source), gap_factor, gap_action)


def read_gnss(source: LogSource) -> GnssLog:
    """Read the GNSS log with its format's reader."""
    reader = FORMATS[source.format].read_gnss
    assert reader is not None
    return reader(source)
