"""Model files that transform another model go through the pipeline in one command."""

import pytest
import sympy as sp

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.loading import load_model, load_model_text
from modelgen.model.transform import keep_states, markov_to_white


def test_reduced_file_equals_the_transformations_applied_in_code():
    from_file = derive(load_model("ned_doppler13_reduced"))
    full = load_model("ned_doppler18")
    kept = keep_states(full, [s for s in full.state_names if s != "gyro_constant_drift_z"], measurements=["Z_n", "Z_e"])
    in_code = derive(markov_to_white(kept, ["eps_r_z", "nabla_x", "nabla_y", "nabla_z"]))
    assert from_file.n_states == 13
    assert from_file.model.state_names == in_code.model.state_names
    assert from_file.F == in_code.F and from_file.G == in_code.G and from_file.H == in_code.H
    assert sp.simplify(from_file.Q - in_code.Q) == sp.zeros(*in_code.Q.shape)


def test_augmented_file_adds_scale_factor_and_misalignment_terms():
    d = derive(load_model("ned_doppler32_augmented"))
    m = d.model
    assert d.n_states == 32
    c11, w = sp.Symbol("c11", real=True), sp.Symbol("omega_bx", real=True)
    assert d.F[m.state_index("alpha"), m.state_index("k_gx")] == c11 * w
    V_n, V_e = sp.Symbol("V_n", real=True), sp.Symbol("V_e", real=True)
    assert d.H[0, m.state_index("k_d")] == -V_n
    assert d.H[1, m.state_index("psi_d")] == -V_n
    assert d.H[0, m.state_index("psi_d")] == V_e


BASE = "model: small\nbase: ned_doppler18\ntransforms:\n"


@pytest.mark.parametrize(
    "body, message",
    [
        ("  - drop_states: {states: [alpha]}\n", "file.yaml:4: transforms[0]: unknown transformation 'drop_states'"),
        ("  - keep_states: {states: [alpha], extra: 1}\n", "keep_states has unknown argument 'extra'"),
        ("  - keep_states: {states: [alphaa]}\n", "alphaa"),
        ("  - markov_to_white: {states: [eps_c_x]}\n", "transforms[0] (markov_to_white)"),
    ],
)
def test_bad_transform_step_is_refused_with_file_and_step(body, message):
    with pytest.raises(ModelError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[").replace("]", r"\]")):
        load_model_text(BASE + body, "file.yaml")


def test_unknown_base_model_is_refused():
    with pytest.raises(ModelError, match="no such model file"):
        load_model_text("model: x\nbase: nonexistent_model\n", "file.yaml")
