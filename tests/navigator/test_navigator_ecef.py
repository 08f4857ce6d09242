"""The ECEF navigator: a model with ``mechanization: ecef`` (ins_gps15_ecef_nav) flown in r^e, v^e, C_b^e.

The same drive excerpt as the other navigator tests (tests/navigator/data/excerpt_ecef.yaml is excerpt.yaml with
the ECEF model): its C and Python agree, its trajectory agrees with the local-level navigator's, the mechanization
rates generated from its navigation equations keep a body at rest at rest, and an ECEF model the navigator cannot
fly is refused with one located line.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import package_path
from modelgen.navigator.mechanization import NAV_SIZE, dcm_to_quaternion, euler_to_dcm, mechanize
from modelgen.model.wgs84 import EARTH_RATE

pytestmark = pytest.mark.flight

DATA = Path(__file__).parent / "data"
MODEL = package_path("navigator", "models", "ins_gps15_ecef_nav.yaml")


@pytest.fixture(scope="module")
def ecef_spec():
    from modelgen.navigator.spec import navigator_spec

    return navigator_spec(MODEL)


def test_the_ecef_spec_reads_e_frame_blocks_and_whole_vector_gnss_rows(ecef_spec):
    assert ecef_spec.ecef and ecef_spec.frame == "ECEF" and ecef_spec.n_states == len(ecef_spec.derived.model.state_names)
    assert ecef_spec.blocks["position"].form == "metres"
    assert sorted(ecef_spec.blocks) == ["accel_bias", "attitude", "gyro_bias", "position", "velocity"]
    assert sorted((r.kind, r.axis) for r in ecef_spec.gnss_rows) == [(k, a) for k in ("position", "velocity")
                                                                     for a in range(3)]
    # the generated rates are the e-frame ones: inputs r^e, v^e; r' = v
    assert "def navigation_rates(x, y, z, v_x, v_y, v_z)" in ecef_spec.rates_python


def test_ecef_mechanization_at_rest_with_ideal_sensors_stays_at_rest(ecef_spec):
    """Level, heading 30 deg, sensing exactly the model's own gravity and the earth rate: 60 s at 100 Hz."""
    from modelgen.navigator.ecef import geodetic_to_ecef, ned_to_ecef

    lat, lon, h, yaw = math.radians(40.0), math.radians(-105.0), 1600.0, math.radians(30.0)
    r = geodetic_to_ecef(lat, lon, h)
    c_be = ned_to_ecef(lat, lon) @ euler_to_dcm(0.0, 0.0, yaw)
    rates = ecef_spec.rates(r[0], r[1], r[2], 0.0, 0.0, 0.0)
    g_e = np.array(rates[0:3])  # v' - C f at rest: gravity with the centrifugal term, from the model's equations
    n = 6001
    time = np.arange(n) * 0.01
    force = np.tile(c_be.T @ -g_e, (n, 1))
    rate = np.tile(c_be.T @ np.array(rates[6:9]), (n, 1))
    nav = np.zeros(NAV_SIZE)
    nav[0:4] = dcm_to_quaternion(c_be)
    nav[7:10] = r
    mechanize(nav, np.zeros(6), time, force, rate, 1, n, np.zeros(3), np.zeros(3), np.zeros(4), np.zeros(3),
              np.zeros(3), ecef_spec.rates)
    assert abs(np.linalg.norm(g_e) - 9.80) < 0.01 and rates[8] == pytest.approx(EARTH_RATE)
    assert np.abs(nav[4:7]).max() < 1e-3
    assert np.linalg.norm(nav[7:10] - r) < 0.03
    assert np.abs(nav[0:4] - dcm_to_quaternion(c_be)).max() < 1e-9


@pytest.fixture(scope="module")
def ecef_both():
    from modelgen.navigator.replay import run_replay

    return run_replay(DATA / "excerpt_ecef.yaml", None, echo=lambda _: None, navigator="both")


@pytest.mark.compile
def test_the_ecef_c_navigator_agrees_with_its_python_within_1_mm(ecef_both):
    """1.6e-9 m when written."""
    assert ecef_both.summary["navigator"] == "c"
    assert ecef_both.summary["model"]["frame"] == "ECEF"
    assert ecef_both.summary["c_python_max_difference_m"] <= 1e-3
    assert ecef_both.summary["counts"]["gnss_updates"] == 240 - 60 - 55  # as the local-level navigator's


@pytest.mark.compile
def test_the_ecef_trajectory_agrees_with_the_local_level_one_on_the_excerpt(ecef_both):
    """Against the local-level navigator (excerpt.yaml, the same settings): when written the largest differences
    were 4.1 mm horizontal, 0.45 mm vertical, 0.56 mm/s, 0.008 deg of yaw, 0.7 mm in sigma north.

    Bound: 2 cm horizontal, 1 cm vertical, 5 mm/s, 0.05 deg, 5 mm in the sigmas.  The two are the same
    navigation equations in two frames; they differ by the gravity model (the ECEF model's J2 field against normal
    gravity) and by where each linearizes, which over the excerpt's 15-s outage is millimetres.
    """
    from modelgen.navigator.metrics import COLUMN
    from modelgen.navigator.replay import run_replay

    a = ecef_both.flight.outputs
    b = run_replay(DATA / "excerpt.yaml", None, echo=lambda _: None, navigator="c").flight.outputs
    assert a.shape == b.shape and np.array_equal(a[:, COLUMN["time"]], b[:, COLUMN["time"]])
    lat, lon = COLUMN["latitude"], COLUMN["longitude"]
    north = (a[:, lat] - b[:, lat]) * 6.37e6
    east = (a[:, lon] - b[:, lon]) * 6.37e6 * np.cos(b[:, lat])
    assert np.hypot(north, east).max() <= 0.02
    assert np.abs(a[:, COLUMN["height"]] - b[:, COLUMN["height"]]).max() <= 0.01
    velocity = slice(COLUMN["v_north"], COLUMN["v_down"] + 1)
    assert np.abs(a[:, velocity] - b[:, velocity]).max() <= 0.005
    yaw = a[:, COLUMN["yaw"]] - b[:, COLUMN["yaw"]]
    assert np.abs(np.angle(np.exp(1j * yaw))).max() <= math.radians(0.05)
    for sigma in ("sigma_north", "sigma_east", "sigma_up"):
        assert np.abs(a[:, COLUMN[sigma]] - b[:, COLUMN[sigma]]).max() <= 0.005, sigma
    inside = a[:, COLUMN["in_outage"]] == 1
    assert inside.sum() == 60 and not a[inside, COLUMN["gnss_used"]].any()


def _ecef_model(tmp_path: Path, name: str, measurements: str) -> Path:
    """The ECEF model with its measurements: section replaced."""
    text = MODEL.read_text()
    start = text.index("  measurements:")
    path = tmp_path / f"{name}.yaml"
    path.write_text(text[:start].replace("model: ins_gps15_ecef_nav", f"model: {name}") + measurements)
    return path


def test_an_ecef_model_without_gnss_rows_is_refused_at_its_measurements_line(tmp_path):
    from modelgen.navigator.spec import navigator_spec

    position_only = _ecef_model(tmp_path, "ecef_position_only", "  measurements:\n    - {of: position, lever_arm: "
                                "{symbol: l}, symbols: [Z_rx, Z_ry, Z_rz], variance: \"sigma_r**2\"}\n")
    assert [r.kind for r in navigator_spec(position_only, with_python=False).gnss_rows] == ["position"] * 3
    none = _ecef_model(tmp_path, "ecef_no_gnss", "  measurements: []\n")
    line = len(none.read_text().splitlines())
    with pytest.raises(ModelError, match=rf"^{none}:{line}: the navigator's GNSS update of an ecef model needs its "
                                         r"measurements as whole e-frame vectors.*0 position, 0 velocity"):
        navigator_spec(none, with_python=False)


def test_the_cli_refuses_an_ecef_model_the_navigator_cannot_fly_with_one_located_line_and_exit_2(tmp_path):
    import re

    from click.testing import CliRunner

    from modelgen.cli import main

    model = _ecef_model(tmp_path, "ecef_no_gnss", "  measurements: []\n")
    config = (DATA / "excerpt_ecef.yaml").read_text().replace("model: ins_gps15_ecef_nav", f"model: {model.name}")
    config = config.replace("extends: excerpt.yaml", f"extends: {DATA / 'excerpt.yaml'}")  # its logs: from there
    path = tmp_path / "replay.yaml"
    path.write_text(config)
    result = CliRunner().invoke(main, ["replay", str(path), "--no-figures", "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("modelgen: error:")]
    assert len(errors) == 1, result.output
    assert re.match(rf"modelgen: error: {re.escape(str(model))}:\d+: ", errors[0]), errors[0]
    assert "Traceback" not in result.output and "gcc" not in result.output
