"""Circular error probable and paper units (modelgen.table2.metrics)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from modelgen.table2.metrics import cep_approximation, cep_factor, circular_error_probable, navigation_errors


def test_cep_of_a_circular_distribution_is_sqrt_2_ln_2_sigma():
    assert circular_error_probable(np.diag([4.0, 4.0])) == pytest.approx(2.0 * math.sqrt(2 * math.log(2)), rel=1e-7)


def test_cep_of_a_one_axis_distribution_is_the_median_of_the_absolute_error():
    assert circular_error_probable(np.diag([9.0, 0.0])) == pytest.approx(3.0 * 0.6744897501960817, rel=1e-7)


def test_cep_does_not_depend_on_the_orientation_of_the_ellipse():
    theta = 0.7
    rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    cov = np.diag([5.0, 1.0])
    assert circular_error_probable(rot @ cov @ rot.T) == pytest.approx(circular_error_probable(cov), rel=1e-9)


def test_cep_agrees_with_monte_carlo():
    rng = np.random.default_rng(0)
    z = rng.standard_normal((2, 400_000))
    radius = np.hypot(z[0], 0.4 * z[1])
    assert cep_factor(0.4) == pytest.approx(np.median(radius), rel=4e-3)


def test_usual_approximation_is_within_half_a_percent_for_similar_axes_only():
    for rho in (0.7, 0.9, 1.0):
        exact = circular_error_probable(np.diag([1.0, rho**2]))
        assert cep_approximation(1.0, rho) == pytest.approx(exact, rel=5e-3)
    exact = circular_error_probable(np.diag([1.0, 0.25]))
    assert 1.01 < cep_approximation(1.0, 0.5) / exact < 1.02


def test_navigation_errors_are_in_the_papers_units():
    names = ["attitude_error_north", "velocity_error_north", "latitude_error", "longitude_error"]
    R, lat = 6.4e6, math.radians(60.0)
    sigma = np.array([100.0 / 206264.80624709636, 1852.0 / 3600.0, 1852.0 / R, 2 * 1852.0 / (R * math.cos(lat))])
    cov = np.diag(sigma**2)[None].repeat(2, axis=0)
    e = navigation_errors(cov, names, lat, R, np.array([0.0, 2.0]))
    assert e["attitude_error_north"][-1] == pytest.approx(100.0)  # arcsec
    assert e["velocity_error_north"][-1] == pytest.approx(1.0)  # nmile/h
    assert e["position_error_north"][-1] == pytest.approx(1.0) and e["position_error_east"][-1] == pytest.approx(2.0)
    assert e["average_drift_rate"][-1] == pytest.approx(e["position_cep"][-1] / 2.0)
    assert e["average_drift_rate"][0] == 0.0
    assert "doppler_bias_error_north" not in e
