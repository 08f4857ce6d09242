"""The navigator's mechanization rates: generated from the model's own navigation equations (one source).

The generated ``navigation_rates`` is checked against the strapdown formulas the
navigator had written by hand (kept here as the reference: Groves 2013 eqs.
5.44-5.56 with WGS-84 radii and normal gravity from modelgen.simulation.earth)
and against the model's symbolic mechanization; a model that writes its own
velocity equation flies it, and the error-model approximations do not reach
the mechanization (the navigator flies the exact equations).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from modelgen.codegen.mechanization import c_source, python_source
from modelgen.derivation.mechanization_rates import mechanization_rates
from modelgen.fileio.datafiles import package_path
from modelgen.model.loading import load_model
from modelgen.model.mechanizations.local_level import Gravity, MeridianRadius, PrimeVerticalRadius
from modelgen.model.perturbation.problem import NavigationState
from modelgen.model.wgs84 import GPS_EARTH_RATE
from modelgen.navigator.mechanization import model_rates
from modelgen.simulation.earth import normal_gravity, radii_of_curvature

NED_MODEL = package_path("navigator", "models", "ins_gnss21_rw_nav.yaml")  # the drive's 21-state model
ENU_MODEL = package_path("navigator", "models", "ins_gps15_nav.yaml")  # the drive's 15-state model (equations, ENU)

#: realistic points: latitude [deg], longitude [deg], height [m], NED velocity [m/s] (a car, an aircraft, the south)
POINTS = [(30.5, 114.3, 25.0, 12.0, -7.5, 0.3), (51.0, -1.2, 3000.0, 150.0, 80.0, -5.0),
          (-33.9, 151.2, 0.0, -3.0, 20.0, 0.0), (65.0, 25.0, 120.0, 0.0, 0.0, 0.0)]


def _hand_written(lat, lon, h, vn, ve, vd, earth_rate):
    """The navigator's former hand-written physics: v' - C f, (L', lambda', h'), w_in (NED)."""
    rm, rn = radii_of_curvature(lat)
    sl, cl = math.sin(lat), math.cos(lat)
    wie = np.array([earth_rate * cl, 0.0, -earth_rate * sl])
    wen = np.array([ve / (rn + h), -vn / (rm + h), -ve * sl / cl / (rn + h)])
    v = np.array([vn, ve, vd])
    velocity = -np.cross(2.0 * wie + wen, v) + np.array([0.0, 0.0, normal_gravity(lat, h)])
    position = np.array([vn / (rm + h), ve / ((rn + h) * cl), -vd])
    return np.concatenate([velocity, position, wie + wen])


def _generated(path: Path):
    rates = mechanization_rates(load_model(path))
    return rates, model_rates(python_source(rates), rates.model)


@pytest.fixture(scope="module")
def drive():
    """The drive's 21-state model (NED_MODEL), loaded once for the module, with its rates and their compiled function."""
    model = load_model(NED_MODEL)
    rates = mechanization_rates(model)
    return model, rates, model_rates(python_source(rates), rates.model)


def _relative(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)) / np.maximum(np.abs(np.asarray(b)), 1e-30)


@pytest.mark.parametrize("path", [NED_MODEL, ENU_MODEL], ids=["ned_21_state", "enu_15_state"])
def test_generated_rates_equal_the_hand_written_strapdown_physics(path, request):
    """NED (21 states) and ENU (15 states) models: each output within 1e-12 relative (or 1e-18 absolute)."""
    # NED_MODEL: the module's drive fixture (loaded and compiled once); the ENU model here
    _, function = request.getfixturevalue("drive")[1:] if path == NED_MODEL else _generated(path)
    for lat, lon, h, *v in POINTS:
        got = np.array(function(math.radians(lat), math.radians(lon), h, *v))
        want = _hand_written(math.radians(lat), math.radians(lon), h, *v, GPS_EARTH_RATE)
        close = (_relative(got, want) < 1e-12) | (np.abs(got - want) < 1e-18)
        assert close.all(), (lat, got - want)


def test_generated_rates_equal_the_models_symbolic_mechanization(drive):
    """The printed function against the model's own mechanization object, evaluated symbol by symbol."""
    model, _, function = drive
    problem = model.navigation
    mech = problem.mechanization()
    force = sp.zeros(3, 1)
    state = NavigationState(problem.attitude, problem.velocity, problem.position, force, problem.body_rate,
                            problem.position, problem.position)
    symbolic = sp.Matrix.vstack(mech.velocity_rate(state), mech.position_rate(state), mech.navigation_rate(state))
    L, lam, h = problem.position
    for lat, lon, height, *v in POINTS:
        latitude = math.radians(lat)
        rm, rn = radii_of_curvature(latitude)
        values = {L: latitude, lam: math.radians(lon), h: height, **dict(zip(problem.velocity, v)),
                  problem.earth.earth_rate: GPS_EARTH_RATE}
        earth = {MeridianRadius(L): rm, PrimeVerticalRadius(L): rn, Gravity(L, h): normal_gravity(latitude, height)}
        want = np.array([float(e.xreplace(earth).xreplace(values).evalf(30)) for e in symbolic])
        got = np.array(function(latitude, math.radians(lon), height, *v))
        assert ((_relative(got, want) < 1e-12) | (np.abs(got - want) < 1e-18)).all()


def _variant(tmp_path: Path, name: str, old: str, new: str) -> Path:
    text = NED_MODEL.read_text()
    assert old in text
    path = tmp_path / f"{name}.yaml"
    path.write_text(text.replace("model: ins_gnss21_rw_nav", f"model: {name}").replace(old, new))
    return path


def test_a_velocity_equation_the_model_writes_is_the_one_flown(tmp_path, drive):
    """A model that writes v' without the Coriolis term gets a mechanization without it (one source)."""
    path = _variant(tmp_path, "no_coriolis", "  approximations:",
                    '  equations: {velocity: "f_n - cross(omega_en_n, v_n) + g_n"}\n  approximations:')
    written, function = _generated(path)
    flown = drive[2]
    lat, lon, h, vn, ve, vd = (math.radians(51.0), 0.1, 100.0, 10.0, 20.0, 1.0)
    got, exact = np.array(function(lat, lon, h, vn, ve, vd)), np.array(flown(lat, lon, h, vn, ve, vd))
    wie = np.array([GPS_EARTH_RATE * math.cos(lat), 0.0, -GPS_EARTH_RATE * math.sin(lat)])
    assert got[0:3] - exact[0:3] == pytest.approx(2.0 * np.cross(wie, [vn, ve, vd]), rel=1e-9)
    assert got[3:] == pytest.approx(exact[3:], rel=1e-15)
    assert "0.000145842302934" not in python_source(written)  # 2 w_ie is gone from the printed function


def test_error_model_approximations_do_not_reach_the_mechanization(tmp_path, drive):
    """Without lever_arm_at_computed_position, constant_radii, gravity_height_only, free_air_gradient the error
    model differs, the rates do not."""
    path = _variant(tmp_path, "exact_error_model",
                    "approximations: [lever_arm_at_computed_position, constant_radii, gravity_height_only, free_air_gradient]",
                    "approximations: []")
    exact, (model, rates, _) = load_model(path), drive
    assert exact.dynamics != model.dynamics  # the error models differ (dR/dL, dg/dL, the gravity gradient)
    assert mechanization_rates(exact).outputs == rates.outputs


def test_the_c_function_equals_the_python_function(tmp_path, drive):
    """The C printed from the same expressions, compiled strictly (C99, -Werror), gives the Python numbers."""
    import ctypes
    import shutil
    import subprocess

    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        pytest.skip("no C compiler")
    _, rates, function = drive
    source = tmp_path / "rates.c"
    source.write_text("#include <math.h>\n" + c_source(rates) + "void rates(const double *x, double *out)\n"
                      "{ navigation_rates(x[0], x[1], x[2], x[3], x[4], x[5], out); }\n")
    library = tmp_path / "rates.so"
    subprocess.run([compiler, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-shared", "-fPIC",
                    str(source), "-o", str(library), "-lm"], check=True)
    c_rates = ctypes.CDLL(str(library)).rates
    for lat, lon, h, *v in POINTS:
        x = np.array([math.radians(lat), math.radians(lon), h, *v])
        out = np.zeros(9)
        c_rates(x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        want = np.array(function(*x))
        assert ((_relative(out, want) < 1e-14) | (np.abs(out - want) < 1e-18)).all()
