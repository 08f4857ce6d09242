"""A derived model's F, G, H, Q, R as a CasADi ``Function`` of its parameters, serialized.

The function is ``NAME(latitude, height, ...) -> (F, G, H, Q, R)``: one
scalar input per parameter, named as the parameter and in the model's
parameter order, with the model's default value as the input's default
(``default_in``; NaN for a parameter without a default, so a forgotten input
shows as NaN entries instead of a silent 0).  Called with names
(``f(latitude=0.52, velocity_east=83.3)``) it fills the others from the
defaults.  Every sympy entry is translated by
:func:`modelgen.derivation.casadi_functions.sympy_to_casadi`; zero entries stay
structural zeros.  The text is what ``casadi.Function.save``
writes, so ``casadi.Function.load(path)`` reads the file back in CasADi
(Python, MATLAB, C++).
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import casadi as ca
import sympy as sp

from modelgen.derivation.casadi_functions import sympy_to_casadi
from modelgen.derivation.symbolic import DerivedModel
from modelgen.export.readable import MATRIX_NAMES, nonzero_entries


def _casadi_matrix(matrix: sp.Matrix, symbols: dict[sp.Symbol, ca.SX], where: str) -> ca.SX:
    """``matrix`` as a sparse SX with only its nonzero entries stored."""
    out = ca.SX(*matrix.shape)
    for i, j, entry in nonzero_entries(matrix):
        out[i - 1, j - 1] = sympy_to_casadi(entry, symbols, f"{where}({i},{j})")
    return out


def casadi_function(derived: DerivedModel, name: str | None = None) -> ca.Function:
    """``NAME(<one input per parameter>) -> (F, G, H, Q, R)`` (default name ``<model>_matrices``), each input named as
    its parameter and defaulting to the parameter's value (NaN where the model gives none)."""
    model = derived.model
    inputs = [ca.SX.sym(q.name) for q in model.parameters]
    symbols = {q.sym: inputs[k] for k, q in enumerate(model.parameters)}
    outputs = [_casadi_matrix(getattr(derived, m), symbols, f"model {model.name!r}, {m}") for m in MATRIX_NAMES]
    defaults = [math.nan if q.value is None else float(q.value) for q in model.parameters]
    return ca.Function(name or f"{model.name}_matrices", inputs, outputs, [q.name for q in model.parameters],
                       list(MATRIX_NAMES), {"default_in": defaults})


def to_casadi(derived: DerivedModel, name: str | None = None) -> str:
    """The function as ``casadi.Function.save`` writes it (ASCII text that ``casadi.Function.load`` reads).

    CasADi writes only to a path, so the function is saved into a private
    temporary folder and read back; the caller writes the text atomically.
    """
    function = casadi_function(derived, name)
    with tempfile.TemporaryDirectory(prefix="modelgen-casadi-") as folder:
        path = Path(folder) / "function.casadi"
        function.save(str(path))
        return path.read_text(encoding="ascii")
