"""How a model's error states relate to the simulated navigation and sensor errors.

The scenario file says which model state is which quantity along which axis
(``filter.states``: ``attitude_error_north: north``...).  The *signs* of the
model's conventions are read from its own equations, not assumed:

* attitude: the simulation's attitude error psi is the misalignment of the
  computed navigation frame, C_computed = (I - psi x) C_true (phi-angle,
  true-position frame).  Under that convention d(psi_N)/dt contains
  +d(V_E)/(R_N + h); the sign of the model's entry F[attitude north, velocity
  east] gives the model's attitude sign.
* gyro and accelerometer states: the simulation's sensor errors are measured
  minus true; then d(psi)/dt contains -C_b^n d(omega) and d(dv)/dt contains
  +C_b^n d(f).  Comparing the model's F blocks with C_b^n at the operating
  point gives each group's sign.  (The core paper's model has +C eps in its
  attitude equations: its gyro drift is true minus measured.)
* Doppler bias: the measurement is z = INS value - sensor value; the sign of
  H at the bias column gives the bias sign.

Velocity and position errors are computed minus true.  Axis words ``up`` (and
ENU frames) flip the sign of the down component; ``c11..c33`` are given as
C_b^n in the model's own frame (NED or ENU, from the model's ``frame``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.rotation import misalignment, rotate_attitude

if TYPE_CHECKING:  # sympy-based, named in annotations only: a run of the compiled loop imports no sympy
    from modelgen.derivation.symbolic import DerivedModel
    from modelgen.simulation.model_outline import ModelOutline

NED_AXIS = {"north": (0, 1.0), "east": (1, 1.0), "down": (2, 1.0), "up": (2, -1.0)}
BODY_AXIS = {"x": 0, "y": 1, "z": 2}
POSITION_AXIS = ("latitude", "longitude", "height")
SENSOR_GROUPS = ("gyro_constant", "gyro_markov", "accelerometer_constant", "accelerometer_markov")
#: groups fed back in closed-loop mode (random constants and navigation states)
FED_BACK = ("attitude", "velocity", "position", "gyro_constant", "accelerometer_constant", "doppler_bias")


def frame_matrix(frame: str) -> np.ndarray:
    """P with v_frame = P v_NED for the model's navigation frame."""
    if frame.upper() in ("", "NED"):
        return np.eye(3)
    if frame.upper() == "ENU":
        return np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    raise ModelError(f"simulation: navigation frame {frame!r} is not supported (NED or ENU)")


@dataclass(frozen=True)
class Entry:
    """One model state: its index, the axis (NED, body or position index) and the sign."""

    index: int
    axis: int
    sign: float


@dataclass
class ErrorLayout:
    derived: DerivedModel | ModelOutline  # read for its number of states and names only
    groups: dict[str, list[Entry]]
    conventions: dict[str, float] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.derived.n_states

    def indices(self, group: str) -> list[int]:
        return [e.index for e in self.groups.get(group, [])]

    def fed_back_mask(self) -> np.ndarray:
        mask = np.zeros(self.n, bool)
        for g in FED_BACK:
            mask[self.indices(g)] = True
        return mask

    # -- navigation errors ---------------------------------------------------------
    def navigation_error(self, nav: np.ndarray, truth: np.ndarray) -> np.ndarray:
        """Model-state vector of the navigation errors of ``nav`` (lat, lon, h, v, q) vs ``truth``.

        Sensor-error components are zero.
        """
        x = np.zeros(self.n)
        psi = misalignment(*nav[6:10], *truth[6:10])
        s = self.conventions.get("attitude", 1.0)
        for e in self.groups.get("attitude", []):
            x[e.index] = s * e.sign * psi[e.axis]
        dv = nav[3:6] - truth[3:6]
        for e in self.groups.get("velocity", []):
            x[e.index] = e.sign * dv[e.axis]
        meridian, prime_vertical = earth.radii_of_curvature(truth[0])
        dpos = nav[0:3] - truth[0:3]
        metres = np.array([dpos[0] * (meridian + truth[2]), dpos[1] * (prime_vertical + truth[2]) * math.cos(truth[0]), -dpos[2]])
        for e in self.groups.get("position", []):
            x[e.index] = e.sign * (dpos[e.axis] if e.axis < 3 else metres[e.axis - 3])
        return x

    def corrected(self, nav: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """Navigation state with the estimated errors ``dx`` removed (output correction).

        C = exp(psi x) C~ (the inverse of C~ = (I - psi x) C), v = v~ - dv, p = p~ - dp.
        """
        out = np.array(nav, float)
        psi = np.zeros(3)
        s = self.conventions.get("attitude", 1.0)
        for e in self.groups.get("attitude", []):
            psi[e.axis] += s * e.sign * dx[e.index]
        if psi.any():
            out[6:10] = rotate_attitude(psi[0], psi[1], psi[2], *nav[6:10])
        for e in self.groups.get("velocity", []):
            out[3 + e.axis] -= e.sign * dx[e.index]
        meridian, prime_vertical = earth.radii_of_curvature(nav[0])
        for e in self.groups.get("position", []):
            value = e.sign * dx[e.index]
            if e.axis < 3:
                out[e.axis] -= value
            elif e.axis == 3:
                out[0] -= value / (meridian + nav[2])
            elif e.axis == 4:
                out[1] -= value / ((prime_vertical + nav[2]) * math.cos(nav[0]))
            else:
                out[2] += value  # "down" metres
        return out

    # -- sensor errors ---------------------------------------------------------------
    def sensor_vector(self, group: str, dx: np.ndarray) -> np.ndarray:
        """Measured-minus-true sensor error (3,) that the states of ``group`` in ``dx`` stand for."""
        out = np.zeros(3)
        s = self.conventions.get(group, 1.0)
        for e in self.groups.get(group, []):
            out[e.axis] += s * e.sign * dx[e.index]
        return out

    def sensor_states(self, group: str, error: np.ndarray) -> np.ndarray:
        """Model-state vector holding the measured-minus-true sensor error (3,) in ``group``'s states."""
        x = np.zeros(self.n)
        s = self.conventions.get(group, 1.0)
        for e in self.groups.get(group, []):
            x[e.index] = s * e.sign * error[e.axis]
        return x


def _entries(derived: DerivedModel, mapping: dict[str, str], group: str) -> list[Entry]:
    model = derived.model
    out = []
    for name, axis in mapping.items():
        index = model.state_index(name)
        if group in ("attitude", "velocity", "doppler_bias"):
            a, s = NED_AXIS[axis]
        elif group == "position":
            a, s = {"latitude": (0, 1.0), "longitude": (1, 1.0), "height": (2, 1.0),
                    "north": (3, 1.0), "east": (4, 1.0), "up": (2, 1.0), "down": (5, 1.0)}[axis]
        else:
            a, s = BODY_AXIS[axis], 1.0
        out.append(Entry(index, a, s))
    return out


def _fit_sign(values: list[float], expected: list[float], what: str, model: str, tolerance: float = 1e-6) -> float:
    """The +-1 with values = sign * expected (each within ``tolerance``, relative); refuse anything else."""
    v, e = np.array(values), np.array(expected)
    if not len(v) or np.max(np.abs(e)) == 0:
        return 1.0
    sign = float(np.sign(v @ e))
    if sign == 0 or np.max(np.abs(v - sign * e)) > tolerance * np.max(np.abs(e)):
        raise ModelError(
            f"model {model!r}: cannot identify the {what} convention: F entries {v[:4]} are not +-{e[:4]}"
        )
    return sign


def build_layout(derived: DerivedModel, states: dict[str, dict[str, str]], F: np.ndarray, H: np.ndarray,
                 attitude_ned: np.ndarray, measurement_rows: dict[int, tuple[int, float]],
                 radius: float) -> ErrorLayout:
    """Layout from the scenario's mapping, signs identified from F and H at an operating point.

    ``attitude_ned`` is C_b^n (NED) at that point, ``radius`` the model's R for
    the attitude/velocity check, ``measurement_rows`` maps a measurement row to
    the (NED axis, sign) of the velocity it differences (for the Doppler bias).
    """
    groups = {g: _entries(derived, m, g) for g, m in states.items()}
    name = derived.model.name
    layout = ErrorLayout(derived, groups)
    att = groups.get("attitude", [])
    vel = groups.get("velocity", [])
    # attitude: F[psi_N, dv_E] = +1/R and F[psi_E, dv_N] = -1/R under C~ = (I - psi x) C
    values, expected = [], []
    for a in att:
        for v in vel:
            coefficient = {(0, 1): 1.0, (1, 0): -1.0}.get((a.axis, v.axis))
            if coefficient is not None:
                values.append(F[a.index, v.index] * radius)
                expected.append(a.sign * v.sign * coefficient)
    # 2 %: the model may use R_M + h, R_N + h or one mean radius (they differ by < 0.7 %)
    s_att = _fit_sign(values, expected, "attitude-error", name, tolerance=0.02)
    layout.conventions["attitude"] = s_att
    # sensors: d(psi)/dt = -C d(omega) and d(dv)/dt = +C d(f) (measured - true)
    for group, rows, physical in (("gyro_constant", att, -1.0), ("gyro_markov", att, -1.0),
                                  ("accelerometer_constant", vel, 1.0), ("accelerometer_markov", vel, 1.0)):
        values, expected = [], []
        row_sign = s_att if group.startswith("gyro") else 1.0
        for r in rows:
            for c in groups.get(group, []):
                values.append(F[r.index, c.index])
                expected.append(row_sign * r.sign * physical * attitude_ned[r.axis, c.axis])
        if groups.get(group):
            layout.conventions[group] = _fit_sign(values, expected, f"{group} sign", name)
    # Doppler bias: z = INS - sensor, sensor = true + bias
    values, expected = [], []
    for row, (axis, sign) in measurement_rows.items():
        for b in groups.get("doppler_bias", []):
            if b.axis == axis:
                values.append(H[row, b.index])
                expected.append(-sign * b.sign)
    if groups.get("doppler_bias"):
        layout.conventions["doppler_bias"] = _fit_sign(values, expected, "Doppler-bias sign", name)
    return layout
