"""Measurement noise from the innovations with GNSS present (modelgen.navigator.tuning, issue 26 item 4)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from modelgen.navigator import tuning

DATA = Path(__file__).parent / "data"


def _ar1(phi: float, n: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    w = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = w[0]
    for i in range(1, n):
        x[i] = phi * x[i - 1] + math.sqrt(1 - phi**2) * w[i]
    return x


def test_the_correlation_factor_of_a_first_order_markov_series_is_its_integrated_time():
    """AR(1) with rho_k = phi^k: f = (1 + phi) / (1 - phi) (19 at phi 0.9), tau = -dt / ln(phi); white: f = 1."""
    period = 0.25
    time = np.arange(40000) * period
    rho = tuning.autocorrelation(time, _ar1(0.9, len(time)), period)
    f, lags = tuning.correlation_factor(rho)
    assert f == pytest.approx(19.0, rel=0.15)
    assert 10 < lags < len(rho)
    assert tuning.decorrelation_time(rho, period) == pytest.approx(-period / math.log(0.9), rel=0.1)
    white, _ = tuning.correlation_factor(tuning.autocorrelation(time, _ar1(0.0, len(time)), period))
    assert white == pytest.approx(1.0, abs=0.1)


def test_pairs_are_not_formed_across_a_pause_in_the_updates():
    """Two runs of a constant +1 / -1 series with a pause between: no lag pairs the runs (rho stays 1)."""
    period = 0.1
    time = np.r_[np.arange(100) * period, 50.0 + np.arange(100) * period]
    e = np.r_[np.ones(100), -np.ones(100)]
    rho = tuning.autocorrelation(time, e, period, max_lag_s=5.0)
    assert np.allclose(rho[np.isfinite(rho)], 1.0)


def test_time_tags_drifting_against_a_fixed_grid_keep_every_pair_and_a_gap_still_breaks_pairs():
    """The updates are numbered by their gaps counted in periods (tuning.update_steps), not put on the grid
    t_0 + n T: time tags that drift by 0.3 T over the series keep every pair at lag 1 (the grid dropped the
    samples a quarter period off it), and a real gap still leaves out the pairs across it."""
    period = 0.25
    n = 400
    time = period * np.arange(n) * (1.0 + 0.3 / (n - 1))  # the last tag 0.3 T after t_0 + (n - 1) T
    x = _ar1(0.5, n)
    lag1 = next(b for k, a, b in tuning.lagged_pairs(time, x, period, max_lag_s=1.0) if k == 1)
    assert len(lag1) == n - 1
    assert list(tuning.update_steps(time, period)) == list(range(n))
    gap = np.r_[time[:200], time[200:] + 3 * period]  # three updates missed after the 200th
    assert list(tuning.update_steps(gap, period)) == list(range(200)) + list(range(203, n + 3))
    pairs = {k: len(a) for k, a, b in tuning.lagged_pairs(gap, x, period, max_lag_s=1.0)}
    assert pairs[1] == n - 2  # not the pair across the gap (the updates there are 4 T apart) ...
    assert pairs[4] == (200 - 4) + (n - 200 - 4) + 1  # ... which is a pair at lag 4 (steps 199 and 203)
    e = np.r_[np.ones(200), -np.ones(n - 200)]  # +1 then -1: a pair across the gap would lower rho below 1
    rho = tuning.autocorrelation(gap, e, period, max_lag_s=1.0)
    assert np.allclose(rho[1:4], 1.0) and rho[4] < 1.0


@pytest.fixture(scope="module")
def excerpt():
    from modelgen.navigator.config import load_config
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare
    from modelgen.navigator.spec import navigator_spec

    config = load_config(DATA / "excerpt.yaml")
    inputs = prepare(config, read_imu(config.imu_source, config.gap_factor, config.gap_action),
                     read_gnss(config.gnss_source))
    return config, inputs, navigator_spec(model_path(config.model, config.path))


@pytest.mark.flight
def test_the_innovations_are_recorded_with_gnss_present_and_tune_sets_r_times_f(excerpt):
    """Every GNSS epoch after the alignment is recorded (the excerpt's outage is not flown); NIS = nu S^-1 nu;
    a tuned sigma is the old one x sqrt(f), a variance factor the old one x f, both from the rows' statistics."""
    config, inputs, spec = excerpt
    sources, flight = tuning.record_innovations(config, inputs, spec)
    assert not flight.outages and len(sources["gnss"].time) == len(flight.outputs) > 150  # one per epoch flown
    g = sources["gnss"]
    for nu, S, nis in zip(g.nu[:20], g.S[:20], g.nis[:20]):
        assert nis == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-9)
    stats = tuning.row_statistics(sources, tuning.row_labels(spec))
    assert {s.source for s in stats} >= {"gnss", "nhc"}
    tuned = {t.key: t for t in tuning.tune(config, stats, spec)}
    position = [s.factor for s in stats if s.source == "gnss" and s.label.startswith("position")]
    assert tuned["gnss.position_variance_factor"].after == pytest.approx(config.gnss_position_variance_factor
                                                                          * np.mean(position))
    lateral = next(s for s in stats if s.source == "nhc" and s.label == "lateral")
    assert tuned["nhc.sigma_lateral_m_s"].after == pytest.approx(config.nhc_sigma_lateral * math.sqrt(lateral.factor))
    assert all(t.factor >= 1.0 for t in tuned.values())
    assert tuning.apply(config, list(tuned.values())).nhc_sigma_lateral == tuned["nhc.sigma_lateral_m_s"].after


@pytest.mark.flight
@pytest.mark.compile
def test_the_gnss_variance_factors_reach_r_in_python_and_in_c_alike(excerpt):
    """Position variance x 9, velocity x 4: Python's recorded R is that much larger at the first update, and the
    C navigator flies the changed configuration within 1 mm of the Python one."""
    from modelgen.navigator.cnav import cached_c_navigator, fly_c
    from modelgen.navigator.navigator import fly
    from modelgen.navigator.replay import max_position_difference

    config, inputs, spec = excerpt
    changed = dataclasses.replace(config, gnss_position_variance_factor=9.0, gnss_velocity_variance_factor=4.0)
    before, after = tuning.InnovationRecorder(), tuning.InnovationRecorder()
    fly(config, inputs, spec, monitor=before)
    python = fly(changed, inputs, spec, monitor=after)
    kinds = np.array([r.kind for r in spec.gnss_rows])
    ratio = after.sources["gnss"].r[0] / before.sources["gnss"].r[0]
    assert np.allclose(ratio[kinds == "position"], 9.0) and np.allclose(ratio[kinds == "velocity"], 4.0)
    navigator, _ = cached_c_navigator(spec)
    c_flight, _ = fly_c(changed, inputs, navigator)
    assert max_position_difference(c_flight, python) <= 1e-3
    assert max_position_difference(c_flight, fly_c(config, inputs, navigator)[0]) > 1e-3


STAGE4_RESULTS = Path(__file__).parents[2] / "bench" / "results"
CONFIG_FIELDS = {"gnss.position_variance_factor": "gnss_position_variance_factor",
                 "gnss.velocity_variance_factor": "gnss_velocity_variance_factor",
                 "nhc.sigma_lateral_m_s": "nhc_sigma_lateral", "nhc.sigma_vertical_m_s": "nhc_sigma_vertical",
                 "zupt.sigma_m_s": "zupt_sigma"}


@pytest.mark.parametrize("config_name, result_name", [
    ("replay_drive_0708.yaml", "navigator_tuning_stage10_fixed_point_15.json"),
    ("replay_drive_0708_21.yaml", "navigator_tuning_stage9_fixed_point_21_white.json")])
def test_the_shipped_configurations_hold_the_fixed_point_of_stages_4_and_5(config_name, result_name):
    """Every number stages 4 and 5 set, iterated to their fixed point (bench/navigator_tuning.py --fixed-point
    --json, its result committed in bench/results), is held in the shipped configuration to the 3 figures written
    there, and the configuration's tuning: record names every such key.  Each stage-4 number of the last iterate is
    its white value x the correlation factor measured at the iterate before (a sigma x sqrt(f)): the factor on the
    white R, not on the one before."""
    import json

    from modelgen.navigator import likelihood
    from modelgen.navigator.config import builtin_config_path, load_config

    config = load_config(builtin_config_path().parent / config_name)
    result = json.loads((STAGE4_RESULTS / result_name).read_text())
    assert result["model"] == config.model and result["configuration"] == config_name
    assert set(result["fixed_point"]) == set(CONFIG_FIELDS) | set(likelihood.PROCESS_NOISE)
    for key, value in result["fixed_point"].items():
        assert likelihood.parameter_value(config, key) == pytest.approx(value, rel=5e-3), key
        assert key in config.tuning
    last = result["iterates"][-1]
    assert last["values"] == result["fixed_point"] and last["iteration"] == result["iterations"]
    assert result["converged"] == (max(last["change"].values()) < result["tolerance"])
    for key, f in last["correlation_factors"].items():
        power = 1.0 if key.startswith("gnss.") else 0.5
        assert last["values"][key] == pytest.approx(result["white_values"][CONFIG_FIELDS[key]] * f**power, rel=1e-9)


def test_a_tuning_statement_with_a_bar_and_a_newline_stays_one_table_row_of_the_summary():
    """The `tuning:` texts are the user's free text: each becomes exactly one Markdown row, its '|' escaped."""
    from modelgen.navigator.config import builtin_config_path, load_config
    from modelgen.navigator.report import _tuning_lines

    config = dataclasses.replace(load_config(builtin_config_path()), tuning={"zupt.sigma_m_s": "a | b\n| c |"})
    lines = _tuning_lines(config)
    rows = [line for line in lines if line.startswith("| ") and "zupt" in line]
    assert rows == ["| zupt.sigma_m_s | a \\| b \\| c \\| |"]
    assert not _tuning_lines(dataclasses.replace(config, tuning={}))


def test_the_summary_states_the_pooled_nees_it_flew_not_a_figure_of_another_configuration():
    """The overconfidence note of summary.md is computed from the flight's own schedules (report.py): the pooled
    mean NEES and the fraction inside the 95 % region; nothing when no schedule was flown."""
    from modelgen.navigator.report import _overconfidence_lines

    summary = {"schedules": [{}], "consistency_pooled": {"count": 51, "nees_mean": 2.4712, "inside_95_fraction": 0.86}}
    (text, _) = _overconfidence_lines(summary)
    assert "51 outage ends" in text and "mean 2.47 against 2" in text and "86 % inside" in text
    assert "halves" not in text and "replay_drive_0708_21" not in text
    assert _overconfidence_lines({"schedules": [], "consistency_pooled": {}}) == []


@pytest.mark.parametrize("stage, states, config_name", [(10, 15, "replay_drive_0708.yaml"),
                                                        (9, 21, "replay_drive_0708_21.yaml")])
def test_of_the_fixed_points_from_both_starts_the_shipped_one_has_the_higher_thinned_log_likelihood(stage, states,
                                                                                                    config_name):
    """Stage 7's step 5 (bench/navigator_tuning.py --fixed-point --both-starts, run again as stage 9 after stage 4
    was made to pair every update, and for 15 states as stage 10 with the NHC lever arm; --select on the committed
    fixed points): of the converged fixed points, from
    the shipped and from the white start, the configuration holds the one whose innovations' thinned composite
    log-likelihood with GNSS present is higher (likelihood.thinned_log_likelihood: a choice the innovations make,
    not the outages).  The selection scored exactly that stage's points, and its flights reproduce their white
    log-likelihoods (stated beside, not used)."""
    import json

    from modelgen.navigator import likelihood
    from modelgen.navigator.config import builtin_config_path, load_config

    runs = [json.loads((STAGE4_RESULTS / f"navigator_tuning_stage{stage}_fixed_point_{states}{suffix}.json").read_text())
            for suffix in ("", "_white")]
    assert [r["start"] for r in runs] == ["shipped", "white"] and all(r["converged"] for r in runs)
    assert all(r["configuration"] == config_name for r in runs)
    selector = json.loads((STAGE4_RESULTS / f"navigator_tuning_stage{stage}_selector.json").read_text())
    (selection,) = [s for s in selector["selections"] if s["configuration"] == config_name]
    assert selection["points"] == {r["start"]: r["fixed_point"] for r in runs}
    for r in runs:
        assert selection["white_log_likelihood"][r["start"]]["total"] == pytest.approx(r["log_likelihood"]["total"],
                                                                                      rel=1e-9)
    thinned = selection["thinned"]
    assert selection["chosen"] == max(thinned["total"], key=thinned["total"].get)
    assert thinned["total"] == pytest.approx({n: sum(r["score"][n] for r in thinned["rows"]) for n in thinned["total"]})
    assert all(r["step"] == math.ceil(max(r["factors"].values())) for r in thinned["rows"])
    assert {r["source"] for r in thinned["rows"]} == {"gnss", "nhc", "zupt"} and not thinned["left_out"]
    (best,) = [r for r in runs if r["start"] == selection["chosen"]]
    config = load_config(builtin_config_path().parent / config_name)
    for key, value in best["fixed_point"].items():
        assert likelihood.parameter_value(config, key) == pytest.approx(value, rel=best["tolerance"]), key
