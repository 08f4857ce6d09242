"""CasADi as a second, independent derivation backend.

The same :class:`~modelgen.model.declaration.ErrorModel` equations are rebuilt as CasADi
``SX`` expressions by walking the sympy expression tree node by node (no
round trip through strings, so nothing depends on how either library prints),
and F = df/dx, G = df/dw, H = dh/dx are taken with CasADi's own automatic
differentiation.  Agreement with :func:`modelgen.derivation.symbolic.derive` at random
operating points is evidence that neither backend mis-derives a Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import casadi as ca
import numpy as np
import sympy as sp

from modelgen.derivation.symbolic import parameter_vector
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel

#: sympy function class -> CasADi function of one argument.  Every function in
#: modelgen.model.declaration.ALLOWED_FUNCTIONS has an entry here or a dedicated branch
#: (atan2, sqrt as a power, pi as a number).
_UNARY: dict[type, Callable[[ca.SX], ca.SX]] = {
    sp.sin: ca.sin,
    sp.cos: ca.cos,
    sp.tan: ca.tan,
    sp.sec: lambda a: 1 / ca.cos(a),
    sp.csc: lambda a: 1 / ca.sin(a),
    sp.cot: lambda a: 1 / ca.tan(a),
    sp.asin: ca.asin,
    sp.acos: ca.acos,
    sp.atan: ca.atan,
    sp.exp: ca.exp,
    sp.log: ca.log,
    sp.Abs: ca.fabs,
}


def sympy_to_casadi(expr: sp.Basic, symbols: Mapping[sp.Symbol, ca.SX], where: str = "expression") -> ca.SX:
    """Translate a sympy expression into CasADi SX, node by node.

    ``symbols`` maps every free sympy symbol to its SX counterpart.  A symbol
    or function without a CasADi counterpart is refused with a ModelError
    naming it and ``where`` it occurred.
    """
    cache: dict[sp.Basic, ca.SX] = {}

    def walk(node: sp.Basic) -> ca.SX:
        hit = cache.get(node)
        if hit is not None:
            return hit
        out = _translate(node, walk, symbols, where)
        cache[node] = out
        return out

    return walk(sp.sympify(expr))


def _translate(
    node: sp.Basic,
    walk: Callable[[sp.Basic], ca.SX],
    symbols: Mapping[sp.Symbol, ca.SX],
    where: str,
) -> ca.SX:
    """One node of the tree; children are translated through ``walk``."""
    if isinstance(node, sp.Symbol):
        if node not in symbols:
            raise ModelError(f"{where}: symbol {node} has no CasADi counterpart")
        return symbols[node]
    if isinstance(node, (sp.Number, sp.NumberSymbol)):
        if not node.is_real:
            raise ModelError(f"{where}: non-real constant {node}")
        return ca.SX(float(node))
    if isinstance(node, sp.Add):
        terms = [walk(a) for a in node.args]
        total = terms[0]
        for t in terms[1:]:
            total = total + t
        return total
    if isinstance(node, sp.Mul):
        factors = [walk(a) for a in node.args]
        product = factors[0]
        for f in factors[1:]:
            product = product * f
        return product
    if isinstance(node, sp.Pow):
        base, exponent = node.args
        b = walk(base)
        if exponent == sp.Rational(1, 2):
            return ca.sqrt(b)
        if exponent == sp.Rational(-1, 2):
            return 1 / ca.sqrt(b)
        if exponent == -1:
            return 1 / b
        if exponent == 2:
            return b * b
        if exponent.is_Integer:
            return ca.power(b, int(exponent))
        return ca.power(b, walk(exponent))
    if isinstance(node, sp.atan2):
        return ca.atan2(walk(node.args[0]), walk(node.args[1]))
    unary = _UNARY.get(type(node))
    if unary is not None:
        return unary(walk(node.args[0]))
    raise ModelError(f"{where}: no CasADi counterpart for {type(node).__name__} in {node}")


@dataclass(frozen=True)
class CasadiModel:
    """The model's f(x, w, p), h(x, p) and their Jacobians as CasADi SX.

    ``F``, ``G``, ``H`` are the Jacobians evaluated at x = 0, w = 0, as SX
    expressions in the parameter vector ``p`` (model parameter order).
    """

    model: ErrorModel
    x: ca.SX
    w: ca.SX
    p: ca.SX
    f: ca.SX
    h: ca.SX
    F: ca.SX
    G: ca.SX
    H: ca.SX
    function: ca.Function  # p -> (F, G, H)

    def numeric(self, values: Mapping[str, float]) -> dict[str, np.ndarray]:
        """F, G, H as float arrays at the given parameter values.

        Same convention as :meth:`modelgen.derivation.symbolic.DerivedModel.numeric`:
        ``values`` maps parameter names (or symbols) to numbers; parameters
        with a default may be omitted.
        """
        p = parameter_vector(self.model, values)
        F, G, H = self.function(p)
        return {"F": F.full(), "G": G.full(), "H": H.full()}


def build_casadi_model(model: ErrorModel) -> CasadiModel:
    """Rebuild ``model`` in CasADi SX and differentiate it (see module doc)."""
    x = ca.SX.sym("x", len(model.states))
    w = ca.SX.sym("w", len(model.noises))
    p = ca.SX.sym("p", len(model.parameters))
    symbols: dict[sp.Symbol, ca.SX] = {}
    for vector, quantities in ((x, model.states), (w, model.noises), (p, model.parameters)):
        for i, q in enumerate(quantities):
            symbols[q.sym] = vector[i]

    f = ca.vertcat(
        *[sympy_to_casadi(model.dynamics[s.name], symbols, f"model {model.name!r}, d({s.name})/dt") for s in model.states]
    )
    if model.measurements:
        h = ca.vertcat(
            *[
                sympy_to_casadi(model.measurement_expressions[m.name], symbols, f"model {model.name!r}, measurement {m.name!r}")
                for m in model.measurements
            ]
        )
    else:
        h = ca.SX(0, 1)

    at_zero_error = (ca.vertcat(x, w), ca.DM.zeros(x.numel() + w.numel(), 1))
    F, G, H = (
        ca.substitute(ca.jacobian(expr, var), *at_zero_error) for expr, var in ((f, x), (f, w), (h, x))
    )
    function = ca.Function(f"{model.name}_fgh", [p], [F, G, H], ["p"], ["F", "G", "H"])
    return CasadiModel(model=model, x=x, w=w, p=p, f=f, h=h, F=F, G=G, H=H, function=function)
