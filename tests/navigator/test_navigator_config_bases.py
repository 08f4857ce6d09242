"""A replay configuration that extends another (modelgen.navigator.config_bases): merged key by key, every
inherited key keeping its own file:line and folder, cycles and bad bases refused at the extends line."""

from __future__ import annotations

import dataclasses
import re
import sys
from pathlib import Path

import pytest

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path
from modelgen.navigator.config import builtin_config_path, load_config

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cli_in_process import run_modelgen  # noqa: E402

#: NavigatorConfig fields that say which file was read, not what was configured.
WHERE_FIELDS = {"path", "key_lines"}


def line_of(path: Path, needle: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), start=1) if needle in line)


def configured(config) -> dict:
    return {f.name: getattr(config, f.name) for f in dataclasses.fields(config) if f.name not in WHERE_FIELDS}


def test_the_builtin_ecef_configuration_is_the_drive_configuration_with_only_its_name_and_model_changed():
    drive = configured(load_config(builtin_config_path()))
    ecef = configured(load_config(data_path("replay_drive_0708_ecef.yaml")))
    differing = {k for k in drive if drive[k] != ecef[k]}
    assert differing == {"name", "model"}
    assert ecef["model"] == "ins_gps15_ecef_nav" and ecef["tuning"] == drive["tuning"] and ecef["tuning"]


def test_an_inherited_key_names_the_base_file_and_line_and_an_own_key_its_own(tmp_path):
    child = tmp_path / "child.yaml"
    child.write_text(f"extends: {builtin_config_path()}\nnavigator: mine\nnoise:\n  gyro_white:\n    factor: 2.5\n")
    config = load_config(child)
    base = builtin_config_path()
    assert config.where("noise.accel_white.factor") == f"{base}:{_line_after(base, 'accel_white:', 'factor:')}"
    assert config.where("noise.gyro_white.factor") == f"{child}:5"
    assert config.where("navigator") == f"{child}:2"
    assert config.noise["gyro_white"].factor == 2.5
    drive = load_config(base)
    assert config.noise["gyro_white"].value == drive.noise["gyro_white"].value  # merged, not replaced
    assert config.noise["accel_white"] == drive.noise["accel_white"]


def _line_after(path: Path, section: str, needle: str) -> int:
    """The first line holding ``needle`` after the line holding ``section``."""
    start = line_of(path, section)
    return next(i for i, line in enumerate(path.read_text().splitlines(), start=1) if i > start and needle in line)


def test_inherited_relative_log_paths_start_from_the_base_folder_and_a_builtin_name_extends_the_builtin(tmp_path):
    (tmp_path / "sub").mkdir()
    child = tmp_path / "sub" / "nav.yaml"
    child.write_text("extends: replay_drive_0708\nnavigator: mine\n")
    config = load_config(child)
    drives = builtin_config_path().parent / "drives" / "gnss_imu_drive_0708"
    assert config.imu_file == drives / "imu.csv.gz" and config.gnss_file == drives / "gnss.pos"
    assert config.origin("model") == builtin_config_path()


def test_an_own_list_replaces_the_base_list_whole_and_the_base_items_lose_their_lines(tmp_path):
    child = tmp_path / "nav.yaml"
    child.write_text("extends: replay_drive_0708\nnavigator: mine\nevaluation:\n  schedules:\n"
                     "    - {name: only, windows: [[50.0, 10.0]]}\n")
    config = load_config(child)
    assert [s.name for s in config.evaluation_schedules] == ["only"]
    assert config.where("evaluation.schedules[0]") == f"{child}:5"
    assert not any(k.startswith("evaluation.schedules[1]") for k in config.key_lines)
    assert config.target_end_rms_m == load_config(builtin_config_path()).target_end_rms_m  # the rest merged


def test_a_bad_value_in_the_child_is_refused_at_the_child_line_and_an_unknown_key_too(tmp_path):
    child = tmp_path / "nav.yaml"
    child.write_text("extends: replay_drive_0708\nnavigator: mine\nfilter:\n  predict_period_s: -1\n")
    with pytest.raises(ModelError, match=rf"{re.escape(str(child))}:4: filter\.predict_period_s must be positive"):
        load_config(child)
    child.write_text("extends: replay_drive_0708\nnavigator: mine\nimu:\n  gap_fcator: 4\n")
    with pytest.raises(ModelError, match=rf"{re.escape(str(child))}:4: unknown key 'gap_fcator' in imu"):
        load_config(child)


CYCLE = r"extends 'nav\.yaml': the configurations extend each other in a cycle"


@pytest.mark.parametrize("case, text, problem", [
    ("missing", "extends: nowhere.yaml\n", r"extends 'nowhere\.yaml': no such configuration file"),
    ("not text", "extends: [a, b]\n", r"extends must name a configuration file"),
    ("itself", "extends: nav.yaml\n", CYCLE + r" \(nav\.yaml -> nav\.yaml\)"),
    ("cycle", "extends: other.yaml\n", CYCLE + r" \(nav\.yaml -> other\.yaml -> nav\.yaml\)"),
])
def test_a_bad_extends_is_refused_at_its_line(tmp_path, case, text, problem):
    (tmp_path / "other.yaml").write_text("extends: nav.yaml\nnavigator: other\n")
    child = tmp_path / "nav.yaml"
    child.write_text("navigator: mine\n" + text)
    where = child if case != "cycle" else tmp_path / "other.yaml"
    line = 2 if case != "cycle" else 1
    with pytest.raises(ModelError, match=rf"^{re.escape(str(where))}:{line}: {problem}"):
        load_config(child)


def test_a_chain_deeper_than_the_limit_is_refused(tmp_path):
    from modelgen.navigator.config_bases import MAX_DEPTH

    for i in range(MAX_DEPTH + 1):
        (tmp_path / f"c{i}.yaml").write_text(f"extends: c{i + 1}.yaml\n" if i < MAX_DEPTH else
                                             f"extends: {builtin_config_path()}\n")
    with pytest.raises(ModelError, match=rf"more than {MAX_DEPTH} configurations extend one another"):
        load_config(tmp_path / "c0.yaml")
    assert load_config(tmp_path / "c2.yaml").name == "replay_drive_0708"  # a chain within the limit is read
    # c1 has exactly MAX_DEPTH bases (c2 .. c8 and the built-in one): "at most 8 deep" is read (it was refused)
    assert load_config(tmp_path / "c1.yaml").name == "replay_drive_0708"


@pytest.mark.parametrize("case, lay_out, problem", [
    ("symlink loop", lambda d: ((d / "a.yaml").symlink_to("b.yaml"), (d / "b.yaml").symlink_to("a.yaml")),
     r"a\.yaml is a symbolic link in a loop, not a configuration file"),
    ("symlink to itself", lambda d: (d / "a.yaml").symlink_to("a.yaml"), r"a symbolic link in a loop"),
    ("dangling symlink", lambda d: (d / "a.yaml").symlink_to("gone.yaml"),
     r"a symbolic link to a file that does not exist"),
    ("pipe", lambda d: __import__("os").mkfifo(d / "a.yaml"), r"not a regular file \(a device, a pipe or a socket\)"),
    ("folder", lambda d: (d / "a.yaml").mkdir(), r"a\.yaml is a folder, not a configuration file"),
])
def test_a_base_that_is_no_regular_file_is_refused_at_the_extends_line_saying_what_it_is(tmp_path, case, lay_out,
                                                                                       problem):
    """They were all 'no such configuration file'; a pipe would have blocked the read had it got that far."""
    lay_out(tmp_path)
    child = tmp_path / "nav.yaml"
    child.write_text("navigator: mine\nextends: a.yaml\n")
    with pytest.raises(ModelError, match=rf"^{re.escape(str(child))}:2: extends 'a\.yaml': .*{problem}"):
        load_config(child)


def test_a_symlink_to_a_base_is_read_and_one_back_to_the_child_is_a_cycle(tmp_path):
    from modelgen.navigator.config_bases import read_config_with_bases

    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "real.yaml").write_text("navigator: base\nmodel: m\n")
    (tmp_path / "base.yaml").symlink_to(tmp_path / "elsewhere" / "real.yaml")
    child = tmp_path / "nav.yaml"
    child.write_text("navigator: mine\nextends: base.yaml\n")
    assert read_config_with_bases(child)[0] == {"navigator": "mine", "model": "m"}
    child.write_text("navigator: mine\nextends: link.yaml\n")
    (tmp_path / "link.yaml").symlink_to("nav.yaml")
    with pytest.raises(ModelError, match=rf"^{re.escape(str(child))}:2: extends 'link\.yaml': the configurations "
                                         r"extend each other in a cycle \(nav\.yaml -> link\.yaml\)"):
        load_config(child)


@pytest.mark.corpus
def test_the_cli_refuses_an_extends_cycle_with_one_located_line_and_exit_2(tmp_path):
    child = tmp_path / "nav.yaml"
    child.write_text("navigator: mine\nextends: nav.yaml\n")
    result = run_modelgen(["replay", child, "--out", tmp_path / "out", "--no-figures"], cwd=tmp_path, timeout=120)
    assert result is not None and result.returncode == 2, result
    errors = [line for line in result.stderr.splitlines() if line.strip()]
    assert errors == [f"modelgen: error: {child}:2: extends 'nav.yaml': the configurations extend each other in a "
                      "cycle (nav.yaml -> nav.yaml)"], result.stderr
    assert not (tmp_path / "out").exists()
