"""The INS/GPS pseudo-range model (the accumulated-correction paper), built in code for any number of satellites.

The model files in ``modelgen/models`` cover fixed state sets.  The accumulated-correction paper's
INS/GPS pseudo-range filter has one measurement per tracked satellite, so it
is built here for any number of satellites by :func:`pseudorange_model`;
``modelgen/models/gps_pseudorange11.yaml`` is its 4-satellite instance (a test
checks that both derive to the same matrices).  The line-of-sight parameter
values for given satellites come from
:func:`modelgen.model.operating_point.pseudorange_parameters`.
"""

from __future__ import annotations

from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Measurement, Noise, Parameter, State
from modelgen.model.wgs84 import GPS_EARTH_RATE, SEMI_MAJOR_AXIS


# -- the accumulated-correction paper: INS/GPS pseudo-range model ---------------------------------------
_PSEUDORANGE_STATES = (
    State("position_error_east", "m", "east position error in the local-level frame (X_p)", "dr_E"),
    State("position_error_north", "m", "north position error in the local-level frame (X_p)", "dr_N"),
    State("position_error_up", "m", "up position error in the local-level frame (X_p)", "dr_U"),
    State("velocity_error_east", "m/s", "east velocity error (X_v)", "dv_E"),
    State("velocity_error_north", "m/s", "north velocity error (X_v)", "dv_N"),
    State("velocity_error_up", "m/s", "up velocity error (X_v)", "dv_U"),
    State("attitude_error_east", "rad", "platform attitude error about east, psi-angle (X_phi)", "psi_E"),
    State("attitude_error_north", "rad", "platform attitude error about north, psi-angle (X_phi)", "psi_N"),
    State("attitude_error_up", "rad", "platform attitude error about up, psi-angle (X_phi)", "psi_U"),
    State("clock_bias_range", "m", "receiver clock bias times c (I_t, 'clock-difference range')", "I_t"),
    State("clock_drift_range", "m/s", "receiver clock drift times c (I_f, 'frequency-difference range')", "I_f"),
)

_PSEUDORANGE_NOISES = (
    Noise("gyro_white_noise_east", "rad/sqrt(s)", "gyro white noise resolved east", "w_g_E", psd="N_g**2"),
    Noise("gyro_white_noise_north", "rad/sqrt(s)", "gyro white noise resolved north", "w_g_N", psd="N_g**2"),
    Noise("gyro_white_noise_up", "rad/sqrt(s)", "gyro white noise resolved up", "w_g_U", psd="N_g**2"),
    Noise("accel_white_noise_east", "m/s/sqrt(s)", "accelerometer white noise resolved east", "w_a_E", psd="N_a**2"),
    Noise("accel_white_noise_north", "m/s/sqrt(s)", "accelerometer white noise resolved north", "w_a_N", psd="N_a**2"),
    Noise("accel_white_noise_up", "m/s/sqrt(s)", "accelerometer white noise resolved up", "w_a_U", psd="N_a**2"),
    Noise("clock_bias_noise", "m/sqrt(s)", "white noise driving the clock bias range", "w_t", psd="S_t"),
    Noise("clock_drift_noise", "m/s/sqrt(s)", "white noise driving the clock drift range", "w_f", psd="S_f"),
)

_PSEUDORANGE_PARAMETERS = (
    Parameter("latitude", "rad", "geographic latitude", "L"),
    Parameter("velocity_east", "m/s", "east ground speed", "v_E"),
    Parameter("velocity_north", "m/s", "north ground speed", "v_N"),
    Parameter("specific_force_east", "m/s^2", "specific force along east", "f_E"),
    Parameter("specific_force_north", "m/s^2", "specific force along north", "f_N"),
    Parameter("specific_force_up", "m/s^2", "specific force along up (about +g in level flight)", "f_U"),
    Parameter("earth_rate", "rad/s", "earth rotation rate (WGS-84)", "omega_ie", GPS_EARTH_RATE),
    Parameter("earth_radius", "m", "earth radius of the spherical psi-angle model", "R", SEMI_MAJOR_AXIS),
    Parameter("gravity", "m/s^2", "gravity magnitude (gravity-error gradient g/R, 2g/R)", "g", 9.80665),
    Parameter("gyro_angle_random_walk", "rad/sqrt(s)", "gyro white noise, PSD N_g^2 (all axes)", "N_g"),
    Parameter("accel_velocity_random_walk", "m/s/sqrt(s)", "accelerometer white noise, PSD N_a^2 (all axes)", "N_a"),
    Parameter("clock_bias_psd", "m^2/s", "PSD of the clock bias-range driving noise (h0/2 c^2)", "S_t"),
    Parameter("clock_drift_psd", "m^2/s^3", "PSD of the clock drift-range driving noise (2 pi^2 h_-2 c^2)", "S_f"),
)

# The psi-angle error model (Benson 1975; Titterton & Weston, ch. 12) in the
# local-level East-North-Up frame, position error as a vector in metres:
#   d(dr)/dt  = -w_en x dr + dv
#   d(dv)/dt  = -(2 w_ie + w_en) x dv + f x psi + dg + w_a,  dg = (-g/R dr_E, -g/R dr_N, 2 g/R dr_U)
#   d(psi)/dt = -w_in x psi - w_g
# with w_ie = (0, W cos L, W sin L), w_en = (-v_N/R, v_E/R, v_E tan L/R),
# w_in = w_ie + w_en.  Written out component by component below.
_PSEUDORANGE_DYNAMICS = {
    # -w_en x dr + dv
    "dr_E": "dv_E + v_E*tan(L)/R*dr_N - v_E/R*dr_U",
    "dr_N": "dv_N - v_E*tan(L)/R*dr_E - v_N/R*dr_U",
    "dr_U": "dv_U + v_E/R*dr_E + v_N/R*dr_N",
    # -(2 w_ie + w_en) x dv + f x psi + dg + w_a
    "dv_E": (
        "(2*omega_ie*sin(L) + v_E*tan(L)/R)*dv_N - (2*omega_ie*cos(L) + v_E/R)*dv_U"
        " + f_N*psi_U - f_U*psi_N - g/R*dr_E + w_a_E"
    ),
    "dv_N": (
        "-(2*omega_ie*sin(L) + v_E*tan(L)/R)*dv_E - v_N/R*dv_U"
        " + f_U*psi_E - f_E*psi_U - g/R*dr_N + w_a_N"
    ),
    "dv_U": (
        "(2*omega_ie*cos(L) + v_E/R)*dv_E + v_N/R*dv_N"
        " + f_E*psi_N - f_N*psi_E + 2*g/R*dr_U + w_a_U"
    ),
    # -w_in x psi - w_g
    "psi_E": "(omega_ie*sin(L) + v_E*tan(L)/R)*psi_N - (omega_ie*cos(L) + v_E/R)*psi_U - w_g_E",
    "psi_N": "-(omega_ie*sin(L) + v_E*tan(L)/R)*psi_E - v_N/R*psi_U - w_g_N",
    "psi_U": "(omega_ie*cos(L) + v_E/R)*psi_E + v_N/R*psi_N - w_g_U",
    # receiver clock: bias range driven by drift range (the accumulated-correction paper, eq. (3): rho' = rho - sum I_t - dt sum I_f)
    "I_t": "I_f + w_t",
    "I_f": "w_f",
}


def pseudorange_model(n_satellites: int, name: str | None = None) -> ErrorModel:
    """The accumulated-correction paper's 11-state INS/GPS pseudo-range error model for ``n_satellites``.

    States (the accumulated-correction paper, section 3): position error X_p, velocity error X_v,
    platform attitude error X_phi, clock bias range I_t, clock drift range
    I_f.  Decisions (the paper prints no F):

    * Position error is a vector in metres in the local-level ENU frame, so
      that a pseudo-range row is linear in it with the line-of-sight vector as
      coefficients; the INS error dynamics that go with that state are the
      psi-angle model (see ``_PSEUDORANGE_DYNAMICS``), spherical earth of
      radius R.  Its attitude states are psi-angles (the attitude error seen
      from the true frame); phi = psi + (-dr_N/R, dr_E/R, dr_E tan L/R).
    * The INS has no sensor-bias states (the paper's 11 states have none):
      gyro and accelerometer errors are white noises resolved in the
      navigation frame.  For equal noise on all axes this is exact whatever
      the attitude (C w has the covariance of w), so no attitude matrix is
      needed.
    * Clock: I_t' = I_f + w_t, I_f' = w_f (two-state clock, PSDs from the
      oscillator's Allan-variance coefficients).
    * Measurement k (the accumulated-correction paper eq. (8)): Z_k = rho'_GPS,k - rho_C,k, measured
      (clock-corrected) minus computed from the INS position.  With the INS
      position error dr = r_INS - r_true and e_k the unit vector from the
      receiver to satellite k, rho_C = |r_s - r_true - dr| = rho - e_k . dr
      and rho'_GPS = rho + I_t + eta_k, so
          Z_k = e_k . dr + I_t + eta_k,   H_k = [e_k^T  0  0  1  0].
      (The brief's [-e_k^T ... 1 0] is the same row with e_k pointing from
      the satellite to the receiver.)  e_k = (e_k_x, e_k_y, e_k_z) are
      parameters (east, north, up), see :func:`modelgen.model.operating_point.line_of_sight`.

    ``name`` defaults to ``gps_pseudorange11_<n>sat``.
    """
    if isinstance(n_satellites, bool) or not isinstance(n_satellites, int) or n_satellites < 1:
        raise ModelError(f"pseudorange_model: number of satellites must be a positive integer, not {n_satellites!r}")
    parameters = list(_PSEUDORANGE_PARAMETERS)
    measurements = []
    for k in range(1, n_satellites + 1):
        for axis, direction in (("x", "east"), ("y", "north"), ("z", "up")):
            parameters.append(
                Parameter(
                    f"line_of_sight_{direction}_{k}",
                    "1",
                    f"{direction} component of the unit vector from the receiver to satellite {k}",
                    f"e_{k}_{axis}",
                )
            )
        parameters.append(Parameter(f"pseudorange_sigma_{k}", "m", f"pseudo-range noise of satellite {k}", f"sigma_rho_{k}"))
        measurements.append(
            Measurement(
                f"pseudorange_difference_{k}",
                "m",
                f"measured (clock-corrected) minus INS-computed pseudo-range to satellite {k}, eq. (8)",
                f"Z_{k}",
                expression=f"e_{k}_x*dr_E + e_{k}_y*dr_N + e_{k}_z*dr_U + I_t",
                variance=f"sigma_rho_{k}**2",
            )
        )
    return ErrorModel.build(
        name=name or f"gps_pseudorange{len(_PSEUDORANGE_STATES)}_{n_satellites}sat",
        states=_PSEUDORANGE_STATES,
        noises=_PSEUDORANGE_NOISES,
        parameters=parameters,
        dynamics=_PSEUDORANGE_DYNAMICS,
        measurements=measurements,
        title=f"INS/GPS pseudo-range, 11-state error model (psi-angle, ENU, metres), {n_satellites} satellites",
        source="the accumulated-correction paper, Zou, Zhuang, Ding (2001), section 3; dynamics: psi-angle model (Benson 1975)",
        frame="ENU",
        notes=("Built by modelgen.model.pseudorange.pseudorange_model.",),
    )
