"""The perturbation engine (modelgen.model.perturbation) on sympy objects, without model files.

The central check: the derived F is the exact first-order error dynamics.  It
is compared with central differences of the nonlinear error dynamics computed
here in numpy: the local-level NED mechanization with the WGS-84 radii and
normal gravity (TR8350.2 eqs. 4-1 and 4-3, typed below), a true state built from
the computed one and an error, attitude errors through the matrix exponential.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from scipy.linalg import expm

from modelgen.errors import ModelError
from modelgen.model.mechanizations.local_level import EarthSymbols
from modelgen.model.perturbation.derivation import derive_error_equations
from modelgen.model.perturbation.problem import ErrorDefinition, InertialSensorErrors, NavigationProblem

S = lambda name: sp.Symbol(name, real=True)  # noqa: E731
VEC = lambda names: sp.Matrix([S(n) for n in names])  # noqa: E731

A, F_FLAT, W_EARTH = 6378137.0, 1 / 298.257223563, 7.292115e-5
E2 = F_FLAT * (2 - F_FLAT)
GAMMA_E, K_SOMIGLIANA = 9.7803253359, 0.00193185265241
M_RATIO = W_EARTH**2 * A**2 * A * (1 - F_FLAT) / 3.986004418e14


def radii(L):
    w = 1 - E2 * np.sin(L) ** 2
    return A * (1 - E2) / w**1.5, A / np.sqrt(w)


def gravity(L, h):
    s2 = np.sin(L) ** 2
    return GAMMA_E * (1 + K_SOMIGLIANA * s2) / np.sqrt(1 - E2 * s2) * (1 - 2 * h / A * (1 + F_FLAT + M_RATIO - 2 * F_FLAT * s2) + 3 * h**2 / A**2)


def skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def mechanization(C, v, p, f_b, w_b):
    """(C', v', p') of the local-level NED mechanization (Groves 2013 ch. 5)."""
    L, _, h = p
    RM, RN = radii(L)
    w_ie = W_EARTH * np.array([np.cos(L), 0.0, -np.sin(L)])
    p_rate = np.array([v[0] / (RM + h), v[1] / ((RN + h) * np.cos(L)), -v[2]])
    w_en = np.array([p_rate[1] * np.cos(L), -p_rate[0], -p_rate[1] * np.sin(L)])
    C_rate = C @ skew(w_b) - skew(w_ie + w_en) @ C
    v_rate = C @ f_b - np.cross(2 * w_ie + w_en, v) + np.array([0.0, 0.0, gravity(L, h)])
    return C_rate, v_rate, p_rate


POINT = {
    "L": 0.7, "lambda_": 0.2, "h": 1500.0, "v": np.array([120.0, -60.0, 3.0]),
    "C": expm(skew(np.array([0.02, -0.03, 2.1]))),
    "f_b": np.array([0.3, -0.2, -9.7]), "w_b": np.array([1e-3, -2e-3, 5e-3]),
}


def numeric_error_rates(e):
    """d/dt of (phi, dv, dL, dlambda, dh) for errors e (phi, dv, dp, b_g, b_a, s_g, s_a), computed minus true."""
    phi, dv, dp, bg, ba, sg, sa = (e[3 * k: 3 * k + 3] for k in range(7))
    C, v, p = POINT["C"], POINT["v"], np.array([POINT["L"], POINT["lambda_"], POINT["h"]])
    C_t = expm(skew(phi)) @ C  # computed C = exp(-[phi x]) C_true
    f_t, w_t = (POINT["f_b"] - ba) / (1 + sa), (POINT["w_b"] - bg) / (1 + sg)
    Cc_rate, vc_rate, pc_rate = mechanization(C, v, p, POINT["f_b"], POINT["w_b"])
    Ct_rate, vt_rate, pt_rate = mechanization(C_t, v - dv, p - dp, f_t, w_t)
    E_rate = Cc_rate @ C_t.T + C @ Ct_rate.T  # E = C C_t^T = I - [phi x] to first order
    phi_rate = -np.array([E_rate[2, 1] - E_rate[1, 2], E_rate[0, 2] - E_rate[2, 0], E_rate[1, 0] - E_rate[0, 1]]) / 2
    return np.concatenate([phi_rate, vc_rate - vt_rate, pc_rate - pt_rate])


def numeric_F():
    steps = np.array([1e-5] * 3 + [1e-3] * 3 + [1e-6, 1e-6, 1.0] + [1e-7] * 6 + [1e-5] * 6)
    columns = []
    for k, step in enumerate(steps):
        e = np.zeros(21)
        e[k] = step
        columns.append((numeric_error_rates(e) - numeric_error_rates(-e)) / (2 * step))
    return np.column_stack(columns)


def problem(approximations=(), errors=None, measurements=()):
    """The NED problem of POINT with biases and scale factors (random constants), geodetic position errors."""
    C = sp.Matrix(3, 3, [S(f"c{i}{j}") for i in range(1, 4) for j in range(1, 4)])
    sensors = {k: VEC([f"{k}_{a}" for a in "xyz"]) for k in ("b_g", "b_a", "s_g", "s_a")}
    errors = errors or ErrorDefinition("phi", tuple(VEC(["phi_n", "phi_e", "phi_d"])), "difference",
                                          tuple(VEC(["dv_n", "dv_e", "dv_d"])), "geodetic", tuple(VEC(["dL", "dlambda", "dh"])))
    others = [s for k in ("b_g", "b_a", "s_g", "s_a") for s in sensors[k]]
    return NavigationProblem(
        frame="NED", attitude=C, velocity=VEC(["v_n", "v_e", "v_d"]), position=VEC(["L", "lambda_", "h"]),
        specific_force=VEC(["f_x", "f_y", "f_z"]), specific_force_axes="body", body_rate=VEC(["w_x", "w_y", "w_z"]),
        earth=EarthSymbols(S("omega_ie"), S("R_M"), S("R_N"), S("g"), S("R")), errors=errors,
        gyro=InertialSensorErrors(sensors["b_g"], sensors["s_g"]), accelerometer=InertialSensorErrors(sensors["b_a"], sensors["s_a"]),
        state_order=(*errors.attitude_states, *errors.velocity_states, *errors.position_states, *others),
        auxiliary_dynamics={s: sp.S.Zero for s in others}, noises=(), measurements=tuple(measurements), approximations=tuple(approximations),
    )


def values():
    RM, RN = radii(POINT["L"])
    out = {S("L"): POINT["L"], S("h"): POINT["h"], S("omega_ie"): W_EARTH, S("R_M"): RM, S("R_N"): RN, S("g"): gravity(POINT["L"], POINT["h"])}
    out.update({S(n): x for n, x in zip(("v_n", "v_e", "v_d"), POINT["v"])})
    out.update({S(f"c{i + 1}{j + 1}"): POINT["C"][i, j] for i in range(3) for j in range(3)})
    out.update({S(f"f_{a}"): x for a, x in zip("xyz", POINT["f_b"])})
    out.update({S(f"w_{a}"): x for a, x in zip("xyz", POINT["w_b"])})
    return out


def evaluate(matrix):
    return np.array(matrix.xreplace(values()).evalf(), dtype=float)


@pytest.fixture(scope="module")
def exact():
    return derive_error_equations(problem())


def test_derived_F_is_the_exact_first_order_error_dynamics_of_the_mechanization(exact):
    derived = evaluate(exact.F)[:9]
    reference = numeric_F()
    scale = np.abs(reference).max(axis=0) + 1e-300
    assert np.all(np.abs(derived - reference) <= 2e-6 * scale + 1e-13), np.abs(derived - reference).max()


def test_the_comparison_sees_the_radius_derivatives_that_constant_radii_drops():
    approximated = evaluate(derive_error_equations(problem(("constant_radii",))).F)[:9]
    reference = numeric_F()
    scale = np.abs(reference).max(axis=0) + 1e-300
    assert np.any(np.abs(approximated - reference) > 2e-6 * scale + 1e-13)


def test_approximated_matrix_plus_its_neglected_terms_is_the_exact_matrix(exact):
    approximated = derive_error_equations(problem(("constant_radii", "constant_gravity", "no_transport_rate_position_terms")))
    restored = approximated.F.copy()
    for term in approximated.neglected:
        assert term.matrix == "F"
        restored[term.row, term.column] += term.term
    assert np.allclose(evaluate(restored), evaluate(exact.F), rtol=1e-12, atol=1e-18)
    assert {t.approximation for t in approximated.neglected} == {"constant_radii", "constant_gravity", "no_transport_rate_position_terms"}


def test_derivation_is_byte_stable():
    first, second = (derive_error_equations(problem(("constant_radii",))) for _ in range(2))
    assert sp.srepr(first.F) == sp.srepr(second.F) and sp.srepr(first.neglected) == sp.srepr(second.neglected)


def test_metres_and_psi_are_the_geodetic_phi_model_seen_through_the_change_of_variables(exact):
    """x_new = T x_old with T constant at an instant: F_new = (T F_old + T') T^-1, checked numerically."""
    psi = ErrorDefinition("psi", tuple(VEC(["psi_n", "psi_e", "psi_d"])), "computed_frame", tuple(VEC(["dv_n", "dv_e", "dv_d"])),
                             "metres", tuple(VEC(["dr_n", "dr_e", "dr_d"])))
    other = derive_error_equations(problem(errors=psi))
    # eigenvalues are invariant under a change of variables only when T' = 0; the trace of F changes by tr(T' T^-1)
    F_old, F_new = evaluate(exact.F), evaluate(other.F)
    assert F_new.shape == F_old.shape
    L, h, v = POINT["L"], POINT["h"], POINT["v"]
    RM, RN = radii(L)
    # d/dt ln det T = d/dt ln((R_M + h)(R_N + h) cos L) along the path (psi and computed-frame rows have unit diagonal)
    L_rate = v[0] / (RM + h)
    expected = -v[2] / (RM + h) - v[2] / (RN + h) - np.tan(L) * L_rate
    expected += (3 * E2 * np.sin(L) * np.cos(L) * RM / (1 - E2 * np.sin(L) ** 2)) * L_rate / (RM + h)
    expected += (E2 * np.sin(L) * np.cos(L) * RN / (1 - E2 * np.sin(L) ** 2)) * L_rate / (RN + h)
    assert np.trace(F_new) - np.trace(F_old) == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"approximations": ("flat_earth",)}, "unknown approximation(s) flat_earth"),
        ({"frame": "ECEF"}, "navigation frame 'ECEF' is not one of NED, ENU"),
        ({"auxiliary_dynamics": {}}, "have no equation"),
    ],
)
def test_inconsistent_problems_are_refused_before_deriving(change, message):
    from dataclasses import replace

    with pytest.raises(ModelError, match=message.replace("(", r"\(").replace(")", r"\)")):
        derive_error_equations(replace(problem(), **change))


def test_no_vertical_channel_removes_vertical_velocity_and_height_and_lists_their_couplings(exact):
    full = problem()
    horizontal = ErrorDefinition("phi", full.errors.attitude_states, "difference", full.errors.velocity_states[:2],
                                    "geodetic", full.errors.position_states[:2])
    order = tuple(s for s in full.state_order if s not in (full.errors.velocity_states[2], full.errors.position_states[2]))
    from dataclasses import replace

    reduced = derive_error_equations(replace(full, errors=horizontal, state_order=order, approximations=("no_vertical_channel",)))
    kept = [full.state_order.index(s) for s in order]
    assert reduced.states == order and reduced.F.shape == (19, 19)
    assert sp.simplify(reduced.F - exact.F.extract(kept, kept)) == sp.zeros(19, 19)
    dropped = {(t.row, t.column) for t in reduced.neglected}
    v_d, h = full.state_order.index(full.errors.velocity_states[2]), full.state_order.index(full.errors.position_states[2])
    # every nonzero coupling of a kept state to the vertical channel is listed (column -1: the removed state)
    couplings = {kept.index(i) for i in kept for j in (v_d, h) if exact.F[i, j] != 0}
    assert couplings == {row for row, column in dropped if column == -1 and row >= 0}
    assert any(row == -1 for row, _ in dropped)  # and the vertical channel's own rows


def test_no_vertical_channel_needs_the_horizontal_components_only():
    from dataclasses import replace

    with pytest.raises(ModelError, match="velocity error has 3 states, 2 expected"):
        derive_error_equations(replace(problem(), approximations=("no_vertical_channel",)))


@pytest.mark.parametrize("position_form", ["geodetic", "metres"])
def test_damped_vertical_channel_makes_the_height_loop_stable_with_its_gains(position_form):
    """dh' = dv_up - k_1 dh, dv_up' = (2g/R - k_2) dh: roots of s^2 + k_1 s + (k_2 - 2g/R), in either position form."""
    from dataclasses import replace

    base = problem()
    position = VEC(["dL", "dlambda", "dh"]) if position_form == "geodetic" else VEC(["dr_n", "dr_e", "dr_d"])
    errors = replace(base.errors, position=position_form, position_states=tuple(position))
    order = (*base.errors.attitude_states, *base.errors.velocity_states, *position, *base.state_order[9:])
    free = derive_error_equations(replace(base, errors=errors, state_order=order))
    damped = derive_error_equations(replace(base, errors=errors, state_order=order, approximations=("damped_vertical_channel",)))
    v_d, h = 5, 8
    gains = {S("k_v1"): 0.02, S("k_v2"): 3e-4}
    change = np.array((damped.F - free.F).xreplace(gains).evalf(), dtype=float)
    expected = np.zeros_like(change)
    expected[h, h] = -0.02
    expected[v_d, h] = 3e-4 if position_form == "geodetic" else -3e-4  # NED: v_D = -v_up; metres: dr_D = -dh
    assert np.array_equal(change, expected)
    assert [(t.row, t.column) for t in damped.neglected] == [(v_d, h), (h, h)]
    # the vertical pair alone (level, at rest in height rate): stable only with the damping
    for derived, stable in ((free, False), (damped, True)):
        block = evaluate(derived.F.xreplace(gains))[np.ix_([v_d, h], [v_d, h])]
        assert (np.linalg.eigvals(block).real.max() < 0) == stable
