"""parse_expression: equation text is data; only names, numbers and arithmetic reach sympy.

The refusals of whole models (unknown symbols, undefined or pathological
equations) are proved through ErrorModel.build in test_declaration.py.
"""

from __future__ import annotations

import pytest
import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.expression import parse_expression


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
