"""Inferring a value the OCR lost from one of the paper's own results.

The Doppler white-noise rms (Table 1 says only "white noise") is the one
input the integrated results depend on strongly.  It is inferred as the value
for which the optimal 18-state filter's velocity error at the end of the run
equals the paper's (Table 2, optimal row, mean of dV_n and dV_e).  The value
written in error_budget_000.yaml is this result, rounded; all other
integrated-system cells are then predictions.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from modelgen.table2.budget import ErrorBudget
from modelgen.analysis.covariance import discretize, optimal_filter_covariance
from modelgen.table2.metrics import navigation_errors
from modelgen.table2.scenario import AnalysisScenario, operating_point
from modelgen.table2.systems import PaperModels
from modelgen.errors import ModelError

DOPPLER_NOISE_PARAMETERS = ("doppler_noise_sigma_north", "doppler_noise_sigma_east")


def optimal_velocity_error(models: PaperModels, scenario: AnalysisScenario, budget: ErrorBudget, doppler_sigma: float) -> float:
    """Mean of the optimal filter's final dV_n, dV_e errors (nmile/h) for a Doppler noise rms (m/s)."""
    noise = {p: doppler_sigma for p in DOPPLER_NOISE_PARAMETERS}
    values = {**budget.parameters, **noise, **operating_point(scenario)}
    truth = discretize(models.truth, values, scenario.step_s, scenario.taylor_order)
    cov = optimal_filter_covariance(truth, budget.initial_covariance(models.truth.model), scenario.steps)
    errors = navigation_errors(cov[-1:], truth.state_names, scenario.latitude, scenario.earth_radius, np.array([1.0]))
    return 0.5 * float(errors["velocity_error_north"][-1] + errors["velocity_error_east"][-1])


def infer_doppler_noise(
    models: PaperModels, scenario: AnalysisScenario, budget: ErrorBudget, target_velocity_error: float
) -> float:
    """Doppler noise rms (m/s) giving the target optimal velocity error (nmile/h)."""
    low, high = 1e-3, 10.0
    f_low = optimal_velocity_error(models, scenario, budget, low) - target_velocity_error
    f_high = optimal_velocity_error(models, scenario, budget, high) - target_velocity_error
    if f_low * f_high > 0:
        raise ModelError(
            f"no Doppler noise between {low} and {high} m/s gives an optimal velocity error of {target_velocity_error} nmile/h"
        )
    return float(
        brentq(lambda s: optimal_velocity_error(models, scenario, budget, s) - target_velocity_error, low, high, xtol=1e-6)
    )
