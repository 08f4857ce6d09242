"""Body rate and specific force in measurement expressions, measurement-bias processes, per-axis statistics (issue 27)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.loading import load_model_text

ODOMETER = """\
model: odometer
frame: NED
parameters:
  - {name: odometer_arm_x, symbol: l_x, unit: m}
  - {name: odometer_arm_y, symbol: l_y, unit: m}
  - {name: odometer_arm_z, symbol: l_z, unit: m}
  - {name: odometer_sigma, symbol: sigma_o, unit: m/s}
navigation:
  errors: {attitude: {form: phi}, velocity: {form: difference}, position: {form: metres}}
  sensor_errors:
    - {of: gyro_bias, process: random_constant}
  measurements:   # the wheel's velocity in body axes: v_b + omega_ib x l (Earth rate neglected at the wheel)
    - {of: expression, expression: "transpose(C_b_n)*v_n + cross(omega_ib_b, vector(l_x, l_y, l_z))",
       symbols: [z_x, z_y, z_z], variance: "sigma_o**2", units: [m/s, m/s, m/s]BIAS}
"""


def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _values(model, rng):
    values = {p.name: float(rng.uniform(0.2, 1.5)) for p in model.parameters}
    C = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    values.update({f"c{i + 1}{j + 1}": C[i, j] for i in range(3) for j in range(3)})
    return values, C


def test_an_odometer_with_a_lever_arm_sees_the_body_rate_and_its_gyro_bias():
    model = load_model_text(ODOMETER.replace("BIAS", ""), "m.yaml")
    derived = derive(model)
    values, C = _values(model, np.random.default_rng(27))
    H = derived.numeric(values)["H"]
    names = [s.name for s in model.states]
    v = np.array([values[f"velocity_{a}"] for a in ("north", "east", "down")])
    lever = np.array([values[f"odometer_arm_{a}"] for a in "xyz"])
    column = lambda prefix: [names.index(n) for n in names if n.startswith(prefix)]  # noqa: E731
    # computed minus true: C^T dv - C^T [v x] phi (true C = (I + [phi x]) C) + b_g x l (true rate = sensed - b_g)
    np.testing.assert_allclose(H[:, column("velocity_error")], C.T, rtol=0, atol=1e-14)
    np.testing.assert_allclose(H[:, column("attitude_error")], -C.T @ _skew(v), rtol=0, atol=1e-14)
    np.testing.assert_allclose(H[:, column("gyro_bias")], -_skew(lever), rtol=0, atol=1e-14)


def test_the_specific_force_in_body_axes_is_usable_and_carries_the_accelerometer_errors():
    text = ODOMETER.replace("BIAS", "").replace("of: gyro_bias, process: random_constant", "of: accel_bias, process: random_constant")
    text = text.replace('"transpose(C_b_n)*v_n + cross(omega_ib_b, vector(l_x, l_y, l_z))"', '"f_b"').replace("[m/s, m/s, m/s]", "[m/s^2, m/s^2, m/s^2]")
    text = text.replace("sigma_o, unit: m/s}", "sigma_o, unit: m/s^2}")
    model = load_model_text(text, "m.yaml")
    H = derive(model).numeric(_values(model, np.random.default_rng(3))[0])["H"]
    names = [s.name for s in model.states]
    bias = [names.index(f"accel_bias_{a}") for a in "xyz"]
    np.testing.assert_allclose(H[:, bias], np.eye(3), atol=1e-14)  # sensed f = true f + b_a: computed minus true = b_a
    assert np.abs(np.delete(H, bias, axis=1)).max() < 1e-14


@pytest.mark.parametrize(
    "process, rate",
    [
        ("{process: gauss_markov, symbols: [b_x, b_y, b_z], rate: mu_o, sigma: [0.01, 0.02, 0.03]}", "-mu_o*b_x"),
        ("{process: random_walk, symbols: [b_x, b_y, b_z], psd: [1.0e-6, 2.0e-6, 3.0e-6]}", "0"),
    ],
)
def test_a_measurement_bias_may_be_gauss_markov_or_random_walk_with_per_axis_statistics(process, rate):
    text = ODOMETER.replace("BIAS", f", bias: {process}").replace(
        "  - {name: odometer_sigma", "  - {name: odometer_bias_rate, symbol: mu_o, unit: 1/s}\n  - {name: odometer_sigma")
    model = load_model_text(text, "m.yaml")
    assert model.dynamics["b_x_bias"] == sp.sympify(rate, locals={"mu_o": sp.Symbol("mu_o", real=True), "b_x": sp.Symbol("b_x", real=True)}) + sp.Symbol("w_b_x", real=True)
    noises = {n.name: n for n in model.noises}
    psds = [str(noises[f"b_{a}_bias_driving_noise"].psd) for a in "xyz"]
    assert len(set(psds)) == 3  # one statistic per axis
    derived = derive(model)
    Q = derived.numeric({**_values(model, np.random.default_rng(5))[0], "odometer_bias_rate": 0.5})["Q"]
    expected = [2 * 0.5 * s**2 for s in (0.01, 0.02, 0.03)] if "gauss" in process else [1e-6, 2e-6, 3e-6]
    np.testing.assert_allclose(sorted(np.diag(Q))[-3:], sorted(expected), rtol=1e-12)


@pytest.mark.parametrize(
    "bias, message",
    [
        ("{process: gauss_markov, symbols: [b_x, b_y, b_z], rate: 1.0}", "a Gauss-Markov measurement bias needs 'sigma'"),
        ("{process: random_walk, symbols: [b_x, b_y, b_z]}", "a random-walk measurement bias needs 'psd'"),
        ("{process: random_walk, symbols: [b_x, b_y, b_z], psd: [1.0, 2.0]}", "psd lists 2 values for 3 components"),
        ("{process: flicker, symbols: [b_x, b_y, b_z]}", "'flicker' is not one of random_constant, gauss_markov, random_walk"),
    ],
)
def test_a_bad_measurement_bias_is_refused_with_file_line(bias, message):
    with pytest.raises(ModelError, match=r"^m\.yaml:\d+: ") as caught:
        load_model_text(ODOMETER.replace("BIAS", f", bias: {bias}"), "m.yaml")
    assert message in str(caught.value)


def test_per_axis_sensor_error_sigmas_and_noise_psds():
    text = ODOMETER.replace("BIAS", "").replace(
        "    - {of: gyro_bias, process: random_constant}",
        "    - {of: gyro_bias, process: gauss_markov, rate: 0.01, sigma: [1.0e-5, 2.0e-5, 3.0e-5]}",
    ).replace("  measurements:", "  noises: {accel: {psd: [1.0e-6, 2.0e-6, 4.0e-6]}}\n  measurements:")
    model = load_model_text(text, "m.yaml")
    noises = {n.name: str(n.psd) for n in model.noises}
    assert len({noises[f"gyro_bias_driving_noise_{a}"] for a in "xyz"}) == 3
    assert [float(noises[f"accel_white_noise_{a}"]) for a in "xyz"] == [1.0e-6, 2.0e-6, 4.0e-6]


def test_a_vector_parameter_is_declared_by_component_and_used_whole_in_expressions():
    text = ODOMETER.replace("BIAS", "").replace(
        "  - {name: odometer_arm_x, symbol: l_x, unit: m}\n  - {name: odometer_arm_y, symbol: l_y, unit: m}\n"
        "  - {name: odometer_arm_z, symbol: l_z, unit: m}\n",
        "  - {name: odometer_arm, symbol: l, shape: 3, axes: body, unit: m, value: [1.5, -0.2, 0.4]}\n",
    ).replace("cross(omega_ib_b, vector(l_x, l_y, l_z))", "cross(omega_ib_b, l)")
    model = load_model_text(text, "m.yaml")
    arm = {p.name: (p.symbol, p.value) for p in model.parameters if p.name.startswith("odometer_arm")}
    assert arm == {"odometer_arm_x": ("l_x", 1.5), "odometer_arm_y": ("l_y", -0.2), "odometer_arm_z": ("l_z", 0.4)}
    by_components = load_model_text(ODOMETER.replace("BIAS", ""), "m.yaml")
    assert model.measurement_expressions == by_components.measurement_expressions


@pytest.mark.parametrize(
    "entry, message",
    [
        ("{name: arm, shape: 3, value: [1.0, 2.0]}", "parameter 'arm' is a 3-vector: its value must list 3 numbers"),
        ("{name: arm, shape: [3, 3]}", "a navigation model's parameter is a scalar or a 3-vector"),
        ("{name: arm, axes: body}", "'axes' is for a vector parameter (shape: 3)"),
        ("{name: arm, shape: 3, axes: wing}", "parameters[3].axes 'wing' is not one of body, navigation"),
    ],
)
def test_a_bad_vector_parameter_is_refused_with_file_line(entry, message):
    text = ODOMETER.replace("BIAS", "").replace("  - {name: odometer_sigma", f"  - {entry}\n  - {{name: odometer_sigma")
    with pytest.raises(ModelError, match=r"^m\.yaml:\d+: ") as caught:
        load_model_text(text, "m.yaml")
    assert message in str(caught.value)
