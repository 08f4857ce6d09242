"""The NHC lever-arm fit: it recovers a known rear-axle lever arm from a synthetic drive, in the convention the
navigator's NHC rows use, and states a standard error that counts the time correlation of the errors."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from modelgen.navigator.lever_fit import UNKNOWNS, design, fit
from modelgen.navigator.sensors import NHC, body_velocity_rows

#: IMU to the rear axle's centre on the ground: 1.4 m behind, 0.1 m left, 1.3 m below [m]
LEVER = np.array([-1.4, -0.1, 1.3])


def _ar1(rng, n: int, sigma: float, rho: float) -> np.ndarray:
    """A first-order autoregressive series of standard deviation sigma and lag-1 correlation rho."""
    e = rng.normal(0.0, sigma * math.sqrt(1.0 - rho * rho), n)
    out = np.empty(n)
    out[0] = rng.normal(0.0, sigma)
    for k in range(1, n):
        out[k] = rho * out[k - 1] + e[k]
    return out


def _drive(n: int = 4000, noise: float = 0.02, rho: float = 0.9, seed: int = 26):
    """A car at 10 Hz: the rear axle rolls forward at a varying speed, turning, rolling and pitching a little; the
    IMU's body velocity is v_axle - omega x l plus a boresight yaw error of 0.01 rad and correlated noise."""
    rng = np.random.default_rng(seed)
    speed = 8.0 + 4.0 * np.sin(np.arange(n) / 300.0)
    rate = np.column_stack([_ar1(rng, n, 0.03, 0.95), _ar1(rng, n, 0.02, 0.95), _ar1(rng, n, 0.15, 0.98)])
    v_axle = np.column_stack([speed, np.zeros(n), np.zeros(n)])
    v_imu = v_axle - np.cross(rate, LEVER)
    v_imu[:, 1] += -0.01 * speed
    v_body = v_imu[:, 1:3] + np.column_stack([_ar1(rng, n, noise, rho), _ar1(rng, n, noise, rho)])
    return v_body, rate, speed, v_imu


def test_the_fit_recovers_the_rear_axle_lever_arm_and_the_boresight_term():
    v_body, rate, speed, _ = _drive()
    result = fit(v_body, rate, speed, lags=50)
    for name, truth in zip(("l_x", "l_y", "l_z"), LEVER):
        assert abs(result.estimate[name] - truth) < 4.0 * result.standard_error[name]
        assert abs(result.estimate[name] - truth) < 0.05
    assert result.estimate["lateral_per_speed"] == pytest.approx(-0.01, abs=2e-3)
    assert result.residual_rms["lateral"] < result.raw_rms["lateral"]


def test_the_fitted_lever_arm_zeroes_the_navigator_s_nhc_rows():
    """The fit's l is nhc.lever_arm_m's: the body-velocity rows at it vanish where the noise and boresight do."""
    _, rate, speed, v_imu = _drive(n=50)
    for k in range(50):
        z, _ = body_velocity_rows(SimpleNamespace(n_states=15, blocks={"attitude": _NoBlock(), "velocity": _NoBlock()}),
                                  np.eye(3), v_imu[k] + [0.0, 0.01 * speed[k], 0.0], rate[k], LEVER, NHC.axes, 0.0)
        assert np.abs(z).max() < 1e-12


class _NoBlock:
    """A spec block with no states (only z is looked at)."""

    indices, axes, signs = (), (), ()


def test_the_standard_error_counts_the_correlation_of_the_errors():
    """With errors correlated over about 20 steps the Newey-West error is several times the OLS one; with white
    errors the two agree."""
    v_body, rate, speed, _ = _drive(rho=0.95)
    correlated = fit(v_body, rate, speed, lags=100)
    assert correlated.standard_error["l_x"] > 2.0 * correlated.ols_standard_error["l_x"]
    v_body, rate, speed, _ = _drive(rho=0.0)
    white = fit(v_body, rate, speed, lags=100)
    assert white.standard_error["l_x"] == pytest.approx(white.ols_standard_error["l_x"], rel=0.3)


def test_the_design_has_one_column_per_unknown_and_two_rows_per_step():
    A = design(np.zeros((5, 3)), np.ones(5))
    assert A.shape == (10, len(UNKNOWNS))


RESULTS = Path(__file__).parents[2] / "bench" / "results"


@pytest.mark.parametrize("config_name", ["replay_drive_0708.yaml", "replay_drive_0708_21.yaml"])
def test_the_shipped_configurations_hold_stage_10_s_lever_arm_and_rate_limit(config_name):
    """nhc.lever_arm_m is the fit's components above 3 Newey-West sigma (bench/navigator_tuning.py --lever-arm, its
    result committed in bench/results), each configuration its own model's; nhc.rate_max_deg_s is what stage 3's
    rule picks with that lever arm; the tuning: record names both."""
    from modelgen.navigator.config import DEG, builtin_config_path, load_config

    config = load_config(builtin_config_path().parent / config_name)
    (result,) = [r for r in json.loads((RESULTS / "navigator_tuning_stage10_lever_arm.json").read_text())["results"]
                 if r["configuration"] == config_name]
    assert result["model"] == config.model
    for name, chosen, held in zip(("l_x", "l_y", "l_z"), result["chosen_lever_arm_m"], config.nhc_lever_arm):
        significant = result["fit"]["significance"][name] > 3.0
        assert held == (pytest.approx(round(result["fit"]["estimate"][name], 2)) if significant else 0.0) == chosen
    assert config.nhc_rate_max == pytest.approx(result["rate_limit_choice"][str(result["chosen_lever_arm_m"])] * DEG)
    assert {"nhc.lever_arm_m", "nhc.rate_max_deg_s"} <= set(config.tuning)
