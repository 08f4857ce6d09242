"""Covariance recursions (modelgen.analysis.covariance)."""

from __future__ import annotations

import numpy as np
import pytest

from modelgen.table2.budget import load_error_budget
from modelgen.analysis.covariance import (
    discretize,
    filter_gains,
    optimal_filter_covariance,
    propagate_covariance,
    selection_matrix,
    true_error_covariance,
)
from modelgen.table2.scenario import load_analysis_scenario, operating_point
from modelgen.table2.suboptimal import PAPER_FILTERS, filter_parameters
from modelgen.derivation.discretization import van_loan_discretization
from modelgen.errors import ModelError

STEPS = 60  # one hour is enough to exercise every recursion


@pytest.fixture(scope="module")
def setup(paper_systems):
    models, scenario, budget = paper_systems, load_analysis_scenario(), load_error_budget()
    values = {**budget.parameters, **operating_point(scenario)}
    truth = discretize(models.truth, values, scenario.step_s, scenario.taylor_order)
    return models, scenario, budget, values, truth, budget.initial_covariance(models.truth.model)


def test_true_covariance_of_the_optimal_filter_is_its_own_covariance(setup):
    """When the filter model is the truth model, the sensitivity recursion reduces to eq. (12)."""
    _, _, _, _, truth, P0 = setup
    own = optimal_filter_covariance(truth, P0, STEPS)
    gains, _ = filter_gains(truth, P0, STEPS, np.ones(STEPS, dtype=bool))
    true = true_error_covariance(truth, truth, P0, gains)
    scale = np.sqrt(np.outer(np.diag(own[-1]), np.diag(own[-1]))) + 1e-300
    assert np.max(np.abs(true - own) / scale) < 1e-8


def test_held_gain_filter_covariance_in_joseph_form_is_its_true_covariance(setup):
    """Piecewise-constant gain on the right model: Joseph form is exact for any gain."""
    _, _, _, _, truth, P0 = setup
    recompute = np.arange(STEPS) % 6 == 0
    gains, own = filter_gains(truth, P0, STEPS, recompute)
    true = true_error_covariance(truth, truth, P0, gains)
    assert np.allclose(np.diag(true[-1]), np.diag(own[-1]), rtol=1e-8, atol=0)
    assert np.all(np.repeat(gains[::6], 6, axis=0)[:STEPS] == gains)


def test_no_filter_beats_the_optimal_one_in_any_diagonal_element(setup):
    models, scenario, budget, values, truth, P0 = setup
    optimal = np.einsum("kii->ki", optimal_filter_covariance(truth, P0, STEPS))
    design = PAPER_FILTERS[1]  # reduced order
    derived = models.filters[design.key]
    filt = discretize(derived, filter_parameters(design, values, budget.initial_sigma), 60.0, 9)
    gains, own = filter_gains(filt, budget.initial_covariance(derived.model), STEPS, np.ones(STEPS, dtype=bool))
    true = np.einsum("kii->ki", true_error_covariance(truth, filt, P0, gains))
    assert np.all(true >= optimal * (1 - 1e-9))
    # ... and the reduced filter's own covariance is not its accuracy
    i = truth.state_names.index("velocity_error_north")
    j = filt.state_names.index("velocity_error_north")
    assert abs(own[-1][j, j] - true[-1, i]) > 0.1 * true[-1, i]


def test_pure_inertial_propagation_matches_the_exact_exponential(setup):
    models, scenario, budget, values, _, _ = setup
    pure = discretize(models.pure_inertial, values, 60.0, 9)
    m = models.pure_inertial.numeric({k: v for k, v in values.items() if k in models.pure_inertial.model.parameter_names})
    phi, qd = van_loan_discretization(m["F"], m["G"], m["Q"], 60.0)
    P0 = budget.initial_covariance(models.pure_inertial.model)
    taylor = propagate_covariance(pure, P0, STEPS)[-1]
    exact = P0
    for _ in range(STEPS):
        exact = phi @ exact @ phi.T + qd
    assert np.allclose(np.diag(taylor), np.diag(exact), rtol=1e-3)


def test_unestimated_truth_states_keep_their_own_covariance(setup):
    """Open-loop compensation: a state the filter does not carry is not corrected at all."""
    models, scenario, budget, values, truth, P0 = setup
    design = PAPER_FILTERS[4]  # 9 states: no gyro or accelerometer states
    derived = models.filters[design.key]
    filt = discretize(derived, filter_parameters(design, values, budget.initial_sigma), 60.0, 9)
    gains, _ = filter_gains(filt, budget.initial_covariance(derived.model), STEPS, np.ones(STEPS, dtype=bool))
    true = true_error_covariance(truth, filt, P0, gains)
    free = propagate_covariance(truth, P0, STEPS)
    k = truth.state_names.index("gyro_constant_drift_x")
    assert true[-1, k, k] == pytest.approx(free[-1, k, k])


def test_selection_of_a_state_the_truth_lacks_is_named():
    with pytest.raises(ModelError, match="scale_factor.*not states of the truth model"):
        selection_matrix(["alpha", "beta"], ["alpha", "scale_factor"])


def test_gain_schedule_must_start_with_a_gain(setup):
    _, _, _, _, truth, P0 = setup
    with pytest.raises(ModelError, match="recompute at the first step"):
        filter_gains(truth, P0, 3, [False, True, True])
