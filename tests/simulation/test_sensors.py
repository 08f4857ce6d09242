"""Sensor models: Doppler radar (the Doppler error thesis), GPS receivers, IMU error processes, WGS-84 earth."""

import math

import numpy as np
import pytest

from modelgen.errors import ModelError
from modelgen.simulation import earth
from modelgen.simulation.doppler import (
    DopplerSettings,
    JanusBeams,
    attitude_induced_error,
    doppler_shift,
    simulate_doppler,
    velocity_from_shifts,
)
from modelgen.simulation.gps import (
    Constellation,
    PseudorangeSettings,
    elevation,
    simulate_pseudoranges,
    solve_position,
)
from modelgen.simulation.imu import ImuErrorBudget, corrupt_increments, markov_sequence
from modelgen.simulation.rotation import euler_quaternion, quaternion_to_dcm, rotation_vectors_to_quaternions, quaternion_product


def test_doppler_shift_is_two_v_cos_gamma_over_lambda():
    # the Doppler error thesis eq. (2-10): a beam at angle gamma to the velocity
    beams = JanusBeams()
    b = beams.directions()
    v = np.array([80.0, 5.0, 2.0])
    gamma = np.arccos(b @ v / np.linalg.norm(v))
    assert np.allclose(doppler_shift(v, b, beams.wavelength), 2 * np.linalg.norm(v) * np.cos(gamma) / beams.wavelength)


def test_janus_beams_give_back_the_body_velocity_exactly():
    beams = JanusBeams()
    v = np.array([[83.3, -4.0, 27.0], [120.0, 10.0, -3.0]])
    assert np.allclose(velocity_from_shifts(doppler_shift(v, beams.directions(), beams.wavelength), beams.directions(), beams.wavelength), v)
    # the four Janus beams are symmetric: fore/aft pairs cancel the vertical in x
    assert np.allclose(beams.directions().sum(axis=0)[:2], 0.0)


def test_attitude_error_in_resolving_the_doppler_gives_minus_psi_cross_v():
    q = np.array(euler_quaternion(0.05, 0.1, 1.2))
    psi = np.array([2e-4, -3e-4, 5e-3])
    v_ned = np.array([10.0, 80.0, -5.0])
    body = quaternion_to_dcm(q).T @ v_ned
    wrong = quaternion_product(rotation_vectors_to_quaternions(-psi), q)  # C~ = (I - psi x) C
    resolved = quaternion_to_dcm(wrong) @ body
    # first order in psi: the second-order remainder is below |psi|^2 |v|
    assert np.allclose(resolved - v_ned, attitude_induced_error(v_ned, psi), rtol=0, atol=np.linalg.norm(psi) ** 2 * np.linalg.norm(v_ned))


def test_doppler_ned_model_has_one_constant_bias_and_white_noise():
    n = 4000
    settings = DopplerSettings(period=60.0, measurement="ned", bias=0.4, white_noise=0.2)
    v = np.tile([0.0, 83.3, 0.0], (n, 1))
    record = simulate_doppler(np.arange(n) * 60.0, v, np.tile([1.0, 0, 0, 0], (n, 1)), settings, np.random.default_rng(1))
    error = record.velocity - v
    assert np.allclose(error.mean(axis=0)[:2], record.bias[0, :2], atol=0.02)
    assert np.allclose(error.std(axis=0)[:2], 0.2, rtol=0.05)
    assert np.all(record.bias == record.bias[0]) and np.all(record.valid)


def test_beams_model_errors_scale_with_frequency_noise():
    n = 2000
    quiet = DopplerSettings(measurement="beams", beams=JanusBeams(frequency_noise=0.0, frequency_bias=0.0, mounting_error=0.0))
    noisy = DopplerSettings(measurement="beams", beams=JanusBeams(frequency_noise=20.0, frequency_bias=0.0, mounting_error=0.0))
    q = np.tile(euler_quaternion(0.0, 0.1, math.pi / 2), (n, 1))
    v = np.tile([0.0, 83.3, -10.0], (n, 1))
    body = np.einsum("kji,kj->ki", quaternion_to_dcm(q), v)
    exact = simulate_doppler(np.arange(n), v, q, quiet, np.random.default_rng(2))
    assert np.allclose(exact.velocity, body)
    rough = simulate_doppler(np.arange(n), v, q, noisy, np.random.default_rng(2))
    # least squares of four beams: sigma_v = lambda/2 sigma_f sqrt(diag((B^T B)^-1))
    b = JanusBeams().directions()
    expected = 0.5 * 0.0225 * 20.0 * np.sqrt(np.diag(np.linalg.inv(b.T @ b)))
    assert np.allclose((rough.velocity - body).std(axis=0), expected, rtol=0.08)


def test_pseudorange_receiver_fix_recovers_position_and_clock_bias():
    position = np.array([[math.radians(30.0), math.radians(120.0), 3000.0]])
    settings = PseudorangeSettings(noise=0.0)
    record = simulate_pseudoranges(np.array([100.0]), position, settings, np.random.default_rng(3))
    visible = np.isfinite(record.pseudoranges[0]).sum()
    assert 6 <= visible <= 12  # a 24-satellite constellation above 10 deg
    fix, clock = solve_position(record.pseudoranges[0], record.satellites[0])
    assert np.allclose(fix, earth.geodetic_to_ecef(*position[0]), atol=1e-4)
    assert clock == pytest.approx(record.clock_bias[0], abs=1e-4)


def test_constellation_orbits_are_circular_and_masked_satellites_are_below_the_horizon():
    sats = Constellation().positions(5000.0)
    assert np.allclose(np.linalg.norm(sats, axis=1), Constellation().radius)
    user = earth.geodetic_to_ecef(0.5, 2.0, 0.0)
    record = simulate_pseudoranges(np.array([5000.0]), np.array([[0.5, 2.0, 0.0]]), PseudorangeSettings(), np.random.default_rng(4))
    masked = ~np.isfinite(record.pseudoranges[0])
    assert np.all(elevation(user, record.satellites[0][masked]) < math.radians(10.0))


def test_too_few_satellites_is_refused():
    with pytest.raises(ModelError, match="at least 4"):
        solve_position(np.array([2e7, 2e7, np.nan, np.nan]), np.ones((4, 3)))


def test_markov_sequence_has_the_stationary_variance_and_correlation():
    dt, tau, sigma = 1.0, 50.0, 2.0
    x = markov_sequence(200_000, sigma, tau, dt, np.random.default_rng(5), axes=1)[:, 0]
    assert x.std() == pytest.approx(sigma, rel=0.05)
    lag = 50
    assert np.corrcoef(x[:-lag], x[lag:])[0, 1] == pytest.approx(math.exp(-lag * dt / tau), abs=0.05)


def test_zero_error_budget_leaves_increments_untouched_and_constants_are_constant():
    rng = np.random.default_rng(6)
    dtheta, dvel = rng.standard_normal((100, 3)), rng.standard_normal((100, 3))
    same = corrupt_increments(dtheta, dvel, 0.01, ImuErrorBudget(), rng, 10)
    assert np.array_equal(same[0], dtheta) and np.array_equal(same[1], dvel)
    budget = ImuErrorBudget(gyro_constant_drift=1e-5, accel_constant_bias=1e-3)
    measured_theta, measured_velocity, history = corrupt_increments(dtheta, dvel, 0.01, budget, rng, 10)
    assert np.allclose(measured_theta - dtheta, history.gyro_constant * 0.01)
    assert np.allclose(measured_velocity - dvel, history.accel_constant * 0.01)


def test_error_budget_refuses_negative_or_uncorrelated_markov_values():
    with pytest.raises(ModelError, match="non-negative"):
        ImuErrorBudget(gyro_constant_drift=-1.0)
    with pytest.raises(ModelError, match="correlation time"):
        ImuErrorBudget(gyro_markov_drift=1e-6)


def test_wgs84_gravity_and_radii_at_equator_and_pole():
    assert earth.normal_gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-9)
    assert earth.normal_gravity(math.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-7)
    assert earth.normal_gravity(0.5, 1000.0) < earth.normal_gravity(0.5, 0.0) - 3.0e-3  # free-air ~3.1e-6 /s^2 per m
    meridian, prime_vertical = earth.radii_of_curvature(0.0)
    assert prime_vertical == pytest.approx(earth.SEMI_MAJOR_AXIS)
    assert meridian == pytest.approx(earth.SEMI_MAJOR_AXIS * (1 - earth.ECCENTRICITY_SQUARED))


def test_geodetic_ecef_round_trip():
    lat, lon, h = np.array([0.3, -1.2, 1.5]), np.array([2.0, -0.5, 3.0]), np.array([0.0, 8000.0, -50.0])
    back = earth.ecef_to_geodetic(earth.geodetic_to_ecef(lat, lon, h))
    assert np.allclose(back[0], lat, atol=1e-11) and np.allclose(back[1], lon) and np.allclose(back[2], h, atol=1e-5)
