"""Model files with a ``navigation:`` section: the error model derived from the navigation equations.

The twins of the hand-written models must reproduce them entry by entry
(numerically at the check scenario, same states, noises and measurements in
the same order) once the hand model's own approximations are declared, and
every term an approximation drops must be listed with its size.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from modelgen.derivation.symbolic import derive
from modelgen.model.navigation_model.approximation_notes import neglected_terms


def _numeric(model):
    values = dict(model.parameter_defaults())
    values.update(model.check.parameter_values())
    return derive(model).numeric(values)


TWINS = ("ins_gps15", "gps_pseudorange11")


@pytest.fixture(scope="module")
def ins_gps15_pair(loaded_builtin):
    return loaded_builtin("ins_gps15"), loaded_builtin("ins_gps15_twin")


@pytest.mark.parametrize("hand_name", TWINS)
def test_twin_declares_the_hand_models_states_noises_and_measurements_in_order(hand_name, loaded_builtin):
    hand, twin = loaded_builtin(hand_name), loaded_builtin(f"{hand_name}_twin")
    assert [(s.name, s.symbol) for s in twin.states] == [(s.name, s.symbol) for s in hand.states]
    assert [(n.name, n.symbol) for n in twin.noises] == [(n.name, n.symbol) for n in hand.noises]
    assert [(m.name, m.symbol) for m in twin.measurements] == [(m.name, m.symbol) for m in hand.measurements]


@pytest.mark.parametrize("hand_name", TWINS)
def test_twin_F_G_H_Q_R_equal_the_hand_model_at_its_check_scenario(hand_name, loaded_builtin):
    """ins_gps15 (phi-angle, geodetic position) and Benson's psi-angle pseudo-range model, derived."""
    hand, twin = loaded_builtin(hand_name), loaded_builtin(f"{hand_name}_twin")
    derived, written = _numeric(twin), _numeric(hand)
    for key in "FGHQR":
        scale = np.maximum(1.0, np.abs(written[key]))
        assert np.all(np.abs(derived[key] - written[key]) <= 1e-14 * scale), key


def test_pseudorange_twin_drops_only_spherical_earth_and_gravity_terms_and_sizes_them(loaded_builtin):
    twin = loaded_builtin("gps_pseudorange11_twin")
    terms = neglected_terms(twin)
    assert {t.approximation for t in terms} == {"gravity_height_only", "free_air_gradient", "no_height_in_radii", "single_earth_radius"}
    assert all(t.matrix == "F" for t in terms)  # H (line of sight, clock) is exact: the range is linearized, not approximated
    notes = [n for n in twin.notes if n.startswith("Approximation single_earth_radius")]
    assert re.search(r"F\[position_error_east, position_error_north\] = [^;]*dR_N/dL[^;]*\(6\.44e-09\)", notes[0])


def test_ins_gps15_twin_lists_every_term_its_approximations_drop_with_its_size(ins_gps15_pair):
    _, twin = ins_gps15_pair
    terms = neglected_terms(twin)
    by_approximation = {t.approximation for t in terms}
    assert by_approximation == {"constant_radii", "gravity_height_only", "free_air_gradient"}
    # dg/dL: normal gravity grows ~0.05 m/s^2 per radian of latitude at 34 deg: the dv_U/dL entry
    gravity = [t for t in terms if t.approximation == "gravity_height_only"]
    assert [(t.matrix, t.row, t.column) for t in gravity] == [("F", 5, 6)]
    notes = [n for n in twin.notes if n.startswith("Approximation gravity_height_only")]
    assert notes and "F[velocity_error_up, latitude_error] = -dg/dL (0.048)" in notes[0]


@pytest.mark.compile
def test_readme_navigation_example_is_under_40_lines_and_generates_and_passes_the_compiled_check(tmp_path):
    import re

    from click.testing import CliRunner

    from conftest import REPO
    from modelgen.cli import main

    blocks = re.findall(r"```yaml\n(.*?)```", (REPO / "docs" / "model-language.md").read_text(encoding="utf-8"), re.S)
    example = next(b for b in blocks if "model: ins_gnss15_example" in b)
    assert len(example.splitlines()) < 40
    path = tmp_path / "ins_gnss15_example.yaml"
    path.write_text(example)
    result = CliRunner().invoke(main, ["generate", str(path), "--out", str(tmp_path / "gen"), "--check"])
    assert result.exit_code == 0, result.output
    assert "check c" in result.output and "FAILED" not in result.output


JANUS = """
model: janus_doppler
frame: NED
parameters:
  - {name: q, value: 1.0e-6}   # the PSD of both the gyro and the accelerometer noise: no one unit
  - {name: beam_sigma, symbol: sigma_b, unit: m/s, value: 0.05}
  - {name: depression_cos, symbol: cg, unit: "1", value: 0.8660254037844386}
  - {name: depression_sin, symbol: sg, unit: "1", value: 0.5}
navigation:
  errors:
    position: {form: metres, symbol: dr}
    velocity: {form: difference, symbol: dv}
    attitude: {form: phi, symbol: phi}
  noises: {gyro: {psd: q}, accel: {psd: q}}
  measurements:   # four Janus beams (forward/aft, left/right at 30 deg depression): body velocity along each beam
    - {of: expression, expression: "dot(vector(cg, 0, sg), transpose(C_b_n)*v_n)", symbols: [z_1], variance: "sigma_b**2", units: [m/s]}
    - {of: expression, expression: "dot(vector(-cg, 0, sg), transpose(C_b_n)*v_n)", symbols: [z_2], variance: "sigma_b**2", units: [m/s]}
    - {of: expression, expression: "dot(vector(0, cg, sg), transpose(C_b_n)*v_n)", symbols: [z_3], variance: "sigma_b**2", units: [m/s]}
    - {of: expression, expression: "dot(vector(0, -cg, sg), transpose(C_b_n)*v_n)", symbols: [z_4], variance: "sigma_b**2", units: [m/s]}
"""


def test_janus_doppler_beam_rows_are_b_transpose_C_transpose_on_dv_and_on_v_cross_phi():
    """z_k = b_k . C^T v (the Doppler error thesis's Janus beams); perturbed: H = [0, b^T C^T, -b^T C^T [v x]] (no C C^T = I needed)."""
    from modelgen.model.loading import load_model_text

    model = load_model_text(JANUS, "janus.yaml")
    derived = derive(model)
    rng = np.random.default_rng(5)
    C = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    C *= np.sign(np.linalg.det(C))
    v = np.array([80.0, -20.0, 1.5])
    values = {f"c{i + 1}{j + 1}": C[i, j] for i in range(3) for j in range(3)}
    values.update(velocity_north=v[0], velocity_east=v[1], velocity_down=v[2], latitude=0.7, height=100.0,
                  meridian_radius=6.36e6, prime_vertical_radius=6.39e6, gravity=9.8,
                  body_specific_force_x=0.0, body_specific_force_y=0.0, body_specific_force_z=-9.8)
    H = derived.numeric(values)["H"]
    cg, sg = np.sqrt(3) / 2, 0.5
    beams = np.array([[cg, 0, sg], [-cg, 0, sg], [0, cg, sg], [0, -cg, sg]])
    cross_v = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    expected = np.hstack([np.zeros((4, 3)), beams @ C.T, -beams @ C.T @ cross_v])
    assert np.allclose(H, expected, rtol=0, atol=1e-12)


RANGE_RATE = """
model: range_rate
frame: ENU
parameters:
  - {name: q, value: 1.0e-6}   # the PSD of both the gyro and the accelerometer noise: no one unit
  - {name: rate_sigma, symbol: sigma_d, unit: m/s, value: 0.05}
navigation:
  errors:
    position: {form: metres, symbol: dr}
    velocity: {form: difference, symbol: dv}
    attitude: {form: phi, symbol: phi}
  sensor_errors:
    - {of: receiver_clock, process: clock, symbols: [b_clk, d_clk], psd: [q, q]}
  noises: {gyro: {psd: q}, accel: {psd: q}}
  measurements:
    - {of: pseudorange_rate, difference: measured_minus_computed, symbols: [zd_1, zd_2], variance: "sigma_d**2",
       line_of_sight: [[e_1_x, e_1_y, e_1_z], [e_2_x, e_2_y, e_2_z]], range: [rho_1, rho_2],
       satellite_velocity: [[s_1_x, s_1_y, s_1_z], [s_2_x, s_2_y, s_2_z]]}
"""


def test_pseudorange_rate_rows_see_velocity_along_the_line_of_sight_position_through_its_turn_and_the_clock_drift():
    """z = e . dv + (v_s - v)^T (I - e e^T) dr / rho + drift (measured minus computed), derived from u(d) . (v_s - v)."""
    from modelgen.model.loading import load_model_text

    model = load_model_text(RANGE_RATE, "range_rate.yaml")
    names = [s.name for s in model.states]
    e = np.array([[0.3, 0.5, np.sqrt(1 - 0.34)], [-0.6, 0.0, 0.8]])
    rho = np.array([2.1e7, 2.4e7])
    sat = np.array([[1200.0, -300.0, 800.0], [-500.0, 2500.0, 100.0]])
    v = np.array([30.0, 40.0, -1.0])
    values = {"velocity_east": v[0], "velocity_north": v[1], "velocity_up": v[2], "latitude": 0.7, "height": 10.0,
              "meridian_radius": 6.36e6, "prime_vertical_radius": 6.39e6, "gravity": 9.8,
              "body_specific_force_x": 0.0, "body_specific_force_y": 0.0, "body_specific_force_z": 9.8}
    values.update({f"c{i}{j}": float(i == j) for i in (1, 2, 3) for j in (1, 2, 3)})
    for k in range(2):
        values.update({f"line_of_sight_{w}_{k + 1}": e[k, a] for a, w in enumerate(("east", "north", "up"))})
        values.update({f"satellite_velocity_{w}_{k + 1}": sat[k, a] for a, w in enumerate(("east", "north", "up"))})
        values[f"satellite_range_{k + 1}"] = rho[k]
    H = derive(model).numeric(values)["H"]
    for k in range(2):
        expected = np.zeros(len(names))
        expected[3:6] = e[k]
        expected[0:3] = (sat[k] - v) @ (np.eye(3) - np.outer(e[k], e[k])) / rho[k]
        expected[names.index("clock_drift_range")] = 1.0
        assert np.allclose(H[k], expected, rtol=1e-12, atol=1e-15), (H[k], expected)


WRITTEN = """
model: written
frame: NED
parameters:
  - {name: q, value: 1.0e-6}   # the PSD of both the gyro and the accelerometer noise: no one unit
navigation:
  errors:
    position: {form: metres, symbol: dr}
    velocity: {form: difference, symbol: dv}
    attitude: {form: phi, symbol: phi}
  noises: {gyro: {psd: q}, accel: {psd: q}}
"""
EQUATIONS = """  equations:
    velocity: "f_n - cross(2*omega_ie_n + omega_en_n, v_n) + g_n"
    position: "vector(dot(vector(1, 0, 0), v_n)/(R_M + height), dot(vector(0, 1, 0), v_n)/((R_N + height)*cos(latitude)), -dot(vector(0, 0, 1), v_n))"
"""


def test_written_navigation_equations_give_the_named_mechanizations_error_model():
    """The same equations written out as vector expressions derive the same F, G; a changed one changes F."""
    from modelgen.model.loading import load_model_text

    values = {"latitude": 0.7, "height": 300.0, "velocity_north": 80.0, "velocity_east": -30.0, "velocity_down": 1.0,
              "meridian_radius": 6.36e6, "prime_vertical_radius": 6.39e6, "gravity": 9.8,
              "body_specific_force_x": 0.2, "body_specific_force_y": -0.1, "body_specific_force_z": -9.8}
    values.update({f"c{i}{j}": float(i == j) for i in (1, 2, 3) for j in (1, 2, 3)})
    named = derive(load_model_text(WRITTEN, "named.yaml")).numeric(values)
    written = derive(load_model_text(WRITTEN + EQUATIONS, "written.yaml")).numeric(values)
    for key in "FGH":
        np.testing.assert_allclose(written[key], named[key], rtol=1e-13, atol=1e-20)
    changed = WRITTEN + EQUATIONS.replace(" - cross(2*omega_ie_n + omega_en_n, v_n)", "")
    no_coriolis = derive(load_model_text(changed, "changed.yaml")).numeric(values)
    assert np.abs(no_coriolis["F"] - named["F"]).max() > 1e-5


def test_a_pseudorange_s_displacement_at_the_computed_position_is_listed_among_the_approximations_declared_or_not(
        loaded_builtin):
    """d = M (computed) (p - p_c) in a pseudo-range (rate) is an approximation (exact to first order: it drops no
    term): the twin declares it and its notes list it; a file that does not declare it has it listed anyway, naming
    the measurement that makes it.  Before, neither listed it."""
    from modelgen.model.loading import load_model_text

    twin = [n for n in loaded_builtin("gps_pseudorange11_twin").notes
            if n.startswith("Approximation pseudorange_at_computed_position (")]
    assert len(twin) == 1 and "M (computed)" in twin[0] and "dropped no term in this model" in twin[0]
    assert "declared or not" not in twin[0]
    notes = load_model_text(RANGE_RATE, "range_rate.yaml").notes
    implied = [n for n in notes if n.startswith("Approximation pseudorange_at_computed_position (")]
    assert len(implied) == 1 and "made by navigation.measurements[0] (of: pseudorange_rate), declared or not" in implied[0]
