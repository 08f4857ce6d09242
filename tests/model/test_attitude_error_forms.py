"""Attitude error as a rotation vector (multiplicative, navigation or body axes) and its reset Jacobian (issue 27)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.loading import load_model_text
from modelgen.model.loading import builtin_model_path

NAV = builtin_model_path("ins_gnss21_nav").read_text()
BODY = NAV.replace("attitude: {form: phi, symbol: phi}", "attitude: {form: rotation_vector, axes: body}").replace(
    "attitude_error_north:", "attitude_error_x:").replace("attitude_error_east:", "attitude_error_y:").replace(
    "attitude_error_down:", "attitude_error_z:")
NAVIGATION_AXES = NAV.replace("attitude: {form: phi, symbol: phi}", "attitude: {form: rotation_vector, symbol: phi}")


def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


@pytest.fixture(scope="module")
def phi_and_body(derived_builtin):
    phi = derived_builtin("ins_gnss21_nav").model
    body = load_model_text(BODY, filename="body.yaml")
    values = {**dict(phi.parameter_defaults()), **phi.check.parameter_values()}
    # orthogonal to rounding (the scenario's 12 digits leave C C^T - I ~ 1e-12, which the symbolic C^T C = I step meets)
    C = Rotation.from_euler("ZYX", [30, 2, 1], degrees=True).as_matrix()
    values.update({f"c{i + 1}{j + 1}": C[i, j] for i in range(3) for j in range(3)})
    return phi, body, derived_builtin("ins_gnss21_nav").numeric(values), derive(body).numeric({k: v for k, v in values.items() if k in body.parameter_names}), values


def test_a_navigation_axes_rotation_vector_is_the_phi_angle_to_first_order(derived_builtin):
    phi = derived_builtin("ins_gnss21_nav")
    rotation = derive(load_model_text(NAVIGATION_AXES, filename="nav.yaml"))
    assert phi.F == rotation.F and phi.G == rotation.G and phi.H == rotation.H


def test_body_axes_rotation_vector_has_the_mekf_attitude_block(phi_and_body):
    """theta = -C^T phi: theta' = -[w_ib x] theta + dw (Markley 2003 with the Earth-rate terms), dw = b_g + diag(w) s_g + w_g."""
    _, body, _, numbers, values = phi_and_body
    names = [s.name for s in body.states]
    att = [names.index(f"attitude_error_{a}") for a in "xyz"]
    gyro = [names.index(f"gyro_bias_{a}") for a in "xyz"]
    w = np.array([values[f"body_rate_{a}"] for a in "xyz"])
    F = numbers["F"]
    np.testing.assert_allclose(F[np.ix_(att, att)], -_skew(w), rtol=0, atol=1e-15 * np.abs(w).max())
    np.testing.assert_allclose(F[np.ix_(att, gyro)], np.eye(3), rtol=0, atol=1e-15)


def test_body_axes_F_G_H_equal_the_phi_model_through_theta_equals_minus_C_transpose_phi(phi_and_body):
    """F_b = T F T^-1 + dT/dt T^-1 with T = -C^T on the attitude rows, dT/dt = [w x] C^T - C^T [w_in x] (typed here)."""
    phi, body, phi_numbers, numbers, v = phi_and_body
    C = np.array([[v[f"c{i}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)])
    w = np.array([v[f"body_rate_{a}"] for a in "xyz"])
    L, h = v["latitude"], v["height"]
    RM, RN = v["meridian_radius"] + h, v["prime_vertical_radius"] + h
    vn, ve = v["velocity_north"], v["velocity_east"]
    w_in = v["earth_rate"] * np.array([np.cos(L), 0, -np.sin(L)]) + np.array([ve / RN, -vn / RM, -ve * np.tan(L) / RN])
    att = [s.name for s in phi.states].index("attitude_error_north")
    T, T_dot = np.eye(21), np.zeros((21, 21))
    T[att:att + 3, att:att + 3] = -C.T
    T_dot[att:att + 3, att:att + 3] = _skew(w) @ C.T - C.T @ _skew(w_in)
    T_inv = np.linalg.inv(T)
    F = T @ phi_numbers["F"] @ T_inv + T_dot @ T_inv
    assert np.abs(numbers["F"] - F).max() <= 1e-14 * np.abs(F).max()
    assert np.abs(numbers["G"] - T @ phi_numbers["G"]).max() <= 1e-15
    assert np.abs(numbers["H"] - phi_numbers["H"] @ T_inv).max() <= 1e-14 * np.abs(numbers["H"]).max()


def test_the_reset_jacobian_is_emitted_identity_for_phi_and_the_mekf_form_for_a_rotation_vector(phi_and_body):
    phi, body, *_ = phi_and_body
    assert phi.attitude_reset.matrix == __import__("sympy").eye(3)
    reset = body.attitude_reset
    assert reset.form == "rotation_vector" and reset.axes == "body"
    assert reset.states == ("attitude_error_x", "attitude_error_y", "attitude_error_z")
    estimate = np.array([0.004, -0.007, 0.011])  # rad
    G = np.array(reset.matrix.subs(dict(zip(reset.correction, estimate))), dtype=float)
    # the exact new error after feeding back the estimate: theta+ = log(exp(theta) exp(-estimate)), both conventions
    def after(theta):
        return (Rotation.from_rotvec(theta) * Rotation.from_rotvec(-estimate)).as_rotvec()
    step = 1e-7
    exact = np.column_stack([(after(estimate + step * e) - after(estimate - step * e)) / (2 * step) for e in np.eye(3)])
    assert np.abs(G - exact).max() <= np.linalg.norm(estimate) ** 2  # G is exact to first order in the estimate
    assert np.abs(np.eye(3) - exact).max() > 10 * np.linalg.norm(estimate) ** 2  # ... and the identity is not


def test_body_axes_on_a_phi_angle_is_refused_with_file_line():
    text = NAV.replace("attitude: {form: phi, symbol: phi}", "attitude: {form: phi, axes: body}")
    with pytest.raises(ModelError, match=r"^m\.yaml:\d+: navigation\.errors\.attitude\.axes body is for form rotation_vector"):
        load_model_text(text, filename="m.yaml")
