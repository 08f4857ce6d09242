"""What the navigator needs to know about its error model, computed once from the derived model file.

A :class:`NavigatorSpec` is made once per replay (:func:`navigator_spec`: one
derivation) and handed to the Python navigator, the C navigator's templates and
the embedded build.  From the model's state names -- the names the navigation
notation gives its error states (``attitude_error_<axis>``,
``velocity_error_<axis>``, ``position_error_<axis>`` or ``latitude_error``,
``longitude_error``, ``height_error``; sensor errors ``gyro_bias_x``,
``accel_bias_x``, ``gyro_scale_factor_x``, ``accel_scale_factor_x``; the
hand-written ENU models' ``gyro_constant_drift_x`` and ``accel_constant_bias_x``
are read as biases) and its frame (NED or ENU) it finds the state blocks, and
from them:

* the feedback of every block into the nominal state and its reset
  (:meth:`NavigatorSpec.feedback`): attitude C_b^n = exp([phi x]) C_b^n' (the
  phi-angle definition C' = (I - [phi x]) C), velocity v -= dv, position in
  metres (north, east, down or up) or as dL, dlambda, dh, biases b += db,
  scale factors s += ds (the mechanization uses (raw - b) / (1 + s));
* P0 from the configuration's sigmas per block (:meth:`NavigatorSpec.initial_covariance`);
* the rows of the zero-velocity update (velocity block) and of the
  non-holonomic constraint (attitude and velocity blocks) in the model's frame;
* the GNSS update's rows: each of the model's own measurements is a position or
  a velocity difference (INS minus GNSS) along one axis, found from which
  position or velocity state it depends on; its H is the model's generated H
  (a lever arm in the model is a model parameter, set from the configuration);
* the carried states (:attr:`NavigatorSpec.carried`): an aiding sensor's own error declared in the model
  file (``measurements: - bias: {process: gauss_markov, ...}``, e.g. the GNSS receiver's time-correlated
  position error, a shaping filter).  It is not the INS's error, so it is not fed back into the
  mechanization: the navigator keeps its estimate ``sensors["carried"]``, which the feedback corrects
  (+= x, then x = 0 as for every state), the covariance step propagates by the model's own transition
  (the block of Phi), and the GNSS update subtracts from its differences (z - H_c e: measured = true + e).
  Its P0 is the process's steady state, Q_ii / (2 a_i) from the model's F_ii = -a_i and its noise;
* the model's parameters at the operating point, from one table of expressions
  (:data:`QUANTITIES`) that are valid C and, with ``->`` read as ``.``, Python,
  so that the C navigator's parameter code and the Python navigator's cannot
  disagree; a parameter the table does not know comes from the configuration's
  ``parameters:`` section or the model's default.

* the mechanization's physics: the model's own rates (``navigation_rates``, from
  the equations its error model is derived from; :mod:`modelgen.derivation.mechanization_rates`)
  printed as Python (compiled) and C (:mod:`modelgen.codegen.mechanization`) for the
  navigators' fixed integrators.

A model whose states do not make the attitude, velocity and position blocks is
refused with one error naming its file.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType, SimpleNamespace
from typing import Sequence

import numpy as np

from modelgen.codegen.mechanization import c_source, python_source
from modelgen.derivation.mechanization_rates import RatesRefused, mechanization_rates
from modelgen.derivation.symbolic import is_identically_zero
from modelgen.errors import ModelError
from modelgen.model.ned_enu import NED_TO_ENU
from modelgen.navigator.config import key_place

#: axis word -> (NED axis, sign): the state is sign x the NED component; x, y, z: the e-frame axes (ecef)
AXES = {"north": (0, 1.0), "east": (1, 1.0), "down": (2, 1.0), "up": (2, -1.0), "x": (0, 1.0), "y": (1, 1.0), "z": (2, 1.0)}
#: the axis words of each frame's navigation blocks
FRAME_AXES = {"NED": ("north", "east", "down", "up"), "ENU": ("north", "east", "down", "up"), "ECEF": ("x", "y", "z")}
SENSOR_BLOCKS = ("gyro_bias", "accel_bias", "gyro_scale_factor", "accel_scale_factor")
#: state-name patterns of each block (the navigation notation's names; the hand-written ENU models' bias names)
_PATTERNS = {
    "attitude": re.compile(r"^attitude_error_(north|east|down|up|x|y|z)$"),
    "velocity": re.compile(r"^velocity_error_(north|east|down|up|x|y|z)$"),
    "position": re.compile(r"^position_error_(north|east|down|up|x|y|z)$"),
    "gyro_bias": re.compile(r"^(?:gyro_bias|gyro_constant_drift)_([xyz])$"),
    "accel_bias": re.compile(r"^(?:accel_bias|accel_constant_bias)_([xyz])$"),
    "gyro_scale_factor": re.compile(r"^gyro_scale_factor_([xyz])$"),
    "accel_scale_factor": re.compile(r"^accel_scale_factor_([xyz])$"),
}
_GEODETIC = {"latitude_error": "north", "longitude_error": "east", "height_error": "up"}

#: the model parameters the navigator sets at the operating point: name -> expression over the navigator's
#: quantities (C, and Python with ``->`` read as ``.``): lat, lon, h [rad, m]; rm, rn radii [m]; vn, ve, vd NED
#: velocity; fn, fe, fd NED specific force of the covariance step; fb[3] the same in body axes; wb[3] corrected body
#: rate; e[3][3] C_b^frame (the model's frame); g normal gravity; sig[6] GNSS sigmas vN vE vD pN pE pD;
#: rx, ry, rz the e-frame position and rr its length |r^e| [m] (for an ecef model; the others are then its
#: geodetic and NED equivalents); cfg the configuration struct (:mod:`modelgen.navigator.cconfig`).
QUANTITIES: dict[str, str] = {
    "latitude": "lat", "longitude": "lon", "height": "h",
    "position_x": "rx", "position_y": "ry", "position_z": "rz", "geocentric_radius": "rr",
    "meridian_radius": "rm", "prime_vertical_radius": "rn", "gravity": "g",
    "velocity_north": "vn", "velocity_east": "ve", "velocity_down": "vd", "velocity_up": "-vd",
    "specific_force_north": "fn", "specific_force_east": "fe", "specific_force_down": "fd", "specific_force_up": "-fd",
    **{f"body_specific_force_{a}": f"fb[{i}]" for i, a in enumerate("xyz")},
    **{f"body_rate_{a}": f"wb[{i}]" for i, a in enumerate("xyz")},
    **{f"c{i + 1}{j + 1}": f"e[{i}][{j}]" for i in range(3) for j in range(3)},
    **{f"lever_arm_{a}": f"cfg->lever_arm[{i}]" for i, a in enumerate("xyz")},
    "gyro_angle_random_walk": "cfg->gyro_white", "accel_velocity_random_walk": "cfg->accel_white",
    "gyro_bias_driving_noise": "cfg->gyro_bias_driving", "accel_bias_driving_noise": "cfg->accel_bias_driving",
    "gps_velocity_sigma_north": "sig[0]", "gps_velocity_sigma_east": "sig[1]", "gps_velocity_sigma_up": "sig[2]",
    "gps_position_sigma_north": "sig[3]", "gps_position_sigma_east": "sig[4]", "gps_position_sigma_up": "sig[5]",
    # one sigma for the three axes: only the model's R uses it, and the navigator's R is the per-axis sigmas
    "gnss_velocity_sigma": "sig[0]", "gnss_position_sigma": "sig[3]",
}


@dataclass(frozen=True)
class Block:
    """One block of error states: kind, state indices and, per state, its NED axis and sign (or body axis)."""

    kind: str
    indices: tuple[int, ...]
    axes: tuple[int, ...]  # NED (ECEF: e-frame) axis of navigation blocks or body axis 0..2 (sensor blocks)
    signs: tuple[float, ...]
    form: str = ""  # position: "metres" or "geodetic"

    def ned(self, x: np.ndarray) -> np.ndarray:
        """The block's vector in NED (or body) axes from the state vector."""
        out = np.zeros(3)
        for i, a, s in zip(self.indices, self.axes, self.signs):
            out[a] = s * x[i]
        return out


@dataclass(frozen=True)
class GnssRow:
    """One GNSS measurement row of the model: position or velocity, its NED (ECEF: e-frame) axis and sign."""

    kind: str  # "position" or "velocity"
    axis: int
    sign: float

    @property
    def sigma_index(self) -> int:
        """Index into the GNSS sigma vector vN vE vD pN pE pD."""
        return self.axis + (3 if self.kind == "position" else 0)


@dataclass
class NavigatorSpec:
    """Blocks, frame, measurement rows and parameter code of one derived navigation model."""

    model_file: Path
    derived: object  # modelgen.derivation.symbolic.DerivedModel
    name: str
    frame: str
    n_states: int
    blocks: dict[str, Block]
    gnss_rows: tuple[GnssRow, ...]
    parameter_names: tuple[str, ...]
    parameter_expressions: dict[str, str]  # the navigator's own (QUANTITIES)
    free_parameters: tuple[str, ...]  # set by the configuration's parameters: or the model's default
    defaults: dict[str, float]
    module: ModuleType | None = None
    #: the model's mechanization rates (modelgen.derivation.mechanization_rates), as Python and C source
    #: (modelgen.codegen.mechanization), and the Python one compiled (:func:`modelgen.navigator.mechanization.model_rates`)
    rates_python: str = ""
    rates_c: str = ""
    rates: object = None
    #: the carried states' indices (module docstring): an aiding sensor's own error, estimated but not fed back
    carried: tuple[int, ...] = ()
    _code: object = field(default=None, repr=False)

    @property
    def estimated_sensors(self) -> tuple[str, ...]:
        """The sensor-error blocks (SENSOR_BLOCKS) the model has states for: the others keep their value, 0."""
        return tuple(kind for kind in SENSOR_BLOCKS if kind in self.blocks)

    # -- frames ------------------------------------------------------------------------------
    @property
    def ecef(self) -> bool:
        """The model's mechanization is ecef: the navigation state is r^e, v^e, C_b^e (:mod:`modelgen.navigator.ecef`)."""
        return self.frame == "ECEF"

    @property
    def to_frame(self) -> np.ndarray:
        """The navigation state's frame (NED, or ECEF for an ecef model) -> the model's frame."""
        return NED_TO_ENU if self.frame == "ENU" else np.eye(3)

    def gnss_rotation(self, c_ne: np.ndarray) -> tuple[np.ndarray, list[int]]:
        """(T, sigma indices) turning the ecef model's e-frame GNSS rows into rows along NED (ECEF only).

        The receiver's sigmas are per NED axis: the rows z' = T z, H' = T H (T = C_e^n per kind, row by row of the
        model's rows) have the diagonal R of those sigmas, the same update as the e-frame rows with
        R^e = C_n^e R C_e^n.  Row i of T is the m-th row of its kind in the model's order, along NED axis m
        (:meth:`gnss_rotation_rows`).
        """
        along = self.gnss_rotation_rows()
        m = len(self.gnss_rows)
        T = np.zeros((m, m))
        for i, (axis, _) in enumerate(along):
            for j, other in enumerate(self.gnss_rows):
                if other.kind == self.gnss_rows[i].kind:
                    T[i, j] = c_ne[other.axis, axis] * other.sign
        return T, [sigma for _, sigma in along]

    def gnss_rotation_rows(self) -> list[tuple[int, int]]:
        """(NED axis, sigma index) of each turned GNSS row (:meth:`gnss_rotation`); the C's tables come from it."""
        order: dict[str, int] = {}
        out = []
        for row in self.gnss_rows:
            axis = order.get(row.kind, 0)
            order[row.kind] = axis + 1
            out.append((axis, axis + (3 if row.kind == "position" else 0)))
        if any(count != 3 for count in order.values()):
            raise ModelError(f"{self.model_file}: the ecef model's GNSS rows must be whole e-frame vectors "
                             "(three position and/or three velocity rows)")
        return out

    def check_config(self, config) -> None:
        """Refuse a configuration that lacks what this model needs (scale-factor sigmas, free parameters)."""
        for kind in ("gyro_scale_factor", "accel_scale_factor"):
            if kind in self.blocks and getattr(config, f"{kind}_sigma", None) is None:
                raise ModelError(f"{key_place(config.path, f'initial.{kind}_sigma_ppm')}: model {self.name} has {kind.replace('_', ' ')} states: give "
                                 f"initial.{kind}_sigma_ppm")
        self.free_values(config)

    # -- parameters --------------------------------------------------------------------------
    def free_values(self, config) -> list[float]:
        """Values of the free parameters (configuration's parameters:, else the model's default); refused if unset."""
        given = dict(getattr(config, "parameters", None) or {})
        unknown = sorted(set(given) - set(self.parameter_names))
        if unknown:
            raise ModelError(f"{key_place(config.path, f'parameters.{unknown[0]}')}: parameters: {', '.join(unknown)} is not a parameter of model {self.name} "
                             f"(its parameters: {', '.join(self.parameter_names)})")
        owned = sorted(set(given) & set(self.parameter_expressions))
        if owned:
            raise ModelError(f"{key_place(config.path, f'parameters.{owned[0]}')}: parameters: {', '.join(owned)} is set by the navigator at every step "
                             "(operating point, noise, GNSS sigma or lever arm keys); it cannot be fixed here")
        missing = [p for p in self.free_parameters if p not in given and p not in self.defaults]
        if missing:
            raise ModelError(f"{key_place(config.path, 'parameters')}: model {self.name} needs parameters the navigator does not set: "
                             f"{', '.join(missing)} (give them under parameters:, in the model's units)")
        return [float(given.get(p, self.defaults.get(p, 0.0))) for p in self.free_parameters]

    def parameter_vector(self, quantities: dict) -> np.ndarray:
        """The model's parameter vector from the navigator's quantities (QUANTITIES; cfg with .parameters)."""
        if self._code is None:
            items = []
            for name in self.parameter_names:
                if name in self.parameter_expressions:
                    items.append(self.parameter_expressions[name].replace("->", "."))
                else:
                    items.append(f"cfg.parameters[{self.free_parameters.index(name)}]")
            self._code = compile("(" + ", ".join(items) + ",)", f"<{self.name} parameters>", "eval")
        return np.array(eval(self._code, {"__builtins__": {}}, quantities), float)  # noqa: S307 - our own table

    # -- P0, feedback ------------------------------------------------------------------------
    def initial_covariance(self, config, nav: np.ndarray, heading_sigma: float, radii) -> np.ndarray:
        """P0 (diagonal) from the configuration's sigmas per block, in the blocks' own units."""
        if self.ecef:
            return self._initial_covariance_ecef(config, nav, heading_sigma)
        rm, rn = radii(nav[7])
        sigma = np.zeros(self.n_states)
        att = self.blocks["attitude"]
        for i, a in zip(att.indices, att.axes):
            sigma[i] = heading_sigma if a == 2 else config.roll_pitch_sigma
        for i in self.blocks["velocity"].indices:
            sigma[i] = config.velocity_sigma
        pos = self.blocks["position"]
        for i, a in zip(pos.indices, pos.axes):
            s = config.height_sigma if a == 2 else config.position_sigma
            if pos.form == "geodetic" and a == 0:
                s /= rm + nav[9]
            elif pos.form == "geodetic" and a == 1:
                s /= (rn + nav[9]) * math.cos(nav[7])
            sigma[i] = s
        per_sensor = {"gyro_bias": config.gyro_bias_sigma, "accel_bias": config.accel_bias_sigma,
                      "gyro_scale_factor": config.gyro_scale_factor_sigma,
                      "accel_scale_factor": config.accel_scale_factor_sigma}
        for kind in SENSOR_BLOCKS:
            if kind in self.blocks:
                for i in self.blocks[kind].indices:
                    sigma[i] = per_sensor[kind]
        return np.diag(np.square(sigma))

    def _initial_covariance_ecef(self, config, nav: np.ndarray, heading_sigma: float) -> np.ndarray:
        """P0 of an ecef model: the per-NED-axis sigmas of the attitude, velocity and position rotated into e-frame axes."""
        from modelgen.navigator.ecef import geodetic, ned_to_ecef

        c_ne = ned_to_ecef(*geodetic(nav[7:10])[:2])
        ned = {"attitude": (config.roll_pitch_sigma, config.roll_pitch_sigma, heading_sigma),
               "velocity": (config.velocity_sigma,) * 3,
               "position": (config.position_sigma, config.position_sigma, config.height_sigma)}
        P = np.zeros((self.n_states, self.n_states))
        for kind, sigmas in ned.items():
            block = self.blocks[kind]
            rotated = c_ne @ np.diag(np.square(sigmas)) @ c_ne.T
            for r, (i, a, s) in enumerate(zip(block.indices, block.axes, block.signs)):
                for j, b, t in zip(block.indices, block.axes, block.signs):
                    P[i, j] = s * t * rotated[a, b]
        per_sensor = {"gyro_bias": config.gyro_bias_sigma, "accel_bias": config.accel_bias_sigma,
                      "gyro_scale_factor": config.gyro_scale_factor_sigma,
                      "accel_scale_factor": config.accel_scale_factor_sigma}
        for kind in SENSOR_BLOCKS:
            if kind in self.blocks:
                for i in self.blocks[kind].indices:
                    P[i, i] = per_sensor[kind] ** 2
        return P

    def feedback(self, nav: np.ndarray, x: np.ndarray, sensors: dict[str, np.ndarray], radii, rotate) -> None:
        """Correct the navigation state and the sensor estimates with x (in place); the caller zeroes x.

        ``rotate(nav, phi_ned)``: C_b^n = exp([phi x]) C_b^n' on the quaternion.
        """
        rotate(nav, self.blocks["attitude"].ned(x))
        nav[4:7] -= self.blocks["velocity"].ned(x)
        pos = self.blocks["position"]
        d = pos.ned(x)  # geodetic: (dL, dlambda, -dh)
        if self.ecef:  # r^e -= dr^e
            nav[7:10] -= d
            d = np.zeros(3)
        elif pos.form == "geodetic":
            nav[7] -= d[0]
            nav[8] -= d[1]
        else:
            rm, rn = radii(nav[7])
            nav[7] -= d[0] / (rm + nav[9])
            nav[8] -= d[1] / ((rn + nav[9]) * math.cos(nav[7]))
        nav[9] += d[2]
        for kind in SENSOR_BLOCKS:
            if kind in self.blocks:
                sensors[kind] += self.blocks[kind].ned(x)
        if self.carried:
            sensors["carried"] += x[list(self.carried)]

    # -- carried states ----------------------------------------------------------------------
    def carried_covariance(self, P: np.ndarray, p: np.ndarray) -> np.ndarray:
        """P0 with the carried states' steady-state variances Q_ii / (2 a_i) (F_ii = -a_i, Q = G diag(q) G^T).

        Refused if a carried state's process is not stable at these parameters (a random constant or walk has no
        steady state to start from)."""
        if not self.carried:
            return P
        g = self.module
        F, G, q = g.system_matrix(p), g.noise_input_matrix(p), np.asarray(g.noise_psd(p), float)
        P = P.copy()
        names = self.derived.model.state_names
        for i in self.carried:
            a = -float(F[i, i])
            if not a > 0.0:
                at = self.derived.model.states[i].place("dynamics") or self.model_file  # the line of its process
                raise ModelError(f"{at}: state {names[i]!r} (an aiding sensor's own error) has no steady "
                                 f"state to start from (d/dt = {-a:g} x): declare it gauss_markov with a positive rate")
            P[i, i] = float(np.sum(np.square(G[i]) * q)) / (2.0 * a)
        return P

    def propagate_carried(self, sensors: dict[str, np.ndarray], Phi: np.ndarray) -> None:
        """The carried estimate over a covariance step: e <- Phi_cc e (the model's own transition, in place)."""
        if self.carried:
            c = list(self.carried)
            sensors["carried"][:] = Phi[np.ix_(c, c)] @ sensors["carried"]

    def carried_correction(self, H: np.ndarray, sensors: dict[str, np.ndarray]) -> np.ndarray:
        """What the carried estimate adds to the rows' differences: H_c e (z - H_c e is the update's z)."""
        if not self.carried:
            return np.zeros(len(H))
        return H[:, list(self.carried)] @ sensors["carried"]

    # -- measurement rows --------------------------------------------------------------------
    def zupt_rows(self, v_ned: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """z = the velocity (the error when the truth is zero) and H picking the velocity block."""
        vel = self.blocks["velocity"]
        H = np.zeros((3, self.n_states))
        z = np.zeros(3)
        for r, (i, a, s) in enumerate(zip(vel.indices, vel.axes, vel.signs)):
            H[r, i] = 1.0
            z[r] = s * v_ned[a]
        return z, H

    def nhc_rows(self, c_bn: np.ndarray, v_ned: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """z = body lateral and vertical velocity; H = [-C_n^b [v x], C_n^b] on the attitude and velocity blocks."""
        c_nb = c_bn.T
        skew = np.array([[0.0, -v_ned[2], v_ned[1]], [v_ned[2], 0.0, -v_ned[0]], [-v_ned[1], v_ned[0], 0.0]])
        attitude, velocity = -(c_nb @ skew)[1:3], c_nb[1:3]
        H = np.zeros((2, self.n_states))
        for block, rows in ((self.blocks["attitude"], attitude), (self.blocks["velocity"], velocity)):
            for i, a, s in zip(block.indices, block.axes, block.signs):
                H[:, i] = s * rows[:, a]
        return (c_nb @ v_ned)[1:3], H

    def gnss_z(self, dv_ned: np.ndarray, dp_ned: np.ndarray, sig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """z (INS minus GNSS along each model row) and R's diagonal from the per-axis sigmas vN vE vD pN pE pD."""
        z = np.array([r.sign * (dp_ned if r.kind == "position" else dv_ned)[r.axis] for r in self.gnss_rows])
        return z, np.array([sig[r.sigma_index] ** 2 for r in self.gnss_rows])

    def position_output(self, P: np.ndarray, nav: np.ndarray, radii) -> tuple[float, ...]:
        """sigma north, east, up [m] and covariances north-east, east-up, up-north [m^2] from P's position block."""
        pos = self.blocks["position"]
        if self.ecef:
            from modelgen.navigator.ecef import covariance_to_ned, geodetic, ned_to_ecef

            block = np.array([[pos.signs[r] * pos.signs[c] * P[pos.indices[r], pos.indices[c]] for c in range(3)]
                              for r in range(3)])
            order = np.argsort(pos.axes)  # rows by e-frame axis
            ned = covariance_to_ned(block[np.ix_(order, order)], ned_to_ecef(*geodetic(nav[7:10])[:2]))
            return (math.sqrt(max(ned[0, 0], 0.0)), math.sqrt(max(ned[1, 1], 0.0)), math.sqrt(max(ned[2, 2], 0.0)),
                    ned[0, 1], -ned[1, 2], -ned[2, 0])
        rm, rn = radii(nav[7])
        scale = [1.0, 1.0, 1.0]
        if pos.form == "geodetic":
            scale = [rm + nav[9], (rn + nav[9]) * math.cos(nav[7]), 1.0]
        index, factor = [0, 0, 0], [0.0, 0.0, 0.0]  # per north, east, up: the state and its factor to metres
        for i, a, s in zip(pos.indices, pos.axes, pos.signs):
            index[a] = i
            factor[a] = s * scale[a] * (-1.0 if a == 2 else 1.0)  # the third output axis is up
        n, e, u = index
        fn_, fe_, fu_ = factor
        return (math.sqrt(max(P[n, n], 0.0)) * abs(fn_), math.sqrt(max(P[e, e], 0.0)) * abs(fe_),
                math.sqrt(max(P[u, u], 0.0)) * abs(fu_), P[n, e] * fn_ * fe_, P[e, u] * fe_ * fu_, P[u, n] * fu_ * fn_)


def _blocks(names: list[str], frame: str, where: str, places: Sequence[str] = ()) -> dict[str, Block]:
    """The navigation and sensor error blocks by the states' names; ``places``: each state's file:line, if known."""
    words = FRAME_AXES[frame]
    found: dict[str, list[tuple[int, int, float]]] = {}
    forms: dict[str, str] = {}
    for index, name in enumerate(names):
        if name in _GEODETIC:
            axis, sign = AXES[_GEODETIC[name]]
            found.setdefault("position", []).append((index, axis, sign))
            forms["position_geodetic"] = "geodetic"
            continue
        for kind, pattern in _PATTERNS.items():
            m = pattern.match(name)
            if m:
                word = m.group(1)
                if kind in ("attitude", "velocity", "position") and word not in words:
                    at = places[index] if index < len(places) and places[index] else where
                    raise ModelError(f"{at}: state {name!r}: a model in the {frame} frame names its navigation "
                                     f"error axes {', '.join(words)}")
                axis, sign = AXES[word] if kind in ("attitude", "velocity", "position") else ("xyz".index(word), 1.0)
                found.setdefault(kind, []).append((index, axis, sign))
                if kind == "position":
                    forms["position_metres"] = "metres"
                break
    if len(forms) > 1:
        raise ModelError(f"{where}: the position error states mix metres and latitude/longitude/height errors")
    missing = [k for k in ("attitude", "velocity", "position") if len(found.get(k, [])) != 3]
    if missing:
        raise ModelError(f"{where}: the navigator cannot fly this model: it has no complete {', '.join(missing)} "
                         "error block (three states named as the navigation: section names them, e.g. "
                         "velocity_error_north/east/down); write the model with a navigation: section")
    blocks = {}
    for kind, entries in found.items():
        axes = sorted(a for _, a, _ in entries)
        if len(entries) != 3 or axes != [0, 1, 2]:
            raise ModelError(f"{where}: the {kind} error block must have one state per axis "
                             f"(got {[names[i] for i, _, _ in entries]})")
        form = next(iter(forms.values())) if kind == "position" else ""
        blocks[kind] = Block(kind, tuple(i for i, _, _ in entries), tuple(a for _, a, _ in entries),
                             tuple(s for _, _, s in entries), form)
    return blocks


def _gnss_rows(derived, blocks: dict[str, Block], where: str) -> tuple[GnssRow, ...]:
    model = derived.model
    H = derived.H  # the model's own symbolic H, tidied by the derivation (an entry that cancels is 0 there)
    rows = []
    for r, name in enumerate(model.measurement_names):
        # is_identically_zero screens at two generic points before any symbolic proof: sympy's simplify of each of
        # the 21-state model's 126 entries took 14 s, and found no zero the derivation had not already made 0
        depends = {i for i in range(H.shape[1]) if not is_identically_zero(H[r, i])}
        found = None
        for kind in ("velocity", "position"):
            hits = [(i, a, s) for i, a, s in zip(blocks[kind].indices, blocks[kind].axes, blocks[kind].signs)
                    if i in depends]
            if len(hits) == 1:
                # z along the row is the block's sign times H's: a row written measured minus computed, or along
                # an axis of the other sense (up in an NED model), has H = -1 and takes GNSS minus INS
                found = GnssRow(kind, hits[0][1], hits[0][2] * _sign_at_rest(model, H[r, hits[0][0]]))
                break
        if found is None:
            several = {kind: [model.state_names[i] for i in blocks[kind].indices if i in depends]
                       for kind in ("velocity", "position")}
            several = {kind: states for kind, states in several.items() if len(states) > 1}
            detail = ""
            if several:
                kind, states = next(iter(several.items()))
                detail = (f"; it depends on {len(states)} {kind} error states ({', '.join(states)})"
                          + ("; a GNSS lever arm's exact O(l/R) terms do that: declare approximations: "
                             "[lever_arm_at_computed_position] in the navigation: section"
                             if kind == "position" else ""))
            raise ModelError(f"{model.measurements[r].place() or where}: measurement {name!r} is neither a position nor a velocity difference "
                             f"along one axis: the navigator's GNSS update cannot fill it{detail}")
        _check_row_unit(model.measurements[r], found, where)
        rows.append(found)
    return tuple(rows)


def _check_row_unit(measurement, row: GnssRow, where: str) -> None:
    """Refuse a GNSS row in another unit than the navigator's differences: metres, metres per second (SI, factor 1).

    The navigator fills every row with INS minus GNSS in metres (m/s) and R with the receiver's sigmas in metres:
    a geodetic position measurement (``form: geodetic``, latitude and longitude in rad) was filled so, silently,
    a metre taken for a radian."""
    from modelgen.model.units import parse_unit

    unit = getattr(measurement, "unit", None)
    if not unit:
        return  # undeclared: not checked (a model without units)
    wanted = "m" if row.kind == "position" else "m/s"
    try:
        parsed, target = parse_unit(unit), parse_unit(wanted)
    except ModelError:
        return  # the loader has checked the unit
    if parsed.dimension != target.dimension or not math.isclose(parsed.factor, 1.0, rel_tol=1e-12):
        raise ModelError(f"{measurement.place() or where}: measurement {measurement.name!r} is in {unit}: the "
                         f"navigator's GNSS update fills {row.kind} rows with INS minus GNSS in {wanted} (R from the "
                         f"receiver's sigmas in {wanted}); write it in {wanted}"
                         + (" (form: metres)" if row.kind == "position" else ""))


#: Parameter values of a vehicle at rest, level, north, at 40 deg N (lever arms, rates, forces 0 but gravity), for
#: the sign of an H entry whose terms beyond the leading one are lever-arm and rate terms.
_AT_REST = {"latitude": 0.7, "height": 100.0, "meridian_radius": 6.36e6, "prime_vertical_radius": 6.39e6,
            "earth_radius": 6.37e6, "geocentric_radius": 6.37e6, "gravity": 9.8, "earth_rate": 7.29e-5,
            "c11": 1.0, "c22": 1.0, "c33": 1.0, "body_specific_force_z": -9.8, "specific_force_down": -9.8}


def _sign_at_rest(model, entry) -> float:
    """+1 or -1: the sign of the GNSS row's H entry on its state, at rest (:data:`_AT_REST`; any other symbol 0,
    a model default where there is one), where it is its leading term (1, -1, or a geodetic position's metres)."""
    import sympy as sp

    by_symbol = {p.symbol: p for p in model.parameters}
    point = {}
    for symbol in entry.free_symbols:
        p = by_symbol.get(str(symbol))
        name = p.name if p is not None else str(symbol)
        value = _AT_REST.get(name, p.value if p is not None and p.value is not None and name not in QUANTITIES else 0.0)
        point[symbol] = sp.Float(float(value))
    value = float(sp.sympify(entry).xreplace(point).evalf())
    if not math.isfinite(value) or value == 0.0:
        return 1.0  # no sign to read at rest: the block's own, as before
    return 1.0 if value > 0 else -1.0


def _carried(derived, blocks: dict[str, Block], where: str) -> tuple[int, ...]:
    """The states outside every block: an aiding sensor's own error (module docstring), else refused.

    Such a state must be decoupled from the others -- its rate depends on itself alone and no other state's rate
    on it (F_ij = F_ji = 0, j != i), driven by its own noises only -- and must enter at least one GNSS row, so that
    the navigator can carry its estimate (propagated by F_ii, subtracted in the GNSS rows) instead of feeding it
    back.  The navigation notation makes ``measurements: - bias:`` states so."""
    names = list(derived.model.state_names)
    inside = {i for b in blocks.values() for i in b.indices}
    F, G, H = derived.F, derived.G, derived.H
    out = []
    for i, name in enumerate(names):
        if i in inside:
            continue
        coupled = [names[j] for j in range(len(names)) if j != i and (F[i, j] != 0 or F[j, i] != 0)]
        shared = [k for k in range(G.shape[1]) if G[i, k] != 0 and any(G[j, k] != 0 for j in range(len(names)) if j != i)]
        if coupled or shared or all(H[r, i] == 0 for r in range(H.shape[0])):
            raise ModelError(f"{derived.model.states[i].place() or where}: the navigator cannot fly state {name!r}: it is neither a navigation or sensor "
                             "error block state nor an aiding sensor's own error (a measurement's bias: that enters "
                             "the GNSS rows and is coupled to no other state"
                             + (f"; it is coupled to {', '.join(coupled)}" if coupled else "") + ")")
        out.append(i)
    return tuple(out)


def navigator_spec(model_file: Path, with_python: bool = True) -> NavigatorSpec:
    """Derive the model file once and read the navigator's spec from it (and the generated Python filter)."""
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model

    model_file = Path(model_file)
    derived = derive(load_model(model_file))
    return spec_of(derived, model_file, with_python)


def spec_of(derived, model_file: Path, with_python: bool = True) -> NavigatorSpec:
    """The spec of a derived model (and its generated Python filter, imported, if ``with_python``)."""
    model = derived.model
    where = str(model_file)
    frame = str(model.frame or "").upper()
    if frame not in ("NED", "ENU", "ECEF"):
        raise ModelError(f"{_line_of(model_file, ('frame', 'navigation.mechanization'))}: the navigator flies models in "
                         f"the NED, ENU or ECEF frame (model {model.name} declares {model.frame or 'no frame'})")
    _check_forms(model_file)
    names = list(model.state_names)
    blocks = _blocks(names, frame, where, [s.place() for s in model.states])
    rows = _gnss_rows(derived, blocks, where)
    parameter_names = tuple(model.parameter_names)
    defaults = {k: float(v) for k, v in model.parameter_defaults().items()}
    expressions = {p: QUANTITIES[p] for p in parameter_names if p in QUANTITIES and p not in defaults}
    free = tuple(p for p in parameter_names if p not in expressions)
    _check_imu_noises(model, expressions, model_file)
    _check_bias_driving_noises(derived, blocks, expressions, model_file)
    rates = _rates(model, model_file)
    if frame == "ECEF":
        _check_ecef(model_file, blocks, rows)
    carried = _carried(derived, blocks, where)
    spec = NavigatorSpec(model_file, derived, model.name, frame, len(names), blocks, rows, parameter_names,
                         expressions, free, defaults, rates_python=python_source(rates), rates_c=c_source(rates),
                         carried=carried)
    if with_python:
        from modelgen.navigator.mechanization import shared_model_rates

        spec.module = _python_module(derived)
        spec.rates = shared_model_rates(spec.rates_python, model.name)
    return spec


#: The IMU white noises of a navigation: section and the parameter through which the navigator sets each from the
#: configuration (QUANTITIES): (sensor attribute of the navigation problem, its key under navigation.noises, the
#: parameter, its unit, the configuration's key).
_IMU_NOISES = (("gyro", "gyro", "gyro_angle_random_walk", "rad/sqrt(s)", "noise.gyro_white"),
               ("accelerometer", "accel", "accel_velocity_random_walk", "m/s/sqrt(s)", "noise.accel_white"))


def _unreachable(psd, parameter: str, symbols: dict[str, str], expressions: dict[str, str]) -> str | None:
    """Why the configuration cannot set a noise whose PSD is ``psd`` through ``parameter``, or None when it can: the
    PSD uses the parameter and the parameter has no default (the navigator sets only parameters without one)."""
    wanted = symbols.get(parameter) if parameter in expressions else None
    if wanted is not None and wanted in {str(s) for s in getattr(psd, "free_symbols", ())}:
        return None
    if parameter in symbols and parameter not in expressions:
        return f"its parameter {parameter} has a default value, which the navigator then leaves as it is"
    return f"its PSD {psd} does not use the parameter {parameter}"


def _check_imu_noises(model, expressions: dict[str, str], model_file: Path) -> None:
    """Refuse a navigation: section whose IMU white noise the configuration's ``noise`` cannot reach.

    The navigator sets the gyro and accelerometer white noises at every step through the parameters named
    ``gyro_angle_random_walk`` and ``accel_velocity_random_walk`` (declared without a value). A PSD written with
    another parameter, or with one of these that has a default, kept the model file's value silently while the
    summary reported the configuration's ``noise.gyro_white`` as the value used."""
    problem = getattr(model, "navigation", None)
    if problem is None:
        return  # a model written as equations names its noises itself (ins_gps15_nav)
    symbols = {p.name: p.symbol for p in model.parameters}
    psd_of = {n.symbol: (n.name, model.noise_psd.get(n.name)) for n in model.noises}
    for attribute, key, parameter, unit, config_key in _IMU_NOISES:
        sensor = getattr(problem, attribute, None)
        noise = getattr(sensor, "noise", None)
        if noise is None:
            continue
        for symbol in noise:
            name, psd = psd_of.get(str(symbol), (str(symbol), None))
            why = _unreachable(psd, parameter, symbols, expressions)
            if why is None:
                continue
            raise ModelError(f"{_line_of(model_file, (f'navigation.noises.{key}', 'navigation.noises', 'navigation'))}: "
                             f"white noise {name}: {why}; the navigator sets this noise from the configuration's "
                             f"{config_key} only through a parameter {parameter} [{unit}] declared without a value "
                             f"(the filter would keep the model file's noise while the summary reports {config_key})")


def _check_bias_driving_noises(derived, blocks: dict[str, Block], expressions: dict[str, str], model_file: Path) -> None:
    """Refuse a random-walk gyro or accelerometer bias whose driving noise ``noise.gyro_bias_driving`` /
    ``noise.accel_bias_driving`` cannot reach: its PSD must use ``gyro_bias_driving_noise`` /
    ``accel_bias_driving_noise``, declared without a value (as :func:`_check_imu_noises`). A Gauss-Markov bias
    (F_ii != 0) takes its rate and sigma from the model, and a random constant has no noise: neither is asked."""
    model = derived.model
    if getattr(model, "navigation", None) is None:
        return
    symbols = {p.name: p.symbol for p in model.parameters}
    F, G = derived.F, derived.G
    for kind, parameter, unit, config_key in (
            ("gyro_bias", "gyro_bias_driving_noise", "rad/s/sqrt(s)", "noise.gyro_bias_driving"),
            ("accel_bias", "accel_bias_driving_noise", "m/s^2/sqrt(s)", "noise.accel_bias_driving")):
        for i in (blocks[kind].indices if kind in blocks else ()):
            if F[i, i] != 0:
                continue
            for k in range(G.shape[1]):
                if G[i, k] == 0:
                    continue
                noise = model.noises[k]
                why = _unreachable(model.noise_psd.get(noise.name), parameter, symbols, expressions)
                if why is None:
                    continue
                at = noise.place("psd") or model.states[i].place() or _line_of(model_file, ("navigation.sensor_errors",))
                raise ModelError(f"{at}: random-walk driving noise {noise.name} of {model.states[i].name}: {why}; "
                                 f"the navigator sets it from the configuration's {config_key} only through a "
                                 f"parameter {parameter} [{unit}] declared without a value (the filter would keep the "
                                 f"model file's noise while the summary reports {config_key})")


def _rates(model, model_file: Path):
    """The model's own mechanization rates (one source with its error model), refusals naming the line of the model
    file's key that says why (its velocity equation, its mechanization ...), else the file."""
    try:
        return mechanization_rates(model)
    except RatesRefused as exc:
        raise ModelError(f"{_line_of(model_file, exc.keys)}: {exc}") from None
    except ModelError as exc:
        raise ModelError(f"{model_file}: {exc}") from None


def _line_of(model_file: Path, keys: Sequence[str]) -> str:
    """``file:line`` of the first of ``keys`` (dotted) the model file has, else the file's name."""
    from modelgen.fileio.datafiles import read_yaml_with_lines

    try:
        _, lines = read_yaml_with_lines(model_file, "model file")
    except ModelError:
        return str(model_file)  # the loader has read it already; nothing more to say here
    return next((lines[k] for k in keys if lines.get(k)), str(model_file))


def _check_ecef(model_file: Path, blocks: dict[str, Block], rows: tuple[GnssRow, ...]) -> None:
    """What the navigator needs of an ecef model, refused at the line of the model file that lacks it.

    It flies r^e, so the position error must be e-frame metres; its GNSS update turns the e-frame rows along NED
    (:meth:`NavigatorSpec.gnss_rotation`), so the measurements must be whole e-frame vectors: three position and/or
    three velocity rows, and at least one of them.
    """
    from modelgen.fileio.datafiles import read_yaml_with_lines

    _, lines = read_yaml_with_lines(model_file, "model file")
    here = lines.get("navigation", str(model_file))
    if blocks["position"].form != "metres":
        where = lines.get("navigation.errors.position", here)
        raise ModelError(f"{where}: an ecef model's position error must be e-frame metres (form: metres, states "
                         "position_error_x/y/z): the navigator flies r^e")
    counts = {kind: sum(r.kind == kind for r in rows) for kind in ("position", "velocity")}
    if not rows or any(c not in (0, 3) for c in counts.values()):
        where = lines.get("navigation.measurements", here)
        raise ModelError(f"{where}: the navigator's GNSS update of an ecef model needs its measurements as whole "
                         "e-frame vectors: three position and/or three velocity rows, INS minus GNSS (this model: "
                         f"{counts['position']} position, {counts['velocity']} velocity)")


def _check_forms(model_file: Path) -> None:
    """The error forms the feedback implements: attitude phi, velocity difference (a navigation: section's)."""
    import yaml

    try:
        data = yaml.safe_load(Path(model_file).read_text())
    except (OSError, yaml.YAMLError):
        return  # the loader has already read it; nothing more to say here
    section = data.get("navigation") if isinstance(data, dict) else None
    if not isinstance(section, dict):
        return
    errors = section.get("errors") or {}
    attitude = (errors.get("attitude") or {}).get("form", "phi") if isinstance(errors, dict) else "phi"
    velocity = (errors.get("velocity") or {}).get("form", "difference") if isinstance(errors, dict) else "difference"
    if attitude != "phi" or velocity != "difference":
        keys = ("navigation.errors.attitude.form",) if attitude != "phi" else ("navigation.errors.velocity.form",)
        raise ModelError(f"{_line_of(model_file, (*keys, 'navigation.errors', 'navigation'))}: the navigator feeds back phi-angle attitude errors and velocity "
                         f"differences (navigation.errors: attitude {attitude!r}, velocity {velocity!r})")


def _python_module(derived) -> ModuleType:
    """Generate the derived model's Python filter with modelgen's generator and import it."""
    import tempfile

    from modelgen.codegen.build import load_python_module
    from modelgen.codegen.generate import generate_code
    from modelgen.fileio.output import write_atomically

    name = derived.model.name
    with tempfile.TemporaryDirectory(prefix="modelgen-replay-") as temporary:  # an imported module needs no file
        write_atomically(Path(temporary) / name, generate_code(derived).files)
        return load_python_module(Path(temporary) / name / f"{name}.py")


def quantities(spec: NavigatorSpec, nav: np.ndarray, c_bn: np.ndarray, force_ned: np.ndarray,
               rate_body: np.ndarray, sig: np.ndarray, cfg: SimpleNamespace, radii, gravity) -> dict:
    """The navigator's quantities at the navigation state (the names QUANTITIES' expressions use).

    ``c_bn``, ``force_ned``: the attitude matrix and the specific force in the navigation state's frame (C_b^e, f^e
    for an ecef model: lat, lon, h, vn, ve, vd, fn, fe, fd are then their geodetic and NED equivalents).
    """
    fb = c_bn.T @ force_ned
    if spec.ecef:
        from modelgen.navigator.ecef import geodetic, ned_to_ecef

        lat, lon, h = geodetic(nav[7:10])
        c_en = ned_to_ecef(lat, lon).T
        v, f = c_en @ nav[4:7], c_en @ force_ned
        rm, rn = radii(lat)
        r = nav[7:10]
        return {"lat": lat, "lon": lon, "h": h, "rm": rm, "rn": rn, "g": gravity(lat, h),
                "vn": v[0], "ve": v[1], "vd": v[2], "fn": f[0], "fe": f[1], "fd": f[2], "fb": fb, "wb": rate_body,
                "e": c_bn, "sig": sig, "cfg": cfg, "rx": r[0], "ry": r[1], "rz": r[2],
                "rr": math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])}
    lat, h = nav[7], nav[9]
    rm, rn = radii(lat)
    return {"lat": lat, "lon": nav[8], "h": h, "rm": rm, "rn": rn, "g": gravity(lat, h),
            "vn": nav[4], "ve": nav[5], "vd": nav[6], "fn": force_ned[0], "fe": force_ned[1], "fd": force_ned[2],
            "fb": fb, "wb": rate_body, "e": spec.to_frame @ c_bn, "sig": sig, "cfg": cfg, "rx": 0.0, "ry": 0.0,
            "rz": 0.0, "rr": 0.0}
