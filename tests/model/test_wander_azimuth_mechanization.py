"""The wander_azimuth mechanization (issue 27 item 1) against local level and against its own navigation equations.

``modelgen/data/mechanizations/ins_gnss21_wander.yaml`` is the 21-state INS/GNSS filter in a free
wander-azimuth frame (psi-angle, computed-frame velocity, metres).  Three checks:

* At wander angle alpha = 0 the wander frame is the NED frame, but it turns
  differently: free wander has no vertical transport rate, NED has
  rho_z = -v_E tan L / (R_N + h) (= alpha'). With x_w = T x_n, T = diag(C_n^w, C_n^w,
  C_n^w, I) (the psi-angle, computed-frame velocity and metres rotate with the
  computed frame), at alpha = 0 T = I and dT/dt = rho_z diag([e_z x], [e_z x], [e_z x], 0):
  F_w = F_n + dT/dt, G_w = G_n, Q_w = Q_n, and H_w = H_n except two known
  differences of the local-level twin (the ones tests/model/test_ecef_mechanization.py types):
  its velocity difference is taken in each NED frame (v_c - v_t, no dtheta x v_antenna
  term), and its lever-arm position drops O(l/R) terms.
* At alpha != 0 (and at latitude 89.9 deg, where local level is refused) F, G, H
  equal central finite differences of the wander-azimuth navigation equations and
  the error definitions, written here in numpy from latitude, longitude and the
  wander angle (no modelgen code, no curvature matrix K): computed and true states
  are propagated and the declared errors differenced; each block to 1e-6 of itself, and
  the lever-arm position rows to 1e-9 (their O(l/R) terms are kept: exact first order).
* The polar flight loads in wander azimuth with finite matrices (local level refuses it and
  names both ways out: tests/model/test_ecef_mechanization.py).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from modelgen.checks import mechanizations as mech
from modelgen.checks.mechanizations import (
    POINT_IDS,
    POINTS,
    WANDER_MODEL,
    euler as _euler,
    geodetic as _geodetic,
    known_parameters as _known_parameters,
    normal_gravity as _normal_gravity,
    point_values as _point_values,
    skew as _skew,
)
from modelgen.derivation.symbolic import derive
from modelgen.model import wgs84
from modelgen.model.loading import load_model_text

W = wgs84.GPS_EARTH_RATE


@pytest.fixture(scope="module")
def wander(mechanization_models):
    return mechanization_models[2]  # derive(load_model(WANDER_MODEL)), once per session (tests/conftest.py)


@pytest.fixture(scope="module")
def local_level(mechanization_models):
    return mechanization_models[1]  # derive(load_model_text(LOCAL_LEVEL_TWIN, filename=LOCAL_LEVEL_TWIN_NAME))


# -- the wander-azimuth navigation equations, typed here (numpy) -----------------------------------------------
def _rotation(a):
    """exp([a x]) (Rodrigues)."""
    angle = np.linalg.norm(a)
    if angle == 0.0:
        return np.eye(3)
    k = _skew(a / angle)
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def _C_n_w(alpha):
    """C_n^w: north is (cos alpha, sin alpha, 0) along the wander axes."""
    c, s = math.cos(alpha), math.sin(alpha)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _C_e_n(L, lam):
    sL, cL, sl, cl = math.sin(L), math.cos(L), math.sin(lam), math.cos(lam)
    return np.array([[-sL * cl, -sL * sl, cL], [-sl, cl, 0.0], [-cL * cl, -cL * sl, -sL]])


def _C_e_w(L, lam, alpha):
    return _C_n_w(alpha) @ _C_e_n(L, lam)


def _latitude_and_wander_angle(C_ew):
    k = C_ew[:, 2]  # the Earth's axis along the wander axes: (cos a cos L, sin a cos L, -sin L)
    return math.asin(-k[2]), math.atan2(k[1], k[0])


def _position(C_ew, h):
    """r^e from C_e^w and h: the down axis is C_e^w's third row."""
    up = -C_ew[2]
    L = math.asin(up[2])
    _, RN = wgs84.earth_radii(L)
    return (RN + h) * up - np.array([0.0, 0.0, wgs84.ECCENTRICITY_SQUARED * RN * math.sin(L)])


def _rates(C_bw, v, C_ew, h, f_b, w_b):
    """(C_b^w', v^w', omega_ew^w, h'): free wander azimuth, omega_ew^w = C_n^w (v_E/(R_N+h), -v_N/(R_M+h), 0) horizontally."""
    L, alpha = _latitude_and_wander_angle(C_ew)
    RM, RN = wgs84.earth_radii(L)
    C_nw = _C_n_w(alpha)
    v_n = C_nw.T @ v
    horizontal = C_nw @ np.array([v_n[1] / (RN + h), -v_n[0] / (RM + h), 0.0])
    transport = np.array([horizontal[0], horizontal[1], 0.0])
    earth = W * C_ew[:, 2]
    attitude_rate = C_bw @ _skew(w_b) - _skew(earth + transport) @ C_bw
    velocity_rate = C_bw @ f_b - np.cross(2 * earth + transport, v) + np.array([0.0, 0.0, _normal_gravity(L, h)])
    return attitude_rate, velocity_rate, transport, -v[2]


def _step(state, tau, f_b, w_b):
    """The state tau seconds along its rates (first order; the DCMs kept orthogonal)."""
    C_bw, v, C_ew, h = state
    attitude_rate, velocity_rate, transport, height_rate = _rates(C_bw, v, C_ew, h, f_b, w_b)
    L, alpha = _latitude_and_wander_angle(C_ew)
    earth = W * C_ew[:, 2]
    C_bw_next = _rotation(-tau * (earth + transport)) @ C_bw @ _rotation(tau * w_b)
    return C_bw_next, v + tau * velocity_rate, _rotation(-tau * transport) @ C_ew, h + tau * height_rate


def _errors(computed, true):
    """(dr, dv, psi): dr = C_e^w (r_c - r_t), dv = v_c - C_e^w v^e_t, C_b^w = (I - [psi x]) C_e^w C_b^e_t."""
    C_bw, v, C_ew, h = computed
    C_bw_t, v_t, C_ew_t, h_t = true
    to_computed = C_ew @ C_ew_t.T
    dr = C_ew @ (_position(C_ew, h) - _position(C_ew_t, h_t))
    dv = v - to_computed @ v_t
    M = C_bw @ (to_computed @ C_bw_t).T
    psi = 0.5 * np.array([M[1, 2] - M[2, 1], M[2, 0] - M[0, 2], M[0, 1] - M[1, 0]])
    return np.concatenate([dr, dv, psi])


def _true_state(computed, dx):
    """The true state of the error dx (true wander angle = the computed one: no declared error depends on it)."""
    C_bw, v, C_ew, h = computed
    _, alpha = _latitude_and_wander_angle(C_ew)
    r_t = _position(C_ew, h) - C_ew.T @ dx[0:3]
    L_t, lam_t, h_t = _geodetic(r_t)
    C_ew_t = _C_e_w(L_t, lam_t, alpha)
    to_true = C_ew_t @ C_ew.T
    return to_true @ _rotation(dx[6:9]) @ C_bw, to_true @ (v - dx[3:6]), C_ew_t, h_t


def _true_sensors(f_b, w_b, dx, noise):
    """measured = (I + diag(s)) true + b + w: the true body rate and specific force."""
    w_t = (w_b - dx[9:12] - noise[0:3]) / (1 + dx[15:18])
    f_t = (f_b - dx[12:15] - noise[3:6]) / (1 + dx[18:21])
    return f_t, w_t


def _error_rate(computed, f_b, w_b, dx, noise, tau=5.0):
    """d/dt of the declared errors (central difference in time along both trajectories)."""
    true = _true_state(computed, dx)
    f_t, w_t = _true_sensors(f_b, w_b, dx, noise)
    ahead = _errors(_step(computed, tau, f_b, w_b), _step(true, tau, f_t, w_t))
    behind = _errors(_step(computed, -tau, f_b, w_b), _step(true, -tau, f_t, w_t))
    return (ahead - behind) / (2 * tau)


def _antenna(state, w_b, lever):
    """(C_w^e C_b^w l, v^w of the antenna): the lever arm in the e-frame, v + C (w x l) - w_ie x (C l)."""
    C_bw, v, C_ew, h = state
    arm = C_bw @ lever
    return C_ew.T @ arm, v + C_bw @ np.cross(w_b, lever) - np.cross(W * C_ew[:, 2], arm)


def _measurement(computed, w_b, lever, dx):
    """INS minus GNSS: metres and velocity of the antenna along the computed wander axes.

    The position difference is dr (C_e^w (r_c - r_t), the error definition) plus the lever arms' difference, so that
    r^e's rounding (1e-9 m) does not swamp the attitude columns."""
    C_ew = computed[2]
    true = _true_state(computed, dx)
    _, w_t = _true_sensors(np.zeros(3), w_b, dx, np.zeros(6))
    arm_c, v_c = _antenna(computed, w_b, lever)
    arm_t, v_t = _antenna(true, w_t, lever)
    return np.concatenate([dx[0:3] + C_ew @ (arm_c - arm_t), v_c - C_ew @ true[2].T @ v_t])


#: Finite-difference steps of the 21 error states and the 6 IMU noises (large enough to beat rounding in r^e);
#: H's velocity rows (100 m/s against 1e-14 rounding) take larger attitude and scale-factor steps; its position rows
#: (no r^e in them, see _measurement) a small attitude step, so that their O(l/R) terms (2e-7) show.
STEPS = np.array([50.0] * 3 + [0.05] * 3 + [2e-5] * 3 + [1e-6] * 3 + [1e-3] * 3 + [1e-4] * 6)
H_STEPS = np.array([50.0] * 3 + [0.05] * 3 + [1e-3] * 3 + [1e-6] * 3 + [1e-3] * 3 + [5e-4] * 6)
H_POSITION_STEPS = np.array([50.0] * 3 + [0.05] * 3 + [1e-5] * 3 + [1e-6] * 3 + [1e-3] * 3 + [5e-4] * 6)
NOISE_STEPS = np.array([1e-6] * 3 + [1e-3] * 3)
#: The error-state blocks: position, velocity, attitude, gyro bias, accelerometer bias, the two scale factors.
BLOCKS = [slice(3 * k, 3 * k + 3) for k in range(7)]


def _finite_differences(computed, f_b, w_b, lever):
    """(F, G, H) of the navigation rows by central differences (F, H: 21 columns; G: the 6 IMU noises)."""
    F, H, G = np.zeros((9, 21)), np.zeros((6, 21)), np.zeros((9, 6))
    none = np.zeros(6)
    for j, step in enumerate(STEPS):
        dx = np.zeros(21)
        dx[j] = step
        F[:, j] = (_error_rate(computed, f_b, w_b, dx, none) - _error_rate(computed, f_b, w_b, -dx, none)) / (2 * step)
        for rows, steps in ((slice(0, 3), H_POSITION_STEPS), (slice(3, 6), H_STEPS)):
            dz = np.zeros(21)
            dz[j] = steps[j]
            H[rows, j] = (_measurement(computed, w_b, lever, dz) - _measurement(computed, w_b, lever, -dz))[rows] / (2 * steps[j])
    for j, step in enumerate(NOISE_STEPS):
        w = np.zeros(6)
        w[j] = step
        G[:, j] = (_error_rate(computed, f_b, w_b, np.zeros(21), w) - _error_rate(computed, f_b, w_b, np.zeros(21), -w)) / (2 * step)
    return F, G, H


#: (latitude deg, longitude deg, height m, v_NED m/s, roll, pitch, heading deg, wander angle deg)
WANDER_POINTS = [
    (45.0, 10.0, 300.0, (86.6025403784, 50.0, 0.0), 1.0, 2.0, 30.0, 25.0),
    (-33.9, 151.2, 11000.0, (-150.0, 220.0, 3.0), -4.0, 3.0, 124.0, -140.0),
    (78.0, -60.0, 50.0, (5.0, -12.0, -0.5), 0.5, -1.0, 250.0, 95.0),
    (89.9, 30.0, 1000.0, (120.0, -40.0, 0.0), 2.0, 1.0, 200.0, 60.0),  # local level refuses this one
]
LEVER = np.array([1.2, -0.3, -0.9])
F_B = np.array([0.34, -0.18, -9.79])
W_B = np.array([4.7e-5, -4.2e-5, -5.7e-5])


def _wander_state(point):
    L_deg, lam_deg, h, v_n, roll, pitch, yaw, alpha_deg = point
    L, lam, alpha = (math.radians(a) for a in (L_deg, lam_deg, alpha_deg))
    C_nw = _C_n_w(alpha)
    return C_nw @ _euler(roll, pitch, yaw), C_nw @ np.array(v_n), _C_e_w(L, lam, alpha), h


def _wander_values(state, base):
    """The wander model's parameters of a state; ``base`` the noise, sensor and lever-arm values."""
    C_bw, v, C_ew, h = state
    L, _ = _latitude_and_wander_angle(C_ew)
    RM, RN = wgs84.earth_radii(L)
    return {**base, "height": h, "meridian_radius": RM, "prime_vertical_radius": RN, "gravity": _normal_gravity(L, h),
            **{f"wander_dcm_{i + 1}3": C_ew[i, 2] for i in range(3)}, **{f"velocity_{a}": c for a, c in zip("xyz", v)},
            **{f"c{i + 1}{j + 1}": C_bw[i, j] for i in range(3) for j in range(3)}}


def _sensor_values():
    common = _point_values(POINTS[0])[0]
    values = {k: v for k, v in common.items() if not k.startswith(("velocity_", "c1", "c2", "c3"))}
    values.update({f"body_specific_force_{a}": c for a, c in zip("xyz", F_B)})
    values.update({f"body_rate_{a}": c for a, c in zip("xyz", W_B)})
    values.update({f"lever_arm_{a}": c for a, c in zip("xyz", LEVER)})
    return values


# -- alpha = 0: local level ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("point", POINTS[:4], ids=POINT_IDS[:4])
def test_wander_at_zero_wander_angle_equals_local_level_but_for_the_vertical_transport_rate(wander, local_level, point):
    comparisons = mech.wander_against_local_level(wander, local_level, point)
    assert not [(c.matrix, c.difference, c.bound) for c in comparisons if not c.passed]
    matrices = {c.matrix for c in comparisons}
    assert {"F (F_n + dT/dt)", "G", "Q", "R", "H velocity rows", "H position rows", "H position rows, no lever arm"} <= matrices
    assert "F - F_n (shows alpha' = rho_z)" in matrices  # every point here has a vertical transport rate (>= 1e-9)


# -- alpha != 0: the navigation equations by finite differences ----------------------------------------------------
@pytest.mark.parametrize("point", WANDER_POINTS, ids=["45N_alpha25", "34S_alpha-140", "78N_alpha95", "polar_89.9N_alpha60"])
def test_wander_F_G_H_equal_finite_differences_of_the_wander_navigation_equations(wander, point):
    state = _wander_state(point)
    numeric = wander.numeric(_known_parameters(wander, _wander_values(state, _sensor_values())))
    F, G, H = numeric["F"], numeric["G"], numeric["H"]
    assert np.isfinite(F).all() and np.isfinite(G).all() and np.isfinite(H).all()
    F_fd, G_fd, H_fd = _finite_differences(state, F_B, W_B, LEVER)
    for made, expected, steps, rows in ((F, F_fd, STEPS, BLOCKS[:3]), (H, H_fd, H_STEPS, BLOCKS[:2])):
        for row in rows:
            # the error each column makes over its step: a block that makes < 1e-9 of its rows' largest is zero
            scaled_made, scaled_expected = made[row, :] * steps, expected[row, :] * steps
            scale = np.abs(scaled_expected).max()
            assert np.abs(scaled_made - scaled_expected).max() <= 1e-6 * scale, (row, "all columns")
            for column in BLOCKS:
                block = np.abs(scaled_expected[:, column]).max()
                if block > 1e-9 * scale:  # and each block to 1e-6 of itself
                    assert np.abs(made[row, column] - expected[row, column]).max() <= 1e-6 * np.abs(expected[row, column]).max(), (row, column)
    assert np.abs(G[:9, :6] - G_fd).max() <= 1e-6 * np.abs(G_fd).max()
    # the lever-arm position rows are exact to first order: their O(l/R) terms (2e-7 of C [l x], the ones the local-level
    # twin drops) are in H, to 1e-9
    for column in BLOCKS[:3]:
        assert np.abs(H[:3, column] - H_fd[:3, column]).max() <= 1e-9 * np.abs(H_fd[:3, column]).max(), column
    # the sensor-error rows: first-order Gauss-Markov processes, nothing from the navigation states
    assert not F[9:, :9].any() and np.allclose(np.diag(F[9:, 9:]), -np.array([2.8e-4] * 6 + [2.8e-5] * 6), rtol=0, atol=0)


# -- the poles ---------------------------------------------------------------------------------------------------------
def test_a_polar_flight_loads_in_wander_azimuth_with_finite_matrices_and_local_level_refuses_it():
    state = _wander_state(WANDER_POINTS[-1])
    C_bw, v, C_ew, h = mech.polar_state()
    assert all(np.allclose(a, b, rtol=0, atol=1e-15) for a, b in zip((C_bw, v, C_ew), state[:3]))  # the point flown here
    polar = load_model_text(mech.polar_wander_text(C_ew, C_bw, v, h), filename="polar_wander.yaml")
    values = {**dict(polar.parameter_defaults()), **polar.check.parameter_values()}
    assert abs(values["wander_dcm_33"] + math.sin(math.radians(89.9))) < 1e-15
    check = mech.polar_check()  # derives the polar file itself
    assert check.passed and check.wander_finite and check.local_level_refused
    assert "latitude 89.9 deg is within 1 deg of a pole" in check.local_level_message
    assert "'mechanization: wander_azimuth' or 'mechanization: ecef'" in check.local_level_message


def test_the_wander_curvature_determinant_is_one_over_the_product_of_the_radii():
    """det K = A (A + D cos^2 L) = 1/((R_M + h)(R_N + h)) (R_N - R_M = e^2/(1 - e^2) R_M cos^2 L): the value of Q = 1/det K."""
    from modelgen.model.mechanizations.wander_azimuth import WanderAzimuth
    import sympy as sp

    e2 = wgs84.ECCENTRICITY_SQUARED
    for L_deg in (0.0, 30.0, -45.0, 78.0, 89.9, 90.0):
        L = math.radians(L_deg)
        for h in (0.0, 300.0, 11000.0):
            RM, RN = wgs84.earth_radii(L)
            A, D = 1 / (RN + h), e2 / (1 - e2) * RM / ((RM + h) * (RN + h))
            assert abs(A * (A + D * math.cos(L) ** 2) * (RM + h) * (RN + h) - 1) < 1e-14
            assert abs((RN - RM) - e2 / (1 - e2) * RM * math.cos(L) ** 2) < 1e-8
    # and the mechanization's rules say so
    from modelgen.model.mechanizations import wander_azimuth as w

    h = sp.Symbol("h", real=True)
    position = w.chart_position(h)
    earth = type("Earth", (), {"gravity": sp.Symbol("g"), "meridian_radius": sp.Symbol("R_M"), "prime_vertical_radius": sp.Symbol("R_N")})
    rules = WanderAzimuth("WANDER", sp.Symbol("W")).earth_function_rules(position, earth)
    determinant = w.curvature_determinant(WanderAzimuth("WANDER", sp.Symbol("W")).axis, position)
    at = {**{k: v for k, v in rules.items() if not isinstance(k, sp.Derivative)}}
    L = math.radians(37.0)
    RM, RN = wgs84.earth_radii(L)
    point = {sp.Symbol("R_M"): RM, sp.Symbol("R_N"): RN, h: 500.0, sp.Symbol("Cew13", real=True): math.cos(L) * 0.6,
             sp.Symbol("Cew23", real=True): math.cos(L) * 0.8, sp.Symbol("Cew33", real=True): -math.sin(L)}
    value = float(determinant.xreplace(at).xreplace(point))
    inverse = float(rules[w.WanderInverseDeterminant(*position[:2], h)].xreplace(point))
    assert abs(value * inverse - 1) < 1e-14


def test_wander_position_rows_are_exactly_minus_the_transport_rate_cross_dr_plus_dv(wander):
    """dr' = -[w_ew x] dr + dv with w_ew = (rho_x, rho_y, 0): the curvature terms of dT/dt cancel exactly (the reduction
    by Q det K = 1, D cos^2 L = B - A, |k| = 1 and the ellipsoid's dR_N/dL), so the zeros are zeros, not ~1e-23 sums."""
    F = wander.F
    for i, j in ((0, 0), (0, 1), (1, 0), (1, 1), (2, 2)):  # rho_z = 0: only the dr_z column and row remain
        assert F[i, j] == 0, (i, j, F[i, j])
    for i in range(3):
        for j in range(3):
            assert F[i, 3 + j] == (1 if i == j else 0)
    assert "velocity_z" not in {p.name for p in wander.model.parameters}  # F and H of the psi-angle model need no v_z


def test_a_non_polynomial_measurement_in_wander_azimuth_is_derived_unreduced():
    """A speed |v| (sqrt: not a polynomial, so not reduced by the ellipsoid's relations) is derived as v^T dv / |v|."""
    text = WANDER_MODEL.read_text()
    velocity = '''    - {of: velocity, lever_arm: {symbol: l}, symbols: [Z_vx, Z_vy, Z_vz], variance: "sigma_v**2"}\n'''
    speed = '''    - {of: expression, expression: "sqrt(dot(v_w, v_w))", symbols: [Z_s], units: [m/s], variance: "sigma_v**2"}\n'''
    assert velocity in text
    text = text.replace(velocity, velocity + speed).replace("velocity_y: 81.91520442889918,", "velocity_y: 81.91520442889918, velocity_z: 1.5,")
    model = load_model_text(text, filename="wander_speed.yaml")
    values = {**dict(model.parameter_defaults()), **model.check.parameter_values()}
    H = derive(model).numeric(values)["H"]
    v = np.array([values[f"velocity_{a}"] for a in "xyz"])
    assert np.abs(H[-1, 3:6] - v / np.linalg.norm(v)).max() <= 1e-15 and not H[-1, :3].any() and not H[-1, 6:].any()
