"""The aiding-sensor table: one entry per sensor, a new sensor is one entry, odometer and barometer flown.

The odometer and barometer logs are written by the tests from the excerpt's own
RTK solution: wheel speed = |RTK velocity| (a car moves along its body x axis)
stamped at the velocity's latency, barometric height = RTK height plus 0.2 m
white noise (seeded).  Their sigmas (0.05 m/s, 0.3 m) are set from that noise
before any flight, not from outage errors.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from modelgen.errors import ModelError
from modelgen.navigator import cconfig
from modelgen.navigator.config import AidingSettings, load_config
from modelgen.navigator.logs import ScalarLog, read_gnss
from modelgen.navigator.metrics import COLUMN, errors_against_reference
from modelgen.navigator.sensors import FORMS, NHC, SENSORS, AidingSensor, compiled_condition, rows, stream_values
from modelgen.navigator.cconfig_fields import Field
from tests.navigator.qemu_support import needs_qemu_arm

pytestmark = pytest.mark.flight

DATA = Path(__file__).parent / "data"
ODOMETER_SIGMA_M_S, BAROMETER_SIGMA_M = 0.05, 0.3
#: IMU to a rear axle 1.2 m behind it and 0.5 m below it (body x forward, y right, z down) [m]
NHC_LEVER_ARM_M = (-1.2, 0.0, 0.5)


def test_the_table_has_one_entry_per_aiding_sensor():
    names = [s.name for s in SENSORS]
    assert names == ["gnss", "zupt", "nhc", "odometer", "barometer"]
    assert len({s.section for s in SENSORS}) == len(SENSORS)
    for sensor in SENSORS:
        assert sensor.form in FORMS
        compiled_condition(sensor)  # valid Python after the C -> Python reading
        for item in sensor.fields:
            assert item in cconfig.FIELDS  # its fields are in the one field list the C struct comes from


def test_every_entry_s_fields_reach_the_c_struct():
    struct = cconfig.c_struct("m", 1)
    for sensor in SENSORS:
        for item in sensor.fields:
            assert f" {item.name}" in struct


def _reference():
    config = load_config(DATA / "excerpt.yaml")
    return config, read_gnss(config.gnss_source)


def _write_odometer(path: Path, gnss, latency: float) -> None:
    rng = np.random.default_rng(26)
    speed = np.linalg.norm(gnss.velocity, axis=1) + rng.normal(0.0, 0.02, len(gnss.time))
    lines = ["time,speed_km_h"] + [f"{t - latency:.3f},{3.6 * v:.4f}" for t, v in zip(gnss.time, speed)]
    path.write_text("\n".join(lines) + "\n")


def _write_barometer(path: Path, gnss) -> None:
    rng = np.random.default_rng(27)
    height = gnss.height + rng.normal(0.0, 0.2, len(gnss.time))
    path.write_text("".join(f"{t:.3f},{h:.3f}\n" for t, h in zip(gnss.time, height)))


def _config_with(tmp_path: Path, extra: dict) -> Path:
    data = yaml.safe_load((DATA / "excerpt.yaml").read_text())
    data["imu"]["file"] = str(DATA / data["imu"]["file"])
    data["gnss"]["file"] = str(DATA / data["gnss"]["file"])
    data.pop("evaluation", None)
    data.update(extra)
    path = tmp_path / "nav.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def aided(tmp_path_factory):
    """The excerpt flown in C and Python without, with the odometer, and with the barometer."""
    from modelgen.navigator.replay import run_replay

    folder = tmp_path_factory.mktemp("aided")
    config, gnss = _reference()
    _write_odometer(folder / "odometer.csv", gnss, config.velocity_latency)
    _write_barometer(folder / "barometer.csv", gnss)
    odometer = {"odometer": {"enabled": True, "file": str(folder / "odometer.csv"), "units": "km/h",
                             "columns": {"time": 1, "value": 2}, "sigma_m_s": ODOMETER_SIGMA_M_S,
                             "lever_arm_m": [-1.2, 0.0, 0.5]}}
    barometer = {"barometer": {"enabled": True, "file": str(folder / "barometer.csv"), "sigma_m": BAROMETER_SIGMA_M}}
    nhc = {"nhc": {**yaml.safe_load((DATA / "excerpt.yaml").read_text())["nhc"], "lever_arm_m": list(NHC_LEVER_ARM_M)}}
    # the barometer is flown through one 40-s outage: over the excerpt's 15-s outage the height drifts 0.16 m
    # (NHC holds the vertical velocity), less than the barometer's own noise
    long = {"outages": {"windows": [[14.0, 40.0]]}}
    runs = {}
    for name, extra in (("none", {}), ("odometer", odometer), ("none_long", long),
                        ("barometer", {**long, **barometer}), ("nhc_lever_arm", nhc)):
        (folder / name).mkdir()
        runs[name] = run_replay(_config_with(folder / name, extra), None, echo=lambda _: None, navigator="both")
    return runs, gnss


def _outage_errors(result, gnss) -> dict[str, float]:
    """Horizontal and vertical error [m] at the last output epoch inside the outage, and their RMS over it."""
    errors = errors_against_reference(result.flight, gnss)
    inside = result.flight.outputs[:, COLUMN["in_outage"]] == 1.0
    end = np.flatnonzero(inside)[-1]
    return {"end_horizontal": float(errors.horizontal[end]), "end_up": float(abs(errors.up[end])),
            "rms_horizontal": float(np.sqrt(np.mean(errors.horizontal[inside] ** 2))),
            "rms_up": float(np.sqrt(np.mean(errors.up[inside] ** 2)))}


def test_the_odometer_improves_the_outage_end_in_c_and_python_alike(aided):
    runs, gnss = aided
    with_odometer, without = runs["odometer"], runs["none"]
    assert with_odometer.summary["counts"]["odometer_updates"] > 100
    assert without.summary["counts"]["odometer_updates"] == 0
    assert with_odometer.summary["c_python_max_difference_m"] <= 1e-3
    aided_errors, plain = _outage_errors(with_odometer, gnss), _outage_errors(without, gnss)
    # 2.83 m against 4.04 m at the end, 1.31 m against 2.45 m RMS over the outage when written
    assert aided_errors["end_horizontal"] < plain["end_horizontal"]
    assert aided_errors["rms_horizontal"] < plain["rms_horizontal"]


def test_the_barometer_improves_the_outage_end_height_in_c_and_python_alike(aided):
    runs, gnss = aided
    with_barometer, without = runs["barometer"], runs["none_long"]
    assert with_barometer.summary["counts"]["barometer_updates"] > 100
    assert with_barometer.summary["c_python_max_difference_m"] <= 1e-3
    aided_errors, plain = _outage_errors(with_barometer, gnss), _outage_errors(without, gnss)
    # 0.08 m against 1.47 m at the end, 0.23 m against 0.87 m RMS over the 40-s outage when written
    assert aided_errors["end_up"] < plain["end_up"]
    assert aided_errors["rms_up"] < plain["rms_up"]


def test_gnss_zupt_nhc_alone_fly_as_before_the_table(aided):
    """The excerpt with no odometer or barometer: the counts and the outage error of the excerpt's own test."""
    runs, _ = aided
    s = runs["none"].summary
    assert s["counts"]["gnss_updates"] == 240 - 60 - 55 and s["counts"]["nhc_updates"] == 552
    assert s["c_python_max_difference_m"] <= 1e-3


def _turn(heading: float, yaw_rate: float, speed: float, lever: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A car turning at a constant yaw rate, its rear axle (at ``lever`` from the IMU) rolling forward at ``speed``:
    the IMU's attitude C_b^n, NED velocity and body rate (v_imu = v_axle - omega x l)."""
    c, s = math.cos(heading), math.sin(heading)
    c_bn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    rate = np.array([0.0, 0.0, yaw_rate])
    v_body = np.array([speed, 0.0, 0.0]) - np.cross(rate, lever)
    return c_bn, c_bn @ v_body, rate


def test_nhc_with_the_rear_axle_s_lever_arm_has_zero_innovation_in_a_constant_rate_turn():
    """At 0.3 rad/s the IMU 1.2 m ahead of the axle slides 0.36 m/s sideways: the constraint at the IMU sees that
    as an innovation, the constraint at the axle (nhc.lever_arm_m) sees none."""
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.spec import navigator_spec

    spec = navigator_spec(model_path("ins_gps15_nav", DATA / "excerpt.yaml"))
    lever = np.array(NHC_LEVER_ARM_M)
    at_axle, at_imu = (cconfig.namespace({"nhc_lever_arm": list(arm)}) for arm in (lever, np.zeros(3)))
    for heading in np.linspace(0.0, 2.0 * math.pi, 7):
        c_bn, v_ned, rate = _turn(heading, 0.3, 8.0, lever)
        nav = np.r_[np.zeros(4), v_ned, np.zeros(3)]
        z_axle, H_axle = rows(NHC, spec, nav, c_bn, rate, 0.0, at_axle)
        z_imu, H_imu = rows(NHC, spec, nav, c_bn, rate, 0.0, at_imu)
        assert np.abs(z_axle).max() < 1e-12
        assert z_imu == pytest.approx([0.3 * 1.2, 0.0], abs=1e-12)
        assert np.array_equal(H_axle, H_imu)  # the lever-arm term is in z only (its gyro-bias error is neglected)


def test_the_nhc_lever_arm_is_flown_by_c_and_python_alike(aided):
    """nhc.lever_arm_m reaches both navigators (they agree) and changes the flight against the constraint at the IMU."""
    runs, _ = aided
    with_arm, without = runs["nhc_lever_arm"], runs["none"]
    assert with_arm.summary["c_python_max_difference_m"] <= 1e-3
    velocity = [COLUMN["v_north"], COLUMN["v_east"]]
    moved = np.abs(with_arm.flight.outputs[:, velocity] - without.flight.outputs[:, velocity]).max()
    assert moved > 1e-3  # [m/s]


def test_a_configuration_without_nhc_lever_arm_constrains_the_imu():
    config, _ = _reference()
    assert config.nhc_lever_arm == (0.0, 0.0, 0.0)
    assert cconfig.namespace(NHC.values(config)).nhc_lever_arm.tolist() == [0.0, 0.0, 0.0]


def test_a_new_sensor_is_one_table_entry(tmp_path):
    """A second height sensor (an 'altimeter'): one entry, its settings and log; flown in Python, it is used."""
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_imu
    from modelgen.navigator.navigator import fly, prepare
    from modelgen.navigator.spec import navigator_spec

    altimeter = AidingSensor(
        "altimeter", "altimeter", "altimeter", "height", ("cfg->altimeter_sigma",), "fresh", "altimeter_enabled",
        "a second height sensor",
        fields=(Field("altimeter_enabled", "int", 1, "on"), Field("altimeter_sigma", "double", 1, "sigma [m]")),
        values=stream_values("altimeter"))
    table = (*SENSORS, altimeter)
    config, gnss = _reference()
    config = dataclasses.replace(config, outage_schedule=None, outage_windows=[(14.0, 40.0)])  # as the barometer's
    inputs = prepare(config, read_imu(config.imu_source, config.gap_factor, config.gap_action), gnss)
    spec = navigator_spec(model_path(config.model, config.path))
    rng = np.random.default_rng(28)
    log = ScalarLog("altimeter.csv", "altimeter", gnss.time.copy(), gnss.height + rng.normal(0.0, 0.2, len(gnss.time)))
    aided_config = dataclasses.replace(config, aiding={**config.aiding, "altimeter": AidingSettings(
        "altimeter", True, tmp_path / "altimeter.csv", sigma=BAROMETER_SIGMA_M)})
    aided_inputs = dataclasses.replace(inputs, aiding={"altimeter": log})
    flown = fly(aided_config, aided_inputs, spec, table=table)
    plain = fly(config, inputs, spec)
    assert flown.counts["altimeter_updates"] > 100 and "altimeter_updates" not in plain.counts

    def rms_up(flight):
        inside = flight.outputs[:, COLUMN["in_outage"]] == 1.0
        return float(np.sqrt(np.mean(errors_against_reference(flight, gnss).up[inside] ** 2)))

    assert rms_up(flown) < rms_up(plain)


def test_an_enabled_sensor_without_its_log_is_refused_by_the_loop():
    from modelgen.navigator.navigator import Inputs, enabled_step_sensors

    cfg = cconfig.namespace({"zupt_enabled": 0, "nhc_enabled": 0, "odometer_enabled": 1, "barometer_enabled": 0})
    empty = Inputs(np.zeros(1), np.zeros((1, 3)), np.zeros((1, 3)), None, [], 0.0)  # type: ignore[arg-type]
    with pytest.raises(ModelError, match="odometer is enabled but no odometer log"):
        enabled_step_sensors(SENSORS, cfg, empty)


@pytest.mark.parametrize(("section", "body", "message"), [
    ("odometer", "  enabled: true\n  sigma_m_s: 0.05\n", "odometer is enabled but odometer.file names no log"),
    ("odometer", "  enabled: true\n  file: odo.csv\n", "odometer is enabled but odometer.sigma_m_s is not given"),
    ("odometer", "  enabled: true\n  file: odo.csv\n  sigma_m_s: 0.05\n  columns: {time: 2, value: 2}\n",
     "time and value are both column 2"),
    ("barometer", "  enabled: true\n  file: odo.csv\n  sigma_m: 0.5\n  pressure: 3\n", "unknown key 'pressure'"),
])
def test_a_bad_aiding_section_is_refused_with_its_line(tmp_path, section, body, message):
    (tmp_path / "odo.csv").write_text("1752003261.0,3.2\n")
    text = (DATA / "excerpt.yaml").read_text().replace("file: excerpt_imu.csv.gz", f"file: {DATA / 'excerpt_imu.csv.gz'}")
    text = text.replace("file: excerpt.pos", f"file: {DATA / 'excerpt.pos'}")
    line = text.count("\n") + 2
    path = tmp_path / "nav.yaml"
    path.write_text(text + f"{section}:\n" + body)
    with pytest.raises(ModelError) as refused:
        load_config(path)
    assert str(refused.value).startswith(f"{path}:") and message in str(refused.value)
    assert "\n" not in str(refused.value)
    if "both column" not in message and "unknown key" not in message:
        assert str(refused.value).startswith(f"{path}:{line}:")


def test_the_odometer_reader_converts_units_and_skips_a_header(tmp_path):
    from modelgen.navigator.logs import read_scalar

    (tmp_path / "o.csv").write_text("t,v\n# a comment\n1.0,36.0\n2.0,nan\n3.0,72.0\n")
    log = read_scalar("odometer", tmp_path / "o.csv", 1, 2, "km/h")
    assert np.allclose(log.value, [10.0, 20.0]) and list(log.time) == [1.0, 3.0]
    assert "1 odometer row(s)" in log.notes[0] and math.isfinite(log.value.sum())



@needs_qemu_arm
@pytest.mark.embedded
@pytest.mark.compile
def test_odometer_and_barometer_fly_under_qemu_arm_within_1_cm_of_the_double_c(tmp_path):
    """The qemu driver feeds the aiding logs too (it refused them): float filter against double C, 1 cm."""
    from modelgen.navigator.replay import run_replay

    config, gnss = _reference()
    _write_odometer(tmp_path / "odometer.csv", gnss, config.velocity_latency)
    _write_barometer(tmp_path / "barometer.csv", gnss)
    extra = {"odometer": {"enabled": True, "file": str(tmp_path / "odometer.csv"), "units": "km/h",
                          "columns": {"time": 1, "value": 2}, "sigma_m_s": ODOMETER_SIGMA_M_S,
                          "lever_arm_m": [-1.2, 0.0, 0.5]},
             "barometer": {"enabled": True, "file": str(tmp_path / "barometer.csv"), "sigma_m": BAROMETER_SIGMA_M}}
    result = run_replay(_config_with(tmp_path, extra), None, echo=lambda _: None, navigator="c", embedded=True)
    assert result.summary["counts"]["odometer_updates"] > 100 and result.summary["counts"]["barometer_updates"] > 100
    embedded = result.summary["embedded"]
    assert embedded["heap_or_stdio_symbols"] == []
    assert embedded["qemu_max_position_difference_m"] <= 0.01, embedded  # 1.2e-4 m when written
    # the report states the buffers this build got (sized from the configuration and the log), which the struct holds
    from modelgen.navigator.cnav import rest_capacity, window_capacity
    from modelgen.navigator.report import summary_markdown

    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare

    c = result.config
    time_ = prepare(c, read_imu(c.imu_source, c.gap_factor, c.gap_action), read_gnss(c.gnss_source)).time
    rest, window = embedded["rest_max_samples"], embedded["window_max_samples"]
    assert (rest, window) == (rest_capacity(c, time_), window_capacity(c, time_))
    assert embedded["navigator_struct_bytes"] >= rest * (7 * 8 + 1) + window * 2 * 8
    text = summary_markdown(result.summary, result.config, result.timings, result.config.velocity_latency)
    assert f"of which {rest * 7 * 8} B hold the last {rest} IMU samples" in text
    assert f"{window * 2 * 8} B the zero-velocity detector's window of {window})" in text
