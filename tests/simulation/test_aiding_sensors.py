"""Aiding sensors as plug-ins: a sensor registered by a test flies a profile with no module edited,
and every built-in sensor's measurement function agrees with its own simulation at zero noise."""

import dataclasses
from dataclasses import dataclass

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.simulation.doppler import DOPPLER
from modelgen.simulation.filters import ReferenceFilter
from modelgen.simulation.flight import fly_profile, simulate_sensors
from modelgen.simulation.gps import GPS
from modelgen.simulation.ins_aiding import NavigationQuantitySensor
from modelgen.simulation.profile_keys import ProfileSection, valid_mask
from modelgen.simulation.pseudorange import PSEUDORANGE, PseudorangeNavigator
from modelgen.simulation.scenario import load_profile, load_profile_data
from modelgen.simulation.sensors import SENSORS, aiding_sensor, register_sensor
from modelgen.simulation.trajectory import generate_trajectory
from modelgen.fileio.datafiles import read_yaml

pytestmark = pytest.mark.flight


@dataclass(frozen=True)
class VelocityLogSettings:
    period: float = 60.0
    noise: float = 0.1  # m/s rms per horizontal axis


@dataclass(frozen=True)
class VelocityLogRecord:
    times: np.ndarray
    velocity: np.ndarray
    valid: np.ndarray


class VelocityLog(NavigationQuantitySensor):
    """A toy sensor: NED ground velocity with white noise on the horizontal axes, nothing else."""

    name = "velocity_log"

    def read_settings(self, section: ProfileSection) -> VelocityLogSettings:
        settings = VelocityLogSettings(section.number("period_s", 60.0, positive=True),
                                       section.number("noise_mps", 0.1, non_negative=True))
        section.done()
        return settings

    def period(self, settings):
        return settings.period

    def noise_parameters(self, settings):
        # the paper's model calls its velocity-measurement noise the Doppler's
        return {"doppler_noise_sigma_north": settings.noise, "doppler_noise_sigma_east": settings.noise}

    def simulate_at(self, settings, truth, rng):
        noise = np.zeros((len(truth), 3))
        noise[:, :2] = settings.noise * rng.standard_normal((len(truth), 2))
        return VelocityLogRecord(truth[:, 0], truth[:, 4:7] + noise, valid_mask(truth[:, 0], ()))

    def fix(self, record, epoch, navigation):
        return record.velocity[epoch], None


@pytest.fixture
def velocity_log():
    sensor = VelocityLog()
    register_sensor(sensor)
    yield sensor
    del SENSORS[sensor.name]


def velocity_log_profile():
    """profile_000 with its filter aided by the toy sensor (a ``velocity_log`` section and mapping)."""
    data = read_yaml(load_profile("profile_000").source_file, "scenario file")
    data["velocity_log"] = {"period_s": 60.0, "noise_mps": 0.05}
    data["filter"]["aiding"] = "velocity_log"
    data["filter"]["measurements"] = {"velocity_log": data["filter"]["measurements"]["doppler"]}
    data["filter"]["states"].pop("doppler_bias")  # the toy has no bias of its own
    return load_profile_data(data, "velocity_log_profile.yaml")


def test_a_sensor_registered_by_a_test_flies_a_profile_without_editing_any_module(velocity_log, paper_derived):
    profile = velocity_log_profile().with_changes(hours=0.25, imu_rate=20.0)
    assert profile.aiding_sensor is velocity_log and profile.aiding_period == 60.0
    assert profile.noise_parameters()["doppler_noise_sigma_north"] == 0.05  # the aiding sensor's noise holds
    trajectory = generate_trajectory(profile.path, profile.imu_rate, 1.0 / profile.filter.period)
    result = fly_profile(profile, paper_derived, trajectory, np.random.default_rng(4),
                         lambda x, P: ReferenceFilter(paper_derived, x, P))
    assert result.updates == 15 and not result.rejected and not result.refused
    velocity = [paper_derived.model.state_index(n) for n in ("velocity_error_north", "velocity_error_east")]
    assert np.all(np.abs(result.estimation_error[-1, velocity]) < 3 * result.sigma[-1, velocity])
    assert result.sigma[-1, velocity].max() < 0.2  # m/s: the log bounds the velocity error


def test_a_registered_name_cannot_be_taken_twice_and_an_unknown_one_is_refused(velocity_log):
    with pytest.raises(ModelError, match="already registered"):
        register_sensor(VelocityLog())
    with pytest.raises(ModelError, match="not registered"):
        aiding_sensor("sonar")


def test_an_unregistered_aiding_name_is_refused_by_the_profile_loader():
    data = read_yaml(load_profile("profile_000").source_file, "scenario file")
    data["filter"]["aiding"] = "velocity_log"
    with pytest.raises(ModelError, match="'velocity_log' is not one of doppler, gps, pseudorange"):
        load_profile_data(data, "x.yaml")


# -- built-in sensors: measurement function against simulation, zero noise -------------------------


@pytest.fixture(scope="module")
def short_paper_flight():
    profile = load_profile("profile_000").with_changes(hours=0.1, imu_rate=10.0)
    return profile, generate_trajectory(profile.path, profile.imu_rate, 1.0 / profile.filter.period)


@pytest.mark.parametrize("sensor, changes", [
    (DOPPLER, {"bias": 0.0, "white_noise": 0.0}),
    (DOPPLER, {"measurement": "beams", "period": 6.0}),  # beams: the quiet radar is below
    (GPS, {"position_noise": 0.0, "height_noise": 0.0, "velocity_noise": 0.0}),
], ids=["doppler-ned", "doppler-beams", "gps"])
def test_measurement_function_at_the_truth_returns_the_noise_free_simulation(short_paper_flight, sensor, changes):
    profile, trajectory = short_paper_flight
    settings = dataclasses.replace(profile.sensors[sensor.name], **changes)
    if sensor is DOPPLER and settings.measurement == "beams":
        settings = dataclasses.replace(settings, beams=dataclasses.replace(
            settings.beams, frequency_noise=0.0, frequency_bias=0.0, mounting_error=0.0))
    profile = profile.with_sensor(sensor.name, settings).with_changes(
        filter=dataclasses.replace(profile.filter, aiding=sensor.name))
    record = sensor.simulate(profile, trajectory, trajectory.initial_state(), np.random.default_rng(2))
    step = int(round(sensor.period(settings) / trajectory.record_period))
    assert len(record.times) == len(trajectory.truth[::step]) > 5
    for epoch, truth in enumerate(trajectory.truth[::step]):
        velocity, position = sensor.fix(record, epoch, truth[1:])
        assert np.allclose(velocity, truth[4:7], rtol=0, atol=1e-9)
        if position is not None:
            assert np.allclose(position[:2], truth[1:3], rtol=0, atol=1e-15)
            assert position[2] == pytest.approx(truth[3], abs=1e-9)


def test_pseudorange_measurement_at_the_true_state_and_clock_is_zero_without_noise():
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model

    profile = load_profile("profile_003").with_changes(hours=60 / 3600, imu_rate=50.0)
    receiver = dataclasses.replace(profile.sensors["pseudorange"], noise=0.0)
    profile = profile.with_sensor("pseudorange", receiver)
    derived = derive(load_model(profile.filter.model))
    trajectory = generate_trajectory(profile.path, profile.imu_rate, 1.0 / profile.filter.period)
    sensors = simulate_sensors(profile, trajectory, np.random.default_rng(6))
    assert sensors.aiding.clock_bias[0] != 0.0  # the clock runs; the measurement function must remove it
    navigator = PseudorangeNavigator(profile, derived, sensors)
    for k in range(0, len(trajectory.truth), 10):
        output = np.r_[trajectory.truth[k, 1:], sensors.aiding.clock_bias[k], sensors.aiding.clock_drift[k]]
        navigator.cycle = k
        navigator.parameters(output)  # selects the satellites seen from ``output``
        assert np.max(np.abs(navigator.measurement(k, output, np.zeros(11)).z)) < 1e-6  # m, of ~2e7 m ranges


def test_every_built_in_sensor_is_registered_under_its_profile_name():
    assert {name: sensor.name for name, sensor in SENSORS.items()} == {
        "doppler": "doppler", "gps": "gps", "pseudorange": "pseudorange"}
    assert PSEUDORANGE.quantities == () and "velocity_north" in DOPPLER.quantities
