"""North-East-Down <-> East-North-Up: mapping error states between the two.

The core paper's model (``ned_inertial16`` / ``ned_doppler18``) and the Doppler error thesis's
(``enu_doppler18``) describe the same physics in different axes.  A linear
map T takes an NED error state to the ENU one, so that a covariance maps as
P_enu = T P_ned T^T; ``tests/model/test_ned_enu.py`` uses it to show that both
models propagate the same covariance on the states they share.

The map, group by group (P = NED -> ENU component permutation, D -> -U):

* attitude errors  (phi_E, phi_N, phi_U) = (beta, alpha, -gamma): P (alpha, beta, gamma);
* velocity errors  (dv_E, dv_N) = (dV_e, dV_n);  dv_U has no NED counterpart;
* position errors  dL = dphi, dlambda = dlambda;  dh has no NED counterpart;
* sensor errors are in body axes; each model's attitude matrix C_b^n takes
  its own body axes to its own navigation axes, so body components map by
  B = C_enu^T P C_ned.  Accelerometer biases: nabla_enu = B nabla_ned.
  Gyro drifts: the core paper writes d(alpha)/dt = ... + C eps, the ENU model
  (Qin's form, first principles with eps = measured - true rate) ... - C eps,
  so the two eps are opposite in sign: eps_enu = -B eps_ned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel

#: Components of a vector: ENU = NED_TO_ENU @ NED (swap N and E, U = -D).
NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True)
class StateGroup:
    """ENU states = sign * M @ NED states, with M fixed (``nav``) or body-axis (``body``)."""

    enu: tuple[str, ...]
    ned: tuple[str, ...]
    kind: str  # "nav": the fixed matrix `matrix`; "body": B = C_enu^T P C_ned
    sign: float = 1.0
    matrix: tuple[tuple[float, ...], ...] = ()


#: How each ENU state of enu_doppler18 is made from the states of ned_inertial16 / ned_doppler18.
NED_TO_ENU_GROUPS: tuple[StateGroup, ...] = (
    StateGroup(
        ("attitude_error_east", "attitude_error_north", "attitude_error_up"),
        ("attitude_error_north", "attitude_error_east", "heading_error"),
        "nav",
        matrix=tuple(map(tuple, NED_TO_ENU)),
    ),
    StateGroup(
        ("velocity_error_east", "velocity_error_north"),
        ("velocity_error_north", "velocity_error_east"),
        "nav",
        matrix=((0.0, 1.0), (1.0, 0.0)),
    ),
    StateGroup(("latitude_error", "longitude_error"), ("latitude_error", "longitude_error"), "nav", matrix=((1.0, 0.0), (0.0, 1.0))),
    StateGroup(
        ("gyro_constant_drift_x", "gyro_constant_drift_y", "gyro_constant_drift_z"),
        ("gyro_constant_drift_x", "gyro_constant_drift_y", "gyro_constant_drift_z"),
        "body",
        sign=-1.0,
    ),
    StateGroup(
        ("gyro_markov_drift_x", "gyro_markov_drift_y", "gyro_markov_drift_z"),
        ("gyro_markov_drift_x", "gyro_markov_drift_y", "gyro_markov_drift_z"),
        "body",
        sign=-1.0,
    ),
    StateGroup(
        ("accel_markov_bias_x", "accel_markov_bias_y", "accel_markov_bias_z"),
        ("accel_markov_bias_x", "accel_markov_bias_y", "accel_markov_bias_z"),
        "body",
    ),
)


def body_axes_map(attitude_ned: np.ndarray, attitude_enu: np.ndarray) -> np.ndarray:
    """B = C_enu^T P C_ned: NED-model body components -> ENU-model body components.

    ``attitude_ned`` is C_b^n of the NED model (body -> NED), ``attitude_enu``
    that of the ENU model (its body axes -> ENU), for the same vehicle.
    """
    c_ned = np.asarray(attitude_ned, dtype=float)
    c_enu = np.asarray(attitude_enu, dtype=float)
    for label, c in (("NED", c_ned), ("ENU", c_enu)):
        if c.shape != (3, 3) or not np.allclose(c @ c.T, np.eye(3), atol=1e-9):
            raise ModelError(f"body_axes_map: the {label} attitude matrix is not a 3x3 rotation matrix")
    return c_enu.T @ NED_TO_ENU @ c_ned


def ned_to_enu_transformation(
    ned: ErrorModel, enu: ErrorModel, attitude_ned: np.ndarray, attitude_enu: np.ndarray
) -> tuple[np.ndarray, list[str]]:
    """T with x_enu = T x_ned on the shared states, and the names of those ENU states.

    Rows of ENU states without an NED counterpart (dv_U, dh; any state not in
    :data:`NED_TO_ENU_GROUPS`) are zero; NED states the ENU model does not
    have (the Doppler biases of ned_doppler18) are simply not used.  A group
    is used only if both models have all of its states.
    """
    B = body_axes_map(attitude_ned, attitude_enu)
    T = np.zeros((len(enu.states), len(ned.states)))
    shared: list[str] = []
    enu_names, ned_names = enu.state_names, ned.state_names
    for group in NED_TO_ENU_GROUPS:
        if not (set(group.enu) <= set(enu_names) and set(group.ned) <= set(ned_names)):
            continue
        block = B if group.kind == "body" else np.array(group.matrix, dtype=float)
        rows = [enu_names.index(n) for n in group.enu]
        cols = [ned_names.index(n) for n in group.ned]
        T[np.ix_(rows, cols)] = group.sign * block
        shared.extend(group.enu)
    if not shared:
        raise ModelError(f"ned_to_enu_transformation: models {ned.name!r} and {enu.name!r} share no states")
    return T, shared
