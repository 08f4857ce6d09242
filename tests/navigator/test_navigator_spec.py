"""The navigator generated from the model file: the spec, the configuration field list, the 21-state model flown."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import package_path
from tests.navigator.qemu_support import needs_qemu_arm

pytestmark = pytest.mark.flight

DATA = Path(__file__).parent / "data"
MODELS = package_path("navigator", "models")


@pytest.fixture(scope="module")
def spec21():
    from modelgen.navigator.spec import navigator_spec

    return navigator_spec(MODELS / "ins_gnss21_rw_nav.yaml", with_python=False)


def test_the_21_state_spec_finds_every_block_and_the_gnss_rows_in_ned(spec21):
    assert spec21.n_states == 21 and spec21.frame == "NED"
    assert set(spec21.blocks) == {"attitude", "velocity", "position", "gyro_bias", "accel_bias", "gyro_scale_factor",
                                  "accel_scale_factor"}
    assert spec21.blocks["position"].form == "metres"
    assert [(r.kind, r.axis) for r in spec21.gnss_rows] == [("position", 0), ("position", 1), ("position", 2),
                                                             ("velocity", 0), ("velocity", 1), ("velocity", 2)]
    # the lever arm is a model parameter the navigator sets from gnss.lever_arm_m
    assert spec21.parameter_expressions["lever_arm_y"] == "cfg->lever_arm[1]"


def test_the_15_state_enu_model_reads_as_geodetic_position_and_enu_axes():
    from modelgen.navigator.spec import navigator_spec

    spec = navigator_spec(MODELS / "ins_gps15_nav.yaml", with_python=False)
    assert spec.frame == "ENU" and spec.n_states == 15
    position = spec.blocks["position"]
    assert position.form == "geodetic" and position.axes == (0, 1, 2) and position.signs == (1.0, 1.0, -1.0)
    assert spec.blocks["attitude"].axes == (1, 0, 2)  # east, north, up
    assert "gyro_scale_factor" not in spec.blocks


def test_feedback_corrects_scale_factors_and_metres_position(spec21):
    from modelgen.navigator.errorstate import rotate
    from modelgen.navigator.mechanization import radii

    nav = np.array([1.0, 0, 0, 0, 1.0, 2.0, 3.0, 0.7, -1.8, 1600.0])
    x = np.zeros(21)
    x[0], x[2] = 6.0, -2.0  # 6 m north, 2 m up (down error -2): computed minus true
    x[15:18] = [1e-3, 2e-3, 3e-3]
    sensors = {k: np.zeros(3) for k in ("gyro_bias", "accel_bias", "gyro_scale_factor", "accel_scale_factor")}
    before = nav.copy()
    spec21.feedback(nav, x, sensors, radii, rotate)
    rm, _ = radii(before[7])
    assert (before[7] - nav[7]) * (rm + before[9]) == pytest.approx(6.0, rel=1e-9)  # latitude rounding: 1e-16 rad of 1e-6
    assert nav[9] - before[9] == pytest.approx(-2.0)
    assert np.allclose(sensors["gyro_scale_factor"], [1e-3, 2e-3, 3e-3])


@pytest.mark.compile
def test_the_21_state_model_flies_alike_in_python_and_c_on_the_excerpt():
    """60 s of the drive, 21 states: C against Python at every epoch (1 mm, as the 15-state test), the outage end
    within the 15-state excerpt's band."""
    from modelgen.navigator.replay import run_replay

    both = run_replay(DATA / "excerpt_21.yaml", None, echo=lambda _: None, navigator="both")
    s = both.summary
    assert s["navigator"] == "c"
    assert s["c_python_max_difference_m"] <= 1e-3
    assert 0.5 <= s["outages"][0]["horizontal_error_end_m"] <= 6.0
    assert s["horizontal_rms_outside_outages_m"] <= 0.10
    # the scale-factor estimates reach the output record, the summary and the trajectory file
    from modelgen.navigator.metrics import COLUMN
    from modelgen.navigator.report import csv_text

    final = both.flight.outputs[-1]
    for kind in ("gyro_scale_factor", "accel_scale_factor"):
        estimates = final[COLUMN[f"{kind}_x"]:COLUMN[f"{kind}_z"] + 1]
        assert np.all(estimates != 0.0) and np.all(np.abs(estimates) < 0.05)  # estimated, and physical (< 5 %)
        assert s[f"final_{kind}_ppm"] == pytest.approx(list(estimates * 1e6), rel=1e-12)
    assert both.flight.estimated == spec_blocks_21
    assert "gyro_scale_factor_x" in csv_text(both.flight, errors_against(both)).splitlines()[0]
    from modelgen.navigator.logs import read_gnss
    from modelgen.navigator.report import figures

    drawn = figures(both.flight, errors_against(both), read_gnss(both.config.gnss_source))
    assert "scale_factors.svg" in drawn and "ppm" in drawn["scale_factors.svg"]


spec_blocks_21 = ("gyro_bias", "accel_bias", "gyro_scale_factor", "accel_scale_factor")


def errors_against(result):
    from modelgen.navigator.logs import read_gnss
    from modelgen.navigator.metrics import errors_against_reference

    return errors_against_reference(result.flight, read_gnss(result.config.gnss_source))


def _model_without_velocity_block(tmp_path: Path) -> Path:
    text = (MODELS / "ins_gps15_nav.yaml").read_text().replace("name: velocity_error_", "name: speed_error_")
    text = text.replace("model: ins_gps15_nav", "model: no_velocity15")
    path = tmp_path / "no_velocity15.yaml"
    path.write_text(text)
    return path


def test_a_model_without_navigation_blocks_is_refused_naming_its_file(tmp_path):
    from modelgen.navigator.spec import navigator_spec

    path = _model_without_velocity_block(tmp_path)
    with pytest.raises(ModelError, match=r"no_velocity15\.yaml: .*no complete velocity error block"):
        navigator_spec(path, with_python=False)


def test_the_cli_refuses_such_a_model_with_one_line_and_exit_2(tmp_path):
    from click.testing import CliRunner

    from modelgen.cli import main

    model = _model_without_velocity_block(tmp_path)
    config = (DATA / "excerpt.yaml").read_text().replace("model: ins_gps15_nav", f"model: {model.name}")
    config = config.replace("excerpt_imu.csv.gz", str(DATA / "excerpt_imu.csv.gz"))
    config = config.replace("file: excerpt.pos", f"file: {DATA / 'excerpt.pos'}")
    path = tmp_path / "replay.yaml"
    path.write_text(config)
    result = CliRunner().invoke(main, ["replay", str(path), "--no-figures"])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("modelgen: error:")]
    # replay's own check (replay.check_navigation_model) or the spec's: either names the file and what is missing
    assert len(errors) == 1 and "no_velocity15.yaml" in errors[0]
    assert "velocity" in errors[0] or "not a navigation model" in errors[0]
    assert "Traceback" not in result.output and "gcc" not in result.output


def test_parameters_the_model_lacks_or_the_navigator_sets_are_refused(spec21):
    from types import SimpleNamespace

    config = SimpleNamespace(path="replay.yaml", parameters={"no_such_parameter": 1.0})
    with pytest.raises(ModelError, match="no_such_parameter is not a parameter of model ins_gnss21_rw_nav"):
        spec21.free_values(config)
    config = SimpleNamespace(path="replay.yaml", parameters={"latitude": 0.7})
    with pytest.raises(ModelError, match="latitude is set by the navigator"):
        spec21.free_values(config)
    config = SimpleNamespace(path="replay.yaml", parameters={"earth_rate": 7.3e-5})
    assert spec21.free_values(config) == [7.3e-5]  # a free parameter (here one with a default) is the config's


def test_configuration_parameters_refused_by_the_model_name_their_configuration_line(tmp_path, spec21):
    """The spec's refusals of a configuration's parameters: name FILE:LINE of the key (before: the file alone)."""
    from types import SimpleNamespace

    path = tmp_path / "replay.yaml"
    path.write_text("navigator: x\nparameters:\n  latitude: 0.7\n  no_such_parameter: 1.0\n")
    with pytest.raises(ModelError, match=rf"^{re.escape(str(path))}:4: parameters: no_such_parameter is not a parameter"):
        spec21.free_values(SimpleNamespace(path=str(path), parameters={"no_such_parameter": 1.0}))
    with pytest.raises(ModelError, match=rf"^{re.escape(str(path))}:3: parameters: latitude is set by the navigator"):
        spec21.free_values(SimpleNamespace(path=str(path), parameters={"latitude": 0.7}))


def test_a_scale_factor_model_without_its_sigmas_is_refused(spec21):
    from dataclasses import replace

    from modelgen.navigator.config import load_config

    config = replace(load_config(DATA / "excerpt_21.yaml"), gyro_scale_factor_sigma=None)
    with pytest.raises(ModelError, match="initial.gyro_scale_factor_sigma_ppm"):
        spec21.check_config(config)


@pytest.mark.compile
def test_the_field_list_generates_both_sides_of_the_config_struct(tmp_path, spec21):
    """sizeof and every member's offset of the C struct (compiled) equal the ctypes twin's."""
    import ctypes

    from modelgen.codegen.build import compile_shared_library
    from modelgen.navigator import cconfig
    from modelgen.navigator.cnav import generate_c_navigator

    folder = generate_c_navigator(spec21, tmp_path / "nav")
    name = spec21.name
    offsets = "\n".join(f"        case {i}: return (unsigned long)offsetof({name}_navigator_config, {f.name});"
                        for i, f in enumerate(cconfig.FIELDS))
    probe = folder / "probe.c"
    probe.write_text(f'#include <stddef.h>\n#include "{name}_navigator.h"\n'
                     f"unsigned long probe_size(void) {{ return (unsigned long)sizeof({name}_navigator_config); }}\n"
                     f"unsigned long probe_offset(int i)\n{{\n    switch (i) {{\n{offsets}\n"
                     "        default: return 0;\n    }\n}\n")
    library = ctypes.CDLL(str(compile_shared_library([probe], folder / "libprobe.so", ("-O0", f"-I{folder}"))))
    library.probe_size.restype = library.probe_offset.restype = ctypes.c_ulong
    twin = cconfig.structure(len(spec21.free_parameters))
    assert library.probe_size() == ctypes.sizeof(twin)
    for i, item in enumerate(cconfig.FIELDS):
        assert library.probe_offset(i) == getattr(twin, item.name).offset, item.name
    header = (folder / f"{name}_navigator.h").read_text()
    assert f"}} {name}_navigator_config;" in header and "cfg[" not in header


def test_no_state_count_index_or_configuration_slot_is_written_by_hand():
    root = Path(__file__).resolve().parents[2] / "modelgen"
    sources = [root / "navigator" / f for f in ("navigator.py", "errorstate.py", "cnav.py", "embedded.py")]
    sources += [root / "codegen" / "backends" / "c" / "templates" / f
                for f in ("navigator_source.c.j2", "navigator_header.h.j2")]
    for path in sources:
        text = path.read_text()
        assert "N_STATES = " not in text and "N_CONFIG" not in text, path
        assert not re.search(r"cfg\[\d", text), path
        assert not re.search(r"P\[[0-9]+\]\[[0-9]+\]|P\[[0-9]+, *[0-9]+\]", text), path



@needs_qemu_arm
@pytest.mark.embedded
@pytest.mark.compile
def test_the_21_state_float_navigator_under_qemu_arm_stays_within_1_cm_of_the_double_c(spec21):
    """The 21-state Cortex-M4F build (float filter, packed configuration struct) on the excerpt under qemu-arm."""
    from modelgen.navigator.cnav import cached_c_navigator, fly_c, log_arrays
    from modelgen.navigator.config import load_config
    from modelgen.navigator.embedded import embedded_replay
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare

    config = load_config(DATA / "excerpt_21.yaml")
    inputs = prepare(config, read_imu(config.imu_source, config.gap_factor, config.gap_action),
                     read_gnss(config.gnss_source))
    arrays = log_arrays(config, inputs, spec21)
    navigator, _ = cached_c_navigator(spec21, rest_max=arrays.rest_max)
    reference, _ = fly_c(config, inputs, navigator)
    result = embedded_replay(spec21, arrays, reference.outputs)
    assert result.forbidden_symbols == []
    assert result.max_position_difference_m <= 0.01
    assert 0 < result.worst_case_stack["ins_gnss21_rw_nav_navigator_epoch"] < 4096


def _config_with(tmp_path: Path, extra: str) -> Path:
    text = (DATA / "excerpt_21.yaml").read_text() + extra
    text = text.replace("excerpt_imu.csv.gz", str(DATA / "excerpt_imu.csv.gz"))
    path = tmp_path / "replay21.yaml"
    path.write_text(text.replace("file: excerpt.pos", f"file: {DATA / 'excerpt.pos'}"))
    return path


def test_the_parameters_section_reaches_the_configuration_struct(tmp_path, spec21):
    from modelgen.navigator import cconfig
    from modelgen.navigator.config import load_config

    config = load_config(_config_with(tmp_path, "parameters:\n  earth_rate: 7.3e-5\n"))
    assert config.parameters == {"earth_rate": 7.3e-5}
    fields = cconfig.values(config, spec21, 50, 10, 50)
    assert fields["parameters"] == [7.3e-5]
    assert list(cconfig.to_structure(fields, 1).parameters) == [7.3e-5]
    assert cconfig.namespace(fields).gyro_scale_factor_sigma == pytest.approx(3000e-6)


def test_a_parameter_that_is_not_a_number_is_refused_with_its_line(tmp_path):
    from modelgen.navigator.config import load_config

    with pytest.raises(ModelError, match=r"replay21\.yaml:\d+: parameters\.earth_rate must be a finite number"):
        load_config(_config_with(tmp_path, "parameters:\n  earth_rate: fast\n"))
