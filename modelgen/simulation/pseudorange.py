"""Pseudo-range aiding (the accumulated-correction paper): the simulated INS against the 11-state model.

:data:`PSEUDORANGE` is the pseudo-range receiver's aiding-sensor plug-in
(profile section ``pseudorange`` with its ``constellation``, ``filter.aiding:
pseudorange``).  :class:`PseudorangeNavigator`, its measurement function,
implements the Navigator protocol of :mod:`modelgen.simulation.filter_loop` for the accumulated-correction paper's INS/GPS pseudo-range
model (``gps_pseudorange11``, ``modelgen.model.pseudorange.pseudorange_model(n)``):
the same :class:`~modelgen.simulation.strapdown.Strapdown` mechanization as
the Doppler/GPS navigator, plus a receiver-clock estimate, with the errors
mapped explicitly onto the model's states (its header fixes them):

* position error dr = r_INS - r_true in METRES, East-North-Up, in the true
  local-level frame: (dlon (R_N + h) cos L, dlat (R_M + h), dh);
* velocity error dv = C_c^t v_INS - v_true, ENU, both resolved in the true
  frame t: the INS's velocity components are taken in its own local-level
  frame c (defined below), C_c^t = I + dtheta x.  Only with this resolution
  does the model's d(dr)/dt = -w_en x dr + dv hold: an INS displaced east
  and flying east with the true velocity in its own frame keeps its height
  error, and C_c^t v_INS has the up component -v_E dr_E / R that cancels
  the -w_en x dr term (v_E dr_E / R = 0.026 m/s for 2 km at 83 m/s; the
  naive v_INS - v_true fails the mechanization check of the tests);
* attitude: the psi-angle.  Three frames: t (local level at the true
  position), c (local level at the INS position), p (the frame the INS takes
  for local level, C_b^p = its attitude matrix).  The simulation measures the
  phi-angle C_b^p = (I - phi x) C_b^t (``rotation.misalignment``).  c is t
  turned by dtheta: moving north by dlat turns the frame about east by
  -dlat (the up axis leans north, i.e. turns by a negative angle about east),
  moving east by dlon turns it about the polar axis (0, cos L, sin L) by dlon,
  so dtheta = (-dlat, dlon cos L, dlon sin L) and C_t^c = I - dtheta x.  With
  C_b^p = (I - psi x) C_b^c = (I - psi x)(I - dtheta x) C_b^t the psi-angle is
      psi = phi - dtheta,
  the model header's phi = psi + (-dr_N/R, dr_E/R, dr_E tan L/R).  (Check: an
  INS 1 km north of the truth with a numerically true attitude matrix has
  phi = 0, psi = (dlat, 0, 0) and, in the model, d(dv_N)/dt = f_U psi_E -
  g/R dr_N = 0 -- as it must, since it sees gravity exactly along its own
  vertical; the opposite sign would give 2 g dr_N / R.  The test file checks
  this against the mechanization.)
* clock: the states are the receiver clock bias and drift ranges not yet
  accounted for by the navigator's own clock estimate (b^, d^), which it
  carries as b^' = d^ (zero, and never corrected, in open-loop and
  accumulated modes): I_t = b - b^, I_f = d - d^.

Measurement each pseudo-range epoch (the accumulated-correction paper eqs. (3), (7), (8)): the n
visible satellites of highest elevation seen from the INS position (n = the
model's satellite count), z_k = rho_k - b^_c - |r_s,k - r_c|, with r_c the
corrected INS position and b^_c the clock estimate of the output the
filter loop hands in: raw in closed loop (the clock is fed back), corrected
by the accumulator in accumulated mode (eq. (3)).  The line-of-sight unit
vectors e_k (ENU, receiver to satellite) of that epoch go to the model
through :meth:`PseudorangeNavigator.parameters`, so H is evaluated per epoch.

The vertical channel is the profile's (``altitude_reference``); profile_003
flies it free, as the model assumes: no barometer, the pseudo-ranges bound it.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.error_layout import frame_matrix
from modelgen.simulation.aiding import (
    FilterMaker,
    Progress,
    SensorData,
    measurement_function,
    operating_point,
    samples_per_cycle,
    whole_ratio,
)
from modelgen.simulation.error_layout import ErrorLayout
from modelgen.simulation.filter_loop import FilterLoop, Measurement, RunResult
from modelgen.simulation.filters import named_parameters
from modelgen.simulation.gps import Constellation, PseudorangeRecord, PseudorangeSettings, simulate_pseudoranges
from modelgen.simulation.profile_keys import DEG, ProfileSection
from modelgen.simulation.rotation import misalignment, rotate_attitude
from modelgen.simulation.strapdown import Strapdown
from modelgen.simulation.trajectory import Trajectory

if TYPE_CHECKING:  # sympy-based, named in annotations only: a run of the compiled loop imports no sympy
    from modelgen.derivation.symbolic import DerivedModel

#: the model's states, in the order the navigator maps them (pseudorange_model(n), gps_pseudorange11)
STATE_NAMES = (
    "position_error_east", "position_error_north", "position_error_up",
    "velocity_error_east", "velocity_error_north", "velocity_error_up",
    "attitude_error_east", "attitude_error_north", "attitude_error_up",
    "clock_bias_range", "clock_drift_range",
)
ENU_FROM_NED = frame_matrix("ENU")  # its own inverse
CLOCK_BIAS, CLOCK_DRIFT = 10, 11  # output columns after lat, lon, h, v_NED, q_b^n


def frame_rotation(latitude: float, delta_latitude: float, delta_longitude: float) -> np.ndarray:
    """dtheta (ENU): rotation of the local-level frame when the position moves by (dlat, dlon)."""
    return np.array([-delta_latitude, delta_longitude * math.cos(latitude), delta_longitude * math.sin(latitude)])


def navigation_error_states(nav: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(dr_ENU [m], dv_ENU [m/s], psi_ENU [rad]) of a navigation state (lat, lon, h, v_NED, q) against truth."""
    lat, h = truth[0], truth[2]
    meridian, prime_vertical = earth.radii_of_curvature(lat)
    dlat, dlon, dh = nav[0] - truth[0], nav[1] - truth[1], nav[2] - truth[2]
    position = np.array([dlon * (prime_vertical + h) * math.cos(lat), dlat * (meridian + h), dh])
    dtheta = frame_rotation(lat, dlat, dlon)
    v_ins = ENU_FROM_NED @ nav[3:6]
    velocity = v_ins + np.cross(dtheta, v_ins) - ENU_FROM_NED @ truth[3:6]
    phi = ENU_FROM_NED @ np.array(misalignment(*nav[6:10], *truth[6:10]))
    psi = phi - dtheta
    return np.concatenate([position, velocity, psi])


def corrected_navigation(nav: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """Output with the estimated errors dx (model states) removed; clock estimate += clock states.

    Position: minus the estimate.  Velocity: resolved in the corrected frame
    (C_c^t v_INS), minus the estimate.  Attitude: the psi estimate
    turns the attitude relative to the INS's own frame c; moving the position
    back to the corrected one turns the frame by -dtheta^, so the attitude
    matrix is turned by phi^ = psi^ + dtheta^: C = exp(phi^ x) C~.
    """
    out = np.array(nav, float)
    # metres -> angles at the corrected position: the inverse of navigation_error_states
    h = nav[2] - dx[2]
    lat = nav[0] - dx[1] / (earth.radii_of_curvature(nav[0])[0] + h)
    meridian, prime_vertical = earth.radii_of_curvature(lat)
    dlat = dx[1] / (meridian + h)
    dlon = dx[0] / ((prime_vertical + h) * math.cos(lat))
    out[0] -= dlat
    out[1] -= dlon
    out[2] -= dx[2]
    dtheta = frame_rotation(lat, dlat, dlon)
    v_ins = ENU_FROM_NED @ nav[3:6]
    out[3:6] = ENU_FROM_NED @ (v_ins + np.cross(dtheta, v_ins) - dx[3:6])
    phi = ENU_FROM_NED @ (dx[6:9] + dtheta)
    if phi.any():
        out[6:10] = rotate_attitude(phi[0], phi[1], phi[2], *nav[6:10])
    out[CLOCK_BIAS] += dx[9]
    out[CLOCK_DRIFT] += dx[10]
    return out


def line_of_sight_enu(position: np.ndarray, satellites: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (satellites, 3) receiver -> satellite in ENU at geodetic ``position``, and ranges [m]."""
    user = earth.geodetic_to_ecef(position[0], position[1], position[2])
    difference = satellites - user
    ranges = np.linalg.norm(difference, axis=1)
    ned = (difference / ranges[:, None]) @ earth.ned_to_ecef_matrix(float(position[0]), float(position[1]))
    return ned @ ENU_FROM_NED.T, ranges


def satellite_count(derived: DerivedModel) -> int:
    """n of the model; refuse a model whose states are not the 11 of the pseudo-range model."""
    model = derived.model
    if tuple(model.state_names) != STATE_NAMES:
        raise ModelError(f"pseudorange aiding: model {model.name!r} does not have the 11 states of "
                         f"modelgen.model.pseudorange.pseudorange_model ({', '.join(STATE_NAMES)})")
    return len(model.measurement_names)


class PseudorangeNavigator:
    """The simulated INS with a pseudo-range receiver and a clock estimate (module docstring)."""

    def __init__(self, profile: Any, derived: DerivedModel, sensors: SensorData):
        record = sensors.aiding
        if not isinstance(record, PseudorangeRecord):
            raise ModelError(f"scenario {profile.name!r}: no simulated pseudo-ranges (filter.aiding must be pseudorange)")
        self.profile, self.derived, self.sensors, self.record = profile, derived, sensors, record
        self.settings: PseudorangeSettings = profile.sensors[PSEUDORANGE.name]
        self.satellites = satellite_count(derived)
        trajectory = sensors.trajectory
        self.period = trajectory.record_period
        self.samples_per_cycle = samples_per_cycle(trajectory, profile.coning)
        self.every = whole_ratio(self.settings.period, self.period, "pseudorange period")
        visible = np.isfinite(record.pseudoranges[::self.every]).sum(axis=1)
        if visible.min() < self.satellites:
            j = int(np.argmin(visible))
            raise ModelError(
                f"scenario {profile.name!r}: model {derived.model.name!r} fuses {self.satellites} pseudo-ranges, but only "
                f"{int(visible[j])} satellites are above the {math.degrees(self.settings.elevation_mask):g} deg "
                f"elevation mask at t = {record.times[j * self.every]:g} s ({int(visible.min())}..{int(visible.max())} "
                f"visible over the flight)")
        self.strapdown = Strapdown(sensors.initial_navigation, trajectory.imu_rate, profile.coning,
                                   profile.vertical_damping)
        self.clock = np.zeros(2)  # (b^, d^): the navigator's own clock estimate [m, m/s]
        self.cycle = 0
        self.selected = np.arange(self.satellites)
        self.line_of_sight = np.tile([0.0, 0.0, 1.0], (self.satellites, 1))
        self.noise = profile.constant_parameters()

    # -- navigator protocol ------------------------------------------------------------
    def advance(self, cycle: int) -> None:
        start = (cycle - 1) * self.samples_per_cycle - self.sensors.sample_offset
        heights = self.sensors.altitude_reference
        self.strapdown.run(self.sensors.delta_theta, self.sensors.delta_velocity, start,
                           start + self.samples_per_cycle, (heights[cycle - 1], heights[cycle]))
        self.clock[0] += self.clock[1] * self.period
        self.cycle = cycle

    def output(self) -> np.ndarray:
        return np.concatenate([self.strapdown.navigation_state(), self.clock])

    def correct_output(self, output: np.ndarray, dx: np.ndarray) -> np.ndarray:
        return corrected_navigation(output, dx)

    def feedback(self, dx: np.ndarray) -> None:
        corrected = corrected_navigation(self.output(), dx)
        self.strapdown.correct(corrected[:10])
        self.clock = corrected[CLOCK_BIAS:CLOCK_DRIFT + 1].copy()

    def parameters(self, corrected_output: np.ndarray) -> dict[str, float]:
        if self.cycle % self.every == 0:
            self._select(corrected_output)
        values = operating_point(corrected_output[:10], self.strapdown.specific_force, "ENU", self.profile.imu_budget,
                                 self.noise)
        for k, (east, north, up) in enumerate(self.line_of_sight, start=1):
            values[f"line_of_sight_east_{k}"] = float(east)
            values[f"line_of_sight_north_{k}"] = float(north)
            values[f"line_of_sight_up_{k}"] = float(up)
        return named_parameters(self.derived, values, validate=self.cycle <= 1)

    def _select(self, nav: np.ndarray) -> None:
        """The n visible satellites of highest elevation seen from the INS, and their lines of sight."""
        rho = self.record.pseudoranges[self.cycle]
        visible = np.flatnonzero(np.isfinite(rho))
        los, _ = line_of_sight_enu(nav[0:3], self.record.satellites[self.cycle, visible])
        order = np.argsort(-los[:, 2], kind="stable")[: self.satellites]
        self.selected = visible[order]
        self.line_of_sight = los[order]

    def measurement(self, cycle: int, corrected_output: np.ndarray, accumulated: np.ndarray) -> Measurement | None:
        if cycle % self.every:
            return None
        _, ranges = line_of_sight_enu(corrected_output[0:3], self.record.satellites[cycle, self.selected])
        z = self.record.pseudoranges[cycle, self.selected] - corrected_output[CLOCK_BIAS] - ranges
        return Measurement(z, np.arange(self.satellites))

    def estimation_error(self, cycle: int, corrected_output: np.ndarray, estimate: np.ndarray) -> np.ndarray:
        truth = self.sensors.trajectory.truth[cycle, 1:]
        clock = np.array([self.record.clock_bias[cycle], self.record.clock_drift[cycle]])
        # the corrected output already has the estimate removed (navigation) / added (clock)
        return np.concatenate([navigation_error_states(corrected_output, truth),
                               clock - corrected_output[CLOCK_BIAS:CLOCK_DRIFT + 1]])


def initial_covariance(profile: Any, truth0: np.ndarray) -> np.ndarray:
    """P0 of the 11 states from the profile's initial errors (psi = phi - dtheta couples attitude and position).

    Drawn independently (``flight.simulate_sensors`` and :meth:`PseudorangeAiding.simulate`): phi about N, E, D,
    velocity and position errors per axis (the vertical ones only with
    pseudo-range aiding: a 3-D fix initializes the INS); the receiver clock
    bias and drift.
    """
    ie, clock = profile.initial_errors, profile.sensors[PSEUDORANGE.name]
    lat, h = truth0[0], truth0[2]
    meridian, prime_vertical = earth.radii_of_curvature(lat)
    # independent variables u = (dr_E, dr_N, dr_U, dv_E, dv_N, dv_U, phi_E, phi_N, phi_U, b, d)
    sigma = np.array([ie.position] * 3 + [ie.velocity] * 3 + [ie.attitude[1], ie.attitude[0], ie.attitude[2],
                                                             clock.clock_bias, clock.clock_drift])
    J = np.eye(11)
    # psi = phi - dtheta, dtheta = (-dr_N/(R_M+h), dr_E/(R_N+h), dr_E tan L/(R_N+h))
    J[6, 1] = 1.0 / (meridian + h)
    J[7, 0] = -1.0 / (prime_vertical + h)
    J[8, 0] = -math.tan(lat) / (prime_vertical + h)
    return J @ np.diag(sigma**2) @ J.T


class PseudorangeAiding:
    """The pseudo-range receiver as an aiding-sensor plug-in (module docstring); every state is fed back."""

    name = "pseudorange"
    quantities: tuple[str, ...] = ()  # the rows are the model's satellites, mapped here

    def read_settings(self, section: ProfileSection) -> PseudorangeSettings:
        """The receiver (the accumulated-correction paper) and its constellation; defaults when the section is absent."""
        c = section.section("constellation")
        constellation = Constellation(
            satellites=int(c.number("satellites", 24.0)),
            planes=int(c.number("planes", 6.0)),
            phasing=int(c.number("phasing", 1.0)),
            inclination=c.number("inclination_deg", 55.0 * DEG, DEG),  # defaults are SI
            radius=c.number("orbit_radius_m", 26_559_700.0),
        )
        c.done()
        if constellation.satellites < 1 or constellation.planes < 1 or constellation.satellites % constellation.planes:
            raise ModelError(f"{c.where}: {constellation.satellites} satellites do not fill {constellation.planes} planes")
        settings = PseudorangeSettings(
            period=section.number("period_s", 1.0, positive=True),
            noise=section.number("noise_m", 3.0),
            clock_bias=section.number("clock_bias_m", 3.0e4),
            clock_drift=section.number("clock_drift_mps", 3.0),
            clock_bias_psd=section.number("clock_bias_psd_m2ps", 0.1),
            clock_drift_psd=section.number("clock_drift_psd_m2ps3", 0.01),
            elevation_mask=section.number("elevation_mask_deg", 10.0 * DEG, DEG),
            constellation=constellation,
        )
        section.done()
        where = section.where
        for key, value in (("noise_m", settings.noise), ("clock_bias_m", settings.clock_bias),
                           ("clock_drift_mps", settings.clock_drift), ("clock_bias_psd_m2ps", settings.clock_bias_psd),
                           ("clock_drift_psd_m2ps3", settings.clock_drift_psd)):
            if value < 0:
                raise ModelError(f"{where}.{key}: must not be negative, got {value}")
        if not 0 <= settings.elevation_mask < math.pi / 2:
            raise ModelError(f"{where}.elevation_mask_deg: must be in [0, 90)")
        return settings

    def period(self, settings: PseudorangeSettings) -> float:
        return settings.period

    def noise_parameters(self, settings: PseudorangeSettings) -> dict[str, float]:
        """Clock noise and one range sigma per satellite the constellation can offer."""
        out = {"clock_bias_psd": settings.clock_bias_psd, "clock_drift_psd": settings.clock_drift_psd}
        for k in range(1, settings.constellation.satellites + 1):
            out[f"pseudorange_sigma_{k}"] = settings.noise
        return out

    def simulate(self, profile: Any, trajectory: Trajectory, initial_navigation: np.ndarray,
                 rng: np.random.Generator) -> PseudorangeRecord:
        """Ranges at every record time; a pseudo-range INS is initialized from a 3-D fix (height and
        vertical velocity errors drawn too)."""
        ie = profile.initial_errors
        initial_navigation[2] += ie.position * rng.standard_normal()
        initial_navigation[5] += ie.velocity * rng.standard_normal()
        truth = trajectory.truth
        return simulate_pseudoranges(truth[:, 0], truth[:, 1:4], profile.sensors[self.name], rng)

    def layout(self, profile: Any, derived: DerivedModel, trajectory: Trajectory) -> ErrorLayout:
        """No layout from the profile: the states are mapped explicitly by this module."""
        return ErrorLayout(derived, {})

    def filter_loop(self, profile: Any, derived: DerivedModel, trajectory: Trajectory, sensors: SensorData,
                    layout: ErrorLayout, make_filter: FilterMaker, mode: str, progress: Progress | None,
                    record_every: int = 1, sink: Any = None) -> FilterLoop:
        """The correction-mode loop with a :class:`PseudorangeNavigator`, ready to step; every state is fed back."""
        navigator = PseudorangeNavigator(profile, derived, sensors)
        kalman = make_filter(np.zeros(len(STATE_NAMES)), initial_covariance(profile, trajectory.initial_state()))
        return FilterLoop(navigator, kalman, measurement_function(derived), mode, len(trajectory.truth) - 1,
                          trajectory.record_period, np.ones(len(STATE_NAMES), bool), profile.filter.gate_probability,
                          getattr(kalman, "name", type(kalman).__name__), progress, record_every=record_every, sink=sink)

    def fly(self, profile: Any, derived: DerivedModel, trajectory: Trajectory, sensors: SensorData,
            layout: ErrorLayout, make_filter: FilterMaker, mode: str, progress: Progress | None) -> RunResult:
        """The correction-mode loop with a :class:`PseudorangeNavigator` over the whole (held) flight."""
        loop = self.filter_loop(profile, derived, trajectory, sensors, layout, make_filter, mode, progress)
        for k in range(1, loop.n_cycles + 1):
            loop.step(k)
        return loop.result


#: the registry entry (modelgen.simulation.sensors)
PSEUDORANGE = PseudorangeAiding()
