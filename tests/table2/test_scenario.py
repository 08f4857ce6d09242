"""The flight scenario file and the level-flight operating point (modelgen.table2.scenario)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from modelgen.table2.scenario import load_analysis_scenario, operating_point, specific_force_ned
from modelgen.errors import ModelError


def test_paper_scenario_is_4_hours_of_60_s_steps_at_30_north_flying_east():
    s = load_analysis_scenario()
    assert s.steps == 240 and s.step_s == 60.0 and s.taylor_order == 9
    assert math.degrees(s.latitude) == pytest.approx(30.0)
    assert s.velocity_ned == pytest.approx((0.0, 300 / 3.6, 0.0))
    assert np.array_equal(np.array(s.attitude_matrix), [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert s.times_h()[-1] == pytest.approx(4.0)


def test_manoeuvre_phases_are_the_first_0_4_hours():
    s = load_analysis_scenario()
    assert s.manoeuvring(0.0) and s.manoeuvring(0.39 * 3600)
    assert not s.manoeuvring(0.4 * 3600) and not s.manoeuvring(3.0 * 3600)


def test_specific_force_at_rest_is_minus_gravity():
    f = specific_force_ned(math.radians(30), np.zeros(3), 6.4e6, 7.3e-5, 9.8)
    assert f == pytest.approx([0.0, 0.0, -9.8])


def test_specific_force_flying_east_has_coriolis_and_transport_terms():
    lat, v, R, w, g = math.radians(30), 100.0, 6.4e6, 7.3e-5, 9.8
    f = specific_force_ned(lat, np.array([0.0, v, 0.0]), R, w, g)
    assert f[0] == pytest.approx((2 * w * math.sin(lat) + v / R * math.tan(lat)) * v)
    assert f[1] == pytest.approx(0.0)
    assert f[2] == pytest.approx(-g + (2 * w * math.cos(lat) + v / R) * v)  # Eotvos: lighter flying east


def test_operating_point_gives_every_operating_parameter_of_the_model(paper_model):
    values = operating_point(load_analysis_scenario())
    needed = {p.name for p in paper_model.parameters if p.value is None and not ("markov" in p.name or "noise" in p.name)}
    assert needed <= set(values)
    assert values["c12"] == -1.0 and values["c21"] == 1.0 and values["c33"] == 1.0


def _write(tmp_path, text):
    path = tmp_path / "scenario.yaml"
    path.write_text(text, encoding="utf-8")
    return path


BASE = """
scenario: test
start: {latitude_deg: 30.0}
duration_h: 1.0
step_s: 60.0
taylor_order: 9
earth: {radius_m: 6378137.0, rate_rad_s: 7.29e-5, gravity_m_s2: 9.8}
level_flight:
  velocity_kmh: {north: 0.0, east: 300.0, down: 0.0}
  attitude_matrix: MATRIX
phases: []
"""


def test_scenario_with_a_non_rotation_attitude_matrix_is_refused(tmp_path):
    path = _write(tmp_path, BASE.replace("MATRIX", "[[1, 0, 0], [0, 2, 0], [0, 0, 1]]"))
    with pytest.raises(ModelError, match="attitude_matrix is not a rotation matrix"):
        load_analysis_scenario(path)


def test_scenario_missing_key_is_named(tmp_path):
    path = _write(tmp_path, BASE.replace("MATRIX", "[[1, 0, 0], [0, 1, 0], [0, 0, 1]]").replace("step_s: 60.0\n", ""))
    with pytest.raises(ModelError, match="missing key 'step_s'"):
        load_analysis_scenario(path)


def test_scenario_duration_not_a_whole_number_of_steps_is_refused(tmp_path):
    path = _write(tmp_path, BASE.replace("MATRIX", "[[1, 0, 0], [0, 1, 0], [0, 0, 1]]").replace("step_s: 60.0", "step_s: 7.0"))
    with pytest.raises(ModelError, match="whole number of steps"):
        load_analysis_scenario(path)
