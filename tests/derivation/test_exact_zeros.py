"""Entries of F, G, H that cancel to zero are dropped (issue 27, exact zeros)."""

from __future__ import annotations

from pathlib import Path

import sympy as sp

from modelgen.derivation.symbolic import derive, is_identically_zero
from modelgen.model.loading import load_model

HERE = Path(__file__).resolve().parent


def test_a_psi_angle_enu_model_has_no_entry_that_cancels_to_zero():
    derived = derive(load_model(HERE / "psi_enu_cancelling.yaml"))
    index = derived.model.state_names.index
    # before: v_u*cos(L)/(R*cos(L) + h*cos(L)) - v_u/(R + h), printed, in the sparsity, ~1e-21 when evaluated
    assert derived.F[index("velocity_error_east"), index("velocity_error_east")] == 0
    assert derived.F[index("attitude_error_east"), index("position_error_east")] == 0
    assert derived.nonzeros("F") == 47  # 54 before: 7 entries cancelled
    assert not derived.structure("F")[index("velocity_error_east"), index("velocity_error_east")]
    for matrix in "FGH":
        m = getattr(derived, matrix)
        assert not any(m[i, j] != 0 and is_identically_zero(m[i, j]) for i in range(m.rows) for j in range(m.cols))


def test_is_identically_zero_tells_cancelling_sums_from_near_misses():
    R, h, L, v, c, l, w = sp.symbols("R h L v c l w", real=True)
    assert is_identically_zero(v * sp.cos(L) / (R * sp.cos(L) + h * sp.cos(L)) - v / (R + h))
    assert is_identically_zero(sp.sin(L) ** 2 + sp.cos(L) ** 2 - 1)
    assert not is_identically_zero(v / (R + h) - v / (R + 2 * h))
    assert not is_identically_zero(c * l * w - c * l * v)
    assert not is_identically_zero(v)
