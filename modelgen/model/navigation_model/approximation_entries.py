"""The ``navigation.approximations`` list: names, scopes (``in:``) and what each mechanization accepts.

Refused with file:line before anything is derived: an unknown name, one listed
twice, one the mechanization does not have, and a scope on an approximation
that changes the model's states or its perturbed equations.
"""

from __future__ import annotations

from typing import Any, Mapping

from modelgen.errors import ModelError
from modelgen.model.mechanizations import MECHANIZATION_APPROXIMATIONS
from modelgen.model.navigation_model.section import SectionReader
from modelgen.model.perturbation.approximations import APPROXIMATIONS, EQUATION_APPROXIMATIONS


#: What an approximation's ``in:`` may name: the rows of F and G of a navigation quantity's error states, or H.
APPROXIMATION_SCOPES = ("attitude", "velocity", "position", "measurements")
#: Approximations that change the model's structure and so cannot be scoped to some rows.
UNSCOPED_APPROXIMATIONS = frozenset({"no_vertical_channel", "damped_vertical_channel"})


def approximation_name(entry: Any) -> Any:
    """The name of an ``approximations`` entry: the text itself, or the ``name`` of ``{name, in}``."""
    return entry.get("name") if isinstance(entry, dict) else entry


def read_approximations(read: SectionReader, section: Mapping, mechanization: str = "local_level") -> tuple[tuple[str, ...], dict[str, tuple[str, ...]]]:
    """The declared approximations' names in order, and the scope (``in:``) of those that have one."""
    raw = section.get("approximations") or []
    if not isinstance(raw, list):
        raise ModelError(f"{read.at('navigation.approximations')}: 'navigation.approximations' must be a list of names")
    scopes: dict[str, tuple[str, ...]] = {}
    names = []
    for i, entry in enumerate(raw):
        key = f"navigation.approximations[{i}]"
        if isinstance(entry, dict):
            read.mapping(entry, key, ("name", "in"), ("name", "in"))
            within = entry["in"] if isinstance(entry["in"], list) else [entry["in"]]
            for quantity in within:
                read.choice(quantity, f"{key}.in", APPROXIMATION_SCOPES)
            if entry["name"] in UNSCOPED_APPROXIMATIONS:
                raise ModelError(f"{read.at(key)}: approximation {entry['name']!r} changes the model's states and cannot be scoped ('in:')")
            if entry["name"] in EQUATION_APPROXIMATIONS:
                raise ModelError(f"{read.at(key)}: approximation {entry['name']!r} changes the perturbed equations and cannot be scoped ('in:')")
            scopes[str(entry["name"])] = tuple(str(q) for q in within)
        names.append(approximation_name(entry))
    for i, name in enumerate(names):
        if not isinstance(name, str) or name not in APPROXIMATIONS:
            raise ModelError(
                f"{read.at(f'navigation.approximations[{i}]')}: unknown approximation {name!r} "
                f"(known: {', '.join(sorted(APPROXIMATIONS))})"
            )
    accepted = MECHANIZATION_APPROXIMATIONS.get(mechanization)
    for i, name in enumerate(names):
        if accepted is not None and name not in accepted:
            raise ModelError(
                f"{read.at(f'navigation.approximations[{i}]')}: approximation {name!r} does not apply to the {mechanization} "
                f"mechanization (it has: {', '.join(sorted(accepted)) or 'none'})"
            )
        if accepted is None and name == "no_gravity_gradient":
            raise ModelError(
                f"{read.at(f'navigation.approximations[{i}]')}: approximation 'no_gravity_gradient' is the ecef mechanization's "
                f"(local level: constant_gravity, free_vertical_channel)"
            )
    if len(set(names)) != len(names):
        raise ModelError(f"{read.at('navigation.approximations')}: an approximation is listed twice: {names}")
    return tuple(str(a) for a in names), scopes
