"""The measurements as functions of the navigation state, and their declarations.

:func:`read_measurements` reads ``navigation.measurements``: each kind gives the
engine a function h(state, computed, mechanization) (GNSS position and velocity
at a lever arm here; pseudo-ranges in :mod:`.pseudoranges`; expressions in
:mod:`.expressions`), and the file its names, units and variances; an aiding
sensor's own error (``bias:``) becomes states of the model.
"""

from __future__ import annotations

from typing import Callable, Mapping, Sequence

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.declaration import Measurement, Noise, State
from modelgen.model.expression import parse_expression
from modelgen.model.file_fields import scalar_text
from modelgen.model.mechanizations.local_level import metres_matrix
from modelgen.model.navigation_model.expressions import expression_measurement
from modelgen.model.navigation_model.pseudoranges import pseudorange_measurement, pseudorange_rate_measurement
from modelgen.model.navigation_model.section import (
    MEASUREMENT_KINDS,
    Declarations,
    MeasurementParts,
    SectionReader,
    axis_words,
    offer,
    per_component,
    symbol_matrix,
    vector_symbols,
)
from modelgen.model.perturbation.problem import MeasurementFunction, Mechanization, NavigationState


def _lever_arm(read: SectionReader, entry: Mapping, key: str, decl: Declarations) -> sp.Matrix | None:
    """The antenna's lever arm l^b (body axes): ``lever_arm: {symbols: [...]}`` or ``{symbol: l}``."""
    if "lever_arm" not in entry:
        return None
    arm = read.mapping(entry["lever_arm"], f"{key}.lever_arm", ("symbols", "symbol"))
    symbols = vector_symbols(read, arm, f"{key}.lever_arm", "l", "NED", "body")
    for s, axis in zip(symbols, "xyz"):
        offer(decl, s, f"lever_arm_{axis}", "m", f"GNSS antenna position from the IMU along body {axis}")
    return symbol_matrix(symbols)


def _component_order(read: SectionReader, entry: Mapping, key: str, frame: str) -> tuple[list[int], list[int]]:
    """Indices and signs that take the frame's axis order to the ``axes`` the measurement lists."""
    words = axis_words(frame, None)
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


def read_measurements(
    read: SectionReader, section: Mapping, frame: str, decl: Declarations, clock: sp.Matrix | None, namespace: Callable[[], dict],
    mechanization: str = "local_level",
) -> tuple[list[MeasurementFunction], list[Measurement]]:
    """The measurement functions for the engine and the Measurement declarations (names, variances)."""
    raw = section.get("measurements") or []
    if not isinstance(raw, list):
        raise ModelError(f"{read.at('navigation.measurements')}: 'navigation.measurements' must be a list")
    functions: list[MeasurementFunction] = []
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
            function, scale, units, count, extra = pseudorange_measurement(read, entry, key, frame, clock, decl)
        elif kind == "pseudorange_rate":
            function, scale, units, count, extra = pseudorange_rate_measurement(read, entry, key, frame, clock, decl)
        else:
            function, scale, units, count, extra = expression_measurement(read, entry, key, namespace)
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
        functions.append(MeasurementFunction(tuple(sp.Symbol(s, real=True) for s in symbols), function, scale, extra, measured_minus_computed))
    return functions, declared


def _measurement_bias(
    read: SectionReader, entry: Mapping, key: str, count: int, units: Sequence[str], decl: Declarations, namespace: Callable[[], dict] | None = None
) -> sp.Matrix | None:
    """An aiding sensor's own error, one state per component (``bias: {process, symbols, names, ...}``).

    E.g. the Doppler radar's velocity error of the core paper: measured = true + bias, so the
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
            rates = per_component(read, bias["rate"], f"{where}.rate", count)
            sigmas = per_component(read, bias["sigma"], f"{where}.sigma", count)
            parsed = [parse_expression(r, (namespace or dict)(), f"{read.at(f'{where}.rate')}: {where}.rate") for r in rates]
            psds = [f"2*({r})*({q})**2" for r, q in zip(rates, sigmas)]
            decl.measurement_bias_dynamics.update({b: -r * b + w for b, r, w in zip(states, parsed, noises)})
        else:
            if "psd" not in bias:
                raise ModelError(f"{read.at(where)}: a random-walk measurement bias needs 'psd'")
            psds = per_component(read, bias["psd"], f"{where}.psd", count)
            decl.measurement_bias_dynamics.update({b: w for b, w in zip(states, noises)})
        for name, symbol, psd, unit in zip(noise_names, noise_symbols, psds, units):
            decl.noises.append(Noise(name=name, symbol=symbol, unit=f"{unit}/sqrt(s)", psd=psd, description=f"drives the measurement bias ({process.replace('_', ' ')})"))
            decl.places[("noise", name)] = where
    return sp.Matrix(states)


def _kinematic_measurement(
    read: SectionReader, entry: Mapping, key: str, kind: str, frame: str, arm: sp.Matrix | None, index: Sequence[int], sign: Sequence[int],
    mechanization: str = "local_level",
) -> MeasurementParts:
    """GNSS position (geodetic, or metres along the listed axes) or velocity of the antenna at lever arm l^b.

    Antenna position: p + D(p) (C l), D = (1/(R_M + h), 1/((R_N + h) cos L), up) per
    metre at the state's own position p (so that in metres the lever arm is the
    Cartesian offset C l, as in Groves 2013 eq. 14.x); its variation with the
    position error, O(l/R), stays in H unless the model declares
    ``lever_arm_at_computed_position`` (D at the computed position); antenna velocity: v + C (w_ib x l) - w_ie x (C l) (Groves 2013, eqs. 14.x).
    """
    form = read.choice(entry.get("form", "metres" if kind == "position" else "navigation"), f"{key}.form", ("metres", "geodetic") if kind == "position" else ("navigation",))
    if kind == "position":
        def function(state: NavigationState, computed: NavigationState, mech: Mechanization) -> sp.Matrix:
            if arm is None:
                return state.position
            # metres to (dL, dlambda, dh) at the state's own position (exact to first order in l/R), or at
            # the computed one under lever_arm_at_computed_position (the O(l/R) dR/dL and d/dh terms dropped)
            at = state.position if state.lever_arm_position is None else state.lever_arm_position
            return state.position + mech.metres_inverse(at) * (state.attitude * arm)

        if mechanization == "wander_azimuth":  # metres along the computed wander axes (the chart has no geodetic form)
            if form == "geodetic":
                raise ModelError(f"{read.at(f'{key}.form')}: {key}: the wander_azimuth position has no latitude and longitude (form: metres, along the wander axes)")

            def wander_position(state: NavigationState, computed: NavigationState, mech: Mechanization) -> sp.Matrix:
                antenna = mech.displacement(state, computed)
                if arm is not None:  # the lever arm C l of the state, resolved in the computed wander axes
                    antenna = antenna + mech.to_computed_axes(state, computed, state.attitude * arm)
                return _reorder(antenna, index, sign)

            return wander_position, None, ["m"] * len(index), len(index), None

        if mechanization == "ecef":  # the position is already in metres along the e-frame axes
            if form == "geodetic":
                raise ModelError(f"{read.at(f'{key}.form')}: {key}: the ecef mechanization's position is r^e in metres (form: metres), not geodetic")
            return (lambda state, computed, mech: _reorder(function(state, computed, mech), index, sign)), None, ["m"] * len(index), len(index), None

        if form == "geodetic":
            if "axes" in entry:
                raise ModelError(f"{read.at(f'{key}.axes')}: {key}: geodetic position differences (dL, dlambda, dh) take no 'axes'")
            return function, None, ["rad", "rad", "m"], 3, None
        scale = lambda computed: sp.Matrix([[sign[k] * v for v in metres_matrix(frame, computed.position).row(index[k])] for k in range(len(index))])  # noqa: E731
        return function, scale, ["m"] * len(index), len(index), None

    wander = mechanization == "wander_azimuth"

    def velocity(state: NavigationState, computed: NavigationState, mech: Mechanization) -> sp.Matrix:
        if arm is None:
            antenna = state.velocity
        else:
            if computed.body_rate is None:
                raise ModelError(f"{read.at(key)}: a lever arm on a velocity measurement needs the body rate")
            rate = state.body_rate if state.body_rate is not None else computed.body_rate
            antenna = state.velocity + state.attitude * rate.cross(arm) - mech.earth_rate(state).cross(state.attitude * arm)
        if wander:  # resolved in the computed wander axes, as the INS resolves the GNSS velocity
            antenna = mech.to_computed_axes(state, computed, antenna)
        return _reorder(antenna, index, sign)

    return velocity, None, ["m/s"] * len(index), len(index), None
