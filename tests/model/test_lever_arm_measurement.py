"""The lever-arm GNSS position measurement's H against a finite-difference Jacobian (issue 27 item 3).

The antenna at lever arm l (body axes) is at p + D(p) C l in (L, lambda, h), with
D(p) = diag(1/(R_M + h), 1/((R_N + h) cos L), -1) evaluated at the position p it
is attached to.  The measurement is INS minus GNSS in metres along NED:
z = M(p_c) (a(x_c) - a(x_t)), M = diag(R_M + h, (R_N + h) cos L, -1) at the computed
position, with the errors computed minus true (dr in metres along NED, and
C_c = (I - [phi x]) C_t).  Its Jacobian with respect to (dr, phi) is taken here by
central differences in numpy, typed from these definitions alone (no modelgen
code), with the radii held constant as ins_gnss21_nav's ``constant_radii`` says.
The default (exact) H must match it; under ``lever_arm_at_computed_position`` D
is taken at the computed position and the O(l/R) entries go: H then misses it by
exactly those terms, which the model lists.
"""

from __future__ import annotations

import numpy as np
import pytest

from modelgen.derivation.symbolic import derive
from modelgen.model.loading import builtin_model_path, load_model_text

NAV = builtin_model_path("ins_gnss21_nav").read_text()
DECLARED = "approximations: [lever_arm_at_computed_position, constant_radii, gravity_height_only, free_air_gradient]"
EXACT = NAV.replace(DECLARED, "approximations: [constant_radii, gravity_height_only, free_air_gradient]")
#: a navigation engineer's point: 30 deg N, 100 m, a lever arm of about 1 m (the issue's example)
POINT = {"latitude": np.radians(30.0), "height": 100.0, "lever_arm_x": 0.8, "lever_arm_y": -0.5, "lever_arm_z": -0.6}


def _model_and_values(text: str, name: str):
    model = load_model_text(text, filename=f"{name}.yaml")
    values = {**dict(model.parameter_defaults()), **model.check.parameter_values(), **POINT}
    return model, values


def _cross(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _finite_difference_position_rows(p: dict[str, float]) -> np.ndarray:
    """d z_r / d(dr, phi) (3 x 6) by central differences of the definitions in the module docstring."""
    RM0, RN0 = p["meridian_radius"], p["prime_vertical_radius"]
    C_c = np.array([[p[f"c{i}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)])
    lever = np.array([p[f"lever_arm_{a}"] for a in "xyz"])
    computed = np.array([p["latitude"], 0.3, p["height"]])

    def offset(position: np.ndarray, C: np.ndarray) -> np.ndarray:
        """The antenna's offset D(p) C l from the position it is attached to, in (L, lambda, h)."""
        L, h = position[0], position[2]
        return np.diag([1.0 / (RM0 + h), 1.0 / ((RN0 + h) * np.cos(L)), -1.0]) @ (C @ lever)

    L, h = computed[0], computed[2]
    M = np.diag([RM0 + h, (RN0 + h) * np.cos(L), -1.0])

    def z(error: np.ndarray) -> np.ndarray:
        dr, phi = error[:3], error[3:]
        difference = np.linalg.solve(M, dr)  # dr = M (p_c - p_t)
        C_t = np.linalg.solve(np.eye(3) - _cross(phi), C_c)
        # a(x_c) - a(x_t) = (p_c - p_t) + (offset_c - offset_t), summed in that order: adding the ~1e-11 rad
        # attitude effect to a latitude of 0.5 rad first would round it to a few parts in 1e6
        return M @ (difference + (offset(computed, C_c) - offset(computed - difference, C_t)))

    steps = np.array([100.0, 100.0, 100.0, 1e-6, 1e-6, 1e-6])  # metres, rad: error O(step^2 / R^2), O(step^2)
    columns = []
    for k, step in enumerate(steps):
        e = np.zeros(6)
        e[k] = step
        columns.append((z(e) - z(-e)) / (2 * step))
    return np.column_stack(columns)


def _columns(model) -> list[int]:
    """Indices of (dr_N, dr_E, dr_D, phi_N, phi_E, phi_D) among the model's states."""
    names = [s.name for s in model.states]
    return ([names.index(f"position_error_{a}") for a in ("north", "east", "down")]
            + [names.index(f"attitude_error_{a}") for a in ("north", "east", "down")])


def _position_rows(model, values) -> np.ndarray:
    """The derived H's three position rows (they come first) in the columns of :func:`_columns`."""
    return derive(model).numeric(values)["H"][:3][:, _columns(model)]


def test_the_exact_lever_arm_position_rows_match_a_finite_difference_jacobian():
    model, values = _model_and_values(EXACT, "exact")
    typed = _finite_difference_position_rows(values)
    derived = _position_rows(model, values)
    # position-error columns: the O(l/R) entries are 3e-9 to 1.4e-7 and the differences exact to ~1e-16;
    # attitude columns (entries about 1): the differences' rounding is about 1e-10
    assert np.abs(derived[:, :3] - typed[:, :3]).max() <= 1e-14
    assert np.abs(derived[:, 3:] - typed[:, 3:]).max() <= 1e-9
    assert abs(typed[0, 2]) > 1e-7 and abs(typed[1, 0]) > 1e-9 and abs(typed[1, 2]) > 1e-9  # the terms are there


def test_the_computed_position_approximation_misses_it_by_exactly_the_o_l_over_r_terms_it_lists():
    model, values = _model_and_values(NAV, "declared")
    typed = _finite_difference_position_rows(values)
    derived = _position_rows(model, values)
    missed = derived - typed
    assert np.abs(missed[:, :3]).max() > 1e-7  # the approximation is visible at this point
    assert np.abs(missed[:, 3:]).max() <= 1e-9  # ... and only in the position-error columns
    columns = _columns(model)
    missed_entries = {(row, columns[k]) for row in range(3) for k in range(3) if abs(missed[row, k]) > 1e-14}
    assert len(missed_entries) == 3  # (Z_rn, dr_D), (Z_re, dr_N), (Z_re, dr_D): the radii are constant here
    listed = {(t.row, t.column) for t in model.neglected
              if t.approximation == "lever_arm_at_computed_position" and t.matrix == "H"}
    assert missed_entries <= listed  # every entry it gets wrong is one it lists as dropped
