"""Trade studies in this process: each case is the paper's covariance analysis at the case's values; outputs."""

import csv
import dataclasses
import math
import textwrap

import numpy as np
import pytest

from modelgen.table2.metrics import final_values
from modelgen.table2.systems import PaperModels, analyse_systems
from modelgen.model.units import to_si
from modelgen.study.outputs import csv_text, panel_values, table_columns, write_outputs
from modelgen.study.studyfile import load_study
from modelgen.study.trade import (
    apply_point,
    chunks,
    covariance_setup,
    evaluate_points,
    monte_carlo_profile,
    run_trade,
)

SMALL_GRID = """\
study: small_grid
parameters:
  gyro_drift:
    unit: deg/h
    values: [0.01, 0.1, 1.0]
    sets: [gyro_markov_sigma_x, gyro_markov_sigma_y, gyro_markov_sigma_z,
           initial_sigma.gyro_constant_drift_x, initial_sigma.gyro_constant_drift_y,
           initial_sigma.gyro_constant_drift_z]
    profile: [imu.gyro_markov_drift_dph, imu.gyro_constant_drift_dph]
  doppler_noise:
    unit: m/s
    values: [0.1, 0.5]
    sets: [doppler_noise_sigma_north, doppler_noise_sigma_east]
    profile: [doppler.white_noise_mps]
filters: [optimal, suboptimal_1, suboptimal_2, suboptimal_3, suboptimal_4, pure_inertial]
"""


@pytest.fixture(scope="module")
def small_study(tmp_path_factory):
    path = tmp_path_factory.mktemp("study") / "small.yaml"
    path.write_text(SMALL_GRID, encoding="utf-8")
    return load_study(path)


@pytest.fixture(scope="module")
def small_result(small_study):
    return run_trade(small_study)


def test_a_case_at_table_1s_values_is_the_papers_table_2_analysis(tmp_path, paper_derived):
    text = """\
    study: baseline
    parameters:
      doppler_noise: {unit: m/s, sets: [doppler_noise_sigma_north, doppler_noise_sigma_east]}
      gyro_drift: {unit: deg/h, sets: [gyro_markov_sigma_x, gyro_markov_sigma_y, gyro_markov_sigma_z]}
    cases:
      - {doppler_noise: 0.167, gyro_drift: 0.1}
    """
    path = tmp_path / "baseline.yaml"
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    study = load_study(path)
    result = run_trade(study)
    expected = analyse_systems(PaperModels.build(paper_derived), study.scenario, study.budget)
    assert len(result.cases) == 6
    for case in result.cases:
        assert case.final == {k: v for k, v in final_values(expected[case.filter].errors).items() if k in case.final}
        assert case.final["position_cep"] > 0


def test_apply_point_sets_every_target_in_si(small_study):
    scenario, budget = apply_point(small_study.scenario, small_study.budget, small_study.parameters, (0.3, 0.25))
    assert budget.parameters["gyro_markov_sigma_y"] == pytest.approx(to_si(0.3, "deg/h"))
    assert budget.initial_sigma["gyro_constant_drift_z"] == pytest.approx(to_si(0.3, "deg/h"))
    assert budget.parameters["doppler_noise_sigma_east"] == 0.25
    assert budget.initial_sigma["gyro_markov_drift_x"] == small_study.budget.initial_sigma["gyro_markov_drift_x"]
    assert scenario == small_study.scenario


def test_the_optimal_filter_is_never_worse_and_gets_worse_with_the_gyro(small_study, small_result):
    cep = {(c.point, c.filter): c.final["position_cep"] for c in small_result.cases}
    assert len(cep) == small_study.case_count == 36
    for point in small_study.points:
        for name in ("suboptimal_1", "suboptimal_2", "suboptimal_3", "suboptimal_4", "pure_inertial"):
            assert cep[(point, "optimal")] <= cep[(point, name)] * (1 + 1e-9), (point, name)
    for noise in (0.1, 0.5):
        series = [cep[((gyro, noise), "optimal")] for gyro in (0.01, 0.1, 1.0)]
        assert series == sorted(series) and series[-1] > 1.2 * series[0]


def test_results_do_not_depend_on_how_the_points_are_split_into_tasks(small_study, small_result):
    setup = covariance_setup(small_study)
    one_task = evaluate_points(setup, small_study.points)
    per_point = [r for chunk in chunks(small_study.points, workers=8) for r in evaluate_points(setup, chunk)]
    assert one_task == per_point
    assert len(chunks(small_study.points, workers=1)) == 6 and len(chunks(list(range(1000)), workers=2)) == 16


def test_the_table_is_written_as_csv_and_parquet_with_units_in_the_column_names(small_study, small_result, tmp_path):
    files = write_outputs(small_result, tmp_path)
    names = {p.name for p in files}
    assert {"summary.md", "trade.csv", "trade.parquet", "position_cep_vs_gyro_drift.png"} <= names
    rows = list(csv.DictReader((tmp_path / "trade.csv").open(encoding="utf-8")))
    assert len(rows) == 36 and list(rows[0]) == table_columns(small_study)
    assert "gyro_drift_deg_per_h" in rows[0] and "position_cep_nmile" in rows[0]
    pq = pytest.importorskip("pyarrow.parquet")
    table = pq.read_table(tmp_path / "trade.parquet").to_pydict()
    assert table["filter"] == [r["filter"] for r in rows]
    assert np.allclose(table["position_cep_nmile"], [float(r["position_cep_nmile"]) for r in rows], rtol=1e-9)
    pure = [r for r in rows if r["filter"] == "pure_inertial"]
    assert all(r["doppler_bias_error_north_nmile_per_h"] == "nan" for r in pure)
    assert (tmp_path / "position_cep_vs_gyro_drift.png").stat().st_size > 10_000
    summary = (tmp_path / "summary.md").read_text(encoding="utf-8")
    assert "6 points x 6 filters = 36 covariance cases" in summary and "| optimal | 18 |" in summary
    assert csv_text(small_result) == (tmp_path / "trade.csv").read_text(encoding="utf-8")


def test_panels_spread_over_the_values():
    assert panel_values([3.0, 1.0, 2.0, 1.0]) == [1.0, 2.0, 3.0]
    assert panel_values([float(v) for v in range(10)]) == [0.0, 3.0, 6.0, 9.0]


def test_a_monte_carlo_case_writes_its_values_into_the_flight_profile(small_study):
    profile = monte_carlo_profile("modelgen/data/profile_000.yaml", small_study.parameters, (0.3, 0.25), 0.1, 50.0)
    assert profile.imu_budget.gyro_markov_drift == pytest.approx(to_si(0.3, "deg/h"))
    assert profile.imu_budget.gyro_constant_drift == pytest.approx(to_si(0.3, "deg/h"))
    assert profile.sensors["doppler"].white_noise == pytest.approx(0.25)
    assert profile.imu_rate == 50.0 and math.isclose(profile.path.duration, 360.0)


@pytest.mark.flight
def test_a_study_with_monte_carlo_flies_the_selected_case(small_study):
    from modelgen.study.studyfile import MonteCarloChoice

    study = dataclasses.replace(
        small_study, points=small_study.points[:1], filters=small_study.filters[:1],
        monte_carlo=MonteCarloChoice("modelgen/data/profile_000.yaml", 0.05, 20.0, 2, 3, ((0.1, 0.2),)),
    )
    result = run_trade(study)
    assert len(result.cases) == 1 and len(result.monte_carlo) == 1
    ensemble = result.monte_carlo[0].result
    assert ensemble.runs == 2 and ensemble.errors.shape[2] == 18 and np.all(np.isfinite(ensemble.errors))


def test_a_trade_study_with_a_journal_takes_up_where_it_stopped(small_study, small_result, tmp_path):
    journal = tmp_path / "trade.jsonl"
    whole = run_trade(small_study, journal=journal)
    lines = journal.read_text().splitlines()
    assert len(lines) == 1 + 6 and csv_text(whole) == csv_text(small_result)
    journal.write_text("\n".join(lines[:4]) + "\n")  # stopped after three of six tasks
    said = []
    resumed = run_trade(small_study, journal=journal, progress=said.append)
    assert any("3 of 6 tasks already done" in s for s in said)
    assert csv_text(resumed) == csv_text(small_result)
    assert len(journal.read_text().splitlines()) == 7
