"""Vector expressions, component names and definitions (modelgen.model.vectors)."""

import pytest
import sympy as sp
import yaml

from modelgen.errors import ModelError
from modelgen.model.expression import parse_expression
from modelgen.model.loading import builtin_model_path, builtin_models
from modelgen.model.vectors import (
    VECTOR_FUNCTIONS,
    component_names,
    evaluate_definitions,
    parse_vector_expression,
)

a = sp.Matrix(sp.symbols("a_1:4", real=True))
b = sp.Matrix(sp.symbols("b_1:4", real=True))
C = sp.Matrix(3, 3, sp.symbols("C_1:10", real=True))
s = sp.Symbol("s", real=True)
NAMESPACE = {"a": a, "b": b, "C": C, "s": s}


def evaluate(text: str):
    return parse_vector_expression(text, NAMESPACE, "m.yaml:7: test")


def test_component_names_follow_the_frame_the_axes_and_row_major_order():
    assert component_names("dv", 3, "NED") == ["dv_n", "dv_e", "dv_d"]
    assert component_names("dv", 3, "ENU") == ["dv_e", "dv_n", "dv_u"]
    assert component_names("b_g", 3, "NED", "body") == ["b_g_x", "b_g_y", "b_g_z"]
    assert component_names("v", 3, "NED", "ENU") == ["v_e", "v_n", "v_u"]
    assert component_names("C_bn", [3, 3], "NED") == [f"C_bn_{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
    assert component_names("x", None, "whatever") == ["x"]


@pytest.mark.parametrize(
    ("shape", "frame", "axes", "message"),
    [
        ([2, 2], "NED", None, "shape [2, 2] is not supported; use 3 (a 3-vector) or [3, 3]"),
        (4, "NED", None, "shape 4 is not supported"),
        (3, "ECEF", None, "needs 'axes' (body, NED or ENU) when the model's frame is 'ECEF'"),
        (3, "NED", "wing", "axes 'wing' is not supported"),
    ],
)
def test_component_names_refuse_unsupported_shapes_and_axes_saying_what_is_supported(shape, frame, axes, message):
    with pytest.raises(ModelError) as caught:
        component_names("v", shape, frame, axes, "m.yaml:3: state 'v'")
    assert message in str(caught.value) and "m.yaml:3" in str(caught.value)


def test_vector_functions_compute_the_textbook_results():
    assert evaluate("cross(a, b)") == a.cross(b)
    assert evaluate("skew(a)*b") == a.cross(b)
    assert sp.expand(evaluate("dot(a, b)") - (a.T * b)[0]) == 0
    assert evaluate("transpose(a)*b") == (a.T * b)[0]  # a 1x1 product is a scalar
    assert evaluate("C*a") == C * a
    assert evaluate("transpose(C)") == C.T
    assert evaluate("diag(a)") == sp.diag(*a)
    assert evaluate("diag(C)") == sp.Matrix([C[0, 0], C[1, 1], C[2, 2]])
    assert evaluate("diag(s, 2, 3)") == sp.diag(s, 2, 3)
    assert evaluate("eye() + eye(3)") == 2 * sp.eye(3)
    assert evaluate("norm(a)") == sp.sqrt(sum(x**2 for x in a))
    assert evaluate("vector(s, 0, -s)") == sp.Matrix([s, 0, -s])
    assert evaluate("-a/s + 2*s*b") == -a / s + 2 * s * b
    assert set(VECTOR_FUNCTIONS) >= {"cross", "dot", "skew", "transpose", "diag", "eye", "norm"}


def test_library_functions_and_constants_are_available_and_a_declared_name_shadows_them():
    L = sp.Symbol("L", real=True)
    rate = parse_vector_expression("earth_rate_ned(L)", {"L": L}, "here")
    assert rate.shape == (3, 1) and rate[1] == 0
    assert parse_vector_expression("wgs84_semi_major_axis", {}, "here") == sp.Float(6378137.0)
    R_M = sp.Symbol("R_M", real=True)
    assert parse_vector_expression("R_M + 1", {"R_M": R_M}, "here") == R_M + 1
    with pytest.raises(ModelError, match="'R_M' is a scalar value, not a function"):
        parse_vector_expression("R_M(L)", {"R_M": R_M, "L": L}, "here")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("cross(a, C)", "cross() needs two 3-vectors, got 3x1 and 3x3"),
        ("a + C", "cannot add a 3x1 and a 3x3 (shapes differ)"),
        ("a - s", "cannot subtract a 3x1 and a scalar"),
        ("a*b", "cannot multiply a 3x1 by a 3x1 (inner sizes differ)"),
        ("s/a", "cannot divide by a 3x1"),
        ("C**2", "** needs scalars, got 3x3 and scalar"),
        ("sin(a)", "sin() needs scalar arguments, got 3x1"),
        ("dot(a, s)", "dot() needs two 3-vectors, got 3x1 and scalar"),
        ("norm(C)", "norm() needs a 3-vector, got 3x3"),
        ("skew(s)", "skew() needs a 3-vector, got scalar"),
        ("eye(2)", "eye() makes the 3x3 identity"),
        ("diag(a, b)", "diag() needs a 3-vector, three scalars or a 3x3 matrix, got 3x1, 3x1"),
        ("transpose(s)", "transpose() needs a vector or matrix, got scalar"),
        ("cross(a)", "wrong arguments for cross()"),
        ("cross", "'cross' is a function: call it"),
        ("a(1)", "'a' is a 3x1 value, not a function"),
        ("frobnicate(a)", "unknown function(s) frobnicate"),
        ("q + a", "unknown symbol(s) q"),
        ("a.T", "'.' is not allowed"),
        ("a[0]", "'[' is not allowed"),
        ("__import__('os')", "not allowed"),
        ("cross(a, b, ) if s else a", "not allowed"),
        ("log(0)*a", "undefined or infinite"),
    ],
)
def test_bad_expressions_are_refused_naming_place_operation_and_shapes(text, message):
    with pytest.raises(ModelError) as caught:
        evaluate(text)
    assert message in str(caught.value)
    assert str(caught.value).startswith("m.yaml:7: test")


def _scalar_texts(path) -> list[str]:
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    return [str(v) for v in (data.get("dynamics") or {}).values()] + [
        str(m["expression"]) for m in data.get("measurements") or []
    ]


def _scalar_file(name: str) -> bool:
    """A built-in model written as scalar error equations (not a transform, navigation-equation or vector file)."""
    from modelgen.model.vector_loading import uses_vector_syntax

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # at collection: libyaml's loader where there is one
    data = yaml.load(builtin_model_path(name).read_text(encoding="utf-8"), Loader=loader)  # noqa: S506 - a safe loader
    return not ({"base", "navigation"} & set(data)) and not uses_vector_syntax(data)


@pytest.mark.parametrize("name", [n for n in builtin_models() if _scalar_file(n)])
def test_scalar_equations_evaluate_to_exactly_what_the_scalar_parser_gives(name):
    """The vector evaluator is a drop-in for parse_expression on every built-in equation (same sympy tree)."""
    data = yaml.safe_load(builtin_model_path(name).read_text(encoding="utf-8"))
    symbols = {
        str(q.get("symbol") or q["name"]): sp.Symbol(str(q.get("symbol") or q["name"]), real=True)
        for kind in ("states", "noises", "parameters")
        for q in data.get(kind) or []
    }
    for text in _scalar_texts(builtin_model_path(name)):
        assert parse_vector_expression(text, symbols, "here") == parse_expression(text, symbols, "here"), text


def _locate(key: str) -> str:
    return f"m.yaml:{20 + int(key.split('[')[1].split(']')[0])}" if "[" in key else "m.yaml:19"


def test_definitions_are_evaluated_in_order_each_using_the_earlier_ones():
    defined = evaluate_definitions(
        [{"name": "f_n", "value": "C*a"}, {"name": "g", "value": "cross(f_n, b)"}, {"name": "k", "value": 2}],
        NAMESPACE,
        _locate,
    )
    assert list(defined) == ["f_n", "g", "k"]
    assert defined["g"] == (C * a).cross(b) and defined["k"] == 2


@pytest.mark.parametrize(
    ("entries", "message"),
    [
        (
            [{"name": "x", "value": "y + s"}, {"name": "y", "value": "s"}],
            "m.yaml:20: definition 'x' uses 'y' before it is defined (it is defined at m.yaml:21)",
        ),
        ([{"name": "x", "value": "s"}, {"name": "x", "value": "2*s"}], "m.yaml:21: 'x' is defined twice (at m.yaml:20 and here)"),
        ([{"name": "x", "value": "y"}, {"name": "y", "value": "x"}], "m.yaml:20: definitions form a cycle: x -> y -> x"),
        ([{"name": "x", "value": "2*x"}], "definitions form a cycle: x -> x"),
        ([{"name": "a", "value": "s"}], "definition 'a' has the name of a declared"),
        ([{"name": "cross", "value": "s"}], "has the name of a vector function"),
        ([{"name": "x"}], "must be a mapping with a 'name' and a 'value'"),
        ([{"name": "x", "value": "s", "size": 3}], "unknown field 'size'"),
        ([{"name": "x", "value": ["s", "s"]}], "value must be one expression"),
        ([{"name": "x", "value": "cross(a, C)"}], "m.yaml:20: definition 'x': cross() needs two 3-vectors, got 3x1 and 3x3"),
    ],
)
def test_bad_definitions_are_refused_naming_the_definitions_and_lines(entries, message):
    with pytest.raises(ModelError) as caught:
        evaluate_definitions(entries, NAMESPACE, _locate)
    assert message in str(caught.value)


def test_tree_size_counts_shared_subexpressions_each_time_without_walking_the_tree():
    from modelgen.model.vectors import tree_size

    x = sp.Symbol("x", real=True)
    expr = x
    for _ in range(60):  # a tree of ~2^61 nodes, a graph of ~180
        expr = sp.sin(expr) + sp.cos(expr)
    assert tree_size(sp.sin(x) + sp.cos(x), 100) == 5
    assert tree_size(expr, 1000) == 1001


def test_definitions_that_double_their_tree_are_refused_before_sympy_walks_them():
    entries = [{"name": "d0", "value": "s"}] + [
        {"name": f"d{k}", "value": f"sin(d{k - 1}) + cos(d{k - 1})"} for k in range(1, 60)
    ]
    with pytest.raises(ModelError, match="grows to more than 20000 operations"):
        evaluate_definitions(entries, NAMESPACE, _locate)


def test_built_sympy_values_get_the_same_checks_as_text():
    assert parse_vector_expression(a.cross(b), NAMESPACE, "here") == a.cross(b)
    with pytest.raises(ModelError, match="unknown symbol"):
        parse_vector_expression(sp.Symbol("zz") * a, NAMESPACE, "here")
    with pytest.raises(ModelError, match="undefined or infinite"):
        parse_vector_expression(sp.zoo * s, NAMESPACE, "here")
