"""Scenario files: the core paper's profile loads; bad files are refused by key."""

import math

import pytest
import yaml

from modelgen.errors import ModelError
from modelgen.simulation.scenario import KMH, load_profile, load_profile_data
from modelgen.simulation.trajectory import generate_trajectory


def test_paper_profile_loads_with_its_reasoned_values():
    s = load_profile("profile_000")
    assert s.path.duration == pytest.approx(4 * 3600)
    assert s.path.ground_speed == pytest.approx(300 * KMH)
    assert s.path.velocity_down == pytest.approx(-10 * KMH)  # printed -100 km/h: a climb to 30 km (profile_000.yaml)
    assert s.imu_rate == 300 and s.sensors["doppler"].period == 60.0
    assert s.imu_budget.gyro_constant_drift == pytest.approx(math.radians(0.1) / 3600)


def test_paper_profile_levels_off_at_0_4_h_and_flies_east():
    s = load_profile("profile_000").with_changes(hours=0.5)
    t = generate_trajectory(s.path, 10.0, 1.0)
    at = lambda hours: t.truth[int(hours * 3600)]  # noqa: E731
    assert at(0.45)[6] == pytest.approx(0.0, abs=1e-9)  # level
    assert at(0.45)[3] == pytest.approx(10 / 3.6 * 720 * 1.5, rel=1e-9)  # 2.0 km climb + 1.0 km level-off = 3.0 km
    assert at(0.45)[1] == pytest.approx(math.radians(30.0), abs=1e-9)  # due east


def data():
    with open(load_profile("profile_000").source_file) as f:
        return yaml.safe_load(f)


def test_unknown_key_is_refused_with_its_place():
    d = data()
    d["imu"]["gyro_drift_typo_dph"] = 1.0
    with pytest.raises(ModelError, match=r"imu: unknown key 'gyro_drift_typo_dph'"):
        load_profile_data(d, "x.yaml")


def test_non_number_is_refused_with_its_key():
    d = data()
    d["start"]["latitude_deg"] = "north"
    with pytest.raises(ModelError, match=r"start.latitude_deg: 'north' is not a number"):
        load_profile_data(d, "x.yaml")


def test_segment_needs_exactly_one_duration():
    d = data()
    d["segments"][0]["duration_s"] = 5.0
    with pytest.raises(ModelError, match="segments\\[0\\]: give exactly one of"):
        load_profile_data(d, "x.yaml")


def test_unknown_state_axis_is_refused():
    d = data()
    d["filter"]["states"]["attitude"]["heading_error"] = "sideways"
    with pytest.raises(ModelError, match="heading_error: 'sideways' is not one of"):
        load_profile_data(d, "x.yaml")


def test_paper_profile_and_covariance_error_budget_transcribe_table_1_identically():
    """Table 1 is written twice (the simulation's profile_000.yaml in the scenario's
    vocabulary, the analysis's error_budget_000.yaml keyed by model state); this
    keeps the two from drifting apart, so simulation and covariance analysis fly one system."""
    from modelgen.table2.budget import load_error_budget

    s, budget = load_profile("profile_000"), load_error_budget()
    sigma, parameter = budget.initial_sigma, budget.parameters
    imu = s.imu_budget
    pairs = {
        "initial attitude north": (s.initial_errors.attitude[0], sigma["attitude_error_north"]),
        "initial attitude east": (s.initial_errors.attitude[1], sigma["attitude_error_east"]),
        "initial heading": (s.initial_errors.attitude[2], sigma["heading_error"]),
        "initial velocity": (s.initial_errors.velocity, sigma["velocity_error_north"]),
    }
    for axis in "xyz":
        pairs |= {
            f"gyro constant {axis}": (imu.gyro_constant_drift, sigma[f"gyro_constant_drift_{axis}"]),
            f"gyro Markov {axis}": (imu.gyro_markov_drift, parameter[f"gyro_markov_sigma_{axis}"]),
            f"gyro Markov time {axis}": (imu.gyro_markov_correlation_time, 1 / parameter[f"gyro_markov_rate_{axis}"]),
            f"accelerometer Markov {axis}": (imu.accel_markov_bias, parameter[f"accel_markov_sigma_{axis}"]),
            f"accelerometer Markov time {axis}": (imu.accel_markov_correlation_time,
                                                  1 / parameter[f"accel_markov_rate_{axis}"]),
        }
    for axis in ("north", "east"):
        pairs |= {
            f"Doppler bias {axis}": (s.sensors["doppler"].bias, sigma[f"doppler_velocity_bias_{axis}"]),
            f"Doppler white noise {axis}": (s.sensors["doppler"].white_noise, parameter[f"doppler_noise_sigma_{axis}"]),
        }
    differing = {name: pair for name, pair in pairs.items() if pair[0] != pytest.approx(pair[1], rel=1e-12, abs=0)}
    assert not differing
    assert s.initial_errors.position == 0 and sigma["latitude_error"] == 0


def test_gps_profiles_fly_a_free_vertical_channel_like_their_models_and_bad_values_are_refused():
    for name in ("profile_001", "profile_003"):  # ins_gps15 and gps_pseudorange11 model no baro loop
        s = load_profile(name)
        assert s.vertical_damping.k1 == 0 and s.vertical_damping.k2 == 0, name
    assert load_profile("profile_000").vertical_damping.k2 > 0  # the paper's model has no vertical channel
    d = data()
    d["altitude_reference"]["vertical_channel"] = "baro"
    with pytest.raises(ModelError, match="vertical_channel"):
        load_profile_data(d, "x.yaml")


# -- issue 28 minors: latitudes, flight bounds, lax number text, a folder named like a built-in ----------------


def _profile_file(tmp_path, d):
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


@pytest.mark.parametrize("latitude", [100.0, 90.0, -90.0, -91.0])
def test_a_latitude_at_or_beyond_a_pole_is_refused_with_file_and_line(tmp_path, latitude):
    d = data()
    d["start"]["latitude_deg"] = latitude
    path = _profile_file(tmp_path, d)
    with pytest.raises(ModelError, match=rf"^{path}:\d+: start.latitude_deg: latitude {latitude:g} deg is not between"):
        load_profile(path)


def test_a_latitude_just_short_of_the_pole_loads(tmp_path):
    d = data()
    d["start"]["latitude_deg"] = 89.5
    assert load_profile(_profile_file(tmp_path, d)).path.latitude == pytest.approx(math.radians(89.5))


def test_a_flight_longer_than_ten_days_or_an_imu_over_10_khz_is_refused_before_anything_is_flown(tmp_path):
    profile = load_profile("profile_000")
    with pytest.raises(ModelError, match=r"^--hours: a flight of 1e\+09 h is longer than modelgen flies: at most 240 h"):
        profile.with_changes(hours=1e9)
    with pytest.raises(ModelError, match=r"^--imu-rate: an IMU rate of 1e\+06 Hz is faster than modelgen flies"):
        profile.with_changes(imu_rate=1e6)
    with pytest.raises(ModelError, match=r"^--imu-rate: 5000 Hz for 200 h \(--hours\) is 3.6e\+09 IMU samples"):
        profile.with_changes(hours=200.0, imu_rate=5000.0)
    assert profile.with_changes(hours=240.0).path.duration == pytest.approx(240 * 3600)
    d = data()
    d["imu"]["rate_hz"] = 20000
    path = _profile_file(tmp_path, d)
    with pytest.raises(ModelError, match=rf"^{path}:\d+: imu.rate_hz: an IMU rate of 20000 Hz is faster"):
        load_profile(path)


def test_number_text_in_a_lax_form_is_refused_and_plain_text_is_read():
    d = data()
    d["start"]["latitude_deg"] = "1_0"
    with pytest.raises(ModelError, match=r"start.latitude_deg: '1_0' is not a number"):
        load_profile_data(d, "x.yaml")
    d["start"]["latitude_deg"] = "1.5e1"
    assert load_profile_data(d, "x.yaml").path.latitude == pytest.approx(math.radians(15.0))


def test_a_folder_named_like_a_built_in_profile_does_not_shadow_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "profile_000").mkdir()
    assert load_profile("profile_000").path.duration == pytest.approx(4 * 3600)
