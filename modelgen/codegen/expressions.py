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


def sparse_block(matrix: sp.Matrix, entries: list[tuple[int, int]]) -> Block:
    """CSE block over the listed (structurally nonzero) entries of ``matrix``."""
    return eliminate_common_subexpressions([matrix[i, j] for i, j in entries])


def diagonal_block(matrix: sp.Matrix) -> Block:
    """CSE block over the diagonal of a (diagonal) noise matrix."""
    return eliminate_common_subexpressions([matrix[i, i] for i in range(matrix.shape[0])])
