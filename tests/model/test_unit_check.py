"""Declared units parsed with pint and every equation checked term by term (issue 27, units)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from modelgen.errors import ModelError
from modelgen.model.loading import builtin_models, load_model, load_model_text
from modelgen.model.units import declared_value, parse_unit, to_si, unit_to_si

REPO = Path(__file__).resolve().parents[2]
BASE = (REPO / "modelgen" / "models" / "ned_inertial16.yaml").read_text(encoding="utf-8")


@pytest.mark.parametrize(
    "unit, si",
    [
        ("deg/h", math.pi / 180 / 3600),
        ("ppm", 1e-6),
        ("ug", 9.80665e-6),
        ("mg", 9.80665e-3),
        ("g", 9.80665),
        ("arcsec", math.pi / 180 / 3600),
        ("sqrt(Hz)", 1.0),
        ("ug/sqrt(Hz)", 9.80665e-6),
        ("deg/sqrt(h)", math.pi / 180 / 60),
        ("nmile", 1852.0),
        ("m/s^2/sqrt(s)", 1.0),
    ],
)
def test_every_navigation_unit_is_parsed_with_its_size(unit, si):
    assert parse_unit(unit).factor == pytest.approx(si, rel=1e-12)


def test_the_table_units_keep_their_factors_and_pint_agrees_with_them():
    for unit in ("deg", "arcmin", "arcsec", "deg/h", "km/h", "nmile/h", "g", "nmile", "h"):
        assert unit_to_si(1.0, unit, "x") == to_si(1.0, unit)
        assert parse_unit(unit).factor == pytest.approx(to_si(1.0, unit), rel=1e-15)


def test_a_value_given_in_a_non_si_unit_is_converted_and_so_is_the_unit():
    value, unit = declared_value(0.01, "deg/h", "p")
    assert value == pytest.approx(0.01 * math.pi / 180 / 3600, rel=1e-15) and unit == "rad/s"
    assert declared_value(100.0, "ug", "p") == (pytest.approx(9.80665e-4, rel=1e-15), "m/s^2")
    assert declared_value(2.0, "m/s", "p") == (2.0, "m/s")


def test_unknown_units_are_refused():
    with pytest.raises(ModelError, match="unknown unit 'furlongz'"):
        parse_unit("furlongz", "x")
    with pytest.raises(ModelError, match="measures m, but the quantity is in 'rad'"):
        unit_to_si(1.0, "furlong", "x", expected="rad")


@pytest.mark.parametrize("name", builtin_models())
def test_every_shipped_model_passes_the_unit_check(name, loaded_builtin):
    loaded_builtin(name)  # load_model checks the units (once per session for every test: tests/conftest.py)


def test_the_navigator_model_passes_the_unit_check():
    load_model(REPO / "modelgen" / "navigator" / "models" / "ins_gps15_nav.yaml")


def test_a_state_declared_in_deg_and_used_as_radians_is_refused_with_the_term_and_both_units():
    text = BASE.replace("symbol: gamma, unit: rad", "symbol: gamma, unit: deg")
    with pytest.raises(ModelError) as error:
        load_model_text(text, "m.yaml")
    message = str(error.value)
    assert message.startswith("m.yaml:")
    assert "V_n*gamma/R" in message and "deg/s" in message and "rad/s" in message


def test_an_angle_state_in_furlongs_is_refused():
    text = BASE.replace("symbol: alpha, unit: rad", "symbol: alpha, unit: furlongs")
    with pytest.raises(ModelError, match=r"m.yaml:\d+: .*attitude_error_north.*is in rad/s, but the equation is in fur/s"):
        load_model_text(text, "m.yaml")


def test_a_latitude_in_deg_inside_sin_is_refused():
    text = BASE.replace("symbol: phi, unit: rad", "symbol: phi, unit: deg")
    with pytest.raises(ModelError, match="argument of sin must be a plain number or an angle in rad; 'phi' is in deg"):
        load_model_text(text, "m.yaml")


def test_a_noise_declared_in_its_rate_unit_is_refused():
    text = BASE.replace("unit: rad/s/sqrt(s), psd", "unit: rad/sqrt(s), psd", 1)
    with pytest.raises(ModelError, match="term 'w_eps_x' is in rad/s, but the equation is in rad/s\\*\\*2"):
        load_model_text(text, "m.yaml")


SCALAR = """\
model: m
parameters:
  - {name: rate, symbol: mu, unit: 1/s, value: 0.5}
  - {name: sigma, symbol: sig, unit: m/s}
states:
  - {name: position_error, symbol: dx, unit: m}
  - {name: velocity_error, symbol: dv, unit: m/s}
noises:
  - {name: accel_noise, symbol: w, unit: m/s/sqrt(s), psd: "2*mu*sig**2"}
dynamics:
  dx: dv
  dv: -mu*dv + w
measurements:
  - {name: position_difference, symbol: z, unit: m, expression: dx, variance: "0.01"}
"""


def test_a_consistent_scalar_model_loads_and_a_measurement_in_the_wrong_unit_is_refused():
    load_model_text(SCALAR, "m.yaml")
    with pytest.raises(ModelError, match=r"m.yaml:14: .*measurement 'position_difference'.*term 'dv' is in m/s, but the equation is in m"):
        load_model_text(SCALAR.replace("expression: dx", "expression: dx + dv"), "m.yaml")
    with pytest.raises(ModelError, match=r"noise 'accel_noise' psd.*'2\*mu\*\*2\*sig\*\*2' is in m\*\*2/s\*\*4"):
        load_model_text(SCALAR.replace("psd: \"2*mu*sig**2\"", "psd: \"2*mu**2*sig**2\""), "m.yaml")


def test_units_left_out_are_not_checked():
    text = SCALAR.replace(", unit: m/s/sqrt(s)", "").replace(", unit: 1/s", "")
    load_model_text(text.replace("-mu*dv", "-mu*mu*dv"), "m.yaml")  # mu has no declared unit: the term is not checked


@pytest.mark.parametrize("variance", ["1", "1e-2", "4"])
def test_a_variance_written_as_a_bare_number_is_in_the_measurement_unit_squared(variance):
    """A number alone carries its author's unit: variance '1' of a measurement in m is 1 m^2 (as '1e-2' is)."""
    text = ("model: m\nparameters:\n  - {name: sigma, symbol: s, unit: m, value: 0.1}\n"
            "states:\n  - {name: drift, symbol: d, unit: m}\ndynamics: {d: \"0\"}\n"
            f"measurements:\n  - {{name: z, symbol: z, unit: m, expression: d, variance: \"{variance}\"}}\n")
    assert load_model_text(text, filename="m.yaml").measurements[0].unit == "m"
    with pytest.raises(ModelError, match="is in m, but the equation is in m"):  # a term with a unit is still checked
        load_model_text(text.replace(f'variance: "{variance}"', 'variance: "4*s"'), filename="m.yaml")


@pytest.mark.parametrize("lax", ["1_000", " 1.5", True])
def test_a_value_with_a_unit_in_a_lax_form_is_refused_as_not_a_number(lax):
    """Issue 28: float() read '1_000' (and True as 1) where a file gave a number with its unit."""
    from modelgen.model.units import to_si, unit_to_si

    with pytest.raises(ModelError, match=r"^x.yaml:3: .* is not a number$"):
        to_si(lax, "deg/h", "x.yaml:3: value")
    with pytest.raises(ModelError, match=r"^x.yaml:3: .* is not a number$"):
        unit_to_si(lax, "ppm", "x.yaml:3: value")
    assert to_si("1.5e-3", "m", "x") == 1.5e-3 and unit_to_si(2, "ppm", "x") == pytest.approx(2e-6)
