"""Discretization is accurate for any finite T, in the reference, the generated Python and the generated C.

The paper's 9th-order Taylor series alone is 64 % off at T = 3600 s for the
paper's model; with scaling and squaring (modelgen.derivation.discretization) Phi and
Gamma match scipy's expm (Phi = e^{F T}; Gamma = int_0^T e^{F s} ds G from
the block exponential of [[F, G], [0, 0]] T) from T = 1 ms to one day, on the
paper's model and on the 15-state INS/GPS model.  Stated bounds, relative to
the largest entry of the exact matrix: 1e-13 up to T = 600 s, 1e-10 up to a
day (measured: below 6e-15 and 4e-11).
"""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.linalg import expm

from modelgen.derivation import reference
from modelgen.derivation.symbolic import derive
from modelgen.derivation.discretization import (
    _taylor_terms,
    balanced_norm,
    series_range,
    sweep_exponent,
    taylor_discretization,
    taylor_discretization_with_doublings,
    taylor_process_noise,
    van_loan_discretization,
)
from modelgen.model.loading import load_model

STEPS = [1e-3, 1.0, 60.0, 600.0, 3600.0, 1e4, 86400.0]
MODELS = Path(__file__).resolve().parents[2] / "modelgen" / "models"


def bound(T: float, tolerance: float | None = None) -> float:
    """The stated relative bound at step T: with the accuracy rule, never below its tolerance."""
    fixed = 1e-13 if T <= 600.0 else 1e-10
    return fixed if tolerance is None else max(fixed, tolerance)


#: Above this step the oracle is mpmath's expm at EXACT_DIGITS: scipy's (1.17) is not accurate enough there to judge
#: the 1e-10 bound (the 32-state model at 3600 s: scipy 1.6e-10 from a 40-digit expm, modelgen's series 6.8e-16).
EXACT_MPMATH_ABOVE_S = 600.0
EXACT_DIGITS = 30


def exact(F: np.ndarray, G: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """e^{F T} and int_0^T e^{F s} ds G (the block exponential of [[F, G], [0, 0]] T), far more accurate than
    the bound they judge: scipy's expm up to EXACT_MPMATH_ABOVE_S, mpmath's at EXACT_DIGITS digits above."""
    n, nw = F.shape[0], G.shape[1]
    block = np.zeros((n + nw, n + nw))
    block[:n, :n] = F
    block[:n, n:] = G
    if T <= EXACT_MPMATH_ABOVE_S:
        return expm(F * T), expm(block * T)[:n, n:]
    import mpmath

    with mpmath.workdps(EXACT_DIGITS):
        whole = np.array(mpmath.expm(mpmath.matrix(block.tolist()) * T).tolist(), dtype=float)
    return whole[:n, :n], whole[:n, n:]


def relative_error(value: np.ndarray, truth: np.ndarray) -> float:
    return float(np.max(np.abs(value - truth)) / np.max(np.abs(truth)))


@pytest.fixture(scope="module")
def level_matrices(paper_derived, level_flight):
    return paper_derived.numeric(level_flight)


@pytest.fixture(scope="module")
def ins_gps_matrices():
    """The 15-state INS/GPS model at its declared check operating point (a rotation, WGS-84 radii)."""
    derived = derive(load_model("ins_gps15"))
    values = yaml.safe_load((MODELS / "ins_gps15.yaml").read_text())["check"]["parameters"]
    return derived.numeric(values)


@pytest.fixture(params=["paper", "ins_gps15"])
def matrices(request, level_matrices, ins_gps_matrices):
    return level_matrices if request.param == "paper" else ins_gps_matrices


@pytest.mark.parametrize("T", STEPS)
def test_reference_transition_and_noise_input_match_expm(matrices, T):
    phi, gamma = taylor_discretization(matrices["F"], matrices["G"], T, 9)
    phi_exact, gamma_exact = exact(matrices["F"], matrices["G"], T)
    assert relative_error(phi, phi_exact) < bound(T)
    assert relative_error(gamma, gamma_exact) < bound(T)


def test_the_series_alone_was_far_off_at_an_hour(level_matrices):
    """What scaling and squaring fixes: the plain series of order 9 (Phi = I + F T S, to order 10) is 16 % off at T = 3600 s."""
    phi, _ = _taylor_terms(level_matrices["F"], 3600.0, 9)
    assert relative_error(phi, exact(level_matrices["F"], level_matrices["G"], 3600.0)[0]) > 0.1
    _, _, s = taylor_discretization_with_doublings(level_matrices["F"], level_matrices["G"], 3600.0, 9)
    assert s > 0


def test_doublings_grow_with_the_step_and_vanish_for_short_steps(level_matrices):
    s = [taylor_discretization_with_doublings(level_matrices["F"], level_matrices["G"], T, 9)[2] for T in STEPS]
    assert s == sorted(s) and s[0] == 0 and s[1] == 0


def test_balanced_norm_hardly_depends_on_the_units_of_the_states(level_matrices):
    """g = 9.8 m/s^2 makes the plain infinity norm of F about 11; balanced it is near the Schuler rate (1.2e-3)."""
    F = level_matrices["F"]
    assert np.max(np.sum(np.abs(F), axis=1)) > 10.0
    assert 1e-3 < balanced_norm(F) < 5e-3
    rng = np.random.default_rng(0)
    for _ in range(5):  # the same model with each state in other units (powers of two up to 2^10)
        units = np.diag(2.0 ** rng.integers(-10, 10, F.shape[0]))
        assert balanced_norm(np.linalg.inv(units) @ F @ units) < 4 * balanced_norm(F)


def test_series_range_keeps_the_remainder_below_the_unit_roundoff():
    theta = series_range(9)
    remainder = theta**10 / math.factorial(10) * 11 / (11 - theta)
    assert 0.1 < theta < 0.13 and remainder <= 2.0**-53
    assert series_range(9, 2.0**-24) > theta


def test_sweep_exponent_is_a_bounded_floor_of_half_the_binary_exponent():
    assert sweep_exponent(1.0, 1.0) == 0  # equal exponents
    assert sweep_exponent(16.0, 1.0) == 2
    assert sweep_exponent(1.0, 16.0) == -2  # exponents 1 and 5: floor(-4/2) = -2
    assert sweep_exponent(1e300, 1e-300) == 8 and sweep_exponent(1e-300, 1e300) == -8
    assert sweep_exponent(0.0, 1.0) == -8  # drives others, driven by none: shrink its column
    assert sweep_exponent(1.0, 0.0) == 8
    assert sweep_exponent(0.0, 0.0) == 0


@pytest.mark.parametrize("T", [0.0, -1.0, math.nan, math.inf])
def test_a_step_that_is_not_finite_and_positive_is_refused(level_matrices, T):
    with pytest.raises(ValueError, match="T"):
        taylor_discretization(level_matrices["F"], level_matrices["G"], T, 9)


def test_a_transition_that_is_not_representable_is_refused(level_matrices):
    with pytest.raises(ValueError, match="not representable"):
        taylor_discretization(level_matrices["F"], level_matrices["G"], 1e300, 9)


def test_non_finite_F_is_refused(level_matrices):
    F = level_matrices["F"].copy()
    F[0, 1] = math.nan
    with pytest.raises(ValueError, match="non-finite"):
        taylor_discretization(F, level_matrices["G"], 60.0, 9)


def test_gamma_process_noise_agrees_with_van_loan_over_four_hours(level_matrices):
    """Gamma (Q/T) Gamma^T is a first-order-hold approximation of the exact Q_d.

    Entry by entry they differ (the attitude terms by about 25% for one step,
    T^3/4 against T^3/3), but both drive the same covariance: after 4 hours of
    pure propagation the standard deviations agree to better than 1%.
    """
    m = level_matrices
    T = 60.0
    phi, gamma = taylor_discretization(m["F"], m["G"], T, 9)
    qd_taylor = taylor_process_noise(gamma, m["Q"], T)
    phi_exact, qd_exact = van_loan_discretization(m["F"], m["G"], m["Q"], T)
    P_taylor = P_exact = np.zeros_like(phi)
    for _ in range(240):
        P_taylor = reference.predict_covariance(P_taylor, phi, qd_taylor)
        P_exact = reference.predict_covariance(P_exact, phi_exact, qd_exact)
    sd_t, sd_e = np.sqrt(np.diag(P_taylor)), np.sqrt(np.diag(P_exact))
    driven = sd_e > 0
    assert np.max(np.abs(sd_t[driven] / sd_e[driven] - 1)) < 0.01


def test_order_below_one_is_refused(level_matrices):
    with pytest.raises(ValueError):
        taylor_discretization(level_matrices["F"], level_matrices["G"], 60.0, 0)


def test_vectorized_sweep_exponents_equal_the_scalar_rule():
    from modelgen.derivation.discretization import sweep_exponents

    rng = np.random.default_rng(2)
    row = np.where(rng.random(200) < 0.2, 0.0, 10.0 ** rng.uniform(-30, 30, 200))
    column = np.where(rng.random(200) < 0.2, 0.0, 10.0 ** rng.uniform(-30, 30, 200))
    assert list(sweep_exponents(row, column)) == [sweep_exponent(r, c) for r, c in zip(row, column)]


# -- the accuracy rule (taylor_plan) --------------------------------------------------------


@pytest.mark.parametrize("theta", [1e-6, 1e-3, 0.05, 0.3, 1.0, 3.0])
@pytest.mark.parametrize("order", [1, 2, 5, 9])
def test_truncation_bound_bounds_the_remainder_of_the_exponential_series(theta, order):
    """rho_m(theta) >= e^theta - sum_{k<=m} theta^k / k!: the scalar series is the worst case of the norm bound."""
    from modelgen.derivation.discretization import truncation_bound

    remainder = math.fsum(theta**k / math.factorial(k) for k in range(order + 1, order + 60))
    assert remainder <= truncation_bound(theta, order)
    if theta <= (order + 2) / 2:  # and tight where the rule uses it (infinite from theta = m + 2 on)
        assert truncation_bound(theta, order) <= 2 * remainder


def test_accuracy_rule_sums_fewer_orders_for_short_steps_and_none_past_the_highest(level_matrices):
    """Paper's model: order 5 at T = 1 s, the full order 9 without doubling at T = 60 s, doublings beyond."""
    from modelgen.derivation.discretization import taylor_plan

    norm = balanced_norm(level_matrices["F"])
    plans = {T: taylor_plan(norm, T, 9) for T in STEPS}
    assert plans[1.0] == (0, 5) and plans[60.0] == (0, 9)
    assert plans[1e-3][1] < plans[1.0][1] and plans[600.0][0] > 0
    assert all(order <= 9 for _, order in plans.values())


def test_a_tolerance_of_none_or_within_rounding_is_the_fixed_order(level_matrices):
    from modelgen.derivation.discretization import DOUBLE_ROUNDOFF, FLOAT_ROUNDOFF, doublings, taylor_plan

    norm = balanced_norm(level_matrices["F"])
    for T in STEPS:
        fixed = (doublings(norm, T, 9), 9)
        assert taylor_plan(norm, T, 9, None) == fixed
        assert taylor_plan(norm, T, 9, DOUBLE_ROUNDOFF) == fixed
        assert taylor_plan(norm, T, 9, 1e-8, FLOAT_ROUNDOFF) == (doublings(norm, T, 9, FLOAT_ROUNDOFF), 9)


BUILTIN = ["ned_doppler18", "ned_inertial16", "enu_doppler18", "ins_gps15", "gps_pseudorange11", "ned_doppler32_augmented"]


@pytest.mark.parametrize("name", BUILTIN)
def test_accuracy_rule_meets_its_tolerance_against_expm_on_every_builtin_model(name):
    """Phi and Gamma within 1e-12 of the largest exact entry from 10 ms to 10 minutes, with the order the rule picks."""
    from modelgen.derivation.discretization import DEFAULT_TOLERANCE
    from modelgen.jobs import check_scenario

    derived = derive(load_model(name))
    m = derived.numeric(check_scenario(derived).parameters)
    for T in (0.01, 0.1, 1.0, 10.0, 60.0, 600.0):
        phi, gamma = taylor_discretization(m["F"], m["G"], T, 9, DEFAULT_TOLERANCE)
        phi_exact, gamma_exact = exact(m["F"], m["G"], T)
        assert relative_error(phi, phi_exact) < DEFAULT_TOLERANCE, T
        assert relative_error(gamma, gamma_exact) < DEFAULT_TOLERANCE, T


def test_error_bound_is_infinite_not_an_overflow_far_beyond_the_series_reach():
    import math

    from modelgen.derivation.discretization import step_error_bound

    assert step_error_bound(1.0e4, 9, 0) == math.inf  # e^10000 is not a float; the bound says "too far", no exception
    assert math.isfinite(step_error_bound(0.5, 9, 0))


def test_van_loan_reference_matches_the_closed_form_markov_variance_far_beyond_its_correlation_time():
    """Q_d of a first-order Markov state is q tau / 2 (1 - e^(-2T/tau)), through the halved-and-doubled step up to 720 tau."""
    tau, q = 3600.0, 2.5e-3
    F, G, Q = np.array([[-1.0 / tau]]), np.array([[1.0]]), np.array([[q]])
    for T in (1.0, 60.0, 86400.0, 30 * 86400.0):
        phi, qd = van_loan_discretization(F, G, Q, T)
        assert phi[0, 0] == pytest.approx(math.exp(-T / tau), rel=1e-13, abs=1e-300)
        assert qd[0, 0] == pytest.approx(q * tau / 2.0 * -math.expm1(-2.0 * T / tau), rel=1e-12)


def test_van_loan_reference_over_a_day_equals_a_day_of_one_second_steps(level_matrices):
    """The doubled Van Loan step agrees with the exact recursion Q_d(t + 1) = Phi Q_d(t) Phi^T + Q_d(1) over 86,400 s.

    One block exponential over the day cancels e^(F T) against about e^(-F T): it was 6.8e5 times Q_d's
    largest entry off; the doubled step is 2.4e-11 off.
    """
    m = level_matrices
    phi_1, qd_1 = van_loan_discretization(m["F"], m["G"], m["Q"], 1.0)
    phi_day, qd_day = van_loan_discretization(m["F"], m["G"], m["Q"], 86400.0)
    phi, qd = np.eye(len(phi_1)), np.zeros_like(qd_1)
    for _ in range(86400):
        qd = phi_1 @ qd @ phi_1.T + qd_1
        phi = phi_1 @ phi
    assert np.abs(phi_day - phi).max() <= 1e-8 * np.abs(phi).max()
    assert np.abs(qd_day - qd).max() <= 1e-8 * np.abs(qd).max()
