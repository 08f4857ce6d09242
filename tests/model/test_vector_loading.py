"""Model files with 3-vectors, 3x3 matrices and definitions load as ordinary scalar models.

The small INS error model below is written once with vectors; its F, G, H
are compared with the same equations written out with numpy block matrices
(skew-symmetric matrices of f^n and omega_ie^n), and with the same model
hand-expanded into scalar equations in a second file.
"""

import math
import textwrap

import numpy as np
import pytest
import sympy as sp

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.loading import load_model, load_model_text
from modelgen.model.wgs84 import EARTH_RATE

VECTOR_MODEL = textwrap.dedent(
    """\
    model: vec_demo
    title: small vector INS error model
    frame: NED
    states:
      - {name: dv, shape: 3, unit: m/s, description: velocity error}
      - {name: phi, shape: 3, unit: rad, description: attitude error}
      - {name: b_a, shape: 3, axes: body, unit: m/s^2, description: accelerometer bias}
    noises:
      - {name: w_a, shape: 3, axes: body, unit: m/s^2/sqrt(Hz), psd: "q_a"}
      - {name: w_g, shape: 3, axes: body, unit: rad/s/sqrt(Hz), psd: ["q_g", "q_g", "2*q_g"]}
    parameters:
      - {name: L, unit: rad, description: latitude}
      - {name: C_bn, shape: [3, 3], unit: "1", description: attitude matrix body to NED}
      - {name: f_b, shape: 3, axes: body, unit: m/s^2, value: [0.1, -0.2, -9.8]}
      - {name: q_a, value: 1.0e-6}
      - {name: q_g, value: 1.0e-10}
      - {name: r_v, value: 0.01}
    definitions:
      - {name: w_ie, value: "earth_rate_ned(L)"}
      - {name: f_n, value: "C_bn*f_b"}
    dynamics:
      dv: "cross(f_n, phi) - cross(2*w_ie, dv) + C_bn*b_a + C_bn*w_a"
      phi: "-cross(w_ie, phi) - C_bn*w_g"
      b_a: 0
    measurements:
      - {name: z_v, shape: 3, expression: "dv", variance: "r_v"}
    check:
      step_s: 1.0
      steps: 10
      parameters:
        L: 0.6
        C_bn: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
      initial_sigma:
        dv: 0.1
        phi: [0.001, 0.001, 0.01]
        b_a: 0.001
    """
)


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@pytest.fixture(scope="module")
def model():
    return load_model_text(VECTOR_MODEL, "vec_demo.yaml")


def test_vectors_expand_to_components_named_by_frame_and_axes(model):
    assert model.state_names == ["dv_n", "dv_e", "dv_d", "phi_n", "phi_e", "phi_d", "b_a_x", "b_a_y", "b_a_z"]
    assert model.noise_names == ["w_a_x", "w_a_y", "w_a_z", "w_g_x", "w_g_y", "w_g_z"]
    assert model.parameter_names[:10] == ["L"] + [f"C_bn_{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
    assert model.measurement_names == ["z_v_n", "z_v_e", "z_v_d"]
    assert model.parameter_defaults()["f_b_z"] == -9.8
    assert model.states[1].description == "velocity error (east component)"
    assert str(model.noise_psd["w_g_z"]) == "2*q_g"


def test_vector_model_matrices_are_the_block_formulas_of_the_vector_equations(model):
    rng = np.random.default_rng(3)
    C = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    values = {"L": 0.7, **{f"C_bn_{i + 1}{j + 1}": C[i, j] for i in range(3) for j in range(3)}}
    got = derive(model).numeric(values)
    f_n = C @ np.array([0.1, -0.2, -9.8])
    w_ie = EARTH_RATE * np.array([math.cos(0.7), 0.0, -math.sin(0.7)])
    F = np.zeros((9, 9))
    F[0:3, 0:3] = -skew(2 * w_ie)
    F[0:3, 3:6] = skew(f_n)
    F[0:3, 6:9] = C
    F[3:6, 3:6] = -skew(w_ie)
    G = np.zeros((9, 6))
    G[0:3, 0:3], G[3:6, 3:6] = C, -C
    H = np.hstack([np.eye(3), np.zeros((3, 6))])
    assert got["F"] == pytest.approx(F, abs=1e-15)
    assert got["G"] == pytest.approx(G, abs=1e-15)
    assert got["H"] == pytest.approx(H)
    assert np.diag(got["Q"]) == pytest.approx([1e-6] * 3 + [1e-10, 1e-10, 2e-10])


def test_vector_file_and_its_hand_expanded_scalar_file_give_the_same_model(model):
    scalar = textwrap.dedent(
        """\
        model: vec_demo
        frame: NED
        states:
          - {name: dv_n}
          - {name: dv_e}
          - {name: dv_d}
        noises:
          - {name: w, psd: q}
        parameters:
          - {name: L}
          - {name: q, value: 1.0}
        dynamics:
          dv_n: "-2*0.00007292115*sin(L)*dv_e + w"
          dv_e: "2*0.00007292115*(sin(L)*dv_n + cos(L)*dv_d)"
          dv_d: "-2*0.00007292115*cos(L)*dv_e"
        """
    )
    vector = textwrap.dedent(
        """\
        model: vec_demo
        frame: NED
        states:
          - {name: dv, shape: 3}
        noises:
          - {name: w, psd: q}
        parameters:
          - {name: L}
          - {name: q, value: 1.0}
        dynamics:
          dv: "-cross(2*earth_rate_ned(L), dv) + vector(w, 0, 0)"
        """
    )
    a, b = derive(load_model_text(scalar, "s.yaml")), derive(load_model_text(vector, "v.yaml"))
    assert a.F.free_symbols == b.F.free_symbols == {sp.Symbol("L", real=True)}
    for latitude in (-1.2, 0.0, 0.4, 1.5):
        numbers_a, numbers_b = a.numeric({"L": latitude}), b.numeric({"L": latitude})
        for name in "FGHQ":
            assert numbers_a[name] == pytest.approx(numbers_b[name], rel=1e-15, abs=1e-22), name


def test_check_section_takes_vector_values_by_the_vectors_name(model):
    values = model.check.parameter_values()
    assert values["C_bn_11"] == 1 and values["C_bn_12"] == 0 and values["L"] == 0.6
    sigma = dict(model.check.initial_sigma)
    assert sigma["dv_d"] == 0.1 and sigma["phi_d"] == 0.01 and sigma["b_a_y"] == 0.001


def test_a_scalar_model_may_call_the_navigation_library():
    text = textwrap.dedent(
        """\
        model: lib_scalar
        states:
          - {name: dn}
          - {name: dve}
        parameters:
          - {name: L}
          - {name: h, value: 0.0}
        dynamics:
          dn: "dve/(R_N(L) + h)"
          dve: "-normal_gravity(L, h)/meridian_radius(L)*dn"
        """
    )
    m = load_model_text(text, "lib.yaml")
    F = derive(m).numeric({"L": 0.0})["F"]
    assert F[0, 1] == pytest.approx(1 / 6378137.0, rel=1e-15)
    assert F[1, 0] == pytest.approx(-9.7803253359 / 6335439.3272928195, rel=1e-12)


def test_models_declaring_library_names_keep_their_own_meaning():
    ins = load_model("ins_gnss21")  # declares parameters R_M, R_N, g: plain symbols, not library calls
    assert {"R_M", "R_N"} <= {p.symbol for p in ins.parameters}


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('dv: "cross(f_n, phi)', 'dv: "cross(C_bn, phi)', "vec_demo.yaml:22: model 'vec_demo', equation d(dv)/dt: cross() needs two 3-vectors, got 3x3 and 3x1"),
        ("b_a: 0", "b_a: L", "vec_demo.yaml:24: model 'vec_demo', equation d(b_a)/dt: 'L' is a scalar, but 3x1 state 'b_a' is a 3x1 (0 stands for the zero vector)"),
        ('psd: "q_a"', 'psd: "f_b"', "vec_demo.yaml:9: model 'vec_demo', 3x1 noise 'w_a' psd: 'f_b' is a 3x1, but a psd is a scalar"),
        ("shape: [3, 3], unit", "shape: [2, 2], unit", "vec_demo.yaml:13: parameter 'C_bn': shape [2, 2] is not supported"),
        ("value: [0.1, -0.2, -9.8]", "value: [0.1, -0.2]", "vec_demo.yaml:14: 3x1 parameter 'f_b' value must be a list of 3 numbers"),
        ("{name: f_n, value", "{name: w_ie, value", "'w_ie' is defined twice"),
        ('value: "earth_rate_ned(L)"', 'value: "earth_rate_ned(L) + f_n"', "vec_demo.yaml:19: definition 'w_ie' uses 'f_n' before it is defined (it is defined at vec_demo.yaml:20)"),
        ("{name: r_v, value: 0.01}", "{name: dv_n, value: 0.01}", "vec_demo.yaml:17: parameter 'dv_n' collides with component 'dv_n' of 3x1 state 'dv' at vec_demo.yaml:5"),
        ('expression: "dv"', 'expression: "dv_n"', "vec_demo.yaml:26: model 'vec_demo', 3x1 measurement 'z_v': 'dv_n' is a scalar, but 3x1 measurement 'z_v' is a 3x1"),
        ("  b_a: 0\n", "  b_a: 0\n  dv_n: 0\n", "'dv_n' is a component of 3x1 state 'dv'; write one 3x1 equation for 'dv'"),
        ("    dv: 0.1\n", "    dv: [0.1, 0.2]\n", "check.initial_sigma.dv: 3x1 state 'dv' needs 3 values"),
        ("    dv: 0.1\n", "    dv: 0.1\n    dv_e: 0.2\n", "check.initial_sigma.dv gives 'dv_e', which check.initial_sigma.dv_e gives too"),
    ],
)
def test_bad_vector_files_are_refused_with_file_line_and_shapes(old, new, message):
    assert old in VECTOR_MODEL
    with pytest.raises(ModelError) as caught:
        load_model_text(VECTOR_MODEL.replace(old, new, 1), "vec_demo.yaml")
    assert message in str(caught.value)


def test_enu_vectors_are_stored_east_north_up_and_equal_the_ned_model_permuted():
    """The same earth-rate coupling written in ENU and in NED: F_enu = P F_ned P^T with P the NED->ENU map."""
    from modelgen.model.ned_enu import NED_TO_ENU

    def model(frame: str, rate: str) -> str:
        return textwrap.dedent(
            f"""\
            model: coriolis_{frame.lower()}
            frame: {frame}
            states:
              - {{name: dv, shape: 3, unit: m/s}}
            parameters:
              - {{name: L, unit: rad}}
            dynamics:
              dv: "-cross(2*{rate}(L), dv)"
            """
        )

    enu = load_model_text(model("ENU", "earth_rate_enu"), "enu.yaml")
    ned = load_model_text(model("NED", "earth_rate_ned"), "ned.yaml")
    assert enu.state_names == ["dv_e", "dv_n", "dv_u"] and ned.state_names == ["dv_n", "dv_e", "dv_d"]
    F_enu, F_ned = derive(enu).numeric({"L": 0.8})["F"], derive(ned).numeric({"L": 0.8})["F"]
    assert F_enu == pytest.approx(NED_TO_ENU @ F_ned @ NED_TO_ENU.T, abs=1e-20)


def test_every_component_of_a_vector_entry_carries_the_entry_s_line(model):
    """A vector's components are items of their own: each keeps the line of the entry that declared the vector
    (noise w_g, its psd list on that line too), for refusals made after loading."""
    lines = VECTOR_MODEL.splitlines()
    noise = next(i for i, text in enumerate(lines, start=1) if "name: w_g" in text)
    assert {w.place("psd") for w in model.noises if w.name.startswith("w_g")} == {f"vec_demo.yaml:{noise}"}
    measurement = next(i for i, text in enumerate(lines, start=1) if "name: z_v" in text)
    assert {m.place("variance") for m in model.measurements} == {f"vec_demo.yaml:{measurement}"}
