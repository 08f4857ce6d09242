"""Any model can fly: parameters by name from the simulation, constants from the profile, or a refusal naming them."""

import dataclasses

import numpy as np
import pytest
import yaml

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path
from modelgen.simulation.aiding import operating_point
from modelgen.simulation.filters import named_parameters
from modelgen.simulation.flight_report import simulate
from modelgen.simulation.scenario import load_profile, load_profile_data

pytestmark = pytest.mark.flight

BODY = ["body_rate_x", "body_rate_y", "body_rate_z", "body_specific_force_x", "body_specific_force_y", "body_specific_force_z"]


@pytest.fixture(scope="module")
def augmented(derived_builtin):
    return derived_builtin("ned_doppler32_augmented")  # load_and_derive, once per session


def _vocabulary(profile) -> dict[str, float]:
    nav = np.array([0.5, 2.0, 100.0, 10.0, 20.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    return operating_point(nav, np.array([0.0, 0.0, -9.8]), "NED", profile.imu_budget, profile.constant_parameters())


def test_parameters_the_simulation_cannot_supply_are_refused_all_by_name_with_the_way_to_supply_them(augmented):
    profile = load_profile("profile_000")
    with pytest.raises(ModelError) as refused:
        named_parameters(augmented, _vocabulary(profile))
    message = str(refused.value)
    assert all(name in message for name in BODY)
    assert "filter.parameters" in message and "latitude" in message and "pseudorange_sigma_<k>" in message


def test_profile_filter_parameters_are_constants_that_complete_the_model(augmented):
    data = yaml.safe_load(data_path("profile_000.yaml").read_text(encoding="utf-8"))
    data["filter"]["parameters"] = {name: 0.0 for name in BODY} | {"body_specific_force_z": -9.8}
    profile = load_profile_data(data, "p.yaml")
    assert profile.constant_parameters()["body_specific_force_z"] == -9.8
    assert "body_specific_force_z" not in profile.noise_parameters()
    chosen = named_parameters(augmented, _vocabulary(profile))
    assert chosen["body_rate_x"] == 0.0 and chosen["latitude"] == 0.5


def test_a_filter_parameter_that_is_not_a_number_is_refused_with_its_line():
    text = data_path("profile_000.yaml").read_text(encoding="utf-8").replace(
        "  gate_probability:", "  parameters: {body_rate_x: fast}\n  gate_probability:", 1)
    with pytest.raises(ModelError, match="body_rate_x: 'fast' is not a number"):
        load_profile_data(yaml.safe_load(text), "p.yaml")


def test_an_augmented_model_flies_the_paper_profile_with_constants_from_the_profile(augmented, tmp_path):
    profile = load_profile("profile_000").with_changes(hours=1 / 60, imu_rate=30.0, model="ned_doppler32_augmented")
    assert profile.filter.model == "ned_doppler32_augmented"
    constants = {name: 0.0 for name in BODY} | {"body_specific_force_z": -9.8}
    profile = dataclasses.replace(profile, filter=dataclasses.replace(profile.filter, parameters=constants))
    summary = simulate(profile, augmented, tmp_path, runs=0, echo=lambda line: None, implementation="reference")
    text = summary.read_text(encoding="utf-8")
    assert "filter model `ned_doppler32_augmented`" in text and "| closed_loop |" in text
