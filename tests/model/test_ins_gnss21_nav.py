"""ins_gnss21_nav (21 states, derived from the navigation equations) against a textbook derivation typed here.

The textbook model is the local-level NED phi-angle error model of Shin (2005),
"Estimation techniques for low-cost inertial navigation", ch. 4, and Groves
(2013), "Principles of GNSS, Inertial, and Multisensor Integrated Navigation
Systems", ch. 14, with the position error in NED metres, typed below in numpy
as vector equations (nothing from modelgen's derivation engine):

    d(dL)/dt = dv_N/(R_M + h) - v_N dh/(R_M + h)^2              (Groves eq. 14.64, position rows)
    d(dlambda)/dt = dv_E/((R_N + h) cos L) + v_E sin L dL/((R_N + h) cos^2 L) - v_E dh/((R_N + h)^2 cos L)
    d(dh)/dt = -dv_D,   in metres: dr = ((R_M + h) dL, (R_N + h) cos L dlambda, -dh), differentiated along the path
    d(dv)/dt  = (C f) x phi + C df - (2 w_ie + w_en) x dv - (2 dw_ie + dw_en) x v + (0, 0, 2 g dr_D / (R_N + h))
    d(phi)/dt = -w_in x phi + dw_ie + dw_en - C dw
    df = b_a + diag(f) s_a + w_a,  dw = b_g + diag(w) s_g + w_g,  d(b)/dt = -mu b + w_b (each bias and scale factor)
    GNSS position (antenna at l):  z_r = dr + (C l) x phi
    GNSS velocity (antenna at l):  z_v = dv + (C (w x l)) x phi + C ((b_g + diag(w) s_g) x l)
                                         + w_ie x (phi x C l) - dw_ie x (C l)

with dL = dr_N/(R_M + h), dlambda = dr_E/((R_N + h) cos L), dh = -dr_D,
dw_ie, dw_en the
first-order changes of w_ie = W (cos L, 0, -sin L) and w_en = (v_E/(R_N + h),
-v_N/(R_M + h), -v_E tan L/(R_N + h)).  (Shin's vector form of the position rows,
d(dr)/dt = -w_en x dr + dtheta x v + dv, holds for a spherical Earth only: it puts R_N + h
where the east row needs R_M + h, 0.3 % of F[dr_E, dr_N] and of the tan L part of F[dr_E, dr_E].)
Like the textbooks it neglects the
variation of R_M, R_N and of gravity with latitude and uses the inverse-square
free-air gradient: exactly the three approximations ins_gnss21_nav declares,
whose dropped terms the model lists with their sizes.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from modelgen.derivation.symbolic import derive
from modelgen.model.navigation_model.approximation_notes import neglected_terms


def _cross(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _textbook(p: dict[str, float]):
    """F, G, H of the textbook model at parameter values ``p`` (by name), states in ins_gnss21_nav's order."""
    L, h, g, W = p["latitude"], p["height"], p["gravity"], p["earth_rate"]
    RM, RN = p["meridian_radius"] + h, p["prime_vertical_radius"] + h
    v = np.array([p["velocity_north"], p["velocity_east"], p["velocity_down"]])
    C = np.array([[p[f"c{i}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)])
    f = np.array([p[f"body_specific_force_{a}"] for a in "xyz"])
    w = np.array([p[f"body_rate_{a}"] for a in "xyz"])
    lever = np.array([p[f"lever_arm_{a}"] for a in "xyz"])
    w_ie = W * np.array([np.cos(L), 0.0, -np.sin(L)])
    w_en = np.array([v[1] / RN, -v[0] / RM, -v[1] * np.tan(L) / RN])
    mu = {"b_g": p["gyro_bias_rate"], "b_a": p["accel_bias_rate"], "s_g": p["scale_factor_rate"], "s_a": p["scale_factor_rate"]}

    def errors(x):
        dr, dv, phi, bg, ba, sg, sa = (x[3 * k: 3 * k + 3] for k in range(7))
        dL, dh = dr[0] / RM, -dr[2]
        dw_ie = W * np.array([-np.sin(L) * dL, 0.0, -np.cos(L) * dL])
        dw_en = np.array([
            dv[1] / RN - v[1] * dh / RN**2,
            -dv[0] / RM + v[0] * dh / RM**2,
            -dv[1] * np.tan(L) / RN - v[1] * dL / (RN * np.cos(L) ** 2) + v[1] * np.tan(L) * dh / RN**2,
        ])
        return dr, dv, phi, bg, ba, sg, sa, dL, dw_ie, dw_en

    def rates(x, noise):
        dr, dv, phi, bg, ba, sg, sa, dL, dw_ie, dw_en = errors(x)
        dh = -dr[2]
        wg, wa, drive = noise[0:3], noise[3:6], noise[6:18]
        df = ba + f * sa + wa
        dw = bg + w * sg + wg
        dlam = dr[1] / (RN * np.cos(L))
        d_dL = dv[0] / RM - v[0] * dh / RM**2
        d_dlam = dv[1] / (RN * np.cos(L)) + v[1] * np.sin(L) * dL / (RN * np.cos(L) ** 2) - v[1] * dh / (RN**2 * np.cos(L))
        h_rate, L_rate = -v[2], v[0] / RM
        d_dr = np.array([
            RM * d_dL + h_rate * dL,
            RN * np.cos(L) * d_dlam + (h_rate * np.cos(L) - RN * np.sin(L) * L_rate) * dlam,
            dv[2],
        ])
        d_dv = (np.cross(C @ f, phi) + C @ df - np.cross(2 * w_ie + w_en, dv) - np.cross(2 * dw_ie + dw_en, v)
                + np.array([0.0, 0.0, 2 * g * dr[2] / (p["prime_vertical_radius"] + h)]))
        d_phi = -np.cross(w_ie + w_en, phi) + dw_ie + dw_en - C @ dw
        sensors = [-mu[k] * s + drive[3 * i: 3 * i + 3] for i, (k, s) in enumerate(zip(("b_g", "b_a", "s_g", "s_a"), (bg, ba, sg, sa)))]
        return np.concatenate([d_dr, d_dv, d_phi, *sensors])

    def measured(x):
        dr, dv, phi, bg, _, sg, _, _, dw_ie, _ = errors(x)
        arm = C @ lever
        z_r = dr + np.cross(arm, phi)
        z_v = dv + np.cross(C @ np.cross(w, lever), phi) + C @ np.cross(bg + w * sg, lever) + np.cross(w_ie, np.cross(phi, arm)) - np.cross(dw_ie, arm)
        return np.concatenate([z_r, z_v])

    unit = np.eye(21)
    F = np.column_stack([rates(unit[k], np.zeros(18)) for k in range(21)])
    G = np.column_stack([rates(np.zeros(21), np.eye(18)[k]) for k in range(18)])
    H = np.column_stack([measured(unit[k]) for k in range(21)])
    return F, G, H


@pytest.fixture(scope="module")
def model(loaded_builtin):
    return loaded_builtin("ins_gnss21_nav")


def _values(model):
    values = dict(model.parameter_defaults())
    values.update(model.check.parameter_values())
    return values


def test_ins_gnss21_nav_F_G_H_equal_the_textbook_derivation_to_rounding(model):
    values = _values(model)
    derived = derive(model).numeric(values)
    for name, typed in zip("FGH", _textbook(values)):
        assert derived[name].shape == typed.shape
        scale = np.abs(typed).max()
        assert np.abs(derived[name] - typed).max() <= 1e-14 * scale, name


def test_ins_gnss21_nav_is_21_states_in_at_most_60_lines(model):
    from modelgen.model.loading import builtin_model_path

    assert len(model.states) == 21 and len(model.measurements) == 6
    assert len(builtin_model_path("ins_gnss21_nav").read_text().splitlines()) <= 60


def test_ins_gnss21_nav_lists_what_its_four_approximations_drop_with_sizes(model):
    terms = neglected_terms(model)
    assert {t.approximation for t in terms} == {"lever_arm_at_computed_position", "constant_radii", "gravity_height_only", "free_air_gradient"}
    notes = [n for n in model.notes if n.startswith("Approximation ")]
    assert len(notes) == 4
    # the lever arm turned into (dL, dlambda, dh) at the computed position: the O(l/R) H terms, each by name
    for entry in (r"H\[Z_rn, position_error_north\]", r"H\[Z_rn, position_error_down\] = \(c11\*l_x \+ c12\*l_y \+ c13\*l_z\)/\(R_M \+ h\) \(1\.81e-07\)",
                  r"H\[Z_re, position_error_north\]", r"H\[Z_re, position_error_down\]"):
        assert re.search(entry, notes[0])
    # dg/dh: WGS-84 normal-gravity gradient against 2 g / (R_N + h), the textbook's: 0.5 % of 3.1e-6 s^-2
    assert re.search(r"F\[velocity_error_down, position_error_down\] = -\(R_N\*dg/dh \+ dg/dh\*h \+ 2\*g\)/\(R_N \+ h\) \(1\.58e-08\)", notes[3])
    # dR_N/dL in the east position rate: d((R_N + h) cos L)/dt
    assert re.search(r"F\[position_error_east, position_error_east\] = dR_N/dL\*v_n/[^;]*\(4\.57e-08\)", notes[1])
