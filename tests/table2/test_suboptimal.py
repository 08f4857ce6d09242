"""The paper's filter designs, made from the full model by transformations (modelgen.table2.suboptimal)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from modelgen.table2.budget import load_error_budget
from modelgen.table2.scenario import load_analysis_scenario
from modelgen.table2.suboptimal import PAPER_FILTERS, filter_model, filter_parameters, gain_schedule
from modelgen.errors import ModelError

DESIGNS = {d.key: d for d in PAPER_FILTERS}


def test_reduced_filter_I_has_13_states_without_vertical_gyro_drift_and_accelerometer_biases(paper_model):
    m = filter_model(paper_model, DESIGNS["suboptimal_1"])
    gone = set(paper_model.state_names) - set(m.state_names)
    assert len(m.states) == 13
    assert gone == {"gyro_constant_drift_z", "gyro_markov_drift_z", "accel_markov_bias_x", "accel_markov_bias_y", "accel_markov_bias_z"}
    assert "gyro_markov_drift_z_white" in m.noise_names and m.measurement_names == paper_model.measurement_names


def test_reduced_filter_IV_has_the_9_navigation_and_doppler_states(paper_model):
    m = filter_model(paper_model, DESIGNS["suboptimal_4"])
    assert m.state_names == paper_model.state_names[:7] + paper_model.state_names[16:]
    assert len(m.noises) == 6  # one white noise per gyro and accelerometer axis


def test_full_order_designs_use_the_full_model(paper_model):
    assert filter_model(paper_model, DESIGNS["optimal"]) is paper_model
    assert filter_model(paper_model, DESIGNS["suboptimal_2"]) is paper_model


def test_lumped_vertical_drift_has_the_rms_of_constant_and_markov_parts():
    budget = load_error_budget()
    out = filter_parameters(DESIGNS["suboptimal_1"], budget.parameters, budget.initial_sigma)
    assert out["gyro_markov_sigma_z"] == pytest.approx(math.sqrt(2) * budget.parameters["gyro_markov_sigma_z"])
    assert out["gyro_markov_sigma_x"] == budget.parameters["gyro_markov_sigma_x"]


def test_piecewise_gain_every_2_steps_while_manoeuvring_then_every_6():
    flags = gain_schedule(DESIGNS["suboptimal_2"], load_analysis_scenario())
    starts = np.flatnonzero(flags)
    assert list(starts[:13]) == [0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24]
    assert list(starts[13:16]) == [30, 36, 42]
    assert len(flags) == 240 and np.all(np.diff(starts[12:]) == 6)


def test_every_step_gain_for_the_optimal_filter():
    assert gain_schedule(DESIGNS["optimal"], load_analysis_scenario()).all()


def test_bad_gain_period_is_refused():
    with pytest.raises(ModelError, match="'suboptimal_2'.*positive integer"):
        gain_schedule(replace(DESIGNS["suboptimal_2"], gain_period=0), load_analysis_scenario())
