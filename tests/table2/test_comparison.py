"""Table 2: what the paper asserts, checked against our computed covariance analysis.

Bands (fraction of the paper's value), fixed from what is known about the
inputs, not from where our numbers happen to land:

* CORE_BAND = 5 % for the pure-inertial row and the optimal filter's
  predicted cells.  The paper leaves the speed, earth radius, gravity and
  specific-force model unprinted; over their plausible range (300-1000 km/h,
  R = 6371-6378 km, kinematic or gravity-only specific force) these cells move
  by up to ~4 % (pure-inertial alpha at 1000 km/h; see the sensitivity
  section of table2.md), so a reproduction cannot claim more than ~5 %.
* FIT_BAND = 1 % for the optimal filter's velocity errors: the Doppler noise
  was inferred from them (error_budget_000.yaml), so they only check the fit
  (0.2 % from rounding the inferred value).
* The pure-inertial heading is printed only in the text, as "0.5 deg": one
  significant digit, i.e. [0.45, 0.55).
* SUBOPTIMAL_BAND = 15 % for suboptimal filters II-IV: on top of the inputs
  above they depend on design details the paper does not print (how the
  covariance is carried between gain updates, when the first gain is
  computed, the white-noise strength of the reduced filters).

Cells outside their band are listed in GAPS with the reason; for them the test
checks what any correct result must satisfy (a suboptimal filter's true
error is at least the optimal filter's, and below pure inertial) and that the
gap is still there, so the list stays true.
"""

from __future__ import annotations

import pytest

from modelgen.table2.budget import load_error_budget
from modelgen.table2.metrics import final_values
from modelgen.table2.scenario import load_analysis_scenario
from modelgen.table2.systems import PURE_INERTIAL, analyse_systems
from modelgen.table2.comparison import COLUMNS, IMPROVEMENT_COLUMNS, load_paper_table, table_rows

CORE_BAND, FIT_BAND, SUBOPTIMAL_BAND = 0.05, 0.01, 0.15
INTEGRATED = ("optimal", "suboptimal_1", "suboptimal_2", "suboptimal_3", "suboptimal_4")
SUBOPTIMAL = INTEGRATED[1:]

REPRODUCED = {
    PURE_INERTIAL: {c: CORE_BAND for c in ("attitude_error_north", "attitude_error_east", "velocity_error_north",
                                           "velocity_error_east", "position_cep", "average_drift_rate")},
    "optimal": {
        "attitude_error_north": CORE_BAND,
        "attitude_error_east": CORE_BAND,
        "velocity_error_north": FIT_BAND,
        "velocity_error_east": FIT_BAND,
        "position_cep": CORE_BAND,
        "doppler_bias_error_north": CORE_BAND,
        "doppler_bias_error_east": CORE_BAND,
    },
    "suboptimal_2": {c: SUBOPTIMAL_BAND for c in ("velocity_error_east", "position_cep", "doppler_bias_error_east")},
    "suboptimal_3": {c: SUBOPTIMAL_BAND for c in ("attitude_error_north", "velocity_error_north", "velocity_error_east",
                                                  "position_cep", "doppler_bias_error_north", "doppler_bias_error_east")},
    "suboptimal_4": {c: SUBOPTIMAL_BAND for c in ("attitude_error_north", "velocity_error_north", "position_cep",
                                                  "doppler_bias_error_north")},
}

_WHITE = "low-frequency white noise (2 sigma^2/mu) makes the reduced filter over-trust the Doppler velocity"
_ASYM = "paper's suboptimal rows are north/east asymmetric, our model's channels behave alike"
GAPS = {
    **{("suboptimal_1", c.key): _WHITE for c in COLUMNS[:7]},
    ("suboptimal_2", "attitude_error_north"): "held gain hardly disturbs level attitude in our model",
    ("suboptimal_2", "attitude_error_east"): _ASYM,
    ("suboptimal_2", "velocity_error_north"): _ASYM,
    ("suboptimal_2", "doppler_bias_error_north"): _ASYM,
    ("suboptimal_3", "attitude_error_east"): _ASYM,
    ("suboptimal_4", "attitude_error_east"): _ASYM,
    ("suboptimal_4", "velocity_error_east"): _ASYM,
    ("suboptimal_4", "doppler_bias_error_east"): _ASYM,
}


@pytest.fixture(scope="module")
def results(paper_systems):
    return analyse_systems(paper_systems, load_analysis_scenario(), load_error_budget())


@pytest.fixture(scope="module")
def final(results):
    return {k: final_values(r.errors) for k, r in results.items()}


@pytest.fixture(scope="module")
def paper():
    return load_paper_table()


def test_every_paper_cell_is_either_reproduced_or_a_documented_gap(paper):
    for system, values in paper.values.items():
        for column in values:
            if column == "heading_error":
                continue
            listed = column in REPRODUCED.get(system, {}) or (system, column) in GAPS
            assert listed, f"{system} {column} is neither checked against a band nor listed as a gap"


@pytest.mark.parametrize("system,column,band", [(s, c, b) for s, cols in REPRODUCED.items() for c, b in cols.items()])
def test_reproduced_cell_lies_within_its_band_of_the_paper(final, paper, system, column, band):
    ours, theirs = final[system][column], paper.values[system][column]
    assert abs(ours / theirs - 1.0) <= band, f"{system} {column}: ours {ours:.4g}, paper {theirs:.4g}"


@pytest.mark.parametrize("system,column", sorted(GAPS))
def test_gap_cell_is_plausible_and_the_gap_is_real(final, paper, system, column):
    ours = final[system][column]
    assert ours >= final["optimal"][column] * (1 - 1e-9)  # no filter beats the optimal one
    if column in final[PURE_INERTIAL]:
        assert ours < final[PURE_INERTIAL][column]
    ratio = ours / paper.values[system][column]
    assert abs(ratio - 1.0) > SUBOPTIMAL_BAND, f"{system} {column} is reproduced now (ratio {ratio:.2f}): move it to REPRODUCED"


def test_pure_inertial_heading_error_is_the_papers_half_degree(final):
    assert 0.45 <= final[PURE_INERTIAL]["heading_error"] < 0.55


def test_optimal_filter_is_best_and_suboptimal_filters_lie_between_it_and_pure_inertial(final):
    cep = {k: final[k]["position_cep"] for k in final}
    for k in SUBOPTIMAL:
        assert cep["optimal"] < cep[k] < cep[PURE_INERTIAL]
    # III adds II's held gain to I's reduced model; IV reduces further still
    assert cep["suboptimal_2"] < cep["suboptimal_3"] < cep["suboptimal_4"]


def test_optimal_filter_error_is_smallest_in_every_state_at_every_time(results):
    import numpy as np

    optimal = np.einsum("kii->ki", results["optimal"].covariance)
    for k in SUBOPTIMAL:
        assert np.all(np.einsum("kii->ki", results[k].covariance) >= optimal * (1 - 1e-9) - 1e-30), k


def test_integrated_systems_reach_about_1_nmile_per_hour(final):
    """Abstract and conclusion 2: 1 nmile/h with 0.1 deg/h gyros and 1e-4 g accelerometers."""
    for k in INTEGRATED:
        assert final[k]["average_drift_rate"] <= 1.0, k
        assert final[k]["velocity_error_north"] <= 1.0 and final[k]["velocity_error_east"] <= 1.0, k
    assert final[PURE_INERTIAL]["average_drift_rate"] > 5.0  # "cannot meet the navigation requirement"


def test_improvement_ratio_is_the_papers_formula(results, paper):
    rows = {r.key: r for r in table_rows(results, paper)}
    pure = rows[PURE_INERTIAL].ours
    for k in INTEGRATED:
        for c in IMPROVEMENT_COLUMNS:
            assert rows[k].improvement_ours[c] == pytest.approx((pure[c] - rows[k].ours[c]) / pure[c])
    assert rows[PURE_INERTIAL].improvement_ours == {}


def test_paper_table_has_all_of_table_2(paper):
    assert set(paper.values) == set(INTEGRATED) | {PURE_INERTIAL}
    for k in INTEGRATED:
        assert len(paper.values[k]) == 7 and len(paper.improvement[k]) == 5
