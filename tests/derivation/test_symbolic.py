"""F, G, H, Q, R are derived from the equations and mean what the physics says."""

import numpy as np
import pytest
import sympy as sp

from modelgen.derivation.symbolic import derive, parameter_vector
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Measurement, Noise, Parameter, State


def test_paper_model_has_the_papers_dimensions(paper_derived):
    assert paper_derived.F.shape == (18, 18)
    assert paper_derived.G.shape == (18, 6)
    assert paper_derived.H.shape == (2, 18)


def test_latitude_error_rate_is_north_velocity_error_over_radius(paper_derived, level_flight):
    m = paper_derived.model
    F = paper_derived.numeric(level_flight)["F"]
    assert F[m.state_index("dphi"), m.state_index("dV_n")] == pytest.approx(1 / 6378137.0)


def test_level_flight_gives_schuler_oscillation(paper_derived, level_flight):
    """The tilt/velocity loop beta <-> dV_n oscillates at sqrt(g/R) (Schuler, 84 min)."""
    m = paper_derived.model
    F = paper_derived.numeric(level_flight)["F"]
    b, v = m.state_index("beta"), m.state_index("dV_n")
    loop_gain = -F[b, v] * F[v, b]  # d2(beta)/dt2 = -loop_gain * beta
    assert loop_gain > 0
    assert np.sqrt(loop_gain) == pytest.approx(np.sqrt(9.78 / 6378137.0))
    period_min = 2 * np.pi / np.sqrt(loop_gain) / 60
    assert 84.0 < period_min < 85.0


def test_gyro_drift_enters_through_attitude_matrix(paper_derived, level_flight):
    m = paper_derived.model
    F = paper_derived.numeric(level_flight)["F"]
    # body x points east in level flight: x drift drives the east attitude error beta
    assert F[m.state_index("beta"), m.state_index("eps_c_x")] == 1.0
    assert F[m.state_index("alpha"), m.state_index("eps_r_y")] == -1.0


def test_noise_input_and_measurement_matrices(paper_derived):
    G = np.array(paper_derived.G, dtype=float)
    assert G.sum() == 6 and all(G[10 + k, k] == 1 for k in range(6))
    H = np.array(paper_derived.H, dtype=float)
    assert H[0, 3] == 1 and H[0, 16] == -1 and H[1, 4] == 1 and H[1, 17] == -1
    assert np.count_nonzero(H) == 4


def test_markov_noise_psd_is_two_mu_sigma_squared(paper_derived):
    mu, sigma = sp.Symbol("mu_eps_x", real=True), sp.Symbol("sigma_eps_x", real=True)
    assert sp.simplify(paper_derived.Q[0, 0] - 2 * mu * sigma**2) == 0


@pytest.mark.parametrize(
    "dynamics, measurement",
    [
        ({"a": "a*b", "b": "k*b + w"}, "a"),  # product of two states
        ({"a": "a*w", "b": "k*b + w"}, "a"),  # state times noise
        ({"a": "sin(b)", "b": "k*b + w"}, "a"),
        ({"a": "k*a", "b": "k*b + w"}, "b**2 + b"),  # nonlinear measurement, the same rule
        ({"a": "k*a", "b": "k*b + w"}, "sqrt(a)"),
        ({"a": "k*a + 1", "b": "k*b + w"}, "a"),  # a constant forcing: no place in F x + G w
        ({"a": "k*a", "b": "k*b + w"}, "a + k"),  # a constant offset: no place in H x + v
    ],
)
def test_nonlinear_or_constant_term_is_refused_when_the_model_is_built(dynamics, measurement):
    with pytest.raises(ModelError, match="not linear|depends on none of"):
        ErrorModel.build(
            "toy",
            states=[State("a"), State("b")],
            noises=[Noise("w")],
            parameters=[Parameter("k")],
            dynamics=dynamics,
            measurements=[Measurement("z", expression=measurement)],
        )


def test_linear_equations_with_nonlinear_parameters_are_accepted():
    model = ErrorModel.build(
        "toy",
        states=[State("a"), State("b")],
        noises=[Noise("w")],
        parameters=[Parameter("k")],
        dynamics={"a": "sin(k)**2*a + b/cos(k)", "b": "-k*b + sqrt(k)*w"},
        measurements=[Measurement("z", expression="a*exp(k) - b")],
    )
    assert derive(model).nonlinear == ()


def test_missing_and_unknown_parameters_are_refused(paper_model):
    with pytest.raises(ModelError, match="no value for parameter 'latitude'"):
        parameter_vector(paper_model, {})
    with pytest.raises(ModelError, match="unknown parameter"):
        parameter_vector(paper_model, {"latitud": 0.5})
    with pytest.raises(ModelError, match="not finite"):
        parameter_vector(paper_model, {p.name: float("nan") for p in paper_model.parameters})
