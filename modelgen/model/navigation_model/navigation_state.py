"""The computed navigation state's symbols and the file's own parameters.

:func:`read_navigation_state` names the symbols of the attitude matrix C_b^n,
the velocity, the position (geodetic, or r^e for the ecef mechanization), the
sensed specific force and body rate, and the Earth quantities, each offered as a
parameter the derived matrices may use; :func:`read_user_parameters` reads the
file's ``parameters:`` (scalars, and 3-vectors expanded by component).
"""

from __future__ import annotations

from typing import Any, Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model import wgs84
from modelgen.model.declaration import Parameter, check_identifier
from modelgen.model.mechanizations import wander_azimuth
from modelgen.model.mechanizations.local_level import EarthSymbols
from modelgen.model.navigation_model.section import (
    Declarations,
    SectionReader,
    axis_words,
    component_names,
    offer,
    symbol_matrix,
    vector_symbols,
)
from modelgen.model.units import declared_value


def read_navigation_state(read: SectionReader, section: Mapping, frame: str, decl: Declarations) -> dict[str, Any]:
    """Symbols of the computed attitude, velocity, position, sensed inputs and Earth quantities."""
    axes_words = axis_words(frame, None)
    ecef, wander = frame == "ECEF", frame == wander_azimuth.FRAME
    attitude = read.mapping(section.get("attitude", {}), "navigation.attitude", ("symbols",))
    c = read.names(attitude["symbols"], "navigation.attitude.symbols", 9) if "symbols" in attitude else [f"c{i}{j}" for i in range(1, 4) for j in range(1, 4)]
    for k, s in enumerate(c):
        offer(decl, s, s, "1", f"attitude matrix C_b^n (body to {frame}), row {k // 3 + 1} col {k % 3 + 1}")
    velocity = read.mapping(section.get("velocity", {}), "navigation.velocity", ("symbols", "symbol"))
    v = vector_symbols(read, velocity, "navigation.velocity", "v", frame, None)
    for s, word in zip(v, axes_words):
        offer(decl, s, f"velocity_{word}", "m/s", f"e-frame velocity {word} (with respect to the Earth)" if ecef
              else f"ground speed along wander axis {word}" if wander else f"{word} ground speed")
    position = read.mapping(section.get("position", {}), "navigation.position", ("symbols",))
    if wander:  # C_e^w's third column (the Earth's axis in w axes) and the height; the engine perturbs a chart about it
        p = read.names(position["symbols"], "navigation.position.symbols", 1) if "symbols" in position else ["h"]
        for s, name, axis in zip(wander_azimuth.AXIS_SYMBOLS, wander_azimuth.AXIS_NAMES, "xyz"):
            offer(decl, s, name, "1", f"C_e^w row {axis} col 3: the Earth's rotation axis along wander axis {axis} (z: -sin L)")
        offer(decl, p[0], "height", "m", "height above the ellipsoid")
    else:
        default_position = ["r_x", "r_y", "r_z"] if ecef else ["L", "lambda_", "h"]
        p = read.names(position["symbols"], "navigation.position.symbols", 3) if "symbols" in position else default_position
        if ecef:
            position_words = [("position_x", "m", "e-frame position x (Earth's centre to the IMU)"), ("position_y", "m", "e-frame position y"),
                              ("position_z", "m", "e-frame position z (along the Earth's rotation axis)")]
        else:
            position_words = [("latitude", "rad", "geodetic latitude"), ("longitude", "rad", "longitude"), ("height", "m", "height above the ellipsoid")]
        for s, (name, unit, text) in zip(p, position_words):
            offer(decl, s, name, unit, text)
    force = read.mapping(section.get("specific_force", {}), "navigation.specific_force", ("symbols", "symbol", "axes"))
    force_axes = read.choice(force.get("axes", "body"), "navigation.specific_force.axes", ("body", "navigation"))
    f = vector_symbols(read, force, "navigation.specific_force", "f_b" if force_axes == "body" else "f", frame, "body" if force_axes == "body" else None)
    for s, word in zip(f, ("x", "y", "z") if force_axes == "body" else axes_words):
        name = f"body_specific_force_{word}" if force_axes == "body" else f"specific_force_{word}"
        offer(decl, s, name, "m/s^2", f"sensed specific force along {'body ' if force_axes == 'body' else ''}{word}")
    rate = read.mapping(section.get("body_rate", {}), "navigation.body_rate", ("symbols", "symbol"))
    w = vector_symbols(read, rate, "navigation.body_rate", "omega_b", frame, "body")
    for s, word in zip(w, "xyz"):
        offer(decl, s, f"body_rate_{word}", "rad/s", f"sensed body rate w_ib^b about body {word}")
    earth = read.mapping(section.get("earth", {}), "navigation.earth", ("earth_rate", "meridian_radius", "prime_vertical_radius", "gravity", "earth_radius", "geocentric_radius"))
    defaults = {"earth_rate": "omega_ie", "meridian_radius": "R_M", "prime_vertical_radius": "R_N", "gravity": "g", "earth_radius": "R", "geocentric_radius": "r_e"}
    symbols = {}
    for key, default in defaults.items():
        symbols[key] = str(earth.get(key, default))
        check_identifier(symbols[key], f"{read.at(f'navigation.earth.{key}')}: navigation.earth.{key}")
    offer(decl, symbols["earth_rate"], "earth_rate", "rad/s", "earth rotation rate (WGS-84, IS-GPS-200 value)", wgs84.GPS_EARTH_RATE)
    offer(decl, symbols["meridian_radius"], "meridian_radius", "m", "meridian radius of curvature at the latitude (WGS-84)")
    offer(decl, symbols["prime_vertical_radius"], "prime_vertical_radius", "m", "prime-vertical radius of curvature at the latitude (WGS-84)")
    offer(decl, symbols["gravity"], "gravity", "m/s^2", "normal gravity at the position (WGS-84)")
    offer(decl, symbols["earth_radius"], "earth_radius", "m", "radius of the spherical Earth", wgs84.SEMI_MAJOR_AXIS)
    offer(decl, symbols["geocentric_radius"], "geocentric_radius", "m", "|r^e|: distance from the Earth's centre to the IMU (ecef gravity)")
    offer(decl, "k_v1", "vertical_damping_gain_1", "1/s", "baro-damped vertical channel: height feedback gain k_1")
    offer(decl, "k_v2", "vertical_damping_gain_2", "1/s^2", "baro-damped vertical channel: vertical-velocity feedback gain k_2")
    S = lambda name: sp.Symbol(name, real=True)  # noqa: E731
    return {
        "attitude": sp.Matrix(3, 3, [S(s) for s in c]),
        "velocity": symbol_matrix(v),
        "position": wander_azimuth.chart_position(S(p[0])) if wander else symbol_matrix(p),
        "specific_force": symbol_matrix(f),
        "specific_force_axes": force_axes,
        "body_rate": symbol_matrix(w),
        "earth": EarthSymbols(*(S(symbols[k]) for k in ("earth_rate", "meridian_radius", "prime_vertical_radius", "gravity", "earth_radius", "geocentric_radius"))),
    }


def read_user_parameters(read: SectionReader, data: Mapping, decl: Declarations, frame: str = "NED") -> list[str]:
    """The file's own ``parameters:`` (statistics, noise levels): always declared; returns their symbols.

    A parameter with ``shape: 3`` is a vector (``axes: body`` or the navigation frame, the default):
    one parameter per component (``lever`` -> ``lever_x, lever_y, lever_z`` in body axes), its
    ``value`` a list of three; expressions see it whole, by its symbol (:attr:`Declarations.vectors`).
    """
    raw = data.get("parameters") or []
    if not isinstance(raw, list):
        raise ModelError(f"{read.at('parameters')}: 'parameters' must be a list of entries with a 'name'")
    symbols = []
    expanded = []
    for i, entry in enumerate(raw):
        key = f"parameters[{i}]"
        entry = read.mapping(entry, key, ("name", "symbol", "unit", "description", "value", "shape", "axes"), ("name",))
        if "shape" not in entry:
            if "axes" in entry:
                raise ModelError(f"{read.at(key)}: parameter {entry['name']!r}: 'axes' is for a vector parameter (shape: 3)")
            expanded.append((key, entry))
            continue
        if entry["shape"] not in (3, [3], [3, 1]):
            raise ModelError(f"{read.at(f'{key}.shape')}: parameter {entry['name']!r}: a navigation model's parameter is a scalar or a 3-vector (shape: 3), not {entry['shape']!r}")
        axes = read.choice(entry.get("axes", "navigation"), f"{key}.axes", ("body", "navigation"))
        name, symbol = str(entry["name"]), str(entry.get("symbol", entry["name"]))
        check_identifier(symbol, f"{read.at(key)}: parameter symbol")
        where = f"{read.at(key)}: parameter {name!r}"
        names = component_names(name, 3, frame, "body" if axes == "body" else None, where)
        parts = component_names(symbol, 3, frame, "body" if axes == "body" else None, where)
        values = entry.get("value")
        if values is not None and (not isinstance(values, list) or len(values) != 3):
            raise ModelError(f"{read.at(key)}: parameter {name!r} is a 3-vector: its value must list 3 numbers, got {values!r}")
        for k, (component, part) in enumerate(zip(names, parts)):
            item = {f: v for f, v in entry.items() if f not in ("shape", "axes", "value")}
            item.update(name=component, symbol=part)
            if values is not None:
                item["value"] = values[k]
            expanded.append((key, item))
        decl.vectors[symbol] = symbol_matrix(parts)
    for key, entry in expanded:
        if "value" in entry and (isinstance(entry["value"], bool) or not isinstance(entry["value"], (int, float))):
            raise ModelError(f"{read.at(key)}: parameter {entry['name']!r} value {entry['value']!r} is not a number")
        fields = {k: (float(v) if k == "value" else str(v)) for k, v in entry.items()}
        if "value" in fields and "unit" in fields:  # given in deg/h, ppm, ug ...: converted to SI, and so is the unit
            fields["value"], fields["unit"] = declared_value(fields["value"], fields["unit"], f"{read.at(f'{key}.unit')}: {key}.unit")
        parameter = Parameter(**fields)
        check_identifier(parameter.symbol, f"{read.at(key)}: parameter symbol")
        decl.parameters[parameter.symbol] = parameter
        decl.places[("parameter", parameter.name)] = key
        symbols.append(parameter.symbol)
    return symbols
