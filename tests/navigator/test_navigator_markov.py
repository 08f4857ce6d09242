"""The shaping filter for time-correlated GNSS errors (issue 26): Gauss-Markov measurement-error states in the
navigator (ins_gnss24_gm_nav, NavigatorSpec.carried), their identification with GNSS present (tuning.markov_fit,
likelihood.maximum_likelihood over model parameters) and the C navigator's agreement with the Python one."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import package_path
from modelgen.navigator import likelihood
from modelgen.navigator.config import load_config
from modelgen.navigator.tuning import Innovations, autocovariance, markov_fit

DATA = Path(__file__).parent / "data"
MODELS = package_path("navigator", "models")
TAU, SIGMA, WHITE, PERIOD = 2.0, 0.05, 0.02, 0.25


def _gauss_markov(n: int, seed: int, tau: float = TAU, sigma: float = SIGMA, period: float = PERIOD) -> np.ndarray:
    """A first-order Gauss-Markov sequence sampled exactly (e_k+1 = a e_k + w, a = exp(-T / tau), stationary)."""
    rng = np.random.default_rng(seed)
    a = math.exp(-period / tau)
    e = np.empty(n)
    e[0] = rng.normal(0.0, sigma)
    w = rng.normal(0.0, sigma * math.sqrt(1.0 - a * a), n)
    for k in range(1, n):
        e[k] = a * e[k - 1] + w[k]
    return e


@pytest.fixture(scope="module")
def spec24():
    from modelgen.navigator.spec import navigator_spec

    return navigator_spec(MODELS / "ins_gnss24_gm_nav.yaml")


def test_the_autocovariance_fit_recovers_tau_and_sigma_of_a_simulated_error_under_white_noise():
    e = _gauss_markov(40000, seed=3)
    x = e + np.random.default_rng(4).normal(0.0, WHITE, len(e))
    time = np.arange(len(x)) * PERIOD
    time = np.delete(time, np.arange(100, len(time), 97))  # gaps: pairs are formed on the grid only
    x = np.delete(x, np.arange(100, len(x), 97))
    fit = markov_fit(autocovariance(time, x, PERIOD), PERIOD)
    assert fit.tau_s == pytest.approx(TAU, rel=0.15)
    assert fit.sigma == pytest.approx(SIGMA, rel=0.1)
    assert fit.white_sigma == pytest.approx(WHITE, rel=0.25)  # lag 0 holds the white part too
    with pytest.raises(ValueError, match="not positive"):  # white noise alone: nothing to fit
        markov_fit(autocovariance(time, np.random.default_rng(5).normal(size=len(time)), PERIOD), PERIOD)


def _shaping_filter_innovations(n: int = 6000, seed: int = 8):
    """z = e + v (e Gauss-Markov TAU, SIGMA; v white WHITE): the innovations of the scalar shaping filter run with
    the configuration's parameters gnss_error_time and gnss_error_sigma."""
    z = _gauss_markov(n, seed) + np.random.default_rng(seed + 1).normal(0.0, WHITE, n)

    def innovations(config) -> dict[str, Innovations]:
        tau, sigma = config.parameters["gnss_error_time"], config.parameters["gnss_error_sigma"]
        a = math.exp(-PERIOD / tau)
        q = sigma * sigma * (1.0 - a * a)
        entry = Innovations("gnss")
        x, p = 0.0, sigma * sigma
        nus, ss = np.empty(n), np.empty(n)
        for k in range(n):
            x, p = a * x, a * a * p + q
            s = p + WHITE * WHITE
            nus[k], ss[k] = z[k] - x, s
            gain = p / s
            x, p = x + gain * nus[k], (1.0 - gain) * p
        entry.time = list(np.arange(n) * PERIOD)
        entry.nu = [np.array([v]) for v in nus]
        entry.S = [np.array([[s]]) for s in ss]
        entry.nis = list(nus * nus / ss)
        return {"gnss": entry}

    return innovations


def test_maximum_likelihood_over_model_parameters_recovers_the_simulated_tau_and_sigma():
    config = likelihood.with_parameters(load_config(DATA / "excerpt_24.yaml"),
                                        {"parameters.gnss_error_time": 0.5, "parameters.gnss_error_sigma": 0.02})
    assert config.parameters == {"gnss_error_time": 0.5, "gnss_error_sigma": 0.02}
    keys = ("parameters.gnss_error_time", "parameters.gnss_error_sigma")
    estimate = likelihood.maximum_likelihood(config, _shaping_filter_innovations(), keys, max_flights=120,
                                             log10_tolerance=0.005)
    assert estimate.after["parameters.gnss_error_time"] == pytest.approx(TAU, rel=0.2)
    assert estimate.after["parameters.gnss_error_sigma"] == pytest.approx(SIGMA, rel=0.15)
    assert estimate.log_likelihood_after["total"] > estimate.log_likelihood_before["total"] + 100
    criteria = likelihood.information_criteria(estimate.log_likelihood_after["total"], 2, 6000)
    assert criteria["aic"] == pytest.approx(4 - 2 * estimate.log_likelihood_after["total"])
    assert criteria["bic"] == pytest.approx(2 * math.log(6000) - 2 * estimate.log_likelihood_after["total"])


def test_a_model_parameter_without_a_value_is_refused_by_the_search():
    config = load_config(DATA / "excerpt_21.yaml")
    with pytest.raises(KeyError, match="parameters.gnss_error_time"):
        likelihood.parameter_value(config, "parameters.gnss_error_time")
    assert likelihood.parameter_value(config, "parameters.gnss_error_time", {"gnss_error_time": 2.0}) == 2.0


def test_the_24_state_spec_carries_the_gnss_error_states_from_the_model_file(spec24):
    names = spec24.derived.model.state_names
    assert spec24.n_states == 24
    assert [names[i] for i in spec24.carried] == ["gnss_error_north", "gnss_error_east", "gnss_error_down"]
    assert not set(spec24.carried) & {i for b in spec24.blocks.values() for i in b.indices}
    # the GNSS rows are still found (position rows depend on one position state, and on their error state)
    assert [(r.kind, r.axis) for r in spec24.gnss_rows][:3] == [("position", 0), ("position", 1), ("position", 2)]


def _parameters(spec, tau: float, sigma: float) -> np.ndarray:
    from types import SimpleNamespace

    from modelgen.navigator.mechanization import gravity, radii
    from modelgen.navigator.spec import quantities

    nav = np.array([1.0, 0, 0, 0, 5.0, 1.0, 0.0, 0.7, -1.8, 1600.0])
    cfg = SimpleNamespace(lever_arm=np.array([0.0, -0.05, 0.0]), gyro_white=1e-3, accel_white=1e-2,
                          gyro_bias_driving=1e-6, accel_bias_driving=1e-5,
                          parameters=np.array([tau, sigma] + [7.2921151467e-5]))
    assert spec.free_parameters == ("gnss_error_time", "gnss_error_sigma", "earth_rate")
    q = quantities(spec, nav, np.eye(3), np.array([0.1, 0.2, -9.8]), np.array([0.01, 0.0, 0.02]),
                   np.array([0.03, 0.03, 0.05, 0.02, 0.02, 0.04]), cfg, radii, gravity)
    return spec.parameter_vector(q)


def test_the_carried_states_start_at_their_steady_state_and_decay_with_the_model_transition(spec24):
    p = _parameters(spec24, 1.5, 0.04)
    P = spec24.carried_covariance(np.eye(24) * 7.0, p)
    for i in spec24.carried:
        assert P[i, i] == pytest.approx(0.04 ** 2, rel=1e-12)  # 2 sigma^2 / tau over 2 / tau
    assert P[0, 0] == 7.0  # the others untouched
    g = spec24.module
    Phi, _ = g.discretize(g.system_matrix(p), g.noise_input_matrix(p), g.noise_psd(p), 0.1)
    sensors = {"carried": np.array([0.3, -0.2, 0.1])}
    spec24.propagate_carried(sensors, Phi)
    assert sensors["carried"] == pytest.approx(np.array([0.3, -0.2, 0.1]) * math.exp(-0.1 / 1.5), rel=1e-9)


def test_the_feedback_moves_the_error_estimate_into_the_carried_states_not_the_mechanization(spec24):
    from modelgen.navigator.errorstate import rotate
    from modelgen.navigator.mechanization import radii

    nav = np.array([1.0, 0, 0, 0, 1.0, 2.0, 3.0, 0.7, -1.8, 1600.0])
    x = np.zeros(24)
    x[list(spec24.carried)] = [0.05, -0.03, 0.01]
    sensors = {k: np.zeros(3) for k in ("gyro_bias", "accel_bias", "gyro_scale_factor", "accel_scale_factor")}
    sensors["carried"] = np.array([0.01, 0.0, 0.0])
    before = nav.copy()
    spec24.feedback(nav, x, sensors, radii, rotate)
    assert np.array_equal(nav, before)
    assert sensors["carried"] == pytest.approx([0.06, -0.03, 0.01])
    # the GNSS difference loses the carried estimate's share: measured = true + e, H_c = -I on the position rows
    H = spec24.module.measurement_matrix(_parameters(spec24, 2.0, 0.05))
    assert spec24.carried_correction(H, sensors)[:3] == pytest.approx([-0.06, 0.03, -0.01])
    assert np.all(spec24.carried_correction(H, sensors)[3:] == 0.0)


def _model_with_bias(tmp_path: Path, bias: str) -> Path:
    text = (MODELS / "ins_gnss24_gm_nav.yaml").read_text()
    start = text.index("      bias: {process: gauss_markov")
    end = text.index("\n", text.index('sigma: "sigma_e"}', start))
    path = tmp_path / "gnss_bias_nav.yaml"
    path.write_text(text[:start] + bias + text[end:])
    return path


def test_an_error_state_without_a_steady_state_is_refused_naming_the_model_file_and_line(tmp_path):
    """The refusal names the line of the entry that declared the state's process (before: the file alone)."""
    from modelgen.navigator.spec import navigator_spec

    path = _model_with_bias(tmp_path, "      bias: {process: random_constant, symbols: [e_rn, e_re, e_rd], "
                                      "names: [gnss_error_north, gnss_error_east, gnss_error_down]}")
    spec = navigator_spec(path)
    assert len(spec.carried) == 3
    line = next(i for i, text in enumerate(path.read_text().splitlines(), start=1) if "bias: {process: random_constant" in text)
    with pytest.raises(ModelError, match=rf"gnss_bias_nav\.yaml:{line}: state 'gnss_error_north'.*no steady state"):
        spec.carried_covariance(np.eye(24), _parameters(spec, 2.0, 0.05))


@pytest.mark.compile
@pytest.mark.flight
def test_the_24_state_model_flies_alike_in_python_and_c_and_its_states_change_the_flight(spec24):
    """60 s of the drive: C against Python at every epoch (1 mm, as the 21-state test); the Gauss-Markov states
    change the trajectory against the same configuration with them nearly switched off."""
    import dataclasses

    from modelgen.navigator.replay import run_replay

    both = run_replay(DATA / "excerpt_24.yaml", None, echo=lambda _: None, navigator="both")
    s = both.summary
    assert s["navigator"] == "c" and s["c_python_max_difference_m"] <= 1e-3
    assert s["horizontal_rms_outside_outages_m"] <= 0.10
    from modelgen.navigator.cnav import cached_c_navigator, fly_c, log_arrays
    from modelgen.navigator.logs import read_gnss, read_imu
    from modelgen.navigator.navigator import prepare

    config = both.config
    quiet = dataclasses.replace(config, parameters={**config.parameters, "gnss_error_sigma": 1e-6})
    inputs = prepare(quiet, read_imu(quiet.imu_source, quiet.gap_factor, quiet.gap_action), read_gnss(quiet.gnss_source))
    spec = spec24  # the module's spec of ins_gnss24_gm_nav.yaml (navigator_spec), not derived again
    navigator, _ = cached_c_navigator(spec, rest_max=log_arrays(quiet, inputs, spec).rest_max)
    off, _ = fly_c(quiet, inputs, navigator)
    ok = ~np.isnan(off.outputs[:, 1]) & ~np.isnan(both.flight.outputs[:, 1])
    metres = np.abs(off.outputs[ok, 1:3] - both.flight.outputs[ok, 1:3]) * 6.37e6
    assert metres.max() > 5e-3


@pytest.mark.compile
@pytest.mark.flight
def test_the_smoother_carries_the_error_states_alike_from_the_c_and_the_python_forward_record():
    """replay --smooth on the 24-state excerpt: the C navigator's forward record (its nominal with the carried
    estimates) and the Python one's give the same smoothed trajectory, better than the forward one in the outage."""
    from modelgen.navigator.replay import run_replay

    results = {nav: run_replay(DATA / "excerpt_24.yaml", None, echo=lambda _: None, navigator=nav, smooth=True)
               for nav in ("c", "python")}
    c, python = (results[n].smoothed.outputs for n in ("c", "python"))
    ok = ~np.isnan(c[:, 1])
    assert np.array_equal(ok, ~np.isnan(python[:, 1]))
    assert np.max(np.abs(c[ok, 1:3] - python[ok, 1:3])) * 6.37e6 <= 1e-3
    smoothed = results["c"].summary["smoothed"]
    assert smoothed["smoothed"]["horizontal_error_outage_rms_m"] < 0.5 * smoothed["forward"]["horizontal_error_outage_rms_m"]


def test_a_state_the_navigator_can_neither_feed_back_nor_carry_is_refused_naming_it(tmp_path):
    """A second gyro bias (summed Gauss-Markov drift) enters the attitude rates: it is not an aiding sensor's own
    error, and the navigator has no feedback for it, so it is refused instead of flown with P0 = 0 and reset; the
    refusal names the line of the entry that declares it."""
    from modelgen.navigator.spec import navigator_spec

    text = (MODELS / "ins_gnss21_rw_nav.yaml").read_text()
    line = '    - {of: gyro_bias, process: random_walk, psd: "N_bg**2"}\n'
    assert line in text
    path = tmp_path / "summed_drift_nav.yaml"
    path.write_text(text.replace(line, line + (
        '    - {of: gyro_bias, process: gauss_markov, rate: "1/300", sigma: "1e-4", symbols: [m_gx, m_gy, m_gz], '
        'names: [gyro_markov_x, gyro_markov_y, gyro_markov_z], noise_symbols: [w_mx, w_my, w_mz], '
        'noise_names: [gyro_markov_noise_x, gyro_markov_noise_y, gyro_markov_noise_z]}\n')))
    at = next(i for i, text in enumerate(path.read_text().splitlines(), start=1) if "gyro_markov_x" in text)
    with pytest.raises(ModelError, match=rf"summed_drift_nav\.yaml:{at}: the navigator cannot fly state 'gyro_markov_x'.*"
                                         r"coupled to attitude_error_north"):
        navigator_spec(path, with_python=False)
