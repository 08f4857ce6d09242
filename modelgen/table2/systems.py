"""The six navigation systems of Table 2: pure inertial, optimal, suboptimal I-IV.

:class:`PaperModels` derives the symbolic matrices of every model once (the
18-state truth, its 16-state pure-inertial form and each filter's reduced
model, all made by ``modelgen.model.transform``); :func:`analyse_systems` then only
evaluates, discretizes and runs the recursions for one scenario and budget,
so sensitivity studies are cheap.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from modelgen.table2.budget import ErrorBudget
from modelgen.analysis.covariance import (
    discretize,
    filter_gains,
    optimal_filter_covariance,
    propagate_covariance,
    true_error_covariance,
)
from modelgen.table2.metrics import navigation_errors
from modelgen.table2.scenario import AnalysisScenario, operating_point
from modelgen.table2.suboptimal import PAPER_FILTERS, FilterDesign, filter_model, filter_parameters, gain_schedule
from modelgen.derivation.symbolic import DerivedModel, derive
from modelgen.model.transform import keep_states

PURE_INERTIAL = "pure_inertial"
DOPPLER_STATES = ("doppler_velocity_bias_north", "doppler_velocity_bias_east")


@dataclass(frozen=True)
class PaperModels:
    """Derived truth, pure-inertial and filter models (built once)."""

    truth: DerivedModel
    pure_inertial: DerivedModel
    filters: dict[str, DerivedModel]
    designs: tuple[FilterDesign, ...]

    @classmethod
    def build(cls, truth: DerivedModel, designs: Sequence[FilterDesign] = PAPER_FILTERS) -> "PaperModels":
        """The paper's systems made from ``truth``, the full 18-state model the caller derived."""
        full = truth.model
        pure = keep_states(
            full,
            [s for s in full.state_names if s not in DOPPLER_STATES],
            name=f"{full.name}_pure_inertial",
            title="pure-inertial form (Doppler states and measurements dropped)",
        )
        filters = {d.key: (truth if not d.reduced else derive(filter_model(full, d))) for d in designs}
        return cls(truth, derive(pure), filters, tuple(designs))

    def with_designs(self, designs: Sequence[FilterDesign]) -> "PaperModels":
        """Other filter designs on the same truth; a filter model already derived is reused."""
        known = {_structure(d): self.filters[d.key] for d in self.designs}
        filters = {}
        for d in designs:
            if _structure(d) not in known:
                known[_structure(d)] = self.truth if not d.reduced else derive(filter_model(self.truth.model, d))
            filters[d.key] = known[_structure(d)]
        return PaperModels(self.truth, self.pure_inertial, filters, tuple(designs))


def _structure(design: FilterDesign) -> tuple:
    """What determines a design's filter model (not its gain schedule)."""
    return (design.white_states, design.lumps, design.whitening if design.white_states else None)


@dataclass(frozen=True)
class SystemResult:
    """Error covariance history of one system, and its errors in the paper's units."""

    key: str
    label: str
    filter_states: int  # 0 for the pure-inertial system
    state_names: tuple[str, ...]
    covariance: np.ndarray  # (steps+1, n, n), SI, error of the (compensated) output
    errors: dict[str, np.ndarray]  # time series in the paper's units, see metrics.py


def analyse_systems(models: PaperModels, scenario: AnalysisScenario, budget: ErrorBudget) -> dict[str, SystemResult]:
    """Run all systems for 4 h; keys: the designs' keys, then ``pure_inertial``."""
    values = {**budget.parameters, **operating_point(scenario)}
    steps, T, order = scenario.steps, scenario.step_s, scenario.taylor_order
    times = scenario.times_h()

    def result(key: str, label: str, n_filter: int, names: Sequence[str], cov: np.ndarray) -> SystemResult:
        errors = navigation_errors(cov, names, scenario.latitude, scenario.earth_radius, times)
        return SystemResult(key, label, n_filter, tuple(names), cov, errors)

    truth = discretize(models.truth, values, T, order)
    P0 = budget.initial_covariance(models.truth.model)
    out: dict[str, SystemResult] = {}
    for design in models.designs:
        derived = models.filters[design.key]
        n_filter = derived.n_states
        if not design.reduced and design.gain_period == 1 and design.manoeuvre_gain_period == 1:
            cov = optimal_filter_covariance(truth, P0, steps)  # eq. (12): accuracy = filter covariance
        else:
            filter_values = filter_parameters(design, values, budget.initial_sigma)
            filt = discretize(derived, filter_values, T, order)
            P0_filter = budget.initial_covariance(derived.model)
            gains, _ = filter_gains(filt, P0_filter, steps, gain_schedule(design, scenario))
            cov = true_error_covariance(truth, filt, P0, gains)
        out[design.key] = result(design.key, design.label, n_filter, truth.state_names, cov)

    pure = discretize(models.pure_inertial, values, T, order)
    cov = propagate_covariance(pure, budget.initial_covariance(models.pure_inertial.model), steps)  # eq. (9)
    out[PURE_INERTIAL] = result(PURE_INERTIAL, "I (inertial)", 0, pure.state_names, cov)
    return out
