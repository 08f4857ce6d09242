"""From derived sympy matrices to common-subexpression-eliminated blocks.

A *block* is what one generated function evaluates: a list of temporaries
``t_k = expr`` followed by output assignments ``out[e] = expr``, where only the
structurally nonzero entries appear.  Parameters are renamed to whatever the
target language uses to reach them (``p->latitude`` in C, ``p[0]`` in Python)
by the printer, not here.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp


@dataclass(frozen=True)
class Block:
    """Temporaries and outputs of one generated function."""

    temporaries: tuple[tuple[sp.Symbol, sp.Expr], ...]
    outputs: tuple[sp.Expr, ...]

    @property
    def operation_count(self) -> int:
        """Arithmetic operations and function calls after CSE (sympy count_ops)."""
        exprs = [e for _, e in self.temporaries] + list(self.outputs)
        return int(sum(sp.count_ops(e) for e in exprs))


def _rewrite_for_code(expr: sp.Expr) -> sp.Expr:
    """sec(x) -> 1/cos(x): C has no sec, and CSE then shares cos(x)."""
    return expr.replace(sp.sec, lambda arg: 1 / sp.cos(arg))


def eliminate_common_subexpressions(exprs: list[sp.Expr], prefix: str = "t") -> Block:
    """Run sympy's CSE over all ``exprs`` of one function, deterministically."""
    rewritten = [_rewrite_for_code(sp.sympify(e)) for e in exprs]
    if not rewritten:
        return Block((), ())
    temps, reduced = sp.cse(rewritten, symbols=sp.numbered_symbols(prefix), order="canonical")
    return Block(tuple((s, e) for s, e in temps), tuple(reduced))


@dataclass(frozen=True)
class Pole:
    """A denominator of the model's expressions that vanishes at some operating points.

    ``function`` (``cos`` or ``sin``) of ``argument`` divides somewhere:
    tan, sec, cot, csc or a negative power of cos or sin.  In floating point
    cos(pi/2) is 6e-17, not 0, so latitude 90 degrees gives tan = 1.6e16
    and a finite but meaningless F; the generated code therefore refuses an
    operating point where the denominator is zero within its rounding error
    (|value| <= 4 eps max(1, |argument|)), instead of relying on a NaN.
    """

    function: str
    argument: sp.Expr

    @property
    def denominator(self) -> sp.Expr:
        return (sp.cos if self.function == "cos" else sp.sin)(self.argument)


def poles(exprs: list[sp.Expr]) -> list[Pole]:
    """The trigonometric denominators of ``exprs``, each once, in a deterministic order."""
    found: set[tuple[str, sp.Expr]] = set()
    for expr in exprs:
        for node in sp.preorder_traversal(sp.sympify(expr)):
            if isinstance(node, (sp.tan, sp.sec)):
                found.add(("cos", node.args[0]))
            elif isinstance(node, (sp.cot, sp.csc)):
                found.add(("sin", node.args[0]))
            elif isinstance(node, sp.Pow) and node.exp.is_negative and isinstance(node.base, (sp.cos, sp.sin)):
                found.add(("cos" if isinstance(node.base, sp.cos) else "sin", node.base.args[0]))
    return [Pole(f, a) for f, a in sorted(found, key=lambda item: (item[0], sp.srepr(item[1])))]
