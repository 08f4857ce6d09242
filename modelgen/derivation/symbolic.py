"""Automatic derivation of F, G, H, Q, R from a model's equations.

F = df/dx, G = df/dw and H = dh/dx are Jacobians evaluated at zero error and
zero noise (the error equations are linear in x and w, so this is exact for
them and the first-order linearization otherwise).  Nothing is typed by hand.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable, Mapping

import numpy as np
import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, nonlinear_variables


@dataclass(frozen=True)
class DerivedModel:
    """The symbolic matrices of ``dx/dt = F x + G w``, ``z = H x + v``.

    ``Q`` is the continuous noise power spectral density matrix (diagonal,
    from each noise's ``psd``) and ``R`` the measurement noise covariance.
    """

    model: ErrorModel
    F: sp.Matrix
    G: sp.Matrix
    H: sp.Matrix
    Q: sp.Matrix
    R: sp.Matrix
    nonlinear: tuple[str, ...] = ()

    @property
    def n_states(self) -> int:
        return self.F.shape[0]

    @property
    def n_noises(self) -> int:
        return self.G.shape[1]

    @property
    def n_measurements(self) -> int:
        return self.H.shape[0]

    def nonzeros(self, matrix: str) -> int:
        """How many entries of F, G, H, Q or R are structurally nonzero."""
        m = getattr(self, matrix)
        return sum(1 for entry in m if entry != 0)

    def __repr__(self) -> str:
        """One line: the model and the sizes (the default repr printed every matrix: 26,545 characters)."""
        counts = ", ".join(f"{m} {self.nonzeros(m)}" for m in "FGH")
        return (f"<DerivedModel {self.model.name!r}: {self.n_states} states, {self.n_noises} noises, "
                f"{self.n_measurements} measurements; nonzeros {counts}>")

    def _repr_markdown_(self) -> str:
        """What a notebook shows: the model, its sizes and its states (the matrices are ``.F`` ... ``.R``)."""
        title = getattr(self.model, "title", "") or ""
        lines = [f"**DerivedModel `{self.model.name}`**" + (f": {title}" if title else ""), "",
                 "| matrix | shape | nonzeros |", "|---|---|---:|"]
        lines += [f"| {m} | {getattr(self, m).shape[0]} x {getattr(self, m).shape[1]} | {self.nonzeros(m)} |" for m in "FGHQR"]
        lines += ["", "states: " + ", ".join(f"`{name}`" for name in self.model.state_names)]
        return "\n".join(lines) + "\n"

    def structure(self, matrix: str) -> np.ndarray:
        """Boolean mask of the structurally nonzero entries of F, G or H."""
        return self._structures[matrix].copy()

    @cached_property
    def _structures(self) -> dict[str, np.ndarray]:
        """The masks of F, G, H, Q and R, made once (from the matrices' nonzero entries, not entry by entry)."""
        out = {}
        for name in "FGHQR":
            m = getattr(self, name)
            mask = np.zeros(m.shape, dtype=bool)
            for (i, j), entry in m.todok().items():
                mask[i, j] = entry != 0
            out[name] = mask
        return out

    @cached_property
    def _numeric(self) -> Callable[..., tuple]:
        params = self.model.parameter_symbols
        # numpy as a module object, not "numpy": the string makes lambdify run `from numpy import *`, which
        # loads numpy.testing and numpy.f2py (0.07 s, paid by the first code generation in a process)
        return sp.lambdify(params, [self.F, self.G, self.H, self.Q, self.R], modules=[np], cse=True)

    def numeric(self, values: Mapping[str, float]) -> dict[str, np.ndarray]:
        """F, G, H, Q, R as float arrays at the given parameter values.

        ``values`` maps parameter names to numbers; parameters with a default
        in the model may be omitted.
        """
        args = parameter_vector(self.model, values)
        F, G, H, Q, R = self._numeric(*args)
        shapes = {
            "F": self.F.shape,
            "G": self.G.shape,
            "H": self.H.shape,
            "Q": self.Q.shape,
            "R": self.R.shape,
        }
        out = {}
        for key, value in zip("F G H Q R".split(), (F, G, H, Q, R)):
            out[key] = np.broadcast_to(np.asarray(value, dtype=float), shapes[key]).copy()
        return out


def parameter_vector(model: ErrorModel, values: Mapping[str, float]) -> list[float]:
    """Parameter values in model order, defaults filled in, unknowns refused."""
    known = {p.name for p in model.parameters} | {p.symbol for p in model.parameters}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ModelError(f"model {model.name!r}: unknown parameter(s) {', '.join(unknown)}")
    out = []
    for p in model.parameters:
        if p.name in values:
            v = values[p.name]
        elif p.symbol in values:
            v = values[p.symbol]
        elif p.value is not None:
            v = p.value
        else:
            at = f"{p.place()}: " if p.place() else ""  # its declaration, which gives no value
            raise ModelError(f"{at}model {model.name!r}: no value for parameter {p.name!r} ({p.symbol})")
        v = float(v)
        if not np.isfinite(v):
            raise ModelError(f"model {model.name!r}: parameter {p.name!r} is not finite ({v})")
        out.append(v)
    return out


def derive(model: ErrorModel) -> DerivedModel:
    """Derive F, G, H, Q, R from the model's equations (see module doc)."""
    x = list(model.state_symbols)
    w = list(model.noise_symbols)
    f = [sp.sympify(model.dynamics[name]) for name in model.state_names]
    zero = {s: 0 for s in (*model.state_symbols, *model.noise_symbols)}

    F = _sparse_jacobian(f, x, zero)
    G = _sparse_jacobian(f, w, zero) if model.noises else sp.zeros(len(x), 0)
    if model.measurements:
        h = [sp.sympify(model.measurement_expressions[m.name]) for m in model.measurements]
        H = _sparse_jacobian(h, x, zero)
        R = sp.diag(*[model.measurement_variance[m.name] for m in model.measurements])
    else:
        H = sp.zeros(0, len(x))
        R = sp.zeros(0, 0)
    Q = sp.diag(*[model.noise_psd[n] for n in model.noise_names]) if model.noises else sp.zeros(0, 0)

    # ErrorModel.build refuses nonlinear equations (one rule for every command);
    # this stays as a guard for models assembled around build, by the same rule.
    errors_and_noises = {*model.state_symbols, *model.noise_symbols}
    nonlinear = tuple(name for name, rhs in zip(model.state_names, f) if nonlinear_variables(rhs, errors_and_noises))
    return DerivedModel(
        model=model,
        F=_tidy(F),
        G=_tidy(G),
        H=_tidy(H),
        Q=_tidy(Q),
        R=_tidy(R),
        nonlinear=nonlinear,
    )


def _sparse_jacobian(rows: list[sp.Expr], variables: list[sp.Symbol], zero: Mapping[sp.Symbol, int]) -> sp.Matrix:
    """``Matrix(rows).jacobian(variables).subs(zero)``, entry for entry, differentiating only by the symbols present.

    An entry whose row does not contain the variable is an exact zero (what ``diff`` returns), and
    the substitution of zero errors and noises is made only in an entry that contains one of them
    (elsewhere it is the identity): a 200-state model has 40,000 entries and about 1,500 nonzeros.
    """
    index = {v: j for j, v in enumerate(variables)}
    entries: dict[tuple[int, int], sp.Expr] = {}
    for i, expr in enumerate(rows):
        # the derivative of a sum is the sum of its terms' derivatives (sympy's Add._eval_derivative): a term
        # without the variable adds an exact zero, so only the terms that contain it are differentiated
        terms = sp.Add.make_args(expr) if expr.is_Add else None
        by_variable: dict[sp.Symbol, list[sp.Expr]] = {}
        if terms is not None:
            for term in terms:
                for s in term.free_symbols:
                    if s in index:
                        by_variable.setdefault(s, []).append(term)
        for v in sorted((s for s in expr.free_symbols if s in index), key=index.__getitem__):
            d = expr.diff(v) if terms is None else sp.Add(*[t.diff(v) for t in by_variable[v]])
            if d == 0:
                continue
            if not d.free_symbols.isdisjoint(zero):
                d = d.subs(zero)
                if d == 0:
                    continue
            entries[i, index[v]] = d
    return sp.Matrix(sp.SparseMatrix(len(rows), len(variables), entries))


def _tidy(m: sp.Matrix) -> sp.Matrix:
    """Expand products so that equal entries print identically everywhere; entries that cancel to 0 become 0.

    An entry such as ``v_u*cos(L)/(R*cos(L) + h*cos(L)) - v_u/(R + h)`` (a
    psi-angle model's change of variables leaves several) is identically zero
    but does not expand to 0: kept, it would print, enter the generated sparsity
    and evaluate to rounding (1e-21).  :func:`is_identically_zero` decides.
    """
    def tidy(e: sp.Expr) -> sp.Expr:
        if e == 0:
            return sp.S.Zero
        expanded = sp.expand(e)
        return sp.S.Zero if is_identically_zero(expanded) else expanded

    return m.applyfunc(tidy)


#: Two generic points (square roots of primes: no symmetry between symbols) at which a candidate zero is screened.
_SCREEN_POINTS = ((2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37), (41, 43, 47, 53, 59, 61, 67, 71, 73, 79, 83, 89))


def is_identically_zero(expr: sp.Expr) -> bool:
    """Whether ``expr`` is 0 for every value of its symbols (sympy's cancel, then simplify, decides).

    A sum that is not small beside its terms at either of two generic points is
    not zero (fast: most entries stop here); one that is small there is proved
    zero symbolically or kept.
    """
    if expr == 0:
        return True
    if not expr.is_Add or not expr.free_symbols:
        return False
    symbols = sorted(expr.free_symbols, key=str)
    for primes in _SCREEN_POINTS:
        point = {s: sp.Rational(round(10**6 * (0.25 + 0.5 * ((primes[k % len(primes)] + k // len(primes)) ** 0.5 % 1.0))), 10**6)
                 for k, s in enumerate(symbols)}  # exact values, evaluated to 30 digits
        try:
            value = complex(expr.xreplace(point).evalf(30))
            scale = sum(abs(complex(t.xreplace(point).evalf(30))) for t in expr.args)
        except (TypeError, ValueError, ZeroDivisionError):
            return False
        if not (abs(value) <= 1e-20 * scale):
            return False
    return sp.cancel(sp.together(expr)) == 0 or sp.simplify(expr) == 0
