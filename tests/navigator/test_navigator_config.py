"""The navigator configuration: data-sheet units to SI with stated factors; refusals name file:line."""

from __future__ import annotations

import math

import pytest

from modelgen.errors import ModelError
from modelgen.navigator.config import builtin_config_path, load_config


def builtin_text() -> str:
    return builtin_config_path().read_text(encoding="utf-8")


def write(tmp_path, text: str):
    """The built-in configuration edited by ``text``, beside links to the drive's files."""
    path = tmp_path / "nav.yaml"
    drives = builtin_config_path().parent / "drives"
    path.write_text(text.replace("drives/", f"{drives}/"), encoding="utf-8")
    return path


def test_builtin_configuration_converts_data_sheet_noise_to_si_with_its_factor():
    config = load_config(builtin_config_path())
    gyro = config.noise["gyro_white"]
    assert gyro.unit == "deg/s/sqrt(Hz)"
    assert gyro.si == pytest.approx(gyro.value * math.pi / 180 * gyro.factor)
    accel = config.noise["accel_white"]
    assert accel.si == pytest.approx(accel.value * 1e-6 * 9.80665 * accel.factor)
    assert config.rotation_to_body[0] == pytest.approx(math.pi)
    assert config.outage_schedule == {"first_after_s": 40.0, "length_s": 15.0, "period_s": 45.0, "end_margin_s": 30.0}


def line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), start=1) if needle in line)


def test_unparseable_noise_unit_is_refused_with_its_line(tmp_path):
    text = builtin_text().replace("unit: deg/s/sqrt(Hz)", "unit: deg/fortnight")
    path = write(tmp_path, text)
    with pytest.raises(ModelError, match=rf"nav\.yaml:{line_of(text, 'deg/fortnight')}: noise\.gyro_white\.unit "
                                         r"'deg/fortnight' cannot be parsed"):
        load_config(path)


def test_unknown_key_is_refused_with_its_line(tmp_path):
    text = builtin_text().replace("  gap_factor: 3", "  gap_factor: 3\n  gap_fcator: 4")
    path = write(tmp_path, text)
    with pytest.raises(ModelError, match=rf"nav\.yaml:{line_of(text, 'gap_fcator')}: unknown key 'gap_fcator' in imu"):
        load_config(path)


def test_imu_unit_that_cannot_be_parsed_is_refused_with_its_line(tmp_path):
    text = builtin_text().replace("units: {accel: g, gyro: rad/s}", "units: {accel: g, gyro: rpm}")
    path = write(tmp_path, text)
    with pytest.raises(ModelError, match=r"nav\.yaml:\d+: gyro unit 'rpm' cannot be parsed"):
        load_config(path)


def test_missing_log_file_and_bad_outage_window_are_refused(tmp_path):
    path = write(tmp_path, builtin_text().replace("gnss_imu_drive_0708/gnss.pos", "gnss_imu_drive_0708/nope.pos"))
    with pytest.raises(ModelError, match=r"nav\.yaml:\d+: gnss\.file: no such file"):
        load_config(path)
    text = builtin_text().split("outages:")[0] + "outages:\n  windows: [[10.0, -5.0]]\n"
    with pytest.raises(ModelError, match=r"each outage window is \[start_s, length_s > 0\]"):
        load_config(write(tmp_path, text))


def test_yaml_tags_are_not_constructed(tmp_path):
    text = builtin_text().replace("navigator: replay_drive_0708",
                                  "navigator: !!python/object/apply:os.system ['touch PWNED']")
    with pytest.raises(ModelError, match=r"nav\.yaml:\d+: not valid YAML"):
        load_config(write(tmp_path, text))
    assert not (tmp_path / "PWNED").exists()
