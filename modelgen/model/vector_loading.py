"""Reading a model file that declares 3-vectors, 3x3 matrices or definitions.

A model file takes this path (from :func:`modelgen.model.loading.load_model_text`)
when an entry has a ``shape`` or ``axes``, when it has a ``definitions:``
section, or when an expression calls a function of the navigation library
(:mod:`modelgen.model.navlib`) or a vector function the model does not
declare as a name of its own.  Every vector is expanded into its scalar
components (:func:`modelgen.model.vectors.component_names`), every
expression is evaluated with shapes checked
(:func:`modelgen.model.vectors.parse_vector_expression`), and the result is
handed to :meth:`ErrorModel.build` as an ordinary scalar model: derivation,
code generation and the checks see no difference.  Each error still names the
file and line of the entry it is about.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Measurement, Noise, Parameter, State, check_identifier
from modelgen.model.file_fields import as_float, free_text, is_number, notes_text, scalar_text
from modelgen.model.unit_check import check_model_units
from modelgen.model.units import declared_value
from modelgen.model.vectors import (
    Value,
    component_names,
    evaluate_definitions,
    is_matrix,
    library_constants,
    library_functions,
    normalize_shape,
    parse_vector_expression,
    shape_text,
)

#: Fields each kind of entry may have, besides ``shape`` and ``axes``.
_FIELDS: dict[str, frozenset[str]] = {
    "states": frozenset({"name", "symbol", "unit", "description"}),
    "noises": frozenset({"name", "symbol", "unit", "description", "psd"}),
    "parameters": frozenset({"name", "symbol", "unit", "description", "value"}),
    "measurements": frozenset({"name", "symbol", "unit", "description", "expression", "variance"}),
}
_KIND = {"states": "state", "noises": "noise", "parameters": "parameter", "measurements": "measurement"}
#: Words for the component suffixes, used in the components' descriptions.
_AXIS_WORDS = {"n": "north", "e": "east", "d": "down", "u": "up", "x": "x", "y": "y", "z": "z"}
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def uses_vector_syntax(data: Mapping[str, Any]) -> bool:
    """Whether a parsed model file needs this path (see module doc); a malformed file answers False."""
    if "definitions" in data:
        return True
    declared: set[str] = set()
    texts: list[str] = []
    for kind in _FIELDS:
        entries = data.get(kind)
        for entry in entries if isinstance(entries, list) else []:
            if not isinstance(entry, dict):
                continue
            if "shape" in entry or "axes" in entry:
                return True
            declared.update(str(entry.get(k)) for k in ("name", "symbol") if k in entry)
            texts.extend(str(entry[k]) for k in ("psd", "expression", "variance") if isinstance(entry.get(k), str))
    dynamics = data.get("dynamics")
    if isinstance(dynamics, dict):
        texts.extend(v for v in dynamics.values() if isinstance(v, str))
    mentioned = {name for text in texts for name in _IDENTIFIER.findall(text)}
    library = set(library_functions()) | set(library_constants())
    return bool((mentioned & library) - declared)


@dataclass(frozen=True)
class _Declared:
    """One entry of the file, vector or scalar, with its components."""

    kind: str  # "states", "noises", "parameters", "measurements"
    index: int  # position in the file's list
    entry: Mapping[str, Any]
    shape: tuple[int, int]
    names: tuple[str, ...]  # component names, in storage order
    symbols: tuple[str, ...]  # component symbols, in the same order
    descriptions: tuple[str, ...]
    place: str  # file:line

    @property
    def name(self) -> str:
        return str(self.entry["name"])

    @property
    def symbol(self) -> str:
        return str(self.entry.get("symbol") or self.entry["name"])

    @property
    def what(self) -> str:
        """``state 'dv'`` or ``3x1 state 'dv'``, for messages."""
        prefix = "" if self.shape == (1, 1) else f"{shape_text(self.shape)} "
        return f"{prefix}{_KIND[self.kind]} {self.name!r}"

    def value(self) -> Value:
        """The entry in expressions: its symbol, or the Matrix of its component symbols."""
        symbols = [sp.Symbol(s, real=True) for s in self.symbols]
        return symbols[0] if self.shape == (1, 1) else sp.Matrix(self.shape[0], self.shape[1], symbols)


def _declare(kind: str, index: int, entry: Any, frame: str, lines: Mapping[str, str], filename: str) -> _Declared:
    """Validate one entry and name its components."""
    place = lines.get(f"{kind}[{index}]", filename)
    if not isinstance(entry, dict) or "name" not in entry:
        raise ModelError(f"{place}: {kind}[{index}] must be a mapping with a 'name'")
    allowed = _FIELDS[kind] | {"shape", "axes"}
    extra = sorted(set(entry) - allowed)
    if extra:
        raise ModelError(f"{place}: {kind}[{index}] has unknown field {extra[0]!r} (allowed: {sorted(allowed)})")
    what = f"{_KIND[kind]} {entry['name']!r}"
    for text_field in ("unit", "description", "axes"):
        if isinstance(entry.get(text_field), (list, dict)):
            raise ModelError(f"{place}: {kind}[{index}] {text_field!r} must be text, not a list or mapping")
    shape = normalize_shape(entry.get("shape"), f"{lines.get(f'{kind}[{index}].shape', place)}: {what}")
    if "axes" in entry and shape != (3, 1):
        raise ModelError(f"{lines.get(f'{kind}[{index}].axes', place)}: {what} has 'axes', which only a 3-vector (shape: 3) takes")
    for label in ("name", "symbol"):
        if label in entry:
            check_identifier(entry[label], f"{place}: {what} {label}")
    name, symbol = str(entry["name"]), str(entry.get("symbol") or entry["name"])
    axes = None if entry.get("axes") is None else str(entry["axes"])
    names = component_names(name, shape, frame, axes, f"{place}: {what}")
    symbols = component_names(symbol, shape, frame, axes, f"{place}: {what}")
    description = str(entry.get("description") or "")
    if shape == (1, 1):
        descriptions = [description]
    elif shape == (3, 1):
        words = [_AXIS_WORDS[n.rsplit("_", 1)[1]] for n in names]
        descriptions = [f"{description} ({w} component)" if description else f"{w} component" for w in words]
    else:
        cells = [f"row {i}, column {j}" for i in range(1, 4) for j in range(1, 4)]
        descriptions = [f"{description} ({c})" if description else c for c in cells]
    if kind == "noises" and "psd" not in entry:
        raise ModelError(f"{place}: {what} has no 'psd' (its power spectral density)")
    if kind == "measurements" and "expression" not in entry:
        raise ModelError(f"{place}: {what} has no 'expression'")
    return _Declared(kind, index, entry, shape, tuple(names), tuple(symbols), tuple(descriptions), place)


def _check_unique(declared: list[_Declared]) -> None:
    """Refuse a name or symbol (vector stem or component) that two entries both use."""
    seen: dict[str, tuple[_Declared, str]] = {}
    for item in declared:
        idents = {item.name: f"{item.what}", item.symbol: f"{item.what}"}
        if item.shape != (1, 1):
            for n, s in zip(item.names, item.symbols):
                idents[n] = f"component {n!r} of {item.what}"
                idents[s] = f"component {s!r} of {item.what}"
        for ident, origin in idents.items():
            if ident in seen and seen[ident][0] is not item:
                other, other_origin = seen[ident]
                raise ModelError(
                    f"{item.place}: {origin} is named {ident!r}, which {other_origin} at {other.place} already uses"
                    if origin != item.what
                    else f"{item.place}: {item.what} collides with {other_origin} at {other.place} (both named {ident!r})"
                )
            seen.setdefault(ident, (item, origin))


def _parameter_values(item: _Declared, lines: Mapping[str, str]) -> list[float | None]:
    """The default ``value`` of each component: a number, a list of 3, or 3 lists of 3."""
    if "value" not in item.entry:
        return [None] * len(item.names)
    raw = item.entry["value"]
    place = lines.get(f"parameters[{item.index}].value", item.place)
    if item.shape == (1, 1):
        if not is_number(raw):
            raise ModelError(f"{place}: parameter {item.name!r} value {raw!r} is not a number")
        return [as_float(raw, place)]
    rows, columns = item.shape
    flat: list[Any] = []
    if isinstance(raw, list) and len(raw) == rows and columns == 1:
        flat = list(raw)
    elif isinstance(raw, list) and len(raw) == rows and all(isinstance(r, list) and len(r) == columns for r in raw):
        flat = [v for r in raw for v in r]
    expected = "a list of 3 numbers" if columns == 1 else "a list of 3 rows of 3 numbers ([[..], [..], [..]])"
    if not flat or not all(is_number(v) for v in flat):
        raise ModelError(f"{place}: {item.what} value must be {expected}, got {raw!r}")
    return [as_float(v, place) for v in flat]


def _per_component_texts(item: _Declared, field_name: str, lines: Mapping[str, str]) -> list[tuple[str, str]]:
    """(text, place) of a psd or variance: one text for every component, or a list with one per component."""
    raw = item.entry[field_name]
    key = f"{item.kind}[{item.index}].{field_name}"
    place = lines.get(key, item.place)
    if isinstance(raw, bool):
        raise ModelError(f"{place}: {item.what} {field_name} {raw!r} is not numeric")
    if isinstance(raw, list):
        if len(raw) != len(item.names):
            raise ModelError(
                f"{place}: {item.what} {field_name} is a list of {len(raw)}; give one expression for every component "
                f"or a list of {len(item.names)}"
            )
        return [(scalar_text(v, lines.get(f"{key}[{j}]", place), f"{key}[{j}]"), lines.get(f"{key}[{j}]", place)) for j, v in enumerate(raw)]
    return [(scalar_text(raw, place, key), place)] * len(item.names)


def _scalar_statistics(item: _Declared, field_name: str, namespace: Mapping[str, Value], lines: Mapping[str, str], model: str) -> list[sp.Expr]:
    """Each component's psd or variance, evaluated; a vector or matrix value is refused."""
    out = []
    for j, (text, place) in enumerate(_per_component_texts(item, field_name, lines)):
        where = f"{place}: model {model!r}, {item.what} {field_name}"
        value = parse_vector_expression(text, namespace, where)
        if is_matrix(value):
            raise ModelError(
                f"{where}: {text!r} is a {shape_text(value)}, but a {field_name} is a scalar "
                f"(write one scalar for every component, or a list of {len(item.names)})"
            )
        out.append(value)
    return out


def _shaped(value: Value, item: _Declared, where: str, text: str) -> list[sp.Expr]:
    """The components of an equation's value, which must have the item's shape (a scalar 0 is the zero vector)."""
    if item.shape != (1, 1) and not is_matrix(value) and value == 0:
        return [sp.S.Zero] * len(item.names)
    got = value.shape if is_matrix(value) else (1, 1)
    if tuple(got) != item.shape:
        hint = " (0 stands for the zero vector)" if item.shape != (1, 1) else ""
        raise ModelError(
            f"{where}: {text!r} is a {shape_text(tuple(got))}, but {item.what} is a {shape_text(item.shape)}{hint}"
        )
    return list(value) if is_matrix(value) else [value]


def _dynamics(
    states: list[_Declared], raw: Any, namespace: Mapping[str, Value], lines: Mapping[str, str], filename: str, model: str
) -> tuple[dict[str, sp.Expr], dict[str, str]]:
    """Each state component's right-hand side, from one equation per declared state (vector or scalar).

    Also returns, for each component, the ``dynamics:`` key its equation was
    written under (for the line of a later message).
    """
    if not isinstance(raw, dict):
        raise ModelError(f"{lines.get('dynamics', filename)}: 'dynamics' must map each state to its right-hand side")
    by_key: dict[str, _Declared] = {}
    component_of: dict[str, _Declared] = {}
    for item in states:
        by_key[item.name] = by_key[item.symbol] = item
        if item.shape != (1, 1):
            for ident in (*item.names, *item.symbols):
                component_of[ident] = item
    done: dict[str, str] = {}
    out: dict[str, sp.Expr] = {}
    for key, text in raw.items():
        place = lines.get(f"dynamics.{key}", lines.get("dynamics", filename))
        item = by_key.get(key)
        if item is None and key in component_of:
            owner = component_of[key]
            raise ModelError(
                f"{place}: model {model!r}: {key!r} is a component of {owner.what}; write one {shape_text(owner.shape)} "
                f"equation for {owner.symbol!r}"
            )
        if item is None:
            raise ModelError(f"{place}: model {model!r}: equation given for {key!r}, which is not a declared state")
        if item.name in done:
            raise ModelError(f"{place}: model {model!r}: two equations for state {item.name!r} ({done[item.name]!r} and {key!r})")
        done[item.name] = key
        where = f"{place}: model {model!r}, equation d({key})/dt"
        text = scalar_text(text, place, f"dynamics.{key}")
        value = parse_vector_expression(text, namespace, where)
        out.update(zip(item.names, _shaped(value, item, where, text)))
    missing = [item.name for item in states if item.name not in done]
    if missing:
        raise ModelError(f"{lines.get('dynamics', filename)}: model {model!r}: no equation for state(s) {', '.join(missing)}")
    keys = {component: done[item.name] for item in states for component in item.names}
    return out, keys


def _locations(lines: Mapping[str, str], declared: list[_Declared], dynamics_keys: Mapping[str, str]) -> dict[str, str]:
    """The file's line map with every entry key moved to its components' positions (for ErrorModel.build's messages)."""
    out = {k: v for k, v in lines.items() if not (any(k.startswith(f"{kind}[") for kind in _FIELDS) or k.startswith("dynamics."))}
    position = {kind: 0 for kind in _FIELDS}
    for item in declared:
        for j in range(len(item.names)):
            k = position[item.kind]
            position[item.kind] += 1
            for suffix in ("", ".name", ".symbol", ".unit", ".description", ".value", ".psd", ".expression", ".variance"):
                line = lines.get(f"{item.kind}[{item.index}]{suffix}[{j}]") or lines.get(f"{item.kind}[{item.index}]{suffix}")
                if line:
                    out[f"{item.kind}[{k}]{suffix}"] = line
    for component, key in dynamics_keys.items():
        if f"dynamics.{key}" in lines:
            out[f"dynamics.{component}"] = lines[f"dynamics.{key}"]
    return out


def _expand_check(data: Mapping[str, Any], declared: list[_Declared], lines: dict[str, str]) -> dict[str, Any]:
    """The ``check:`` section with a vector's values given by its name expanded to its components.

    ``check.parameters.f_b: [0, 0, -9.8]`` becomes ``f_b_x: 0, f_b_y: 0,
    f_b_z: -9.8``; ``check.initial_sigma.dv: 0.1`` gives every component of
    ``dv`` 0.1, and a list gives one per component.  Other entries are left
    to :mod:`modelgen.model.check_scenario`.
    """
    check = data.get("check")
    if not isinstance(check, dict):
        return dict(data)
    check = dict(check)
    for key, kinds in (("parameters", ("parameters",)), ("initial_sigma", ("states",))):
        section = check.get(key)
        if not isinstance(section, dict):
            continue
        vectors = {d.name: d for d in declared if d.kind in kinds and d.shape != (1, 1)}
        expanded: dict[str, Any] = {}
        for name, value in section.items():
            item = vectors.get(name)
            if item is None:
                expanded[name] = value
                continue
            place = lines.get(f"check.{key}.{name}", lines.get("check", ""))
            values = [v for row in value for v in (row if isinstance(row, list) else [row])] if isinstance(value, list) else None
            if values is None:
                values = [value] * len(item.names) if key == "initial_sigma" else None
            if values is None or len(values) != len(item.names):
                raise ModelError(
                    f"{place}: check.{key}.{name}: {item.what} needs {len(item.names)} values "
                    f"(a list{', or one value for all' if key == 'initial_sigma' else ''}), got {value!r}"
                )
            twice = sorted(set(item.names) & set(section))
            if twice:
                raise ModelError(
                    f"{place}: check.{key}.{name} gives {twice[0]!r}, which check.{key}.{twice[0]} gives too; give it once"
                )
            for component, v in zip(item.names, values):
                expanded[component] = v
                lines.setdefault(f"check.{key}.{component}", place)
        check[key] = expanded
    return {**data, "check": check}


def _declare_all(data: Mapping[str, Any], frame: str, lines: Mapping[str, str], filename: str) -> list[_Declared]:
    """Every entry of ``states``, ``noises``, ``parameters`` and ``measurements``, validated, no name used twice."""
    declared: list[_Declared] = []
    for kind in _FIELDS:
        raw = data.get(kind) or []
        if not isinstance(raw, list):
            raise ModelError(f"{lines.get(kind, filename)}: {kind!r} must be a list of entries with a 'name'")
        declared.extend(_declare(kind, i, entry, frame, lines, filename) for i, entry in enumerate(raw))
    _check_unique(declared)
    return declared


def _namespace(declared: list[_Declared], *kinds: str) -> dict[str, Value]:
    """Names usable in expressions: each entry's symbol (scalar or Matrix) and its component symbols."""
    out: dict[str, Value] = {}
    for item in declared:
        if item.kind in kinds:
            out[item.symbol] = item.value()
            if item.shape != (1, 1):
                out.update({s: sp.Symbol(s, real=True) for s in item.symbols})
    return out


def _definitions(
    data: Mapping[str, Any], declared: list[_Declared], namespace: Mapping[str, Value], lines: Mapping[str, str], filename: str
) -> dict[str, Value]:
    """The ``definitions:`` section evaluated; a definition named like a declared entry is refused naming both lines."""
    raw = data.get("definitions")
    names = {d.name: d for d in declared if d.kind != "measurements"}
    for i, entry in enumerate(raw if isinstance(raw, list) else []):
        if isinstance(entry, dict) and entry.get("name") in names:
            other = names[entry["name"]]
            raise ModelError(
                f"{lines.get(f'definitions[{i}]', filename)}: definition {entry['name']!r} has the name of {other.what} "
                f"declared at {other.place}"
            )
    return evaluate_definitions(
        [] if raw is None else raw,
        namespace,
        lambda key: lines.get(key) or lines.get(key.split(".")[0]) or lines.get("definitions", filename),
    )


def _quantities(item: _Declared, cls: type, unit: str | None = None, **per_component: list[Any]) -> list[Any]:
    """One ``cls`` (State, Noise, Parameter, Measurement) per component of ``item``, with per-component fields."""
    unit = str(item.entry.get("unit", "1")) if unit is None else unit
    return [
        cls(name=n, symbol=s, unit=unit, description=t, **{k: v[j] for k, v in per_component.items()})
        for j, (n, s, t) in enumerate(zip(item.names, item.symbols, item.descriptions))
    ]


def _measurement_expressions(item: _Declared, namespace: Mapping[str, Value], lines: Mapping[str, str], model: str) -> list[sp.Expr]:
    """Each component's h(x): the expression evaluated, with the declared shape."""
    key = f"measurements[{item.index}].expression"
    place = lines.get(key, item.place)
    text = scalar_text(item.entry["expression"], place, key)
    where = f"{place}: model {model!r}, {item.what}"
    return _shaped(parse_vector_expression(text, namespace, where), item, where, text)


def load_vector_model(data: Mapping[str, Any], lines: dict[str, str], filename: str) -> tuple[ErrorModel, dict[str, Any]]:
    """Build the scalar ErrorModel of a file with vectors, matrices or definitions (see module doc).

    Returns the model and the file's data with its ``check:`` section's
    vector entries expanded to components (:func:`_expand_check`).
    """
    model = str(data["model"])
    frame = free_text(data, "frame", lines, filename)
    declared = _declare_all(data, frame, lines, filename)
    everything = _namespace(declared, "states", "noises", "parameters")
    definitions = _definitions(data, declared, everything, lines, filename)
    statistics_namespace = {**_namespace(declared, "parameters"), **definitions}
    measured_namespace = {**_namespace(declared, "states", "parameters"), **definitions}
    states, noises, parameters, measurements = [], [], [], []
    for d in declared:
        if d.kind == "states":
            states += _quantities(d, State)
        elif d.kind == "parameters":
            values, unit = _parameter_values(d, lines), str(d.entry.get("unit", "1"))
            if "unit" in d.entry and "value" in d.entry:  # given in deg/h, ppm, ug ...: converted to SI, and so is the unit
                where = f"{lines.get(f'parameters[{d.index}].unit', d.place)}: parameters[{d.index}].unit"
                converted = [declared_value(v, unit, where) for v in values]
                values, unit = [v for v, _ in converted], converted[0][1]
            parameters += _quantities(d, Parameter, unit=unit, value=values)
        elif d.kind == "noises":
            noises += _quantities(d, Noise, psd=_scalar_statistics(d, "psd", statistics_namespace, lines, model))
        else:
            variances = (
                _scalar_statistics(d, "variance", statistics_namespace, lines, model)
                if "variance" in d.entry
                else ["1"] * len(d.names)
            )
            expressions = _measurement_expressions(d, measured_namespace, lines, model)
            measurements += _quantities(d, Measurement, expression=expressions, variance=variances)
    state_items = [d for d in declared if d.kind == "states"]
    dynamics, dynamics_keys = _dynamics(state_items, data.get("dynamics"), {**everything, **definitions}, lines, filename, model)
    built = ErrorModel.build(
        name=model,
        states=states,
        noises=noises,
        parameters=parameters,
        dynamics=dynamics,
        measurements=measurements,
        title=free_text(data, "title", lines, filename),
        source=free_text(data, "source", lines, filename),
        frame=frame,
        notes=notes_text(data, lines, filename),
        locations=_locations(lines, declared, dynamics_keys),
    )
    undeclared = [n for d in declared if "unit" not in d.entry for n in d.names]
    check_model_units(built, _locations(lines, declared, dynamics_keys), undeclared)
    return built, _expand_check(data, declared, lines)
