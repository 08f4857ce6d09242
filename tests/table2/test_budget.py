"""The error budget file, Table 1 (modelgen.table2.budget) and its units."""

from __future__ import annotations

import math

import pytest

from modelgen.table2.budget import load_error_budget
from modelgen.model.units import ARCSEC_PER_RAD, to_si
from modelgen.errors import ModelError
from modelgen.model.transform import keep_states

DEG_PER_HOUR = math.radians(1.0) / 3600.0


def test_table_1_values_in_si():
    b = load_error_budget()
    assert b.initial_sigma["attitude_error_north"] == pytest.approx(120.0 / ARCSEC_PER_RAD)
    assert b.initial_sigma["heading_error"] == pytest.approx(math.radians(20.0 / 60.0))
    assert b.initial_sigma["gyro_constant_drift_z"] == pytest.approx(0.1 * DEG_PER_HOUR)
    assert b.initial_sigma["accel_markov_bias_y"] == pytest.approx(1e-4 * 9.80665)
    assert b.initial_sigma["doppler_velocity_bias_east"] == pytest.approx(1.5 / 3.6)
    assert b.parameters["gyro_markov_rate_x"] == pytest.approx(1 / 3600.0)
    assert b.parameters["accel_markov_rate_z"] == pytest.approx(1 / 1800.0)
    assert set(b.inferred) == {"doppler_noise_sigma_north", "doppler_noise_sigma_east"}


def test_initial_covariance_follows_the_model_state_order(paper_model):
    b = load_error_budget()
    pure = keep_states(paper_model, paper_model.state_names[:16])
    P0 = b.initial_covariance(pure)
    assert P0.shape == (16, 16)
    assert P0[2, 2] == pytest.approx(math.radians(1 / 3) ** 2)
    assert P0[3, 3] == 0.0


def test_initial_covariance_names_an_unbudgeted_state(paper_model):
    b = load_error_budget()
    sigmas = dict(b.initial_sigma)
    del sigmas["latitude_error"]
    partial = type(b)(b.name, sigmas, b.parameters)
    with pytest.raises(ModelError, match="no initial sigma for state.*latitude_error"):
        partial.initial_covariance(paper_model)


def test_unknown_unit_is_named(tmp_path):
    path = tmp_path / "budget.yaml"
    path.write_text("budget: t\ninitial_sigma:\n  alpha: {value: 1, unit: furlong}\nparameters: {}\n", encoding="utf-8")
    with pytest.raises(ModelError, match="initial_sigma.alpha.*unknown unit 'furlong'"):
        load_error_budget(path)


def test_negative_sigma_is_refused(tmp_path):
    path = tmp_path / "budget.yaml"
    path.write_text("budget: t\ninitial_sigma:\n  alpha: {value: -1, unit: arcsec}\nparameters: {}\n", encoding="utf-8")
    with pytest.raises(ModelError, match="cannot be negative"):
        load_error_budget(path)


def test_replacing_an_unknown_parameter_is_refused():
    with pytest.raises(ModelError, match="no parameter named doppler_noise_sigma_up"):
        load_error_budget().with_parameters(doppler_noise_sigma_up=1.0)


def test_to_si_refuses_non_numbers():
    with pytest.raises(ModelError, match="'fast' is not a number"):
        to_si("fast", "km/h", "speed")
