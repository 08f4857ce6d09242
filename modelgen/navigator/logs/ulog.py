"""PX4 ULog (.ulg): IMU and GNSS topics read with pyulog, on GPS time through the GNSS clock.

Units and time base
  ULog ``timestamp`` fields are microseconds of boot time (the autopilot's
  monotonic clock).  With ``time_base: gps`` (the default) both the IMU and the
  GNSS are put on GPS time: a GNSS epoch's time is its ``time_utc_usec`` (the
  receiver's UTC time of the fix) plus the leap seconds of its date, and the
  boot clock is tied to it by the median over the GNSS messages of
  (that GPS time - the message's ``timestamp_sample``, or ``timestamp`` when
  the topic has no sample time).  A ``timestamp`` is the time PX4 received the
  message, so without ``timestamp_sample`` the tie includes the receiver's
  output latency: correct it with ``imu.time_offset_s``.  With
  ``time_base: boot`` the boot clock is kept (both sections must say so); the
  report's times are then seconds since boot.

IMU topics (``imu.topic``)
  * ``sensor_combined`` (the default): ``gyro_rad[3]`` [rad/s] and
    ``accelerometer_m_s2[3]`` [m/s^2] at ``timestamp``; a sample whose
    ``accelerometer_timestamp_relative`` is PX4's invalid marker is dropped.
    The axes are the vehicle's FRD body axes after PX4's board rotation.
  * ``vehicle_imu``: ``delta_angle[3]`` / ``delta_angle_dt`` and
    ``delta_velocity[3]`` / ``delta_velocity_dt`` (microseconds) as mean rates,
    at ``timestamp_sample``; body axes as above.
  * ``sensor_gyro+sensor_accel``: the raw sensor topics (``x, y, z`` [rad/s],
    [m/s^2], sensor axes, before the board rotation), each gyro sample paired
    with the accelerometer sample nearest in ``timestamp_sample``; a gyro
    sample with no accelerometer sample within half the gyro interval is
    dropped and counted.

GNSS topics (``gnss.topic``: ``vehicle_gps_position`` or ``sensor_gps``, auto by default)
  Position ``latitude_deg``/``longitude_deg`` (double, PX4 >= 1.14) or
  ``lat``/``lon`` (int, 1e-7 deg); height ``altitude_ellipsoid_m``/``alt_ellipsoid``
  (mm) or, with ``height: msl``, ``altitude_msl_m``/``alt``; velocity
  ``vel_n_m_s, vel_e_m_s, vel_d_m_s``.  Standard deviations as PX4's own EKF
  uses them: ``eph`` [m] for north and east, ``epv`` [m] for up,
  ``s_variance_m_s`` [m/s] (a standard deviation, despite its name) for each
  velocity axis.  ``fix_type`` maps to RTKLIB's Q: 6 (RTK fixed) -> 1, 5 (RTK
  float) -> 2, 4 (DGPS) -> 4, 3 (3-D) -> 5; 0-1 (no fix), 2 (2-D: no height)
  and others (extrapolated) are dropped and counted, as are epochs whose
  ``vel_ned_valid`` is false or whose sigmas are not finite.

Refused, one line each: a file that is not a ULog, one whose definitions are
damaged or nest formats absurdly (checked before pyulog parses it, see
:func:`check_structure`), one pyulog finds corrupt, a missing topic or
field, time going backwards in a topic, and ``time_base: gps`` without any
GNSS time.
"""

from __future__ import annotations

import contextlib
import io
import struct
from pathlib import Path
from typing import Any

import numpy as np

from modelgen.errors import ModelError
from modelgen.navigator.logs.files import check_size
from modelgen.navigator.logs.formats import LogFormat, LogSource, Option
from modelgen.navigator.logs.gps_time import seconds, to_gpst_ns
from modelgen.navigator.logs.records import GnssLog, ImuLog, gnss_log

MAGIC = b"\x55\x4c\x6f\x67\x01\x12\x35"
DEFINITION_TYPES = set(b"BFIMPQ")  # flag bits, format, info, info multiple, parameter, parameter default
DATA_SECTION_TYPES = set(b"ALC")  # add logged message, logging, tagged logging: the data section starts
DATA_TYPES = set(b"ADLCOPQRSIM")  # the data section's message types (ULog spec; F and B only in definitions)
MAX_FIELDS = 4096  # flattened fields of one format
MAX_NESTING = 8
RELATIVE_TIMESTAMP_INVALID = 0x7FFFFFFF
FIX_TO_QUALITY = {6: 1, 5: 2, 4: 4, 3: 5}
GNSS_TOPICS = ("vehicle_gps_position", "sensor_gps")
IMU_TOPICS = ("sensor_combined", "vehicle_imu", "sensor_gyro+sensor_accel")
EXTRA_HINT = "pip install 'modelgen-nav[logs]'"


def check_structure(data: bytes, path: Path) -> list[str]:
    """Refuse a ULog whose message structure is damaged or whose formats nest absurdly; notes for a cut tail.

    pyulog recovers from damage as best it can, and silently stops at a message
    that runs past the end of the file.  Here every message is walked once:
    a message type the format does not define (in the definitions section, one
    that does not belong there) is refused naming its byte, and a last message
    cut short (a log whose recording stopped mid-write) is noted.  Every format
    is then flattened with cycle and size checks, so that a hostile format
    cannot make the parser recurse or allocate without end.
    """
    if len(data) < 16 or data[:7] != MAGIC:
        raise ModelError(f"{path}: not a ULog file (no ULog header)")
    offset = 16
    formats: dict[str, list[tuple[str, int]]] = {}
    definitions = True
    notes = []
    unpack = struct.Struct("<HB").unpack_from
    while offset + 3 <= len(data):
        size, kind = unpack(data, offset)
        if definitions and kind in DATA_SECTION_TYPES:
            definitions = False
        allowed = DEFINITION_TYPES if definitions else DATA_TYPES
        if kind not in allowed:
            section = "definitions" if definitions else "data"
            raise ModelError(f"{path}: corrupt ULog: damaged {section} section at byte {offset} "
                             f"(message type {kind:#04x})")
        if offset + 3 + size > len(data):
            if definitions:
                raise ModelError(f"{path}: corrupt ULog: damaged definitions section at byte {offset} "
                                 "(a message runs past the end of the file)")
            notes.append(f"{path}: the log ends inside a message (recording cut short): its last "
                         f"{len(data) - offset} bytes are not read")
            break
        if kind == ord("F"):
            text = data[offset + 3:offset + 3 + size].decode("utf-8", "replace")
            name, _, fields = text.partition(":")
            formats[name] = _format_fields(fields, path, offset)
        offset += 3 + size
    sizes: dict[str, int] = {}
    for name in formats:
        _flat_size(name, formats, sizes, (), path)
    return notes


def _format_fields(fields: str, path: Path, offset: int) -> list[tuple[str, int]]:
    """(type, count) of each field of a format message's text."""
    out = []
    for item in filter(None, fields.split(";")):
        parts = item.split(" ")
        kind = parts[0]
        count = 1
        if "[" in kind:
            base, _, rest = kind.partition("[")
            try:
                count = int(rest.rstrip("]"))
            except ValueError:
                raise ModelError(f"{path}: corrupt ULog: bad array size in a format at byte {offset}") from None
            kind = base
        if count < 0 or count > 0xFFFF:
            raise ModelError(f"{path}: corrupt ULog: array size {count} in a format at byte {offset}")
        out.append((kind, count))
    return out


def _flat_size(name: str, formats: dict, sizes: dict, stack: tuple[str, ...], path: Path) -> int:
    """Number of flattened fields of a format; refuses cycles, deep nesting and huge formats."""
    if name in sizes:
        return sizes[name]
    if name in stack or len(stack) >= MAX_NESTING:
        raise ModelError(f"{path}: corrupt ULog: format {name!r} nests itself or nests deeper than {MAX_NESTING}")
    total = 0
    for kind, count in formats.get(name, []):
        inner = _flat_size(kind, formats, sizes, stack + (name,), path) if kind in formats else 1
        total += count * inner
        if total > MAX_FIELDS:
            raise ModelError(f"{path}: format {name!r} has more than {MAX_FIELDS} fields: not read")
    sizes[name] = total
    return total


def load(path: Path, topics: list[str]) -> tuple[Any, list[str]]:
    """The parsed ULog (only ``topics``) and notes, or one ModelError; pyulog's printed warnings are captured."""
    check_size(path)
    try:
        from pyulog import ULog
    except ImportError:
        raise ModelError(f"{path}: reading a PX4 ULog needs pyulog ({EXTRA_HINT})") from None
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ModelError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    notes = check_structure(data, path)
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            ulog = ULog(io.BytesIO(data), message_name_filter_list=topics, disable_str_exceptions=True)
    except Exception as exc:  # an untrusted file: whatever the parser raises is a refusal, not a traceback
        raise ModelError(f"{path}: corrupt ULog ({type(exc).__name__}: {str(exc)[:120]})") from None
    if ulog.file_corruption:
        said = printed.getvalue().strip().splitlines()
        raise ModelError(f"{path}: corrupt ULog (pyulog found damaged data{': ' + said[0][:120] if said else ''})")
    return ulog, notes


def _dataset(ulog: Any, path: Path, topic: str, instance: int) -> dict[str, np.ndarray]:
    for item in ulog.data_list:
        if item.name == topic and item.multi_id == instance:
            return item.data
    present = sorted({f"{d.name}[{d.multi_id}]" for d in ulog.data_list})
    raise ModelError(f"{path}: no ULog topic {topic!r} instance {instance} (present: {', '.join(present) or 'none'})")


def _field(data: dict[str, np.ndarray], names: tuple[str, ...], path: Path, topic: str) -> np.ndarray:
    for name in names:
        if name in data:
            return data[name]
    raise ModelError(f"{path}: ULog topic {topic!r} has no field {' or '.join(names)}")


def _vector(data: dict[str, np.ndarray], stem: str, path: Path, topic: str) -> np.ndarray:
    return np.column_stack([_field(data, (f"{stem}[{i}]",), path, topic).astype(float) for i in range(3)])


def _sample_time_us(data: dict[str, np.ndarray]) -> np.ndarray:
    """Per message: ``timestamp_sample`` where the topic has it (and it is set), else ``timestamp`` [us]."""
    stamp = data["timestamp"].astype(np.int64)
    if "timestamp_sample" in data:
        sample = data["timestamp_sample"].astype(np.int64)
        return np.where(sample > 0, sample, stamp)
    return stamp


def _gnss_topic(ulog: Any, path: Path, wanted: str) -> str:
    if wanted != "auto":
        return wanted
    names = {d.name for d in ulog.data_list}
    for topic in GNSS_TOPICS:
        if topic in names:
            return topic
    raise ModelError(f"{path}: no GNSS topic in the ULog (looked for {', '.join(GNSS_TOPICS)})")


def _gps_time_us(data: dict[str, np.ndarray], path: Path, topic: str) -> tuple[np.ndarray, list[str]]:
    """GPS time [us since 1970, GPS calendar] of each message's time_utc_usec (0 where unset)."""
    utc = _field(data, ("time_utc_usec",), path, topic).astype(np.int64)
    out = np.zeros_like(utc)
    notes: list[str] = []
    valid = utc > 0
    if valid.any():
        gpst_ns, notes = to_gpst_ns(utc[valid] * 1000, "UTC", str(path))
        out[valid] = gpst_ns // 1000
    return out, notes


def _boot_to_gps_us(ulog: Any, path: Path, topic: str, instance: int) -> tuple[int, list[str]]:
    """The boot-to-GPS-time offset [us] from the GNSS topic (see the module docstring)."""
    data = _dataset(ulog, path, topic, instance)
    gps_us, notes = _gps_time_us(data, path, topic)
    valid = gps_us > 0
    if not valid.any():
        raise ModelError(f"{path}: ULog topic {topic!r} has no GNSS time (time_utc_usec is 0 throughout): "
                         "set time_base: boot in both the imu and the gnss sections to fly on boot time")
    offsets = gps_us[valid] - _sample_time_us(data)[valid]
    return int(np.median(offsets).round()), notes


def _increasing(time_us: np.ndarray, path: Path, topic: str) -> None:
    bad = np.nonzero(np.diff(time_us) <= 0)[0]
    if len(bad):
        k = int(bad[0]) + 1
        kind = "duplicated" if time_us[k] == time_us[k - 1] else "goes back in time"
        raise ModelError(f"{path}: {topic} message {k + 1}: time stamp {int(time_us[k])} us {kind} "
                         f"(message {k} has {int(time_us[k - 1])} us)")


def _imu_samples(ulog: Any, path: Path, topic: str, instance: int) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                             np.ndarray, list[str], str]:
    """(time_us, force, rate, message numbers, notes, record kind) of the IMU topic."""
    notes: list[str] = []
    if topic == "sensor_combined":
        d = _dataset(ulog, path, topic, instance)
        time_us = d["timestamp"].astype(np.int64)
        rate, force = _vector(d, "gyro_rad", path, topic), _vector(d, "accelerometer_m_s2", path, topic)
        keep = np.ones(len(time_us), dtype=bool)
        if "accelerometer_timestamp_relative" in d:
            keep = d["accelerometer_timestamp_relative"].astype(np.int64) != RELATIVE_TIMESTAMP_INVALID
    elif topic == "vehicle_imu":
        d = _dataset(ulog, path, topic, instance)
        time_us = _sample_time_us(d)
        angle_dt = _field(d, ("delta_angle_dt",), path, topic).astype(float) * 1e-6
        velocity_dt = _field(d, ("delta_velocity_dt",), path, topic).astype(float) * 1e-6
        keep = (angle_dt > 0) & (velocity_dt > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = _vector(d, "delta_angle", path, topic) / angle_dt[:, None]
            force = _vector(d, "delta_velocity", path, topic) / velocity_dt[:, None]
    else:
        gyro = _dataset(ulog, path, "sensor_gyro", instance)
        accel = _dataset(ulog, path, "sensor_accel", instance)
        time_us, accel_us = _sample_time_us(gyro), _sample_time_us(accel)
        _increasing(accel_us, path, "sensor_accel")
        rate = np.column_stack([_field(gyro, (a,), path, "sensor_gyro").astype(float) for a in "xyz"])
        accel_xyz = np.column_stack([_field(accel, (a,), path, "sensor_accel").astype(float) for a in "xyz"])
        nearest = np.clip(np.searchsorted(accel_us, time_us), 1, max(1, len(accel_us) - 1))
        if len(accel_us) > 1:
            earlier = np.abs(time_us - accel_us[nearest - 1]) <= np.abs(accel_us[nearest] - time_us)
            nearest = np.where(earlier, nearest - 1, nearest)
        else:
            nearest = np.zeros(len(time_us), dtype=int)
        half = 0.5 * float(np.median(np.diff(time_us))) if len(time_us) > 1 else np.inf
        keep = np.abs(accel_us[nearest] - time_us) <= half
        force = accel_xyz[nearest]
        topic = "sensor_gyro"
    _increasing(time_us, path, topic)
    finite = np.isfinite(rate).all(axis=1) & np.isfinite(force).all(axis=1)
    dropped = int(np.count_nonzero(~(keep & finite)))
    if dropped:
        notes.append(f"{path}: {dropped} {topic} sample(s) dropped (invalid or unpaired accelerometer data, or "
                     "not finite)")
    keep &= finite
    numbers = np.arange(1, len(time_us) + 1)
    return time_us[keep], force[keep], rate[keep], numbers[keep], notes, f"{topic} message"


def read_imu(source: LogSource) -> ImuLog:
    """The IMU topic of a ULog on the configured time base (see the module docstring)."""
    o = source.options
    path = source.path
    topics = o["topic"].split("+") + list(GNSS_TOPICS)
    ulog, cut = load(path, topics)
    time_us, force, rate, numbers, notes, kind = _imu_samples(ulog, path, o["topic"], o["instance"])
    notes = cut + notes
    if not len(time_us):
        raise ModelError(f"{path}: no IMU samples in ULog topic {o['topic']!r}")
    scale = "boot"
    if o["time_base"] == "gps":
        offset_us, time_notes = _boot_to_gps_us(ulog, path, _gnss_topic(ulog, path, o["gnss_topic"]),
                                                o["gnss_instance"])
        time_us = time_us + offset_us
        notes += time_notes
        scale = "GPST"
    if ulog.dropouts:
        notes.append(f"{path}: the logger reports {len(ulog.dropouts)} dropout(s) "
                     f"({sum(d.duration for d in ulog.dropouts)} ms in all)")
    return ImuLog(str(path), seconds(time_us * 1000), force, rate, notes=notes, records=numbers,
                  record_kind=kind, time_scale=scale)


def read_gnss(source: LogSource) -> GnssLog:
    """The GNSS topic of a ULog (see the module docstring for units, sigmas and fix types)."""
    o = source.options
    path = source.path
    ulog, notes = load(path, list(GNSS_TOPICS))
    topic = _gnss_topic(ulog, path, o["topic"])
    d = _dataset(ulog, path, topic, o["instance"])
    if o["time_base"] == "gps":
        time_us, time_notes = _gps_time_us(d, path, topic)
        notes += time_notes
        if not (time_us > 0).any():
            _boot_to_gps_us(ulog, path, topic, o["instance"])  # raises: no GNSS time
        scale = "GPST"
    else:
        time_us, scale = _sample_time_us(d), "boot"
    if "latitude_deg" in d:
        latitude, longitude = d["latitude_deg"].astype(float), d["longitude_deg"].astype(float)
    else:
        latitude = _field(d, ("lat",), path, topic).astype(float) * 1e-7
        longitude = _field(d, ("lon",), path, topic).astype(float) * 1e-7
    if o["height"] == "ellipsoid":
        height = (d["altitude_ellipsoid_m"].astype(float) if "altitude_ellipsoid_m" in d
                  else _field(d, ("alt_ellipsoid",), path, topic).astype(float) * 1e-3)
    else:
        height = (d["altitude_msl_m"].astype(float) if "altitude_msl_m" in d
                  else _field(d, ("alt",), path, topic).astype(float) * 1e-3)
    fix = _field(d, ("fix_type",), path, topic).astype(int)
    velocity = np.column_stack([_field(d, (f"vel_{a}_m_s",), path, topic).astype(float) for a in "ned"])
    eph, epv = (_field(d, (k,), path, topic).astype(float) for k in ("eph", "epv"))
    speed_sigma = _field(d, ("s_variance_m_s",), path, topic).astype(float)
    valid_velocity = _field(d, ("vel_ned_valid",), path, topic).astype(bool)
    satellites = d["satellites_used"].astype(int) if "satellites_used" in d else np.zeros(len(fix), int)
    quality = np.array([FIX_TO_QUALITY.get(int(f), 0) for f in fix])
    sigmas = np.column_stack([eph, eph, epv, speed_sigma])
    finite = (np.isfinite(np.column_stack([latitude, longitude, height, velocity])).all(axis=1)
              & np.isfinite(sigmas).all(axis=1) & (sigmas >= 0).all(axis=1))
    timed = time_us > 0
    keep = (quality > 0) & valid_velocity & finite & timed
    for mask, why in ((fix <= 1, "without a fix (fix_type 0-1)"), (fix == 2, "with a 2-D fix only (no height)"),
                      ((quality == 0) & (fix > 2), "with a fix_type that is not a measurement (e.g. 8, extrapolated)"),
                      ((quality > 0) & ~valid_velocity, "without a valid velocity (vel_ned_valid false)"),
                      ((quality > 0) & valid_velocity & ~finite, "with non-finite or negative values"),
                      ((quality > 0) & valid_velocity & finite & ~timed, "without GNSS time (time_utc_usec 0)")):
        if mask.any():
            notes.append(f"{path}: {int(np.count_nonzero(mask))} {topic} message(s) {why} not used")
    _increasing(time_us[keep], path, topic)
    rows = {"time": seconds(time_us[keep] * 1000), "latitude": np.radians(latitude[keep]),
            "longitude": np.radians(longitude[keep]), "height": height[keep], "quality": quality[keep],
            "satellites": satellites[keep],
            "sigma_position": np.column_stack([eph, eph, epv])[keep],
            "velocity": velocity[keep], "sigma_velocity": np.column_stack([speed_sigma] * 3)[keep]}
    return gnss_log(str(path), rows, notes, scale)


_TIME_BASE = Option("time_base", "choice", "gps", ("gps", "boot"),
                    doc="gps: boot time tied to GPS time through the GNSS topic's time_utc_usec; boot: seconds "
                        "since boot (imu and gnss must agree)")

FORMAT = LogFormat(
    name="ulog",
    summary="PX4 ULog (.ulg), read with pyulog",
    imu_options=(
        Option("topic", "choice", "sensor_combined", IMU_TOPICS, doc="the IMU topic (see docs/log-formats.md)"),
        Option("instance", "integer", 0, doc="the topic's multi-instance number"),
        _TIME_BASE,
        Option("gnss_topic", "choice", "auto", ("auto",) + GNSS_TOPICS,
               doc="the GNSS topic whose time_utc_usec ties the boot clock to GPS time"),
        Option("gnss_instance", "integer", 0, doc="its multi-instance number"),
    ),
    gnss_options=(
        Option("topic", "choice", "auto", ("auto",) + GNSS_TOPICS,
               doc="the GNSS topic (auto: vehicle_gps_position, else sensor_gps)"),
        Option("instance", "integer", 0, doc="the topic's multi-instance number"),
        _TIME_BASE,
        Option("height", "choice", "ellipsoid", ("ellipsoid", "msl"),
               doc="height above the WGS-84 ellipsoid (default) or above mean sea level"),
    ),
    read_imu=read_imu,
    read_gnss=read_gnss,
    extra="logs",
)
