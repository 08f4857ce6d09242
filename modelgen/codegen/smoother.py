"""The backward pass of a fixed-interval Rauch-Tung-Striebel smoother, described for the backends.

Every generated filter carries the backward pass of its own model (Python
``smooth``/``smooth_step``/``smooth_refer``, C ``<model>_smooth``,
``<model>_smooth_step``, ``<model>_smooth_refer``).  It runs on what a closed-loop
forward pass stores per covariance step k: the transition Phi_k from step k-1,
the prior P_k^- (after predict), the posterior P_k^+ (after the step's updates
and resets) and the corrections dx fed back at the step, in order.

With s_{k+1} the smoothed error relative to the nominal after step k+1's
corrections, the corrections are undone last to first (the reset of a
correction dx maps the error e to G(dx) (e - dx), so e = G(dx)^-1 e' + dx and
P = G^-1 P' G^-T), which refers s_{k+1} and P^s_{k+1} to the nominal before
them, the one the prior is about; then

    A_k   = P_k^+ Phi_{k+1}^T (P_{k+1}^-)^-1      (Cholesky factor of P_{k+1}^-)
    s_k   = A_k s_{k+1}^-
    P^s_k = P_k^+ + A_k (P^s_{k+1}^- - P_{k+1}^-) A_k^T

with s_N = 0, P^s_N = P_N^+.  G comes from the derivation
(:func:`modelgen.model.perturbation.problem.attitude_reset`): I + [dtheta x]/2
over a rotation-vector attitude error, the identity for phi and psi angles and
every additive state, where undoing a reset is s + dx and leaves P^s as it is.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from modelgen.errors import ModelError


@dataclass(frozen=True)
class ResetInverse:
    """G(dx)^-1 over the states whose reset is not the identity: ``matrix`` in ``symbols`` (dx of ``states``)."""

    states: tuple[int, ...]
    symbols: tuple[sp.Symbol, ...]
    matrix: sp.Matrix


def reset_inverse(derived) -> ResetInverse | None:
    """The model's non-identity reset block and its inverse, None when every reset is the identity."""
    model = derived.model
    reset = getattr(model, "attitude_reset", None)
    if reset is None or reset.matrix == sp.eye(reset.matrix.shape[0]):
        return None
    names = list(model.state_names)
    try:
        states = tuple(names.index(s) for s in reset.states)
    except ValueError:
        raise ModelError(f"model {model.name!r}: its attitude reset names states it does not have "
                         f"({', '.join(reset.states)})") from None
    symbols = tuple(sp.Symbol(f"dx{i}", real=True) for i in states)
    matrix = reset.matrix.subs(dict(zip(reset.correction, symbols)))
    inverse = sp.simplify(matrix.inv())
    return ResetInverse(states, symbols, sp.Matrix(inverse))


def phi_rows(structure) -> list[list[int]]:
    """Per row of Phi the columns that can be nonzero (the backward pass multiplies only those)."""
    return structure.rows("Phi")
