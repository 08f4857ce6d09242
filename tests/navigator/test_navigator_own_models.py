"""Navigation models a user writes from the docs alone, as the navigator reads them (modelgen.navigator.spec).

Each test is a case where the navigator silently flew something other than the model said, found by writing
models from docs/model-language.md and docs/replay-configuration.md only."""

from __future__ import annotations

import numpy as np
import pytest

from modelgen.errors import ModelError

MODEL = """\
model: m9
frame: NED
parameters:
  - {name: gyro_angle_random_walk, symbol: N_g, unit: rad/sqrt(s)}
  - {name: accel_velocity_random_walk, symbol: N_a, unit: m/s/sqrt(s)}
  - {name: gnss_position_sigma, symbol: sigma_r, unit: m, value: 2.0}
  - {name: gnss_velocity_sigma, symbol: sigma_v, unit: m/s, value: 0.1}
navigation:
  errors:
    position: {form: metres, symbol: dr}
    velocity: {form: difference, symbol: dv}
    attitude: {form: phi, symbol: phi}
  noises: {gyro: {psd: "N_g**2"}, accel: {psd: "N_a**2"}}
  measurements:
    - {of: position, form: metres, symbols: [z_n, z_e, z_d], variance: "sigma_r**2"DIFFERENCE}
    - {of: velocity, symbols: [z_vn, z_ve, z_vd], variance: "sigma_v**2"}
"""


def _spec(tmp_path, text: str, name: str = "m.yaml"):
    from modelgen.navigator.spec import navigator_spec

    path = tmp_path / name
    path.write_text(text)
    return navigator_spec(path, with_python=False)


def test_a_measured_minus_computed_gnss_row_gets_gnss_minus_ins(tmp_path):
    """difference: measured_minus_computed (documented) flips H; the navigator kept z = INS - GNSS for such a row,
    so every GNSS update pushed the wrong way (1462 m RMS outside outages on the test excerpt, against 0.05 m)."""
    plain = _spec(tmp_path, MODEL.replace("DIFFERENCE", ""), "plain.yaml")
    flipped = _spec(tmp_path, MODEL.replace("DIFFERENCE", ", difference: measured_minus_computed"), "flipped.yaml")
    assert [r.sign for r in plain.gnss_rows] == [1.0] * 6
    assert [r.sign for r in flipped.gnss_rows] == [-1.0] * 3 + [1.0] * 3
    dv, dp, sig = np.array([0.1, -0.2, 0.3]), np.array([1.0, 2.0, -3.0]), np.ones(6)
    z_plain, z_flipped = plain.gnss_z(dv, dp, sig)[0], flipped.gnss_z(dv, dp, sig)[0]
    assert np.array_equal(z_flipped[:3], -z_plain[:3]) and np.array_equal(z_flipped[3:], z_plain[3:])
    import sympy as sp

    sum_of_rows = (flipped.derived.H[:3, :] + plain.derived.H[:3, :]).applyfunc(sp.simplify)
    assert sum_of_rows == sp.zeros(3, plain.n_states)  # H flipped too: z - H x is the same update


def test_a_gnss_position_row_along_up_in_an_ned_model_gets_the_up_difference(tmp_path):
    """axes: [north, east, up] (documented) makes the third row -position_error_down; the navigator took the block's
    sign alone and filled it with the down difference, so the height updates pushed the wrong way (2.0 m RMS outside
    outages on the test excerpt against 0.050 m with the rows along down)."""
    spec = _spec(tmp_path, MODEL.replace("DIFFERENCE", ", axes: [north, east, up]"))
    assert [(r.kind, r.axis, r.sign) for r in spec.gnss_rows[:3]] == [("position", 0, 1.0), ("position", 1, 1.0),
                                                                      ("position", 2, -1.0)]
    z = spec.gnss_z(np.zeros(3), np.array([1.0, 2.0, 3.0]), np.ones(6))[0]
    assert z[2] == -3.0  # up = -down, as H says


@pytest.mark.parametrize("parameter, problem", [
    ("{name: gyro_noise, symbol: N_g, unit: rad/sqrt(s), value: 3.5e-5}", "does not use the parameter gyro_angle_random_walk"),
    ("{name: gyro_angle_random_walk, symbol: N_g, unit: rad/sqrt(s), value: 3.5e-5}", "has a default value"),
])
def test_a_gyro_white_noise_the_configuration_cannot_reach_is_refused_at_its_noises_line(tmp_path, parameter, problem):
    text = MODEL.replace("DIFFERENCE", "").replace("{name: gyro_angle_random_walk, symbol: N_g, unit: rad/sqrt(s)}",
                                                   parameter)
    with pytest.raises(ModelError, match=rf"m\.yaml:13: white noise gyro_white_noise_x: .*{problem}.*noise\.gyro_white"):
        _spec(tmp_path, text)


def test_a_geodetic_gnss_position_measurement_is_refused_at_its_line(tmp_path):
    """form: geodetic (latitude and longitude in rad, documented) was filled with INS minus GNSS in metres and R in
    square metres: a metre taken for a radian, silently."""
    text = MODEL.replace('{of: position, form: metres, symbols: [z_n, z_e, z_d], variance: "sigma_r**2"DIFFERENCE}',
                         '{of: position, form: geodetic, symbols: [z_L, z_l, z_h], variance: "1.0e-12"}')
    with pytest.raises(ModelError, match=r"m\.yaml:15: measurement 'position_difference_z_L' is in rad: the navigator's "
                                         r"GNSS update fills position rows with INS minus GNSS in m .*form: metres"):
        _spec(tmp_path, text)
