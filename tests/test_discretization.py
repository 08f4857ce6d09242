"""The paper's Taylor discretization against the exact exponential (Van Loan)."""

import numpy as np
import pytest

from modelgen import reference
from modelgen.discretization import taylor_discretization, taylor_process_noise, van_loan_discretization


@pytest.fixture(scope="module")
def level_matrices(paper_derived, level_flight):
    return paper_derived.numeric(level_flight)


def test_ninth_order_taylor_transition_matrix_matches_exponential_at_60s(level_matrices):
    m = level_matrices
    phi, _ = taylor_discretization(m["F"], m["G"], 60.0, 9)
    exact, _ = van_loan_discretization(m["F"], m["G"], m["Q"], 60.0)
    assert np.max(np.abs(phi - exact)) < 1e-9


def test_taylor_error_shrinks_with_order(level_matrices):
    m = level_matrices
    exact, _ = van_loan_discretization(m["F"], m["G"], m["Q"], 60.0)
    errors = [np.max(np.abs(taylor_discretization(m["F"], m["G"], 60.0, k)[0] - exact)) for k in (1, 2, 3, 5)]
    assert errors == sorted(errors, reverse=True)
    assert errors[0] > 1e3 * errors[-1]


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
