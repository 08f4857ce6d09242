"""The ``navigation:`` section's vocabulary and the reader every part of it uses.

The keys a navigation model file and its section may have, the quantities,
sensor errors, processes and measurement kinds it may name; :class:`SectionReader`
(typed access with file:line in every message); the generated component names
of vectors (``dv`` -> ``dv_n, dv_e, dv_d``; the e-frame's ``_x, _y, _z``); and
:class:`Declarations`, the states, noises and parameters collected while the
section is read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.declaration import Noise, Parameter, State, check_identifier
from modelgen.model.file_fields import scalar_text
from modelgen.model.vectors import component_names as _vector_component_names


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
#: Sensor errors that may be declared more than once: the bias is then their sum (the core paper eq. (2): gyro
#: drift = random constant + first-order Markov process).
SUMMED_SENSOR_ERROR_KINDS = ("gyro_bias", "accel_bias")
#: Processes of sensor-error states.
PROCESSES = ("random_constant", "gauss_markov", "random_walk", "clock")
#: Measurement kinds: what a measurement observes.
MEASUREMENT_KINDS = ("position", "velocity", "pseudorange", "pseudorange_rate", "expression")

_AXIS_WORDS = {"n": "north", "e": "east", "d": "down", "u": "up", "x": "x", "y": "y", "z": "z"}

class SectionReader:
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
_NAVIGATION_ONLY_FRAMES = {"ECEF": ("x", "y", "z"), "WANDER": ("x", "y", "z")}


def component_names(name: str, shape: int, frame: str, axes: str | None = None, where: str = "") -> list[str]:
    """:func:`modelgen.model.vectors.component_names`, and the e-frame's ``_x, _y, _z`` for a navigation-frame vector."""
    if axes is None and frame in _NAVIGATION_ONLY_FRAMES and shape == 3:
        return [f"{name}_{a}" for a in _NAVIGATION_ONLY_FRAMES[frame]]
    return _vector_component_names(name, shape, frame, axes, where)


def symbol_matrix(names: Sequence[str]) -> sp.Matrix:
    return sp.Matrix([sp.Symbol(n, real=True) for n in names])


def vector_symbols(read: SectionReader, entry: Mapping, key: str, default_symbol: str, frame: str, axes: str | None) -> list[str]:
    """The symbols of a 3-vector: its ``symbols`` list, or ``symbol`` expanded by component (``dv`` -> ``dv_n``...)."""
    if "symbols" in entry:
        return read.names(entry["symbols"], f"{key}.symbols", 3)
    symbol = str(entry.get("symbol", default_symbol))
    check_identifier(symbol, f"{read.at(key)}: {key}.symbol")
    return component_names(symbol, 3, frame, axes, f"{read.at(key)}: {key}")


def axis_words(frame: str, axes: str | None) -> list[str]:
    return [_AXIS_WORDS[n.rsplit("_", 1)[1]] for n in component_names("a", 3, frame, axes)]


@dataclass
class Declarations:
    """What the section declares, collected while reading it."""

    states: list[State]
    noises: list[Noise]
    parameters: dict[str, Parameter]  # by symbol: parameters the engine may put into the matrices
    measurement_biases: list[sp.Symbol] = field(default_factory=list)  # error states of aiding sensors
    measurement_bias_dynamics: dict[sp.Symbol, sp.Expr] = field(default_factory=dict)  # their rates (absent: random constant)
    places: dict[tuple[str, str], str] = field(default_factory=dict)  # (kind, name) -> the key that declared it
    vectors: dict[str, sp.Matrix] = field(default_factory=dict)  # vector parameters (shape: 3) by symbol: their components


def offer(decl: Declarations, symbol: str, name: str, unit: str, description: str, value: float | None = None) -> None:
    """A parameter the engine may use (declared in the model only if the result uses it); the file's own wins."""
    decl.parameters.setdefault(symbol, Parameter(name=name, symbol=symbol, unit=unit, description=description, value=value))


def per_component(read: SectionReader, value: Any, key: str, count: int) -> list[str]:
    """One expression text per component: a list of ``count``, or one value for all of them."""
    values = value if isinstance(value, list) else [value] * count
    if len(values) != count:
        raise ModelError(f"{read.at(key)}: {key} lists {len(values)} values for {count} components")
    return [scalar_text(v, read.at(key), key) for v in values]


#: What each measurement kind gives: h(state, computed, mechanization), the scale (or None), the units,
#: the number of components and the measured side's extra term (or None).
MeasurementParts = tuple[Callable, Callable | None, list[str], int, sp.Matrix | None]
