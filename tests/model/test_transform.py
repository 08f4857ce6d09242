"""Model transformations: keep_states, markov_to_white, augment (modelgen.model.transform)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from modelgen.derivation.symbolic import derive
from modelgen.derivation.discretization import van_loan_discretization
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Measurement, Noise, Parameter, State
from modelgen.model.transform import augment, keep_states, markov_to_white

DOPPLER = ("doppler_velocity_bias_north", "doppler_velocity_bias_east")
ACCELS = ("accel_markov_bias_x", "accel_markov_bias_y", "accel_markov_bias_z")


def _sub_block(derived, kept_names, matrix="F"):
    idx = [derived.model.state_names.index(n) for n in kept_names]
    m = getattr(derived, matrix)
    return m.extract(idx, idx) if matrix == "F" else m.extract(idx, list(range(m.shape[1])))


def _same(a: sp.Matrix, b: sp.Matrix) -> bool:
    return a.shape == b.shape and all(sp.simplify(x - y) == 0 for x, y in zip(a, b))


# -- keep_states ---------------------------------------------------------------
def test_pure_inertial_form_has_16_states_no_measurements_and_the_sub_block_of_F(paper_model, paper_derived):
    kept = [s for s in paper_model.state_names if s not in DOPPLER]
    pure = keep_states(paper_model, kept, name="pure_inertial16")
    d = derive(pure)
    assert pure.name == "pure_inertial16"
    assert len(pure.states) == 16 and pure.measurements == ()
    assert d.H.shape == (0, 16)
    assert _same(d.F, _sub_block(paper_derived, kept))
    assert _same(d.G, _sub_block(paper_derived, kept, "G"))  # all six noises still drive it
    assert _same(d.Q, paper_derived.Q)
    assert any("dropped states doppler_velocity_bias_north" in n for n in pure.notes)
    assert "doppler_noise_sigma_north" not in pure.parameter_names  # only the dropped measurements used it


def test_dropping_a_middle_state_keeps_order_and_gives_the_sub_block(paper_model, paper_derived):
    kept = [s for s in paper_model.state_names if s != "gyro_constant_drift_z"]
    reduced = keep_states(paper_model, kept)
    d = derive(reduced)
    assert reduced.state_names == kept
    assert _same(d.F, _sub_block(paper_derived, kept))
    assert _same(d.H, paper_derived.H.extract([0, 1], [paper_model.state_names.index(n) for n in kept]))


def test_dropping_accelerometer_states_drops_their_noises_and_parameters(paper_model):
    kept = [s for s in paper_model.state_names if s not in ACCELS]
    reduced = keep_states(paper_model, kept)
    assert len(reduced.states) == 15
    assert not any(n.startswith("accel") for n in reduced.noise_names)
    assert not any(p.startswith("accel") for p in reduced.parameter_names)
    assert reduced.measurement_names == paper_model.measurement_names


def test_explicitly_kept_measurement_loses_the_dropped_state_term(paper_model):
    kept = [s for s in paper_model.state_names if s not in DOPPLER]
    reduced = keep_states(paper_model, kept, measurements=["Z_n", "velocity_difference_east"])
    d = derive(reduced)
    assert d.H.shape == (2, 16)
    assert d.H[0, reduced.state_index("dV_n")] == 1 and d.H[1, reduced.state_index("dV_e")] == 1
    assert sum(1 for x in d.H if x != 0) == 2


def test_explicitly_kept_measurement_whose_row_vanishes_is_refused(paper_model):
    kept = [s for s in paper_model.state_names if s not in ("dV_n", "velocity_error_north", "doppler_velocity_bias_north")]
    with pytest.raises(ModelError, match="velocity_difference_north.*no kept state"):
        keep_states(paper_model, kept, measurements=["Z_n"])


def test_keep_states_unknown_state_is_named(paper_model):
    with pytest.raises(ModelError, match="no state named 'attitude_error_up'"):
        keep_states(paper_model, ["alpha", "attitude_error_up"])


def test_keep_states_unknown_measurement_is_named(paper_model):
    with pytest.raises(ModelError, match="no measurement named 'Z_d'"):
        keep_states(paper_model, paper_model.state_names, measurements=["Z_d"])


def test_keep_states_accepts_symbols_and_refuses_a_state_named_twice(paper_model):
    assert keep_states(paper_model, ["alpha", "beta", "gamma"]).state_names == [
        "attitude_error_north",
        "attitude_error_east",
        "heading_error",
    ]
    with pytest.raises(ModelError, match="named twice"):
        keep_states(paper_model, ["alpha", "attitude_error_north"])


# -- markov_to_white -----------------------------------------------------------
def test_markov_to_white_removes_the_state_and_feeds_white_noise_where_it_entered(paper_model, paper_derived):
    white = markov_to_white(paper_model, ["nabla_x"], name="no_accel_x")
    d = derive(white)
    assert len(white.states) == 17
    kept = [s for s in paper_model.state_names if s != "accel_markov_bias_x"]
    assert _same(d.F, _sub_block(paper_derived, kept))
    # the new noise enters exactly where nabla_x did: its G column = the old F column of nabla_x
    j_old = paper_model.state_index("nabla_x")
    old_column = paper_derived.F.extract([paper_model.state_names.index(n) for n in kept], [j_old])
    col = d.G[:, white.noise_names.index("accel_markov_bias_x_white")]
    assert _same(col, old_column)
    assert "accel_markov_noise_x" not in white.noise_names  # the driving noise went with the state
    mu, sigma = sp.symbols("mu_nabla_x sigma_nabla_x", real=True)
    assert sp.simplify(white.noise_psd["accel_markov_bias_x_white"] - 2 * sigma**2 / mu) == 0


def test_white_noise_has_the_markov_process_low_frequency_strength():
    """Var(int_0^t x) -> PSD_white * t for t >> 1/mu: the equivalence markov_to_white promises."""
    model = ErrorModel.build(
        name="markov_integrator",
        states=[State("integral", symbol="y"), State("markov", symbol="x")],
        noises=[Noise("drive", symbol="w", psd="2*mu*sigma**2")],
        parameters=[Parameter("rate", symbol="mu", value=1 / 1800), Parameter("rms", symbol="sigma", value=1e-3)],
        dynamics={"y": "x", "x": "-mu*x + w"},
    )
    white = markov_to_white(model, ["x"])
    assert white.state_names == ["integral"]
    for m in (model, white):
        assert m.parameter_names == ["rate", "rms"]
    markov = derive(model).numeric({})
    equivalent = derive(white).numeric({})
    step = 600.0
    phi, qd = van_loan_discretization(markov["F"], markov["G"], markov["Q"], step)
    P = np.zeros((2, 2))
    history = [P[0, 0]]
    for _ in range(120):  # 40 correlation times
        P = phi @ P @ phi.T + qd
        history.append(P[0, 0])
    psd_white = equivalent["G"][0, 0] ** 2 * equivalent["Q"][0, 0]
    assert psd_white == pytest.approx(2 * 1e-3**2 * 1800, rel=1e-12)  # 2 sigma^2 / mu
    # growth rate of Var(int x) between 20 and 40 correlation times = the white noise's PSD
    slope = (history[120] - history[60]) / (60 * step)
    assert slope == pytest.approx(psd_white, rel=1e-6)
    # ... while over one correlation time the white noise overstates it (why the choice matters)
    assert history[3] < 0.5 * psd_white * 3 * step


def test_markov_to_white_driving_strength_keeps_the_driving_noise_psd(paper_model):
    white = markov_to_white(paper_model, ["eps_r_z"], strength="driving_noise")
    mu, sigma = sp.symbols("mu_eps_z sigma_eps_z", real=True)
    assert sp.simplify(white.noise_psd["gyro_markov_drift_z_white"] - 2 * mu * sigma**2) == 0
    with pytest.raises(ModelError, match="strength 'medium'"):
        markov_to_white(paper_model, ["eps_r_z"], strength="medium")


def test_markov_to_white_refuses_a_random_constant(paper_model):
    with pytest.raises(ModelError, match="gyro_constant_drift_z.*random constant"):
        markov_to_white(paper_model, ["eps_c_z"])


def test_markov_to_white_refuses_a_state_that_is_not_markov(paper_model):
    with pytest.raises(ModelError, match=r"attitude_error_north.*not of the form -mu\*x \+ b\*w"):
        markov_to_white(paper_model, ["alpha"])


def test_markov_to_white_refuses_a_state_in_a_measurement():
    m = ErrorModel.build(
        name="measured_markov",
        states=[State("bias", symbol="b")],
        noises=[Noise("drive", symbol="w", psd="2*mu")],
        parameters=[Parameter("rate", symbol="mu", value=1.0)],
        dynamics={"b": "-mu*b + w"},
        measurements=[Measurement("z", expression="b")],
    )
    with pytest.raises(ModelError, match="enters measurement 'z'"):
        markov_to_white(m, ["b"])


def test_markov_to_white_unknown_state_is_named(paper_model):
    with pytest.raises(ModelError, match="no state named 'nabla_w'"):
        markov_to_white(paper_model, ["nabla_w"])


# -- augment -------------------------------------------------------------------
def _augmented(paper_model):
    return augment(
        paper_model,
        new_states=[
            State("gyro_scale_factor_x", symbol="k_gx", description="x gyro scale-factor error"),
            State("gyro_scale_factor_y", symbol="k_gy"),
            State("gyro_scale_factor_z", symbol="k_gz"),
            State("doppler_scale_factor", symbol="k_d", description="Doppler scale-factor error"),
            State("doppler_boresight_error", symbol="psi_d", unit="rad", description="Doppler azimuth misalignment"),
        ],
        equations={
            "k_gx": "0",
            "k_gy": "0",
            "k_gz": "0",
            "k_d": "0",
            "psi_d": "0",
            # gyro scale factor: drift = k * body rate, through C_b^n as in eq. (1)
            "alpha": "c11*omega_bx*k_gx + c12*omega_by*k_gy + c13*omega_bz*k_gz",
            "beta": "c21*omega_bx*k_gx + c22*omega_by*k_gy + c23*omega_bz*k_gz",
            "gamma": "c31*omega_bx*k_gx + c32*omega_by*k_gy + c33*omega_bz*k_gz",
        },
        parameters=[Parameter(f"body_rate_{a}", symbol=f"omega_b{a}", unit="rad/s") for a in "xyz"],
        # Doppler reads V (1 + k_d), rotated by psi_d: Z = V_ins - V_doppler
        measurement_terms={"Z_n": "-V_n*k_d + V_e*psi_d", "velocity_difference_east": "-V_e*k_d - V_n*psi_d"},
        name="ned_doppler23",
    )


def test_augment_adds_states_and_the_expected_F_and_H_entries(paper_model, paper_derived):
    big = _augmented(paper_model)
    d = derive(big)
    assert len(big.states) == 23 and big.name == "ned_doppler23"
    assert _same(d.F[:18, :18], paper_derived.F)
    c11, c23, c33, wx, wy, wz = sp.symbols("c11 c23 c33 omega_bx omega_by omega_bz", real=True)
    i = big.state_index
    assert sp.simplify(d.F[i("alpha"), i("k_gx")] - c11 * wx) == 0
    assert sp.simplify(d.F[i("beta"), i("k_gz")] - c23 * wz) == 0
    assert sp.simplify(d.F[i("gamma"), i("k_gz")] - c33 * wz) == 0
    assert all(x == 0 for x in d.F[18:, :])  # random constants
    V_n, V_e = sp.symbols("V_n V_e", real=True)
    assert sp.simplify(d.H[0, i("k_d")] + V_n) == 0 and sp.simplify(d.H[0, i("psi_d")] - V_e) == 0
    assert sp.simplify(d.H[1, i("k_d")] + V_e) == 0 and sp.simplify(d.H[1, i("psi_d")] + V_n) == 0
    assert _same(d.H[:, :18], paper_derived.H)


def test_augmented_model_goes_through_numeric_evaluation(paper_model, level_flight):
    d = derive(_augmented(paper_model))
    m = d.numeric({**level_flight, "body_rate_x": 0.0, "body_rate_y": 0.0, "body_rate_z": 1e-3})
    assert m["F"].shape == (23, 23) and m["H"].shape == (2, 23)
    assert m["F"][2, 20] == pytest.approx(1e-3)  # gamma <- k_gz * c33 * omega_bz


def test_augment_equation_for_unknown_state_is_named(paper_model):
    with pytest.raises(ModelError, match="'delta'.*neither an existing nor a new state"):
        augment(paper_model, [State("new_bias", symbol="b_new")], {"b_new": "0", "delta": "b_new"})


def test_augment_new_state_without_equation_is_named(paper_model):
    with pytest.raises(ModelError, match="no equation for new state.*new_bias"):
        augment(paper_model, [State("new_bias", symbol="b_new")], {"alpha": "b_new"})


def test_augment_unknown_symbol_in_a_term_is_named(paper_model):
    with pytest.raises(ModelError, match="unknown symbol.*omega_q"):
        augment(paper_model, [State("new_bias", symbol="b_new")], {"b_new": "0", "alpha": "omega_q*b_new"})


def test_augment_term_for_unknown_measurement_is_named(paper_model):
    with pytest.raises(ModelError, match="measurement 'Z_u'"):
        augment(paper_model, [State("new_bias", symbol="b_new")], {"b_new": "0"}, measurement_terms={"Z_u": "b_new"})


def test_pure_inertial_form_equals_the_library_16_state_model(paper_model):
    from modelgen.model.loading import builtin_models, load_model

    if "ned_inertial16" not in builtin_models():
        pytest.skip("no ned_inertial16 model file in the library")
    library = derive(load_model("ned_inertial16"))
    made = derive(keep_states(paper_model, [s for s in paper_model.state_names if s not in DOPPLER]))
    assert made.model.state_names == library.model.state_names
    assert set(made.model.parameter_names) == set(library.model.parameter_names)
    for matrix in ("F", "G", "Q"):
        assert _same(getattr(made, matrix), getattr(library, matrix)), matrix
