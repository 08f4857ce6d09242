"""A navigation model file to an ordinary ErrorModel: the section read, the engine run, the matrices written as equations.

:func:`derive_navigation_model` checks the file's keys, frame and mechanization,
reads each part of the ``navigation:`` section (this subpackage's modules), builds
the :class:`~modelgen.model.perturbation.problem.NavigationProblem`, derives it
(:func:`~modelgen.model.perturbation.derivation.derive_error_equations`) and writes
F x + G w and H x as the dynamics and measurements of an
:class:`~modelgen.model.declaration.ErrorModel`, with file:line of every derived
declaration; a polar check scenario of a local-level model is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping, Sequence

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Measurement, Parameter
from modelgen.model.file_fields import free_text, notes_text
from modelgen.model.mechanizations import MECHANIZATION_FRAMES, mechanization_named
from modelgen.model.navigation_model.approximation_entries import read_approximations
from modelgen.model.navigation_model.approximation_notes import approximation_notes
from modelgen.model.navigation_model.error_states import read_error_definition
from modelgen.model.navigation_model.expressions import read_written_equations
from modelgen.model.navigation_model.measurements import read_measurements
from modelgen.model.navigation_model import pseudoranges
from modelgen.model.navigation_model.navigation_state import read_navigation_state, read_user_parameters
from modelgen.model.navigation_model.section import (
    NAVIGATION_TOP_KEYS,
    SECTION_KEYS,
    Declarations,
    SectionReader,
)
from modelgen.model.navigation_model.sensor_errors import read_sensor_errors, read_sensor_noises
from modelgen.model.perturbation.derivation import derive_error_equations
from modelgen.model.perturbation.problem import (
    ErrorEquations,
    InertialSensorErrors,
    MeasurementFunction,
    NavigationProblem,
    attitude_reset,
)
from modelgen.model.unit_check import check_model_units


@dataclass(frozen=True)
class NavigationDerivation:
    """A navigation model as loaded: the ErrorModel and the engine's result (neglected terms included)."""

    model: ErrorModel
    equations: ErrorEquations


def derive_navigation_model(data: Mapping[str, Any], lines: Mapping[str, str], filename: str) -> NavigationDerivation:
    """The ErrorModel of a file with a ``navigation:`` section (its ``check:`` is attached by the loader)."""
    read = SectionReader(lines, filename)
    unknown = sorted(set(data) - NAVIGATION_TOP_KEYS)
    if unknown:
        derived = " (a model with a 'navigation:' section derives its states, noises, dynamics and measurements)" if unknown[0] in ("states", "noises", "dynamics", "measurements") else ""
        raise ModelError(f"{read.at(unknown[0])}: unknown key {unknown[0]!r}{derived} (expected one of {', '.join(sorted(NAVIGATION_TOP_KEYS))})")
    if "model" not in data:
        raise ModelError(f"{filename}: missing required key 'model'")
    if "frame" not in data:
        raise ModelError(f"{filename}: a model with a 'navigation:' section needs 'frame: NED' or 'frame: ENU' (its navigation frame)")
    frames = tuple(dict.fromkeys(f for fs in MECHANIZATION_FRAMES.values() for f in fs))
    frame = read.choice(free_text(data, "frame", dict(lines), filename), "frame", frames)
    section = read.mapping(data["navigation"], "navigation", SECTION_KEYS, ("errors",))
    mechanization = str(section.get("mechanization", "local_level"))
    mechanization_named(mechanization, f"{read.at('navigation.mechanization')}: navigation.mechanization")
    if frame not in MECHANIZATION_FRAMES[mechanization]:
        owner = next(m for m, fs in MECHANIZATION_FRAMES.items() if frame in fs)
        raise ModelError(
            f"{read.at('frame')}: frame {frame!r} is the {owner} mechanization's; the {mechanization} mechanization resolves its "
            f"vectors in {' or '.join(MECHANIZATION_FRAMES[mechanization])} (frame: {MECHANIZATION_FRAMES[mechanization][0]})"
        )
    _refuse_polar_scenario(read, data, lines, filename, mechanization)
    _refuse_non_unit_wander_axis(read, data, lines, filename, mechanization)
    decl = Declarations(states=[], noises=[], parameters={})
    own = read_user_parameters(read, data, decl, frame)
    nav = read_navigation_state(read, section, frame, decl)

    def namespace() -> dict[str, Any]:
        return {**{s: sp.Symbol(s, real=True) for s in own}, **decl.vectors}

    approximation_names, approximation_scopes = read_approximations(read, section, mechanization)
    definition, navigation_order = read_error_definition(read, section, frame, decl, mechanization)
    noises = read_sensor_noises(read, section, frame, decl)
    parts, aux, sensor_order = read_sensor_errors(read, section, frame, decl, namespace)
    functions, measurement_decls = read_measurements(read, section, frame, decl, parts.get("receiver_clock"), namespace, mechanization)
    problem = NavigationProblem(
        frame=frame, **nav, errors=definition,
        gyro=InertialSensorErrors(parts.get("gyro_bias"), parts.get("gyro_scale_factor"), *noises.get("gyro", (None, "body"))),
        accelerometer=InertialSensorErrors(parts.get("accel_bias"), parts.get("accel_scale_factor"), *noises.get("accel", (None, "body"))),
        state_order=tuple(navigation_order + sensor_order + decl.measurement_biases),
        auxiliary_dynamics={**aux, **{s: decl.measurement_bias_dynamics.get(s, sp.S.Zero) for s in decl.measurement_biases}},
        noises=tuple(sp.Symbol(n.symbol, real=True) for n in decl.noises),
        measurements=tuple(functions),
        approximations=approximation_names,
        approximation_scopes=approximation_scopes,
        equations=read_written_equations(read, section, frame, namespace),
        mechanization_name=mechanization,
    )
    if problem.specific_force_axes == "navigation" and problem.accelerometer.scale_factor is not None:
        raise ModelError(f"{read.at('navigation.specific_force')}: accelerometer scale factors need the specific force in body axes (specific_force: {{axes: body}})")
    try:
        equations = derive_error_equations(problem)
    except ModelError as exc:
        if str(exc).startswith(filename):  # already names its file and line
            raise
        raise ModelError(f"{read.at('navigation')}: model {data['model']!r}: {exc}") from None
    _refuse_measurements_of_removed_states(read, equations, functions)
    attitude_names = [s.name for s in decl.states if sp.Symbol(s.symbol, real=True) in definition.attitude_states]
    model = replace(
        _error_model(data, lines, filename, decl, own, equations, measurement_decls),
        neglected=equations.neglected, attitude_reset=attitude_reset(definition, attitude_names), navigation=problem,
    )
    return NavigationDerivation(model=model, equations=equations)


def _refuse_polar_scenario(read: SectionReader, data: Mapping, lines: Mapping[str, str], filename: str, mechanization: str) -> None:
    """A local-level model whose check scenario is within POLAR_LIMIT_DEG of a pole is refused (1/cos L, tan L blow up)."""
    from modelgen.model.check_scenario import parse_check_section
    from modelgen.model.mechanizations.local_level import POLAR_LIMIT_DEG

    if mechanization != "local_level" or not isinstance(data.get("check"), Mapping):
        return
    latitude = parse_check_section(data["check"], lines, filename).get("parameters", {}).get("latitude")
    if latitude is None or abs(math.degrees(latitude)) <= POLAR_LIMIT_DEG:
        return
    raise ModelError(
        f"{read.at('check.parameters.latitude')}: check.parameters.latitude {math.degrees(latitude):.6g} deg is within "
        f"{90 - POLAR_LIMIT_DEG:g} deg of a pole: the local-level mechanization divides by cos(latitude) (longitude rate "
        f"1/cos L = {1 / math.cos(latitude):.0f}, transport rate tan L) and is refused beyond {POLAR_LIMIT_DEG:g} deg; "
        f"use 'mechanization: wander_azimuth' or 'mechanization: ecef' (no singularity at the poles)"
    )


def _refuse_non_unit_wander_axis(read: SectionReader, data: Mapping, lines: Mapping[str, str], filename: str, mechanization: str) -> None:
    """A wander_azimuth check scenario's C_e^w column (wander_dcm_13, _23, _33) must be a unit vector: the derived
    matrices use |k| = 1 (and k_x^2 + k_y^2 = cos^2 L), so other values would evaluate them off the ellipsoid."""
    from modelgen.model.check_scenario import parse_check_section
    from modelgen.model.mechanizations.wander_azimuth import AXIS_NAMES

    if mechanization != "wander_azimuth" or not isinstance(data.get("check"), Mapping):
        return
    values = parse_check_section(data["check"], lines, filename).get("parameters", {})
    if not all(name in values for name in AXIS_NAMES):
        return
    norm = math.sqrt(sum(float(values[name]) ** 2 for name in AXIS_NAMES))
    if abs(norm - 1) > 1e-9:
        raise ModelError(
            f"{read.at('check.parameters.' + AXIS_NAMES[0])}: check.parameters {', '.join(AXIS_NAMES)} have length {norm:.9g}: "
            f"they are C_e^w's third column (cos a cos L, sin a cos L, -sin L), a unit vector"
        )


def _refuse_measurements_of_removed_states(read: SectionReader, equations: ErrorEquations, functions: Sequence[MeasurementFunction]) -> None:
    """A measurement that depends on a quantity with no error state (the vertical channel under no_vertical_channel) is refused."""
    rows = [(f"navigation.measurements[{i}]", symbol) for i, f in enumerate(functions) for symbol in f.symbols]
    for term in equations.neglected:
        if term.matrix == "H" and term.column == -1:
            key, symbol = rows[term.row]
            raise ModelError(
                f"{read.at(key)}: measurement {str(symbol)!r} depends on the vertical velocity or height, which have no "
                f"error state under no_vertical_channel (measure the horizontal components only)"
            )


def _error_model(data, lines, filename, decl: Declarations, own: list[str], equations: ErrorEquations, measurement_decls) -> ErrorModel:
    """The derived matrices written as the linear equations of an ordinary ErrorModel."""
    x = sp.Matrix(equations.states)
    w = sp.Matrix(equations.noises) if equations.noises else sp.zeros(0, 1)
    rhs = equations.F * x + (equations.G * w if equations.noises else sp.zeros(x.rows, 1))
    measured = equations.H * x if equations.H.rows else sp.zeros(0, 1)
    used = set().union(*(m.free_symbols for m in (equations.F, equations.G, equations.H)))
    used |= {s for n in decl.noises for s in sp.sympify(n.psd, locals=_locals(decl)).free_symbols}
    used |= {s for m in measurement_decls for s in sp.sympify(m.variance, locals=_locals(decl)).free_symbols}
    used_names = {str(s) for s in used}
    parameters = [p for symbol, p in decl.parameters.items() if symbol in own or symbol in used_names]
    measurements = [
        Measurement(name=m.name, symbol=m.symbol, unit=m.unit, description=m.description, variance=m.variance, expression=measured[i])
        for i, m in enumerate(measurement_decls)
    ]
    locations = _locations(lines, filename, decl, parameters, measurements)
    model = ErrorModel.build(
        name=str(data["model"]),
        states=decl.states,
        noises=decl.noises,
        parameters=parameters,
        dynamics={s.name: rhs[i] for i, s in enumerate(decl.states)},
        measurements=measurements,
        title=free_text(data, "title", dict(lines), filename),
        source=free_text(data, "source", dict(lines), filename),
        frame=free_text(data, "frame", dict(lines), filename),
        notes=[*notes_text(dict(data), dict(lines), filename), *approximation_notes(data, equations, decl, implied_approximations(data))],
        locations=locations,
    )
    undeclared = [str(p.get("name")) for p in (data.get("parameters") or []) if isinstance(p, dict) and "unit" not in p]
    undeclared += [name for stem in undeclared for name in (f"{stem}_{a}" for a in ("x", "y", "z", "n", "e", "d", "u"))
                   if any(q.name == name for q in parameters)]  # a vector parameter's components
    check_model_units(model, locations, undeclared)
    return model


def implied_approximations(data: Mapping) -> dict[str, str]:
    """The approximations the file's measurements make whether it declares them or not, each with the key of the
    first entry that makes it: a local-level pseudo-range's M (computed) (:data:`.pseudoranges.APPROXIMATION`)."""
    section = data["navigation"]
    if str(section.get("mechanization", "local_level")) != "local_level":
        return {}
    for i, entry in enumerate(section.get("measurements") or []):
        if isinstance(entry, Mapping) and entry.get("of") in pseudoranges.KINDS:
            return {pseudoranges.APPROXIMATION: f"navigation.measurements[{i}] (of: {entry['of']})"}
    return {}


def _locations(lines: Mapping[str, str], filename: str, decl: Declarations, parameters: Sequence[Parameter], measurements: Sequence[Measurement]) -> dict[str, str]:
    """file:line of every derived declaration (ErrorModel.build's keys), from the entry of the section that made it."""
    read = SectionReader(lines, filename)
    derived = ("parameters", "states", "noises", "measurements", "dynamics")
    out = {k: v for k, v in lines.items() if not k.startswith(derived)}
    for kind, items, fields in (("state", decl.states, ()), ("noise", decl.noises, ("psd",)), ("parameter", parameters, ()),
                                ("measurement", measurements, ("expression", "variance"))):
        for i, item in enumerate(items):
            place = read.at(decl.places.get((kind, item.name), "navigation"))
            out[f"{kind}s[{i}]"] = place
            out.update({f"{kind}s[{i}].{f}": place for f in fields})
            if kind == "state":
                out[f"dynamics.{item.name}"] = place
    return out


def _locals(decl: Declarations) -> dict[str, sp.Symbol]:
    """Symbols for reading PSD and variance texts (only to find which parameters they use; parsed properly by build)."""
    return {s: sp.Symbol(s, real=True) for s in decl.parameters}
