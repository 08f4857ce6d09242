"""The error definition: the declared attitude, velocity and position error states and their forms.

``navigation.errors`` says, per quantity, the form of its error (phi, psi or
rotation vector; difference or computed-frame velocity; geodetic or metres
position) and the states' symbols and names (generated when not given);
:func:`read_error_definition` declares the states and returns the
:class:`~modelgen.model.perturbation.problem.ErrorDefinition` the engine perturbs.
"""

from __future__ import annotations

from typing import Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.declaration import State
from modelgen.model.mechanizations import MECHANIZATION_ERROR_FORMS
from modelgen.model.navigation_model.approximation_entries import approximation_name
from modelgen.model.navigation_model.section import (
    ERROR_QUANTITIES,
    Declarations,
    SectionReader,
    axis_words,
    vector_symbols,
)
from modelgen.model.perturbation.problem import (
    ATTITUDE_AXES,
    ATTITUDE_FORMS,
    POSITION_FORMS,
    VELOCITY_FORMS,
    ErrorDefinition,
)


_ERROR_FORMS = {"attitude": ATTITUDE_FORMS, "velocity": VELOCITY_FORMS, "position": POSITION_FORMS}
_ERROR_DEFAULTS = {"attitude": ("phi", "phi"), "velocity": ("difference", "dv"), "position": ("geodetic", "d")}


def read_error_definition(
    read: SectionReader, section: Mapping, frame: str, decl: Declarations, mechanization: str = "local_level"
) -> tuple[ErrorDefinition, list[sp.Symbol]]:
    """The declared navigation error states (in the file's order) and their definition."""
    errors = read.mapping(section.get("errors"), "navigation.errors", (*ERROR_QUANTITIES,))
    missing = [q for q in ERROR_QUANTITIES if q not in errors]
    if missing:
        raise ModelError(
            f"{read.at('navigation.errors')}: the error definition has no {', '.join(missing)} error; the {mechanization.replace('_', '-')} "
            f"mechanization integrates attitude, velocity and position, and each needs its error states"
        )
    own_forms = MECHANIZATION_ERROR_FORMS.get(mechanization) or {}
    chosen: dict[str, tuple[str, list[str]]] = {}
    order: list[sp.Symbol] = []
    approximations = section.get("approximations")
    horizontal = isinstance(approximations, list) and "no_vertical_channel" in [approximation_name(a) for a in approximations]
    for quantity in errors:
        key = f"navigation.errors.{quantity}"
        entry = read.mapping(errors[quantity], key, ("form", "symbols", "symbol", "names", "axes") if quantity == "attitude" else ("form", "symbols", "symbol", "names"))
        default_form = own_forms[quantity][0] if quantity in own_forms else _ERROR_DEFAULTS[quantity][0]
        form = read.choice(entry.get("form", default_form), f"{key}.form", _ERROR_FORMS[quantity])
        if quantity in own_forms and form not in own_forms[quantity]:
            raise ModelError(
                f"{read.at(f'{key}.form')}: {key}.form {form!r} is a local-level form (it follows the frame's turning with "
                f"position); the {mechanization} mechanization's {quantity} error is {', '.join(own_forms[quantity])}"
            )
        count = 2 if horizontal and quantity != "attitude" else 3  # no_vertical_channel: horizontal components only
        if quantity == "attitude":
            attitude_axes = read.choice(entry.get("axes", "navigation"), f"{key}.axes", ATTITUDE_AXES)
            if attitude_axes == "body" and form != "rotation_vector":
                raise ModelError(f"{read.at(f'{key}.axes')}: {key}.axes body is for form rotation_vector (phi and psi are navigation-frame angles)")
        body_attitude = quantity == "attitude" and attitude_axes == "body"
        if "symbols" in entry:
            symbols = read.names(entry["symbols"], f"{key}.symbols", count)
        elif quantity == "position" and form == "geodetic":
            symbols = ["dL", "dlambda", "dh"][:count]
        else:
            default_symbol = "dr" if quantity == "position" else "theta" if body_attitude else _ERROR_DEFAULTS[quantity][1]
            symbols = vector_symbols(read, entry, key, default_symbol, frame, "body" if body_attitude else None)[:count]
        if body_attitude:
            names = [f"attitude_error_{w}" for w in "xyz"]
        elif quantity == "attitude":
            names = [f"attitude_error_{w}" for w in axis_words(frame, None)]
        elif quantity == "velocity":
            names = [f"velocity_error_{w}" for w in axis_words(frame, None)]
        elif form == "geodetic":
            names = ["latitude_error", "longitude_error", "height_error"]
        else:
            names = [f"position_error_{w}" for w in axis_words(frame, None)]
        names = read.names(entry["names"], f"{key}.names", count) if "names" in entry else names[:count]
        units = {"attitude": ["rad"] * 3, "velocity": ["m/s"] * 3, "position": ["rad", "rad", "m"] if form == "geodetic" else ["m"] * 3}[quantity][:count]
        label = {"phi": "phi-angle", "psi": "psi-angle", "rotation_vector": "rotation vector"}.get(form, form)
        if quantity == "attitude" and form == "rotation_vector":
            label += ", body axes" if body_attitude else f", {frame} axes"
        for name, symbol, unit in zip(names, symbols, units):
            decl.states.append(State(name=name, symbol=symbol, unit=unit, description=f"{quantity} error ({label}), computed minus true"))
            decl.places[("state", name)] = key
        chosen[quantity] = (form, symbols)
        order.extend(sp.Symbol(s, real=True) for s in symbols)
    S = lambda names: tuple(sp.Symbol(s, real=True) for s in names)  # noqa: E731
    definition = ErrorDefinition(
        chosen["attitude"][0], S(chosen["attitude"][1]), chosen["velocity"][0], S(chosen["velocity"][1]),
        chosen["position"][0], S(chosen["position"][1]), attitude_axes,
    )
    return definition, order
