"""Reading error models from YAML files.

A model file declares parameters, states, noises, the state equations and the
measurements as plain text (format documented in README.md).  Errors name the
file, the line and the key, and nothing is derived or written until the whole
file has been validated.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from modelgen.errors import ModelError
from modelgen.model import ErrorModel, Measurement, Noise, Parameter, State

_ITEM_FIELDS = {
    "states": (State, {"name", "symbol", "unit", "description"}),
    "noises": (Noise, {"name", "symbol", "unit", "description", "psd"}),
    "parameters": (Parameter, {"name", "symbol", "unit", "description", "value"}),
    "measurements": (Measurement, {"name", "symbol", "unit", "description", "expression", "variance"}),
}
_TOP_KEYS = {"model", "title", "source", "frame", "notes", "parameters", "states", "noises", "dynamics", "measurements"}


def _plain(node: yaml.Node, path: str, lines: dict[str, str], filename: str) -> Any:
    """Turn a composed YAML node into Python data, recording each key's line."""
    lines.setdefault(path, f"{filename}:{node.start_mark.line + 1}")
    if isinstance(node, yaml.MappingNode):
        out: dict[str, Any] = {}
        for key_node, value_node in node.value:
            key = key_node.value
            sub = f"{path}.{key}" if path else str(key)
            if key in out:
                raise ModelError(f"{filename}:{key_node.start_mark.line + 1}: key {sub!r} appears twice")
            lines[sub] = f"{filename}:{key_node.start_mark.line + 1}"
            out[key] = _plain(value_node, sub, lines, filename)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_plain(item, f"{path}[{i}]", lines, filename) for i, item in enumerate(node.value)]
    if node.tag == "tag:yaml.org,2002:str":
        return node.value
    try:
        return yaml.SafeLoader(" ").construct_object(node)
    except yaml.YAMLError as exc:  # e.g. an unknown tag such as !!python/object
        problem = getattr(exc, "problem", None) or exc
        raise ModelError(f"{filename}:{node.start_mark.line + 1}: key {path!r}: {problem}") from None


def load_model_text(text: str, filename: str = "<model>") -> ErrorModel:
    """Parse and validate a model from YAML text; see :func:`load_model`."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        if mark is not None:
            problem = " ".join(str(p) for p in (getattr(exc, "context", None), getattr(exc, "problem", None)) if p)
            raise ModelError(f"{filename}:{mark.line + 1}: not valid YAML ({problem}, column {mark.column + 1})") from None
        raise ModelError(f"{filename}: not valid YAML ({exc})") from None
    if not isinstance(root, yaml.MappingNode):
        raise ModelError(f"{filename}: a model file must be a mapping with keys {sorted(_TOP_KEYS)}")
    lines: dict[str, str] = {}
    data = _plain(root, "", lines, filename)
    if "base" in data:  # a new state set made from another model (modelgen.transform_file)
        from modelgen.transform_file import load_transformed_model

        return load_transformed_model(data, lines, filename, load_model)
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise ModelError(f"{lines[unknown[0]]}: unknown key {unknown[0]!r} (expected one of {sorted(_TOP_KEYS)})")
    for key in ("model", "states", "dynamics"):
        if key not in data:
            raise ModelError(f"{filename}: missing required key {key!r}")

    items: dict[str, list] = {}
    for key, (cls, fields) in _ITEM_FIELDS.items():
        raw = data.get(key) or []
        if not isinstance(raw, list):
            raise ModelError(f"{lines[key]}: {key!r} must be a list of entries with a 'name'")
        built = []
        for i, entry in enumerate(raw):
            place = lines.get(f"{key}[{i}]", filename)
            if not isinstance(entry, dict) or "name" not in entry:
                raise ModelError(f"{place}: {key}[{i}] must be a mapping with a 'name'")
            extra = sorted(set(entry) - fields)
            if extra:
                raise ModelError(f"{place}: {key}[{i}] has unknown field {extra[0]!r} (allowed: {sorted(fields)})")
            if key == "parameters" and "value" in entry and not _is_number(entry["value"]):
                raise ModelError(f"{place}: parameter {entry['name']!r} value {entry['value']!r} is not a number")
            if key == "measurements" and "expression" not in entry:
                raise ModelError(f"{place}: measurement {entry['name']!r} has no 'expression'")
            if key == "noises" and "psd" not in entry:
                raise ModelError(f"{place}: noise {entry['name']!r} has no 'psd' (its power spectral density)")
            if key == "noises" and "psd" in entry and isinstance(entry["psd"], bool):
                raise ModelError(f"{place}: noise {entry['name']!r} psd {entry['psd']!r} is not numeric")
            fields_in = {
                k: (_scalar_text(v, lines.get(f"{key}[{i}].{k}", place), f"{key}[{i}].{k}") if k in {"psd", "expression", "variance"} else v)
                for k, v in entry.items()
            }
            if "value" in fields_in:
                fields_in["value"] = float(fields_in["value"])
            built.append(cls(**fields_in))
        items[key] = built

    dynamics = data["dynamics"]
    if not isinstance(dynamics, dict):
        raise ModelError(f"{lines['dynamics']}: 'dynamics' must map each state to its right-hand side")
    dynamics = {k: _scalar_text(v, lines.get(f"dynamics.{k}", filename), f"dynamics.{k}") for k, v in dynamics.items()}
    notes = data.get("notes") or []
    return ErrorModel.build(
        name=str(data["model"]),
        states=items["states"],
        noises=items["noises"],
        parameters=items["parameters"],
        dynamics=dynamics,
        measurements=items["measurements"],
        title=str(data.get("title", "")),
        source=str(data.get("source", "")),
        frame=str(data.get("frame", "")),
        notes=[str(n) for n in notes] if isinstance(notes, list) else [str(notes)],
        locations=lines,
    )


def _scalar_text(value: Any, place: str, key: str) -> str:
    """The text of one scalar expression; a list, mapping or empty value is refused."""
    if value is None or (isinstance(value, str) and not value.strip()):
        raise ModelError(f"{place}: {key!r} is empty (expected one expression)")
    if isinstance(value, (list, dict)):
        kind = f"a list of {len(value)} items" if isinstance(value, list) else "a mapping"
        raise ModelError(f"{place}: {key!r} is {kind}; dimension mismatch (expected one scalar expression)")
    return value if isinstance(value, str) else str(value)


def _is_number(value: Any) -> bool:
    if isinstance(value, bool):
        return False
    if isinstance(value, (int, float)):
        return True
    try:
        float(str(value))
    except ValueError:
        return False
    return True


def load_model(path: str | Path) -> ErrorModel:
    """Load a model file, or a built-in model by name (``ned_doppler18``)."""
    path = Path(path)
    if not path.exists() and path.suffix == "" and builtin_model_path(str(path)) is not None:
        path = builtin_model_path(str(path))  # type: ignore[assignment]
    if not path.exists():
        raise ModelError(f"{path}: no such model file, and not a built-in model ({', '.join(builtin_models())})")
    return load_model_text(path.read_text(encoding="utf-8"), filename=str(path))


def builtin_models() -> list[str]:
    """Names of the models shipped in ``modelgen/models``."""
    folder = resources.files("modelgen") / "models"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def builtin_model_path(name: str) -> Path | None:
    candidate = resources.files("modelgen") / "models" / f"{name}.yaml"
    return Path(str(candidate)) if candidate.is_file() else None
