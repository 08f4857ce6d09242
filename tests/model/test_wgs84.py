"""The one WGS-84 module: its derived constants agree with the values NIMA TR8350.2 prints."""

import math

import pytest

from modelgen.model import wgs84


def test_derived_constants_match_the_values_tr8350_2_prints():
    assert wgs84.ECCENTRICITY_SQUARED == pytest.approx(6.69437999014e-3, rel=1e-12)  # Table 3.3
    assert wgs84.SEMI_MINOR_AXIS == pytest.approx(6356752.3142, abs=1e-4)  # Table 3.3
    assert wgs84.GRAVITY_RATIO_M == pytest.approx(0.00344978650684, rel=1e-12)  # Table 3.3


def test_the_two_earth_rates_are_the_wgs84_and_the_gps_interface_values():
    assert wgs84.EARTH_RATE == 7.292115e-5
    assert wgs84.GPS_EARTH_RATE == 7.2921151467e-5
    assert abs(wgs84.GPS_EARTH_RATE / wgs84.EARTH_RATE - 1) < 3e-8


def test_radii_of_curvature_at_the_equator_and_the_pole():
    r_m, r_n = wgs84.earth_radii(0.0)
    assert r_n == pytest.approx(wgs84.SEMI_MAJOR_AXIS)
    assert r_m == pytest.approx(wgs84.SEMI_MAJOR_AXIS * (1 - wgs84.ECCENTRICITY_SQUARED))
    r_m, r_n = wgs84.earth_radii(math.pi / 2)
    assert r_m == pytest.approx(r_n) == pytest.approx(wgs84.SEMI_MAJOR_AXIS**2 / wgs84.SEMI_MINOR_AXIS)


def test_no_other_module_defines_its_own_earth_rate_or_semi_major_axis():
    from conftest import REPO

    owners = sorted(
        str(path.relative_to(REPO))
        for path in (REPO / "modelgen").rglob("*.py")
        if path.name != "wgs84.py"
        and any(line.split("=")[0].strip() in ("EARTH_RATE", "SEMI_MAJOR_AXIS", "WGS84_EARTH_RATE", "WGS84_SEMI_MAJOR_AXIS")
                for line in path.read_text(encoding="utf-8").splitlines() if "=" in line and not line.startswith(" "))
    )
    assert owners == []
