"""What the declared approximations dropped, as the model's notes and as records.

:func:`approximation_notes` writes one note per approximation: what it is and each
term it removed, with its size at the file's check scenario;
:func:`neglected_terms` returns the records carried on the model (the full
first-order linearization is its F, G, H plus these, for the cross-check).
"""

from __future__ import annotations

from typing import Any, Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model import wgs84
from modelgen.model.navigation_model.approximation_entries import approximation_name
from modelgen.model.navigation_model.section import Declarations
from modelgen.model.perturbation.approximations import APPROXIMATION_DESCRIPTIONS
from modelgen.model.perturbation.problem import ErrorEquations, NeglectedTerm


def approximation_notes(data: Mapping, equations: ErrorEquations, decl: Declarations,
                        implied: Mapping[str, str] | None = None) -> list[str]:
    """One note per approximation: what it is and each term it dropped, with its size at the check scenario.

    The declared ones in their order, then those ``implied`` (name -> the key of the entry that makes it whether
    declared or not, such as a pseudo-range's) that the file does not declare, so that none goes unlisted."""
    values = _check_values(data, decl)
    names = {"F": ([s.name for s in decl.states], [s.name for s in decl.states]),
             "G": ([s.name for s in decl.states], [n.name for n in decl.noises])}
    approximations = [approximation_name(a) for a in data["navigation"].get("approximations") or []]
    scopes = {approximation_name(a): a["in"] for a in data["navigation"].get("approximations") or [] if isinstance(a, dict)}
    made_by = {name: key for name, key in (implied or {}).items() if name not in approximations}
    notes = []
    for name in [*approximations, *made_by]:
        terms = [(t, shown) for t, shown in zip(equations.neglected, equations.readable) if t.approximation == name]
        parts = []
        for t, text in terms:
            rows, columns = names.get(t.matrix, (list(map(str, equations.measurements)), [s.name for s in decl.states]))
            size = term_magnitude(t.term, values)
            row = rows[t.row] if t.row >= 0 else "a removed vertical state"
            column = columns[t.column] if t.column >= 0 else "a removed vertical state"
            shown = f" = {text}" if len(text) <= 120 else ""
            parts.append(f"{t.matrix}[{row}, {column}]{shown}" + (f" ({size:.3g})" if size is not None else ""))
        dropped = "; ".join(parts) if parts else "no term in this model"
        within = scopes.get(name)
        scope = f", in the {', '.join(within) if isinstance(within, list) else within} rows only" if within else ""
        scope += f"; made by {made_by[name]}, declared or not" if name in made_by else ""
        notes.append(f"Approximation {name} ({APPROXIMATION_DESCRIPTIONS[name]}{scope}): dropped {dropped} (term, and its size at the check scenario).")
    if (approximations or made_by) and not values:
        notes.append("The sizes above need a check: scenario; this model has none.")
    return notes


def _check_values(data: Mapping, decl: Declarations) -> dict[sp.Symbol, float]:
    """Parameter values of the file's check scenario (SI) and defaults, by symbol; empty without a scenario.

    Quantities an approximation removed from the model (so the scenario cannot
    give them) take their value at the scenario: height 0 and vertical velocity
    0 if absent, WGS-84 radii and normal gravity at the scenario's latitude.
    """
    from modelgen.model.check_scenario import parse_check_section
    from modelgen.model.navlib import normal_gravity

    values = {p.name: p.value for p in decl.parameters.values() if p.value is not None}
    if "check" in data:
        try:
            values.update(parse_check_section(data["check"], {}, "<check>").get("parameters", {}))
        except ModelError:
            pass  # the loader reports it with file:line
    values.setdefault("height", 0.0)
    for name in ("velocity_down", "velocity_up"):
        values.setdefault(name, 0.0)
    if "latitude" in values:
        radii = wgs84.earth_radii(values["latitude"])
        values.setdefault("meridian_radius", radii[0])
        values.setdefault("prime_vertical_radius", radii[1])
        values.setdefault("gravity", float(normal_gravity(values["latitude"], values["height"])))
    return {sp.Symbol(p.symbol, real=True): values[p.name] for p in decl.parameters.values() if p.name in values}


def term_magnitude(term: sp.Expr, values: Mapping[sp.Symbol, float]) -> float | None:
    """|term| at the given values, or None if a value is missing."""
    number = sp.sympify(term).xreplace({k: sp.Float(v) for k, v in values.items()})  # a bare symbol becomes a Float, not a float
    if number.free_symbols:
        return None
    return abs(float(number))


def neglected_terms(model: Any) -> tuple[NeglectedTerm, ...]:
    """The terms the declared approximations dropped from a navigation model (carried on the model: ``model.neglected``).

    Its F, G, H entries plus these terms are the full first-order
    linearization (for the cross-check).  ``model`` is the ErrorModel or a
    derived model (which carries it); a model written as equations has none.
    """
    if isinstance(model, str):
        raise ModelError(f"neglected_terms takes the loaded model, not its name {model!r} (load_model({model!r}).neglected)")
    model = getattr(model, "model", model)  # a DerivedModel carries its ErrorModel
    return tuple(model.neglected)
