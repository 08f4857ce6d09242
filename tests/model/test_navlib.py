"""The navigation library against independent sources.

Oracles: the values NIMA TR8350.2 publishes (radii at the equator and the
poles, normal gravity at the equator and the poles, the free-air gradient),
pymap3d's geodetic -> ECEF conversion (the radii of curvature are the rates
of change of the ECEF position along the meridian and the parallel), and
scipy's rotations for Euler angles and quaternions.  The numeric Earth of the
simulation (modelgen.simulation.earth) must give the same numbers.
"""

import math

import numpy as np
import pymap3d
import pytest
import sympy as sp
from scipy.spatial.transform import Rotation

from modelgen.errors import ModelError
from modelgen.model import navlib, wgs84
from modelgen.model.ned_enu import NED_TO_ENU
from modelgen.simulation import earth

LATITUDES_DEG = (-89.0, -60.0, -33.3, 0.0, 12.5, 45.0, 60.0, 89.9)


def number(expr) -> float:
    return float(sp.N(expr, 30))


def test_radii_at_equator_and_pole_are_the_published_wgs84_values():
    # TR8350.2 Table 3.3: a = 6378137 m, b^2/a = a(1-e^2) = 6335439.3273 m, polar radius of curvature c = 6399593.6258 m.
    assert number(navlib.meridian_radius(0)) == pytest.approx(6335439.3273, abs=1e-3)
    assert number(navlib.prime_vertical_radius(0)) == pytest.approx(6378137.0, abs=1e-6)
    assert number(navlib.meridian_radius(sp.pi / 2)) == pytest.approx(6399593.6258, abs=1e-3)
    assert number(navlib.prime_vertical_radius(-sp.pi / 2)) == pytest.approx(6399593.6258, abs=1e-3)


@pytest.mark.parametrize("latitude_deg", LATITUDES_DEG)
def test_radii_are_the_rates_of_pymap3d_ecef_position_along_meridian_and_parallel(latitude_deg):
    """R_M = |d r_ecef / dL| and R_N cos L = |d r_ecef / d lambda| at h = 0 (central differences on pymap3d)."""
    step = 1e-6  # deg
    ell = pymap3d.Ellipsoid.from_name("wgs84")

    def ecef(lat, lon):
        return np.array(pymap3d.geodetic2ecef(lat, lon, 0.0, ell=ell, deg=True))

    d_lat = (ecef(latitude_deg + step, 10.0) - ecef(latitude_deg - step, 10.0)) / math.radians(2 * step)
    d_lon = (ecef(latitude_deg, 10.0 + step) - ecef(latitude_deg, 10.0 - step)) / math.radians(2 * step)
    latitude = math.radians(latitude_deg)
    assert number(navlib.R_M(latitude)) == pytest.approx(np.linalg.norm(d_lat), rel=1e-8)
    assert number(navlib.R_N(latitude)) * math.cos(latitude) == pytest.approx(np.linalg.norm(d_lon), rel=1e-8)


def test_normal_gravity_at_equator_and_pole_is_tr8350_2s_value():
    assert number(navlib.normal_gravity(0, 0)) == pytest.approx(9.7803253359, abs=1e-10)
    assert number(navlib.normal_gravity(sp.pi / 2, 0)) == pytest.approx(9.8321849378, abs=1e-9)


def test_normal_gravity_falls_with_height_by_the_free_air_gradient():
    """About 0.3086 mGal per metre (3.086e-6 s^-2), the normal free-air gradient of geodesy."""
    h = sp.Symbol("h", real=True)
    gradient = sp.diff(navlib.normal_gravity(sp.pi / 4, h), h).subs(h, 0)
    assert number(gradient) == pytest.approx(-3.086e-6, rel=2e-3)


@pytest.mark.parametrize("latitude_deg", LATITUDES_DEG)
@pytest.mark.parametrize("height", (0.0, 350.0, 10_000.0))
def test_simulation_earth_and_wgs84_module_compute_the_same_numbers_as_the_library(latitude_deg, height):
    latitude = math.radians(latitude_deg)
    meridian, prime_vertical = earth.radii_of_curvature(latitude)
    assert number(navlib.meridian_radius(latitude)) == pytest.approx(meridian, rel=1e-14)
    assert number(navlib.prime_vertical_radius(latitude)) == pytest.approx(prime_vertical, rel=1e-14)
    assert wgs84.earth_radii(latitude) == pytest.approx((meridian, prime_vertical), rel=1e-14)
    assert number(navlib.normal_gravity(latitude, height)) == pytest.approx(earth.normal_gravity(latitude, height), rel=1e-14)
    rate = [number(c) for c in navlib.earth_rate_ned(latitude)]
    assert rate == pytest.approx(list(earth.earth_rate_ned(latitude)), rel=1e-14, abs=1e-20)
    velocity = (120.0, -35.0, 2.0)
    transport = [number(c) for c in navlib.transport_rate_ned(latitude, height, list(velocity))]
    assert transport == pytest.approx(list(earth.transport_rate_ned(latitude, height, *velocity[:2])), rel=1e-13)
    position_rate = [number(c) for c in navlib.position_rate_ned(latitude, height, list(velocity))]
    assert position_rate == pytest.approx(list(earth.position_rates(latitude, height, *velocity)), rel=1e-13)


def test_earth_and_transport_rates_in_enu_are_the_ned_vectors_in_enu_axes():
    latitude, height = 0.7, 250.0
    v_ned = np.array([80.0, -20.0, 1.5])
    v_enu = NED_TO_ENU @ v_ned
    as_array = lambda m: np.array([number(c) for c in m])  # noqa: E731
    assert as_array(navlib.earth_rate_enu(latitude)) == pytest.approx(NED_TO_ENU @ as_array(navlib.earth_rate_ned(latitude)))
    assert as_array(navlib.transport_rate_enu(latitude, height, list(v_enu))) == pytest.approx(
        NED_TO_ENU @ as_array(navlib.transport_rate_ned(latitude, height, list(v_ned))), rel=1e-14
    )
    assert as_array(navlib.gravity_enu(latitude, height)) == pytest.approx(NED_TO_ENU @ as_array(navlib.gravity_ned(latitude, height)))


def test_rates_work_on_symbols_and_take_a_models_own_earth_rate_and_radii():
    L, h, W, RM, RN = sp.symbols("L h omega_ie R_M R_N", real=True)
    v = sp.Matrix(sp.symbols("v_n v_e v_d", real=True))
    assert navlib.earth_rate_ned(L, W) == sp.Matrix([W * sp.cos(L), 0, -W * sp.sin(L)])
    assert navlib.transport_rate_ned(L, h, v, RM, RN) == sp.Matrix([v[1] / (RN + h), -v[0] / (RM + h), -v[1] * sp.tan(L) / (RN + h)])
    assert navlib.meridian_radius(L).free_symbols == {L}


def test_euler_to_dcm_is_scipys_intrinsic_zyx_rotation_body_to_navigation():
    roll, pitch, yaw = 0.3, -0.4, 2.1
    expected = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    got = np.array(navlib.euler_to_dcm(roll, pitch, yaw).evalf(), dtype=float)
    assert got == pytest.approx(expected, abs=1e-15)
    angles = [number(a) for a in navlib.dcm_to_euler(navlib.euler_to_dcm(roll, pitch, yaw))]
    assert angles == pytest.approx([roll, pitch, yaw], abs=1e-14)


def test_quaternion_to_dcm_is_scipys_rotation_of_the_same_hamilton_quaternion():
    q = np.array([0.8, -0.2, 0.5, 0.26])
    q /= np.linalg.norm(q)
    expected = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()  # scipy: scalar last
    for got in (navlib.quaternion_to_dcm(*q), navlib.quaternion_to_dcm(sp.Matrix(q))):
        assert np.array(got.evalf(), dtype=float) == pytest.approx(expected, abs=1e-15)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: navlib.meridian_radius(sp.ones(3, 1)), "meridian_radius() needs a scalar latitude, got 3x1"),
        (lambda: navlib.transport_rate_ned(0.1, 0, sp.eye(3)), "needs a 3-vector velocity, got 3x3"),
        (lambda: navlib.transport_rate_ned(0.1, 0, [1, 2, 3], 6.4e6), "either no radii or both R_M and R_N"),
        (lambda: navlib.dcm_to_euler(sp.ones(3, 1)), "dcm_to_euler() needs a 3x3 matrix, got 3x1"),
        (lambda: navlib.quaternion_to_dcm(1, 0, 0), "needs four scalars"),
    ],
)
def test_library_functions_refuse_wrong_shapes_naming_function_and_shape(call, message):
    with pytest.raises(ModelError, match=None) as caught:
        call()
    assert message in str(caught.value)


def test_every_library_function_documents_its_formula_and_source():
    for name, function in navlib.NAVLIB_FUNCTIONS.items():
        doc = function.__doc__ or ""
        assert "=" in doc, name
        assert "Source" in doc or ":func:" in doc, name
