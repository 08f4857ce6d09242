"""Navigation models: a bias declared as a sum of processes, and an aiding sensor's own bias in a measurement."""

from __future__ import annotations

import pytest
import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.loading import load_model_text

C11 = sp.Symbol("c11", real=True)


@pytest.fixture(scope="module")
def twin(derived_builtin):
    return derived_builtin("ned_doppler18_twin")


def test_gyro_drift_declared_twice_is_the_sum_of_a_random_constant_and_a_markov_process(twin):
    model = twin.model
    alpha = model.state_index("alpha")
    assert twin.F[alpha, model.state_index("eps_c_x")] == twin.F[alpha, model.state_index("eps_r_x")] == -C11
    markov = model.state_index("eps_r_x")
    assert twin.F[markov, markov] == -sp.Symbol("mu_eps", real=True)
    assert all(twin.F[model.state_index("eps_c_x"), j] == 0 for j in range(twin.n_states))


def test_a_measurement_bias_is_a_random_constant_state_the_measured_value_carries(twin):
    model = twin.model
    bias = model.state_index("dV_dn")
    assert [m.symbol for m in model.measurements] == ["Z_n", "Z_e"]
    assert twin.H[0, bias] == -1 and twin.H[0, model.state_index("dV_n")] == 1
    assert all(twin.F[bias, j] == 0 for j in range(twin.n_states))
    assert model.states[bias].name == "doppler_velocity_bias_north"


MINIMAL = """\
model: m
frame: NED
navigation:
  errors:
    attitude: {{form: phi}}
    velocity: {{symbol: dv}}
    position: {{form: geodetic}}
  sensor_errors:
{sensors}
  measurements:
{measurements}
"""


def test_a_receiver_clock_declared_twice_is_refused_naming_the_line():
    sensors = "    - {of: receiver_clock, process: clock, psd: [1, 1]}\n    - {of: receiver_clock, process: clock, psd: [1, 1]}"
    with pytest.raises(ModelError, match=r"m\.yaml:\d+: sensor error 'receiver_clock' is declared twice"):
        load_model_text(MINIMAL.format(sensors=sensors, measurements="    []"), "m.yaml")


def test_a_bias_with_the_wrong_number_of_states_is_refused():
    sensors = "    - {of: gyro_bias, process: random_constant}"
    measurements = "    - {of: velocity, symbols: [z1, z2, z3], variance: 1, bias: {symbols: [b1, b2]}}"
    with pytest.raises(ModelError, match=r"bias\.symbols' must list 3 names, got 2 names"):
        load_model_text(MINIMAL.format(sensors=sensors, measurements=measurements), "m.yaml")
