"""A derived model's F, G, H, Q, R as a CasADi ``Function`` of its parameters, serialized.

The function is ``NAME(p) -> (F, G, H, Q, R)`` with ``p`` the parameter
vector in the model's parameter order (as in
:func:`modelgen.derive.symbolic.parameter_vector`); every sympy entry is
translated by :func:`modelgen.derive.casadi_functions.sympy_to_casadi`, zero
entries stay structural zeros.  The text is what ``casadi.Function.save``
writes, so ``casadi.Function.load(path)`` reads the file back in CasADi
(Python, MATLAB, C++).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import casadi as ca
import sympy as sp

from modelgen.derive.casadi_functions import sympy_to_casadi
from modelgen.derive.symbolic import DerivedModel
from modelgen.export.readable import MATRIX_NAMES, nonzero_entries


def _casadi_matrix(matrix: sp.Matrix, symbols: dict[sp.Symbol, ca.SX], where: str) -> ca.SX:
    """``matrix`` as a sparse SX with only its nonzero entries stored."""
    out = ca.SX(*matrix.shape)
    for i, j, entry in nonzero_entries(matrix):
        out[i - 1, j - 1] = sympy_to_casadi(entry, symbols, f"{where}({i},{j})")
    return out


def casadi_function(derived: DerivedModel, name: str | None = None) -> ca.Function:
    """``NAME(p) -> (F, G, H, Q, R)`` (default name ``<model>_matrices``)."""
    model = derived.model
    p = ca.SX.sym("p", len(model.parameters))
    symbols = {q.sym: p[k] for k, q in enumerate(model.parameters)}
    outputs = [_casadi_matrix(getattr(derived, m), symbols, f"model {model.name!r}, {m}") for m in MATRIX_NAMES]
    return ca.Function(name or f"{model.name}_matrices", [p], outputs, ["p"], list(MATRIX_NAMES))


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
