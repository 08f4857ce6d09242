"""Continuous -> discrete: transition matrix Phi and process noise.

Two methods, so that each checks the other:

* the paper's truncated Taylor series (the core paper, eqs. (10)-(11)),
  Phi = sum_{k=0..N} (F T)^k / k!,  Gamma = T sum_{k=0..N} (F T)^k / (k+1)! G,
  with the discrete noise covariance Gamma (Q/T) Gamma^T.  Dividing the
  continuous power spectral density Q by T turns it into the covariance of the
  equivalent white sequence W(k) held over one step, so that
  Gamma Q_k Gamma^T ~ T G Q G^T to first order.  The series is summed with
  scaling and squaring, so that it stays accurate for any finite T (below);
* the exact matrix exponential, with Van Loan's method for
  Q_d = int_0^T e^{F s} G Q G^T e^{F^T s} ds.

Scaling and squaring.  Truncated at order N, the series is only accurate
while F T is small: with the paper's order 9, Phi of the 18-state model is
16 % off at T = 3600 s (64 % summed to order 9 alone).  So the series is summed over h = T / 2^s and then
doubled s times:

    Phi(2h) = Phi(h)^2,   Psi(2h) = Psi(h) + Phi(h) Psi(h),

(on E = Phi - I: E(2h) = 2 E + E^2, so that adding the identity does not
round away the small part of Phi(h) s times over)

where Psi(h) = int_0^h e^{F s} ds = h sum_k (F h)^k / (k+1)! is the series of
eq. (11) and Gamma = Psi(T) G.  Both identities are exact, so Phi and Gamma
converge to e^{F T} and int_0^T e^{F s} ds G, the limits of eqs. (10)-(11),
for any finite T; Q_d stays the paper's Gamma (Q/T) Gamma^T.

s is the smallest integer with theta = ||F||_D h <= theta_N, where

* ||F||_D = max_i sum_j |F_ij| d_j / d_i is the infinity norm of D^-1 F D,
  D = diag(d) a power-of-two diagonal scaling from at most eight Jacobi
  sweeps of Osborne's balancing (fewer when a sweep changes nothing) (each d_i moves by at most 2^8 per sweep and stays
  within 2^-40..2^40).  Any D
  gives a valid norm; balancing makes it independent of the units chosen
  for each state (unscaled, g = 9.8 m/s^2 from tilt into velocity makes
  ||F T|| about 650 at T = 60 s for the paper's model; balanced it is
  0.16, the Schuler rate times T).  Since any D will do, the generated
  code balances once, at generation time, at the model's check operating
  point (``nominal_scaling``), and keeps that D as constants: the run-time
  norm is then one pass over the nonzeros of F (no sweeps).  At another
  operating point that D can be far from F's own balancing (a state that
  drives nothing at the check point, where a rate is zero, keeps d = 1), so
  when the plan on the fixed D needs a doubling, F is rebalanced at run
  time from that D and the plan retaken on the smaller norm (``step_plan``):
  the doublings are those of F's own balancing at the actual operating
  point, and the sweeps run only when a doubling is at stake, and stop after
  the first whose norm leaves none.  A
  model without a ``check:`` section is balanced at run time, as above;
* theta_N is the largest theta for which the remainder of the series,
  at most theta^(N+1) / (N+1)! * (N+2) / (N+2-theta) in that norm, is below
  the unit roundoff u (2^-53 in double, 2^-24 in float): 0.12 for N = 9 in
  double.

So the truncation error of Phi(h) is below u ||Phi(h)||_D, the series for
Psi converges faster still, and what remains is the rounding of s
doublings (s = 1 at the paper's 60 s step, 11 at one day).  Measured
against scipy's expm on the paper's model, the largest error of Phi is below
1e-15 of its largest entry up to T = 600 s and below 1e-11 up to T = 1 day
(tests/derivation/test_discretization.py states 1e-13 and 1e-10).  The generated C and
Python compute the same D (given the same ``scaling``), norm and s, so the three agree.  s is capped at
64 (||F||_D T up to about 2e18): beyond, e^{F T} is refused as not
representable.

Order.  The series is summed by Horner's rule over S(h) = Psi(h) / h =
sum_(k=0..m) (F h)^k / (k+1)!, and Phi(h) = I + F h S(h), the identity
e^X = I + X int_0^1 e^(X s) ds truncated: Phi is then the series of
eq. (10) to order m + 1 and Gamma = T S G that of eq. (11) to order m, one
product per order for both (m + 1 in all) instead of a power and two sums.
Phi of order m + 1 is within every bound stated here for order m (its
remainder is the smaller); the paper's order 9 stays the order of eq. (11),
and at the paper's step the extra term of Phi is below the unit roundoff.

The accuracy rule (``tolerance``, default 1e-12; None keeps the order fixed).
With X = F h, theta = ||X||_D and the remainder R = e^X - T_m(X) of the
series truncated after order m, ||R||_D <= rho_m(theta) = theta^(m+1) /
(m+1)! * (m+2) / (m+2-theta) (the tail of e^theta, bounded by a geometric
series, for theta < m + 2).  R is a power series in X, so
T_m(X) = e^X (I + E) with E = -e^{-X} R commuting with e^X and
||E||_D <= delta = e^theta rho_m(theta).  Squaring s times,
T_m(X)^(2^s) = e^{F T} (I + E)^(2^s), and
||(I + E)^(2^s) - I|| <= (1 + delta)^(2^s) - 1 <= 2^(s+1) delta
whenever 2^s delta <= 1/2.  So

    ||Phi - e^{F T}||_D <= tol ||e^{F T}||_D   when   2^(s+1) e^theta rho_m(theta) <= tol,

in exact arithmetic (rounding adds about s + m unit roundoffs).  That norm
lets the balancing scale a block of F that drives another without being
driven (a bias into the attitude) by up to 2^-80 against it, so an entry
whose leading term crosses such a coupling (a gyro bias into velocity
through the tilt, of order 2 in T) is bounded only relative to its block,
and its relative error is larger by about 1/theta: at T = 1 s the paper's
model with order 4 is 3.4e-12 off at that entry against 1.2e-15 in the
balanced norm.  The rule therefore keeps one order of margin
(CROSS_BLOCK_MARGIN): it asks 2^(s+1) e^theta rho_(m-1)(theta) <= tol,
which bounds those entries too (measured against expm on every built-in
model, tests/derivation/test_discretization.py), the stated bound.  The same holds for Psi: its series is the integral of the
series of Phi, term by term smaller by 1/(k+1), and each doubling
Psi(2h) = Psi(h) + Phi(h) Psi(h) carries Phi's relative error.  The plan
(``taylor_plan``) takes the smallest s for which the highest generated order
N meets the bound, then the smallest order m <= N that still meets it: at
T = 1 s the paper's model needs order 5 (theta = 0.0026), at T = 60 s order 9
without doubling (theta = 0.155), where the fixed order 9 takes one doubling
to reach the unit roundoff.  A tolerance not above the unit roundoff of the
arithmetic (every tolerance in single precision, where rounding through the
doublings dominates) means the fixed order.  Measured against scipy's expm (tests), the largest error
stays below the tolerance relative to the largest entry.
"""

from __future__ import annotations

import functools
import math
from typing import Callable

import numpy as np

from modelgen.errors import ModelError

DEFAULT_TAYLOR_ORDER = 9  # the core paper, eq. (10): terms up to F^9 T^9 / 9!
DEFAULT_TOLERANCE = 1e-12  # relative error of Phi against e^{F T} that the accuracy rule guarantees
CROSS_BLOCK_MARGIN = 1  # orders kept beyond the balanced-norm bound, for entries that couple blocks of F (docstring)
MAX_DOUBLINGS = 64  # T / 2^64: far below any step a navigation filter takes
BALANCING_SWEEPS = 8
MAX_SWEEP_EXPONENT = 8  # a scale moves by at most 2^8 per sweep
MAX_SCALE_EXPONENT = 40  # and stays within 2^-40..2^40 (a ratio d_j / d_i fits a float)
DOUBLE_ROUNDOFF = 2.0**-53
FLOAT_ROUNDOFF = 2.0**-24


@functools.lru_cache(maxsize=None)
def series_range(order: int, unit_roundoff: float = DOUBLE_ROUNDOFF) -> float:
    """Largest theta = ||F h|| for which the Taylor remainder after ``order`` is below ``unit_roundoff``.

    The remainder sum_{k>N} theta^k / k! is at most
    theta^(N+1) / (N+1)! * (N+2) / (N+2-theta); bisection on theta in [0, N+1].
    """
    def remainder(theta: float) -> float:
        return theta ** (order + 1) / math.factorial(order + 1) * (order + 2) / (order + 2 - theta)

    low, high = 0.0, float(order + 1)
    for _ in range(200):
        mid = 0.5 * (low + high)
        if remainder(mid) <= unit_roundoff:
            low = mid
        else:
            high = mid
    return low


def sweep_exponent(row: float, column: float) -> int:
    """Power of two k by which Osborne's balancing scales a state: 2^k ~ sqrt(row / column), bounded.

    With e the difference of frexp's exponents of row and column (log2 of
    their ratio to within one), k = floor(e / 2), within
    [-MAX_SWEEP_EXPONENT, MAX_SWEEP_EXPONENT].  A state that drives others
    but is driven by none (row 0: a random constant or a bias) takes the
    lower bound, one driven but driving none (column 0) the upper bound: the
    norm shrinks the further they go.  Integer arithmetic on exponents, so
    C and Python agree exactly.
    """
    if row > 0.0 and column > 0.0:
        e = math.frexp(row)[1] - math.frexp(column)[1]  # log2(row / column) within 1, never overflowing
        return max(-MAX_SWEEP_EXPONENT, min(MAX_SWEEP_EXPONENT, e // 2))
    if column > 0.0:
        return -MAX_SWEEP_EXPONENT
    if row > 0.0:
        return MAX_SWEEP_EXPONENT
    return 0


def sweep_exponents(row: np.ndarray, column: np.ndarray) -> np.ndarray:
    """:func:`sweep_exponent` of every state at once (the same integers)."""
    both = (row > 0.0) & (column > 0.0)
    ratio = np.minimum(np.maximum((np.frexp(row)[1] - np.frexp(column)[1]) // 2, -MAX_SWEEP_EXPONENT), MAX_SWEEP_EXPONENT)
    lone = np.where(column > 0.0, -MAX_SWEEP_EXPONENT, np.where(row > 0.0, MAX_SWEEP_EXPONENT, 0))
    return np.where(both, ratio, lone).astype(np.int64)


def balancing_exponents(
    F: np.ndarray, start: tuple[int, ...] | None = None, enough: Callable[[np.ndarray], bool] | None = None
) -> tuple[int, ...]:
    """e with D = diag(2^e) from Osborne's balancing of F (module docstring).

    At most BALANCING_SWEEPS Jacobi sweeps over the off-diagonal nonzeros,
    stopped at a fixed point, or after a sweep whose exponents ``enough``
    accepts (:func:`step_plan`: the plan on them needs no doubling); each e_i
    within +-MAX_SCALE_EXPONENT, so that no ratio d_j / d_i overflows, even
    in single precision.  The sweeps start from D = I, or from D =
    2^``start`` (the nominal scaling: run-time rebalancing, :func:`step_plan`).
    """
    F = np.asarray(F, dtype=float)
    rows, cols = np.nonzero(F)
    n = F.shape[0]
    off = rows != cols
    off_rows, off_cols, off_size = rows[off], cols[off], np.abs(F[rows[off], cols[off]])
    exponent = np.zeros(n, dtype=np.int64) if start is None else np.array(start, dtype=np.int64)  # d = 2^exponent
    for _ in range(BALANCING_SWEEPS if off_rows.size else 0):
        d = np.ldexp(1.0, exponent)
        v = off_size * d[off_cols] / d[off_rows]
        row = np.bincount(off_rows, weights=v, minlength=n)
        column = np.bincount(off_cols, weights=v, minlength=n)
        new = np.minimum(np.maximum(exponent + sweep_exponents(row, column), -MAX_SCALE_EXPONENT), MAX_SCALE_EXPONENT)
        if np.array_equal(new, exponent):
            break  # a fixed point: further sweeps change nothing
        exponent = new
        if enough is not None and enough(exponent):
            break
    return tuple(int(e) for e in exponent)


def scaled_norm(F: np.ndarray, exponents: tuple[int, ...]) -> float:
    """||F||_D = max_i sum_j |F_ij| d_j / d_i for D = diag(2^exponents).

    The sums run over the nonzero entries row by row (``np.bincount`` adds in
    that order), as the generated C and Python do, so that all round alike;
    each d_j / d_i is an exact power of two.
    """
    F = np.asarray(F, dtype=float)
    rows, cols = np.nonzero(F)
    if not rows.size:
        return 0.0
    d = np.ldexp(1.0, np.asarray(exponents, dtype=np.int64))
    return float(np.bincount(rows, weights=np.abs(F[rows, cols]) * d[cols] / d[rows], minlength=F.shape[0]).max())


def balanced_norm(F: np.ndarray, scaling: tuple[int, ...] | None = None) -> float:
    """||F||_D (module docstring): D = 2^``scaling`` fixed in advance, or from Osborne's balancing of F itself (None)."""
    return scaled_norm(F, balancing_exponents(F) if scaling is None else scaling)


def nominal_scaling(derived) -> tuple[int, ...] | None:
    """The exponents of D balanced once, at the model's check operating point (its ``check:`` section).

    Any fixed D gives a valid norm (module docstring), so the generated code
    uses this D as constants for every operating point and only sums
    max_i sum_j |F_ij| d_j / d_i at run time; None (balance F itself at run
    time) for a model without a ``check:`` section or whose F is not finite
    there.
    """
    check = derived.model.check
    if check is None:
        return None
    F = derived.numeric(check.parameter_values())["F"]
    if not np.all(np.isfinite(F)):
        return None
    return balancing_exponents(F)


def doublings(norm: float, T: float, order: int, unit_roundoff: float = DOUBLE_ROUNDOFF) -> int:
    """Smallest s with norm * T / 2^s <= series_range(order); ModelError beyond MAX_DOUBLINGS."""
    theta = series_range(order, unit_roundoff)
    for s in range(MAX_DOUBLINGS + 1):
        if norm * math.ldexp(T, -s) <= theta:
            return s
    raise ModelError(
        f"discretize: e^(F T) is not representable: ||F||*T = {norm * T:.3g} needs more than "
        f"{MAX_DOUBLINGS} doublings of the Taylor series"
    )


def truncation_bound(theta: float, order: int) -> float:
    """rho_m(theta) = theta^(m+1) / (m+1)! * (m+2) / (m+2-theta): the Taylor remainder bound (module docstring).

    Computed by one product, term by term, so that the generated C (which
    does the same operations in the same order) gets the same bits;
    infinity for theta >= m + 2, where the geometric bound fails.
    """
    if not theta < order + 2:
        return math.inf
    power = 1.0
    for k in range(1, order + 2):
        power = power * theta / k
    return power * (order + 2) / (order + 2 - theta)


def step_error_bound(theta: float, order: int, halvings: int) -> float:
    """2^(s+1) e^theta rho_(m-1)(theta): the bound on the relative error of Phi (module docstring).

    One order of margin (CROSS_BLOCK_MARGIN) over the balanced-norm bound
    2^(s+1) e^theta rho_m(theta), for the entries that couple two blocks of F.
    """
    remainder = truncation_bound(theta, order - CROSS_BLOCK_MARGIN)
    if math.isinf(remainder):  # theta beyond the series' reach: e^theta may not even be a float
        return math.inf
    return math.ldexp(math.exp(theta) * remainder, halvings + 1)


def taylor_plan(
    norm: float, T: float, order: int, tolerance: float | None = DEFAULT_TOLERANCE, unit_roundoff: float = DOUBLE_ROUNDOFF
) -> tuple[int, int]:
    """(s, m): the doublings and the order actually summed, for ||F||_D = ``norm`` and step ``T``.

    ``tolerance`` None, or not above the unit roundoff (where rounding,
    not truncation, limits the accuracy; single precision): the order is
    fixed at ``order`` and s keeps the remainder below the unit roundoff
    (:func:`doublings`).  Otherwise s is the smallest number of doublings
    for which order ``order`` meets :func:`step_error_bound` <= tolerance,
    and m the smallest order that meets it with that s.  ModelError beyond
    MAX_DOUBLINGS.
    """
    if tolerance is None or tolerance <= unit_roundoff:
        return doublings(norm, T, order, unit_roundoff), order
    target = tolerance
    for s in range(MAX_DOUBLINGS + 1):
        theta = norm * math.ldexp(T, -s)
        if step_error_bound(theta, order, s) <= target:
            break
    else:
        raise ModelError(
            f"discretize: e^(F T) is not representable: ||F||*T = {norm * T:.3g} needs more than "
            f"{MAX_DOUBLINGS} doublings of the Taylor series"
        )
    for m in range(1, order + 1):
        if step_error_bound(theta, m, s) <= target:
            return s, m
    return s, order


def rebalanced_norm(
    F: np.ndarray,
    scaling: tuple[int, ...],
    T: float,
    order: int,
    tolerance: float | None = DEFAULT_TOLERANCE,
    unit_roundoff: float = DOUBLE_ROUNDOFF,
) -> float:
    """||F||_D with D rebalanced at run time from ``scaling`` (:func:`step_plan`): the sweeps stop at a fixed point,
    after BALANCING_SWEEPS, or after the first whose norm needs no doubling at step ``T`` (no further sweep could take one away)."""

    def no_doubling(exponents: np.ndarray) -> bool:
        try:
            return taylor_plan(scaled_norm(F, exponents), T, order, tolerance, unit_roundoff)[0] == 0
        except ModelError:
            return False

    return scaled_norm(F, balancing_exponents(F, scaling, no_doubling))


def step_plan(
    F: np.ndarray,
    T: float,
    order: int,
    tolerance: float | None = DEFAULT_TOLERANCE,
    scaling: tuple[int, ...] | None = None,
    unit_roundoff: float = DOUBLE_ROUNDOFF,
) -> tuple[int, int]:
    """(s, m) at the actual operating point F: what the generated C and Python choose at run time.

    ``scaling`` None: F is balanced from D = I and :func:`taylor_plan` runs
    on that norm.  A nominal scaling (:func:`nominal_scaling`): the plan is
    first taken on ||F||_D with that fixed D (one pass over F's nonzeros, no
    sweeps); when it needs a doubling, F is rebalanced at run time, the
    sweeps starting from the nominal D (so that at the check operating point
    they stop after one), and the plan is retaken on the smaller of the two
    norms (each is a valid bound).  A D balanced at another operating point
    can be far from this one's: the 32-state model's check point has zero
    body rates, so its scale-factor states drive nothing there and keep
    d = 1, and at a manoeuvre the fixed D gives ||F||_D = 7.1 where F's own
    balancing gives 0.89 (3 doublings against none at T = 0.148 s).  The
    sweeps cost a few passes over F's nonzeros, a doubling a sparse matrix
    product or two, so they run only when a doubling is at stake, and stop
    after the first sweep whose norm needs none (fewer doublings there are
    not; at the manoeuvre the first of the eight sweeps already finds 0.89:
    bench/bench_cycle.py, 6,665 fewer instructions per cycle at 32 states and
    T = 0.148 s).
    """
    if scaling is None:
        return taylor_plan(balanced_norm(F), T, order, tolerance, unit_roundoff)
    norm = scaled_norm(F, scaling)
    try:
        s, m = taylor_plan(norm, T, order, tolerance, unit_roundoff)
    except ModelError:  # beyond MAX_DOUBLINGS in the fixed D: F's own balancing may still reach it
        s, m = MAX_DOUBLINGS + 1, order
    if s == 0:
        return s, m
    rebalanced = rebalanced_norm(F, scaling, T, order, tolerance, unit_roundoff)
    if rebalanced < norm or s > MAX_DOUBLINGS:
        return taylor_plan(min(rebalanced, norm), T, order, tolerance, unit_roundoff)
    return s, m


@functools.lru_cache(maxsize=None)
def single_step_thresholds(order: int, tolerance: float) -> tuple[float, ...]:
    """theta_m, m = 1..order: the largest double theta with step_error_bound(theta, m, 0) <= tolerance.

    The bound is a product and quotient of factors that do not decrease with
    theta, each rounded (rounding is monotone), so it does not decrease with
    theta either, and bound <= tolerance exactly when theta <= theta_m: the
    generated C's plan compares ||F||_D T with these (a double each, printed
    exactly) instead of summing the bound order by order whenever no doubling
    is needed (theta <= theta_order), the same s and m as :func:`taylor_plan`
    with no call of exp.  Found by bisection over the doubles' bit patterns.
    """
    out = []
    for m in range(1, order + 1):
        low, high = 0, int(np.float64(m + 1).view(np.int64))  # bit patterns of 0.0 and m + 1 (where the bound is huge)
        if not step_error_bound(0.0, m, 0) <= tolerance:
            out.append(-1.0)  # no step meets it (never for a tolerance above the unit roundoff)
            continue
        while high - low > 1:
            mid = (low + high) // 2
            if step_error_bound(float(np.int64(mid).view(np.float64)), m, 0) <= tolerance:
                low = mid
            else:
                high = mid
        out.append(float(np.int64(low).view(np.float64)))
    return tuple(out)


def _taylor_increment(F: np.ndarray, h: float, order: int) -> tuple[np.ndarray, np.ndarray]:
    """(E, S) over one step h: S = sum_(k=0..m) (F h)^k / (k+1)! by Horner's rule, E = Phi - I = F h S.

    R_m = I / (m+1)!, R_k = I / (k+1)! + (F h) R_(k+1), S = R_0: m products,
    the constants only on the diagonal (module docstring, "Order").  The
    generated C and Python do the same operations.
    """
    n = F.shape[0]
    Fh = F * h
    diagonal = np.diag_indices(n)
    series = np.eye(n) / math.factorial(order + 1)
    for k in range(order - 1, -1, -1):
        series = Fh @ series
        series[diagonal] += 1.0 / math.factorial(k + 1)
    return Fh @ series, series


def _taylor_terms(F: np.ndarray, h: float, order: int) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, S) over one step h, without doubling: Phi = I + E (:func:`_taylor_increment`)."""
    increment, series = _taylor_increment(F, h, order)
    return np.eye(F.shape[0]) + increment, series


def check_step(T: float) -> float:
    """T as a float, or ModelError (a ValueError) when it is not finite and positive."""
    T = float(T)
    if not math.isfinite(T):
        raise ModelError(f"discretize: step T is not finite ({T})")
    if not T > 0.0:
        raise ModelError(f"discretize: step T must be positive, not {T}")
    return T


def taylor_discretization_with_doublings(
    F: np.ndarray,
    G: np.ndarray,
    T: float,
    order: int = DEFAULT_TAYLOR_ORDER,
    tolerance: float | None = None,
    scaling: tuple[int, ...] | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Phi, Gamma and the number s of doublings used (module docstring).

    ``order`` is the highest order; ``tolerance`` None sums exactly that
    order (the paper's fixed order), a number lets :func:`taylor_plan`
    choose s and the order for that relative accuracy, as the generated code
    does by default (``CodegenOptions.taylor_tolerance``).  ``scaling``:
    the exponents of D for ||F||_D (:func:`nominal_scaling`, what the
    generated code bakes in), None to balance F itself.
    ModelError (a ValueError) for an order below 1, a non-finite or non-positive T, a
    non-finite F or G, or an e^(F T) that is not representable.
    """
    if order < 1:
        raise ModelError(f"Taylor order must be at least 1, got {order}")
    T = check_step(T)
    if not (np.all(np.isfinite(F)) and np.all(np.isfinite(G))):
        raise ModelError("discretize: F or G has a non-finite entry")
    s, order = step_plan(F, T, order, tolerance, scaling)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused just below, with a message
        increment, series = _taylor_increment(F, math.ldexp(T, -s), order)
        for _ in range(s):  # on E = Phi - I, so that the identity does not round the small part away
            series = series + 0.5 * (increment @ series)  # Psi(2h) / (2h) = (S + Phi S) / 2
            increment = 2.0 * increment + increment @ increment  # Phi(2h) - I = (I + E)^2 - I
        phi = np.eye(F.shape[0]) + increment
    if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(series))):
        raise ModelError(f"discretize: e^(F T) overflows at T = {T!r} (is the operating point singular?)")
    return phi, T * series @ G, s


def taylor_discretization(
    F: np.ndarray,
    G: np.ndarray,
    T: float,
    order: int = DEFAULT_TAYLOR_ORDER,
    tolerance: float | None = None,
    scaling: tuple[int, ...] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Phi and Gamma by the series of eqs. (10) and (11), with scaling and squaring.

    Accurate for any finite T (module docstring); ``tolerance``, ``scaling`` and
    ModelError as :func:`taylor_discretization_with_doublings`.
    """
    phi, gamma, _ = taylor_discretization_with_doublings(F, G, T, order, tolerance, scaling)
    return phi, gamma


def taylor_process_noise(gamma: np.ndarray, Q: np.ndarray, T: float) -> np.ndarray:
    """Gamma (Q/T) Gamma^T: the discrete process noise of eq. (9)."""
    qd = gamma @ (Q / T) @ gamma.T
    return 0.5 * (qd + qd.T)


def van_loan_block(F: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Van Loan's (1978) M = [[-F, W], [0, F^T]] (2N x 2N) for W = G Q G^T, the step not applied."""
    n = F.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = -F
    block[:n, n:] = W
    block[n:, n:] = F.T
    return block


def van_loan_discretization(F: np.ndarray, G: np.ndarray, Q: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact Phi = e^{F T} and Q_d by Van Loan's block exponential (1978), over a step short enough to be exact.

    Van Loan's Q_d = Phi (e^{M})_12 multiplies e^{F T} by a block of about
    e^{-F T}: for a decaying state (a Markov process of correlation time
    tau) the two are e^{-T/tau} and e^{T/tau}, so at T >> tau the product
    cancels catastrophically (at one day and tau = 1 h, 3e8 where the
    variance is 259).  So the block exponential is taken over
    h = T / 2^s with ||F||_1 h <= 1, where the cancellation costs at most a
    few roundoffs, and the step is doubled s times by the exact identities
    Phi(2h) = Phi(h)^2 and Q_d(2h) = Q_d(h) + Phi(h) Q_d(h) Phi(h)^T.
    """
    from scipy.linalg import expm  # here: scipy.linalg (0.15 s to import) is needed by no other function

    n = F.shape[0]
    norm = float(np.abs(F).sum(axis=0).max()) if n else 0.0
    halvings = max(0, math.ceil(math.log2(norm * T))) if norm * T > 1.0 else 0
    h = math.ldexp(T, -halvings)
    e = expm(van_loan_block(F, G @ Q @ G.T) * h)
    phi = e[n:, n:].T
    qd = phi @ e[:n, n:]
    qd = 0.5 * (qd + qd.T)
    for _ in range(halvings):
        qd = qd + phi @ qd @ phi.T
        qd = 0.5 * (qd + qd.T)
        phi = phi @ phi
    return phi, qd
