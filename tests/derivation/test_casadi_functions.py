"""The CasADi backend derives the same F, G, H as the sympy derivation."""

from __future__ import annotations

import re

import numpy as np
import pytest
import sympy as sp

from modelgen.derivation.casadi_functions import build_casadi_model, sympy_to_casadi
from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Parameter, State
from modelgen.model.expression import ALLOWED_FUNCTIONS
from modelgen.model.loading import builtin_models, load_model

RELATIVE_TOLERANCE = 1e-12
N_OPERATING_POINTS = 5
_DIRECTION_COSINE = re.compile(r"^c([1-3])([1-3])$")
#: An element of a 3x3 matrix parameter of a vector model (``C_bn_12``: stem, row, column).
_MATRIX_ELEMENT = re.compile(r"^(.+)_([1-3])([1-3])$")


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random proper rotation matrix (QR of a Gaussian matrix)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def random_operating_point(model: ErrorModel, rng: np.random.Generator) -> dict[str, float]:
    """Random but physically plausible values for every parameter of ``model``.

    Latitude, velocities, specific forces, attitude matrix entries c_ij (from
    one random rotation) and inverse correlation times are drawn from their
    physical ranges; parameters with a default keep it; anything else (models
    added later) gets a value in (0.2, 0.9), inside every allowed function's
    domain.
    """
    rotation = random_rotation(rng)
    values: dict[str, float] = {}
    matrices: dict[str, np.ndarray] = {}  # 3x3 matrix parameters of vector models: one random rotation each
    for p in model.parameters:
        text = f"{p.name} {p.symbol}".lower()
        cosine = _DIRECTION_COSINE.match(p.symbol) or _DIRECTION_COSINE.match(p.name)
        element = _MATRIX_ELEMENT.match(p.name)
        if cosine:
            values[p.name] = float(rotation[int(cosine[1]) - 1, int(cosine[2]) - 1])
        elif element and p.unit == "1" and p.value is None:
            matrix = matrices.setdefault(element[1], random_rotation(rng))
            values[p.name] = float(matrix[int(element[2]) - 1, int(element[3]) - 1])
        elif p.value is None and (p.symbol == "L" or "latitude" in p.description.lower()):
            values[p.name] = float(rng.uniform(-1.3, 1.3))
        elif p.value is None and p.unit == "m/s":
            values[p.name] = float(rng.uniform(-300.0, 300.0))
        elif p.value is None and p.unit in ("m/s^2", "m/s**2"):
            values[p.name] = float(rng.uniform(-15.0, 15.0))
        elif "latitude" in text:
            values[p.name] = float(rng.uniform(-1.3, 1.3))
        elif "velocity" in text:
            values[p.name] = float(rng.uniform(-300.0, 300.0))
        elif "specific_force" in text:
            values[p.name] = float(rng.uniform(-15.0, 15.0))
        elif p.unit == "1/s" and ("rate" in text or text.startswith("mu")):
            values[p.name] = 1.0 / float(rng.uniform(60.0, 36000.0))  # correlation time 1 min .. 10 h
        elif p.value is not None:
            values[p.name] = p.value
        else:
            values[p.name] = float(rng.uniform(0.2, 0.9))
    return values


def assert_close(sympy_value: np.ndarray, casadi_value: np.ndarray, what: str) -> None:
    assert sympy_value.shape == casadi_value.shape, what
    assert np.all(np.isfinite(sympy_value)) and np.all(np.isfinite(casadi_value)), what
    error = np.abs(sympy_value - casadi_value)
    bound = RELATIVE_TOLERANCE * np.abs(sympy_value)
    bad = np.argwhere(error > bound)
    assert bad.size == 0, f"{what}: entries {[(int(i) + 1, int(j) + 1) for i, j in bad[:5]]} differ: " + ", ".join(
        f"{sympy_value[i, j]!r} vs {casadi_value[i, j]!r}" for i, j in bad[:5]
    )


@pytest.fixture(scope="module", params=builtin_models())
def both_backends(request, derived_builtin):
    derived = derived_builtin(request.param)
    return derived, build_casadi_model(derived.model)


def test_sympy_and_casadi_jacobians_agree_at_random_operating_points(both_backends):
    derived, casadi_model = both_backends
    rng = np.random.default_rng(20240611)
    for k in range(N_OPERATING_POINTS):
        values = random_operating_point(derived.model, rng)
        reference = derived.numeric(values)
        candidate = casadi_model.numeric(values)
        for key in ("F", "G", "H"):
            assert_close(reference[key], candidate[key], f"{derived.model.name} point {k} {key}")


def _declares_a_check_scenario(name: str) -> bool:
    """Whether the built-in model's file has a ``check:`` section (read, not derived: collection stays fast)."""
    import yaml

    from modelgen.model.loading import builtin_model_path

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    return "check" in (yaml.load(builtin_model_path(name).read_text(encoding="utf-8"), Loader=loader) or {})  # noqa: S506


@pytest.mark.parametrize("name", [n for n in builtin_models() if _declares_a_check_scenario(n)])
def test_sympy_and_casadi_jacobians_agree_at_the_models_own_check_scenario(name, derived_builtin):
    """The realistic operating point each model file declares (its ``check:`` section)."""
    derived = derived_builtin(name)
    model = derived.model
    assert model.check is not None, f"{name}: its file has a check: section, the loaded model has none"
    values = model.check.parameter_values()
    reference, candidate = derived.numeric(values), build_casadi_model(model).numeric(values)
    for key in ("F", "G", "H"):
        assert np.array_equal(reference[key] == 0, candidate[key] == 0), f"{name} {key}"
        assert_close(reference[key], candidate[key], f"{name} check scenario {key}")


VECTOR_MODEL = """\
model: vector_ins
frame: NED
states:
  - {name: dr, shape: 3, unit: m}
  - {name: dv, shape: 3, unit: m/s}
  - {name: phi, shape: 3, unit: rad}
  - {name: b_g, shape: 3, axes: body, unit: rad/s}
noises:
  - {name: w_a, shape: 3, axes: body, psd: "1.0e-6"}
  - {name: w_g, shape: 3, axes: body, psd: "1.0e-10"}
parameters:
  - {name: L, unit: rad, description: latitude}
  - {name: h, unit: m, value: 1200.0}
  - {name: v, shape: 3, unit: m/s}
  - {name: C_bn, shape: [3, 3], unit: "1"}
  - {name: f_b, shape: 3, axes: body, unit: m/s^2}
  - {name: l_b, shape: 3, axes: body, unit: m, value: [0.5, -0.2, 1.1]}
definitions:
  - {name: w_ie, value: "earth_rate_ned(L)"}
  - {name: w_en, value: "transport_rate_ned(L, h, v)"}
  - {name: w_in, value: "w_ie + w_en"}
  - {name: radii, value: "diag(1/(R_M(L) + h), 1/((R_N(L) + h)*cos(L)), -1)"}
dynamics:
  dr: "-cross(w_en, dr) + dv"
  dv: "cross(C_bn*f_b, phi) - cross(2*w_ie + w_en, dv) + vector(0, 0, 2*normal_gravity(L, h)/(R_N(L) + h))*dr_d + C_bn*w_a"
  phi: "-cross(w_in, phi) - C_bn*b_g - C_bn*w_g"
  b_g: "-b_g/3600"
measurements:
  - {name: z_r, shape: 3, expression: "radii*(dr + cross(C_bn*l_b, phi))", variance: "1.0e-12"}
"""


def test_sympy_and_casadi_agree_on_a_vector_model_using_the_navigation_library():
    from modelgen.model.loading import load_model_text

    model = load_model_text(VECTOR_MODEL, "vector_ins.yaml")
    derived, casadi_model = derive(model), build_casadi_model(model)
    rng = np.random.default_rng(12)
    for k in range(N_OPERATING_POINTS):
        values = random_operating_point(model, rng)
        reference, candidate = derived.numeric(values), casadi_model.numeric(values)
        for key in ("F", "G", "H"):
            assert_close(reference[key], candidate[key], f"vector model point {k} {key}")


def test_casadi_structural_zeros_are_the_sympy_structural_zeros(both_backends):
    derived, casadi_model = both_backends
    values = random_operating_point(derived.model, np.random.default_rng(7))
    candidate = casadi_model.numeric(values)
    for key in ("F", "G", "H"):
        nonzero_casadi = candidate[key] != 0.0
        # reshape: a 0-row H gives a flat mask from DerivedModel.structure
        nonzero_sympy = derived.structure(key).reshape(getattr(derived, key).shape)
        assert np.array_equal(nonzero_casadi, nonzero_sympy), f"{derived.model.name} {key}"


def test_paper_model_agrees_at_the_papers_level_flight_point():
    model = load_model("ned_doppler18")
    derived, casadi_model = derive(model), build_casadi_model(model)
    level_flight_east = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    values = {f"c{i + 1}{j + 1}": float(level_flight_east[i][j]) for i in range(3) for j in range(3)}
    values.update(latitude=np.radians(30.0), velocity_north=0.0, velocity_east=3000 / 3.6, velocity_down=0.0)
    values.update(specific_force_north=0.0, specific_force_east=0.0, specific_force_down=-9.78)
    values.update({f"gyro_markov_rate_{a}": 1 / 3600.0 for a in "xyz"})
    values.update({f"accel_markov_rate_{a}": 1 / 1800.0 for a in "xyz"})
    values.update({p.name: 1.0 for p in model.parameters if "sigma" in p.name})
    reference, candidate = derived.numeric(values), casadi_model.numeric(values)
    for key in ("F", "G", "H"):
        # exact zeros (V_n = 0, a_n = 0, c_ij = 0) must stay exact zeros
        assert np.array_equal(reference[key] == 0, candidate[key] == 0), key
        assert_close(reference[key], candidate[key], f"level flight {key}")


def test_every_allowed_function_translates_to_the_same_number():
    a, b = sp.symbols("a b", real=True)
    import casadi as ca

    sx = {a: ca.SX.sym("a"), b: ca.SX.sym("b")}
    point = {a: 0.3, b: 0.7}
    expressions = [
        sp.sin(a), sp.cos(a), sp.tan(a), sp.sec(a), sp.asin(a), sp.acos(a), sp.atan(a), sp.atan2(a, b),
        sp.sqrt(b), 1 / sp.sqrt(b), sp.exp(a), sp.log(b), sp.Abs(a - b), sp.pi * a, a**3 / b**2, b**sp.Rational(3, 2),
        b**a, sp.Float(0.125) * a + sp.Rational(2, 3),
    ]
    covered = {type(e).__name__ for e in expressions} | {"pi", "sqrt"}
    assert set(ALLOWED_FUNCTIONS) <= covered | {"Pow", "Mul", "Add"}
    for expr in expressions:
        function = ca.Function("e", [sx[a], sx[b]], [sympy_to_casadi(expr, sx)])
        got = float(function(point[a], point[b]))
        want = float(expr.subs(point).evalf(30))
        assert abs(got - want) <= 1e-14 * max(1.0, abs(want)), f"{expr}: {got} vs {want}"


def test_unknown_function_or_symbol_is_refused_with_its_place():
    import casadi as ca

    a = sp.Symbol("a", real=True)
    with pytest.raises(ModelError, match="no CasADi counterpart for foo"):
        sympy_to_casadi(sp.Function("foo")(a), {a: ca.SX.sym("a")}, "test equation")
    with pytest.raises(ModelError, match="test equation: symbol a"):
        sympy_to_casadi(a + 1, {}, "test equation")


def test_model_without_noises_or_measurements_builds():
    model = ErrorModel.build(
        name="tiny",
        states=[State(name="drift", symbol="d")],
        noises=[],
        parameters=[Parameter(name="rate", symbol="mu", value=0.5)],
        dynamics={"d": "-mu*d"},
    )
    numeric = build_casadi_model(model).numeric({})
    assert numeric["F"].tolist() == [[-0.5]]
    assert numeric["G"].shape == (1, 0) and numeric["H"].shape == (0, 1)
