"""The mechanizations cross-checked: ECEF and wander azimuth against local level, and the poles.

The same 21-state INS/GNSS filter ships in three mechanizations:
``modelgen/data/mechanizations/ins_gnss21_ecef.yaml`` (phi^e, dv^e, dr^e),
``ins_gnss21_wander.yaml`` (free wander azimuth: psi-angle, computed-frame
velocity, metres) and, written from the ECEF file, its local-level NED twin
with no approximation and the errors the e-frame ones rotate into (psi-angle,
computed-frame velocity, NED metres; :data:`LOCAL_LEVEL_TWIN`):

    phi^e = C_n^e psi^n,   dv^e = C_n^e (dv^n + dtheta x v^n),   dr^e = C_n^e dr^n.

So with x_e = T x_n, T = diag(C_n^e, C_n^e, C_n^e, I), dT/dt = T diag([w_en^n x] ...):

    F_e = T F_n T^-1 + dT/dt T^-1,   G_e = T G_n,   H_e = diag(C_n^e, C_n^e) H_n T^-1,

entry by entry at realistic points (:data:`POINTS`), except the gravity model:
local level uses WGS-84 normal gravity along the ellipsoid normal, the e-frame
J2 plus the centrifugal term, so F[dv, dr] is held against each model's own
gravity gradient, computed here by central differences of the two fields
(numpy, no modelgen), and the two gradients' difference is reported.  The
local-level velocity measurement differences velocities in their own NED
frames, so its rows gain dtheta x v_antenna before rotating; its lever-arm
position drops O(l/R) terms (bounded by 2 |l| (1 + |tan L|) / 6.35e6), and
without a lever arm the positions agree to rounding.

At wander angle 0 the wander frame is the NED frame but turns without the
vertical transport rate: F_w = F_n + dT/dt with dT/dt = rho_z diag([e_z x] x 3, 0),
G, Q, R identical, H as for ECEF.  At latitude 89.9 deg the wander model
loads and its matrices are finite; local level refuses with its message.

:func:`run_mechanization_checks` returns every comparison (point, matrix,
largest difference, the bound it is held to and why, verdict);
:func:`write_mechanizations_report` writes ``mechanizations.md``/``.json``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from modelgen.derivation.symbolic import DerivedModel, derive
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path
from modelgen.fileio.output import write_text_atomically
from modelgen.model import wgs84
from modelgen.model.loading import builtin_model_path, load_model, load_model_text

ECEF_MODEL = data_path("mechanizations/ins_gnss21_ecef.yaml")
WANDER_MODEL = data_path("mechanizations/ins_gnss21_wander.yaml")
#: The built-in local-level model whose check scenario is moved to latitude 89.9 deg (refused).
LOCAL_LEVEL_MODEL = "ins_gnss21_nav"
POLAR_LATITUDE_DEG = 89.9


def local_level_twin_text() -> str:
    """ins_gnss21_ecef in local-level NED, no approximation, its errors the ones the e-frame errors rotate into."""
    text = ECEF_MODEL.read_text().replace("model: ins_gnss21_ecef", "model: ins_gnss21_ecef_local_level").replace(
        "frame: ECEF", "frame: NED").replace("mechanization: ecef", "mechanization: local_level").replace(
        "velocity: {form: difference, symbol: dv}", "velocity: {form: computed_frame, symbol: dv}").replace(
        "attitude: {form: phi, symbol: phi}", "attitude: {form: psi, symbol: psi}").replace(
        "symbols: [Z_rx, Z_ry, Z_rz]", "symbols: [Z_rn, Z_re, Z_rd]").replace("symbols: [Z_vx, Z_vy, Z_vz]", "symbols: [Z_vn, Z_ve, Z_vd]")
    return text[: text.index("check:")]


LOCAL_LEVEL_TWIN = local_level_twin_text()
LOCAL_LEVEL_TWIN_NAME = "ins_gnss21_ecef_local_level.yaml"

#: Realistic points: (latitude deg, longitude deg, height m, v_NED m/s, roll, pitch, heading deg).
POINTS = [
    (45.0, 10.0, 300.0, (86.6025403784, 50.0, 0.0), 1.0, 2.0, 30.0),
    (-33.9, 151.2, 11000.0, (-150.0, 220.0, 3.0), -4.0, 3.0, 124.0),
    (78.0, -60.0, 50.0, (5.0, -12.0, -0.5), 0.5, -1.0, 250.0),
    (0.2, -90.0, 2000.0, (0.0, 250.0, -8.0), 10.0, 5.0, 90.0),
    (89.9, 30.0, 1000.0, (120.0, -40.0, 0.0), 2.0, 1.0, 200.0),  # a polar flight: local level is refused there
]
POINT_IDS = ["45N_10E_300m", "34S_151E_11km", "78N_60W_50m", "equator_2km", "polar_89.9N"]
LEVER = (1.2, -0.3, -0.9)


# -- geodesy typed here (numpy, Groves 2013 eqs. 2.112, 2.150, 2.99) -------------------------
def ecef_position(L, lam, h):
    _, RN = wgs84.earth_radii(L)
    e2 = wgs84.ECCENTRICITY_SQUARED
    return np.array([(RN + h) * math.cos(L) * math.cos(lam), (RN + h) * math.cos(L) * math.sin(lam), (RN * (1 - e2) + h) * math.sin(L)])


def geodetic(r):
    """(L, lambda, h) of an e-frame position by fixed-point iteration (to 1e-15 rad)."""
    x, y, z = r
    e2 = wgs84.ECCENTRICITY_SQUARED
    lam, p = math.atan2(y, x), math.hypot(x, y)
    L = math.atan2(z, p * (1 - e2))

    def height(L):  # the better-conditioned of the two forms (p / cos L is poor near the poles)
        RN = wgs84.earth_radii(L)[1]
        return p / math.cos(L) - RN if abs(L) < math.pi / 4 else z / math.sin(L) - RN * (1 - e2)

    for _ in range(20):
        RN = wgs84.earth_radii(L)[1]
        L = math.atan2(z, p * (1 - e2 * RN / (RN + height(L))))
    return L, lam, height(L)


def C_n_e(L, lam):
    sL, cL, sl, cl = math.sin(L), math.cos(L), math.sin(lam), math.cos(lam)
    return np.array([[-sL * cl, -sl, -cL * cl], [-sL * sl, cl, -cL * sl], [cL, 0.0, -sL]])


def normal_gravity(L, h):
    """WGS-84 normal gravity (TR8350.2 eqs. 4-1, 4-3), as the local-level mechanization's Gravity(L, h)."""
    e2, a, f, k = wgs84.ECCENTRICITY_SQUARED, wgs84.SEMI_MAJOR_AXIS, wgs84.FLATTENING, wgs84.SOMIGLIANA_K
    s2 = math.sin(L) ** 2
    surface = wgs84.EQUATORIAL_GRAVITY * (1 + k * s2) / math.sqrt(1 - e2 * s2)
    return surface * (1 - 2 * h * (1 + f + wgs84.GRAVITY_RATIO_M - 2 * f * s2) / a + 3 * h**2 / a**2)


def local_level_gravity(r):
    """g^e of the local-level mechanization: normal gravity along the ellipsoid normal, down."""
    L, lam, h = geodetic(r)
    return C_n_e(L, lam) @ np.array([0.0, 0.0, normal_gravity(L, h)])


def j2_gravity(r, W=wgs84.GPS_EARTH_RATE):
    """Groves eq. 2.142 plus the centrifugal term, typed here."""
    mu, J2, a = wgs84.GRAVITATIONAL_CONSTANT, wgs84.J2, wgs84.SEMI_MAJOR_AXIS
    x, y, z = r
    n = np.linalg.norm(r)
    q = 1.5 * J2 * a**2 / n**2
    t = 5 * z**2 / n**2
    return -mu / n**3 * np.array([x * (1 + q * (1 - t)), y * (1 + q * (1 - t)), z * (1 + q * (3 - t))]) + W**2 * np.array([x, y, 0.0])


def gradient(field, r, step=1.0):
    return np.column_stack([(field(r + step * e) - field(r - step * e)) / (2 * step) for e in np.eye(3)])


def euler(roll, pitch, yaw):
    """C_b^n from roll, pitch, heading in degrees (Groves eq. 2.22)."""
    r, p, y = (math.radians(a) for a in (roll, pitch, yaw))
    Rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    return Rz @ Ry @ Rx


def skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def point_values(point):
    """(local-level values, e-frame values, C_n^e, NED transport rate, r^e) of one point of :data:`POINTS`."""
    L_deg, lam_deg, h, v_n, roll, pitch, yaw = point
    L, lam = math.radians(L_deg), math.radians(lam_deg)
    RM, RN = wgs84.earth_radii(L)
    C_bn = euler(roll, pitch, yaw)
    C_ne = C_n_e(L, lam)
    r = ecef_position(L, lam, h)
    v_n = np.array(v_n)
    common = {"gyro_angle_random_walk": 3.5e-5, "accel_velocity_random_walk": 3e-4, "gyro_bias_rate": 2.8e-4, "gyro_bias_sigma": 4.8e-8,
              "accel_bias_rate": 2.8e-4, "accel_bias_sigma": 2.5e-4, "scale_factor_rate": 2.8e-5, "gyro_scale_factor_sigma": 5e-6,
              "accel_scale_factor_sigma": 1e-4, "gnss_position_sigma": 2.0, "gnss_velocity_sigma": 0.05,
              "body_specific_force_x": 0.34, "body_specific_force_y": -0.18, "body_specific_force_z": -9.79,
              "body_rate_x": 4.7e-5, "body_rate_y": -4.2e-5, "body_rate_z": -5.7e-5,
              **{f"lever_arm_{a}": c for a, c in zip("xyz", LEVER)}, "earth_rate": wgs84.GPS_EARTH_RATE}
    local = {**common, "latitude": L, "longitude": lam, "height": h, "meridian_radius": RM, "prime_vertical_radius": RN,
             "gravity": normal_gravity(L, h), **{f"velocity_{w}": v for w, v in zip(("north", "east", "down"), v_n)},
             **{f"c{i + 1}{j + 1}": C_bn[i, j] for i in range(3) for j in range(3)}}
    C_be = C_ne @ C_bn
    ecef = {**common, **{f"position_{a}": c for a, c in zip("xyz", r)}, "geocentric_radius": float(np.linalg.norm(r)),
            **{f"c{i + 1}{j + 1}": C_be[i, j] for i in range(3) for j in range(3)}}
    transport = np.array([v_n[1] / (RN + h), -v_n[0] / (RM + h), -v_n[1] * math.tan(L) / (RN + h)])
    return local, ecef, C_ne, transport, r


def frame_angle(p):
    """Theta: dtheta = Theta dr^n (NED metres), the computed local-level frame against the true one."""
    L, h = p["latitude"], p["height"]
    RM, RN = p["meridian_radius"] + h, p["prime_vertical_radius"] + h
    return np.array([[0.0, 1 / RN, 0.0], [-1 / RM, 0.0, 0.0], [0.0, -math.tan(L) / RN, 0.0]])


def antenna_velocity(p):
    """v + C (w x l) - w_ie x (C l) in NED (Groves eq. 14.x), the velocity the GNSS antenna has."""
    L = p["latitude"]
    C = np.array([[p[f"c{i}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)])
    v = np.array([p["velocity_north"], p["velocity_east"], p["velocity_down"]])
    w = np.array([p[f"body_rate_{a}"] for a in "xyz"])
    lever = np.array([p[f"lever_arm_{a}"] for a in "xyz"])
    w_ie = p["earth_rate"] * np.array([math.cos(L), 0.0, -math.sin(L)])
    return v + C @ np.cross(w, lever) - np.cross(w_ie, C @ lever)


def known_parameters(derived: DerivedModel, values: dict) -> dict:
    names = {p.name for p in derived.model.parameters}
    return {k: v for k, v in values.items() if k in names}


# -- the comparisons ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Comparison:
    """One matrix (or block) at one point: its largest difference and the bound it is held to, and why.

    ``at_least``: the difference must reach the bound (it shows a term that must be there)."""

    check: str
    point: str
    matrix: str
    difference: float
    bound: float
    reason: str
    at_least: bool = False

    @property
    def passed(self) -> bool:
        return bool(self.difference >= self.bound) if self.at_least else bool(self.difference <= self.bound)


@dataclass(frozen=True)
class PolarCheck:
    """Latitude 89.9 deg: wander azimuth loads with finite matrices; local level refuses with ``local_level_message``."""

    latitude_deg: float
    wander_finite: bool
    wander_largest_entry: float
    local_level_refused: bool
    local_level_message: str

    @property
    def passed(self) -> bool:
        message = self.local_level_message
        return (self.wander_finite and self.local_level_refused and "of a pole" in message
                and "wander_azimuth" in message and "ecef" in message)


@dataclass(frozen=True)
class MechanizationChecks:
    comparisons: tuple[Comparison, ...]
    polar: PolarCheck
    seconds: float = 0.0

    @property
    def failed(self) -> list[str]:
        out = [f"{c.check} {c.point} {c.matrix}" for c in self.comparisons if not c.passed]
        return out + ([] if self.polar.passed else ["polar flight"])

    @property
    def passed(self) -> bool:
        return not self.failed

    def of(self, check: str, point: str) -> dict[str, Comparison]:
        return {c.matrix: c for c in self.comparisons if c.check == check and c.point == point}


ROUNDING = "rounding (1e-13 of the matrix's largest entry)"
LEVER_REASON = "the local-level lever-arm position drops O(l/R) terms (metres at the computed position): 2 |l| (1 + |tan L|) / 6.35e6"


def _largest(a) -> float:
    return float(np.abs(a).max())


def ecef_against_local_level(ecef: DerivedModel, local: DerivedModel, point, point_id: str = "") -> list[Comparison]:
    """F, G, H of the e-frame model against the local-level twin's through T, at ``point`` (one of :data:`POINTS`)."""
    local_values, ecef_values, C_ne, transport, r = point_values(point)
    n = ecef.numeric(known_parameters(ecef, ecef_values))
    m = local.numeric(known_parameters(local, local_values))
    T = np.eye(21)
    for block in range(3):
        T[3 * block:3 * block + 3, 3 * block:3 * block + 3] = C_ne
    T_dot = T @ np.kron(np.diag([1.0, 1.0, 1.0, 0, 0, 0, 0]), skew(transport))
    T_inv = T.T
    F_expected = T @ m["F"] @ T_inv + T_dot @ T_inv
    gravity_local, gravity_j2 = gradient(local_level_gravity, r), gradient(j2_gravity, r)
    dv, dr = slice(3, 6), slice(0, 3)
    out = []

    def add(matrix, difference, bound, reason):
        out.append(Comparison("ecef_vs_local_level", point_id, matrix, float(difference), float(bound), reason))

    fd = "central differences (1 m) of the gravity field typed in numpy"
    add("F[dv,dr] local level vs normal-gravity gradient", _largest(F_expected[dv, dr] - gravity_local), 1e-12, fd)
    add("F[dv,dr] ecef vs J2 gravity gradient", _largest(n["F"][dv, dr] - gravity_j2), 1e-12, fd)
    add("J2 vs normal-gravity gradient (the models' one difference)", _largest(gravity_j2 - gravity_local), 1e-8,
        "the two gravity models differ: J2 field vs Somigliana normal gravity, under 0.3 % of 2 g / R")
    F_expected[dv, dr] = gravity_j2
    add("F (gravity gradient the e-frame's)", _largest(n["F"] - F_expected), 1e-13 * _largest(n["F"]), ROUNDING)
    add("G", _largest(n["G"] - T @ m["G"]), 1e-13 * _largest(n["G"]), ROUNDING)
    T_z = np.kron(np.eye(2), C_ne)
    H_local = m["H"].copy()  # v_c - v_t in each NED frame: z_e = C_n^e (z_n + dtheta x v_antenna), dtheta = Theta dr^n
    H_local[3:6, 0:3] -= skew(antenna_velocity(local_values)) @ frame_angle(local_values)
    H_expected = T_z @ H_local @ T_inv
    add("H velocity rows", _largest(n["H"][3:6] - H_expected[3:6]), 1e-13 * _largest(n["H"]), ROUNDING)
    lever = float(np.linalg.norm(LEVER))
    add("H position rows", _largest(n["H"][:3] - H_expected[:3]),
        2 * lever * (1 + abs(math.tan(local_values["latitude"]))) / 6.35e6, LEVER_REASON)
    no_arm = {f"lever_arm_{a}": 0.0 for a in "xyz"}
    n0 = ecef.numeric(known_parameters(ecef, {**ecef_values, **no_arm}))
    m0 = local.numeric(known_parameters(local, {**local_values, **no_arm}))
    add("H position rows, no lever arm", _largest(n0["H"][:3] - (T_z @ m0["H"] @ T_inv)[:3]), 1e-13,
        "rounding (1e-13 absolute): without a lever arm nothing is dropped")
    return out


def wander_point_values(local: dict) -> dict:
    """The wander model's values at wander angle 0: the local-level point's, C_e^w's third column and v along NED."""
    L = local["latitude"]
    return {**local, "wander_dcm_13": math.cos(L), "wander_dcm_23": 0.0, "wander_dcm_33": -math.sin(L),
            **{f"velocity_{a}": local[f"velocity_{w}"] for a, w in zip("xyz", ("north", "east", "down"))}}


def wander_against_local_level(wander: DerivedModel, local: DerivedModel, point, point_id: str = "") -> list[Comparison]:
    """At wander angle 0: F_w = F_n + dT/dt (the vertical transport rate), G, Q, R equal, H as for ECEF."""
    local_values, _, _, transport, _ = point_values(point)
    L = local_values["latitude"]
    values = wander_point_values(local_values)
    n = wander.numeric(known_parameters(wander, values))
    m = local.numeric(known_parameters(local, local_values))
    T_dot = np.zeros((21, 21))
    for block in range(3):  # alpha' = -lambda' sin L = rho_z (NED)
        T_dot[3 * block:3 * block + 3, 3 * block:3 * block + 3] = transport[2] * skew([0.0, 0.0, 1.0])
    out = []

    def add(matrix, difference, bound, reason, at_least=False):
        out.append(Comparison("wander_vs_local_level", point_id, matrix, float(difference), float(bound), reason, at_least))

    add("F (F_n + dT/dt)", _largest(n["F"] - (m["F"] + T_dot)), 1e-13 * _largest(n["F"]), ROUNDING)
    if abs(transport[2]) >= 1e-9:
        add("F - F_n (shows alpha' = rho_z)", _largest(n["F"] - m["F"]), abs(transport[2]) * 1e-13,
            "must exceed 1e-13 rho_z: free wander has no vertical transport rate", at_least=True)
    for name in ("G", "Q", "R"):
        add(name, _largest(n[name] - m[name]), 0.0, "identical (the same noises, in the same axes at alpha = 0)")
    H_local = m["H"].copy()
    H_local[3:6, 0:3] -= skew(antenna_velocity(local_values)) @ frame_angle(local_values)
    add("H velocity rows", _largest(n["H"][3:6] - H_local[3:6]), 1e-13 * _largest(n["H"]), ROUNDING)
    lever = float(np.linalg.norm(LEVER))
    add("H position rows", _largest(n["H"][:3] - H_local[:3]), 2 * lever * (1 + abs(math.tan(L))) / 6.35e6, LEVER_REASON)
    no_arm = {f"lever_arm_{a}": 0.0 for a in "xyz"}
    n0 = wander.numeric(known_parameters(wander, {**values, **no_arm}))
    m0 = local.numeric(known_parameters(local, {**local_values, **no_arm}))
    add("H position rows, no lever arm", _largest(n0["H"][:3] - m0["H"][:3]), 1e-13,
        "rounding (1e-13 absolute): without a lever arm nothing is dropped")
    return out


# -- the poles ---------------------------------------------------------------------------------
def replace_value(text: str, name: str, value: float) -> str:
    return re.sub(rf"{name}: [-0-9.e+]+", f"{name}: {float(value)!r}", text, count=1)


def polar_wander_text(C_ew: np.ndarray, C_bw: np.ndarray, v: np.ndarray, h: float) -> str:
    """The wander model file with its check scenario moved to the state (C_e^w, C_b^w, v^w, h)."""
    L = math.asin(-C_ew[2, 2])
    RM, RN = wgs84.earth_radii(L)
    values = {"height": h, "meridian_radius": RM, "prime_vertical_radius": RN, "gravity": normal_gravity(L, h),
              **{f"wander_dcm_{i + 1}3": C_ew[i, 2] for i in range(3)}, **{f"velocity_{a}": c for a, c in zip("xyz", v)},
              **{f"c{i + 1}{j + 1}": C_bw[i, j] for i in range(3) for j in range(3)}}
    text = WANDER_MODEL.read_text()
    for name, value in values.items():
        text = replace_value(text, name, value)
    return text


def polar_state(latitude_deg=POLAR_LATITUDE_DEG, longitude_deg=30.0, height=1000.0, v_n=(120.0, -40.0, 0.0),
                attitude=(2.0, 1.0, 200.0), wander_deg=60.0):
    """(C_b^w, v^w, C_e^w, h) of a flight near the pole with wander angle ``wander_deg``."""
    L, lam, alpha = (math.radians(a) for a in (latitude_deg, longitude_deg, wander_deg))
    c, s = math.cos(alpha), math.sin(alpha)
    C_nw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    C_ne = C_n_e(L, lam)
    return C_nw @ euler(*attitude), C_nw @ np.array(v_n), C_nw @ C_ne.T, height


def polar_check(wander: DerivedModel | None = None) -> PolarCheck:
    """The wander model with its check scenario at 89.9 deg (loaded, and evaluated with ``wander``'s matrices, which
    depend on no check value; derived here if not given); ``ins_gnss21_nav`` with its scenario there (refused)."""
    C_bw, v, C_ew, h = polar_state()
    polar = load_model_text(polar_wander_text(C_ew, C_bw, v, h), filename="polar_wander.yaml")
    derived = wander if wander is not None else derive(polar)
    if [s.name for s in derived.model.states] != [s.name for s in polar.states]:
        raise ModelError("polar check: the wander model given is not ins_gnss21_wander")
    values = {**dict(polar.parameter_defaults()), **polar.check.parameter_values()}
    numeric = derived.numeric(known_parameters(derived, values))
    finite = all(np.isfinite(numeric[k]).all() for k in ("F", "G", "H"))
    largest = max(_largest(numeric[k]) for k in ("F", "G", "H")) if finite else math.inf
    nav = builtin_model_path(LOCAL_LEVEL_MODEL).read_text()
    try:
        load_model_text(nav.replace("latitude: {value: 45, unit: deg}", f"latitude: {{value: {POLAR_LATITUDE_DEG}, unit: deg}}"),
                        filename=f"{LOCAL_LEVEL_MODEL}_polar.yaml")
        refused, message = False, ""
    except ModelError as error:
        refused, message = True, str(error)
    return PolarCheck(POLAR_LATITUDE_DEG, finite, largest, refused, message)


# -- the run -----------------------------------------------------------------------------------
def derive_mechanization_models() -> tuple[DerivedModel, DerivedModel, DerivedModel]:
    """(ecef, its local-level twin, wander azimuth), derived."""
    return (derive(load_model(ECEF_MODEL)), derive(load_model_text(LOCAL_LEVEL_TWIN, filename=LOCAL_LEVEL_TWIN_NAME)),
            derive(load_model(WANDER_MODEL)))


def run_mechanization_checks(models: tuple[DerivedModel, DerivedModel, DerivedModel] | None = None,
                             clock: Callable[[], float] | None = None) -> MechanizationChecks:
    """Every comparison at every point (wander at the points local level accepts), and the polar flight."""
    import time

    clock = clock or time.process_time
    start = clock()
    ecef, local, wander = models if models is not None else derive_mechanization_models()
    comparisons: list[Comparison] = []
    for point, point_id in zip(POINTS, POINT_IDS):
        comparisons += ecef_against_local_level(ecef, local, point, point_id)
    for point, point_id in zip(POINTS[:4], POINT_IDS[:4]):
        comparisons += wander_against_local_level(wander, local, point, point_id)
    return MechanizationChecks(tuple(comparisons), polar_check(wander), clock() - start)


CHECK_TITLES = {
    "ecef_vs_local_level": "ECEF against local level through T = diag(C_n^e, C_n^e, C_n^e, I)",
    "wander_vs_local_level": "Wander azimuth at wander angle 0 against local level",
}


def _verdict(passed: bool) -> str:
    return "ok" if passed else "**FAILED**"


def mechanizations_markdown(checks: MechanizationChecks) -> str:
    intro = re.sub(r":data:`(\w+)`", r"`\1`", __doc__.split("\n\n", 1)[1].split(":func:")[0].rstrip())
    lines = ["# Mechanizations cross-checked", "", intro, ""]
    for check, title in CHECK_TITLES.items():
        rows = [c for c in checks.comparisons if c.check == check]
        lines += [f"## {title}", "", "| point | matrix | largest difference | bound | why | verdict |", "|---|---|---|---|---|---|"]
        for c in rows:
            bound = (">= " if c.at_least else "<= ") + f"{c.bound:.3g}"
            lines.append(f"| {c.point} | {c.matrix} | {c.difference:.3g} | {bound} | {c.reason} | {_verdict(c.passed)} |")
        lines.append("")
    p = checks.polar
    lines += [f"## A polar flight (latitude {p.latitude_deg} deg)", "",
              f"- wander azimuth: loaded, F, G, H finite: {p.wander_finite} (largest entry {p.wander_largest_entry:.3g})",
              f"- local level ({LOCAL_LEVEL_MODEL}): refused: {p.local_level_refused}; its message:", "",
              "  > " + (p.local_level_message or "(none)"), "", f"Verdict: {_verdict(p.passed)}", ""]
    return "\n".join(lines)


def mechanizations_json(checks: MechanizationChecks) -> str:
    return json.dumps({
        "comparisons": [{**asdict(c), "passed": c.passed} for c in checks.comparisons],
        "polar": {**asdict(checks.polar), "passed": checks.polar.passed},
        "passed": checks.passed, "cpu_seconds": round(checks.seconds, 2)}, indent=1) + "\n"


def write_mechanizations_report(checks: MechanizationChecks, folder: str | Path) -> tuple[Path, Path]:
    """``mechanizations.md`` and ``mechanizations.json`` into ``folder`` (atomically); returns both paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    markdown, data = folder / "mechanizations.md", folder / "mechanizations.json"
    write_text_atomically(markdown, mechanizations_markdown(checks))
    write_text_atomically(data, mechanizations_json(checks))
    return markdown, data


def report_section_text(checks: MechanizationChecks) -> str:
    """The run report's section body: per check the worst ratio of difference to bound, the polar flight, links."""
    lines = ["Cross-checks of the same 21-state INS/GNSS filter in three mechanizations, entry by entry at "
             "realistic points (45 N, 34 S 11 km, 78 N, the equator, 89.9 N), each matrix held to a stated bound.", "",
             "| check | comparisons | passed | worst difference / bound |", "|---|---|---|---|"]
    for check, title in CHECK_TITLES.items():
        rows = [c for c in checks.comparisons if c.check == check and not c.at_least]
        worst = max(rows, key=lambda c: c.difference / c.bound if c.bound else (0.0 if c.difference == 0 else math.inf))
        ratio = worst.difference / worst.bound if worst.bound else (0.0 if worst.difference == 0 else math.inf)
        every = [c for c in checks.comparisons if c.check == check]
        lines.append(f"| {title} | {len(every)} | {sum(c.passed for c in every)} | {ratio:.2g} ({worst.point}, {worst.matrix}) |")
    p = checks.polar
    lines += ["", f"Polar flight (latitude {p.latitude_deg} deg): wander azimuth {'finite' if p.wander_finite else 'NOT finite'}; "
              f"local level {'refused' if p.local_level_refused else 'NOT refused'}: \"{p.local_level_message}\" "
              f"({_verdict(p.passed)}).", "",
              f"Every check passed: **{'yes' if checks.passed else 'no'}** ({checks.seconds:.1f} s CPU). "
              "Details: [mechanizations.md](mechanizations.md), [mechanizations.json](mechanizations.json)."]
    return "\n".join(lines)
