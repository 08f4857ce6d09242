"""Noise parameters by maximum likelihood of the innovations (modelgen.navigator.likelihood, issue 26 item 4)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from modelgen.navigator import likelihood, tuning
from modelgen.navigator.config import builtin_config_path, load_config
from modelgen.navigator.tuning import Innovations

RESULTS = Path(__file__).parents[2] / "bench" / "results"


def test_the_log_likelihood_is_the_gaussian_density_of_each_innovation_under_its_s():
    rng = np.random.default_rng(5)
    entry = Innovations("gnss")
    expected = 0.0
    for _ in range(30):
        a = rng.standard_normal((3, 3))
        S = a @ a.T + 0.5 * np.eye(3)
        nu = rng.standard_normal(3)
        entry.nu.append(nu)
        entry.S.append(S)
        entry.nis.append(float(nu @ np.linalg.solve(S, nu)))
        expected += multivariate_normal(np.zeros(3), S).logpdf(nu)
    result = likelihood.log_likelihood({"gnss": entry})
    assert result["gnss"] == pytest.approx(expected, rel=1e-12)
    assert result["total"] == result["gnss"]


def test_the_white_noise_factor_sets_both_white_noises_and_their_si_values():
    config = load_config(builtin_config_path())
    changed = likelihood.with_parameters(config, {"noise.gyro_white.factor": 14.0, "zupt.sigma_m_s": 0.5})
    for kind in ("gyro_white", "accel_white"):
        before, after = config.noise[kind], changed.noise[kind]
        assert after.factor == 14.0
        assert after.si == pytest.approx(before.si / before.factor * 14.0, rel=1e-15)
    assert changed.noise["gyro_bias_driving"] == config.noise["gyro_bias_driving"]
    assert changed.zupt_sigma == 0.5 and likelihood.parameter_value(changed, "zupt.sigma_m_s") == 0.5


def _random_walk_innovations(q: float, r: float, n: int = 3000, seed: int = 11):
    """A scalar random walk x' = x + w (var q) seen as z = x + v (var r); innovations of a filter run with (q, r)."""
    rng = np.random.default_rng(seed)
    truth = np.cumsum(rng.normal(0.0, math.sqrt(q), n))
    z = truth + rng.normal(0.0, math.sqrt(r), n)

    def innovations(config) -> dict[str, Innovations]:
        q_f, r_f = config.zupt_sigma ** 2, config.gnss_position_variance_factor
        entry = Innovations("gnss")
        x, p = z[0], r_f
        nus, ss = [], []
        for k in range(1, n):
            p += q_f
            s = p + r_f
            nu = z[k] - x
            nus.append(nu)
            ss.append(s)
            gain = p / s
            x += gain * nu
            p *= 1.0 - gain
        entry.nu = list(np.array(nus)[:, None])
        entry.S = list(np.array(ss)[:, None, None])
        entry.nis = [nu * nu / s for nu, s in zip(nus, ss)]
        return {"gnss": entry}

    return innovations


def test_the_search_finds_the_process_and_measurement_noise_of_a_simulated_random_walk():
    """From a factor 3-5 off, Nelder-Mead ends at the likelihood's maximum on a fine grid, near the truth."""
    q, r = 0.04, 1.0
    innovations = _random_walk_innovations(q, r)
    config = likelihood.with_parameters(load_config(builtin_config_path()),
                                        {"zupt.sigma_m_s": math.sqrt(q) * 3.0, "gnss.position_variance_factor": r / 5})
    keys = ("zupt.sigma_m_s", "gnss.position_variance_factor")
    estimate = likelihood.maximum_likelihood(config, innovations, keys, log10_tolerance=0.005)
    assert estimate.converged
    assert estimate.log_likelihood_after["total"] > estimate.log_likelihood_before["total"]
    # the maximum on a grid around the truth, scored by the same likelihood
    grid = [(s, v) for s in np.sqrt(q) * np.geomspace(0.6, 1.6, 15) for v in r * np.geomspace(0.85, 1.15, 11)]
    scores = [likelihood.log_likelihood(innovations(likelihood.with_parameters(
        config, {"zupt.sigma_m_s": s, "gnss.position_variance_factor": v})))["total"] for s, v in grid]
    best_sigma, best_r = grid[int(np.argmax(scores))]
    assert estimate.after["zupt.sigma_m_s"] == pytest.approx(best_sigma, rel=0.06)
    assert estimate.after["gnss.position_variance_factor"] == pytest.approx(best_r, rel=0.02)
    assert estimate.after["zupt.sigma_m_s"] ** 2 == pytest.approx(q, rel=0.25)
    assert estimate.after["gnss.position_variance_factor"] == pytest.approx(r, rel=0.1)


@pytest.mark.parametrize("config_name, result_name", [
    ("replay_drive_0708.yaml", "navigator_tuning_stage10_fixed_point_15.json"),
    ("replay_drive_0708_21.yaml", "navigator_tuning_stage9_fixed_point_21_white.json")])
def test_the_shipped_configurations_hold_the_maximum_likelihood_estimate_at_the_fixed_point(config_name, result_name):
    """The white-noise factor stage 5 estimated in the last iteration of stages 4 and 5 to a fixed point
    (bench/navigator_tuning.py --fixed-point --json, committed in bench/results) is held in the shipped
    configuration to the 3 figures written there; the configuration's tuning: record names it; the log L stated
    for the fixed point is that of the search's maximum."""
    config = load_config(builtin_config_path().parent / config_name)
    result = json.loads((RESULTS / result_name).read_text())
    assert result["model"] == config.model and result["configuration"] == config_name
    for key in likelihood.PROCESS_NOISE:
        assert likelihood.parameter_value(config, key) == pytest.approx(result["fixed_point"][key], rel=5e-3), key
        assert key in config.tuning
    assert result["iterates"][-1]["log_likelihood"] == pytest.approx(result["log_likelihood"]["total"], rel=1e-12)


def _rows(source: str, time, nu, s) -> Innovations:
    """One sensor's record with one row: innovations ``nu`` at ``time``, innovation variance ``s`` (scalar or per
    update)."""
    nu = np.asarray(nu, float)
    s = np.broadcast_to(np.asarray(s, float), nu.shape)
    entry = Innovations(source)
    entry.time = [float(t) for t in time]
    entry.nu = list(nu[:, None])
    entry.S = list(s[:, None, None])
    entry.nis = list(nu**2 / s)
    return entry


def _ar1(rng, n: int, phi: float) -> np.ndarray:
    """A stationary AR(1) sequence of unit variance: x_t = phi x_{t-1} + w_t."""
    from scipy.signal import lfilter

    w = rng.standard_normal(n) * math.sqrt(1.0 - phi**2)
    w[0] = rng.standard_normal()
    return lfilter([1.0], [1.0, -phi], w)


def test_the_thinned_score_is_each_rows_gaussian_density_summed_over_the_epochs_and_divided_by_k():
    """With k given: a row's score is sum over its epochs of -1/2 (log 2 pi S_ii + nu_i^2 / S_ii), / k; offset 0
    keeps the epochs whose grid step is a multiple of k; the rows of a 2-row update are scored as marginals."""
    rng = np.random.default_rng(3)
    n = 301
    time = 0.1 * np.arange(n)
    nu = rng.standard_normal((n, 2))
    entry = Innovations("nhc")
    entry.time = list(time)
    for v in nu:
        a = rng.standard_normal((2, 2))
        S = a @ a.T + 0.3 * np.eye(2)
        entry.nu.append(v)
        entry.S.append(S)
        entry.nis.append(float(v @ np.linalg.solve(S, v)))
    score = likelihood.thinned_log_likelihood({"a": {"nhc": entry}}, steps={("nhc", 0): 1, ("nhc", 1): 3})
    var = np.array([np.diag(S) for S in entry.S])
    density = -0.5 * (np.log(2 * math.pi * var) + nu**2 / var)
    first, second = score.rows
    assert (first.step, second.step) == (1, 3) and first.epochs == second.epochs == n
    assert first.score["a"] == pytest.approx(density[:, 0].sum(), rel=1e-12)
    assert second.score["a"] == pytest.approx(density[:, 1].sum() / 3, rel=1e-12)
    assert second.first_offset["a"] == pytest.approx(density[::3, 1].sum(), rel=1e-12)
    assert second.kept_first_offset == 101
    assert score.total["a"] == pytest.approx(first.score["a"] + second.score["a"], rel=1e-12)
    assert score.by_source["a"]["nhc"] == score.total["a"]


def test_every_candidate_is_scored_on_the_identical_epochs():
    """A candidate's updates where another has none are not scored for anyone: the epochs are those every
    candidate has, so changing a candidate's innovations there changes no score; the epochs are numbered by
    their gaps in update periods (:func:`tuning.update_steps`), so drifting time tags are all kept."""
    rng = np.random.default_rng(8)
    time = 0.1 * np.arange(400)
    nu = rng.standard_normal(400)
    a = _rows("nhc", time, nu, 1.0)
    keep = np.ones(400, bool)
    keep[[17, 18, 250]] = False  # b does not update there (its NHC condition did not hold)
    b = _rows("nhc", time[keep], 0.9 * nu[keep], 1.2)
    steps = {("nhc", 0): 4}
    score = likelihood.thinned_log_likelihood({"a": {"nhc": a}, "b": {"nhc": b}}, steps=steps)
    (row,) = score.rows
    assert row.epochs == 397
    expected = -0.5 * (np.log(2 * math.pi) + nu[keep] ** 2)
    assert row.score["a"] == pytest.approx(expected.sum() / 4, rel=1e-12)
    assert row.first_offset["a"] == pytest.approx(expected[(np.arange(400)[keep] % 4) == 0].sum(), rel=1e-12)
    changed = _rows("nhc", time, np.where(keep, nu, 50.0), 1.0)  # a's innovations where b has none
    again = likelihood.thinned_log_likelihood({"a": {"nhc": changed}, "b": {"nhc": b}}, steps=steps)
    assert again.total == score.total and again.first_offset_total == score.first_offset_total
    # epochs that drift against a fixed grid (a receiver's clock) and half-period steps are all scored
    drift = 0.25007 * np.arange(2000) + 0.001 * rng.standard_normal(2000)
    drift[1000:] += 0.05  # one gap a fifth of a period long: still one update step
    steps_of = tuning.update_steps(drift)
    assert steps_of[0] == 0 and np.all(np.diff(steps_of) == 1)
    a, b = _rows("gnss", drift, rng.standard_normal(2000), 1.0), _rows("gnss", drift, rng.standard_normal(2000), 2.0)
    drifting = likelihood.thinned_log_likelihood({"a": {"gnss": a}, "b": {"gnss": b}}, steps={("gnss", 0): 5})
    assert drifting.rows[0].epochs == 2000 and drifting.rows[0].kept_first_offset == 400
    assert list(tuning.update_steps(np.array([0.0, 0.1, 0.15, 0.25, 0.35]))) == [0, 1, 2, 3, 4]  # half a step
    # a gap counts its missed periods: b's three missing NHC steps (17, 18, 250) keep the numbering of a
    assert list(tuning.update_steps(time[keep])) == list(np.arange(400)[keep])


def test_the_step_is_the_ceiling_of_the_largest_correlation_factor_over_the_candidates():
    """k of a row is ceil(max_c f_c), f_c stage 4's integrated autocorrelation of candidate c's standardized
    innovations of the row, the same k for every candidate; a sensor with too few updates is left out."""
    from modelgen.navigator.tuning import row_statistics

    rng = np.random.default_rng(21)
    time = 0.1 * np.arange(3000)
    correlated = {"nhc": _rows("nhc", time, _ar1(rng, 3000, 0.9), 1.0),
                  "zupt": _rows("zupt", time[:10], rng.standard_normal(10), 1.0)}
    white = {"nhc": _rows("nhc", time, rng.standard_normal(3000), 1.0),
             "zupt": _rows("zupt", time[:10], rng.standard_normal(10), 1.0)}
    f = {name: row_statistics(c, {})[0].factor for name, c in (("correlated", correlated), ("white", white))}
    assert f["correlated"] > 10 > f["white"]  # AR(1) with phi 0.9: f about 19
    score = likelihood.thinned_log_likelihood({"white": white, "correlated": correlated})
    (row,) = score.rows
    assert row.step == math.ceil(f["correlated"]) and row.factors == pytest.approx(f)
    assert score.left_out == ("zupt",)
    assert row.kept_first_offset == math.ceil(3000 / row.step)


def test_on_an_ar1_row_beside_a_white_row_the_thinned_score_prefers_the_true_variances_where_the_white_one_does_not():
    """Two sensors: an AR(1) row at 10 Hz (phi 0.95: f 39, 3000 updates holding about 77 independent ones) and a
    white row at 1 Hz (100 updates).  The truth has unit variance on both; the other candidate is 5 % low on the
    correlated row and a factor 1.6 high on the white one.  Both statistics favour the truth in expectation, but
    the white log-likelihood weighs the correlated row by its 3000 updates, so that row's chance fluctuation
    decides it; thinned, each row weighs by the information it holds and the white row's clear evidence
    counts.  Over 60 draws the thinned score picks the truth far more often, and where the two disagree it is
    the one that is right."""
    white_right = thinned_right = disagree = thinned_right_there = 0
    for seed in range(60):
        rng = np.random.default_rng(seed)
        c, g = _ar1(rng, 3000, 0.95), rng.standard_normal(100)
        tc, tg = 0.1 * np.arange(3000), 1.0 * np.arange(100)
        candidates = {"truth": {"nhc": _rows("nhc", tc, c, 1.0), "gnss": _rows("gnss", tg, g, 1.0)},
                      "other": {"nhc": _rows("nhc", tc, c, 0.95), "gnss": _rows("gnss", tg, g, 1.6)}}
        white = {name: likelihood.log_likelihood(c)["total"] for name, c in candidates.items()}
        thinned = likelihood.thinned_log_likelihood(candidates).total
        w, t = white["truth"] > white["other"], thinned["truth"] > thinned["other"]
        white_right += w
        thinned_right += t
        if w != t:
            disagree += 1
            thinned_right_there += t
    assert thinned_right >= 54 and white_right <= 48, (thinned_right, white_right)
    assert disagree >= 8 and thinned_right_there >= 0.8 * disagree, (disagree, thinned_right_there)
