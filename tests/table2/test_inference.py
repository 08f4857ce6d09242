"""The Doppler noise inferred from the paper's optimal velocity error (modelgen.table2.inference)."""

from __future__ import annotations

import pytest

from modelgen.table2.budget import load_error_budget
from modelgen.table2.inference import infer_doppler_noise, optimal_velocity_error
from modelgen.table2.scenario import load_analysis_scenario
from modelgen.table2.comparison import load_paper_table
from modelgen.errors import ModelError


def test_budget_doppler_noise_is_the_value_inferred_from_the_paper_rounded(paper_systems):
    models, scenario, budget, paper = paper_systems, load_analysis_scenario(), load_error_budget(), load_paper_table()
    target = 0.5 * (paper.values["optimal"]["velocity_error_north"] + paper.values["optimal"]["velocity_error_east"])
    inferred = infer_doppler_noise(models, scenario, budget, target)
    assert budget.parameters["doppler_noise_sigma_north"] == pytest.approx(inferred, rel=5e-3)
    assert optimal_velocity_error(models, scenario, budget, inferred) == pytest.approx(target, rel=1e-5)


def test_optimal_velocity_error_grows_with_doppler_noise(paper_systems):
    models, scenario, budget = paper_systems, load_analysis_scenario(), load_error_budget()
    errors = [optimal_velocity_error(models, scenario, budget, s) for s in (0.05, 0.2, 1.0)]
    assert errors[0] < errors[1] < errors[2]


def test_unreachable_target_is_refused(paper_systems):
    with pytest.raises(ModelError, match="no Doppler noise"):
        infer_doppler_noise(paper_systems, load_analysis_scenario(), load_error_budget(), 1e-6)
