"""The navigator's mechanization rates, from the equations a navigation model's error model is derived from.

A model with a ``navigation:`` section carries its navigation problem
(:attr:`modelgen.model.declaration.ErrorModel.navigation`): the frame, the
mechanization object (:mod:`modelgen.model.mechanizations`) and any velocity
or position equation the file writes itself (a model written as equations is
flown by the default mechanization, local_level in its own frame).  The error model is the
perturbation of exactly these equations; this module takes the same
expressions, unperturbed, for the navigator that flies the model:

* the velocity rate without its specific-force term,
  v' - C_b^n f^b = -(2 w_ie + w_en) x v + g (the navigator integrates C_b^n f^b
  as sculled velocity increments, fixed code);
* the position rate (L', lambda', h');
* w_in = w_ie + w_en, the rate the attitude update takes out of the body rotation
  (C' = C [w_ib x] - [w_in x] C; the quaternion update with coning is fixed code).

For a local-level model they are resolved in NED, the navigator's state,
whatever the model's frame: for an ENU model the velocity enters as
v^ENU = T v^NED and the rates leave as T^T (rate^ENU), so the ENU equations are
flown, not NED ones.  For the ``ecef`` mechanization the navigator's state is
the e-frame's own (r^e, v^e, C_b^e): the inputs are (x, y, z, v_x, v_y, v_z),
the outputs v' - C_b^e f^b = -2 w_ie x v + g^e(r) (the J2 gravity of the
mechanization object, |r^e| written out), r' = v and w_ie^e; the navigator's
integrator is the same (its position update, the third component first and then
the first two at the mean third, is r += mean(v) dt when the rate is v).

The approximations a model declares (``constant_radii``, ``gravity_height_only``,
``free_air_gradient`` ...) are simplifications of its *error* model: they act
on the derived F, G, H (modelgen.model.perturbation, step 4), never on the
navigation equations.  The navigator flies the exact equations, as a
navigation engineer expects: full WGS-84 radii of curvature and Somigliana
normal gravity with the second-order free-air terms (:func:`wgs84_earth_functions`,
NIMA TR8350.2), while the filter's error model may be simplified.  A velocity
or position equation the model writes itself is an equation, not an
approximation, and is flown as written.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model import wgs84
from modelgen.model.mechanizations.ecef import GeocentricRadius
from modelgen.model.mechanizations.local_level import Gravity, LocalLevel, MeridianRadius, PrimeVerticalRadius
from modelgen.model.perturbation.problem import NavigationState

#: NED -> ENU (the local-level frames' components: swap north and east, up = -down).
_NED_TO_FRAME = {"NED": sp.eye(3), "ENU": sp.Matrix([[0, 1, 0], [1, 0, 0], [0, 0, -1]])}
#: The rate function's arguments, in order: the navigator's position and NED velocity.
INPUT_NAMES = ("latitude", "longitude", "height", "v_north", "v_east", "v_down")
#: The rate function's outputs, in order (all NED but the position rates).
OUTPUT_NAMES = ("velocity_rate_north", "velocity_rate_east", "velocity_rate_down",
                "latitude_rate", "longitude_rate", "height_rate",
                "navigation_rate_north", "navigation_rate_east", "navigation_rate_down")
#: The same of the ecef mechanization: e-frame position and velocity in, e-frame rates out.
ECEF_INPUT_NAMES = ("x", "y", "z", "v_x", "v_y", "v_z")
ECEF_OUTPUT_NAMES = ("velocity_rate_x", "velocity_rate_y", "velocity_rate_z", "x_rate", "y_rate", "z_rate",
                     "earth_rate_x", "earth_rate_y", "earth_rate_z")
#: Where a refusal of the velocity equation points: the equation the file writes, else its mechanization.
_VELOCITY_KEYS = ("navigation.equations.velocity", "navigation.equations", "navigation.mechanization", "navigation")
#: The mechanizations the navigator flies (a model of another is refused naming its file).
FLOWN = ("local_level", "ecef")


class RatesRefused(ModelError):
    """A model the navigator cannot fly by its own rates; ``keys``: the model file's keys that say why, first first
    (the navigator names the line of the first the file has, :func:`modelgen.navigator.spec.spec_of`)."""

    def __init__(self, message: str, keys: tuple[str, ...]):
        super().__init__(message)
        self.keys = keys


@dataclass(frozen=True)
class MechanizationRates:
    """The navigator's rates as expressions of :attr:`inputs` (latitude, longitude, height, NED velocity; or e-frame
    position and velocity for the ecef mechanization)."""

    model: str
    frame: str
    inputs: tuple[sp.Symbol, ...]
    velocity: sp.Matrix  # v' without C_b^n f^b, NED (ECEF: e-frame) [m/s^2]
    position: sp.Matrix  # (L', lambda', h') [rad/s, rad/s, m/s] (ECEF: r' [m/s])
    navigation_rate: sp.Matrix  # w_in, NED (ECEF: w_ie^e) [rad/s]
    input_names: tuple[str, ...] = INPUT_NAMES
    output_names: tuple[str, ...] = OUTPUT_NAMES

    @property
    def outputs(self) -> list[sp.Expr]:
        """The nine outputs in :data:`OUTPUT_NAMES` order."""
        return [*self.velocity, *self.position, *self.navigation_rate]


def wgs84_earth_functions(latitude: sp.Expr, height: sp.Expr) -> dict:
    """R_M(L), R_N(L), g(L, h) of WGS-84 in closed form (TR8350.2: the radii, Somigliana with the free-air terms).

    R_M = a (1 - e^2) / w^(3/2), R_N = a / w^(1/2), w = 1 - e^2 sin^2 L;
    g = gamma_e (1 + k sin^2 L) / w^(1/2) (1 - 2 h (1 + f + m - 2 f sin^2 L) / a + 3 h^2 / a^2).
    The same formulas as :func:`modelgen.model.perturbation.simplification.earth_derivative_rules` differentiates.
    """
    e2, a = sp.Float(wgs84.ECCENTRICITY_SQUARED), sp.Float(wgs84.SEMI_MAJOR_AXIS)
    f, m, k = sp.Float(wgs84.FLATTENING), sp.Float(wgs84.GRAVITY_RATIO_M), sp.Float(wgs84.SOMIGLIANA_K)
    s2 = sp.sin(latitude) ** 2
    w = 1 - e2 * s2
    eta = 1 - 2 * height * (1 + f + m - 2 * f * s2) / a + 3 * height**2 / a**2
    return {
        MeridianRadius(latitude): a * (1 - e2) / w ** sp.Rational(3, 2),
        PrimeVerticalRadius(latitude): a / sp.sqrt(w),
        Gravity(latitude, height): sp.Float(wgs84.EQUATORIAL_GRAVITY) * (1 + k * s2) / sp.sqrt(w) * eta,
    }


def mechanization_rates(model) -> MechanizationRates:
    """The rates of ``model``'s own mechanization (module doc); ModelError for a model the navigator cannot fly so."""
    problem = getattr(model, "navigation", None)
    name, frame = (problem.mechanization_name, problem.frame) if problem is not None else ("local_level", str(model.frame).upper())
    if name == "ecef" and frame == "ECEF":
        return _ecef_rates(model, problem)
    if name != "local_level" or frame not in _NED_TO_FRAME:
        raise RatesRefused(f"model {model.name}: the navigator flies the local_level mechanization in NED or ENU and "
                           f"the ecef mechanization in ECEF (this model: {name}, frame {frame or 'none'})",
                           ("navigation.mechanization", "frame", "navigation"))
    mech, position, attitude, body_rate, earth_rate = _equations(problem, frame)
    T = _NED_TO_FRAME[frame]
    latitude, longitude, height = position
    inputs = (latitude, longitude, height, *sp.symbols("v_north v_east v_down", real=True))
    velocity = T * sp.Matrix(inputs[3:])
    force = sp.Matrix(sp.symbols("mechanization_f0:3", real=True, cls=sp.Dummy))
    state = NavigationState(attitude, velocity, position, force, body_rate, position, position)
    velocity_rate = mech.velocity_rate(state)
    if velocity_rate.jacobian(list(force)) != sp.eye(3):
        raise RatesRefused(f"model {model.name}: the navigator integrates the specific force as C_b^n f^b increments: "
                           "the velocity equation must have the term f_n (plus terms without the specific force)",
                           _VELOCITY_KEYS)
    earth = {**wgs84_earth_functions(latitude, height), earth_rate: _earth_rate(model, str(earth_rate))}
    rates = MechanizationRates(
        model.name, frame, inputs,
        (T.T * velocity_rate.xreplace({s: 0 for s in force})).xreplace(earth),
        mech.position_rate(state).xreplace(earth),
        (T.T * mech.navigation_rate(state)).xreplace(earth),
    )
    _refuse_other_symbols(model, rates)
    return rates


def _ecef_rates(model, problem) -> MechanizationRates:
    """The ecef mechanization's rates in e-frame axes (module doc): the same mechanization object as the error model's."""
    mech, position, attitude, body_rate, earth_rate = _equations(problem, "ECEF")
    velocity = sp.Matrix(sp.symbols("v_x v_y v_z", real=True))
    inputs = (*position, *velocity)
    force = sp.Matrix(sp.symbols("mechanization_f0:3", real=True, cls=sp.Dummy))
    state = NavigationState(attitude, velocity, position, force, body_rate, position, position)
    velocity_rate = mech.velocity_rate(state)
    if velocity_rate.jacobian(list(force)) != sp.eye(3):
        raise RatesRefused(f"model {model.name}: the navigator integrates the specific force as C_b^e f^b increments: "
                           "the velocity equation must have the term f_e (plus terms without the specific force)",
                           _VELOCITY_KEYS)
    x, y, z = position
    earth = {GeocentricRadius(x, y, z): sp.sqrt(x**2 + y**2 + z**2), earth_rate: _earth_rate(model, str(earth_rate))}
    rates = MechanizationRates(
        model.name, "ECEF", tuple(inputs),
        velocity_rate.xreplace({s: 0 for s in force}).xreplace(earth),
        mech.position_rate(state).xreplace(earth),
        mech.navigation_rate(state).xreplace(earth),
        ECEF_INPUT_NAMES, ECEF_OUTPUT_NAMES,
    )
    _refuse_other_symbols(model, rates)
    return rates


def _equations(problem, frame: str) -> tuple:
    """(mechanization, position, attitude, body-rate symbols, Earth-rate symbol) of the model's navigation problem.

    A model written as equations (no ``navigation:`` section) declares no mechanization: it is flown by the
    default of a navigation section, the local_level mechanization in its own frame.
    """
    if problem is not None:
        return problem.mechanization(), problem.position, problem.attitude, problem.body_rate, problem.earth.earth_rate
    earth_rate = sp.Symbol("omega_ie", real=True)
    position = sp.Matrix(sp.symbols("L lambda_ h", real=True))
    return LocalLevel(frame, earth_rate), position, sp.Matrix(3, 3, sp.symbols("c1:4(1:4)", real=True)), None, earth_rate


def _earth_rate(model, symbol: str) -> sp.Float:
    """The value of the model's Earth-rate parameter (its default; the navigation reader gives IS-GPS-200's)."""
    for parameter in model.parameters:
        if (parameter.symbol == symbol or parameter.name == "earth_rate") and parameter.value is not None:
            return sp.Float(parameter.value)
    return sp.Float(wgs84.GPS_EARTH_RATE)


def _refuse_other_symbols(model, rates: MechanizationRates) -> None:
    """Every symbol of the rates must be an input: an attitude, a body rate or a model parameter is refused."""
    def outside(expressions) -> list[str]:
        used = set().union(*(e.free_symbols for e in expressions))
        other = sorted(str(s) for s in used - set(rates.inputs))
        return other + sorted(str(a) for e in expressions for a in e.atoms(sp.Function)
                              if isinstance(a, sp.core.function.AppliedUndef))

    found = outside(rates.outputs)
    if found:
        # the line of the equation that uses them: the velocity's (w_in comes with it), else the position's
        keys = ((_VELOCITY_KEYS if outside([*rates.velocity, *rates.navigation_rate]) else ())
                + ("navigation.equations.position", "navigation.equations", "navigation.mechanization", "navigation"))
        raise RatesRefused(f"model {model.name}: the navigator's rates may depend on the position and the velocity only; "
                           f"its mechanization's also use {', '.join(found)}", keys)
