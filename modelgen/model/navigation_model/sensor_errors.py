"""The inertial sensors' errors: bias, scale-factor and receiver-clock states, and the white noises.

:func:`read_sensor_errors` reads ``navigation.sensor_errors`` (each a random
constant, Gauss-Markov process, random walk or the receiver clock), declaring
their states and driving noises; :func:`read_sensor_noises` reads the gyros'
and accelerometers' white noise (``navigation.noises``), in body or navigation axes.
"""

from __future__ import annotations

from typing import Callable, Mapping, Sequence

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.declaration import Noise, State
from modelgen.model.expression import parse_expression
from modelgen.model.file_fields import scalar_text
from modelgen.model.navigation_model.section import (
    PROCESSES,
    SENSOR_ERROR_KINDS,
    SUMMED_SENSOR_ERROR_KINDS,
    Declarations,
    SectionReader,
    axis_words,
    per_component,
    symbol_matrix,
    vector_symbols,
)


#: A summed bias (gyro_bias, accel_bias) is the sum of at most this many processes (the core paper's is two:
#: a random constant and a Markov process; each summand adds three states).
MAX_SUMMANDS = 4

_UNITS = {
    "gyro_bias": "rad/s", "gyro_scale_factor": "1", "accel_bias": "m/s^2", "accel_scale_factor": "1",
}


def read_sensor_errors(read: SectionReader, section: Mapping, frame: str, decl: Declarations, namespace: Callable[[], dict]) -> tuple[dict, dict, list[sp.Symbol]]:
    """(sensor-model parts by kind, dynamics of the sensor-error states, their symbols in order)."""
    raw = section.get("sensor_errors") or []
    if not isinstance(raw, list):
        raise ModelError(f"{read.at('navigation.sensor_errors')}: 'navigation.sensor_errors' must be a list")
    parts: dict[str, sp.Matrix] = {}
    dynamics: dict[sp.Symbol, sp.Expr] = {}
    order: list[sp.Symbol] = []
    declared: dict[str, str] = {}  # each state's and noise's name and symbol -> the entry that declared it
    summands: dict[str, int] = {}
    for i, item in enumerate(raw):
        key = f"navigation.sensor_errors[{i}]"
        entry = read.mapping(item, key, ("of", "process", "symbols", "symbol", "names", "rate", "sigma", "psd", "noise_symbols", "noise_names"), ("of", "process"))
        kind = read.choice(entry["of"], f"{key}.of", SENSOR_ERROR_KINDS)
        if kind in parts and kind not in SUMMED_SENSOR_ERROR_KINDS:
            raise ModelError(f"{read.at(key)}: sensor error {kind!r} is declared twice (only {', '.join(SUMMED_SENSOR_ERROR_KINDS)} may be, as a sum)")
        summands[kind] = summands.get(kind, 0) + 1
        if summands[kind] > MAX_SUMMANDS:
            raise ModelError(f"{read.at(key)}: sensor error {kind!r} is declared {summands[kind]} times; a bias is the sum "
                             f"of at most {MAX_SUMMANDS} processes")
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
            symbols = vector_symbols(read, entry, key, default_symbols[kind], frame, "body")
            names = read.names(entry["names"], f"{key}.names", 3) if "names" in entry else [f"{kind}_{a}" for a in "xyz"]
            units, suffixes = [_UNITS[kind]] * 3, list("xyz")
        state_symbols = [sp.Symbol(s, real=True) for s in symbols]
        for name, symbol, unit in zip(names, symbols, units):
            decl.states.append(State(name=name, symbol=symbol, unit=unit, description=f"{kind.replace('_', ' ')} ({process.replace('_', ' ')})"))
            decl.places[("state", name)] = key
        noise_symbols = read.names(entry["noise_symbols"], f"{key}.noise_symbols", count) if "noise_symbols" in entry else [f"w_{s}" for s in symbols]
        noise_names = read.names(entry["noise_names"], f"{key}.noise_names", count) if "noise_names" in entry else [f"{kind}_driving_noise_{a}" for a in suffixes]
        driven = process != "random_constant"  # a random constant has no driving noise: its noise names are unused
        _declare_once(read, key, declared, [*names, *symbols, *(noise_names + noise_symbols if driven else [])])
        noises = [sp.Symbol(s, real=True) for s in noise_symbols]
        if process == "random_constant":
            rates = [sp.S.Zero] * count
        elif process == "gauss_markov":
            for field in ("rate", "sigma"):
                if field not in entry:
                    raise ModelError(f"{read.at(key)}: a Gauss-Markov sensor error needs {field!r} (inverse correlation time and steady-state sigma)")
            rate_texts = per_component(read, entry["rate"], f"{key}.rate", count)  # one value, or one per axis
            sigma_texts = per_component(read, entry["sigma"], f"{key}.sigma", count)
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


def _declare_once(read: SectionReader, key: str, declared: dict[str, str], idents: Sequence[str]) -> None:
    """Refuse, at the entry itself, a name or symbol an earlier sensor error declared (a list of 1000
    repeats is not read and derived for minutes before it is refused)."""
    for ident in idents:
        if ident in declared:
            raise ModelError(f"{read.at(key)}: {ident!r} is declared twice ({declared[ident]} and {key}); give this "
                             "sensor error other symbols and names")
    for ident in idents:
        declared[ident] = key


def _add_noises(
    decl: Declarations, names: Sequence[str], symbols: Sequence[str], psds: Sequence[str], units: Sequence[str], kind: str, key: str
) -> None:
    """The white noises driving a sensor error's states (declared at ``key``)."""
    for name, symbol, psd, unit in zip(names, symbols, psds, units):
        decl.noises.append(Noise(name=name, symbol=symbol, unit=f"{unit}/sqrt(s)", psd=psd, description=f"drives the {kind.replace('_', ' ')}"))
        decl.places[("noise", name)] = key


def read_sensor_noises(read: SectionReader, section: Mapping, frame: str, decl: Declarations) -> dict[str, tuple[sp.Matrix, str]]:
    """White noise of the gyros and accelerometers (``noises: {gyro: {...}, accel: {...}}``), in body or navigation axes."""
    raw = read.mapping(section.get("noises", {}), "navigation.noises", ("gyro", "accel"))
    out = {}
    words = {"gyro": ("gyro_white_noise", "w_g", "rad/sqrt(s)", "angle random walk"), "accel": ("accel_white_noise", "w_a", "m/s/sqrt(s)", "velocity random walk")}
    for sensor, value in raw.items():
        key = f"navigation.noises.{sensor}"
        entry = read.mapping(value, key, ("psd", "symbols", "symbol", "names", "axes"), ("psd",))
        axes = read.choice(entry.get("axes", "body"), f"{key}.axes", ("body", "navigation"))
        prefix, default, unit, text = words[sensor]
        symbols = vector_symbols(read, entry, key, default, frame, "body" if axes == "body" else None)
        words_of = list("xyz") if axes == "body" else axis_words(frame, None)
        names = read.names(entry["names"], f"{key}.names", 3) if "names" in entry else [f"{prefix}_{a}" for a in words_of]
        psds = per_component(read, entry["psd"], f"{key}.psd", 3)  # one PSD, or one per axis
        for name, symbol, axis, psd in zip(names, symbols, words_of, psds):
            where = f"{axis}" if axes == "body" else f"resolved {axis}"
            decl.noises.append(Noise(name=name, symbol=symbol, unit=unit, psd=psd, description=f"{sensor} white noise {where} ({text})"))
            decl.places[("noise", name)] = key
        out[sensor] = (symbol_matrix(symbols), axes)
    return out
