"""Observability: ranks and unobservable directions, each justified from the error equations.

Scenarios are level flight (modelgen.model.library.level_flight) at 30 N; "turn"
scenarios are two segments with different headings (piecewise-constant
system).  Sensor statistics only matter for G and Q, not for observability,
except the Markov correlation rates, which enter F.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from modelgen.cli import main
from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.operating_point import level_flight, pseudorange_parameters
from modelgen.model.pseudorange import pseudorange_model
from modelgen.model.declaration import ErrorModel, Measurement, State
from modelgen.model.loading import load_model
from modelgen.analysis.observability import (
    ObservabilityScenario,
    Segment,
    _readable_basis,
    analyse,
    command_line_scenario,
    format_report,
    observability_matrix,
    scenario_from_data,
    single_segment,
)

LATITUDE = math.radians(30)
EAST, NORTH = math.pi / 2, 0.0


@pytest.fixture(scope="module")
def ned(paper_derived):
    return paper_derived


@pytest.fixture(scope="module")
def ins_gps(derived_builtin):
    return derived_builtin("ins_gps15")


def ned_values(model, heading: float, speed: float = 250.0) -> dict[str, float]:
    values = level_flight(model, LATITUDE, speed, heading)
    for a in "xyz":
        values.update({f"gyro_markov_rate_{a}": 1 / 3600, f"gyro_markov_sigma_{a}": 4.8e-7})
        values.update({f"accel_markov_rate_{a}": 1 / 1800, f"accel_markov_sigma_{a}": 1e-3})
    values.update(doppler_noise_sigma_north=0.1, doppler_noise_sigma_east=0.1)
    return values


def gps_values(model, heading: float, speed: float = 250.0) -> dict[str, float]:
    values = level_flight(model, LATITUDE, speed, heading, height=1000.0)
    values.update(gyro_angle_random_walk=1e-5, accel_velocity_random_walk=1e-4)
    values.update({f"gps_{k}_sigma_{a}": 1.0 for k in ("velocity", "position") for a in ("east", "north", "up")})
    return values


def components(direction) -> dict[str, float]:
    return dict(direction.components)


# -- the core paper's Doppler-aided model ---------------------------------------------------
def test_longitude_error_is_unobservable_under_doppler_velocity_aiding(ned):
    """Nothing in F depends on longitude (no column) and H does not measure it: O e_lambda = 0."""
    model = ned.model
    lam = model.state_index("longitude_error")
    O = observability_matrix(ned, single_segment(ned_values(model, EAST), 60.0, 240))
    assert np.all(O[:, lam] == 0)
    report = analyse(ned, single_segment(ned_values(model, EAST), 60.0, 240))
    assert report.unobservable_share["longitude_error"] == pytest.approx(1.0, abs=1e-9)
    assert any(components(d) == {"longitude_error": pytest.approx(1.0)} for d in report.unobservable)
    assert "longitude_error" in report.unobservable_states()


def test_doppler_aided_level_flight_has_rank_12_and_a_turn_raises_it_to_16(ned):
    """Rank 12 of 18 at constant heading: six unobservable directions.

    * longitude error (above);
    * the z accelerometer bias: in level flight it only drives the vertical
      channel, which the model does not have (row 3 of C_b^n never reaches
      dV_n, dV_e);
    * a 3-parameter family of steady states: a constant east velocity error
      equal to the east Doppler bias (Z_e = 0), a latitude error and a
      heading error, with the tilts that cancel the velocity-error rates and
      the three random-constant gyro drifts that cancel the attitude rates;
    * one decaying mode at the gyro Markov rate: a heading error and a
      combination of the three Markov drifts whose attitude-rate effects
      cancel (3 attitude equations, 4 unknowns).
    A turn changes C_b^n, which separates the drifts from the attitude errors
    and the Doppler bias from the velocity error: only longitude and the z
    accelerometer bias stay unobservable (rank 16).
    """
    model = ned.model
    straight = analyse(ned, single_segment(ned_values(model, EAST), 60.0, 240))
    assert straight.rank == 12
    assert straight.unobservable_share["accel_markov_bias_z"] == pytest.approx(1.0, abs=1e-9)
    assert {"heading_error", "doppler_velocity_bias_east", "gyro_constant_drift_x"} <= set(straight.unobservable_states())
    # the rank does not depend on the window once it is longer than the state dimension
    assert analyse(ned, single_segment(ned_values(model, EAST), 60.0, 18)).rank == 12

    turn = ObservabilityScenario(60.0, (Segment(ned_values(model, EAST), 60), Segment(ned_values(model, NORTH), 60)))
    report = analyse(ned, turn)
    assert report.rank == 16
    assert set(report.unobservable_states()) == {"longitude_error", "accel_markov_bias_z"}


# -- the INS/GPS paper's INS/GPS model ----------------------------------------------------------------
def test_position_and_velocity_are_observable_with_position_and_velocity_measurements(ins_gps):
    report = analyse(ins_gps, single_segment(gps_values(ins_gps.model, EAST), 1.0, 60))
    for name in ("velocity_error_east", "velocity_error_north", "velocity_error_up", "latitude_error", "longitude_error", "height_error"):
        assert report.unobservable_share[name] < 1e-6, name


def test_ins_gps_at_constant_heading_has_rank_12_with_the_classic_three_ambiguities(ins_gps):
    """Three unobservable pairs (rank 12 of 15), from d(dv)/dt = f x phi + C nabla with f = (0, 0, g):

    * east tilt phi_E and the accelerometer along north both set d(dv_N)/dt;
    * north tilt phi_N and the accelerometer along east both set d(dv_E)/dt;
    * heading error phi_U and the gyro along east: phi_U enters d(phi_E)/dt
      only through -(W cos L + v_E/R) phi_U, which a constant east gyro
      drift cancels exactly.
    Each tilt direction also carries the gyro drifts that cancel its
    earth-rate couplings (e.g. W sin L phi_E in d(phi_N)/dt), components of
    order W/g smaller.  Heading east with right-forward-up body axes: body x
    points south, body y east.
    """
    report = analyse(ins_gps, single_segment(gps_values(ins_gps.model, EAST), 1.0, 60))
    assert report.rank == 12
    involved = {"attitude_error_east", "accel_constant_bias_x", "attitude_error_north", "accel_constant_bias_y", "attitude_error_up", "gyro_constant_drift_y"}
    for name, share in report.unobservable_share.items():
        if name in involved:
            assert share > 0.3, name
        else:  # the other gyros' small earth-rate-cancelling parts (share < 1e-2 in scaled coordinates)
            assert share < 1e-2, name
    pairs = [set(components(d)) for d in report.unobservable]
    assert {"attitude_error_east", "accel_constant_bias_x"} in pairs


def test_a_turn_makes_the_ins_gps_model_fully_observable(ins_gps):
    model = ins_gps.model
    turn = ObservabilityScenario(1.0, (Segment(gps_values(model, EAST), 60), Segment(gps_values(model, NORTH), 60)))
    report = analyse(ins_gps, turn)
    assert report.rank == 15 and report.unobservable == ()


# -- the accumulated-correction paper's pseudo-range model --------------------------------------------------------------
def pseudorange_values(model, satellites) -> dict[str, float]:
    values = level_flight(model, LATITUDE, 200.0, EAST)
    values.update(gyro_angle_random_walk=1e-5, accel_velocity_random_walk=1e-4, clock_bias_psd=1.0, clock_drift_psd=0.01)
    values.update(pseudorange_parameters(satellites))
    values.update({f"pseudorange_sigma_{k}": 3.0 for k in range(1, len(satellites) + 1)})
    return values


FOUR = [(0.0, math.pi / 2), (0.0, 0.5), (2.1, 0.5), (4.2, 0.5)]


def test_four_pseudoranges_make_all_eleven_states_observable():
    """Position and clock bias from four ranges at once, velocity and clock drift from their change,
    tilts through f x psi, heading through the earth-rate coupling of psi_U into psi_E: full rank."""
    d = derive(pseudorange_model(4))
    report = analyse(d, single_segment(pseudorange_values(d.model, FOUR), 1.0, 11))
    assert report.rank == 11


def test_three_pseudoranges_leave_the_missing_geometry_direction_only_weakly_observable():
    """With three ranges, position along one direction trades against the clock bias at each epoch;
    only the INS dynamics separate them: a weak direction of clock bias and position."""
    d = derive(pseudorange_model(3))
    report = analyse(d, single_segment(pseudorange_values(d.model, FOUR[:3]), 1.0, 11))
    assert report.rank == 11
    weakest = min(report.weak, key=lambda w: w.relative_singular_value)
    assert weakest.relative_singular_value < 1e-6
    names = set(components(weakest))
    assert "clock_bias_range" in names and names & {"position_error_east", "position_error_north", "position_error_up"}


# -- the method on small systems with known answers ------------------------------------------------
def double_integrator(measured: str) -> ErrorModel:
    return ErrorModel.build(
        name="double_integrator",
        states=[State("position_error", "m", symbol="p"), State("velocity_error", "m/s", symbol="v")],
        noises=[],
        parameters=[],
        dynamics={"p": "v", "v": "0"},
        measurements=[Measurement("measured", expression=measured, variance="1")],
    )


def test_position_measurement_observes_a_double_integrator_and_velocity_does_not_observe_position():
    full = analyse(derive(double_integrator("p")), single_segment({}, 1.0, 2))
    assert full.rank == 2 and full.unobservable == ()
    blind = analyse(derive(double_integrator("v")), single_segment({}, 1.0, 5))
    assert blind.rank == 1
    assert components(blind.unobservable[0]) == {"position_error": pytest.approx(1.0)}
    # one measurement step cannot observe velocity yet
    assert analyse(derive(double_integrator("p")), single_segment({}, 1.0, 1)).rank == 1


def test_state_scales_do_not_change_the_rank_or_the_unobservable_states(ned):
    scenario = single_segment(ned_values(ned.model, EAST), 60.0, 60)
    # typical magnitudes (Table 1 of the core paper): rad, m/s, rad/s, m/s^2
    scales = {n: 6e-4 for n in ("attitude_error_north", "attitude_error_east")}
    scales.update(heading_error=6e-3, velocity_error_north=1.0, velocity_error_east=1.0, latitude_error=1e-4, longitude_error=1e-4)
    scales.update(doppler_velocity_bias_north=0.4, doppler_velocity_bias_east=0.4)
    scales.update({n: 5e-7 for n in ned.model.state_names if n.startswith("gyro")})
    scales.update({n: 1e-3 for n in ned.model.state_names if n.startswith("accel")})
    a, b = analyse(ned, scenario), analyse(ned, scenario, scales=scales)
    assert a.rank == b.rank
    # states entirely inside or entirely outside the unobservable subspace stay so under scaling;
    # the share of a state partly inside it depends on the scaling (it is a coordinate statement)
    for threshold in (lambda r: {n for n, v in r.unobservable_share.items() if v > 1 - 1e-9},
                      lambda r: {n for n, v in r.unobservable_share.items() if v < 1e-9}):
        assert threshold(a) == threshold(b)
    assert {"longitude_error", "accel_markov_bias_z"} <= {n for n, v in b.unobservable_share.items() if v > 1 - 1e-9}


def test_readable_basis_turns_a_mixed_basis_into_single_states_where_possible():
    e1, e2, e3 = np.eye(3)
    basis = np.array([(e1 + e2) / math.sqrt(2), (e1 - e2) / math.sqrt(2)])
    out = _readable_basis(basis)
    assert sorted(np.argmax(np.abs(v)) for v in out) == [0, 1]
    for v in out:
        assert np.count_nonzero(np.abs(v) > 1e-12) == 1
    mixed = _readable_basis(np.array([(e1 + e3) / math.sqrt(2)]))
    assert np.allclose(np.abs(mixed[0]), [1 / math.sqrt(2), 0, 1 / math.sqrt(2)])


def test_a_model_without_measurements_is_refused():
    d = derive(load_model("ned_inertial16"))
    with pytest.raises(ModelError, match="no measurements"):
        analyse(d, single_segment(ned_values(d.model, EAST), 60.0, 10))


# -- scenarios ----------------------------------------------------------------------------------------
def test_scenario_data_with_segments_overrides_shared_parameters():
    s = scenario_from_data({"step": 60, "parameters": {"a": 1, "b": 2}, "segments": [{"steps": 3}, {"steps": 2, "parameters": {"b": 5}}]})
    assert s.step == 60.0 and s.n_steps == 5
    assert s.segments[0].values == {"a": 1.0, "b": 2.0} and s.segments[1].values == {"a": 1.0, "b": 5.0}


@pytest.mark.parametrize(
    "data, problem",
    [
        ([1, 2], "must be a mapping"),
        ({"step": 60}, "either 'steps'"),
        ({"step": 60, "steps": 3, "segments": [{"steps": 1}]}, "either 'steps'"),
        ({"step": -1, "steps": 3}, "step must be a positive number"),
        ({"step": 60, "steps": 0}, "positive integer"),
        ({"step": 60, "steps": 3, "parameters": {"latitude": "north"}}, "not a number"),
        ({"step": 60, "steps": 3, "speed": 3}, "unknown key 'speed'"),
        ({"step": 60, "segments": [{"parameters": {}}]}, "with 'steps'"),
    ],
)
def test_bad_scenarios_are_refused_naming_the_problem(data, problem):
    with pytest.raises(ModelError, match=problem):
        scenario_from_data(data, "s.yaml")


def test_command_line_scenario_applies_set_step_and_steps(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump({"step": 60, "steps": 4, "parameters": {"latitude": 0.5}}))
    s = command_line_scenario(path, ["latitude=0.7", "velocity_east=10"], step=30.0, steps=8)
    assert s.step == 30.0 and s.n_steps == 8 and s.segments[0].values == {"latitude": 0.7, "velocity_east": 10.0}
    with pytest.raises(ModelError, match="NAME=VALUE"):
        command_line_scenario(None, ["latitude"])
    assert command_line_scenario(None, [], default_steps=18).n_steps == 18


# -- the command -----------------------------------------------------------------------------------
def test_cli_reports_rank_and_names_longitude_for_the_doppler_model(tmp_path, ned):
    values = ned_values(ned.model, EAST)
    path = tmp_path / "level_east.yaml"
    path.write_text(yaml.safe_dump({"step": 60.0, "steps": 60, "parameters": {k: float(v) for k, v in values.items()}}))
    result = CliRunner().invoke(main, ["observability", "ned_doppler18", "--scenario", str(path)])
    assert result.exit_code == 0, result.output
    assert "rank of the observability matrix: 12 of 18" in result.output
    assert "+1.000*longitude_error" in result.output
    report = analyse(ned, single_segment(values, 60.0, 60))
    assert result.output.strip() == format_report(report)


def test_cli_missing_operating_point_is_an_error_naming_the_parameter(tmp_path):
    """A model with neither the paper's parameters nor a check scenario needs --set or --scenario."""
    model = tmp_path / "tilt.yaml"
    model.write_text(
        "model: tilt\nparameters:\n  - {name: gravity, symbol: g}\nstates:\n  - {name: tilt, symbol: a}\n"
        "  - {name: velocity_error, symbol: v}\ndynamics:\n  a: 0\n  v: g*a\n"
        "measurements:\n  - {name: velocity_measured, symbol: z, expression: v, variance: '1'}\n",
        encoding="utf-8",
    )
    result = CliRunner().invoke(main, ["observability", str(model)])
    assert result.exit_code == 2
    assert "no value for parameter" in result.output and "gravity" in result.output


def test_cli_uses_the_models_check_scenario_when_the_paper_does_not_cover_it():
    result = CliRunner().invoke(main, ["observability", "ins_gps15"])
    assert result.exit_code == 0, result.output
    assert "scenario: the model's check scenario" in result.output


def test_cli_defaults_to_the_papers_level_flight_for_the_paper_model():
    result = CliRunner().invoke(main, ["observability", "ned_doppler18"])
    assert result.exit_code == 0, result.output
    assert "level flight" in result.output
    assert "rank of the observability matrix: 12 of 18" in result.output
    assert "+1.000*longitude_error" in result.output
