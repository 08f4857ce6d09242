"""ROS 2 bags (a bag folder, or its .db3 / .mcap file), read with rosbags.

Messages are decoded with rosbags' own ROS 2 Humble type definitions, never
with definitions carried in the bag, and only these types are read:

IMU (``imu.topic``): ``sensor_msgs/msg/Imu``
  ``angular_velocity`` [rad/s] and ``linear_acceleration`` [m/s^2] (specific
  force) in the message's frame; ROS bodies are x forward, y left, z up
  (REP 103), so a FLU IMU needs ``rotation_to_body_deg: {roll: 180, ...}`` to
  reach the navigator's forward-right-down body axes.  A message whose
  ``angular_velocity_covariance[0]`` or ``linear_acceleration_covariance[0]`` is
  -1 ("no data", by the message's definition) is dropped and counted.

GNSS (``gnss.topic``): ``sensor_msgs/msg/NavSatFix``
  ``latitude``, ``longitude`` [deg], ``altitude`` [m above the WGS-84 ellipsoid,
  by the message's definition]; sigmas from the diagonal of
  ``position_covariance`` (ENU, m^2) unless its type is UNKNOWN (0), when
  ``gnss.sigma_position_m`` is used (and required).  ``status.status`` maps to
  RTKLIB's Q: FIX (0) -> 5 (single), SBAS_FIX (1) -> 3, GBAS_FIX (2) -> 4
  (DGPS/RTK); NO_FIX (-1) is dropped and counted.
  Velocity (optional ``gnss.velocity_topic``): ``geometry_msgs/msg/TwistStamped``
  or ``TwistWithCovarianceStamped``, ``twist.linear`` east, north, up (REP 103;
  ``velocity_frame: ned`` for north, east, down) [m/s], sigmas from the
  covariance's diagonal or ``gnss.sigma_velocity_m_s``.  Each fix takes the
  velocity message nearest in stamp within ``velocity_match_s``; a fix with none
  is dropped and counted.

Time: ``header.stamp`` (``stamp: header``, the default) or the bag's receive
time (``stamp: receive``), integer nanoseconds since 1970 in ``time_system``:
UTC (ROS time is Unix time) by default, put on GPS time with the leap seconds
of its date; GPST if the driver stamps GPS time.  Stamps that do not increase
within a topic are refused.

Refused, one line each: a bag that cannot be opened or decoded, a missing
topic, a topic of another message type, and the cases above.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import numpy as np

from modelgen.errors import ModelError
from modelgen.navigator.logs.files import check_size
from modelgen.navigator.logs.formats import LogFormat, LogSource, Option
from modelgen.navigator.logs.gps_time import seconds, to_gpst_ns
from modelgen.navigator.logs.records import GnssLog, ImuLog, gnss_log

IMU_TYPE = "sensor_msgs/msg/Imu"
FIX_TYPE = "sensor_msgs/msg/NavSatFix"
VELOCITY_TYPES = ("geometry_msgs/msg/TwistStamped", "geometry_msgs/msg/TwistWithCovarianceStamped")
STATUS_TO_QUALITY = {0: 5, 1: 3, 2: 4}
EXTRA_HINT = "pip install 'modelgen-nav[logs]'"


def _typestore() -> Any:
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ModelError(f"reading a ROS 2 bag needs rosbags ({EXTRA_HINT})") from None
    return get_typestore(Stores.ROS2_HUMBLE)


def messages(path: Path, topic: str, types: tuple[str, ...]) -> Iterator[tuple[int, int, Any]]:
    """(message number, receive time [ns], decoded message) of ``topic``; any failure is one ModelError."""
    check_size(path)
    store = _typestore()
    from rosbags.rosbag2 import Reader

    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # untrusted bag: whatever rosbags raises is a refusal
        raise ModelError(f"{path}: cannot be opened as a ROS 2 bag ({type(exc).__name__}: {str(exc)[:160]})") from None
    try:
        connections = [c for c in reader.connections if c.topic == topic]
        if not connections:
            present = ", ".join(sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})) or "none"
            raise ModelError(f"{path}: no topic {topic!r} in the bag (topics: {present[:400]})")
        wrong = sorted({c.msgtype for c in connections if c.msgtype not in types})
        if wrong:
            raise ModelError(f"{path}: topic {topic!r} carries {', '.join(wrong)}, not {' or '.join(types)}")
        number = 0
        iterator = reader.messages(connections=connections)
        while True:
            try:
                connection, received, raw = next(iterator)
            except StopIteration:
                break
            except Exception as exc:  # a damaged storage file
                raise ModelError(f"{path}: damaged ROS 2 bag after {number} {topic} message(s) "
                                 f"({type(exc).__name__}: {str(exc)[:160]})") from None
            number += 1
            try:
                message = store.deserialize_cdr(raw, connection.msgtype)
            except Exception as exc:
                raise ModelError(f"{path}: {topic} message {number} cannot be decoded as {connection.msgtype} "
                                 f"({type(exc).__name__})") from None
            yield number, int(received), message
    finally:
        try:
            reader.close()
        except Exception:  # closing a damaged bag must not hide the refusal above
            pass


def _stamp(message: Any, received: int, how: str) -> int:
    if how == "receive":
        return received
    return int(message.header.stamp.sec) * 1_000_000_000 + int(message.header.stamp.nanosec)


def _gps_seconds(stamps: list[int], system: str, path: Path, topic: str, numbers: list[int]) -> tuple[np.ndarray,
                                                                                                     list[str]]:
    """Stamps [ns] onto GPS time, after refusing stamps that do not increase."""
    array = np.array(stamps, dtype=np.int64)
    bad = np.nonzero(np.diff(array) <= 0)[0]
    if len(bad):
        k = int(bad[0]) + 1
        kind = "duplicated" if array[k] == array[k - 1] else "goes back in time"
        raise ModelError(f"{path}: {topic} message {numbers[k]}: stamp {int(array[k])} ns {kind}")
    gps_ns, notes = to_gpst_ns(array, system, str(path))
    return seconds(gps_ns), notes


def read_imu(source: LogSource) -> ImuLog:
    """The Imu topic of a bag (see the module docstring)."""
    o, path = source.options, source.path
    stamps, numbers, force, rate = [], [], [], []
    no_data = 0
    for number, received, m in messages(path, o["topic"], (IMU_TYPE,)):
        if m.angular_velocity_covariance[0] == -1 or m.linear_acceleration_covariance[0] == -1:
            no_data += 1
            continue
        values = [m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z,
                  m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
        if not np.isfinite(values).all():
            no_data += 1
            continue
        stamps.append(_stamp(m, received, o["stamp"]))
        numbers.append(number)
        force.append(values[:3])
        rate.append(values[3:])
    if not stamps:
        raise ModelError(f"{path}: no IMU samples on {o['topic']!r}"
                         + (f" ({no_data} message(s) without angular velocity or acceleration)" if no_data else ""))
    time, notes = _gps_seconds(stamps, o["time_system"], path, o["topic"], numbers)
    if no_data:
        notes.append(f"{path}: {no_data} {o['topic']} message(s) without angular velocity or acceleration "
                     "(covariance[0] = -1) or with non-finite values dropped")
    return ImuLog(str(path), time, np.array(force), np.array(rate), notes=notes, records=np.array(numbers),
                  record_kind=f"{o['topic']} message")


def _velocities(source: LogSource) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(stamps [ns], NED velocity, NED sigma) of the velocity topic, or None without one."""
    o, path = source.options, source.path
    topic = o["velocity_topic"]
    if not topic:
        return None
    stamps, velocity, sigma = [], [], []
    for number, received, m in messages(path, topic, VELOCITY_TYPES):
        twist = m.twist.twist if hasattr(m.twist, "covariance") else m.twist
        covariance = m.twist.covariance if hasattr(m.twist, "covariance") else None
        v = np.array([twist.linear.x, twist.linear.y, twist.linear.z], dtype=float)
        if covariance is not None and min(covariance[0], covariance[7], covariance[14]) > 0:
            s = np.sqrt([covariance[0], covariance[7], covariance[14]])
        elif o["sigma_velocity_m_s"] is not None:
            s = np.full(3, o["sigma_velocity_m_s"])
        else:
            raise ModelError(f"{path}: {topic} message {number} carries no velocity covariance: set "
                             "gnss.sigma_velocity_m_s")
        if o["velocity_frame"] == "enu":  # east, north, up -> north, east, down
            v, s = np.array([v[1], v[0], -v[2]]), np.array([s[1], s[0], s[2]])
        stamps.append(_stamp(m, received, o["stamp"]))
        velocity.append(v)
        sigma.append(s)
    if not stamps:
        raise ModelError(f"{path}: no velocity messages on {topic!r}")
    return np.array(stamps, dtype=np.int64), np.array(velocity), np.array(sigma)


def read_gnss(source: LogSource) -> GnssLog:
    """The NavSatFix topic of a bag, with the velocity topic's velocities (see the module docstring)."""
    o, path = source.options, source.path
    stamps, numbers, position, sigma, quality = [], [], [], [], []
    no_fix = non_finite = 0
    for number, received, m in messages(path, o["topic"], (FIX_TYPE,)):
        q = STATUS_TO_QUALITY.get(int(m.status.status), 0)
        if q == 0:
            no_fix += 1
            continue
        values = [m.latitude, m.longitude, m.altitude]
        c = m.position_covariance
        if int(m.position_covariance_type) != 0:
            s = [c[4], c[0], c[8]]  # ENU covariance: north is [1][1], east [0][0], up [2][2]
            if min(s) < 0:
                raise ModelError(f"{path}: {o['topic']} message {number}: negative position variance")
            s = list(np.sqrt(s))
        elif o["sigma_position_m"] is not None:
            s = [o["sigma_position_m"]] * 3
        else:
            raise ModelError(f"{path}: {o['topic']} message {number} has no position covariance "
                             "(position_covariance_type UNKNOWN): set gnss.sigma_position_m")
        if not np.isfinite(values + s).all():
            non_finite += 1
            continue
        stamps.append(_stamp(m, received, o["stamp"]))
        numbers.append(number)
        position.append(values)
        sigma.append(s)
        quality.append(q)
    notes = []
    if no_fix:
        notes.append(f"{path}: {no_fix} {o['topic']} message(s) with status NO_FIX not used")
    if non_finite:
        notes.append(f"{path}: {non_finite} {o['topic']} message(s) with non-finite values not used")
    if not stamps:
        return GnssLog(str(path), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, int),
                       np.zeros(0, int), np.zeros((0, 3)), None, None, notes)
    time, time_notes = _gps_seconds(stamps, o["time_system"], path, o["topic"], numbers)
    p = np.array(position)
    rows = {"time": time, "latitude": np.radians(p[:, 0]), "longitude": np.radians(p[:, 1]), "height": p[:, 2],
            "quality": np.array(quality), "satellites": np.zeros(len(p), int), "sigma_position": np.array(sigma)}
    velocities = _velocities(source)
    if velocities is not None:
        v_stamps, v, v_sigma = velocities
        fix_ns = np.array(stamps, dtype=np.int64)
        index = np.clip(np.searchsorted(v_stamps, fix_ns), 0, len(v_stamps) - 1)
        before = np.maximum(index - 1, 0)
        closer = np.abs(v_stamps[before] - fix_ns) < np.abs(v_stamps[index] - fix_ns)
        index = np.where(closer, before, index)
        matched = np.abs(v_stamps[index] - fix_ns) <= round(o["velocity_match_s"] * 1e9)
        if not matched.all():
            notes.append(f"{path}: {int(np.count_nonzero(~matched))} fix(es) without a velocity message within "
                         f"{o['velocity_match_s']} s not used")
        rows = {k: value[matched] for k, value in rows.items()}
        rows["velocity"], rows["sigma_velocity"] = v[index[matched]], v_sigma[index[matched]]
        if not matched.any():
            raise ModelError(f"{path}: no {o['topic']} fix has a {o['velocity_topic']} velocity within "
                             f"{o['velocity_match_s']} s")
    return gnss_log(str(path), rows, notes + time_notes)


_STAMP = Option("stamp", "choice", "header", ("header", "receive"),
                doc="header: the message's header.stamp; receive: the time the bag recorded it")
_TIME_SYSTEM = Option("time_system", "choice", "UTC", ("UTC", "GPST"),
                      doc="the stamps' time scale: UTC (ROS time) or GPST")

FORMAT = LogFormat(
    name="ros2bag",
    summary="ROS 2 bag (folder with metadata.yaml, or a .db3 / .mcap file), read with rosbags",
    imu_options=(Option("topic", "text", doc="the sensor_msgs/msg/Imu topic, e.g. /imu/data"), _STAMP, _TIME_SYSTEM),
    gnss_options=(
        Option("topic", "text", doc="the sensor_msgs/msg/NavSatFix topic, e.g. /fix"),
        Option("velocity_topic", "text", None,
               doc="optional TwistStamped or TwistWithCovarianceStamped topic of the GNSS velocity"),
        Option("velocity_frame", "choice", "enu", ("enu", "ned"), doc="axes of twist.linear (REP 103: enu)"),
        Option("velocity_match_s", "number", 0.02, doc="largest stamp difference between a fix and its velocity [s]"),
        Option("sigma_position_m", "number", None, doc="position sigma where the covariance is UNKNOWN [m]"),
        Option("sigma_velocity_m_s", "number", None, doc="velocity sigma where the twist has no covariance [m/s]"),
        _STAMP, _TIME_SYSTEM,
    ),
    read_imu=read_imu,
    read_gnss=read_gnss,
    folder=True,
    extra="logs",
)
