"""The operating points the jobs check and analyse a model at.

``--check`` flies a model's own check scenario (the ``check:`` section of its
file), else a synthetic, well-conditioned operating point labelled as such;
the core paper's model is also flown at the paper's level flight (Table 1
statistics, 240 steps of 60 s), which ``modelgen observability`` uses too
when it covers the model's parameters.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from modelgen.checks.code_check import CheckScenario
    from modelgen.derivation.symbolic import DerivedModel


def synthetic_scenario(derived: DerivedModel, seed: int = 0, steps: int = 100) -> CheckScenario:
    """A well-conditioned operating point for checking code of a model without a ``check:`` section.

    Parameters without a default are drawn from [0.2, 1.0]; the step is
    chosen so that ||F T|| is about 0.5, which keeps the Taylor series and the
    covariance well scaled whatever the model's units.  It checks the code,
    not the navigation (an attitude matrix drawn so is no rotation), and says
    so in its label.
    """
    from modelgen.checks.code_check import CheckScenario

    rng = np.random.default_rng(seed)
    values = {p.name: float(rng.uniform(0.2, 1.0)) for p in derived.model.parameters if p.value is None}
    F = derived.numeric(values)["F"]
    norm = float(np.linalg.norm(F, 2))
    step = 0.5 / norm if norm > 0 else 1.0
    x0 = rng.standard_normal(derived.n_states)
    label = "synthetic operating point (the model declares no check: section; parameters drawn from [0.2, 1])"
    return CheckScenario(values, np.eye(derived.n_states), step=step, steps=steps, seed=seed, initial_state=x0, label=label)


def paper_parameters() -> dict[str, float]:
    """The core paper's level-flight operating point and Table 1 statistics, by ned_doppler18 parameter name."""
    from modelgen.table2.budget import load_error_budget
    from modelgen.table2.scenario import load_analysis_scenario, operating_point

    return {**load_error_budget().parameters, **operating_point(load_analysis_scenario())}


def paper_scenario(derived: DerivedModel) -> CheckScenario:
    """The core paper's 4-hour scenario: level flight, Table 1 errors, T = 60 s."""
    from modelgen.table2.budget import load_error_budget
    from modelgen.table2.scenario import load_analysis_scenario
    from modelgen.checks.code_check import CheckScenario

    flight, budget = load_analysis_scenario(), load_error_budget()
    values = paper_parameters()
    label = "the core paper's scenario (level flight east at 30 N, Table 1, 240 steps of 60 s)"
    return CheckScenario(values, budget.initial_covariance(derived.model), step=flight.step_s, steps=flight.steps, label=label)


def declared_scenario(derived: DerivedModel) -> CheckScenario | None:
    """The scenario of the model file's ``check:`` section (modelgen.model.check_scenario), if it has one.

    The initial state is drawn from N(0, P(0)) with the section's seed, so the
    state propagation is exercised too, not only the covariance.
    """
    from modelgen.checks.code_check import CheckScenario

    spec = derived.model.check
    if spec is None:
        return None
    P0 = spec.covariance(derived.model.state_names, derived.model.name)
    rng = np.random.default_rng(spec.seed + 1)  # not the measurement stream's seed
    x0 = np.sqrt(np.diag(P0)) * rng.standard_normal(derived.n_states)
    label = f"the model's check scenario ({spec.steps} steps of {spec.step_s:g} s)"
    return CheckScenario(spec.parameter_values(), P0, step=spec.step_s, steps=spec.steps, seed=spec.seed, initial_state=x0, label=label,
                         where=spec.where)


def check_scenario(derived: DerivedModel) -> CheckScenario:
    """What ``--check`` flies: the model's declared scenario, else the synthetic one (labelled so)."""
    return declared_scenario(derived) or synthetic_scenario(derived)


def paper_operating_point(derived: DerivedModel) -> dict[str, float] | None:
    """The paper's level-flight values, when they cover every parameter of the model."""
    values = paper_parameters() if derived.model.frame == "NED" else {}
    needed = {p.name for p in derived.model.parameters if p.value is None}
    return values if values and needed <= set(values) else None


def observability_defaults(derived: DerivedModel) -> tuple[str, dict[str, float], float | None] | None:
    """The operating point ``modelgen observability`` uses without a scenario file: label, values, step.

    The core paper's level flight where it covers the model's parameters, else
    the model file's own check scenario (its values and step), else none.
    """
    paper = paper_operating_point(derived)
    if paper:
        return "the core paper's level flight (30 N, east, 300 km/h, Table 1 statistics)", paper, None
    spec = derived.model.check
    if spec is not None:
        return f"the model's check scenario (steps of {spec.step_s:g} s)", spec.parameter_values(), spec.step_s
    return None
