"""ErrorModel.build and parse_expression: bad declarations and equations are refused.

Each refusal must be a ModelError naming the problem and where it is (the
model, the declaration or equation, and the offending name).
"""

from __future__ import annotations

import pytest
import sympy as sp

from modelgen.errors import ModelError
from modelgen.model import ErrorModel, Measurement, Noise, Parameter, State, check_identifier, parse_expression


def build(**changes):
    """A valid 2-state model (position/velocity with a Markov velocity), with changes."""
    spec = dict(
        name="toy",
        states=[State("position_error", "m", symbol="dx"), State("velocity_error", "m/s", symbol="dv")],
        noises=[Noise("accel_noise", symbol="w", psd="2*mu*sigma**2")],
        parameters=[Parameter("rate", "1/s", symbol="mu", value=0.5), Parameter("sigma", "m/s", symbol="sigma")],
        dynamics={"dx": "dv", "dv": "-mu*dv + w"},
        measurements=[Measurement("position_difference", "m", expression="dx", variance="0.01")],
    )
    spec.update(changes)
    return ErrorModel.build(**spec)


def refused(match: str, **changes) -> str:
    with pytest.raises(ModelError, match=match) as info:
        build(**changes)
    return str(info.value)


def test_a_valid_model_builds_with_equations_in_declared_symbols():
    m = build()
    dx, dv, w, mu = (sp.Symbol(s, real=True) for s in ("dx", "dv", "w", "mu"))
    assert m.state_names == ["position_error", "velocity_error"]
    assert m.dynamics["velocity_error"] == -mu * dv + w
    assert m.dynamics["position_error"] == dv
    assert m.measurement_expressions["position_difference"] == dx
    assert m.state_index("dv") == 1 and m.state_index("velocity_error") == 1


def test_unknown_symbol_in_an_equation_is_refused_with_its_name_and_equation():
    msg = refused("unknown symbol", dynamics={"dx": "dv + drift", "dv": "-mu*dv + w"})
    assert "drift" in msg and "d(dx)/dt" in msg and "'toy'" in msg


def test_unknown_function_is_refused():
    msg = refused("unknown function", dynamics={"dx": "foo(dv)", "dv": "-mu*dv + w"})
    assert "foo" in msg


def test_noise_in_a_measurement_or_state_in_a_psd_is_an_unknown_symbol_there():
    refused("unknown symbol.*w", measurements=[Measurement("position_difference", expression="dx + w")])
    refused("unknown symbol.*dx", noises=[Noise("accel_noise", symbol="w", psd="dx")])


def test_duplicate_name_or_symbol_is_refused_naming_both_kinds():
    msg = refused("declared twice", parameters=[Parameter("rate", symbol="dx", value=0.5), Parameter("sigma")])
    assert "'dx'" in msg and "state and parameter" in msg
    refused("declared twice", states=[State("position_error", symbol="dx"), State("position_error", symbol="dv")])


@pytest.mark.parametrize("bad", ["2x", "x-y", "has space", "", "état"])
def test_invalid_c_identifier_is_refused(bad):
    msg = refused("not a valid C identifier", states=[State(bad, symbol="dx"), State("velocity_error", symbol="dv")])
    assert repr(bad) in msg and "state" in msg


@pytest.mark.parametrize("word", ["double", "while", "static", "lambda", "for"])
def test_c_or_python_keyword_is_refused(word):
    msg = refused("keyword", parameters=[Parameter("rate", symbol=word, value=0.5), Parameter("sigma")])
    assert repr(word) in msg and "parameter 'rate' symbol" in msg


def test_underscore_prefix_and_function_names_are_refused():
    refused("underscore", states=[State("_state", symbol="dx"), State("velocity_error", symbol="dv")])
    refused("name of a function", states=[State("sin", symbol="dx"), State("velocity_error", symbol="dv")])


def test_invalid_model_name_is_refused():
    refused("model name.*not a valid C identifier", name="my model")


@pytest.mark.parametrize("value", ["fast", float("nan"), float("inf")])
def test_non_numeric_or_non_finite_parameter_value_is_refused(value):
    msg = refused("value", parameters=[Parameter("rate", symbol="mu", value=value), Parameter("sigma")])
    assert "parameter 'rate'" in msg


def test_non_numeric_statistic_is_an_unknown_symbol_and_negative_one_is_refused():
    refused("psd: unknown symbol.*high", noises=[Noise("accel_noise", symbol="w", psd="high")])
    refused("variance: unknown symbol.*small", measurements=[Measurement("position_difference", expression="dx", variance="small")])
    refused("negative", noises=[Noise("accel_noise", symbol="w", psd="-2")])
    refused("negative", measurements=[Measurement("position_difference", expression="dx", variance="-0.01")])


def test_equation_for_an_undeclared_state_is_refused():
    msg = refused("not a declared state", dynamics={"dx": "dv", "dv": "-mu*dv + w", "dz": "0"})
    assert "'dz'" in msg


def test_missing_equation_is_refused_naming_the_state():
    msg = refused("no equation for state", dynamics={"dx": "dv"})
    assert "velocity_error" in msg


def test_two_equations_for_one_state_by_name_and_symbol_are_refused():
    refused("two equations", dynamics={"dx": "dv", "position_error": "dv", "dv": "-mu*dv + w"})


def test_model_without_states_is_refused():
    refused("declares no states", states=[], dynamics={})


def test_build_names_the_file_line_when_given_locations():
    with pytest.raises(ModelError, match=r"^m\.yaml:7: model 'toy', equation d\(dx\)/dt: unknown symbol"):
        build(dynamics={"dx": "dq", "dv": "-mu*dv + w"}, locations={"dynamics.dx": "m.yaml:7"})


@pytest.mark.parametrize(
    "text",
    [
        "dv.subs(dv, 2)",  # attribute access would run Python code in sympy's eval-based parser
        "dv.__class__",
        "__import__('os').getcwd()",
        "[dv, dv]",
        "dv if dv else 1",
        "{1: dv}",
        "dv; dv",
    ],
)
def test_equation_text_may_only_contain_names_numbers_and_arithmetic(text):
    namespace = {"dv": sp.Symbol("dv", real=True)}
    with pytest.raises(ModelError, match="not allowed|cannot parse"):
        parse_expression(text, namespace, "here")


def test_arithmetic_functions_and_numbers_parse():
    L, v = sp.Symbol("L", real=True), sp.Symbol("v", real=True)
    expr = parse_expression("2.5e-3*v**2/cos(L) - sec(L)**2 + sqrt(4)", {"L": L, "v": v}, "here")
    assert expr == sp.Float(2.5e-3) * v**2 / sp.cos(L) - sp.sec(L) ** 2 + 2


def test_paper_symbol_names_that_are_sympy_functions_mean_the_declared_symbol():
    # beta and gamma are sympy functions under the default parser
    beta, gamma = sp.Symbol("beta", real=True), sp.Symbol("gamma", real=True)
    assert parse_expression("beta*gamma", {"beta": beta, "gamma": gamma}, "here") == beta * gamma


def test_check_identifier_accepts_spelled_out_names():
    for name in ("attitude_error_north", "gyro_markov_drift_x", "x1", "c11"):
        check_identifier(name, "here")
