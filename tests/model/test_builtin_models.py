"""The model library: every model's F against first principles, and the pseudo-range builder.

"First principles" here means an independent derivation: the navigation
equations (attitude, velocity, position rates as functions of latitude,
height and velocity) are written as vectors, and the error equations are
obtained by perturbing them with sympy Jacobians and cross products, not by
retyping the model files' expanded terms.  The model's derived F must equal
that at random operating points.  Then closed-form results that do not come
from either derivation: the Schuler / Foucault / earth-rate frequencies of a
stationary INS, the vertical-channel divergence rate sqrt(2 g / R), and the
psi-angle/phi-angle equivalence (Benson 1975).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.operating_point import level_attitude, level_flight, line_of_sight, pseudorange_parameters
from modelgen.model.pseudorange import pseudorange_model
from modelgen.model.wgs84 import ECCENTRICITY_SQUARED as WGS84_ECCENTRICITY_SQUARED
from modelgen.model.wgs84 import SEMI_MAJOR_AXIS as WGS84_SEMI_MAJOR_AXIS
from modelgen.model.wgs84 import earth_radii
from modelgen.model.loading import load_model
from modelgen.model.transform import keep_states

EARTH_RATE = 7.2921151467e-5
RNG = np.random.default_rng(20240501)


@pytest.fixture(scope="module")
def models(derived_builtin):
    names = ("ned_doppler18", "ned_inertial16", "enu_doppler18", "ins_gps15", "gps_pseudorange11")
    return {name: derived_builtin(name) for name in names}


def sym(name: str) -> sp.Symbol:
    return sp.Symbol(name, real=True)


def vec(*names: str) -> sp.Matrix:
    return sp.Matrix([sym(n) for n in names])


def attitude_matrix() -> sp.Matrix:
    return sp.Matrix(3, 3, lambda i, j: sym(f"c{i + 1}{j + 1}"))


def perturbation(expr: sp.Matrix, variables: list[sp.Symbol], errors: list[sp.Expr]) -> sp.Matrix:
    """First-order change of ``expr`` when each variable changes by its error."""
    return expr.jacobian(sp.Matrix(variables)) * sp.Matrix(errors)


def random_values(model, overrides: dict[str, float] | None = None) -> dict[str, float]:
    """Plausible random values for every parameter of ``model`` (by symbol)."""
    values = {}
    for p in model.parameters:
        s = p.symbol
        if s in ("phi", "L"):
            v = RNG.uniform(-1.2, 1.2)
        elif s in ("R", "R_M", "R_N"):
            v = RNG.uniform(6.33e6, 6.40e6)
        elif s == "h":
            v = RNG.uniform(0, 1e4)
        elif s.startswith(("V_", "v_")):
            v = RNG.uniform(-300, 300)
        elif s in ("omega_ie",):
            v = EARTH_RATE
        elif s in ("g",):
            v = 9.8
        else:
            v = RNG.uniform(-2, 2)
        values[s] = v
    values.update(overrides or {})
    return values


def assert_same_matrix(derived_matrix, expected_matrix, model, points: int = 2):
    """Equal entry by entry at ``points`` random operating points."""
    symbols = model.parameter_symbols
    f = sp.lambdify(symbols, [derived_matrix, expected_matrix], modules="numpy")
    for _ in range(points):
        values = random_values(model)
        a, b = (np.broadcast_to(np.asarray(m, dtype=float), derived_matrix.shape) for m in f(*[values[s.name] for s in symbols]))
        scale = max(np.abs(b).max(), 1e-300)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * scale)


# -- first-principles error equations -----------------------------------------------
def enu_navigation_errors(gyro_sign: int = -1):
    """d(phi)/dt, d(dv)/dt, d(position)/dt of the ENU phi-angle model, by perturbation.

    Navigation equations (local geographic ENU, ellipsoid radii R_M, R_N held
    constant, height h):  w_ie = (0, W cos L, W sin L),
    w_en = (-v_N/(R_M+h), v_E/(R_N+h), v_E tan L/(R_N+h)),
    dv/dt = C f^b - (2 w_ie + w_en) x v + (0, 0, -g(h)),  g(h) ~ (R_N+h)^-2,
    dL/dt = v_N/(R_M+h), dlambda/dt = v_E/((R_N+h) cos L), dh/dt = v_U.
    Computed frame rotated by phi from the true one: f^n computed = f + f x phi;
    attitude error rate -w_in x phi + d(w_in) + gyro_sign * C eps.
    """
    L, h, W, RM, RN, g = (sym(s) for s in ("L", "h", "omega_ie", "R_M", "R_N", "g"))
    v = vec("v_E", "v_N", "v_U")
    f = vec("f_E", "f_N", "f_U")
    phi = vec("phi_E", "phi_N", "phi_U")
    dv = vec("dv_E", "dv_N", "dv_U")
    q, dq = [L, h, *v], [sym("dL"), sym("dh"), *dv]
    w_ie = sp.Matrix([0, W * sp.cos(L), W * sp.sin(L)])
    w_en = sp.Matrix([-v[1] / (RM + h), v[0] / (RN + h), v[0] * sp.tan(L) / (RN + h)])
    w_in = w_ie + w_en
    attitude = -w_in.cross(phi) + perturbation(w_in, q, dq)
    transport = (2 * w_ie + w_en).cross(v)
    true_height = sym("h_true")
    gravity_up = -g * (RN + h) ** 2 / (RN + true_height) ** 2  # up component of gravity, = -g at h
    dgravity = sp.diff(gravity_up, true_height).subs(true_height, h) * sym("dh")
    velocity = f.cross(phi) - perturbation(transport, q, dq) + sp.Matrix([0, 0, dgravity])
    position = perturbation(sp.Matrix([v[1] / (RM + h), v[0] / ((RN + h) * sp.cos(L)), v[2]]), q, dq)
    return attitude, velocity, position


def ned_navigation_errors():
    """The core paper's NED model by perturbation: one radius R, no vertical channel (dV_d = 0).

    w_ie = (W cos phi, 0, -W sin phi), w_en = (V_e/R, -V_n/R, -V_e tan phi/R);
    the paper's sign for the gyro drift (+C eps) is added by the caller.
    """
    lat, W, R = sym("phi"), sym("omega_ie"), sym("R")
    v = vec("V_n", "V_e", "V_d")
    f = vec("a_n", "a_e", "a_d")
    att = vec("alpha", "beta", "gamma")
    dv = sp.Matrix([sym("dV_n"), sym("dV_e"), 0])
    q, dq = [lat, *v], [sym("dphi"), *dv]
    w_ie = sp.Matrix([W * sp.cos(lat), 0, -W * sp.sin(lat)])
    w_en = sp.Matrix([v[1] / R, -v[0] / R, -v[1] * sp.tan(lat) / R])
    w_in = w_ie + w_en
    attitude = -w_in.cross(att) + perturbation(w_in, q, dq)
    velocity = f.cross(att) - perturbation((2 * w_ie + w_en).cross(v), q, dq)
    position = perturbation(sp.Matrix([v[0] / R, v[1] / (R * sp.cos(lat))]), q, dq)
    return attitude, velocity[:2, 0], position


def rows_jacobian(expressions: sp.Matrix, model) -> sp.Matrix:
    return expressions.jacobian(sp.Matrix(model.state_symbols))


# -- NED models (the core paper) ------------------------------------------------------------
@pytest.mark.parametrize("name", ["ned_doppler18", "ned_inertial16"])
def test_ned_navigation_rows_of_F_equal_the_perturbed_navigation_equations(models, name):
    d = models[name]
    m = d.model
    attitude, velocity, position = ned_navigation_errors()
    C = attitude_matrix()
    drift = sp.Matrix([sym(f"eps_c_{a}") + sym(f"eps_r_{a}") for a in "xyz"])
    accel = sp.Matrix([sym(f"nabla_{a}") for a in "xyz"])
    expected = sp.Matrix.vstack(attitude + C * drift, velocity + (C * accel)[:2, 0], position)
    assert_same_matrix(d.F[:7, :], rows_jacobian(expected, m), m)


def test_ned_inertial16_is_ned_doppler18_without_the_doppler_states(models):
    full = load_model("ned_doppler18")
    kept = keep_states(full, models["ned_inertial16"].model.state_names)
    reduced = derive(kept)
    ours = models["ned_inertial16"]
    assert kept.state_names == ours.model.state_names
    assert ours.n_measurements == 0
    for key in "FGQ":
        assert sp.simplify(getattr(reduced, key) - getattr(ours, key)) == sp.zeros(*getattr(ours, key).shape), key


def stationary_frequencies(latitude: float, g: float, radius: float) -> list[float]:
    """Positive imaginary parts of the stationary INS error modes.

    Characteristic equation of the horizontal channels at rest (one radius R):
    (s^2 + W^2) [(s^2 + w_s^2)^2 + 4 s^2 W^2 sin^2 L] = 0, w_s^2 = g/R, so
    s = +-i W and s = +-i (sqrt(w_s^2 + W^2 sin^2 L) +- W sin L) (Schuler
    split by the Foucault frequency W sin L).
    """
    ws2, fs = g / radius, EARTH_RATE * math.sin(latitude)
    return sorted([EARTH_RATE, math.sqrt(ws2 + fs**2) - fs, math.sqrt(ws2 + fs**2) + fs])


def positive_frequencies(F: np.ndarray) -> list[float]:
    ev = np.linalg.eigvals(F)
    return sorted(x.imag for x in ev if x.imag > 1e-9)


def test_ned_inertial16_at_rest_has_schuler_foucault_and_earth_rate_modes(models):
    d = models["ned_inertial16"]
    lat, g, R = math.radians(30), 9.7803, 6378137.0
    values = level_flight(d.model, lat, 0.0, math.radians(90))
    values.update(specific_force_down=-g, earth_radius=R)
    values.update({f"{k}_{a}": 1e-4 for k in ("gyro_markov_rate", "gyro_markov_sigma", "accel_markov_rate", "accel_markov_sigma") for a in "xyz"})
    F = d.numeric(values)["F"][:7, :7]
    np.testing.assert_allclose(positive_frequencies(F), stationary_frequencies(lat, g, R), rtol=1e-9)


# -- ENU models (the Doppler error thesis and 001) -------------------------------------------------------
def test_enu_doppler18_F_and_G_equal_the_perturbed_navigation_equations(models):
    d = models["enu_doppler18"]
    m = d.model
    attitude, velocity, position = enu_navigation_errors()
    C = attitude_matrix()
    gyro = sp.Matrix([sym(f"eps_b_{a}") + sym(f"eps_r_{a}") + sym(f"w_g_{a}") for a in "xyz"])
    accel = sp.Matrix([sym(f"nabla_{a}") for a in "xyz"])
    markov = sp.Matrix(
        [0, 0, 0]
        + [-sym(f"mu_eps_{a}") * sym(f"eps_r_{a}") + sym(f"w_eps_{a}") for a in "xyz"]
        + [-sym(f"mu_nabla_{a}") * sym(f"nabla_{a}") + sym(f"w_nabla_{a}") for a in "xyz"]
    )
    rhs = sp.Matrix.vstack(attitude - C * gyro, velocity + C * accel, position, markov)
    assert_same_matrix(d.F, rows_jacobian(rhs, m), m)
    assert_same_matrix(d.G, rhs.jacobian(sp.Matrix(m.noise_symbols)), m)
    # H = [0 I3 0]: the Doppler velocity measurement of eq. (2-14)
    H = np.array(d.H, dtype=float)
    assert np.array_equal(H, np.hstack([np.zeros((3, 3)), np.eye(3), np.zeros((3, 12))]))


def test_ins_gps15_F_and_G_equal_the_perturbed_navigation_equations(models):
    d = models["ins_gps15"]
    m = d.model
    attitude, velocity, position = enu_navigation_errors()
    C = attitude_matrix()
    gyro = sp.Matrix([sym(f"eps_b_{a}") + sym(f"w_g_{a}") for a in "xyz"])
    accel = sp.Matrix([sym(f"nabla_{a}") + sym(f"w_a_{a}") for a in "xyz"])
    rhs = sp.Matrix.vstack(attitude - C * gyro, velocity + C * accel, position, sp.zeros(6, 1))
    assert_same_matrix(d.F, rows_jacobian(rhs, m), m)
    assert_same_matrix(d.G, rhs.jacobian(sp.Matrix(m.noise_symbols)), m)


def test_ins_gps15_measures_velocity_and_position_in_metres(models):
    d = models["ins_gps15"]
    lat, h = 0.6, 500.0
    values = level_flight(d.model, lat, 100.0, 1.0, height=h)
    values.update(gyro_angle_random_walk=1e-5, accel_velocity_random_walk=1e-4)
    values.update({f"gps_{k}_sigma_{a}": 1.0 for k in ("velocity", "position") for a in ("east", "north", "up")})
    H = d.numeric(values)["H"]
    x = np.zeros(15)
    x[3:6] = [0.1, -0.2, 0.3]  # velocity errors
    x[6], x[7], x[8] = 1e-6, -2e-6, 4.0  # dL, dlambda (rad), dh (m)
    r_m, r_n = earth_radii(lat)
    expected = [0.1, -0.2, 0.3, (r_m + h) * 1e-6, (r_n + h) * math.cos(lat) * -2e-6, 4.0]
    np.testing.assert_allclose(H @ x, expected, rtol=1e-12)


def test_ins_gps15_and_enu_doppler18_share_the_navigation_error_equations(models):
    a, b = models["ins_gps15"], models["enu_doppler18"]
    nav = slice(0, 9)
    assert sp.simplify(a.F[nav, nav] - b.F[nav, nav]) == sp.zeros(9, 9)


def enu_rest_values(model, earth_rate: float = EARTH_RATE) -> dict[str, float]:
    lat, g, R = math.radians(30), 9.7803, 6378137.0
    values = level_flight(model, lat, 0.0, 0.0, gravity=g)
    values.update(meridian_radius=R, prime_vertical_radius=R, specific_force_up=g, earth_rate=earth_rate)
    values.update({f"{k}_{a}": 1e-4 for k in ("gyro_markov_rate", "gyro_markov_sigma", "accel_markov_rate", "accel_markov_sigma") for a in "xyz"})
    values.update({f"doppler_noise_sigma_{a}": 0.1 for a in ("east", "north", "up")})
    return {k: v for k, v in values.items() if k in model.parameter_names}


def test_enu_horizontal_channels_at_rest_have_the_classic_frequencies(models):
    m = load_model("enu_doppler18")
    horizontal = keep_states(m, [s for s in m.state_names if s not in ("velocity_error_up", "height_error")])
    d = derive(horizontal)
    F = d.numeric(enu_rest_values(horizontal))["F"][:7, :7]
    np.testing.assert_allclose(positive_frequencies(F), stationary_frequencies(math.radians(30), 9.7803, 6378137.0), rtol=1e-9)


def test_enu_vertical_channel_is_unstable_at_the_free_air_rate(models):
    d = models["enu_doppler18"]
    rate = math.sqrt(2 * 9.7803 / 6378137.0)  # 1/(571 s)
    # without earth rate the vertical channel decouples: eigenvalues exactly +-sqrt(2 g / R)
    F = d.numeric(enu_rest_values(d.model, earth_rate=0.0))["F"]
    assert max(np.linalg.eigvals(F).real) == pytest.approx(rate, rel=1e-9)
    # the Coriolis coupling 2 W cos L between dv_E and dv_U moves it by less than 0.5 %
    F = d.numeric(enu_rest_values(d.model))["F"]
    assert max(np.linalg.eigvals(F).real) == pytest.approx(rate, rel=5e-3)
    assert 1 / rate == pytest.approx(571, abs=1)


# -- the accumulated-correction paper: pseudo-range model -----------------------------------------------------
def benson_transformation(latitude: float, radius: float, velocity: tuple[float, float, float]) -> np.ndarray:
    """x_psi = T x_phi for the 9 navigation states (Benson 1975).

    phi-model states (phi_E, phi_N, phi_U, dv_E, dv_N, dv_U, dL, dlambda, dh);
    psi-model states (dr_E, dr_N, dr_U, dv_E, dv_N, dv_U, psi_E, psi_N, psi_U).
    dtheta = rotation of the computed frame = (-dL, cos L dlambda, sin L dlambda);
    dr = (R cos L dlambda, R dL, dh); psi = phi - dtheta;
    dv_psi = dv_phi + dtheta x v (the phi model's velocity error is resolved in
    the computed frame, the psi model's in the true frame).
    """
    T = np.zeros((9, 9))
    T[0, 7], T[1, 6], T[2, 8] = radius * math.cos(latitude), radius, 1.0
    dtheta = np.zeros((3, 9))
    dtheta[0, 6], dtheta[1, 7], dtheta[2, 7] = -1.0, math.cos(latitude), math.sin(latitude)
    vx = np.array([[0, -velocity[2], velocity[1]], [velocity[2], 0, -velocity[0]], [-velocity[1], velocity[0], 0]])
    T[3:6, 3:6] = np.eye(3)
    T[3:6] -= vx @ dtheta
    T[6:9, 0:3] = np.eye(3)
    T[6:9] -= dtheta
    return T


@pytest.mark.parametrize("latitude, speed, heading", [(0.5, 0.0, 0.0), (0.5, 200.0, math.pi / 2), (-0.9, 150.0, 2.5), (1.1, 250.0, 0.3)])
def test_psi_angle_pseudorange_model_is_the_enu_phi_model_seen_through_bensons_transformation(models, latitude, speed, heading):
    """F_psi = (T F_phi + dT/dt) T^-1 exactly, on a steady (unaccelerated) trajectory.

    Both models are linearizations of the same navigation equations, so they
    must be similar; this holds only when the specific force is the one
    steady flight needs (Eotvos and transport terms included), which
    level_flight supplies.  Spherical earth, R_M = R_N = R, h = 0.
    """
    R = WGS84_SEMI_MAJOR_AXIS
    phi_d, psi_d = models["enu_doppler18"], models["gps_pseudorange11"]
    phi_values = level_flight(phi_d.model, latitude, speed, heading, spherical_earth=True)
    phi_values.update({f"{k}_{a}": 1e-4 for k in ("gyro_markov_rate", "gyro_markov_sigma", "accel_markov_rate", "accel_markov_sigma") for a in "xyz"})
    phi_values.update({f"doppler_noise_sigma_{a}": 0.1 for a in ("east", "north", "up")})
    psi_values = level_flight(psi_d.model, latitude, speed, heading)
    psi_values.update(gyro_angle_random_walk=1e-5, accel_velocity_random_walk=1e-4, clock_bias_psd=1.0, clock_drift_psd=0.01)
    psi_values.update(pseudorange_parameters([(0.0, 1.0)] * 4))
    psi_values.update({f"pseudorange_sigma_{k}": 3.0 for k in range(1, 5)})
    F_phi = phi_d.numeric(phi_values)["F"][:9, :9]
    F_psi = psi_d.numeric(psi_values)["F"][:9, :9]
    v = (speed * math.sin(heading), speed * math.cos(heading), 0.0)
    T = benson_transformation(latitude, R, v)
    dt = 1.0  # latitude changes at v_N / R
    T_dot = (benson_transformation(latitude + v[1] / R * dt, R, v) - benson_transformation(latitude - v[1] / R * dt, R, v)) / (2 * dt)
    np.testing.assert_allclose((T @ F_phi + T_dot) @ np.linalg.inv(T), F_psi, rtol=0, atol=1e-12 * np.abs(F_psi).max())


def test_psi_model_at_rest_has_the_classic_frequencies_and_the_vertical_divergence(models):
    d = models["gps_pseudorange11"]
    lat, g = math.radians(30), 9.7803
    values = level_flight(d.model, lat, 0.0, 0.0, gravity=g)
    values.update(gyro_angle_random_walk=1e-5, accel_velocity_random_walk=1e-4, clock_bias_psd=1.0, clock_drift_psd=0.01, earth_rate=0.0)
    values.update(pseudorange_parameters([(0.0, 1.0)] * 4))
    values.update({f"pseudorange_sigma_{k}": 3.0 for k in range(1, 5)})
    F = d.numeric(values)["F"]
    rate = math.sqrt(2 * g / WGS84_SEMI_MAJOR_AXIS)
    assert max(np.linalg.eigvals(F).real) == pytest.approx(rate, rel=1e-9)
    values["earth_rate"] = EARTH_RATE
    F = d.numeric(values)["F"]
    horizontal = [0, 1, 3, 4, 6, 7, 8]  # without dr_U, dv_U (vertical) and the clock
    expected = stationary_frequencies(lat, g, WGS84_SEMI_MAJOR_AXIS)
    # the psi-angle block is -w_ie x psi (modes 0, +-i W); the position/velocity block gives Schuler/Foucault
    got = positive_frequencies(F[np.ix_(horizontal, horizontal)])
    np.testing.assert_allclose(got, expected, rtol=1e-9)


def test_clock_states_are_a_bias_driven_by_a_drift(models):
    d = models["gps_pseudorange11"]
    m = d.model
    i_t, i_f = m.state_index("I_t"), m.state_index("I_f")
    unit_row = sp.zeros(1, 11)
    unit_row[0, i_f] = 1
    assert d.F[i_t, :] == unit_row  # d(I_t)/dt = I_f
    assert d.F[i_f, :] == sp.zeros(1, 11)  # d(I_f)/dt = w_f
    noises = d.model.noise_names
    assert d.G[i_t, noises.index("clock_bias_noise")] == 1 and d.G[i_f, noises.index("clock_drift_noise")] == 1


@pytest.mark.parametrize("n", [1, 4, 7])
def test_pseudorange_model_has_one_row_per_satellite_from_its_line_of_sight(n):
    d = derive(pseudorange_model(n))
    assert d.n_states == 11 and d.n_measurements == n
    for k in range(n):
        e = [sym(f"e_{k + 1}_{a}") for a in "xyz"]
        assert list(d.H[k, :]) == [*e, 0, 0, 0, 0, 0, 0, 1, 0]
        assert d.R[k, k] == sym(f"sigma_rho_{k + 1}") ** 2


def test_pseudorange_row_is_the_linearized_measured_minus_computed_range():
    """Z = rho'_GPS - rho_C (the accumulated-correction paper eq. (8)) computed from positions equals H x."""
    d = derive(pseudorange_model(1))
    az, el = 1.1, 0.6
    e = np.array(line_of_sight(az, el))
    r_sat = 2.02e7 * e  # satellite along the line of sight, receiver at the origin
    dr = np.array([3.0, -4.0, 12.0])  # INS position error (INS minus true), m
    clock = 150.0  # clock bias range, m
    rho_gps = np.linalg.norm(r_sat) + clock
    rho_ins = np.linalg.norm(r_sat - dr)
    values = {"line_of_sight_east_1": e[0], "line_of_sight_north_1": e[1], "line_of_sight_up_1": e[2]}
    H = np.array(d.H.subs({sym(f"e_1_{a}"): values[f"line_of_sight_{n}_1"] for a, n in zip("xyz", ("east", "north", "up"))}), dtype=float)
    x = np.zeros(11)
    x[0:3], x[9] = dr, clock
    assert (H @ x)[0] == pytest.approx(rho_gps - rho_ins, abs=1e-5)


def test_pseudorange_geometry_reproduces_closed_form_dilution_of_precision():
    """One satellite at zenith, three at elevation t spaced 120 deg in azimuth.

    G^T G = diag-blocks: horizontal 3/2 cos^2 t I (HDOP^2 = 4/(3 cos^2 t));
    vertical/clock [[1 + 3 s^2, 1 + 3 s], [1 + 3 s, 4]], s = sin t, det 3 (1 - s)^2.
    """
    t = math.radians(20)
    sats = [(0.0, math.pi / 2), (0.0, t), (2 * math.pi / 3, t), (4 * math.pi / 3, t)]
    d = derive(pseudorange_model(4))
    values = pseudorange_parameters(sats)
    H = np.array(d.H.subs({sym(p.symbol): values[p.name] for p in d.model.parameters if p.name in values}), dtype=float)
    G = H[:, [0, 1, 2, 9]]
    cov = np.linalg.inv(G.T @ G)
    s = math.sin(t)
    det = 3 * (1 - s) ** 2
    assert cov[0, 0] + cov[1, 1] == pytest.approx(4 / (3 * math.cos(t) ** 2), rel=1e-12)
    assert cov[2, 2] == pytest.approx(4 / det, rel=1e-12)
    assert cov[3, 3] == pytest.approx((1 + 3 * s**2) / det, rel=1e-12)


def test_gps_pseudorange11_file_is_the_four_satellite_instance(models):
    ours = derive(pseudorange_model(4))
    shipped = models["gps_pseudorange11"]
    assert shipped.model.state_names == ours.model.state_names
    assert shipped.model.parameter_names == ours.model.parameter_names
    for key in "FGHQR":
        assert getattr(shipped, key) == getattr(ours, key), key


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "4"])
def test_pseudorange_model_refuses_a_bad_satellite_count(bad):
    with pytest.raises(ModelError, match="positive integer"):
        pseudorange_model(bad)


# -- helpers ------------------------------------------------------------------------------
def test_wgs84_radii_of_curvature_at_equator_and_pole():
    a, e2 = WGS84_SEMI_MAJOR_AXIS, WGS84_ECCENTRICITY_SQUARED
    r_m, r_n = earth_radii(0.0)
    assert r_m == pytest.approx(a * (1 - e2), rel=1e-15) and r_n == pytest.approx(a, rel=1e-15)
    r_m, r_n = earth_radii(math.pi / 2)
    assert r_m == pytest.approx(r_n, rel=1e-12) and r_n == pytest.approx(6399593.626, abs=1e-3)
    assert earth_radii(0.0)[0] == pytest.approx(6335439.327, abs=1e-3)


def test_line_of_sight_is_a_unit_vector_pointing_by_azimuth_and_elevation():
    assert line_of_sight(0.0, 0.0) == pytest.approx((0.0, 1.0, 0.0))
    assert line_of_sight(math.pi / 2, 0.0) == pytest.approx((1.0, 0.0, 0.0))
    assert line_of_sight(1.0, math.pi / 2) == pytest.approx((0.0, 0.0, 1.0))
    assert np.linalg.norm(line_of_sight(2.0, 0.4)) == pytest.approx(1.0)


def test_level_attitude_matches_the_papers_heading_east_matrix_and_maps_forward_along_the_heading():
    assert np.array_equal(np.round(level_attitude("NED", math.pi / 2), 12), [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    heading = 0.7
    forward_ned = np.array(level_attitude("NED", heading)) @ [1, 0, 0]  # body x forward
    forward_enu = np.array(level_attitude("ENU", heading)) @ [0, 1, 0]  # body y forward
    assert forward_ned == pytest.approx([math.cos(heading), math.sin(heading), 0])
    assert forward_enu == pytest.approx([math.sin(heading), math.cos(heading), 0])
    with pytest.raises(ModelError):
        level_attitude("XYZ", 0.0)


def test_level_flight_specific_force_balances_coriolis_transport_and_gravity(models):
    m = models["enu_doppler18"].model
    lat, speed, heading, g = 0.8, 250.0, 0.4, 9.8
    values = level_flight(m, lat, speed, heading, gravity=g)
    v = np.array([values["velocity_east"], values["velocity_north"], 0.0])
    r_m, r_n = earth_radii(lat)
    w_ie = EARTH_RATE * np.array([0, math.cos(lat), math.sin(lat)])
    w_en = np.array([-v[1] / r_m, v[0] / r_n, v[0] * math.tan(lat) / r_n])
    f = np.array([values["specific_force_east"], values["specific_force_north"], values["specific_force_up"]])
    acceleration = f - np.cross(2 * w_ie + w_en, v) + [0, 0, -g]
    np.testing.assert_allclose(acceleration, 0, atol=1e-12)
    assert values["meridian_radius"] == r_m and values["prime_vertical_radius"] == r_n
