"""The navigator: mechanization physics, the outage schedule, and a 60 s excerpt of the drive flown."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from modelgen.navigator.mechanization import NAV_SIZE, dcm_to_quaternion, euler_to_dcm, gravity, mechanize
from modelgen.navigator.outages import outage_windows
from modelgen.model.wgs84 import EARTH_RATE
from tests.navigator.qemu_support import needs_qemu_arm

pytestmark = pytest.mark.flight

DATA = Path(__file__).parent / "data"


def _drive_rates():
    """The generated mechanization rates of the drive's NED model (ins_gps15_nav), compiled."""
    from modelgen.navigator.spec import navigator_spec
    from modelgen.fileio.datafiles import package_path

    return navigator_spec(package_path("navigator", "models", "ins_gps15_nav.yaml")).rates


def test_mechanization_at_rest_with_ideal_sensors_stays_at_rest():
    """Level, heading 30 deg, sensing exactly -g and the earth rate: 60 s at 100 Hz drift < 1 mm/s."""
    lat, h, yaw = math.radians(40.0), 1600.0, math.radians(30.0)
    c_bn = euler_to_dcm(0.0, 0.0, yaw)
    rate_n = np.array([EARTH_RATE * math.cos(lat), 0.0, -EARTH_RATE * math.sin(lat)])
    n = 6001
    time = np.arange(n) * 0.01
    force = np.tile(c_bn.T @ np.array([0.0, 0.0, -gravity(lat, h)]), (n, 1))
    rate = np.tile(c_bn.T @ rate_n, (n, 1))
    nav = np.zeros(NAV_SIZE)
    nav[0:4] = dcm_to_quaternion(c_bn)
    nav[7], nav[9] = lat, h
    mechanize(nav, np.zeros(6), time, force, rate, 1, n, np.zeros(3), np.zeros(3), np.zeros(4), np.zeros(3), np.zeros(3),
              _drive_rates())
    assert np.abs(nav[4:7]).max() < 1e-3
    assert abs(nav[7] - lat) * 6.37e6 < 0.03 and abs(nav[9] - h) < 0.03


def test_mechanize_flies_a_second_models_rates_after_the_first_models_are_freed():
    """Run-time compiled rates in one process, each freed before the next is flown (as when a process flies one
    model, then another): the same flight each time.  (The suite once failed here when mechanize kept a disk cache:
    numba pickled its index with a freed function's type in it; this does not reproduce that on its own.)"""
    import gc

    from modelgen.fileio.datafiles import package_path
    from modelgen.navigator.mechanization import model_rates
    from modelgen.navigator.spec import navigator_spec

    source = navigator_spec(package_path("navigator", "models", "ins_gps15_nav.yaml"), with_python=False).rates_python
    lat, h, n = math.radians(40.0), 1600.0, 101
    time = np.arange(n) * 0.01
    force = np.tile([0.0, 0.0, -gravity(lat, h)], (n, 1))
    rate = np.tile([EARTH_RATE * math.cos(lat), 0.0, -EARTH_RATE * math.sin(lat)], (n, 1))
    finals = []
    for name in ("first", "second", "third"):
        rates = model_rates(source, name)
        nav = np.zeros(NAV_SIZE)
        nav[0], nav[7], nav[9] = 1.0, lat, h
        mechanize(nav, np.zeros(6), time, force, rate, 1, n, np.zeros(3), np.zeros(3), np.zeros(4), np.zeros(3),
                  np.zeros(3), rates)
        finals.append(nav)
        del rates
        gc.collect()
    assert np.array_equal(finals[0], finals[1]) and np.array_equal(finals[1], finals[2])


def test_mechanization_integrates_a_constant_forward_acceleration():
    """1 m/s^2 forward (north) for 10 s from rest: 10 m/s and 50 m, to the earth-rate terms."""
    lat, h = math.radians(40.0), 1600.0
    n = 1001
    time = np.arange(n) * 0.01
    g = gravity(lat, h)
    force = np.tile([1.0, 0.0, -g], (n, 1))
    rate_n = np.array([EARTH_RATE * math.cos(lat), 0.0, -EARTH_RATE * math.sin(lat)])
    rate = np.tile(rate_n, (n, 1))
    nav = np.zeros(NAV_SIZE)
    nav[0] = 1.0
    nav[7], nav[9] = lat, h
    mechanize(nav, np.zeros(6), time, force, rate, 1, n, np.zeros(3), np.zeros(3), np.zeros(4), np.zeros(3), np.zeros(3),
              _drive_rates())
    assert nav[4] == pytest.approx(10.0, abs=0.01)
    assert (nav[7] - lat) * 6.363e6 == pytest.approx(50.0, rel=2e-3)


def test_the_anchor_outage_schedule_gives_eleven_outages_on_the_drive():
    windows = outage_windows({"first_after_s": 40.0, "length_s": 15.0, "period_s": 45.0, "end_margin_s": 30.0},
                             None, 0.0, 549.0)
    assert len(windows) == 11
    assert windows[0] == (40.0, 55.0) and windows[-1] == (490.0, 505.0)


@pytest.fixture(scope="module")
def excerpt_flight():
    from modelgen.navigator.replay import run_replay

    return run_replay(DATA / "excerpt.yaml", None, echo=lambda _: None)


def test_excerpt_outage_error_is_within_its_band(excerpt_flight):
    """The drive's first outage (starts 0.25 s after the heading is set): end error 4.07 m when written.

    Band: at most 6 m at the end (the anchor's RMS over all outages is 7.44 m) and at
    least 0.5 m (a navigator that secretly saw GNSS in the outage would end near 0).
    """
    s = excerpt_flight.summary
    assert s["outage_count"] == 1
    record = s["outages"][0]
    assert record["start_s"] == 14.0 and record["duration_s"] == 15.0
    assert 0.5 <= record["horizontal_error_end_m"] <= 6.0
    assert s["horizontal_rms_outside_outages_m"] <= 0.10


def test_excerpt_uses_gnss_only_outside_the_outage(excerpt_flight):
    from modelgen.navigator.metrics import COLUMN

    o = excerpt_flight.flight.outputs
    inside = o[:, COLUMN["in_outage"]] == 1
    assert inside.sum() == 60  # 15 s at 4 Hz
    assert not o[inside, COLUMN["gnss_used"]].any()
    assert o[~inside, COLUMN["gnss_used"]].all()


def test_replay_cli_writes_the_report_files(tmp_path):
    from click.testing import CliRunner

    from modelgen.cli import main

    out = tmp_path / "replay"
    result = CliRunner().invoke(main, ["replay", str(DATA / "excerpt.yaml"), "--out", str(out), "--no-figures"])
    assert result.exit_code == 0, result.output
    assert "1 outages: end-of-outage horizontal error RMS" in result.output
    import json

    summary = json.loads((out / "summary.json").read_text())
    keys = {"start_s", "duration_s", "distance_m", "horizontal_error_end_m", "error_3d_end_m",
            "horizontal_error_max_m", "sigma_horizontal_end_m"}
    assert keys <= set(summary["outages"][0])
    pos = (out / "trajectory.pos").read_text().splitlines()
    assert pos[0].startswith("%") and len([line for line in pos if not line.startswith("%")]) == len(
        (out / "trajectory.csv").read_text().splitlines()) - 1
    assert "| 1 | 14.0 | 15.0 |" in (out / "summary.md").read_text()


@pytest.fixture(scope="module")
def excerpt_both():
    from modelgen.navigator.replay import run_replay

    return run_replay(DATA / "excerpt.yaml", None, echo=lambda _: None, navigator="both")


@pytest.mark.compile
def test_c_navigator_agrees_with_the_python_navigator_within_1_mm(excerpt_both):
    """Generated C (compiled strictly) against the Python reference at every output epoch of the excerpt."""
    assert excerpt_both.summary["navigator"] == "c"
    assert excerpt_both.summary["c_python_max_difference_m"] <= 1e-3


@pytest.mark.compile
def test_a_model_without_scale_factor_states_reports_none_and_draws_no_scale_factor_figure(excerpt_both):
    """The 15-state model holds its scale factors at 0: the summary states no estimate of them, the report no figure."""
    from modelgen.navigator.metrics import COLUMN

    assert excerpt_both.flight.estimated == ("gyro_bias", "accel_bias")
    assert "final_gyro_scale_factor_ppm" not in excerpt_both.summary
    assert np.all(excerpt_both.flight.outputs[:, COLUMN["gyro_scale_factor_x"]:COLUMN["accel_scale_factor_z"] + 1] == 0)
    assert excerpt_both.folder is None or not (excerpt_both.folder / "scale_factors.svg").exists()


@pytest.mark.compile
def test_c_navigator_outage_error_is_within_the_same_band(excerpt_both):
    record = excerpt_both.summary["outages"][0]
    assert 0.5 <= record["horizontal_error_end_m"] <= 6.0
    assert excerpt_both.summary["counts"]["gnss_updates"] == 240 - 60 - 55  # epochs after alignment, outside outage


_SPECS: dict = {}


def _excerpt_spec(name: str = "excerpt.yaml"):
    """The excerpt configuration's model spec, derived once per test session (no Python filter)."""
    if name not in _SPECS:
        from modelgen.navigator.config import load_config
        from modelgen.navigator.errorstate import model_path
        from modelgen.navigator.spec import navigator_spec

        config = load_config(DATA / name)
        _SPECS[name] = navigator_spec(model_path(config.model, config.path), with_python=False)
    return _SPECS[name]


def _excerpt_inputs():
    from modelgen.navigator.config import load_config
    from modelgen.navigator.logs import read_imu_csv, read_rtklib_pos
    from modelgen.navigator.navigator import prepare

    config = load_config(DATA / "excerpt.yaml")
    return config, prepare(config, read_imu_csv(config.imu_file, config.imu_columns, config.gap_factor),
                           read_rtklib_pos(config.gnss_file))


@pytest.mark.compile
def test_c_navigator_aligns_itself_like_the_python_reference(excerpt_both):
    """The C levels and takes its heading from its own IMU and GNSS calls: same epoch, angles to 1e-12 rad.

    The alignment completes at the excerpt's epoch 13.75 s (999 IMU samples in the
    10 s rest window ending 2 s before), 0.25 s before its outage starts.
    """
    from modelgen.navigator.alignment import align

    config, inputs = _excerpt_inputs()
    python = align(config, inputs).record()
    c = excerpt_both.flight.alignment
    assert c["time"] == python["time"] == excerpt_both.flight.alignment_time
    assert c["time"] - inputs.first_epoch == pytest.approx(13.75, abs=1e-6)
    assert c["rest_end"] == python["rest_end"] and c["rest_samples"] == python["rest_samples"] == 711
    for angle in ("roll", "pitch", "heading"):
        assert abs(c[angle] - python[angle]) <= 1e-12, angle
    assert excerpt_both.flight.outputs[0, 0] >= c["time"]  # no record before the alignment
    assert excerpt_both.summary["alignment"]["rest_samples"] == 711


@pytest.mark.compile
def test_c_and_python_refuse_to_align_without_an_epoch_at_rest():
    """GNSS starting when the vehicle already moves: neither navigator can level the IMU; both say so."""
    from dataclasses import replace

    from modelgen.errors import ModelError
    from modelgen.navigator.cnav import cached_c_navigator, fly_c
    from modelgen.navigator.alignment import align

    config, inputs = _excerpt_inputs()
    g = inputs.gnss
    keep = g.time >= align(config, inputs).time
    moving = replace(g, time=g.time[keep], latitude=g.latitude[keep], longitude=g.longitude[keep],
                     height=g.height[keep], quality=g.quality[keep], satellites=g.satellites[keep],
                     sigma_position=g.sigma_position[keep], velocity=g.velocity[keep],
                     sigma_velocity=g.sigma_velocity[keep])
    late = replace(inputs, gnss=moving)
    with pytest.raises(ModelError, match="at rest"):
        align(config, late)
    navigator, _ = cached_c_navigator(_excerpt_spec())
    with pytest.raises(ModelError, match="at rest"):
        fly_c(config, late, navigator)


@pytest.mark.compile
def test_a_rest_window_longer_than_the_c_keeps_is_refused():
    """20 s at 100 Hz needs a larger alignment ring than the default build: the ring follows the configuration,
    and a navigator built with a smaller ring is refused before flying, with a message naming the file."""
    from dataclasses import replace

    from modelgen.errors import ModelError
    from modelgen.navigator.cnav import REST_MAX, CNavigator, fly_c, log_arrays

    config, inputs = _excerpt_inputs()
    long_window = replace(config, rest_window=20.0)
    spec = _excerpt_spec()
    assert log_arrays(long_window, inputs, spec).rest_max > REST_MAX  # the ring follows the config
    assert log_arrays(config, inputs, spec).rest_max == REST_MAX
    small = CNavigator.__new__(CNavigator)
    small.rest_max = REST_MAX  # a navigator built with the default ring: refused before anything runs
    small.spec = spec
    with pytest.raises(ModelError, match="alignment ring"):
        fly_c(long_window, inputs, small)


@pytest.mark.compile
def test_c_navigator_source_is_c99_without_heap(tmp_path):
    from modelgen.navigator.cnav import generate_c_navigator

    folder = generate_c_navigator(_excerpt_spec(), tmp_path / "nav")
    source = (folder / "ins_gps15_nav_navigator.c").read_text()
    for forbidden in ("malloc", "calloc", "realloc", "free("):
        assert forbidden not in source
    assert "GENERATED FILE - DO NOT EDIT" in source



@needs_qemu_arm
@pytest.mark.embedded
@pytest.mark.compile
def test_float_filter_navigator_under_qemu_arm_stays_within_1_cm_of_the_double_c(excerpt_both):
    """Cortex-M4F build without heap, and the excerpt under qemu-arm: 5e-5 m when written, tolerance 1 cm."""
    from modelgen.navigator.cnav import log_arrays
    from modelgen.navigator.embedded import embedded_replay

    config, inputs = _excerpt_inputs()
    spec = _excerpt_spec()
    result = embedded_replay(spec, log_arrays(config, inputs, spec), excerpt_both.flight.outputs)
    assert result.forbidden_symbols == []
    assert result.max_position_difference_m <= 0.01
    assert 0 < result.worst_case_stack["ins_gps15_nav_navigator_epoch"] < 4096


def test_a_replay_loads_its_model_file_once_and_derives_it_once(monkeypatch):
    """Issue 26 item 1, 'derive once per replay': the model file is loaded once (the navigation-model check and the
    spec share it; before, a model written as equations was loaded three times) and derived once."""
    import modelgen.derivation.symbolic as symbolic
    import modelgen.model.loading as loading
    from modelgen.navigator.replay import run_replay

    loads, derivations = [], []
    load, derive = loading.load_model, symbolic.derive
    monkeypatch.setattr(loading, "load_model", lambda path, *a, **k: loads.append(path) or load(path, *a, **k))
    monkeypatch.setattr(symbolic, "derive", lambda model, *a, **k: derivations.append(model) or derive(model, *a, **k))
    run_replay(DATA / "excerpt.yaml", None, echo=lambda _: None)
    assert [Path(p).name for p in loads] == ["ins_gps15_nav.yaml"] and len(derivations) == 1
