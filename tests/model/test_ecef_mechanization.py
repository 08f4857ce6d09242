"""The ecef mechanization (Groves 2013 ch. 5.3, 14.2.3) against the local-level one, through the known transformation.

The same 21-state INS/GNSS filter is derived twice: in the e-frame
(``modelgen/data/mechanizations/ins_gnss21_ecef.yaml``: phi^e, dv^e, dr^e) and in local-level
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

import numpy as np
import pytest

from modelgen.checks import mechanizations as mech
from modelgen.checks.mechanizations import ECEF_MODEL, POINTS, POINT_IDS
from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.loading import builtin_model_path, load_model_text


@pytest.fixture(scope="module")
def models(mechanization_models):
    ecef, local, _ = mechanization_models  # derive(load_model(ECEF_MODEL)), derive(LOCAL_LEVEL_TWIN): tests/conftest.py
    return ecef, local


@pytest.mark.parametrize("point", POINTS, ids=POINT_IDS)
def test_ecef_F_G_H_equal_local_level_through_the_frame_rotation_except_the_gravity_model(models, point):
    ecef, local = models
    comparisons = mech.ecef_against_local_level(ecef, local, point)
    failed = [(c.matrix, c.difference, c.bound) for c in comparisons if not c.passed]
    assert not failed
    matrices = {c.matrix for c in comparisons}
    assert {"F (gravity gradient the e-frame's)", "G", "H velocity rows", "H position rows", "H position rows, no lever arm"} <= matrices
    gravity = next(c for c in comparisons if c.matrix.startswith("J2 vs normal-gravity"))
    assert 0 < gravity.difference < 1e-8  # the gravity models do differ (the one modelling difference), by little


def test_a_comparison_outside_its_bound_fails():
    c = mech.Comparison("ecef_vs_local_level", "p", "F", 2e-13, 1e-13, "rounding")
    assert not c.passed and mech.Comparison("x", "p", "F", 1e-13, 1e-13, "r").passed
    assert not mech.Comparison("x", "p", "F", 0.0, 1e-20, "must show", at_least=True).passed


def test_ecef_model_has_e_frame_states_and_parameters(mechanization_models):
    model = mechanization_models[0].model  # load_model(ECEF_MODEL)
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
    local, ecef_values, _, _, r = mech.point_values(POINTS[-1])
    for axis, value in zip("xyz", r):
        ecef_text = mech.replace_value(ecef_text, f"position_{axis}", value)
    ecef_text = mech.replace_value(ecef_text, "geocentric_radius", float(np.linalg.norm(r)))
    polar = load_model_text(ecef_text, filename="polar_ecef.yaml")
    F = derive(polar).numeric({**dict(polar.parameter_defaults()), **polar.check.parameter_values()})["F"]
    assert np.isfinite(F).all() and np.abs(F[3:6, 0:3]).max() < 1e-5  # the gravity gradient, as anywhere
    nav = builtin_model_path("ins_gnss21_nav").read_text()
    with pytest.raises(ModelError) as caught:
        load_model_text(nav.replace("latitude: {value: 45, unit: deg}", "latitude: {value: 89.9, unit: deg}"), filename="m.yaml")
    message = str(caught.value)
    assert message.startswith("m.yaml:") and "latitude 89.9 deg is within 1 deg of a pole" in message
    assert "1/cos L = 573" in message and "'mechanization: wander_azimuth' or 'mechanization: ecef'" in message
    assert load_model_text(nav.replace("latitude: {value: 45, unit: deg}", "latitude: {value: 89, unit: deg}"), filename="m.yaml")

