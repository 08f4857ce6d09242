"""The ecef mechanization (Groves 2013 ch. 5.3, 14.2.3) against the local-level one, through the known transformation.

The same 21-state INS/GNSS filter is derived twice: in the e-frame
(``tests/model/ins_gnss21_ecef.yaml``: phi^e, dv^e, dr^e) and in local-level
NED with no approximation, its errors chosen as the ones the e-frame errors
rotate into (psi-angle, velocity error in the computed frame, NED metres):

    phi^e = C_n^e psi^n,   dv^e = C_n^e (dv^n + dtheta x v^n),   dr^e = C_n^e dr^n.

(C_b^e = C_n^e(p) C_b^n, so (I - [phi^e x]) = C_n^e (I + [dtheta x] - [phi^n x]) C_e^n
to first order, with dtheta the angle of the computed local-level frame against
the true one; the velocity and position the same way.)  So with
x_e = T x_n, T = diag(C_n^e, C_n^e, C_n^e, I) and dT/dt = T diag([w_en^n x] ...):

    F_e = T F_n T^-1 + dT/dt T^-1,   G_e = T G_n,   H_e = diag(C_n^e, C_n^e) H_n T^-1.

Both are exact first-order error models of the same motion, except for the
gravity model: local level uses WGS-84 normal gravity (Somigliana) along the
ellipsoid normal, the e-frame WGS-84's J2 field plus the centrifugal term.
So every entry must agree to rounding except the gravity gradient block
F[dv, dr], which must equal each model's own gravity gradient, computed here
independently by central differences of the two gravity fields (numpy, no
modelgen); their difference (a few 1e-9 s^-2 at 45 deg, 0.1 % of the gradient)
is the only tolerance, and it is the measured one.  The local-level velocity
measurement differences velocities in their own NED frames (v_c - v_t), the
e-frame one in one frame, so its rows gain dtheta x v_antenna before rotating
(typed here).  The lever-arm position rows
differ by the O(l/R) terms the local-level position measurement drops (its
metres are taken at the computed position): |l|/R = 2.5e-7 of the attitude columns.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model import wgs84
from modelgen.model.loading import load_model, load_model_text

HERE = Path(__file__).resolve().parent
ECEF_MODEL = HERE / "ins_gnss21_ecef.yaml"

#: ins_gnss21_ecef in local-level NED, no approximation, its errors the ones the e-frame errors rotate into.
LOCAL_LEVEL_TWIN = ECEF_MODEL.read_text().replace("model: ins_gnss21_ecef", "model: ins_gnss21_ecef_local_level").replace(
    "frame: ECEF", "frame: NED").replace("mechanization: ecef", "mechanization: local_level").replace(
    "velocity: {form: difference, symbol: dv}", "velocity: {form: computed_frame, symbol: dv}").replace(
    "attitude: {form: phi, symbol: phi}", "attitude: {form: psi, symbol: psi}").replace(
    "symbols: [Z_rx, Z_ry, Z_rz]", "symbols: [Z_rn, Z_re, Z_rd]").replace("symbols: [Z_vx, Z_vy, Z_vz]", "symbols: [Z_vn, Z_ve, Z_vd]")
LOCAL_LEVEL_TWIN = LOCAL_LEVEL_TWIN[: LOCAL_LEVEL_TWIN.index("check:")]

#: Realistic points: (latitude deg, longitude deg, height m, v_NED m/s, roll, pitch, heading deg).
POINTS = [
    (45.0, 10.0, 300.0, (86.6025403784, 50.0, 0.0), 1.0, 2.0, 30.0),
    (-33.9, 151.2, 11000.0, (-150.0, 220.0, 3.0), -4.0, 3.0, 124.0),
    (78.0, -60.0, 50.0, (5.0, -12.0, -0.5), 0.5, -1.0, 250.0),
    (0.2, -90.0, 2000.0, (0.0, 250.0, -8.0), 10.0, 5.0, 90.0),
    (89.9, 30.0, 1000.0, (120.0, -40.0, 0.0), 2.0, 1.0, 200.0),  # a polar flight: local level is refused there
]


# -- geodesy typed here (numpy, Groves 2013 eqs. 2.112, 2.150, 2.99) -------------------------
def _radii(L):
    return wgs84.earth_radii(L)


def _ecef_position(L, lam, h):
    _, RN = _radii(L)
    e2 = wgs84.ECCENTRICITY_SQUARED
    return np.array([(RN + h) * math.cos(L) * math.cos(lam), (RN + h) * math.cos(L) * math.sin(lam), (RN * (1 - e2) + h) * math.sin(L)])


def _geodetic(r):
    """(L, lambda, h) of an e-frame position by fixed-point iteration (to 1e-15 rad)."""
    x, y, z = r
    e2 = wgs84.ECCENTRICITY_SQUARED
    lam, p = math.atan2(y, x), math.hypot(x, y)
    L = math.atan2(z, p * (1 - e2))
    def height(L):  # the better-conditioned of the two forms (p / cos L is poor near the poles)
        RN = _radii(L)[1]
        return p / math.cos(L) - RN if abs(L) < math.pi / 4 else z / math.sin(L) - RN * (1 - e2)

    for _ in range(20):
        RN = _radii(L)[1]
        L = math.atan2(z, p * (1 - e2 * RN / (RN + height(L))))
    return L, lam, height(L)


def _C_n_e(L, lam):
    sL, cL, sl, cl = math.sin(L), math.cos(L), math.sin(lam), math.cos(lam)
    return np.array([[-sL * cl, -sl, -cL * cl], [-sL * sl, cl, -cL * sl], [cL, 0.0, -sL]])


def _normal_gravity(L, h):
    """WGS-84 normal gravity (TR8350.2 eqs. 4-1, 4-3), as the local-level mechanization's Gravity(L, h)."""
    e2, a, f, k = wgs84.ECCENTRICITY_SQUARED, wgs84.SEMI_MAJOR_AXIS, wgs84.FLATTENING, wgs84.SOMIGLIANA_K
    s2 = math.sin(L) ** 2
    surface = wgs84.EQUATORIAL_GRAVITY * (1 + k * s2) / math.sqrt(1 - e2 * s2)
    return surface * (1 - 2 * h * (1 + f + wgs84.GRAVITY_RATIO_M - 2 * f * s2) / a + 3 * h**2 / a**2)


def _local_level_gravity(r):
    """g^e of the local-level mechanization: normal gravity along the ellipsoid normal, down."""
    L, lam, h = _geodetic(r)
    return _C_n_e(L, lam) @ np.array([0.0, 0.0, _normal_gravity(L, h)])


def _j2_gravity(r, W=wgs84.GPS_EARTH_RATE):
    """Groves eq. 2.142 plus the centrifugal term, typed here."""
    mu, J2, a = wgs84.GRAVITATIONAL_CONSTANT, wgs84.J2, wgs84.SEMI_MAJOR_AXIS
    x, y, z = r
    n = np.linalg.norm(r)
    q = 1.5 * J2 * a**2 / n**2
    t = 5 * z**2 / n**2
    return -mu / n**3 * np.array([x * (1 + q * (1 - t)), y * (1 + q * (1 - t)), z * (1 + q * (3 - t))]) + W**2 * np.array([x, y, 0.0])


def _gradient(field, r, step=1.0):
    return np.column_stack([(field(r + step * e) - field(r - step * e)) / (2 * step) for e in np.eye(3)])


def _euler(roll, pitch, yaw):
    """C_b^n from roll, pitch, heading in degrees (Groves eq. 2.22)."""
    r, p, y = (math.radians(a) for a in (roll, pitch, yaw))
    Rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    return Rz @ Ry @ Rx


def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


# -- the two models at one point ------------------------------------------------------------------
@pytest.fixture(scope="module")
def models():
    ecef = load_model(ECEF_MODEL)
    local = load_model_text(LOCAL_LEVEL_TWIN, filename="ins_gnss21_ecef_local_level.yaml")
    return derive(ecef), derive(local)


def _point_values(point):
    L_deg, lam_deg, h, v_n, roll, pitch, yaw = point
    L, lam = math.radians(L_deg), math.radians(lam_deg)
    RM, RN = _radii(L)
    C_bn = _euler(roll, pitch, yaw)
    C_ne = _C_n_e(L, lam)
    r = _ecef_position(L, lam, h)
    v_n = np.array(v_n)
    common = {"gyro_angle_random_walk": 3.5e-5, "accel_velocity_random_walk": 3e-4, "gyro_bias_rate": 2.8e-4, "gyro_bias_sigma": 4.8e-8,
              "accel_bias_rate": 2.8e-4, "accel_bias_sigma": 2.5e-4, "scale_factor_rate": 2.8e-5, "gyro_scale_factor_sigma": 5e-6,
              "accel_scale_factor_sigma": 1e-4, "gnss_position_sigma": 2.0, "gnss_velocity_sigma": 0.05,
              "body_specific_force_x": 0.34, "body_specific_force_y": -0.18, "body_specific_force_z": -9.79,
              "body_rate_x": 4.7e-5, "body_rate_y": -4.2e-5, "body_rate_z": -5.7e-5, "lever_arm_x": 1.2, "lever_arm_y": -0.3,
              "lever_arm_z": -0.9, "earth_rate": wgs84.GPS_EARTH_RATE}
    local = {**common, "latitude": L, "longitude": lam, "height": h, "meridian_radius": RM, "prime_vertical_radius": RN,
             "gravity": _normal_gravity(L, h), **{f"velocity_{w}": v for w, v in zip(("north", "east", "down"), v_n)},
             **{f"c{i + 1}{j + 1}": C_bn[i, j] for i in range(3) for j in range(3)}}
    C_be = C_ne @ C_bn
    ecef = {**common, **{f"position_{a}": c for a, c in zip("xyz", r)}, "geocentric_radius": float(np.linalg.norm(r)),
            **{f"c{i + 1}{j + 1}": C_be[i, j] for i in range(3) for j in range(3)}}
    transport = np.array([v_n[1] / (RN + h), -v_n[0] / (RM + h), -v_n[1] * math.tan(L) / (RN + h)])
    return local, ecef, C_ne, transport, r


def _frame_angle(p):
    """Theta: dtheta = Theta dr^n (NED metres), the computed local-level frame against the true one."""
    L, h = p["latitude"], p["height"]
    RM, RN = p["meridian_radius"] + h, p["prime_vertical_radius"] + h
    return np.array([[0.0, 1 / RN, 0.0], [-1 / RM, 0.0, 0.0], [0.0, -math.tan(L) / RN, 0.0]])


def _antenna_velocity(p):
    """v + C (w x l) - w_ie x (C l) in NED (Groves eq. 14.x), the velocity the GNSS antenna has."""
    L = p["latitude"]
    C = np.array([[p[f"c{i}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)])
    v = np.array([p["velocity_north"], p["velocity_east"], p["velocity_down"]])
    w = np.array([p[f"body_rate_{a}"] for a in "xyz"])
    lever = np.array([p[f"lever_arm_{a}"] for a in "xyz"])
    w_ie = p["earth_rate"] * np.array([math.cos(L), 0.0, -math.sin(L)])
    return v + C @ np.cross(w, lever) - np.cross(w_ie, C @ lever)


def _known_parameters(derived, values):
    names = {p.name for p in derived.model.parameters}
    return {k: v for k, v in values.items() if k in names}


@pytest.mark.parametrize("point", POINTS, ids=["45N_10E_300m", "34S_151E_11km", "78N_60W_50m", "equator_2km", "polar_89.9N"])
def test_ecef_F_G_H_equal_local_level_through_the_frame_rotation_except_the_gravity_model(models, point):
    ecef, local = models
    local_values, ecef_values, C_ne, transport, r = _point_values(point)
    n = ecef.numeric(_known_parameters(ecef, ecef_values))
    m = local.numeric(_known_parameters(local, local_values))
    T = np.eye(21)
    for block in range(3):
        T[3 * block:3 * block + 3, 3 * block:3 * block + 3] = C_ne
    T_dot = T @ np.kron(np.diag([1.0, 1.0, 1.0, 0, 0, 0, 0]), _skew(transport))
    T_inv = T.T
    F_expected = T @ m["F"] @ T_inv + T_dot @ T_inv
    # the only modelling difference: the gravity gradient, each model's own typed here
    gravity_local = _gradient(_local_level_gravity, r)
    gravity_j2 = _gradient(_j2_gravity, r)
    dv, dr = slice(3, 6), slice(0, 3)
    assert np.abs(F_expected[dv, dr] - gravity_local).max() <= 1e-12, "local-level gravity gradient"
    assert np.abs(n["F"][dv, dr] - gravity_j2).max() <= 1e-12, "J2 gravity gradient"
    difference = np.abs(gravity_j2 - gravity_local).max()
    assert difference < 1e-8  # J2 field vs Somigliana normal gravity: under 0.3 % of 2 g / R
    F_expected[dv, dr] = gravity_j2
    scale = np.abs(n["F"]).max()
    assert np.abs(n["F"] - F_expected).max() <= 1e-13 * scale
    assert np.abs(n["G"] - T @ m["G"]).max() <= 1e-13 * np.abs(n["G"]).max()
    T_z = np.kron(np.eye(2), C_ne)
    # the local-level velocity difference is v_c - v_t, each in its own NED frame; in the e-frame
    # z_e = C_n^e (z_n + dtheta x v_antenna), dtheta = Theta dr^n (the frame angle of the position error)
    H_local = m["H"].copy()
    H_local[3:6, 0:3] -= _skew(_antenna_velocity(local_values)) @ _frame_angle(local_values)
    H_expected = T_z @ H_local @ T_inv
    velocity_rows = slice(3, 6)
    assert np.abs(n["H"][velocity_rows] - H_expected[velocity_rows]).max() <= 1e-13 * np.abs(n["H"]).max()
    # position rows: the local-level lever arm drops O(l/R) terms (metres at the computed position)
    lever = math.sqrt(1.2**2 + 0.3**2 + 0.9**2)
    tangent = abs(math.tan(local_values["latitude"]))
    assert np.abs(n["H"][:3] - H_expected[:3]).max() <= 2 * lever * (1 + tangent) / 6.35e6
    # ... and without a lever arm they agree to rounding
    no_arm = {f"lever_arm_{a}": 0.0 for a in "xyz"}
    n0 = ecef.numeric(_known_parameters(ecef, {**ecef_values, **no_arm}))
    m0 = local.numeric(_known_parameters(local, {**local_values, **no_arm}))
    assert np.abs(n0["H"][:3] - (T_z @ m0["H"] @ T_inv)[:3]).max() <= 1e-13


def test_ecef_model_has_e_frame_states_and_parameters():
    model = load_model(ECEF_MODEL)
    names = [s.name for s in model.states]
    assert names[:9] == [f"{q}_error_{a}" for q in ("position", "velocity", "attitude") for a in "xyz"]
    parameters = {p.name for p in model.parameters}
    assert {"position_x", "position_y", "position_z", "geocentric_radius", "earth_rate"} <= parameters
    assert not parameters & {"latitude", "meridian_radius", "gravity", "velocity_x"}  # F and H of the e-frame need none


def test_ecef_no_gravity_gradient_drops_the_position_coupling_and_lists_it():
    text = ECEF_MODEL.read_text().replace("  measurements:", "  approximations: [no_gravity_gradient]\n  measurements:")
    text = text[: text.index("check:")]
    model = load_model_text(text, filename="ecef_no_gradient.yaml")
    derived = derive(model)
    F = derived.F
    for i in range(3, 6):
        for j in range(3):
            assert F[i, j] == 0  # the dv/dr block is gone (the centrifugal gradient too)
    assert len([t for t in model.neglected if t.approximation == "no_gravity_gradient"]) == 9
    assert any("no_gravity_gradient" in note for note in model.notes)


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("frame: ECEF", "frame: NED", "frame 'NED' is the local_level mechanization's; the ecef mechanization resolves its vectors in ECEF"),
        ("mechanization: ecef", "mechanization: local_level", "frame 'ECEF' is the ecef mechanization's; the local_level mechanization"),
        ("attitude: {form: phi, symbol: phi}", "attitude: {form: psi, symbol: phi}", "'psi' is a local-level form"),
        ("position: {form: metres, symbol: dr}", "position: {form: geodetic}", "'geodetic' is a local-level form"),
        ("  measurements:", "  approximations: [constant_radii]\n  measurements:", "approximation 'constant_radii' does not apply to the ecef mechanization"),
    ],
)
def test_ecef_refuses_local_level_frames_forms_and_approximations_with_file_line(old, new, message):
    text = ECEF_MODEL.read_text()
    assert old in text
    with pytest.raises(ModelError, match=r"^m\.yaml:\d+: ") as caught:
        load_model_text(text.replace(old, new), filename="m.yaml")
    assert message in str(caught.value)


def test_a_polar_flight_works_in_ecef_and_local_level_refuses_it_naming_the_way_out():
    """Latitude 89.9 deg: local level's 1/cos L is 573; the e-frame has no singularity."""
    ecef_text = ECEF_MODEL.read_text()
    local, ecef_values, _, _, r = _point_values(POINTS[-1])
    for axis, value in zip("xyz", r):
        ecef_text = _replace_value(ecef_text, f"position_{axis}", value)
    ecef_text = _replace_value(ecef_text, "geocentric_radius", float(np.linalg.norm(r)))
    polar = load_model_text(ecef_text, filename="polar_ecef.yaml")
    F = derive(polar).numeric({**dict(polar.parameter_defaults()), **polar.check.parameter_values()})["F"]
    assert np.isfinite(F).all() and np.abs(F[3:6, 0:3]).max() < 1e-5  # the gravity gradient, as anywhere
    nav = (HERE.parents[1] / "modelgen" / "models" / "ins_gnss21_nav.yaml").read_text()
    with pytest.raises(ModelError) as caught:
        load_model_text(nav.replace("latitude: {value: 45, unit: deg}", "latitude: {value: 89.9, unit: deg}"), filename="m.yaml")
    message = str(caught.value)
    assert message.startswith("m.yaml:") and "latitude 89.9 deg is within 1 deg of a pole" in message
    assert "1/cos L = 573" in message and "'mechanization: wander_azimuth' or 'mechanization: ecef'" in message
    assert load_model_text(nav.replace("latitude: {value: 45, unit: deg}", "latitude: {value: 89, unit: deg}"), filename="m.yaml")


def _replace_value(text: str, name: str, value: float) -> str:
    import re

    return re.sub(rf"{name}: [-0-9.e+]+", f"{name}: {float(value)!r}", text, count=1)
