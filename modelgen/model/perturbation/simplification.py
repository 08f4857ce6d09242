"""Step 5 of the perturbation: Earth functions to parameters, their derivatives to WGS-84 formulas, one simplification.

While deriving, the Earth's radii and gravity are functions of position
(``R_M(L)``, ``R_N(L)``, ``g(L, h)``) so that their derivatives show as terms;
:func:`finish` makes them the model's parameters and the derivatives the
formulas of :func:`earth_derivative_rules` (NIMA TR8350.2), and simplifies every
entry with the one fixed pipeline :func:`simplify_entry`, so that the result is
the same text run to run.  :func:`readable_term` shows a neglected term with the
Earth quantities by name.
"""

from __future__ import annotations

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model import wgs84
from modelgen.model.mechanizations.local_level import EarthSymbols, Gravity, MeridianRadius, PrimeVerticalRadius
from modelgen.model.perturbation.problem import NavigationProblem, Stage


def earth_derivative_rules(latitude: sp.Symbol, height: sp.Symbol, earth: EarthSymbols) -> dict:
    """dR_M/dL, dR_N/dL, dg/dL, dg/dh of WGS-84 (TR8350.2), in the parameter symbols.

    R_M = a (1 - e^2) / w^(3/2), R_N = a / w^(1/2), w = 1 - e^2 sin^2 L:
    dR_M/dL = 3 e^2 sin L cos L R_M / w, dR_N/dL = e^2 sin L cos L R_N / w.
    Normal gravity g = gamma(L) eta(L, h) with Somigliana's gamma =
    gamma_e (1 + k sin^2 L) / w^(1/2) and eta = 1 - 2 h (1 + f + m - 2 f sin^2 L) / a
    + 3 h^2 / a^2 (TR8350.2 eq. 4-3): dg/dL = g sin L cos L (2 k / (1 + k sin^2 L)
    + e^2 / w + 8 f h / (a eta)), dg/dh = g (-2 (1 + f + m - 2 f sin^2 L) / a + 6 h / a^2) / eta.
    """
    L, h = latitude, height
    e2, a = sp.Float(wgs84.ECCENTRICITY_SQUARED), sp.Float(wgs84.SEMI_MAJOR_AXIS)
    f, m, k = sp.Float(wgs84.FLATTENING), sp.Float(wgs84.GRAVITY_RATIO_M), sp.Float(wgs84.SOMIGLIANA_K)
    s, c = sp.sin(L), sp.cos(L)
    w = 1 - e2 * s**2
    eta = 1 - 2 * h * (1 + f + m - 2 * f * s**2) / a + 3 * h**2 / a**2
    g = earth.gravity
    return {
        sp.Derivative(MeridianRadius(L), L): 3 * e2 * s * c * earth.meridian_radius / w,
        sp.Derivative(PrimeVerticalRadius(L), L): e2 * s * c * earth.prime_vertical_radius / w,
        sp.Derivative(Gravity(L, h), L): g * s * c * (2 * k / (1 + k * s**2) + e2 / w + 8 * f * h / (a * eta)),
        sp.Derivative(Gravity(L, h), h): g * (-2 * (1 + f + m - 2 * f * s**2) / a + 6 * h / a**2) / eta,
        MeridianRadius(L): earth.meridian_radius,
        PrimeVerticalRadius(L): earth.prime_vertical_radius,
        Gravity(L, h): g,
    }


def simplify_entry(expr: sp.Expr) -> sp.Expr:
    """The one simplification pipeline: ``expand`` (sums of products; equal bases combine).

    Deterministic and fast (no heuristic ``simplify``): the same expression
    gives the same text on every run, and what ``modelgen.derivation.symbolic``
    does to every model's entries (``expand``) leaves it unchanged.
    """
    return sp.expand(expr) if expr != 0 else sp.S.Zero


def finish(stage: Stage, problem: NavigationProblem) -> Stage:
    """Earth functions to parameters, derivatives to formulas (with (L, h) shown in the Derivative objects), simplified."""
    rules = earth_derivative_rules(problem.position[0], problem.position[2], problem.earth)
    mech = problem.mechanization()
    if hasattr(mech, "earth_function_rules"):  # the mechanization's own Earth functions (ecef: |r^e|; wander: its chart)
        rules.update(mech.earth_function_rules(problem.position, problem.earth))
    derivatives = {k: v for k, v in rules.items() if isinstance(k, sp.Derivative)}
    values = {k: v for k, v in rules.items() if not isinstance(k, sp.Derivative)}
    out = []
    for m in (stage.F, stage.G, stage.H):
        m = m.xreplace(derivatives).xreplace(values)
        leftover = m.atoms(sp.Derivative)
        if leftover:
            raise ModelError(f"derivation left derivatives it has no rule for: {sorted(map(str, leftover))}")
        out.append(m.applyfunc(simplify_entry))
    return Stage(*out)


def readable_term(term: sp.Expr, problem: NavigationProblem) -> str:
    """A neglected term with the Earth quantities by name: ``R_M``, ``dR_M/dL``, ``g``, ``dg/dh``."""
    L, h = problem.position[0], problem.position[2]
    names = {
        sp.Derivative(MeridianRadius(L), L): "dR_M/dL", sp.Derivative(PrimeVerticalRadius(L), L): "dR_N/dL",
        sp.Derivative(Gravity(L, h), L): "dg/dL", sp.Derivative(Gravity(L, h), h): "dg/dh",
        MeridianRadius(L): str(problem.earth.meridian_radius), PrimeVerticalRadius(L): str(problem.earth.prime_vertical_radius),
        Gravity(L, h): str(problem.earth.gravity),
    }
    shown = term.xreplace({k: sp.Symbol(v) for k, v in names.items()})
    return sp.sstr(sp.factor_terms(sp.cancel(sp.together(shown))))
