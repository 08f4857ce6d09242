"""The check: section of a model file: parsed as data, validated against the model, inherited by transforms."""

import numpy as np
import pytest

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.loading import load_model, load_model_text
from modelgen.jobs import check_scenario

MODEL = """\
model: tilt
parameters:
  - {name: gravity, symbol: g, value: 9.8}
  - {name: earth_radius, symbol: R}
  - {name: velocity_sigma, symbol: s_v}
states:
  - {name: tilt_error, symbol: phi}
  - {name: velocity_error, symbol: dv}
dynamics:
  phi: -dv/R
  dv: g*phi
measurements:
  - {name: velocity_difference, symbol: z, expression: dv, variance: "s_v**2"}
"""

CHECK = """\
check:
  step_s: 0.5
  steps: 40
  parameters:
    earth_radius: {value: 6371, unit: km}
    velocity_sigma: 0.1
  initial_sigma:
    tilt_error: {value: 60, unit: arcsec}
    velocity_error: 0.5
"""


def load(check: str):
    return load_model_text(MODEL + check, "m.yaml")


def test_check_section_becomes_the_scenario_in_si():
    derived = derive(load(CHECK))
    scenario = check_scenario(derived)
    assert scenario.step == 0.5 and scenario.steps == 40
    assert scenario.parameters == {"earth_radius": 6371e3, "velocity_sigma": 0.1}
    sigma = np.sqrt(np.diag(scenario.initial_covariance))
    np.testing.assert_allclose(sigma, [60 * np.pi / 180 / 3600, 0.5], rtol=1e-15)
    assert "check scenario" in scenario.label


def test_a_full_initial_covariance_is_accepted_in_state_order():
    text = CHECK.split("  initial_sigma:")[0] + "  initial_covariance: [[1.0e-8, 1.0e-5], [1.0e-5, 0.25]]\n"
    P0 = check_scenario(derive(load(text))).initial_covariance
    np.testing.assert_array_equal(P0, [[1e-8, 1e-5], [1e-5, 0.25]])


@pytest.mark.parametrize(
    "change, message",
    [
        (("steps: 40", "steps: 0"), "m.yaml:16: check.steps: expected a positive integer"),
        (("steps: 40", "steps: 4.5"), "check.steps: expected a positive integer"),
        (("step_s: 0.5", "step_s: 0"), "m.yaml:15: check.step_s: the step must be positive"),
        (("step_s: 0.5", "step_s: -1"), "the step must be positive"),
        (("step_s: 0.5", "step_s: .nan"), "not finite"),
        (("step_s: 0.5", "step_s: '1+1'"), "'1+1' is not a number"),
        (("  step_s: 0.5\n", ""), "check section has no 'step_s'"),
        (("velocity_sigma: 0.1", "velocity_sigmaa: 0.1"), "unknown parameter(s) velocity_sigmaa"),
        (("    velocity_sigma: 0.1\n", ""), "gives no value for velocity_sigma (no default)"),
        (("    velocity_error: 0.5\n", ""), "no sigma for state(s) velocity_error"),
        (("velocity_error: 0.5", "velocity_error: -0.5"), "check.initial_sigma.velocity_error: a standard deviation cannot be negative"),
        (("unit: km}", "unit: furlong}"), "unknown unit 'furlong'"),
        (("unit: km}", "unit: km, scale: 2}"), "expected a number or {value: <number>, unit: <unit>}"),
        (("steps: 40", "steps: 40\n  seeds: 3"), "unknown key check.seeds"),
        (("steps: 40", "steps: 10000000"), "more than the limit"),
    ],
)
def test_a_bad_check_section_is_refused_with_file_line_and_key(change, message):
    old, new = change
    assert old in CHECK
    with pytest.raises(ModelError) as err:
        load(CHECK.replace(old, new))
    assert message in str(err.value)


@pytest.mark.parametrize(
    "matrix, message",
    [
        ("[[1.0, 0.5], [0.4, 1.0]]", "not symmetric"),
        ("[[1.0, 2.0], [2.0, 1.0]]", "not positive semidefinite"),
        ("[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]", "is 3x3, the model has 2 states"),
        ("[[1.0, 0.0], [0.0]]", "expected a square matrix"),
    ],
)
def test_a_bad_initial_covariance_is_refused(matrix, message):
    text = CHECK.split("  initial_sigma:")[0] + f"  initial_covariance: {matrix}\n"
    with pytest.raises(ModelError) as err:
        load(text)
    assert "initial_covariance" in str(err.value) and message in str(err.value)


def test_both_sigmas_and_a_covariance_are_refused():
    with pytest.raises(ModelError, match="both initial_sigma and initial_covariance"):
        load(CHECK + "  initial_covariance: [[1.0, 0.0], [0.0, 1.0]]\n")


def test_a_reduced_transform_inherits_its_base_scenario_without_the_removed_states():
    base, reduced = load_model("ned_doppler18"), load_model("ned_doppler13_reduced")
    assert reduced.check.step_s == base.check.step_s == 60.0 and reduced.check.steps == 240
    sigma_base, sigma_reduced = dict(base.check.initial_sigma), dict(reduced.check.initial_sigma)
    assert list(sigma_reduced) == reduced.state_names
    assert all(sigma_reduced[s] == sigma_base[s] for s in reduced.state_names if s in sigma_base)


def test_an_augmented_transform_lays_its_own_section_over_the_base_one():
    base, augmented = load_model("ned_doppler18"), load_model("ned_doppler32_augmented")
    params = augmented.check.parameter_values()
    assert {"body_rate_x", "body_specific_force_z"} <= set(params)
    assert params["latitude"] == base.check.parameter_values()["latitude"]
    assert len(augmented.check.initial_sigma) == 32


def test_a_transform_file_naming_an_unknown_state_in_its_check_section_is_refused(tmp_path):
    (tmp_path / "t.yaml").write_text(
        "model: reduced\nbase: ned_doppler18\ntransforms:\n  - markov_to_white: {states: [eps_r_z]}\n"
        "check:\n  initial_sigma:\n    gyro_markov_drift_zz: 1.0e-6\n"
    )
    with pytest.raises(ModelError, match="unknown state\\(s\\) gyro_markov_drift_zz"):
        load_model(tmp_path / "t.yaml")


AUGMENT = (
    "model: scaled\nbase: ned_doppler18\ntransforms:\n  - augment:\n      states: [{name: doppler_scale_factor, symbol: k_d}]\n"
    "      equations: {k_d: '0'}\n      measurement_terms: {Z_n: '-V_n*k_d'}\n"
)


def test_an_added_state_without_a_sigma_leaves_the_transform_without_a_check_scenario(tmp_path):
    """Nothing to inherit for the new state: the model loads, and --check falls back to the labelled synthetic scenario."""
    (tmp_path / "t.yaml").write_text(AUGMENT)
    model = load_model(tmp_path / "t.yaml")
    assert model.check is None
    assert check_scenario(derive(model)).label.startswith("synthetic")


def test_a_transform_check_section_must_complete_the_inherited_one(tmp_path):
    (tmp_path / "t.yaml").write_text(AUGMENT + "check:\n  steps: 10\n")
    with pytest.raises(ModelError, match="no sigma for state\\(s\\) doppler_scale_factor"):
        load_model(tmp_path / "t.yaml")
    (tmp_path / "t.yaml").write_text(AUGMENT + "check:\n  steps: 10\n  initial_sigma:\n    doppler_scale_factor: 1.0e-3\n")
    model = load_model(tmp_path / "t.yaml")
    assert model.check.steps == 10 and model.check.step_s == 60.0


# -- initial_sigma by vector stem (issue 27) -------------------------------------------------------
_NAV = open(__import__("pathlib").Path(__file__).resolve().parents[2] / "modelgen" / "models" / "ins_gnss21_nav.yaml").read()
_SIGMA_BY_NAME = _NAV[_NAV.index("  initial_sigma:"):]


def _with_sigma(text: str) -> str:
    return _NAV.replace(_SIGMA_BY_NAME, text)


def test_initial_sigma_by_vector_stem_equals_the_same_sigmas_by_state_name(loaded_builtin):
    by_name = loaded_builtin("ins_gnss21_nav").check
    stems = _with_sigma(
        "  initial_sigma: {position_error: [5.0, 5.0, 8.0], velocity_error: [0.2, 0.2, 0.3],\n"
        "    attitude_error: {value: [0.05, 0.05, 0.5], unit: deg}, gyro_bias: {value: 0.01, unit: deg/h},\n"
        "    accel_bias: {value: 2.5e-5, unit: g}, gyro_scale_factor: 5.0e-6, accel_scale_factor: 1.0e-4}\n"
    )
    by_stem = load_model_text(stems, filename="m.yaml").check
    assert [name for name, _ in by_stem.initial_sigma] == [name for name, _ in by_name.initial_sigma]
    np.testing.assert_allclose([v for _, v in by_stem.initial_sigma], [v for _, v in by_name.initial_sigma], rtol=1e-15)


def test_a_state_named_beside_its_stem_wins_over_the_stem():
    text = _with_sigma(
        "  initial_sigma: {position_error: 5.0, position_error_down: 8.0, velocity_error: 0.2, attitude_error: 0.001,\n"
        "    gyro_bias: 1.0e-7, accel_bias: 1.0e-4, gyro_scale_factor: 5.0e-6, accel_scale_factor: 1.0e-4}\n"
    )
    sigma = dict(load_model_text(text, filename="m.yaml").check.initial_sigma)
    assert (sigma["position_error_north"], sigma["position_error_east"], sigma["position_error_down"]) == (5.0, 5.0, 8.0)


@pytest.mark.parametrize(
    "entry, message",
    [
        ("gyro_bias: [1.0e-7, 1.0e-7]", "check.initial_sigma.gyro_bias lists 2 values for the 3 states gyro_bias_x, gyro_bias_y, gyro_bias_z"),
        ("gyro_bias_x: [1.0e-7, 1.0e-7]", "'gyro_bias_x' is one state; give one number, not a list of 2"),
        ("gyro_drift: 1.0e-7", "unknown state(s) gyro_drift"),
        ("gyro_bias: [1.0e-7, -1.0, 1.0e-7]", "a standard deviation cannot be negative"),
    ],
)
def test_a_bad_stem_entry_is_refused_with_file_line(entry, message):
    text = _with_sigma(
        "  initial_sigma: {position_error: 5.0, velocity_error: 0.2, attitude_error: 0.001, accel_bias: 1.0e-4,\n"
        f"    gyro_bias: 1.0e-7, gyro_scale_factor: 5.0e-6, accel_scale_factor: 1.0e-4, {entry}}}\n"
    )
    if entry.startswith("gyro_bias:"):
        text = text.replace("    gyro_bias: 1.0e-7, ", "    ")
    with pytest.raises(ModelError, match=r"^m\.yaml:\d+: ") as caught:
        load_model_text(text, filename="m.yaml")
    assert message in str(caught.value)
