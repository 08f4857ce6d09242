"""Reading the ``navigation:`` section of a model file: an error model derived from the navigation equations.

A model file with a ``navigation:`` section declares no states, noises,
dynamics or measurements of its own: it names the navigation frame, the
mechanization, the error definition, the sensor errors, the measurements as
functions of the navigation state and the approximations, and
:mod:`modelgen.model.perturbation` derives the linear error model.  The
result is an ordinary :class:`~modelgen.model.declaration.ErrorModel`
(dynamics F x + G w, measurements H x), so derivation, code generation and
every check treat it like a hand-written model.  The format is in README.md,
"Navigation equations -> error model".

Every name is generated unless the file gives it: state names
``attitude_error_north``, ``velocity_error_east``, ``position_error_down``,
``latitude_error``; sensor-error states ``gyro_bias_x``; their driving noises
``gyro_bias_driving_noise_x``; parameters of the navigation state
(``latitude``, ``velocity_north``, ``c11`` ...) are declared for the symbols
the derived matrices use.  Bad input is refused with file:line and the names
involved, before anything is derived.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Mapping, Sequence

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model import perturbation as pt
from modelgen.model import wgs84
from modelgen.model.mechanizations import (  # noqa: F401  (MECHANIZATIONS: public)
    MECHANIZATION_APPROXIMATIONS,
    MECHANIZATION_ERROR_FORMS,
    MECHANIZATION_FRAMES,
    MECHANIZATIONS,
    mechanization_named,
)
from modelgen.model.declaration import ErrorModel, Measurement, Noise, Parameter, State, check_identifier, parse_expression
from modelgen.model.file_fields import free_text, notes_text, scalar_text
from modelgen.model.unit_check import check_model_units
from modelgen.model.units import declared_value
from modelgen.model.vectors import component_names as _vector_component_names
from modelgen.model.vectors import parse_vector_expression

#: Keys of a model file that derives its error model from the navigation equations.
NAVIGATION_TOP_KEYS = frozenset({"model", "title", "source", "frame", "notes", "parameters", "navigation", "check"})
#: Keys of the ``navigation:`` section.
SECTION_KEYS = frozenset(
    {"mechanization", "attitude", "velocity", "position", "specific_force", "body_rate", "earth", "errors",
     "sensor_errors", "noises", "equations", "approximations", "measurements"}
)
#: The mechanizations a file may name: modelgen.model.mechanizations.MECHANIZATIONS (default local_level).
#: Navigation quantities that have error states, and the equations a file may write for them.
ERROR_QUANTITIES = ("attitude", "velocity", "position")
WRITABLE_EQUATIONS = ("velocity", "position")
#: Sensor-error quantities: what each one is in the sensor model.
SENSOR_ERROR_KINDS = ("gyro_bias", "gyro_scale_factor", "accel_bias", "accel_scale_factor", "receiver_clock")
#: Sensor errors that may be declared more than once: the bias is then their sum (seed 000 eq. (2): gyro
#: drift = random constant + first-order Markov process).
SUMMED_SENSOR_ERROR_KINDS = ("gyro_bias", "accel_bias")
#: Processes of sensor-error states.
PROCESSES = ("random_constant", "gauss_markov", "random_walk", "clock")
#: Measurement kinds: what a measurement observes.
MEASUREMENT_KINDS = ("position", "velocity", "pseudorange", "pseudorange_rate", "expression")

_AXIS_WORDS = {"n": "north", "e": "east", "d": "down", "u": "up", "x": "x", "y": "y", "z": "z"}
_UNITS = {
    "gyro_bias": "rad/s", "gyro_scale_factor": "1", "accel_bias": "m/s^2", "accel_scale_factor": "1",
}


@dataclass(frozen=True)
class NavigationDerivation:
    """A navigation model as loaded: the ErrorModel and the engine's result (neglected terms included)."""

    model: ErrorModel
    equations: pt.ErrorEquations


class _Reader:
    """Typed access to the section with file:line in every message."""

    def __init__(self, lines: Mapping[str, str], filename: str):
        self.lines, self.filename = lines, filename

    def at(self, key: str) -> str:
        """The file:line of ``key`` (its nearest located parent if it has none)."""
        while key and key not in self.lines:
            key = key.rsplit(".", 1)[0] if "." in key else key.rsplit("[", 1)[0] if "[" in key else ""
        return self.lines.get(key, self.filename)

    def mapping(self, value: Any, key: str, allowed: Sequence[str] | frozenset, required: Sequence[str] = ()) -> dict:
        if not isinstance(value, dict):
            raise ModelError(f"{self.at(key)}: {key!r} must be a mapping (keys {', '.join(sorted(allowed))})")
        unknown = sorted(set(value) - set(allowed))
        if unknown:
            raise ModelError(f"{self.at(f'{key}.{unknown[0]}')}: unknown key {key}.{unknown[0]} (expected one of {', '.join(sorted(allowed))})")
        for name in required:
            if name not in value:
                raise ModelError(f"{self.at(key)}: {key!r} has no {name!r}")
        return value

    def names(self, value: Any, key: str, count: int) -> list[str]:
        """A list of ``count`` identifiers."""
        if not isinstance(value, list) or len(value) != count:
            got = f"{len(value)} names" if isinstance(value, list) else repr(value)
            raise ModelError(f"{self.at(key)}: {key!r} must list {count} names, got {got}")
        for item in value:
            check_identifier(str(item), f"{self.at(key)}: {key}")
        return [str(v) for v in value]

    def choice(self, value: Any, key: str, options: Sequence[str]) -> str:
        if value not in options:
            raise ModelError(f"{self.at(key)}: {key} {value!r} is not one of {', '.join(options)}")
        return str(value)


#: Axis suffixes of the navigation frames the general vector notation does not know (modelgen.model.vectors: NED, ENU).
_NAVIGATION_ONLY_FRAMES = {"ECEF": ("x", "y", "z")}


def component_names(name: str, shape: int, frame: str, axes: str | None = None, where: str = "") -> list[str]:
    """:func:`modelgen.model.vectors.component_names`, and the e-frame's ``_x, _y, _z`` for a navigation-frame vector."""
    if axes is None and frame in _NAVIGATION_ONLY_FRAMES and shape == 3:
        return [f"{name}_{a}" for a in _NAVIGATION_ONLY_FRAMES[frame]]
    return _vector_component_names(name, shape, frame, axes, where)


def _symbols(names: Sequence[str]) -> sp.Matrix:
    return sp.Matrix([sp.Symbol(n, real=True) for n in names])


def _vector_symbols(read: _Reader, entry: Mapping, key: str, default_symbol: str, frame: str, axes: str | None) -> list[str]:
    """The symbols of a 3-vector: its ``symbols`` list, or ``symbol`` expanded by component (``dv`` -> ``dv_n``...)."""
    if "symbols" in entry:
        return read.names(entry["symbols"], f"{key}.symbols", 3)
    symbol = str(entry.get("symbol", default_symbol))
    check_identifier(symbol, f"{read.at(key)}: {key}.symbol")
    return component_names(symbol, 3, frame, axes, f"{read.at(key)}: {key}")


def _axis_words(frame: str, axes: str | None) -> list[str]:
    return [_AXIS_WORDS[n.rsplit("_", 1)[1]] for n in component_names("a", 3, frame, axes)]


# -- the navigation state and its parameters --------------------------------------------
@dataclass
class _Declarations:
    """What the section declares, collected while reading it."""

    states: list[State]
    noises: list[Noise]
    parameters: dict[str, Parameter]  # by symbol: parameters the engine may put into the matrices
    measurement_biases: list[sp.Symbol] = field(default_factory=list)  # error states of aiding sensors
    measurement_bias_dynamics: dict[sp.Symbol, sp.Expr] = field(default_factory=dict)  # their rates (absent: random constant)
    places: dict[tuple[str, str], str] = field(default_factory=dict)  # (kind, name) -> the key that declared it
    vectors: dict[str, sp.Matrix] = field(default_factory=dict)  # vector parameters (shape: 3) by symbol: their components


def _navigation_state(read: _Reader, section: Mapping, frame: str, decl: _Declarations) -> dict[str, Any]:
    """Symbols of the computed attitude, velocity, position, sensed inputs and Earth quantities."""
    axes_words = _axis_words(frame, None)
    ecef = frame == "ECEF"
    attitude = read.mapping(section.get("attitude", {}), "navigation.attitude", ("symbols",))
    c = read.names(attitude["symbols"], "navigation.attitude.symbols", 9) if "symbols" in attitude else [f"c{i}{j}" for i in range(1, 4) for j in range(1, 4)]
    for k, s in enumerate(c):
        _offer(decl, s, s, "1", f"attitude matrix C_b^n (body to {frame}), row {k // 3 + 1} col {k % 3 + 1}")
    velocity = read.mapping(section.get("velocity", {}), "navigation.velocity", ("symbols", "symbol"))
    v = _vector_symbols(read, velocity, "navigation.velocity", "v", frame, None)
    for s, word in zip(v, axes_words):
        _offer(decl, s, f"velocity_{word}", "m/s", f"e-frame velocity {word} (with respect to the Earth)" if ecef else f"{word} ground speed")
    position = read.mapping(section.get("position", {}), "navigation.position", ("symbols",))
    default_position = ["r_x", "r_y", "r_z"] if ecef else ["L", "lambda_", "h"]
    p = read.names(position["symbols"], "navigation.position.symbols", 3) if "symbols" in position else default_position
    if ecef:
        position_words = [("position_x", "m", "e-frame position x (Earth's centre to the IMU)"), ("position_y", "m", "e-frame position y"),
                          ("position_z", "m", "e-frame position z (along the Earth's rotation axis)")]
    else:
        position_words = [("latitude", "rad", "geodetic latitude"), ("longitude", "rad", "longitude"), ("height", "m", "height above the ellipsoid")]
    for s, (name, unit, text) in zip(p, position_words):
        _offer(decl, s, name, unit, text)
    force = read.mapping(section.get("specific_force", {}), "navigation.specific_force", ("symbols", "symbol", "axes"))
    force_axes = read.choice(force.get("axes", "body"), "navigation.specific_force.axes", ("body", "navigation"))
    f = _vector_symbols(read, force, "navigation.specific_force", "f_b" if force_axes == "body" else "f", frame, "body" if force_axes == "body" else None)
    for s, word in zip(f, ("x", "y", "z") if force_axes == "body" else axes_words):
        name = f"body_specific_force_{word}" if force_axes == "body" else f"specific_force_{word}"
        _offer(decl, s, name, "m/s^2", f"sensed specific force along {'body ' if force_axes == 'body' else ''}{word}")
    rate = read.mapping(section.get("body_rate", {}), "navigation.body_rate", ("symbols", "symbol"))
    w = _vector_symbols(read, rate, "navigation.body_rate", "omega_b", frame, "body")
    for s, word in zip(w, "xyz"):
        _offer(decl, s, f"body_rate_{word}", "rad/s", f"sensed body rate w_ib^b about body {word}")
    earth = read.mapping(section.get("earth", {}), "navigation.earth", ("earth_rate", "meridian_radius", "prime_vertical_radius", "gravity", "earth_radius", "geocentric_radius"))
    defaults = {"earth_rate": "omega_ie", "meridian_radius": "R_M", "prime_vertical_radius": "R_N", "gravity": "g", "earth_radius": "R", "geocentric_radius": "r_e"}
    symbols = {}
    for key, default in defaults.items():
        symbols[key] = str(earth.get(key, default))
        check_identifier(symbols[key], f"{read.at(f'navigation.earth.{key}')}: navigation.earth.{key}")
    _offer(decl, symbols["earth_rate"], "earth_rate", "rad/s", "earth rotation rate (WGS-84, IS-GPS-200 value)", wgs84.GPS_EARTH_RATE)
    _offer(decl, symbols["meridian_radius"], "meridian_radius", "m", "meridian radius of curvature at the latitude (WGS-84)")
    _offer(decl, symbols["prime_vertical_radius"], "prime_vertical_radius", "m", "prime-vertical radius of curvature at the latitude (WGS-84)")
    _offer(decl, symbols["gravity"], "gravity", "m/s^2", "normal gravity at the position (WGS-84)")
    _offer(decl, symbols["earth_radius"], "earth_radius", "m", "radius of the spherical Earth", wgs84.SEMI_MAJOR_AXIS)
    _offer(decl, symbols["geocentric_radius"], "geocentric_radius", "m", "|r^e|: distance from the Earth's centre to the IMU (ecef gravity)")
    _offer(decl, "k_v1", "vertical_damping_gain_1", "1/s", "baro-damped vertical channel: height feedback gain k_1")
    _offer(decl, "k_v2", "vertical_damping_gain_2", "1/s^2", "baro-damped vertical channel: vertical-velocity feedback gain k_2")
    S = lambda name: sp.Symbol(name, real=True)  # noqa: E731
    return {
        "attitude": sp.Matrix(3, 3, [S(s) for s in c]),
        "velocity": _symbols(v),
        "position": _symbols(p),
        "specific_force": _symbols(f),
        "specific_force_axes": force_axes,
        "body_rate": _symbols(w),
        "earth": pt.EarthSymbols(*(S(symbols[k]) for k in ("earth_rate", "meridian_radius", "prime_vertical_radius", "gravity", "earth_radius", "geocentric_radius"))),
    }


def _offer(decl: _Declarations, symbol: str, name: str, unit: str, description: str, value: float | None = None) -> None:
    """A parameter the engine may use (declared in the model only if the result uses it); the file's own wins."""
    decl.parameters.setdefault(symbol, Parameter(name=name, symbol=symbol, unit=unit, description=description, value=value))


# -- error definition ------------------------------------------------------------------------
_ERROR_FORMS = {"attitude": pt.ATTITUDE_FORMS, "velocity": pt.VELOCITY_FORMS, "position": pt.POSITION_FORMS}
_ERROR_DEFAULTS = {"attitude": ("phi", "phi"), "velocity": ("difference", "dv"), "position": ("geodetic", "d")}


def _error_definition(
    read: _Reader, section: Mapping, frame: str, decl: _Declarations, mechanization: str = "local_level"
) -> tuple[pt.ErrorDefinition, list[sp.Symbol]]:
    """The declared navigation error states (in the file's order) and their definition."""
    errors = read.mapping(section.get("errors"), "navigation.errors", (*ERROR_QUANTITIES,))
    missing = [q for q in ERROR_QUANTITIES if q not in errors]
    if missing:
        raise ModelError(
            f"{read.at('navigation.errors')}: the error definition has no {', '.join(missing)} error; the {mechanization.replace('_', '-')} "
            f"mechanization integrates attitude, velocity and position, and each needs its error states"
        )
    own_forms = MECHANIZATION_ERROR_FORMS.get(mechanization) or {}
    chosen: dict[str, tuple[str, list[str]]] = {}
    order: list[sp.Symbol] = []
    approximations = section.get("approximations")
    horizontal = isinstance(approximations, list) and "no_vertical_channel" in [approximation_name(a) for a in approximations]
    for quantity in errors:
        key = f"navigation.errors.{quantity}"
        entry = read.mapping(errors[quantity], key, ("form", "symbols", "symbol", "names", "axes") if quantity == "attitude" else ("form", "symbols", "symbol", "names"))
        default_form = own_forms[quantity][0] if quantity in own_forms else _ERROR_DEFAULTS[quantity][0]
        form = read.choice(entry.get("form", default_form), f"{key}.form", _ERROR_FORMS[quantity])
        if quantity in own_forms and form not in own_forms[quantity]:
            raise ModelError(
                f"{read.at(f'{key}.form')}: {key}.form {form!r} is a local-level form (it follows the frame's turning with "
                f"position); the {mechanization} mechanization's {quantity} error is {', '.join(own_forms[quantity])}"
            )
        count = 2 if horizontal and quantity != "attitude" else 3  # no_vertical_channel: horizontal components only
        if quantity == "attitude":
            attitude_axes = read.choice(entry.get("axes", "navigation"), f"{key}.axes", pt.ATTITUDE_AXES)
            if attitude_axes == "body" and form != "rotation_vector":
                raise ModelError(f"{read.at(f'{key}.axes')}: {key}.axes body is for form rotation_vector (phi and psi are navigation-frame angles)")
        body_attitude = quantity == "attitude" and attitude_axes == "body"
        if "symbols" in entry:
            symbols = read.names(entry["symbols"], f"{key}.symbols", count)
        elif quantity == "position" and form == "geodetic":
            symbols = ["dL", "dlambda", "dh"][:count]
        else:
            default_symbol = "dr" if quantity == "position" else "theta" if body_attitude else _ERROR_DEFAULTS[quantity][1]
            symbols = _vector_symbols(read, entry, key, default_symbol, frame, "body" if body_attitude else None)[:count]
        if body_attitude:
            names = [f"attitude_error_{w}" for w in "xyz"]
        elif quantity == "attitude":
            names = [f"attitude_error_{w}" for w in _axis_words(frame, None)]
        elif quantity == "velocity":
            names = [f"velocity_error_{w}" for w in _axis_words(frame, None)]
        elif form == "geodetic":
            names = ["latitude_error", "longitude_error", "height_error"]
        else:
            names = [f"position_error_{w}" for w in _axis_words(frame, None)]
        names = read.names(entry["names"], f"{key}.names", count) if "names" in entry else names[:count]
        units = {"attitude": ["rad"] * 3, "velocity": ["m/s"] * 3, "position": ["rad", "rad", "m"] if form == "geodetic" else ["m"] * 3}[quantity][:count]
        label = {"phi": "phi-angle", "psi": "psi-angle", "rotation_vector": "rotation vector"}.get(form, form)
        if quantity == "attitude" and form == "rotation_vector":
            label += ", body axes" if body_attitude else f", {frame} axes"
        for name, symbol, unit in zip(names, symbols, units):
            decl.states.append(State(name=name, symbol=symbol, unit=unit, description=f"{quantity} error ({label}), computed minus true"))
            decl.places[("state", name)] = key
        chosen[quantity] = (form, symbols)
        order.extend(sp.Symbol(s, real=True) for s in symbols)
    S = lambda names: tuple(sp.Symbol(s, real=True) for s in names)  # noqa: E731
    definition = pt.ErrorDefinition(
        chosen["attitude"][0], S(chosen["attitude"][1]), chosen["velocity"][0], S(chosen["velocity"][1]),
        chosen["position"][0], S(chosen["position"][1]), attitude_axes,
    )
    return definition, order


# -- sensor errors and noises ------------------------------------------------------------------
def _sensor_errors(read: _Reader, section: Mapping, frame: str, decl: _Declarations, namespace: Callable[[], dict]) -> tuple[dict, dict, list[sp.Symbol]]:
    """(sensor-model parts by kind, dynamics of the sensor-error states, their symbols in order)."""
    raw = section.get("sensor_errors") or []
    if not isinstance(raw, list):
        raise ModelError(f"{read.at('navigation.sensor_errors')}: 'navigation.sensor_errors' must be a list")
    parts: dict[str, sp.Matrix] = {}
    dynamics: dict[sp.Symbol, sp.Expr] = {}
    order: list[sp.Symbol] = []
    for i, item in enumerate(raw):
        key = f"navigation.sensor_errors[{i}]"
        entry = read.mapping(item, key, ("of", "process", "symbols", "symbol", "names", "rate", "sigma", "psd", "noise_symbols", "noise_names"), ("of", "process"))
        kind = read.choice(entry["of"], f"{key}.of", SENSOR_ERROR_KINDS)
        if kind in parts and kind not in SUMMED_SENSOR_ERROR_KINDS:
            raise ModelError(f"{read.at(key)}: sensor error {kind!r} is declared twice (only {', '.join(SUMMED_SENSOR_ERROR_KINDS)} may be, as a sum)")
        process = read.choice(entry["process"], f"{key}.process", PROCESSES)
        if (process == "clock") != (kind == "receiver_clock"):
            raise ModelError(f"{read.at(f'{key}.process')}: process 'clock' is the receiver clock's (bias and drift), and only its")
        count = 2 if kind == "receiver_clock" else 3
        default_symbols = {"gyro_bias": "b_g", "gyro_scale_factor": "s_g", "accel_bias": "b_a", "accel_scale_factor": "s_a"}
        if kind == "receiver_clock":
            symbols = read.names(entry.get("symbols", ["clock_bias", "clock_drift"]), f"{key}.symbols", 2)
            names = read.names(entry.get("names", ["clock_bias_range", "clock_drift_range"]), f"{key}.names", 2)
            units, suffixes = ["m", "m/s"], ["bias", "drift"]
        else:
            symbols = _vector_symbols(read, entry, key, default_symbols[kind], frame, "body")
            names = read.names(entry["names"], f"{key}.names", 3) if "names" in entry else [f"{kind}_{a}" for a in "xyz"]
            units, suffixes = [_UNITS[kind]] * 3, list("xyz")
        state_symbols = [sp.Symbol(s, real=True) for s in symbols]
        for name, symbol, unit in zip(names, symbols, units):
            decl.states.append(State(name=name, symbol=symbol, unit=unit, description=f"{kind.replace('_', ' ')} ({process.replace('_', ' ')})"))
            decl.places[("state", name)] = key
        noise_symbols = read.names(entry["noise_symbols"], f"{key}.noise_symbols", count) if "noise_symbols" in entry else [f"w_{s}" for s in symbols]
        noise_names = read.names(entry["noise_names"], f"{key}.noise_names", count) if "noise_names" in entry else [f"{kind}_driving_noise_{a}" for a in suffixes]
        noises = [sp.Symbol(s, real=True) for s in noise_symbols]
        if process == "random_constant":
            rates = [sp.S.Zero] * count
        elif process == "gauss_markov":
            for field in ("rate", "sigma"):
                if field not in entry:
                    raise ModelError(f"{read.at(key)}: a Gauss-Markov sensor error needs {field!r} (inverse correlation time and steady-state sigma)")
            rate_texts = _per_component(read, entry["rate"], f"{key}.rate", count)  # one value, or one per axis
            sigma_texts = _per_component(read, entry["sigma"], f"{key}.sigma", count)
            parsed = [parse_expression(r, namespace(), f"{read.at(f'{key}.rate')}: {key}.rate") for r in rate_texts]
            psds = [f"2*({r})*({q})**2" for r, q in zip(rate_texts, sigma_texts)]
            rates = [-rate * s + w for rate, s, w in zip(parsed, state_symbols, noises)]
            _add_noises(decl, noise_names, noise_symbols, psds, units, kind, key)
        else:  # random_walk and clock: driven by white noise of the given PSD(s)
            if "psd" not in entry:
                raise ModelError(f"{read.at(key)}: a {process.replace('_', ' ')} sensor error needs 'psd'")
            psds = entry["psd"] if isinstance(entry["psd"], list) else [entry["psd"]] * count
            if len(psds) != count:
                raise ModelError(f"{read.at(f'{key}.psd')}: {key}.psd lists {len(psds)} values for {count} states")
            psds = [scalar_text(p, read.at(f"{key}.psd"), f"{key}.psd") for p in psds]
            rates = [w for w in noises] if process == "random_walk" else [state_symbols[1] + noises[0], noises[1]]
            _add_noises(decl, noise_names, noise_symbols, psds, units, kind, key)
        dynamics.update(zip(state_symbols, rates))
        parts[kind] = parts[kind] + sp.Matrix(state_symbols) if kind in parts else sp.Matrix(state_symbols)
        order.extend(state_symbols)
    return parts, dynamics, order


def _add_noises(
    decl: _Declarations, names: Sequence[str], symbols: Sequence[str], psds: Sequence[str], units: Sequence[str], kind: str, key: str
) -> None:
    """The white noises driving a sensor error's states (declared at ``key``)."""
    for name, symbol, psd, unit in zip(names, symbols, psds, units):
        decl.noises.append(Noise(name=name, symbol=symbol, unit=f"{unit}/sqrt(s)", psd=psd, description=f"drives the {kind.replace('_', ' ')}"))
        decl.places[("noise", name)] = key


def _sensor_noises(read: _Reader, section: Mapping, frame: str, decl: _Declarations) -> dict[str, tuple[sp.Matrix, str]]:
    """White noise of the gyros and accelerometers (``noises: {gyro: {...}, accel: {...}}``), in body or navigation axes."""
    raw = read.mapping(section.get("noises", {}), "navigation.noises", ("gyro", "accel"))
    out = {}
    words = {"gyro": ("gyro_white_noise", "w_g", "rad/sqrt(s)", "angle random walk"), "accel": ("accel_white_noise", "w_a", "m/s/sqrt(s)", "velocity random walk")}
    for sensor, value in raw.items():
        key = f"navigation.noises.{sensor}"
        entry = read.mapping(value, key, ("psd", "symbols", "symbol", "names", "axes"), ("psd",))
        axes = read.choice(entry.get("axes", "body"), f"{key}.axes", ("body", "navigation"))
        prefix, default, unit, text = words[sensor]
        symbols = _vector_symbols(read, entry, key, default, frame, "body" if axes == "body" else None)
        words_of = list("xyz") if axes == "body" else _axis_words(frame, None)
        names = read.names(entry["names"], f"{key}.names", 3) if "names" in entry else [f"{prefix}_{a}" for a in words_of]
        psds = _per_component(read, entry["psd"], f"{key}.psd", 3)  # one PSD, or one per axis
        for name, symbol, axis, psd in zip(names, symbols, words_of, psds):
            where = f"{axis}" if axes == "body" else f"resolved {axis}"
            decl.noises.append(Noise(name=name, symbol=symbol, unit=unit, psd=psd, description=f"{sensor} white noise {where} ({text})"))
            decl.places[("noise", name)] = key
        out[sensor] = (_symbols(symbols), axes)
    return out


# -- measurements -------------------------------------------------------------------------------
#: What each measurement kind gives: h(state, computed, mechanization), the scale (or None), the units,
#: the number of components and the measured side's extra term (or None).
_MeasurementParts = tuple[Callable, Callable | None, list[str], int, sp.Matrix | None]
def _lever_arm(read: _Reader, entry: Mapping, key: str, decl: _Declarations) -> sp.Matrix | None:
    """The antenna's lever arm l^b (body axes): ``lever_arm: {symbols: [...]}`` or ``{symbol: l}``."""
    if "lever_arm" not in entry:
        return None
    arm = read.mapping(entry["lever_arm"], f"{key}.lever_arm", ("symbols", "symbol"))
    symbols = _vector_symbols(read, arm, f"{key}.lever_arm", "l", "NED", "body")
    for s, axis in zip(symbols, "xyz"):
        _offer(decl, s, f"lever_arm_{axis}", "m", f"GNSS antenna position from the IMU along body {axis}")
    return _symbols(symbols)


def _component_order(read: _Reader, entry: Mapping, key: str, frame: str) -> tuple[list[int], list[int]]:
    """Indices and signs that take the frame's axis order to the ``axes`` the measurement lists."""
    words = _axis_words(frame, None)
    if "axes" not in entry:
        return [0, 1, 2], [1, 1, 1]
    axes = entry["axes"]
    opposite = {"down": "up", "up": "down"}
    if not isinstance(axes, list) or len(axes) not in (2, 3):
        raise ModelError(f"{read.at(f'{key}.axes')}: {key}.axes must list two or three of {', '.join(words)}")
    index, sign = [], []
    for a in axes:
        if a in words:
            index.append(words.index(a)), sign.append(1)
        elif a in opposite and opposite[a] in words:
            index.append(words.index(opposite[a])), sign.append(-1)
        else:
            raise ModelError(f"{read.at(f'{key}.axes')}: {key}.axes: {a!r} is not an axis of the {frame} frame ({', '.join(words)})")
    if len(set(index)) != len(index):
        raise ModelError(f"{read.at(f'{key}.axes')}: {key}.axes names an axis twice: {axes}")
    return index, sign


def _reorder(vector: sp.Matrix, index: Sequence[int], sign: Sequence[int]) -> sp.Matrix:
    """The listed components of a navigation-frame vector, in the listed order and sign."""
    return sp.Matrix([sign[k] * vector[index[k]] for k in range(len(index))])


def _measurements(
    read: _Reader, section: Mapping, frame: str, decl: _Declarations, clock: sp.Matrix | None, namespace: Callable[[], dict],
    mechanization: str = "local_level",
) -> tuple[list[pt.MeasurementFunction], list[Measurement]]:
    """The measurement functions for the engine and the Measurement declarations (names, variances)."""
    raw = section.get("measurements") or []
    if not isinstance(raw, list):
        raise ModelError(f"{read.at('navigation.measurements')}: 'navigation.measurements' must be a list")
    functions: list[pt.MeasurementFunction] = []
    declared: list[Measurement] = []
    fields = ("of", "form", "lever_arm", "axes", "symbols", "names", "variance", "line_of_sight", "expression", "difference", "units", "bias",
              "range", "satellite_velocity")
    for i, item in enumerate(raw):
        key = f"navigation.measurements[{i}]"
        entry = read.mapping(item, key, fields, ("of", "symbols", "variance"))
        kind = read.choice(entry["of"], f"{key}.of", MEASUREMENT_KINDS)
        arm = _lever_arm(read, entry, key, decl)
        measured_minus_computed = read.choice(entry.get("difference", "computed_minus_measured"), f"{key}.difference", ("computed_minus_measured", "measured_minus_computed")) == "measured_minus_computed"
        if kind in ("position", "velocity"):
            index, sign = _component_order(read, entry, key, frame)
            function, scale, units, count, extra = _kinematic_measurement(read, entry, key, kind, frame, arm, index, sign, mechanization)
        elif kind == "pseudorange":
            function, scale, units, count, extra = _pseudorange(read, entry, key, frame, clock, decl)
        elif kind == "pseudorange_rate":
            function, scale, units, count, extra = _pseudorange_rate(read, entry, key, frame, clock, decl)
        else:
            function, scale, units, count, extra = _expression_measurement(read, entry, key, namespace)
        bias = _measurement_bias(read, entry, key, count, units, decl, namespace)
        if bias is not None:  # measured = true + bias: the measured side's extra term
            extra = bias if extra is None else extra + bias
        symbols = read.names(entry["symbols"], f"{key}.symbols", count)
        names = read.names(entry["names"], f"{key}.names", count) if "names" in entry else [f"{kind}_difference_{symbol}" for symbol in symbols]
        variances = entry["variance"] if isinstance(entry["variance"], list) else [entry["variance"]] * count
        if len(variances) != count:
            raise ModelError(f"{read.at(f'{key}.variance')}: {key}.variance lists {len(variances)} values for {count} components")
        for name, symbol, variance, unit in zip(names, symbols, variances, units):
            text = scalar_text(variance, read.at(f"{key}.variance"), f"{key}.variance")
            declared.append(Measurement(name=name, symbol=symbol, unit=unit, expression="0", variance=text, description=f"{kind} measurement, {'measured minus computed' if measured_minus_computed else 'computed minus measured'}"))
            decl.places[("measurement", name)] = key
        functions.append(pt.MeasurementFunction(tuple(sp.Symbol(s, real=True) for s in symbols), function, scale, extra, measured_minus_computed))
    return functions, declared


def _measurement_bias(
    read: _Reader, entry: Mapping, key: str, count: int, units: Sequence[str], decl: _Declarations, namespace: Callable[[], dict] | None = None
) -> sp.Matrix | None:
    """An aiding sensor's own error, one state per component (``bias: {process, symbols, names, ...}``).

    E.g. the Doppler radar's velocity error of seed 000: measured = true + bias, so the
    computed-minus-measured difference carries minus the bias; the states follow the
    sensor-error states.  ``process``: ``random_constant`` (b' = 0, the default),
    ``gauss_markov`` (b' = -rate b + w, ``rate`` and steady-state ``sigma``, one value or
    one per component) or ``random_walk`` (b' = w, ``psd`` one value or one per component).
    """
    if "bias" not in entry:
        return None
    bias = read.mapping(entry["bias"], f"{key}.bias", ("process", "symbols", "names", "rate", "sigma", "psd", "noise_symbols", "noise_names"), ("symbols",))
    process = read.choice(bias.get("process", "random_constant"), f"{key}.bias.process", ("random_constant", "gauss_markov", "random_walk"))
    symbols = read.names(bias["symbols"], f"{key}.bias.symbols", count)
    names = read.names(bias["names"], f"{key}.bias.names", count) if "names" in bias else [f"{s}_bias" for s in symbols]
    for name, symbol, unit in zip(names, symbols, units):
        decl.states.append(State(name=name, symbol=symbol, unit=unit, description=f"aiding-sensor error ({process.replace('_', ' ')}): measured = true + bias"))
        decl.places[("state", name)] = f"{key}.bias"
    states = [sp.Symbol(s, real=True) for s in symbols]
    decl.measurement_biases.extend(states)
    if process != "random_constant":
        where = f"{key}.bias"
        noise_symbols = read.names(bias["noise_symbols"], f"{where}.noise_symbols", count) if "noise_symbols" in bias else [f"w_{s}" for s in symbols]
        noise_names = read.names(bias["noise_names"], f"{where}.noise_names", count) if "noise_names" in bias else [f"{n}_driving_noise" for n in names]
        noises = [sp.Symbol(n, real=True) for n in noise_symbols]
        if process == "gauss_markov":
            for needed in ("rate", "sigma"):
                if needed not in bias:
                    raise ModelError(f"{read.at(where)}: a Gauss-Markov measurement bias needs {needed!r} (inverse correlation time and steady-state sigma)")
            rates = _per_component(read, bias["rate"], f"{where}.rate", count)
            sigmas = _per_component(read, bias["sigma"], f"{where}.sigma", count)
            parsed = [parse_expression(r, (namespace or dict)(), f"{read.at(f'{where}.rate')}: {where}.rate") for r in rates]
            psds = [f"2*({r})*({q})**2" for r, q in zip(rates, sigmas)]
            decl.measurement_bias_dynamics.update({b: -r * b + w for b, r, w in zip(states, parsed, noises)})
        else:
            if "psd" not in bias:
                raise ModelError(f"{read.at(where)}: a random-walk measurement bias needs 'psd'")
            psds = _per_component(read, bias["psd"], f"{where}.psd", count)
            decl.measurement_bias_dynamics.update({b: w for b, w in zip(states, noises)})
        for name, symbol, psd, unit in zip(noise_names, noise_symbols, psds, units):
            decl.noises.append(Noise(name=name, symbol=symbol, unit=f"{unit}/sqrt(s)", psd=psd, description=f"drives the measurement bias ({process.replace('_', ' ')})"))
            decl.places[("noise", name)] = where
    return sp.Matrix(states)


def _per_component(read: _Reader, value: Any, key: str, count: int) -> list[str]:
    """One expression text per component: a list of ``count``, or one value for all of them."""
    values = value if isinstance(value, list) else [value] * count
    if len(values) != count:
        raise ModelError(f"{read.at(key)}: {key} lists {len(values)} values for {count} components")
    return [scalar_text(v, read.at(key), key) for v in values]


def _kinematic_measurement(
    read: _Reader, entry: Mapping, key: str, kind: str, frame: str, arm: sp.Matrix | None, index: Sequence[int], sign: Sequence[int],
    mechanization: str = "local_level",
) -> _MeasurementParts:
    """GNSS position (geodetic, or metres along the listed axes) or velocity of the antenna at lever arm l^b.

    Antenna position: p + D (C l), D = (1/(R_M + h), 1/((R_N + h) cos L), up) per
    metre at the computed position (so that in metres the lever arm is the
    Cartesian offset C l, as in Groves 2013 eq. 14.x); antenna velocity: v + C (w_ib x l) - w_ie x (C l) (Groves 2013, eqs. 14.x).
    """
    form = read.choice(entry.get("form", "metres" if kind == "position" else "navigation"), f"{key}.form", ("metres", "geodetic") if kind == "position" else ("navigation",))
    if kind == "position":
        def function(state: pt.NavigationState, computed: pt.NavigationState, mech: pt.Mechanization) -> sp.Matrix:
            if arm is None:
                return state.position
            # metres to (dL, dlambda, dh) at the computed position: the lever arm stays a Cartesian offset
            return state.position + mech.metres_inverse(computed.position) * (state.attitude * arm)

        if mechanization == "ecef":  # the position is already in metres along the e-frame axes
            if form == "geodetic":
                raise ModelError(f"{read.at(f'{key}.form')}: {key}: the ecef mechanization's position is r^e in metres (form: metres), not geodetic")
            return (lambda state, computed, mech: _reorder(function(state, computed, mech), index, sign)), None, ["m"] * len(index), len(index), None

        if form == "geodetic":
            if "axes" in entry:
                raise ModelError(f"{read.at(f'{key}.axes')}: {key}: geodetic position differences (dL, dlambda, dh) take no 'axes'")
            return function, None, ["rad", "rad", "m"], 3, None
        scale = lambda computed: sp.Matrix([[sign[k] * v for v in pt.metres_matrix(frame, computed.position).row(index[k])] for k in range(len(index))])  # noqa: E731
        return function, scale, ["m"] * len(index), len(index), None

    def velocity(state: pt.NavigationState, computed: pt.NavigationState, mech: pt.Mechanization) -> sp.Matrix:
        if arm is None:
            return _reorder(state.velocity, index, sign)
        if computed.body_rate is None:
            raise ModelError(f"{read.at(key)}: a lever arm on a velocity measurement needs the body rate")
        rate = state.body_rate if state.body_rate is not None else computed.body_rate
        antenna = state.velocity + state.attitude * rate.cross(arm) - mech.earth_rate(state).cross(state.attitude * arm)
        return _reorder(antenna, index, sign)

    return velocity, None, ["m/s"] * len(index), len(index), None


def _pseudorange(read: _Reader, entry: Mapping, key: str, frame: str, clock: sp.Matrix | None, decl: _Declarations) -> _MeasurementParts:
    """Pseudo-ranges to satellites along unit line-of-sight vectors e_k (navigation axes, receiver to satellite).

    The range from a point displaced by d (metres, navigation axes) from the
    computed receiver to satellite k at distance rho is
    |rho e_k - d| = sqrt(rho^2 - 2 rho e_k . d + d . d) (|e_k| = 1), exact and
    nonlinear in d; the measured pseudo-range adds the receiver clock bias.
    """
    sights = _lines_of_sight(read, entry, key, frame, clock, decl)
    distance = sp.Symbol("satellite_distance", positive=True)

    def ranges(state: pt.NavigationState, computed: pt.NavigationState, mech: pt.Mechanization) -> sp.Matrix:
        d = mech.metres(computed.position) * (state.position - computed.position)
        return sp.Matrix([sp.sqrt(distance**2 - 2 * distance * e.dot(d) + d.dot(d)) for e in sights])

    extra = sp.Matrix([clock[0]] * len(sights))
    return ranges, None, ["m"] * len(sights), len(sights), extra


def _lines_of_sight(read: _Reader, entry: Mapping, key: str, frame: str, clock: sp.Matrix | None, decl: _Declarations) -> list[sp.Matrix]:
    """The unit line-of-sight vectors of a pseudo-range (rate) measurement; it needs the receiver clock."""
    if clock is None:
        raise ModelError(f"{read.at(key)}: a pseudo-range measurement needs a receiver clock (sensor_errors: {{of: receiver_clock, ...}})")
    raw = entry.get("line_of_sight")
    if not isinstance(raw, list) or not raw:
        raise ModelError(f"{read.at(key)}: a pseudo-range measurement needs 'line_of_sight': one list of 3 symbols per satellite")
    words = _axis_words(frame, None)
    sights = []
    for k, item in enumerate(raw):
        names = read.names(item, f"{key}.line_of_sight[{k}]", 3)
        for name, word in zip(names, words):
            _offer(decl, name, f"line_of_sight_{word}_{k + 1}", "1", f"{word} component of the unit vector from the receiver to satellite {k + 1}")
        sights.append(_symbols(names))
    return sights


def _pseudorange_rate(read: _Reader, entry: Mapping, key: str, frame: str, clock: sp.Matrix | None, decl: _Declarations) -> _MeasurementParts:
    """Pseudo-range rates: the relative velocity of satellite k along the line of sight, plus the clock drift.

    From a point displaced by d (metres, navigation axes) from the computed
    receiver, the unit vector to satellite k at distance rho is
    u = (e_k - d/rho) / sqrt(1 - 2 e_k . d/rho + d . d/rho^2) (|e_k| = 1), and the
    rate is u . (v_k - v) with the satellite's velocity v_k (navigation axes,
    ``satellite_velocity``: required, ``zero`` for still satellites on purpose).  ``range`` names rho per satellite.
    """
    sights = _lines_of_sight(read, entry, key, frame, clock, decl)
    words = _axis_words(frame, None)
    ranges = read.names(entry.get("range"), f"{key}.range", len(sights)) if "range" in entry else [f"rho_{k + 1}" for k in range(len(sights))]
    for k, name in enumerate(ranges):
        _offer(decl, name, f"satellite_range_{k + 1}", "m", f"distance from the receiver to satellite {k + 1}")
    velocities = [sp.zeros(3, 1)] * len(sights)
    if "satellite_velocity" not in entry:
        raise ModelError(
            f"{read.at(key)}: a pseudo-range rate needs 'satellite_velocity' (one list of 3 symbols per satellite, navigation "
            f"axes): GNSS satellites move at about 3.9 km/s, and taking them as still makes the H entries about 50 times too "
            f"small; write 'satellite_velocity: zero' to assume still satellites on purpose"
        )
    if entry["satellite_velocity"] == "zero":
        pass  # still satellites, as the file says
    elif "satellite_velocity" in entry:
        raw = entry["satellite_velocity"]
        if not isinstance(raw, list) or len(raw) != len(sights):
            raise ModelError(f"{read.at(f'{key}.satellite_velocity')}: {key}.satellite_velocity must list one velocity per satellite ({len(sights)})")
        velocities = []
        for k, item in enumerate(raw):
            names = read.names(item, f"{key}.satellite_velocity[{k}]", 3)
            for name, word in zip(names, words):
                _offer(decl, name, f"satellite_velocity_{word}_{k + 1}", "m/s", f"{word} velocity of satellite {k + 1}")
            velocities.append(_symbols(names))
    rhos = [sp.Symbol(r, real=True) for r in ranges]

    def rates(state: pt.NavigationState, computed: pt.NavigationState, mech: pt.Mechanization) -> sp.Matrix:
        d = mech.metres(computed.position) * (state.position - computed.position)
        out = []
        for e, rho, v_sat in zip(sights, rhos, velocities):
            u = (e - d / rho) / sp.sqrt(1 - 2 * e.dot(d) / rho + d.dot(d) / rho**2)
            out.append(u.dot(v_sat - state.velocity))
        return sp.Matrix(out)

    extra = sp.Matrix([clock[1]] * len(sights))
    return rates, None, ["m/s"] * len(sights), len(sights), extra


def state_namespace(state: pt.NavigationState, mech: pt.Mechanization, frame: str, parameters: Mapping[str, sp.Symbol]) -> dict[str, Any]:
    """The names a written equation or measurement expression may use (README lists them)."""
    if hasattr(mech, "expression_names"):  # a mechanization with names of its own (ecef: C_b_e, v_e, r_e ...)
        return {**parameters, **mech.expression_names(state), **_body_names(state)}
    L, lam, h = state.position
    return {
        **_body_names(state),
        **parameters,
        "C_b_n": state.attitude,
        "v_n": state.velocity,
        "latitude": L,
        "longitude": lam,
        "height": h,
        "f_n": state.specific_force,
        "omega_ie_n": mech.earth_rate(state),
        "omega_en_n": mech.transport_rate(state),
        "g_n": pt.gravity_vector(frame, state.position),
        "R_M": pt.MeridianRadius(L),
        "R_N": pt.PrimeVerticalRadius(L),
    }


def _body_names(state: pt.NavigationState) -> dict[str, Any]:
    """The sensed inputs in body axes: the body rate w_ib^b (``omega_ib_b``) and the specific force f^b (``f_b``).

    The true state's body rate is the sensed one corrected by the gyro errors, so an
    odometer with a lever arm (``transpose(C_b_n)*v_n + cross(omega_ib_b, l)``) gets
    its gyro-bias columns; ``f_b`` is C^T f^n of the state.
    """
    names: dict[str, Any] = {"f_b": state.attitude.T * state.specific_force}
    if state.body_rate is not None:
        names["omega_ib_b"] = state.body_rate
    return names


def _expression_measurement(read: _Reader, entry: Mapping, key: str, namespace: Callable[[], dict]) -> _MeasurementParts:
    """A measurement written as an expression of the navigation state (:func:`state_namespace`)."""
    if "expression" not in entry:
        raise ModelError(f"{read.at(key)}: a measurement 'of: expression' needs 'expression'")
    text = scalar_text(entry["expression"], read.at(f"{key}.expression"), f"{key}.expression")
    where = f"{read.at(f'{key}.expression')}: {key}.expression"

    def function(state: pt.NavigationState, computed: pt.NavigationState, mech: pt.Mechanization) -> sp.Matrix:
        value = parse_vector_expression(text, state_namespace(state, mech, mech.frame, namespace()), where)
        return value if isinstance(value, sp.MatrixBase) else sp.Matrix([value])

    count = len(entry["symbols"]) if isinstance(entry.get("symbols"), list) else 1
    units = entry.get("units", ["1"] * count)
    if not isinstance(units, list) or len(units) != count:
        raise ModelError(f"{read.at(f'{key}.units')}: {key}.units must list {count} units")
    return function, None, [str(u) for u in units], count, None


def _written_equations(read: _Reader, section: Mapping, frame: str, namespace: Callable[[], dict]) -> dict[str, Callable]:
    """``equations:``: the velocity or position rate written out (vector expressions of :func:`state_namespace`)."""
    raw = section.get("equations")
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise ModelError(f"{read.at('navigation.equations')}: 'navigation.equations' must map a quantity to its rate")
    out = {}
    for quantity, text in raw.items():
        key = f"navigation.equations.{quantity}"
        if quantity not in WRITABLE_EQUATIONS:
            has = "has error states, but its kinematics are fixed (C' = C [w_ib x] - [w_in x] C)" if quantity == "attitude" else "has no error state"
            raise ModelError(
                f"{read.at(key)}: navigation equation for {quantity!r}, which {has}; equations may be written for "
                f"{', '.join(WRITABLE_EQUATIONS)} (error states: {', '.join(ERROR_QUANTITIES)})"
            )
        body = scalar_text(text, read.at(key), key)
        where = f"{read.at(key)}: {key}"

        def equation(state: pt.NavigationState, mech: pt.Mechanization, body: str = body, where: str = where) -> sp.Matrix:
            value = parse_vector_expression(body, state_namespace(state, mech, frame, namespace()), where)
            if not isinstance(value, sp.MatrixBase) or value.shape != (3, 1):
                raise ModelError(f"{where}: the rate must be a 3-vector, got {'a scalar' if not isinstance(value, sp.MatrixBase) else f'{value.rows}x{value.cols}'}")
            return value

        out[quantity] = equation
    return out


# -- the whole file --------------------------------------------------------------------------
def _user_parameters(read: _Reader, data: Mapping, decl: _Declarations, frame: str = "NED") -> list[str]:
    """The file's own ``parameters:`` (statistics, noise levels): always declared; returns their symbols.

    A parameter with ``shape: 3`` is a vector (``axes: body`` or the navigation frame, the default):
    one parameter per component (``lever`` -> ``lever_x, lever_y, lever_z`` in body axes), its
    ``value`` a list of three; expressions see it whole, by its symbol (:attr:`_Declarations.vectors`).
    """
    raw = data.get("parameters") or []
    if not isinstance(raw, list):
        raise ModelError(f"{read.at('parameters')}: 'parameters' must be a list of entries with a 'name'")
    symbols = []
    expanded = []
    for i, entry in enumerate(raw):
        key = f"parameters[{i}]"
        entry = read.mapping(entry, key, ("name", "symbol", "unit", "description", "value", "shape", "axes"), ("name",))
        if "shape" not in entry:
            if "axes" in entry:
                raise ModelError(f"{read.at(key)}: parameter {entry['name']!r}: 'axes' is for a vector parameter (shape: 3)")
            expanded.append((key, entry))
            continue
        if entry["shape"] not in (3, [3], [3, 1]):
            raise ModelError(f"{read.at(f'{key}.shape')}: parameter {entry['name']!r}: a navigation model's parameter is a scalar or a 3-vector (shape: 3), not {entry['shape']!r}")
        axes = read.choice(entry.get("axes", "navigation"), f"{key}.axes", ("body", "navigation"))
        name, symbol = str(entry["name"]), str(entry.get("symbol", entry["name"]))
        check_identifier(symbol, f"{read.at(key)}: parameter symbol")
        where = f"{read.at(key)}: parameter {name!r}"
        names = component_names(name, 3, frame, "body" if axes == "body" else None, where)
        parts = component_names(symbol, 3, frame, "body" if axes == "body" else None, where)
        values = entry.get("value")
        if values is not None and (not isinstance(values, list) or len(values) != 3):
            raise ModelError(f"{read.at(key)}: parameter {name!r} is a 3-vector: its value must list 3 numbers, got {values!r}")
        for k, (component, part) in enumerate(zip(names, parts)):
            item = {f: v for f, v in entry.items() if f not in ("shape", "axes", "value")}
            item.update(name=component, symbol=part)
            if values is not None:
                item["value"] = values[k]
            expanded.append((key, item))
        decl.vectors[symbol] = _symbols(parts)
    for key, entry in expanded:
        if "value" in entry and (isinstance(entry["value"], bool) or not isinstance(entry["value"], (int, float))):
            raise ModelError(f"{read.at(key)}: parameter {entry['name']!r} value {entry['value']!r} is not a number")
        fields = {k: (float(v) if k == "value" else str(v)) for k, v in entry.items()}
        if "value" in fields and "unit" in fields:  # given in deg/h, ppm, ug ...: converted to SI, and so is the unit
            fields["value"], fields["unit"] = declared_value(fields["value"], fields["unit"], f"{read.at(f'{key}.unit')}: {key}.unit")
        parameter = Parameter(**fields)
        check_identifier(parameter.symbol, f"{read.at(key)}: parameter symbol")
        decl.parameters[parameter.symbol] = parameter
        decl.places[("parameter", parameter.name)] = key
        symbols.append(parameter.symbol)
    return symbols


#: What an approximation's ``in:`` may name: the rows of F and G of a navigation quantity's error states, or H.
APPROXIMATION_SCOPES = ("attitude", "velocity", "position", "measurements")
#: Approximations that change the model's structure and so cannot be scoped to some rows.
UNSCOPED_APPROXIMATIONS = frozenset({"no_vertical_channel", "damped_vertical_channel"})


def approximation_name(entry: Any) -> Any:
    """The name of an ``approximations`` entry: the text itself, or the ``name`` of ``{name, in}``."""
    return entry.get("name") if isinstance(entry, dict) else entry


def _approximations(read: _Reader, section: Mapping, mechanization: str = "local_level") -> tuple[tuple[str, ...], dict[str, tuple[str, ...]]]:
    """The declared approximations' names in order, and the scope (``in:``) of those that have one."""
    raw = section.get("approximations") or []
    if not isinstance(raw, list):
        raise ModelError(f"{read.at('navigation.approximations')}: 'navigation.approximations' must be a list of names")
    scopes: dict[str, tuple[str, ...]] = {}
    names = []
    for i, entry in enumerate(raw):
        key = f"navigation.approximations[{i}]"
        if isinstance(entry, dict):
            read.mapping(entry, key, ("name", "in"), ("name", "in"))
            within = entry["in"] if isinstance(entry["in"], list) else [entry["in"]]
            for quantity in within:
                read.choice(quantity, f"{key}.in", APPROXIMATION_SCOPES)
            if entry["name"] in UNSCOPED_APPROXIMATIONS:
                raise ModelError(f"{read.at(key)}: approximation {entry['name']!r} changes the model's states and cannot be scoped ('in:')")
            if entry["name"] in pt.EQUATION_APPROXIMATIONS:
                raise ModelError(f"{read.at(key)}: approximation {entry['name']!r} changes the perturbed equations and cannot be scoped ('in:')")
            scopes[str(entry["name"])] = tuple(str(q) for q in within)
        names.append(approximation_name(entry))
    for i, name in enumerate(names):
        if not isinstance(name, str) or name not in pt.APPROXIMATIONS:
            raise ModelError(
                f"{read.at(f'navigation.approximations[{i}]')}: unknown approximation {name!r} "
                f"(known: {', '.join(sorted(pt.APPROXIMATIONS))})"
            )
    accepted = MECHANIZATION_APPROXIMATIONS.get(mechanization)
    for i, name in enumerate(names):
        if accepted is not None and name not in accepted:
            raise ModelError(
                f"{read.at(f'navigation.approximations[{i}]')}: approximation {name!r} does not apply to the {mechanization} "
                f"mechanization (it has: {', '.join(sorted(accepted)) or 'none'})"
            )
        if accepted is None and name == "no_gravity_gradient":
            raise ModelError(
                f"{read.at(f'navigation.approximations[{i}]')}: approximation 'no_gravity_gradient' is the ecef mechanization's "
                f"(local level: constant_gravity, free_vertical_channel)"
            )
    if len(set(names)) != len(names):
        raise ModelError(f"{read.at('navigation.approximations')}: an approximation is listed twice: {names}")
    return tuple(str(a) for a in names), scopes


def derive_navigation_model(data: Mapping[str, Any], lines: Mapping[str, str], filename: str) -> NavigationDerivation:
    """The ErrorModel of a file with a ``navigation:`` section (its ``check:`` is attached by the loader)."""
    read = _Reader(lines, filename)
    unknown = sorted(set(data) - NAVIGATION_TOP_KEYS)
    if unknown:
        derived = " (a model with a 'navigation:' section derives its states, noises, dynamics and measurements)" if unknown[0] in ("states", "noises", "dynamics", "measurements") else ""
        raise ModelError(f"{read.at(unknown[0])}: unknown key {unknown[0]!r}{derived} (expected one of {', '.join(sorted(NAVIGATION_TOP_KEYS))})")
    if "model" not in data:
        raise ModelError(f"{filename}: missing required key 'model'")
    if "frame" not in data:
        raise ModelError(f"{filename}: a model with a 'navigation:' section needs 'frame: NED' or 'frame: ENU' (its navigation frame)")
    frames = tuple(dict.fromkeys(f for fs in MECHANIZATION_FRAMES.values() for f in fs))
    frame = read.choice(free_text(data, "frame", dict(lines), filename), "frame", frames)
    section = read.mapping(data["navigation"], "navigation", SECTION_KEYS, ("errors",))
    mechanization = str(section.get("mechanization", "local_level"))
    mechanization_named(mechanization, f"{read.at('navigation.mechanization')}: navigation.mechanization")
    if frame not in MECHANIZATION_FRAMES[mechanization]:
        owner = next(m for m, fs in MECHANIZATION_FRAMES.items() if frame in fs)
        raise ModelError(
            f"{read.at('frame')}: frame {frame!r} is the {owner} mechanization's; the {mechanization} mechanization resolves its "
            f"vectors in {' or '.join(MECHANIZATION_FRAMES[mechanization])} (frame: {MECHANIZATION_FRAMES[mechanization][0]})"
        )
    _refuse_polar_scenario(read, data, lines, filename, mechanization)
    decl = _Declarations(states=[], noises=[], parameters={})
    own = _user_parameters(read, data, decl, frame)
    nav = _navigation_state(read, section, frame, decl)

    def namespace() -> dict[str, Any]:
        return {**{s: sp.Symbol(s, real=True) for s in own}, **decl.vectors}

    approximation_names, approximation_scopes = _approximations(read, section, mechanization)
    definition, navigation_order = _error_definition(read, section, frame, decl, mechanization)
    noises = _sensor_noises(read, section, frame, decl)
    parts, aux, sensor_order = _sensor_errors(read, section, frame, decl, namespace)
    functions, measurement_decls = _measurements(read, section, frame, decl, parts.get("receiver_clock"), namespace, mechanization)
    problem = pt.NavigationProblem(
        frame=frame, **nav, errors=definition,
        gyro=pt.InertialSensorErrors(parts.get("gyro_bias"), parts.get("gyro_scale_factor"), *noises.get("gyro", (None, "body"))),
        accelerometer=pt.InertialSensorErrors(parts.get("accel_bias"), parts.get("accel_scale_factor"), *noises.get("accel", (None, "body"))),
        state_order=tuple(navigation_order + sensor_order + decl.measurement_biases),
        auxiliary_dynamics={**aux, **{s: decl.measurement_bias_dynamics.get(s, sp.S.Zero) for s in decl.measurement_biases}},
        noises=tuple(sp.Symbol(n.symbol, real=True) for n in decl.noises),
        measurements=tuple(functions),
        approximations=approximation_names,
        approximation_scopes=approximation_scopes,
        equations=_written_equations(read, section, frame, namespace),
        mechanization_name=mechanization,
    )
    if problem.specific_force_axes == "navigation" and problem.accelerometer.scale_factor is not None:
        raise ModelError(f"{read.at('navigation.specific_force')}: accelerometer scale factors need the specific force in body axes (specific_force: {{axes: body}})")
    try:
        equations = pt.derive_error_equations(problem)
    except ModelError as exc:
        if str(exc).startswith(filename):  # already names its file and line
            raise
        raise ModelError(f"{read.at('navigation')}: model {data['model']!r}: {exc}") from None
    _refuse_measurements_of_removed_states(read, equations, functions)
    attitude_names = [s.name for s in decl.states if sp.Symbol(s.symbol, real=True) in definition.attitude_states]
    model = replace(
        _error_model(data, lines, filename, decl, own, equations, measurement_decls),
        neglected=equations.neglected, attitude_reset=pt.attitude_reset(definition, attitude_names),
    )
    return NavigationDerivation(model=model, equations=equations)


def _refuse_polar_scenario(read: _Reader, data: Mapping, lines: Mapping[str, str], filename: str, mechanization: str) -> None:
    """A local-level model whose check scenario is within POLAR_LIMIT_DEG of a pole is refused (1/cos L, tan L blow up)."""
    from modelgen.model.check_scenario import parse_check_section
    from modelgen.model.mechanizations.local_level import POLAR_LIMIT_DEG

    if mechanization != "local_level" or not isinstance(data.get("check"), Mapping):
        return
    latitude = parse_check_section(data["check"], lines, filename).get("parameters", {}).get("latitude")
    if latitude is None or abs(math.degrees(latitude)) <= POLAR_LIMIT_DEG:
        return
    raise ModelError(
        f"{read.at('check.parameters.latitude')}: check.parameters.latitude {math.degrees(latitude):.6g} deg is within "
        f"{90 - POLAR_LIMIT_DEG:g} deg of a pole: the local-level mechanization divides by cos(latitude) (longitude rate "
        f"1/cos L = {1 / math.cos(latitude):.0f}, transport rate tan L) and is refused beyond {POLAR_LIMIT_DEG:g} deg; "
        f"use 'mechanization: ecef' (no singularity at the poles)"
    )


def _refuse_measurements_of_removed_states(read: _Reader, equations: pt.ErrorEquations, functions: Sequence[pt.MeasurementFunction]) -> None:
    """A measurement that depends on a quantity with no error state (the vertical channel under no_vertical_channel) is refused."""
    rows = [(f"navigation.measurements[{i}]", symbol) for i, f in enumerate(functions) for symbol in f.symbols]
    for term in equations.neglected:
        if term.matrix == "H" and term.column == -1:
            key, symbol = rows[term.row]
            raise ModelError(
                f"{read.at(key)}: measurement {str(symbol)!r} depends on the vertical velocity or height, which have no "
                f"error state under no_vertical_channel (measure the horizontal components only)"
            )


def _error_model(data, lines, filename, decl: _Declarations, own: list[str], equations: pt.ErrorEquations, measurement_decls) -> ErrorModel:
    """The derived matrices written as the linear equations of an ordinary ErrorModel."""
    x = sp.Matrix(equations.states)
    w = sp.Matrix(equations.noises) if equations.noises else sp.zeros(0, 1)
    rhs = equations.F * x + (equations.G * w if equations.noises else sp.zeros(x.rows, 1))
    measured = equations.H * x if equations.H.rows else sp.zeros(0, 1)
    used = set().union(*(m.free_symbols for m in (equations.F, equations.G, equations.H)))
    used |= {s for n in decl.noises for s in sp.sympify(n.psd, locals=_locals(decl)).free_symbols}
    used |= {s for m in measurement_decls for s in sp.sympify(m.variance, locals=_locals(decl)).free_symbols}
    used_names = {str(s) for s in used}
    parameters = [p for symbol, p in decl.parameters.items() if symbol in own or symbol in used_names]
    measurements = [
        Measurement(name=m.name, symbol=m.symbol, unit=m.unit, description=m.description, variance=m.variance, expression=measured[i])
        for i, m in enumerate(measurement_decls)
    ]
    locations = _locations(lines, filename, decl, parameters, measurements)
    model = ErrorModel.build(
        name=str(data["model"]),
        states=decl.states,
        noises=decl.noises,
        parameters=parameters,
        dynamics={s.name: rhs[i] for i, s in enumerate(decl.states)},
        measurements=measurements,
        title=free_text(data, "title", dict(lines), filename),
        source=free_text(data, "source", dict(lines), filename),
        frame=free_text(data, "frame", dict(lines), filename),
        notes=[*notes_text(dict(data), dict(lines), filename), *approximation_notes(data, equations, decl)],
        locations=locations,
    )
    undeclared = [str(p.get("name")) for p in (data.get("parameters") or []) if isinstance(p, dict) and "unit" not in p]
    undeclared += [name for stem in undeclared for name in (f"{stem}_{a}" for a in ("x", "y", "z", "n", "e", "d", "u"))
                   if any(q.name == name for q in parameters)]  # a vector parameter's components
    check_model_units(model, locations, undeclared)
    return model


def _locations(lines: Mapping[str, str], filename: str, decl: _Declarations, parameters: Sequence[Parameter], measurements: Sequence[Measurement]) -> dict[str, str]:
    """file:line of every derived declaration (ErrorModel.build's keys), from the entry of the section that made it."""
    read = _Reader(lines, filename)
    derived = ("parameters", "states", "noises", "measurements", "dynamics")
    out = {k: v for k, v in lines.items() if not k.startswith(derived)}
    for kind, items, fields in (("state", decl.states, ()), ("noise", decl.noises, ("psd",)), ("parameter", parameters, ()),
                                ("measurement", measurements, ("expression", "variance"))):
        for i, item in enumerate(items):
            place = read.at(decl.places.get((kind, item.name), "navigation"))
            out[f"{kind}s[{i}]"] = place
            out.update({f"{kind}s[{i}].{f}": place for f in fields})
            if kind == "state":
                out[f"dynamics.{item.name}"] = place
    return out


def _locals(decl: _Declarations) -> dict[str, sp.Symbol]:
    """Symbols for reading PSD and variance texts (only to find which parameters they use; parsed properly by build)."""
    return {s: sp.Symbol(s, real=True) for s in decl.parameters}


def approximation_notes(data: Mapping, equations: pt.ErrorEquations, decl: _Declarations) -> list[str]:
    """One note per declared approximation: what it is and each term it dropped, with its size at the check scenario."""
    values = _check_values(data, decl)
    names = {"F": ([s.name for s in decl.states], [s.name for s in decl.states]),
             "G": ([s.name for s in decl.states], [n.name for n in decl.noises])}
    approximations = [approximation_name(a) for a in data["navigation"].get("approximations") or []]
    scopes = {approximation_name(a): a["in"] for a in data["navigation"].get("approximations") or [] if isinstance(a, dict)}
    notes = []
    for name in approximations:
        terms = [(t, shown) for t, shown in zip(equations.neglected, equations.readable) if t.approximation == name]
        parts = []
        for t, text in terms:
            rows, columns = names.get(t.matrix, (list(map(str, equations.measurements)), [s.name for s in decl.states]))
            size = term_magnitude(t.term, values)
            row = rows[t.row] if t.row >= 0 else "a removed vertical state"
            column = columns[t.column] if t.column >= 0 else "a removed vertical state"
            shown = f" = {text}" if len(text) <= 120 else ""
            parts.append(f"{t.matrix}[{row}, {column}]{shown}" + (f" ({size:.3g})" if size is not None else ""))
        dropped = "; ".join(parts) if parts else "no term in this model"
        within = scopes.get(name)
        scope = f", in the {', '.join(within) if isinstance(within, list) else within} rows only" if within else ""
        notes.append(f"Approximation {name} ({pt.APPROXIMATION_DESCRIPTIONS[name]}{scope}): dropped {dropped} (term, and its size at the check scenario).")
    if approximations and not values:
        notes.append("The sizes above need a check: scenario; this model has none.")
    return notes


def _check_values(data: Mapping, decl: _Declarations) -> dict[sp.Symbol, float]:
    """Parameter values of the file's check scenario (SI) and defaults, by symbol; empty without a scenario.

    Quantities an approximation removed from the model (so the scenario cannot
    give them) take their value at the scenario: height 0 and vertical velocity
    0 if absent, WGS-84 radii and normal gravity at the scenario's latitude.
    """
    from modelgen.model.check_scenario import parse_check_section
    from modelgen.model.navlib import normal_gravity

    values = {p.name: p.value for p in decl.parameters.values() if p.value is not None}
    if "check" in data:
        try:
            values.update(parse_check_section(data["check"], {}, "<check>").get("parameters", {}))
        except ModelError:
            pass  # the loader reports it with file:line
    values.setdefault("height", 0.0)
    for name in ("velocity_down", "velocity_up"):
        values.setdefault(name, 0.0)
    if "latitude" in values:
        radii = wgs84.earth_radii(values["latitude"])
        values.setdefault("meridian_radius", radii[0])
        values.setdefault("prime_vertical_radius", radii[1])
        values.setdefault("gravity", float(normal_gravity(values["latitude"], values["height"])))
    return {sp.Symbol(p.symbol, real=True): values[p.name] for p in decl.parameters.values() if p.name in values}


def term_magnitude(term: sp.Expr, values: Mapping[sp.Symbol, float]) -> float | None:
    """|term| at the given values, or None if a value is missing."""
    number = sp.sympify(term).xreplace({k: sp.Float(v) for k, v in values.items()})  # a bare symbol becomes a Float, not a float
    if number.free_symbols:
        return None
    return abs(float(number))


def neglected_terms(model: Any) -> tuple[pt.NeglectedTerm, ...]:
    """The terms the declared approximations dropped from a navigation model (carried on the model: ``model.neglected``).

    Its F, G, H entries plus these terms are the full first-order
    linearization (for the cross-check).  ``model`` is the ErrorModel or a
    derived model (which carries it); a model written as equations has none.
    """
    if isinstance(model, str):
        raise ModelError(f"neglected_terms takes the loaded model, not its name {model!r} (load_model({model!r}).neglected)")
    model = getattr(model, "model", model)  # a DerivedModel carries its ErrorModel
    return tuple(model.neglected)
