"""How much the 4-h results depend on the values we chose and on design readings.

Each case changes one thing against the baseline (scenario_000.yaml,
error_budget_000.yaml, the paper's filters as read in suboptimal.py) and
reruns all six systems.  Cases:

* values the OCR lost: Doppler white noise (inferred), cruise speed (printed
  3000 km/h, read as 300), earth radius, specific force model;
* readings of the paper's filter designs: white-noise strength of the
  reduced filters (low-frequency equivalent vs the Markov driving noise's own
  strength), and N = 6 throughout for the piecewise-constant gain.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Sequence

from modelgen.table2.budget import ErrorBudget
from modelgen.table2.metrics import final_values
from modelgen.table2.scenario import AnalysisScenario
from modelgen.table2.suboptimal import PAPER_FILTERS, FilterDesign
from modelgen.table2.systems import PURE_INERTIAL, PaperModels, analyse_systems
from modelgen.model.units import to_si

SYSTEM_ORDER = ("optimal", "suboptimal_1", "suboptimal_2", "suboptimal_3", "suboptimal_4", PURE_INERTIAL)


@dataclass(frozen=True)
class SensitivityCase:
    label: str
    scenario: AnalysisScenario
    budget: ErrorBudget
    designs: tuple[FilterDesign, ...] = PAPER_FILTERS


@dataclass(frozen=True)
class SensitivityResult:
    label: str
    final: dict[str, dict[str, float]]  # system key -> quantity -> 4-h value (paper units)


def _with_doppler_noise(budget: ErrorBudget, sigma: float) -> ErrorBudget:
    return budget.with_parameters(doppler_noise_sigma_north=sigma, doppler_noise_sigma_east=sigma)


def _with_speed(scenario: AnalysisScenario, kmh: float) -> AnalysisScenario:
    north, _, down = scenario.velocity_ned
    return replace(scenario, velocity_ned=(north, to_si(kmh, "km/h"), down))


def default_cases(scenario: AnalysisScenario, budget: ErrorBudget) -> list[SensitivityCase]:
    """The cases of table2.md's sensitivity section."""
    sigma = budget.parameters["doppler_noise_sigma_north"]
    speed = scenario.velocity_ned[1] * 3.6
    cases = [SensitivityCase(f"baseline (Doppler noise {sigma:.3f} m/s, {speed:.0f} km/h)", scenario, budget)]
    for factor in (0.5, 2.0):
        cases.append(SensitivityCase(f"Doppler noise x{factor:g} ({factor * sigma:.3f} m/s)", scenario, _with_doppler_noise(budget, factor * sigma)))
    cases.append(SensitivityCase("Doppler noise 1.0 m/s", scenario, _with_doppler_noise(budget, 1.0)))
    for kmh in (600.0, 1000.0, 3000.0):
        note = " (as printed)" if kmh == 3000.0 else ""
        cases.append(SensitivityCase(f"speed {kmh:.0f} km/h{note}", _with_speed(scenario, kmh), budget))
    cases.append(SensitivityCase("earth radius 6371 km", replace(scenario, earth_radius=6371000.0), budget))
    cases.append(SensitivityCase("specific force gravity only", replace(scenario, specific_force="gravity_only"), budget))
    driving = tuple(
        replace(d, whitening="driving_noise") if d.white_states else d for d in PAPER_FILTERS
    )
    cases.append(SensitivityCase("filters I, III, IV: white noise at driving strength 2 mu sigma^2", scenario, budget, driving))
    n6 = tuple(replace(d, manoeuvre_gain_period=d.gain_period) for d in PAPER_FILTERS)
    cases.append(SensitivityCase("filters II-IV: N = 6 also while manoeuvring", scenario, budget, n6))
    return cases


def run_sensitivity(
    cases: Sequence[SensitivityCase],
    models: PaperModels,
    progress: Callable[[str], None] | None = None,
) -> list[SensitivityResult]:
    """Rerun the six systems for each case (models re-derived only for new designs)."""
    built: dict[tuple[FilterDesign, ...], PaperModels] = {models.designs: models}
    out = []
    for i, case in enumerate(cases):
        if progress:
            progress(f"sensitivity {i + 1}/{len(cases)}: {case.label}")
        if case.designs not in built:
            built[case.designs] = models.with_designs(case.designs)
        results = analyse_systems(built[case.designs], case.scenario, case.budget)
        out.append(SensitivityResult(case.label, {k: final_values(r.errors) for k, r in results.items()}))
    return out


def markdown_sensitivity(results: Sequence[SensitivityResult]) -> str:
    """4-h position CEP (nmile) of every system, plus the optimal velocity and pure-inertial alpha."""
    names = {"optimal": "opt", "suboptimal_1": "I", "suboptimal_2": "II", "suboptimal_3": "III", "suboptimal_4": "IV", PURE_INERTIAL: "pure"}
    head = (
        "| case | " + " | ".join(f"CEP {names[k]}" for k in SYSTEM_ORDER)
        + " | opt dV_n (nmile/h) | opt alpha (\") | pure alpha (\") |"
    )
    lines = [head, "|---|" + "---:|" * (len(SYSTEM_ORDER) + 3)]
    for r in results:
        ceps = " | ".join(f"{r.final[k]['position_cep']:.2f}" for k in SYSTEM_ORDER)
        lines.append(
            f"| {r.label} | {ceps} | {r.final['optimal']['velocity_error_north']:.3f} | "
            f"{r.final['optimal']['attitude_error_north']:.2f} | {r.final[PURE_INERTIAL]['attitude_error_north']:.2f} |"
        )
    return "\n".join(lines)
