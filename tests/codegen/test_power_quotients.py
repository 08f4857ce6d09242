"""A product over a small power prints with its denominator in parentheses (C and Python).

Small integer powers print as products (``x*x*x``); sympy prints a product's single
denominator factor without parentheses, so ``a/r**3`` printed as ``a/r*r*r`` (= a*r):
the ECEF model's gravity gradient (mu/|r|^3) came out 1e27 too large in both generated
filters.  The printers now parenthesize it.
"""

from __future__ import annotations

import math

import pytest
import sympy as sp

from modelgen.codegen.backends.c.printer import CPrinter
from modelgen.codegen.backends.python.printer import PyPrinter

R, X, Y = sp.symbols("r x y", positive=True)
VALUES = {R: 1.7, X: 0.3, Y: 2.1}
EXPRESSIONS = (3.986e14 / R**3, 2 * X / R**2, -X / R**2, -1 / R**2, (X + Y) / (R + X) ** 2, -3 * X * Y / R**4,
               X / (2 * R**2), -X / (3 * R**3), X / (R**2 * Y**3), X * R**2, X * Y / R**5)


@pytest.mark.parametrize("expression", EXPRESSIONS, ids=str)
def test_a_product_over_a_small_power_evaluates_to_its_value(expression):
    expected = float(expression.subs(VALUES))
    names = {str(k): v for k, v in VALUES.items()}
    python = PyPrinter().doprint(expression)
    assert eval(python, {"math": math}, names) == pytest.approx(expected, rel=1e-14), python  # noqa: S307
    c = CPrinter("double").doprint(expression)  # the C of these is Python too, but for pow()
    assert eval(c.replace("pow(", "math.pow("), {"math": math}, names) == pytest.approx(expected, rel=1e-14), c  # noqa: S307


def test_the_denominator_is_parenthesized():
    assert PyPrinter().doprint(2 * X / R**3) == "2*x/(r*r*r)"
    assert CPrinter("float").doprint(sp.Float(2.5) / R**2) == "2.5F/(r*r)"
