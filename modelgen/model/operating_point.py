"""Operating points: the parameter values a model takes in a given flight state.

Steady level flight (:func:`level_flight`: velocities, specific force,
attitude matrix and earth radii for any NED or ENU model, by parameter name),
the attitude of a level vehicle (:func:`level_attitude`) and the satellite
line-of-sight parameters of the pseudo-range model (:func:`line_of_sight`,
:func:`pseudorange_parameters`).  Earth constants come from
:mod:`modelgen.model.wgs84`.
"""

from __future__ import annotations

import math

from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel
from modelgen.model.wgs84 import GPS_EARTH_RATE, SEMI_MAJOR_AXIS, earth_radii


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
    """The line-of-sight parameters of :func:`modelgen.model.pseudorange.pseudorange_model` for given satellites."""
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
    NED models (the core paper: heading east gives [[0,-1,0],[1,0,0],[0,0,1]]),
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
    earth_rate = defaults.get("earth_rate", GPS_EARTH_RATE)
    if "earth_radius" in names:
        r_m = r_n = defaults.get("earth_radius", SEMI_MAJOR_AXIS)
    elif spherical_earth:
        r_m = r_n = SEMI_MAJOR_AXIS
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
