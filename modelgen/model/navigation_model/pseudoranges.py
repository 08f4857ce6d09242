"""Pseudo-range and pseudo-range-rate measurements along unit line-of-sight vectors.

Both are exact, nonlinear functions of a position displacement from the
computed receiver; the engine linearizes them.  The measured side carries the
receiver clock's bias (pseudo-range) or drift (pseudo-range rate).
"""

from __future__ import annotations

from typing import Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.navigation_model.section import (
    Declarations,
    MeasurementParts,
    SectionReader,
    axis_words,
    offer,
    symbol_matrix,
)
from modelgen.model.perturbation.problem import Mechanization, NavigationState

#: The approximation every local-level pseudo-range (rate) makes, declared or not: the displacement d from the
#: computed receiver is M (computed) times the position difference (``mech.metres(computed.position)`` below), so a
#: model with such a measurement lists it among its approximations (modelgen.model.navigation_model.approximation_notes).
APPROXIMATION = "pseudorange_at_computed_position"
#: The measurement kinds that make it.
KINDS = ("pseudorange", "pseudorange_rate")


def pseudorange_measurement(read: SectionReader, entry: Mapping, key: str, frame: str, clock: sp.Matrix | None, decl: Declarations) -> MeasurementParts:
    """Pseudo-ranges to satellites along unit line-of-sight vectors e_k (navigation axes, receiver to satellite).

    The range from a point displaced by d (metres, navigation axes) from the
    computed receiver to satellite k at distance rho is
    |rho e_k - d| = sqrt(rho^2 - 2 rho e_k . d + d . d) (|e_k| = 1), exact and
    nonlinear in d; the measured pseudo-range adds the receiver clock bias.
    d is M (computed) times the position difference (:data:`APPROXIMATION`).
    """
    sights = _lines_of_sight(read, entry, key, frame, clock, decl)
    distance = sp.Symbol("satellite_distance", positive=True)

    def ranges(state: NavigationState, computed: NavigationState, mech: Mechanization) -> sp.Matrix:
        d = mech.metres(computed.position) * (state.position - computed.position)
        return sp.Matrix([sp.sqrt(distance**2 - 2 * distance * e.dot(d) + d.dot(d)) for e in sights])

    extra = sp.Matrix([clock[0]] * len(sights))
    return ranges, None, ["m"] * len(sights), len(sights), extra


def _lines_of_sight(read: SectionReader, entry: Mapping, key: str, frame: str, clock: sp.Matrix | None, decl: Declarations) -> list[sp.Matrix]:
    """The unit line-of-sight vectors of a pseudo-range (rate) measurement; it needs the receiver clock."""
    if clock is None:
        raise ModelError(f"{read.at(key)}: a pseudo-range measurement needs a receiver clock (sensor_errors: {{of: receiver_clock, ...}})")
    raw = entry.get("line_of_sight")
    if not isinstance(raw, list) or not raw:
        raise ModelError(f"{read.at(key)}: a pseudo-range measurement needs 'line_of_sight': one list of 3 symbols per satellite")
    words = axis_words(frame, None)
    sights = []
    for k, item in enumerate(raw):
        names = read.names(item, f"{key}.line_of_sight[{k}]", 3)
        for name, word in zip(names, words):
            offer(decl, name, f"line_of_sight_{word}_{k + 1}", "1", f"{word} component of the unit vector from the receiver to satellite {k + 1}")
        sights.append(symbol_matrix(names))
    return sights


def pseudorange_rate_measurement(read: SectionReader, entry: Mapping, key: str, frame: str, clock: sp.Matrix | None, decl: Declarations) -> MeasurementParts:
    """Pseudo-range rates: the relative velocity of satellite k along the line of sight, plus the clock drift.

    From a point displaced by d (metres, navigation axes) from the computed
    receiver, the unit vector to satellite k at distance rho is
    u = (e_k - d/rho) / sqrt(1 - 2 e_k . d/rho + d . d/rho^2) (|e_k| = 1), and the
    rate is u . (v_k - v) with the satellite's velocity v_k (navigation axes,
    ``satellite_velocity``: required, ``zero`` for still satellites on purpose).  ``range`` names rho per satellite.
    """
    sights = _lines_of_sight(read, entry, key, frame, clock, decl)
    words = axis_words(frame, None)
    ranges = read.names(entry.get("range"), f"{key}.range", len(sights)) if "range" in entry else [f"rho_{k + 1}" for k in range(len(sights))]
    for k, name in enumerate(ranges):
        offer(decl, name, f"satellite_range_{k + 1}", "m", f"distance from the receiver to satellite {k + 1}")
    velocities = [sp.zeros(3, 1)] * len(sights)
    if "satellite_velocity" not in entry:
        raise ModelError(
            f"{read.at(key)}: a pseudo-range rate needs 'satellite_velocity' (one list of 3 symbols per satellite, navigation "
            f"axes): GNSS satellites move at about 3.9 km/s, and taking them as still makes the H entries about 50 times too "
            f"small; write 'satellite_velocity: zero' to assume still satellites on purpose"
        )
    if entry["satellite_velocity"] == "zero":
        pass  # still satellites, as the file says
    elif "satellite_velocity" in entry:
        raw = entry["satellite_velocity"]
        if not isinstance(raw, list) or len(raw) != len(sights):
            raise ModelError(f"{read.at(f'{key}.satellite_velocity')}: {key}.satellite_velocity must list one velocity per satellite ({len(sights)})")
        velocities = []
        for k, item in enumerate(raw):
            names = read.names(item, f"{key}.satellite_velocity[{k}]", 3)
            for name, word in zip(names, words):
                offer(decl, name, f"satellite_velocity_{word}_{k + 1}", "m/s", f"{word} velocity of satellite {k + 1}")
            velocities.append(symbol_matrix(names))
    rhos = [sp.Symbol(r, real=True) for r in ranges]

    def rates(state: NavigationState, computed: NavigationState, mech: Mechanization) -> sp.Matrix:
        d = mech.metres(computed.position) * (state.position - computed.position)
        out = []
        for e, rho, v_sat in zip(sights, rhos, velocities):
            u = (e - d / rho) / sp.sqrt(1 - 2 * e.dot(d) / rho + d.dot(d) / rho**2)
            out.append(u.dot(v_sat - state.velocity))
        return sp.Matrix(out)

    extra = sp.Matrix([clock[1]] * len(sights))
    return rates, None, ["m/s"] * len(sights), len(sights), extra
