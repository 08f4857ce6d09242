"""Models built in code, where the state or measurement set has a size.

The model files in ``modelgen/models`` cover fixed state sets.  Seed 003's
INS/GPS pseudo-range filter has one measurement per tracked satellite, so it
is built here for any number of satellites by :func:`pseudorange_model`;
``modelgen/models/gps_pseudorange11.yaml`` is its 4-satellite instance (a test
checks that both derive to the same matrices).

Also here: the WGS-84 radii of curvature and the line-of-sight unit vector,
which turn a latitude or a satellite's azimuth and elevation into the
operating-point parameters these models take.
"""

from __future__ import annotations

import math

from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Measurement, Noise, Parameter, State

#: WGS-84 semi-major axis (m) and first eccentricity squared.
WGS84_SEMI_MAJOR_AXIS = 6378137.0
WGS84_ECCENTRICITY_SQUARED = 6.69437999014e-3
WGS84_EARTH_RATE = 7.2921151467e-5


def earth_radii(latitude: float) -> tuple[float, float]:
    """WGS-84 meridian and prime-vertical radii of curvature (R_M, R_N) in metres.

    R_M = a (1 - e^2) / (1 - e^2 sin^2 L)^(3/2),  R_N = a / (1 - e^2 sin^2 L)^(1/2).
    """
    s2 = math.sin(latitude) ** 2
    w = 1.0 - WGS84_ECCENTRICITY_SQUARED * s2
    return (
        WGS84_SEMI_MAJOR_AXIS * (1.0 - WGS84_ECCENTRICITY_SQUARED) / w**1.5,
        WGS84_SEMI_MAJOR_AXIS / math.sqrt(w),
    )


def line_of_sight(azimuth: float, elevation: float) -> tuple[float, float, float]:
    """Unit vector from the receiver to a satellite, in East-North-Up components.

    ``azimuth`` is measured from north towards east, ``elevation`` above the
    local horizontal (radians): e = (cos El sin Az, cos El cos Az, sin El).
    """
    return (
        math.cos(elevation) * math.sin(azimuth),
        math.cos(elevation) * math.cos(azimuth),
        math.sin(elevation),
    )


def pseudorange_parameters(azimuths_elevations: list[tuple[float, float]]) -> dict[str, float]:
    """The line-of-sight parameters of :func:`pseudorange_model` for given satellites."""
    values: dict[str, float] = {}
    for k, (az, el) in enumerate(azimuths_elevations, start=1):
        east, north, up = line_of_sight(az, el)
        values[f"line_of_sight_east_{k}"] = east
        values[f"line_of_sight_north_{k}"] = north
        values[f"line_of_sight_up_{k}"] = up
    return values


def level_attitude(frame: str, heading: float) -> list[list[float]]:
    """C_b^n of a level vehicle with the given heading (rad, from north towards east).

    Body axes follow each frame's usual convention: forward-right-down for
    NED models (seed 000: heading east gives [[0,-1,0],[1,0,0],[0,0,1]]),
    right-forward-up for ENU models (Qin).
    """
    c, s = math.cos(heading), math.sin(heading)
    if frame == "NED":
        return [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    if frame == "ENU":
        return [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]
    raise ModelError(f"level_attitude: frame must be 'NED' or 'ENU', not {frame!r}")


def level_flight(
    model: ErrorModel,
    latitude: float,
    speed: float,
    heading: float,
    height: float = 0.0,
    gravity: float = 9.80665,
    spherical_earth: bool = False,
) -> dict[str, float]:
    """Operating-point parameter values for steady level flight, for any library model.

    Sets whichever of these the model has (by parameter name): latitude,
    height, velocities, specific forces, attitude matrix c11..c33 (see
    :func:`level_attitude`), earth radii, gravity.  The specific force is the
    one steady flight needs, f^n = -g^n + (2 w_ie + w_en) x v (so the
    Eotvos and transport terms are in it), with w_en from the model's own
    radii: WGS-84 R_M, R_N, or the model's ``earth_radius`` (or, with
    ``spherical_earth``, R_M = R_N = the WGS-84 semi-major axis).  Error
    statistics (sensor and measurement noise) are not operating-point values
    and are left to the caller.
    """
    frame = model.frame
    if frame not in ("NED", "ENU"):
        raise ModelError(f"level_flight: model {model.name!r} has frame {frame!r}, expected NED or ENU")
    defaults = model.parameter_defaults()
    names = set(model.parameter_names)
    earth_rate = defaults.get("earth_rate", WGS84_EARTH_RATE)
    if "earth_radius" in names:
        r_m = r_n = defaults.get("earth_radius", WGS84_SEMI_MAJOR_AXIS)
    elif spherical_earth:
        r_m = r_n = WGS84_SEMI_MAJOR_AXIS
    else:
        r_m, r_n = earth_radii(latitude)
    h = height if "height" in names else 0.0
    v_n, v_e = speed * math.cos(heading), speed * math.sin(heading)
    sin_l, cos_l, tan_l = math.sin(latitude), math.cos(latitude), math.tan(latitude)
    # f = (2 w_ie + w_en) x v + (0, 0, g) in ENU, with v = (v_e, v_n, 0) and
    # 2 w_ie + w_en = (-v_n/(R_M+h), 2W cos L + v_e/(R_N+h), 2W sin L + v_e tan L/(R_N+h)).
    w = (-v_n / (r_m + h), 2 * earth_rate * cos_l + v_e / (r_n + h), 2 * earth_rate * sin_l + v_e * tan_l / (r_n + h))
    f_east, f_north, f_up = -w[2] * v_n, w[2] * v_e, gravity + w[0] * v_n - w[1] * v_e
    values = {
        "latitude": latitude,
        "height": height,
        "gravity": gravity,
        "meridian_radius": r_m,
        "prime_vertical_radius": r_n,
    }
    if frame == "NED":
        values.update(velocity_north=v_n, velocity_east=v_e, velocity_down=0.0)
        values.update(specific_force_north=f_north, specific_force_east=f_east, specific_force_down=-f_up)
    else:
        values.update(velocity_east=v_e, velocity_north=v_n, velocity_up=0.0)
        values.update(specific_force_east=f_east, specific_force_north=f_north, specific_force_up=f_up)
    attitude = level_attitude(frame, heading)
    values.update({f"c{i + 1}{j + 1}": attitude[i][j] for i in range(3) for j in range(3)})
    return {k: v for k, v in values.items() if k in names}


# -- seed 003: INS/GPS pseudo-range model ---------------------------------------
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
    Parameter("earth_rate", "rad/s", "earth rotation rate (WGS-84)", "omega_ie", WGS84_EARTH_RATE),
    Parameter("earth_radius", "m", "earth radius of the spherical psi-angle model", "R", WGS84_SEMI_MAJOR_AXIS),
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
    # receiver clock: bias range driven by drift range (seed 003, eq. (3): rho' = rho - sum I_t - dt sum I_f)
    "I_t": "I_f + w_t",
    "I_f": "w_f",
}


def pseudorange_model(n_satellites: int, name: str | None = None) -> ErrorModel:
    """Seed 003's 11-state INS/GPS pseudo-range error model for ``n_satellites``.

    States (seed 003, section 3): position error X_p, velocity error X_v,
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
    * Measurement k (seed 003 eq. (8)): Z_k = rho'_GPS,k - rho_C,k, measured
      (clock-corrected) minus computed from the INS position.  With the INS
      position error dr = r_INS - r_true and e_k the unit vector from the
      receiver to satellite k, rho_C = |r_s - r_true - dr| = rho - e_k . dr
      and rho'_GPS = rho + I_t + eta_k, so
          Z_k = e_k . dr + I_t + eta_k,   H_k = [e_k^T  0  0  1  0].
      (The brief's [-e_k^T ... 1 0] is the same row with e_k pointing from
      the satellite to the receiver.)  e_k = (e_k_x, e_k_y, e_k_z) are
      parameters (east, north, up), see :func:`line_of_sight`.

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
        source="seed 003, Zou, Zhuang, Ding (2001), section 3; dynamics: psi-angle model (Benson 1975)",
        frame="ENU",
        notes=("Built by modelgen.model.library.pseudorange_model.",),
    )
