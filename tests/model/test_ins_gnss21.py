"""The 21-state INS/GNSS model's scalar equations are its vector model, expanded correctly.

The model file (modelgen/models/ins_gnss21.yaml) writes the local-level NED
error model as 21 scalar equations.  Here the vector formulas of its header
are written again, independently, with numpy, and their numeric Jacobians
with respect to the states, the noises and (for the measurements) the
states are compared with the F, G and H modelgen derives from the file, at
the file's own check scenario and at a second, deliberately asymmetric
operating point (every parameter distinct and nonzero, so that a swapped
index or sign cannot hide behind a zero or a symmetry).
"""

import math

import numpy as np
import pytest

from modelgen.derivation.symbolic import parameter_vector
from modelgen.jobs import check_scenario


@pytest.fixture(scope="module")
def derived(derived_builtin):
    return derived_builtin("ins_gnss21")


def skew(a: np.ndarray) -> np.ndarray:
    """[a x], the matrix of the cross product a x (.)."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def vector_model(p: dict[str, float]):
    """(f(x, w), h(x)) of the model header's vector formulas, for parameter values ``p`` (by symbol)."""
    L, h = p["L"], p["h"]
    RM, RN, W, g = p["R_M"], p["R_N"], p["omega_ie"], p["g"]
    v = np.array([p["v_N"], p["v_E"], p["v_D"]])
    C = np.array([[p[f"c{i}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)])
    fb = np.array([p["f_bx"], p["f_by"], p["f_bz"]])
    wb = np.array([p["omega_bx"], p["omega_by"], p["omega_bz"]])
    lever = np.array([p["l_x"], p["l_y"], p["l_z"]])
    mu = np.array([p["mu_bg"], p["mu_ba"], p["mu_sg"], p["mu_sa"]])
    w_ie = np.array([W * math.cos(L), 0.0, -W * math.sin(L)])
    w_en = np.array([v[1] / (RN + h), -v[0] / (RM + h), -v[1] * math.tan(L) / (RN + h)])
    w_in = w_ie + w_en

    def f(x: np.ndarray, w: np.ndarray) -> np.ndarray:
        dr, dv, phi, bg, ba, sg, sa = (x[3 * k : 3 * k + 3] for k in range(7))
        wg, wa, wbg, wba, wsg, wsa = (w[3 * k : 3 * k + 3] for k in range(6))
        dw_in = np.array([dv[1] / (RN + h), -dv[0] / (RM + h), -dv[1] * math.tan(L) / (RN + h)])
        dfb = ba + fb * sa + wa
        dwb = bg + wb * sg + wg
        return np.concatenate(
            [
                -np.cross(w_en, dr) + dv,
                np.cross(C @ fb, phi) + C @ dfb - np.cross(2 * w_ie + w_en, dv) + np.array([0.0, 0.0, 2 * g / (RN + h) * dr[2]]),
                -np.cross(w_in, phi) + dw_in - C @ dwb,
                -mu[0] * bg + wbg,
                -mu[1] * ba + wba,
                -mu[2] * sg + wsg,
                -mu[3] * sa + wsa,
            ]
        )

    def hfun(x: np.ndarray) -> np.ndarray:
        dr, dv, phi, bg, _, sg, _ = (x[3 * k : 3 * k + 3] for k in range(7))
        z_r = dr + np.cross(C @ lever, phi)
        z_v = dv + np.cross(C @ np.cross(wb, lever), phi) + C @ np.cross(bg + wb * sg, lever)
        return np.concatenate([z_r, z_v])

    return f, hfun


def jacobian(fun, n: int) -> np.ndarray:
    """Central differences of a function that is linear in its argument (so exact up to rounding)."""
    cols = []
    for k in range(n):
        e = np.zeros(n)
        e[k] = 1.0
        cols.append((fun(e) - fun(-e)) / 2.0)
    return np.array(cols).T


def asymmetric_point(derived) -> dict[str, float]:
    """Every parameter a distinct, nonzero value (a rotation for C_b^n is not needed for the algebra)."""
    rng = np.random.default_rng(21)
    return {p.name: float(rng.uniform(0.5, 2.0)) * (1 if k % 2 else -1) for k, p in enumerate(derived.model.parameters)}


def by_symbol(derived, values: dict[str, float]) -> dict[str, float]:
    numbers = parameter_vector(derived.model, values)
    return {p.symbol: float(v) for p, v in zip(derived.model.parameters, numbers)}


@pytest.mark.parametrize("point", ["check scenario", "asymmetric"])
def test_derived_F_G_H_equal_the_jacobians_of_the_vector_formulas(derived, point):
    values = dict(check_scenario(derived).parameters) if point == "check scenario" else asymmetric_point(derived)
    m = derived.numeric(values)
    f, hfun = vector_model(by_symbol(derived, values))
    n, q = derived.n_states, len(derived.model.noises)
    F = jacobian(lambda x: f(x, np.zeros(q)), n)
    G = jacobian(lambda w: f(np.zeros(n), w), q)
    H = jacobian(hfun, n)
    for name, ours, theirs in (("F", m["F"], F), ("G", m["G"], G), ("H", m["H"], H)):
        assert ours.shape == theirs.shape, name
        assert np.array_equal(ours != 0, theirs != 0), f"{name}: the nonzero pattern differs"
        np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=0, err_msg=name)


def test_state_order_is_position_velocity_attitude_then_sensor_errors(derived):
    names = derived.model.state_names
    assert len(names) == 21
    assert names[:9] == [f"{q}_error_{a}" for q in ("position", "velocity", "attitude") for a in ("north", "east", "down")]
    assert names[9:] == [f"{s}_{a}" for s in ("gyro_bias", "accel_bias", "gyro_scale_factor", "accel_scale_factor") for a in "xyz"]


def test_check_scenario_is_physical(derived):
    """A rotation for C_b^n, WGS-84 radii, specific force ~ (0, 0, -g) in NED, 1 s GNSS steps."""
    p = check_scenario(derived).parameters
    C = np.array([[p[f"c{i}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)])
    np.testing.assert_allclose(C @ C.T, np.eye(3), atol=1e-11)
    assert abs(np.linalg.det(C) - 1) < 1e-11
    a, e2 = 6378137.0, 6.69437999014e-3
    s2 = math.sin(p["latitude"]) ** 2
    assert p["meridian_radius"] == pytest.approx(a * (1 - e2) / (1 - e2 * s2) ** 1.5, rel=1e-10)
    assert p["prime_vertical_radius"] == pytest.approx(a / math.sqrt(1 - e2 * s2), rel=1e-10)
    f_n = C @ np.array([p[f"body_specific_force_{x}"] for x in "xyz"])
    np.testing.assert_allclose(f_n, [0.0, 0.0, -p["gravity"]], atol=0.02)
    assert 9.78 < p["gravity"] < 9.83
    assert check_scenario(derived).step == 1.0
