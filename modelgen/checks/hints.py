"""Automatic hints for an entry that differs: what a person most likely got wrong.

When an entry a person wrote (a paper's table, a hand-written model) differs
from the derived one, the usual causes are few and mechanical: a flipped
sign, a missing unit conversion (arc-seconds, degrees, hours), the row and
column swapped, the entry put in the wrong row or column, or one term of a
sum left out.  Each test here is a pure, deterministic function over sympy
expressions; :func:`difference_hints` runs them all and returns the hints
in a fixed order, so a report that shows them is identical run to run.

Equality is decided by :func:`same`: the difference expands to zero, or it is
zero to 30 digits at three fixed points.  A hint is a suggestion shown next
to an unexplained difference, never a verdict: it does not change a status.

Public API (used by :mod:`modelgen.checks.paper_check` and the cross-check of
hand-written against derived models)::

    hints = difference_hints(written, derived, key=("F", 2, 1), derived_entries=entries)
    for h in hints: print(h.kind, h.text)
"""

from __future__ import annotations

import random
from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations
from typing import Mapping

import sympy as sp

Key = tuple[str, int, int]  # (matrix, row, column), 1-based as printed

#: Kinds of hint, in the order :func:`difference_hints` reports them.
HINT_KINDS = ("sign_flip", "unit_factor", "transposed", "misplaced", "missing_term", "extra_term", "term_sign")

#: M = 180*3600/pi: radians to arc-seconds, and also rad/s to deg/h.
ARCSECONDS_PER_RADIAN = sp.Integer(180 * 3600) / sp.pi

@dataclass(frozen=True)
class NamedFactor:
    """A unit conversion factor a written entry may be missing: its short name, value and meaning."""

    name: str
    value: sp.Expr
    meaning: str


#: The unit factors a written entry is most often missing.  A ratio
#: written/derived equal to one of these is reported as a unit-factor hint.
UNIT_FACTORS: tuple[NamedFactor, ...] = (
    NamedFactor("M", ARCSECONDS_PER_RADIAN, "180*3600/pi: rad -> arcsec, rad/s -> deg/h"),
    NamedFactor("1/M", 1 / ARCSECONDS_PER_RADIAN, "pi/(180*3600): arcsec -> rad, deg/h -> rad/s"),
    NamedFactor("180/pi", sp.Integer(180) / sp.pi, "rad -> deg"),
    NamedFactor("pi/180", sp.pi / 180, "deg -> rad"),
    NamedFactor("3600", sp.Integer(3600), "s -> h, per second -> per hour"),
    NamedFactor("1/3600", sp.Rational(1, 3600), "h -> s, per hour -> per second"),
)

_DIGITS = 30
_POINTS = 3
_RELATIVE_ZERO = sp.Float("1e-20", _DIGITS)
#: Most terms of a sum a single hint names as missing (subsets are tried smallest first).
MAX_MISSING_TERMS = 2


@dataclass(frozen=True)
class Hint:
    """One suggestion: its kind (one of :data:`HINT_KINDS`) and a sentence for the report."""

    kind: str
    text: str


# -- numeric fingerprints -----------------------------------------------------
def _point_value(symbol: sp.Symbol, point: int) -> sp.Float:
    """The value of ``symbol`` at test point ``point``: fixed by the symbol's name alone.

    Seeding by name makes every expression's fingerprint comparable with every
    other's (the same symbol always gets the same value), and deterministic.
    Values lie in (0.3, 1.1): inside the domain of tan, sec, sqrt and log.
    """
    return sp.Float(random.Random(f"{symbol.name}#{point}").uniform(0.3, 1.1), _DIGITS)


@lru_cache(maxsize=4096)
def fingerprint(expr: sp.Expr) -> tuple[sp.Expr, ...]:
    """``expr`` evaluated at the three fixed test points, to 30 digits."""
    values = []
    for k in range(_POINTS):
        point = {s: _point_value(s, k) for s in expr.free_symbols}
        values.append(sp.N(expr.evalf(_DIGITS, subs=point), _DIGITS) if point else sp.N(expr, _DIGITS))
    return tuple(values)


def _close(a: tuple[sp.Expr, ...], b: tuple[sp.Expr, ...]) -> bool:
    """Whether two fingerprints agree to the relative tolerance (complex values never do)."""
    for x, y in zip(a, b):
        if not (x.is_number and y.is_number and x.is_real is not False and y.is_real is not False):
            return False
        if abs(x - y) > _RELATIVE_ZERO * (abs(x) + abs(y)):
            return False
    return True


def same(a: sp.Expr, b: sp.Expr) -> bool:
    """Whether ``a`` and ``b`` are the same function: zero difference, or equal at every test point."""
    if sp.expand(a - b) == 0:
        return True
    return _close(fingerprint(sp.sympify(a)), fingerprint(sp.sympify(b)))


def _is_zero(expr: sp.Expr) -> bool:
    return expr == 0 or all(v == 0 for v in fingerprint(expr))


# -- the individual tests -----------------------------------------------------
def sign_flip(written: sp.Expr, derived: sp.Expr) -> Hint | None:
    """The written entry is the derived one with the opposite sign."""
    if _is_zero(derived) or not same(written, -derived):
        return None
    return Hint("sign_flip", "sign flip: the written entry is the derived one with the opposite sign")


def constant_ratio(written: sp.Expr, derived: sp.Expr) -> sp.Expr | None:
    """written / derived if it is the same number at every test point, else None."""
    if _is_zero(derived) or _is_zero(written):
        return None
    ratios = [w / d for w, d in zip(fingerprint(written), fingerprint(derived))]
    first = ratios[0]
    if any(abs(r - first) > _RELATIVE_ZERO * (abs(r) + abs(first)) for r in ratios[1:]):
        return None
    return first


def unit_factor(written: sp.Expr, derived: sp.Expr, factors: tuple[NamedFactor, ...] = UNIT_FACTORS) -> Hint | None:
    """written = f * derived (or -f * derived) for a named unit factor f: a unit conversion applied or forgotten."""
    ratio = constant_ratio(written, derived)
    if ratio is None:
        return None
    for factor in factors:
        value = sp.N(factor.value, _DIGITS)
        for sign, words in ((1, ""), (-1, ", and the sign is flipped")):
            if abs(ratio - sign * value) <= _RELATIVE_ZERO * abs(value):
                text = f"unit factor: written = {'-' if sign < 0 else ''}{factor.name} x derived ({factor.name} = {factor.meaning}){words}"
                return Hint("unit_factor", text)
    return None


def placement(written: sp.Expr, key: Key, derived_entries: Mapping[Key, sp.Expr]) -> list[Hint]:
    """Where else in the derived matrix the written value sits: transposed, or elsewhere in its row or column.

    ``derived_entries`` maps (matrix, row, column) to the derived entry in the
    written entry's units; absent keys are zero.  Candidates are tried in a
    fixed order (transposed place, then the row by column, then the column by
    row); a value equal up to sign is reported as such.
    """
    matrix, row, column = key
    if _is_zero(written):
        return []
    rows = sorted({k[1] for k in derived_entries if k[0] == matrix})
    columns = sorted({k[2] for k in derived_entries if k[0] == matrix})
    candidates: list[tuple[str, Key]] = []
    if row != column and (matrix, column, row) in derived_entries:
        candidates.append(("transposed", (matrix, column, row)))
    candidates += [("misplaced", (matrix, row, c)) for c in columns if c != column and (matrix, row, c) in derived_entries]
    candidates += [("misplaced", (matrix, r, column)) for r in rows if r != row and (matrix, r, column) in derived_entries]
    seen: set[Key] = set()
    out = []
    for kind, where in candidates:
        if where in seen:
            continue
        seen.add(where)
        value = derived_entries[where]
        label = f"{where[0]}({where[1]},{where[2]})"
        what = "transposed indices: " if kind == "transposed" else "misplaced entry: "
        if same(written, value):
            out.append(Hint(kind, f"{what}the written value is the derived {label}"))
        elif same(written, -value):
            out.append(Hint(kind, f"{what}the written value is minus the derived {label}"))
    return out


def _terms(expr: sp.Expr) -> tuple[sp.Expr, ...]:
    """The terms of a sum after distributing products (denominators such as (R_M + h)**2 stay whole)."""
    return sp.Add.make_args(sp.expand_mul(expr))


def _subset_equal_to(target: tuple[sp.Expr, ...], terms: tuple[sp.Expr, ...], scale: int = 1) -> tuple[sp.Expr, ...] | None:
    """The smallest subset of ``terms`` (at most :data:`MAX_MISSING_TERMS`) whose sum times ``scale`` has fingerprint ``target``."""
    for size in range(1, min(MAX_MISSING_TERMS, len(terms) - 1) + 1):
        for subset in combinations(terms, size):
            if _close(fingerprint(scale * sp.Add(*subset)), target):
                return subset
    return None


def _sum_text(terms: tuple[sp.Expr, ...]) -> str:
    return ", ".join(sp.sstr(t) for t in terms)


def term_differences(written: sp.Expr, derived: sp.Expr) -> list[Hint]:
    """A term of the derived sum missing from the written one, a term the written one adds, or one term's sign flipped."""
    gap = tuple(d - w for d, w in zip(fingerprint(derived), fingerprint(written)))
    out = []
    missing = _subset_equal_to(gap, _terms(derived)) if len(_terms(derived)) > 1 else None
    if missing:
        out.append(Hint("missing_term", f"missing term: the written entry lacks {_sum_text(missing)} of the derived sum"))
    extra = _subset_equal_to(tuple(-g for g in gap), _terms(written)) if len(_terms(written)) > 1 else None
    if extra:
        out.append(Hint("extra_term", f"extra term: the written entry adds {_sum_text(extra)}, which the derived sum lacks"))
    if not missing and not extra and len(_terms(derived)) > 1:
        flipped = _subset_equal_to(gap, _terms(derived), scale=2)
        if flipped:
            out.append(Hint("term_sign", f"term sign: {_sum_text(flipped)} has the opposite sign in the written entry"))
    return out


# -- all of them ---------------------------------------------------------------
def difference_hints(
    written: sp.Expr | None,
    derived: sp.Expr | None,
    key: Key | None = None,
    derived_entries: Mapping[Key, sp.Expr] | None = None,
    factors: tuple[NamedFactor, ...] = UNIT_FACTORS,
) -> tuple[Hint, ...]:
    """Every hint for one differing entry, in the order of :data:`HINT_KINDS`.

    ``written`` is the entry as a person wrote it, ``derived`` the derived one,
    both in the same units with numbers for every unit symbol (None or 0: no
    entry).  With ``key`` and ``derived_entries`` (all derived nonzeros of the
    matrices, in the written units) the placement hints are searched too.
    ``factors`` are the named unit factors tried (default :data:`UNIT_FACTORS`).
    """
    written = sp.S.Zero if written is None else sp.sympify(written)
    derived = sp.S.Zero if derived is None else sp.sympify(derived)
    out: list[Hint] = []
    if not _is_zero(written) and not _is_zero(derived):
        for hint in (sign_flip(written, derived), unit_factor(written, derived, factors)):
            if hint is not None:
                out.append(hint)
    if key is not None and derived_entries is not None and not _is_zero(written):
        out += placement(written, key, derived_entries)
    if not out and not _is_zero(written) and not _is_zero(derived):
        out += term_differences(written, derived)
    order = {kind: i for i, kind in enumerate(HINT_KINDS)}
    return tuple(sorted(out, key=lambda h: order[h.kind]))
