"""What the expression printers of every backend share: small integer powers as products.

``x*x`` and ``1.0/(x*x)`` are cheaper than ``pow`` on every target and bit
for bit the same in the C and the Python outputs.
"""

from __future__ import annotations

import sympy as sp


def small_power(printer, expr: sp.Pow, one: str) -> str | None:
    """Print x**k for |k| <= 4 as repeated products, or None to fall back to the printer's own."""
    base, exp = expr.as_base_exp()
    if not (exp.is_Integer and 1 <= abs(int(exp)) <= 4):
        return None
    text = printer.parenthesize(base, sp.printing.precedence.PRECEDENCE["Mul"] + 1)
    product = "*".join([text] * abs(int(exp)))
    if int(exp) > 0:
        return product
    return f"{one}/({product})" if abs(int(exp)) > 1 else f"{one}/{text}"
