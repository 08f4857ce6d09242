"""The Python printer: sympy expressions as Python text (math module), parameters as locals or ``p[k]``."""

from __future__ import annotations

import re
from typing import Mapping

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from modelgen.codegen.backends.printing import RenamedSymbols, small_power
from modelgen.codegen.expressions import Block


class PyPrinter(RenamedSymbols, PythonCodePrinter):
    """Python printer (math module) with parameters renamed to locals or vector entries."""

    def __init__(self, renames: Mapping[sp.Symbol, str] | None = None):
        super().__init__({"fully_qualified_modules": True})
        self._init_renames(renames)

    def _print_Pow(self, expr: sp.Pow) -> str:
        text = small_power(self, expr, "1.0")
        return text if text is not None else super()._print_Pow(expr)


_PYTHON_TAKEN = re.compile(r"^(t\d+|p|out|np|math)$")


def parameter_locals(model, block: Block, extra: list[sp.Expr] = ()) -> tuple[list[tuple[str, int]], PyPrinter]:
    """Parameters a generated Python function uses, unpacked into locals named as in the model.

    ``latitude = p[0]`` reads better than ``p[0]`` in every expression; a
    parameter whose name would clash with the function's own names (``p``,
    ``out``, ``np``, ``math``, temporaries ``t<k>``) stays ``p[k]``.
    """
    used = set().union(
        *(e.free_symbols for _, e in block.temporaries), *(e.free_symbols for e in block.outputs), *(e.free_symbols for e in extra)
    )
    renames, locals_ = {}, []
    for k, par in enumerate(model.parameters):
        if par.sym not in used:
            continue
        if _PYTHON_TAKEN.match(par.name):
            renames[par.sym] = f"p[{k}]"
        else:
            renames[par.sym] = par.name
            locals_.append((par.name, k))
    return locals_, PyPrinter(renames)
