"""PX4 ULog and ROS 2 bag logs: read to the same numbers as CSV/.pos, flown to the same trajectory, refused whole.

The logs are written in the test: ULog by the minimal writer of
log_writers_support (pyulog cannot write one from scratch), bags by rosbags'
own Writer.  The drive excerpt goes into every format with the same numbers
(see log_writers_support), so the readers must agree exactly.
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.navigator.config import load_config
from modelgen.navigator.logs import check_logs, read_gnss, read_imu
from tests.navigator import log_writers_support as W

pytest.importorskip("pyulog")
pytest.importorskip("rosbags")

ULOG_IMU = "  file: log.ulg\n  format: ulog\n"
ULOG_GNSS = "  file: log.ulg\n  format: ulog\n"
BAG_IMU = "  file: bag\n  format: ros2bag\n  topic: /imu\n"
BAG_GNSS = "  file: bag\n  format: ros2bag\n  topic: /fix\n  velocity_topic: /fix_velocity\n"
BAG_QUALITY = "{4: 1.0, 5: 10.0}"  # the bag's GBAS_FIX is Q 4 for RTK fixed and float alike
GNSS_FIELDS = ("time", "latitude", "longitude", "height", "sigma_position", "velocity", "sigma_velocity")


@pytest.fixture(scope="module")
def excerpt_logs(tmp_path_factory):
    """The drive excerpt in every format, with one configuration each (csv+pos, ulog, bag, pos for the bag)."""
    folder = tmp_path_factory.mktemp("formats")
    e = W.excerpt()
    W.write_csv(e, folder / "imu.csv")
    W.write_pos(e, folder / "gnss.pos")
    W.write_pos(e, folder / "gnss_bag_quality.pos", quality={1: 4, 2: 4, 5: 5})
    W.write_ulog(e, folder / "log.ulg", boot_offset_us=int(e.imu_us[0]) - 5_000_000)
    W.write_bag(e, folder / "bag")
    configs = {"csv": W.config_text(W.CSV_IMU, W.POS_GNSS), "ulog": W.config_text(ULOG_IMU, ULOG_GNSS),
               "bag": W.config_text(BAG_IMU, BAG_GNSS, BAG_QUALITY),
               "csv_bag_quality": W.config_text(W.CSV_IMU, "  file: gnss_bag_quality.pos\n", BAG_QUALITY)}
    for name, text in configs.items():
        (folder / f"{name}.yaml").write_text(text)
    return folder


def _read(path: Path):
    config = load_config(path)
    return read_imu(config.imu_source, config.gap_factor, config.gap_action), read_gnss(config.gnss_source)


def test_a_ulog_of_the_excerpt_reads_to_exactly_the_csv_and_pos_numbers(excerpt_logs):
    (imu_a, gnss_a), (imu_b, gnss_b) = _read(excerpt_logs / "csv.yaml"), _read(excerpt_logs / "ulog.yaml")
    assert np.array_equal(imu_a.time, imu_b.time)  # boot microseconds tied to GPS time through time_utc_usec
    assert np.array_equal(imu_a.specific_force, imu_b.specific_force)
    assert np.array_equal(imu_a.angular_rate, imu_b.angular_rate)
    for name in GNSS_FIELDS + ("quality", "satellites"):
        assert np.array_equal(getattr(gnss_a, name), getattr(gnss_b, name)), name
    assert imu_b.where(0).endswith("log.ulg: sensor_combined message 1")


def test_a_ros2_bag_of_the_excerpt_reads_to_exactly_the_csv_and_pos_numbers(excerpt_logs):
    (imu_a, gnss_a), (imu_b, gnss_b) = _read(excerpt_logs / "csv.yaml"), _read(excerpt_logs / "bag.yaml")
    assert np.array_equal(imu_a.time, imu_b.time)  # UTC header stamps put back on GPS time
    assert np.array_equal(imu_a.specific_force, imu_b.specific_force)
    assert np.array_equal(imu_a.angular_rate, imu_b.angular_rate)
    for name in GNSS_FIELDS:
        assert np.array_equal(getattr(gnss_a, name), getattr(gnss_b, name)), name
    assert set(gnss_b.quality.tolist()) == {4}  # GBAS_FIX


@pytest.mark.flight
def test_the_ulog_and_the_bag_fly_the_same_trajectory_as_the_csv_and_pos(excerpt_logs):
    from modelgen.navigator.metrics import COLUMN
    from modelgen.navigator.replay import run_replay

    flights = {name: run_replay(excerpt_logs / f"{name}.yaml", None, echo=lambda _: None).flight
               for name in ("csv", "ulog", "bag", "csv_bag_quality")}
    assert flights["csv"].outputs.shape[0] > 150
    assert np.array_equal(flights["csv"].outputs, flights["ulog"].outputs, equal_nan=True)  # NIS is NaN in outages
    same = [i for name, i in COLUMN.items() if name != "gnss_quality"]
    assert np.array_equal(flights["csv_bag_quality"].outputs[:, same], flights["bag"].outputs[:, same], equal_nan=True)


def test_an_mcap_bag_file_reads_like_the_sqlite_bag(tmp_path, excerpt_logs):
    e = W.excerpt(seconds=3.0)
    W.write_bag(e, tmp_path / "bag", storage="mcap")
    mcap = next((tmp_path / "bag").glob("*.mcap"))
    text = W.config_text(f"  file: {mcap}\n  format: ros2bag\n  topic: /imu\n",
                         f"  file: {mcap}\n  format: ros2bag\n  topic: /fix\n  velocity_topic: /fix_velocity\n",
                         BAG_QUALITY)
    (tmp_path / "mcap.yaml").write_text(text)
    imu, gnss = _read(tmp_path / "mcap.yaml")
    assert np.array_equal(imu.time, e.imu_us / 1e6) and len(gnss.time) == len(e.gnss_us)


def test_old_ulog_gps_fields_in_integer_units_are_scaled(tmp_path):
    e = W.excerpt(seconds=3.0)
    W.write_ulog(e, tmp_path / "log.ulg", boot_offset_us=int(e.imu_us[0]) - 1_000_000,
                 gps_topic="vehicle_gps_position")
    (tmp_path / "nav.yaml").write_text(W.config_text(ULOG_IMU, ULOG_GNSS))
    imu, gnss = _read(tmp_path / "nav.yaml")
    assert np.degrees(gnss.latitude) == pytest.approx(np.round(e.latitude_deg * 1e7) * 1e-7, abs=1e-12)
    assert gnss.height == pytest.approx(e.height, abs=5e-4)  # millimetres
    # without timestamp_sample the boot clock is tied through the receive timestamp
    assert np.array_equal(imu.time, e.imu_us / 1e6)


def _ulog(tmp_path, gps_rows, imu_topic="sensor_combined", name="log.ulg", skip=()):
    """A short ULog: 300 IMU samples at 100 Hz in the chosen topic(s) (but those in ``skip``) and sensor_gps rows."""
    w = W.UlogWriter(0)
    formats = {"sensor_combined": W.SENSOR_COMBINED, "vehicle_imu": W.VEHICLE_IMU}
    topics = ["sensor_gyro", "sensor_accel"] if imu_topic == "sensor_gyro+sensor_accel" else [imu_topic]
    for topic in topics:
        w.format(topic, formats.get(topic, W.SENSOR_XYZ))
    w.format("sensor_gps", W.SENSOR_GPS)
    ids = {topic: w.subscribe(topic) for topic in topics}
    gps = w.subscribe("sensor_gps")
    rate, force = [0.01, -0.02, 0.03], [0.1, 0.2, -9.8]
    for k in range(300):
        if k in skip:
            continue
        t = 1_000_000 + 10_000 * k
        if imu_topic == "sensor_combined":
            w.data(ids[imu_topic], {"timestamp": t, "gyro_rad": rate, "accelerometer_m_s2": force})
        elif imu_topic == "vehicle_imu":
            w.data(ids[imu_topic], {"timestamp": t + 300, "timestamp_sample": t, "delta_angle_dt": 5000,
                                    "delta_velocity_dt": 5000, "delta_angle": [r * 0.005 for r in rate],
                                    "delta_velocity": [f * 0.005 for f in force]})
        else:
            w.data(ids["sensor_gyro"], {"timestamp": t, "timestamp_sample": t, "x": rate[0], "y": rate[1],
                                        "z": rate[2]})
            w.data(ids["sensor_accel"], {"timestamp": t + 1000, "timestamp_sample": t + 1000, "x": force[0],
                                         "y": force[1], "z": force[2]})
    for row in gps_rows:
        w.data(gps, row)
    (tmp_path / name).write_bytes(bytes(w.out))
    return tmp_path / name


def _gps_row(k: int, fix: int = 6, utc: bool = True):
    boot = 1_000_000 + 250_000 * k
    return {"timestamp": boot, "timestamp_sample": boot, "time_utc_usec": (1751998000_000_000 + boot) if utc else 0,
            "latitude_deg": 40.0, "longitude_deg": -105.0, "altitude_ellipsoid_m": 1600.0, "eph": 0.5, "epv": 0.8,
            "s_variance_m_s": 0.1, "vel_n_m_s": 1.0, "fix_type": fix, "vel_ned_valid": True, "satellites_used": 12}


def _source(section: str, path: Path, fmt: str, **options):
    from modelgen.navigator.logs import source_from_config

    return source_from_config(section, {"file": str(path), "format": fmt, **options}, lambda key: "nav.yaml",
                              path.parent)


@pytest.mark.parametrize("topic", ["sensor_combined", "vehicle_imu", "sensor_gyro+sensor_accel"])
def test_each_ulog_imu_topic_gives_rates_and_specific_force_in_si(tmp_path, topic):
    path = _ulog(tmp_path, [_gps_row(k) for k in range(12)], imu_topic=topic)
    imu = read_imu(_source("imu", path, "ulog", topic=topic), 3.0, "refuse")
    assert len(imu.time) == 300
    assert np.allclose(imu.angular_rate, [0.01, -0.02, 0.03], rtol=1e-6)
    assert np.allclose(imu.specific_force, [0.1, 0.2, -9.8], rtol=1e-6)
    assert imu.time[1] - imu.time[0] == pytest.approx(0.01, abs=3e-7)  # float64 seconds since 1970: 0.24 us steps
    assert imu.time[0] == pytest.approx(1751998000.0 + 18.0 + 1.0, abs=1e-6)  # boot 1 s + UTC + 18 s leap


def test_an_imu_gap_in_a_ulog_is_refused_naming_its_message(tmp_path):
    path = _ulog(tmp_path, [_gps_row(k) for k in range(12)], skip=range(100, 150))
    with pytest.raises(ModelError, match=r"log\.ulg: sensor_combined message 101: IMU gap of 0\.510 s"):
        read_imu(_source("imu", path, "ulog"), 3.0, "refuse")
    imu = read_imu(_source("imu", path, "ulog"), 3.0, "propagate")
    assert [round(g.length, 3) for g in imu.gaps] == [0.51]


def test_ulog_fix_types_map_to_rtklib_quality_and_epochs_without_a_fix_are_noted(tmp_path):
    fixes = [0, 1, 2, 3, 4, 5, 6, 8]
    path = _ulog(tmp_path, [_gps_row(k, fix) for k, fix in enumerate(fixes)])
    gnss = read_gnss(_source("gnss", path, "ulog"))
    assert gnss.quality.tolist() == [5, 4, 2, 1]
    assert gnss.sigma_position[0].tolist() == [0.5, 0.5, pytest.approx(0.8)]
    notes = " ".join(gnss.notes)
    assert "2 sensor_gps message(s) without a fix" in notes and "1 sensor_gps message(s) with a 2-D fix" in notes
    assert "fix_type that is not a measurement" in notes


def test_a_ulog_with_no_fix_at_all_is_refused_as_such(tmp_path):
    path = _ulog(tmp_path, [_gps_row(k, fix=1) for k in range(12)])
    gnss = read_gnss(_source("gnss", path, "ulog", time_base="boot"))
    imu = read_imu(_source("imu", path, "ulog", time_base="boot"), 3.0, "refuse")
    with pytest.raises(ModelError, match=r"log\.ulg: no GNSS fix at all"):
        check_logs(imu, gnss, {1: 1.0}, 0.0)


def test_a_ulog_without_gnss_time_is_refused_unless_flown_on_boot_time(tmp_path):
    path = _ulog(tmp_path, [_gps_row(k, utc=False) for k in range(12)])
    with pytest.raises(ModelError, match=r"no GNSS time \(time_utc_usec is 0 throughout\): set time_base: boot"):
        read_imu(_source("imu", path, "ulog"), 3.0, "refuse")
    with pytest.raises(ModelError, match=r"no GNSS time"):
        read_gnss(_source("gnss", path, "ulog"))
    imu = read_imu(_source("imu", path, "ulog", time_base="boot"), 3.0, "refuse")
    gnss = read_gnss(_source("gnss", path, "ulog", time_base="boot"))
    assert imu.time[0] == 1.0 and gnss.time[0] == 1.0 and imu.time_scale == gnss.time_scale == "boot"
    with_time = _ulog(tmp_path, [_gps_row(k) for k in range(12)], name="timed.ulg")
    with pytest.raises(ModelError, match=r"GNSS times are GPST but the IMU's .* are boot"):
        check_logs(imu, read_gnss(_source("gnss", with_time, "ulog")), {1: 1.0}, 0.0)


def _definitions(*messages: tuple[bytes, bytes]) -> bytes:
    out = bytearray(W.UlogWriter(0).out)
    for kind, payload in messages:
        out += struct.pack("<HB", len(payload), kind[0]) + payload
    return bytes(out)


@pytest.mark.parametrize("content, message", [
    (b"", r"not a ULog file"),
    (b"PK\x03\x04 this is a zip file, not a ULog", r"not a ULog file"),
    (_definitions((b"F", b"a:a x;"), (b"A", b"\x00\x00\x00a")), r"format 'a' nests itself"),
    (_definitions((b"F", b"b:uint8_t[100] x;"), (b"F", b"c:b[1000] y;")), r"format 'c' has more than 4096 fields"),
    (_definitions((b"F", b"a:uint8_t[70000] x;")), r"array size 70000"),
    (_definitions((b"Z", b"\x00" * 5)), r"damaged definitions section at byte 59"),
    (_definitions((b"F", b"x" * 100))[:-20], r"damaged definitions section"),
])
def test_a_corrupt_or_hostile_ulog_is_one_refusal(tmp_path, content, message):
    path = tmp_path / "bad.ulg"
    path.write_bytes(content)
    with pytest.raises(ModelError, match=message):
        read_imu(_source("imu", path, "ulog"), 3.0, "refuse")


def test_a_ulog_with_damaged_data_or_without_the_topic_is_refused(tmp_path):
    good = _ulog(tmp_path, [_gps_row(k) for k in range(12)]).read_bytes()
    damaged = tmp_path / "damaged.ulg"
    damaged.write_bytes(good[:3000] + b"\xff" * 64 + good[3000:])
    with pytest.raises(ModelError, match=r"damaged\.ulg: corrupt ULog: damaged data section at byte \d+ "
                                         r"\(message type 0xff\)"):
        read_imu(_source("imu", damaged, "ulog"), 3.0, "refuse")
    damaged.write_bytes(good + struct.pack("<HBH", 2, ord("D"), 99))  # data of a topic never subscribed
    with pytest.raises(ModelError, match=r"damaged\.ulg: corrupt ULog \(pyulog found damaged data: Warning: no "
                                         r"subscription found for message id 99"):
        read_imu(_source("imu", damaged, "ulog"), 3.0, "refuse")
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(good[:-5])  # a recording stopped inside its last message: read, and noted
    imu = read_imu(_source("imu", cut, "ulog"), 3.0, "refuse")
    assert any("the log ends inside a message" in note for note in imu.notes)
    with pytest.raises(ModelError, match=r"no ULog topic 'vehicle_imu' instance 0 \(present: "):
        read_imu(_source("imu", tmp_path / "log.ulg", "ulog", topic="vehicle_imu"), 3.0, "refuse")


def test_a_bag_that_is_not_a_bag_or_lacks_the_topic_is_one_refusal(tmp_path, excerpt_logs):
    fake = tmp_path / "fake.db3"
    fake.write_bytes(b"SQLite format 3\x00" + b"\x13" * 4000)
    with pytest.raises(ModelError, match=r"fake\.db3: cannot be opened as a ROS 2 bag"):
        read_imu(_source("imu", fake, "ros2bag", topic="/imu"), 3.0, "refuse")
    folder = tmp_path / "empty_bag"
    folder.mkdir()
    with pytest.raises(ModelError, match=r"empty_bag: cannot be opened as a ROS 2 bag"):
        read_imu(_source("imu", folder, "ros2bag", topic="/imu"), 3.0, "refuse")
    bag = excerpt_logs / "bag"
    with pytest.raises(ModelError, match=r"no topic '/imu/data' in the bag \(topics: /fix \(sensor_msgs/msg/NavSatFix\)"):
        read_imu(_source("imu", bag, "ros2bag", topic="/imu/data"), 3.0, "refuse")
    with pytest.raises(ModelError, match=r"topic '/fix' carries sensor_msgs/msg/NavSatFix, not sensor_msgs/msg/Imu"):
        read_imu(_source("imu", bag, "ros2bag", topic="/fix"), 3.0, "refuse")


def test_a_bag_whose_storage_is_damaged_is_one_refusal(tmp_path):
    W.write_bag(W.excerpt(seconds=2.0), tmp_path / "bag")
    db3 = next((tmp_path / "bag").glob("*.db3"))
    data = bytearray(db3.read_bytes())
    data[len(data) // 2:] = b"\x00" * (len(data) - len(data) // 2)
    db3.write_bytes(bytes(data))
    with pytest.raises(ModelError, match=r"bag: (cannot be opened as a ROS 2 bag|damaged ROS 2 bag|/imu message)"):
        read_imu(_source("imu", tmp_path / "bag", "ros2bag", topic="/imu"), 3.0, "refuse")


def _bag(tmp_path, fixes, covariance_type=2, velocity=True):
    """A bag with 300 IMU messages and the given (status, stamp_s) NavSatFix messages."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    def header(seconds: float):
        ns = int(round(seconds * 1e9))
        return t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                                        frame_id="x")
    v3, zero = t["geometry_msgs/msg/Vector3"], np.zeros(9)
    with Writer(tmp_path / "bag", version=9) as writer:
        imu_c = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
        fix_c = writer.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=store)
        vel_c = writer.add_connection("/vel", "geometry_msgs/msg/TwistStamped", typestore=store)
        for k in range(300):
            covariance = np.array([-1.0] + [0.0] * 8) if k == 5 else zero  # message 6 has no angular velocity
            msg = t["sensor_msgs/msg/Imu"](header=header(1751998000 + 0.01 * k),
                                           orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                                           orientation_covariance=zero, angular_velocity=v3(x=0.1, y=0.0, z=0.0),
                                           angular_velocity_covariance=covariance,
                                           linear_acceleration=v3(x=0.0, y=0.0, z=9.8),
                                           linear_acceleration_covariance=zero)
            writer.write(imu_c, k + 1, store.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
        for k, (status, stamp) in enumerate(fixes):
            fix = t["sensor_msgs/msg/NavSatFix"](header=header(stamp),
                                                 status=t["sensor_msgs/msg/NavSatStatus"](status=status, service=1),
                                                 latitude=40.0, longitude=-105.0, altitude=1600.0,
                                                 position_covariance=np.diag([0.04, 0.09, 0.16]).ravel(),
                                                 position_covariance_type=covariance_type)
            writer.write(fix_c, 1000 + k, store.serialize_cdr(fix, "sensor_msgs/msg/NavSatFix"))
            if velocity:
                twist = t["geometry_msgs/msg/TwistStamped"](header=header(stamp), twist=t["geometry_msgs/msg/Twist"](
                    linear=v3(x=2.0, y=1.0, z=0.5), angular=v3(x=0.0, y=0.0, z=0.0)))
                writer.write(vel_c, 1000 + k, store.serialize_cdr(twist, "geometry_msgs/msg/TwistStamped"))
    return tmp_path / "bag"


def test_bag_fix_status_covariance_and_enu_twist_are_read_as_documented(tmp_path):
    bag = _bag(tmp_path, [(-1, 1751998000.5), (0, 1751998000.75), (1, 1751998001.0), (2, 1751998001.25)])
    gnss = read_gnss(_source("gnss", bag, "ros2bag", topic="/fix", velocity_topic="/vel", sigma_velocity_m_s=0.2))
    assert gnss.quality.tolist() == [5, 3, 4]
    assert gnss.sigma_position[0].tolist() == [0.3, 0.2, 0.4]  # ENU covariance diag: east 0.04, north 0.09
    assert gnss.velocity[0].tolist() == [1.0, 2.0, -0.5]  # ENU twist (2, 1, 0.5) as north, east, down
    assert gnss.sigma_velocity[0].tolist() == [0.2, 0.2, 0.2]
    assert gnss.time[0] - 1751998000.75 == pytest.approx(18.0, abs=1e-6)  # UTC stamp + 18 s
    assert any("1 /fix message(s) with status NO_FIX not used" in note for note in gnss.notes)
    imu = read_imu(_source("imu", bag, "ros2bag", topic="/imu"), 3.0, "propagate")
    assert len(imu.time) == 299 and any("covariance[0] = -1" in note for note in imu.notes)
    with pytest.raises(ModelError, match=r"/vel message 1 carries no velocity covariance: set gnss\.sigma_velocity_m_s"):
        read_gnss(_source("gnss", bag, "ros2bag", topic="/fix", velocity_topic="/vel"))


def test_a_bag_without_fix_or_covariance_is_refused_as_such(tmp_path):
    bag = _bag(tmp_path, [(-1, 1751998000.5 + 0.25 * k) for k in range(8)])
    gnss = read_gnss(_source("gnss", bag, "ros2bag", topic="/fix", velocity_topic="/vel", sigma_velocity_m_s=0.2))
    imu = read_imu(_source("imu", bag, "ros2bag", topic="/imu"), 3.0, "propagate")
    with pytest.raises(ModelError, match=r"bag: no GNSS fix at all"):
        check_logs(imu, gnss, {4: 1.0}, 0.0)
    other = tmp_path / "other"
    other.mkdir()
    bag = _bag(other, [(2, 1751998000.5)], covariance_type=0)
    with pytest.raises(ModelError, match=r"/fix message 1 has no position covariance .*gnss\.sigma_position_m"):
        read_gnss(_source("gnss", bag, "ros2bag", topic="/fix"))


def test_without_the_logs_extra_the_refusal_names_it(tmp_path, monkeypatch):
    path = _ulog(tmp_path, [_gps_row(k) for k in range(3)])
    monkeypatch.setitem(sys.modules, "pyulog", None)
    with pytest.raises(ModelError, match=r"reading a PX4 ULog needs pyulog \(pip install 'modelgen-nav\[logs\]'\)"):
        read_imu(_source("imu", path, "ulog"), 3.0, "refuse")
    monkeypatch.setitem(sys.modules, "rosbags.typesys", None)
    with pytest.raises(ModelError, match=r"reading a ROS 2 bag needs rosbags \(pip install 'modelgen-nav\[logs\]'\)"):
        read_imu(_source("imu", tmp_path, "ros2bag", topic="/imu"), 3.0, "refuse")


def test_each_format_keys_are_checked_against_the_chosen_format(tmp_path):
    (tmp_path / "log.ulg").write_bytes(b"")
    base = W.config_text(ULOG_IMU, ULOG_GNSS)
    cases = {
        "  format: ulog\n  columns: {count: 7}\n": r"imu\.columns is a key of the csv format\(s\), not of ulog",
        "  format: xml\n": r"imu\.format 'xml' is not one of csv, ulog, ros2bag",
        "  format: ulog\n  topic: sensor_mag\n": r"imu\.topic 'sensor_mag' cannot be parsed \(accepted: sensor_combined",
        "  format: rtklib_pos\n": r"imu\.format 'rtklib_pos' is not one of csv, ulog, ros2bag",
        "  format: ros2bag\n": r"missing key 'imu\.topic'",
    }
    for replacement, message in cases.items():
        (tmp_path / "nav.yaml").write_text(base.replace(ULOG_IMU, "  file: log.ulg\n" + replacement, 1))
        with pytest.raises(ModelError, match=rf"nav\.yaml:\d+: .*{message}"):
            load_config(tmp_path / "nav.yaml")


def test_every_format_and_each_of_its_keys_is_documented():
    from modelgen.navigator.logs import FORMATS

    text = (Path(__file__).resolve().parents[2] / "docs" / "log-formats.md").read_text(encoding="utf-8")
    for fmt in FORMATS.values():
        assert f"`{fmt.name}`" in text, fmt.name
        for option in fmt.imu_options + fmt.gnss_options:
            assert f"`{option.key}`" in text, f"{fmt.name}: {option.key}"
