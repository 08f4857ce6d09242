"""Sensitivity of the 4-h results to the chosen values (modelgen.table2.sensitivity)."""

from __future__ import annotations

from modelgen.table2.budget import load_error_budget
from modelgen.table2.scenario import load_analysis_scenario
from modelgen.table2.sensitivity import default_cases, markdown_sensitivity, run_sensitivity
from modelgen.table2.systems import PURE_INERTIAL


def test_cases_cover_every_lost_value_and_design_reading():
    labels = " ".join(c.label for c in default_cases(load_analysis_scenario(), load_error_budget()))
    for word in ("Doppler noise", "3000 km/h", "earth radius", "specific force", "driving strength", "N = 6"):
        assert word in labels


def test_more_doppler_noise_worsens_every_integrated_system_but_not_pure_inertial(paper_systems):
    cases = default_cases(load_analysis_scenario(), load_error_budget())
    low, base, high = (next(c for c in cases if c.label.startswith(p)) for p in ("Doppler noise x0.5", "baseline", "Doppler noise x2"))
    res = run_sensitivity([low, base, high], paper_systems)
    for k in ("optimal", "suboptimal_1", "suboptimal_2", "suboptimal_3", "suboptimal_4"):
        ceps = [r.final[k]["position_cep"] for r in res]
        assert ceps[0] < ceps[1] < ceps[2], k
    assert res[0].final[PURE_INERTIAL] == res[2].final[PURE_INERTIAL]
    text = markdown_sensitivity(res)
    assert text.count("\n") == 4 and "CEP pure" in text
