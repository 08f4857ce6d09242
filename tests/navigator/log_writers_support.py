"""Test logs written in every format from one excerpt of the drive, and a minimal ULog writer.

The same data goes into each format (CSV + RTKLIB .pos, PX4 ULog, ROS 2 bag),
so that a flight of each can be compared with the CSV/.pos flight.  The data
is the 60 s test excerpt of the drive (tests/navigator/data) rounded once to
what the binary formats hold: times to whole microseconds, IMU values and the
GNSS velocities and sigmas to float32.  The CSV and .pos are then written with
every digit of those values (``repr``), so that all formats carry exactly the
same numbers.

ULog (PX4's format; https://docs.px4.io/main/en/dev_log/ulog_file_format.html):
pyulog reads but does not write a ULog from scratch, so :class:`UlogWriter`
writes the few messages a log needs, little endian:

* header, 16 bytes: magic ``55 4c 6f 67 01 12 35``, version 1, uint64 start
  timestamp [us];
* then messages, each ``uint16 size, uint8 type`` and ``size`` bytes:
  ``B`` flag bits (8 compat + 8 incompat flag bytes + 3 uint64 appended
  offsets, all zero: 40 bytes, first after the header), ``I`` info (uint8 key
  length, key ``"type name"``, value), ``F`` format (``"name:type field;..."``),
  ``A`` subscription (uint8 multi id, uint16 message id, topic name) and ``D``
  data (uint16 message id, the fields packed in the format's order, no padding).
"""

from __future__ import annotations

import struct
import time as clock
from dataclasses import dataclass
from pathlib import Path

import numpy as np

DATA = Path(__file__).parent / "data"
LEAP_2025_S = 18  # GPS - UTC on the drive's date (2025-07-08)

_PACK = {"uint64_t": "Q", "int64_t": "q", "uint32_t": "I", "int32_t": "i", "uint16_t": "H", "int16_t": "h",
         "uint8_t": "B", "int8_t": "b", "float": "f", "double": "d", "bool": "?", "char": "c"}

SENSOR_COMBINED = [("uint64_t", "timestamp"), ("float[3]", "gyro_rad"), ("uint32_t", "gyro_integral_dt"),
                   ("int32_t", "accelerometer_timestamp_relative"), ("float[3]", "accelerometer_m_s2"),
                   ("uint32_t", "accelerometer_integral_dt"), ("uint8_t", "accelerometer_clipping"),
                   ("uint8_t", "gyro_clipping"), ("uint8_t", "accel_calibration_count"),
                   ("uint8_t", "gyro_calibration_count")]
#: PX4 >= 1.14 sensor_gps (latitude_deg ... double).
SENSOR_GPS = [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"), ("double", "latitude_deg"),
              ("double", "longitude_deg"), ("double", "altitude_msl_m"), ("double", "altitude_ellipsoid_m"),
              ("uint64_t", "time_utc_usec"), ("uint32_t", "device_id"), ("float", "s_variance_m_s"),
              ("float", "c_variance_rad"), ("float", "eph"), ("float", "epv"), ("float", "hdop"), ("float", "vdop"),
              ("int32_t", "noise_per_ms"), ("int32_t", "jamming_indicator"), ("float", "vel_m_s"),
              ("float", "vel_n_m_s"), ("float", "vel_e_m_s"), ("float", "vel_d_m_s"), ("float", "cog_rad"),
              ("int32_t", "timestamp_time_relative"), ("float", "heading"), ("float", "heading_offset"),
              ("float", "heading_accuracy"), ("uint16_t", "automatic_gain_control"), ("uint8_t", "fix_type"),
              ("uint8_t", "jamming_state"), ("bool", "vel_ned_valid"), ("uint8_t", "satellites_used")]
#: PX4 <= 1.13 vehicle_gps_position (lat/lon int 1e-7 deg, alt mm, no timestamp_sample).
VEHICLE_GPS_POSITION = [("uint64_t", "timestamp"), ("uint64_t", "time_utc_usec"), ("int32_t", "lat"),
                        ("int32_t", "lon"), ("int32_t", "alt"), ("int32_t", "alt_ellipsoid"),
                        ("float", "s_variance_m_s"), ("float", "c_variance_rad"), ("float", "eph"), ("float", "epv"),
                        ("float", "vel_n_m_s"), ("float", "vel_e_m_s"), ("float", "vel_d_m_s"),
                        ("uint8_t", "fix_type"), ("bool", "vel_ned_valid"), ("uint8_t", "satellites_used")]
VEHICLE_IMU = [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"), ("uint32_t", "accel_device_id"),
               ("uint32_t", "gyro_device_id"), ("float[3]", "delta_angle"), ("float[3]", "delta_velocity"),
               ("uint16_t", "delta_angle_dt"), ("uint16_t", "delta_velocity_dt"), ("uint8_t", "delta_angle_clipping"),
               ("uint8_t", "delta_velocity_clipping"), ("uint8_t", "accel_calibration_count"),
               ("uint8_t", "gyro_calibration_count")]
SENSOR_XYZ = [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"), ("uint32_t", "device_id"),
              ("float", "x"), ("float", "y"), ("float", "z"), ("float", "temperature")]
Q_TO_FIX = {1: 6, 2: 5, 4: 4, 5: 3}


class UlogWriter:
    """A minimal ULog writer (see the module docstring for the layout)."""

    def __init__(self, start_us: int = 0):
        self.out = bytearray(b"\x55\x4c\x6f\x67\x01\x12\x35" + bytes([1]) + struct.pack("<Q", start_us))
        self._message(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
        self.formats: dict[str, list[tuple[str, str]]] = {}
        self.subscriptions: dict[int, str] = {}

    def _message(self, kind: bytes, payload: bytes) -> None:
        self.out += struct.pack("<HB", len(payload), kind[0]) + payload

    def info(self, key: str, value: str) -> None:
        name = f"char[{len(value)}] {key}".encode()
        self._message(b"I", bytes([len(name)]) + name + value.encode())

    def format(self, name: str, fields: list[tuple[str, str]]) -> None:
        self.formats[name] = fields
        self._message(b"F", (name + ":" + "".join(f"{t} {n};" for t, n in fields)).encode())

    def subscribe(self, name: str, multi_id: int = 0) -> int:
        msg_id = len(self.subscriptions)
        self.subscriptions[msg_id] = name
        self._message(b"A", struct.pack("<BH", multi_id, msg_id) + name.encode())
        return msg_id

    def data(self, msg_id: int, values: dict[str, object]) -> None:
        payload = bytearray(struct.pack("<H", msg_id))
        for kind, name in self.formats[self.subscriptions[msg_id]]:
            base, _, count = kind.partition("[")
            n = int(count.rstrip("]")) if count else 1
            value = values.get(name, [0] * n if n > 1 else 0)
            items = list(value) if n > 1 else [value]  # type: ignore[arg-type]
            payload += struct.pack("<" + _PACK[base] * n, *items)
        self._message(b"D", bytes(payload))


@dataclass
class Excerpt:
    """The drive excerpt as every format holds it: integer microseconds of GPS time, float32 values."""

    imu_us: np.ndarray  # GPS time of each IMU sample [us since 1970, GPS calendar], before the -0.125 s offset
    force: np.ndarray  # (n, 3) [m/s^2], float32-exact
    rate: np.ndarray  # (n, 3) [rad/s], float32-exact
    gnss_us: np.ndarray
    latitude_deg: np.ndarray
    longitude_deg: np.ndarray
    height: np.ndarray
    quality: np.ndarray
    satellites: np.ndarray
    sigma_horizontal: np.ndarray  # float32-exact (eph)
    sigma_up: np.ndarray  # (epv)
    velocity_ned: np.ndarray  # float32-exact
    sigma_velocity: np.ndarray  # (s_variance_m_s)


def _f32(values: np.ndarray) -> np.ndarray:
    return np.asarray(values, dtype=np.float32).astype(float)


def excerpt(seconds: float | None = None) -> Excerpt:
    """The test excerpt (or its first ``seconds``), rounded to what the binary formats hold."""
    from modelgen.navigator.logs import ImuColumns, read_imu_csv, read_rtklib_pos

    imu = read_imu_csv(DATA / "excerpt_imu.csv.gz", ImuColumns(11, 1, (2, 3, 4), (5, 6, 7), "g", "rad/s"))
    gnss = read_rtklib_pos(DATA / "excerpt.pos")
    imu_keep = np.ones(len(imu.time), bool) if seconds is None else imu.time <= imu.time[0] + seconds
    gnss_keep = np.ones(len(gnss.time), bool) if seconds is None else gnss.time <= imu.time[0] + seconds
    return Excerpt(
        imu_us=np.round(imu.time[imu_keep] * 1e6).astype(np.int64), force=_f32(imu.specific_force[imu_keep]),
        rate=_f32(imu.angular_rate[imu_keep]), gnss_us=np.round(gnss.time[gnss_keep] * 1e6).astype(np.int64),
        latitude_deg=np.degrees(gnss.latitude[gnss_keep]), longitude_deg=np.degrees(gnss.longitude[gnss_keep]),
        height=gnss.height[gnss_keep], quality=gnss.quality[gnss_keep], satellites=gnss.satellites[gnss_keep],
        sigma_horizontal=_f32(gnss.sigma_position[gnss_keep, 0]), sigma_up=_f32(gnss.sigma_position[gnss_keep, 2]),
        velocity_ned=_f32(gnss.velocity[gnss_keep]), sigma_velocity=_f32(gnss.sigma_velocity[gnss_keep, 0]))


def write_csv(e: Excerpt, path: Path) -> None:
    """IMU CSV, 7 columns: time [s] (every digit of us / 1e6), specific force [m/s^2], rate [rad/s]."""
    lines = [",".join(repr(float(v)) for v in (t / 1e6, *f, *w))
             for t, f, w in zip(e.imu_us.tolist(), e.force.tolist(), e.rate.tolist())]
    path.write_text("\n".join(lines) + "\n")


def _calendar(us: int) -> str:
    whole, micro = divmod(us, 1_000_000)
    return clock.strftime("%Y/%m/%d %H:%M:%S", clock.gmtime(whole)) + f".{micro:06d}"


def write_pos(e: Excerpt, path: Path, quality: dict[int, int] | None = None) -> None:
    """RTKLIB lat/lon/height .pos with velocities, every digit of each value; Q remapped by ``quality``."""
    header = ("%  GPST  latitude(deg) longitude(deg) height(m) Q ns sdn(m) sde(m) sdu(m) sdne(m) sdeu(m) sdun(m) "
              "age(s) ratio vn(m/s) ve(m/s) vu(m/s) sdvn sdve sdvu sdvne sdveu sdvun")
    rows = [header]
    for k, us in enumerate(e.gnss_us.tolist()):
        q = int(e.quality[k]) if quality is None else quality[int(e.quality[k])]
        v, sh, sv = e.velocity_ned[k], e.sigma_horizontal[k], e.sigma_velocity[k]
        numbers = [e.latitude_deg[k], e.longitude_deg[k], e.height[k], q, e.satellites[k], sh, sh, e.sigma_up[k],
                   0, 0, 0, 0, 0, v[0], v[1], -v[2], sv, sv, sv, 0, 0, 0]
        rows.append(" ".join([_calendar(us)] + [str(int(x)) if i in (3, 4) else repr(float(x))
                                                for i, x in enumerate(numbers)]))
    path.write_text("\n".join(rows) + "\n")


def write_ulog(e: Excerpt, path: Path, boot_offset_us: int, gps_topic: str = "sensor_gps") -> None:
    """sensor_combined + sensor_gps (or vehicle_gps_position) on boot time = GPS time - ``boot_offset_us``."""
    w = UlogWriter(int(e.imu_us[0] - boot_offset_us))
    w.info("sys_name", "PX4")
    w.format("sensor_combined", SENSOR_COMBINED)
    w.format(gps_topic, SENSOR_GPS if gps_topic == "sensor_gps" else VEHICLE_GPS_POSITION)
    imu_id, gps_id = w.subscribe("sensor_combined"), w.subscribe(gps_topic)
    events = [(int(t), 0, k) for k, t in enumerate(e.imu_us)] + [(int(t), 1, k) for k, t in enumerate(e.gnss_us)]
    for t, kind, k in sorted(events):
        boot = t - boot_offset_us
        if kind == 0:
            w.data(imu_id, {"timestamp": boot, "gyro_rad": e.rate[k], "accelerometer_m_s2": e.force[k],
                            "gyro_integral_dt": 10000, "accelerometer_integral_dt": 10000})
            continue
        v = e.velocity_ned[k]
        fields = {"timestamp": boot + 50_000, "timestamp_sample": boot, "time_utc_usec": t - LEAP_2025_S * 1_000_000,
                  "eph": e.sigma_horizontal[k], "epv": e.sigma_up[k], "s_variance_m_s": e.sigma_velocity[k],
                  "vel_n_m_s": v[0], "vel_e_m_s": v[1], "vel_d_m_s": v[2], "fix_type": Q_TO_FIX[int(e.quality[k])],
                  "vel_ned_valid": True, "satellites_used": int(e.satellites[k])}
        if gps_topic == "sensor_gps":
            fields.update(latitude_deg=e.latitude_deg[k], longitude_deg=e.longitude_deg[k],
                          altitude_ellipsoid_m=e.height[k], altitude_msl_m=e.height[k] - 20.0)
        else:
            fields.update(timestamp=boot, lat=int(round(e.latitude_deg[k] * 1e7)),
                          lon=int(round(e.longitude_deg[k] * 1e7)), alt_ellipsoid=int(round(e.height[k] * 1e3)),
                          alt=int(round((e.height[k] - 20.0) * 1e3)))
        w.data(gps_id, fields)
    path.write_bytes(bytes(w.out))


def write_bag(e: Excerpt, path: Path, storage: str = "sqlite3") -> None:
    """/imu (sensor_msgs/Imu, the drive's IMU axes), /fix (NavSatFix), /fix_velocity (TwistWithCovarianceStamped,
    ENU); UTC stamps, received 2 ms after them."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    Header, Time = t["std_msgs/msg/Header"], t["builtin_interfaces/msg/Time"]
    Vector3, Quaternion = t["geometry_msgs/msg/Vector3"], t["geometry_msgs/msg/Quaternion"]
    Imu, NavSatFix, NavSatStatus = t["sensor_msgs/msg/Imu"], t["sensor_msgs/msg/NavSatFix"], t["sensor_msgs/msg/NavSatStatus"]
    Twist, TwistWithCovariance = t["geometry_msgs/msg/Twist"], t["geometry_msgs/msg/TwistWithCovariance"]
    TwistWithCovarianceStamped = t["geometry_msgs/msg/TwistWithCovarianceStamped"]

    def header(us: int, frame: str):
        ns = (us - LEAP_2025_S * 1_000_000) * 1000
        return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame)

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        imu_c = writer.add_connection("/imu", Imu.__msgtype__, typestore=store)
        fix_c = writer.add_connection("/fix", NavSatFix.__msgtype__, typestore=store)
        vel_c = writer.add_connection("/fix_velocity", TwistWithCovarianceStamped.__msgtype__, typestore=store)
        zero = np.zeros(9)
        events = [(int(u), 0, k) for k, u in enumerate(e.imu_us)] + [(int(u), 1, k) for k, u in enumerate(e.gnss_us)]
        for u, kind, k in sorted(events):
            received = (u - LEAP_2025_S * 1_000_000) * 1000 + 2_000_000
            if kind == 0:
                f, w = e.force[k], e.rate[k]
                msg = Imu(header=header(u, "imu_link"), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                          orientation_covariance=np.array([-1.0] + [0.0] * 8),
                          angular_velocity=Vector3(x=w[0], y=w[1], z=w[2]), angular_velocity_covariance=zero,
                          linear_acceleration=Vector3(x=f[0], y=f[1], z=f[2]), linear_acceleration_covariance=zero)
                writer.write(imu_c, received, store.serialize_cdr(msg, Imu.__msgtype__))
                continue
            status = {1: 2, 2: 2, 4: 2, 5: 0}[int(e.quality[k])]  # fixed/float/DGPS -> GBAS_FIX, single -> FIX
            sh, su = e.sigma_horizontal[k], e.sigma_up[k]
            fix = NavSatFix(header=header(u, "gnss"), status=NavSatStatus(status=status, service=1),
                            latitude=float(e.latitude_deg[k]), longitude=float(e.longitude_deg[k]),
                            altitude=float(e.height[k]), position_covariance=np.diag([sh * sh, sh * sh, su * su]).ravel(),
                            position_covariance_type=2)
            writer.write(fix_c, received, store.serialize_cdr(fix, NavSatFix.__msgtype__))
            v, sv = e.velocity_ned[k], e.sigma_velocity[k]
            covariance = np.zeros(36)
            covariance[[0, 7, 14]] = sv * sv
            twist = TwistWithCovarianceStamped(
                header=header(u, "gnss"),
                twist=TwistWithCovariance(twist=Twist(linear=Vector3(x=v[1], y=v[0], z=-v[2]),
                                                      angular=Vector3(x=0.0, y=0.0, z=0.0)), covariance=covariance))
            writer.write(vel_c, received, store.serialize_cdr(twist, TwistWithCovarianceStamped.__msgtype__))


def config_text(imu: str, gnss: str, quality_factor: str = "{1: 1.0, 2: 3.0, 5: 10.0}") -> str:
    """The excerpt's configuration with its imu: file/format keys and gnss: file/format keys replaced.

    ``imu`` and ``gnss`` are the YAML lines (two-space indented) that replace
    the file and column keys of each section.
    """
    text = (DATA / "excerpt.yaml").read_text()
    text = text.replace("  file: excerpt_imu.csv.gz     # relative to this file; gzip accepted\n"
                        "  columns: {count: 11, time: 1, accel: [2, 3, 4], gyro: [5, 6, 7]}   # 1-based\n"
                        "  units: {accel: g, gyro: rad/s}                  # g = 9.80665 m/s^2\n", imu)
    text = text.replace("  file: excerpt.pos       # RTKLIB lat/lon/height solution with velocities\n", gnss)
    text = text.replace("quality_factor: {1: 1.0, 2: 3.0, 5: 10.0}", f"quality_factor: {quality_factor}")
    assert "excerpt_imu" not in text and "excerpt.pos" not in text
    return text


CSV_IMU = ("  file: imu.csv\n  columns: {count: 7, time: 1, accel: [2, 3, 4], gyro: [5, 6, 7]}\n"
           "  units: {accel: m/s^2, gyro: rad/s}\n")
POS_GNSS = "  file: gnss.pos\n"
