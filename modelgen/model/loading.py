"""Reading error models from YAML files.

A model file declares parameters, states, noises, the state equations and the
measurements as plain text (format documented in README.md).  Errors name the
file, the line and the key, and nothing is derived or written until the whole
file has been validated.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import yaml

from modelgen.model.check_scenario import build_check_spec, parse_check_section
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import package_path
from modelgen.model.declaration import ErrorModel, Measurement, Noise, Parameter, State
from modelgen.model.file_fields import as_float as _as_float
from modelgen.model.file_fields import free_text, notes_text
from modelgen.model.file_fields import is_number as _is_number
from modelgen.model.file_fields import scalar_text as _scalar_text
from modelgen.model.navigation_model.derivation import derive_navigation_model
from modelgen.model.transform_file import load_transformed_model
from modelgen.model.unit_check import check_model_units
from modelgen.model.units import declared_value
from modelgen.model.vector_loading import load_vector_model, uses_vector_syntax

_ITEM_FIELDS = {
    "states": (State, {"name", "symbol", "unit", "description"}),
    "noises": (Noise, {"name", "symbol", "unit", "description", "psd"}),
    "parameters": (Parameter, {"name", "symbol", "unit", "description", "value"}),
    "measurements": (Measurement, {"name", "symbol", "unit", "description", "expression", "variance"}),
}
_TOP_KEYS = {"model", "title", "source", "frame", "notes", "parameters", "states", "noises", "dynamics", "measurements", "check", "definitions"}


#: Largest model file accepted, in bytes (the largest built-in model is ~15 kB).
MAX_FILE_BYTES = 1_000_000


def _plain(
    node: yaml.Node, path: str, lines: dict[str, str], filename: str, seen: set[int] | None = None
) -> Any:
    """Turn a composed YAML node into Python data, recording each key's line.

    A node met twice is an alias (``*name``): refused, because aliases let a
    few lines expand to billions of nodes (an "alias bomb") and a model needs
    none.
    """
    seen = set() if seen is None else seen
    if id(node) in seen:
        raise ModelError(
            f"{filename}:{node.start_mark.line + 1}: key {path!r} repeats an anchored node through an alias; "
            "YAML aliases (*name) are not accepted in a model file"
        )
    seen.add(id(node))
    lines.setdefault(path, f"{filename}:{node.start_mark.line + 1}")
    if isinstance(node, yaml.MappingNode):
        out: dict[str, Any] = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise ModelError(f"{filename}:{key_node.start_mark.line + 1}: a key must be plain text, not a list or mapping")
            key = key_node.value
            sub = f"{path}.{key}" if path else str(key)
            if key in out:
                raise ModelError(f"{filename}:{key_node.start_mark.line + 1}: key {sub!r} appears twice")
            lines[sub] = f"{filename}:{key_node.start_mark.line + 1}"
            out[key] = _plain(value_node, sub, lines, filename, seen)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_plain(item, f"{path}[{i}]", lines, filename, seen) for i, item in enumerate(node.value)]
    if node.tag == "tag:yaml.org,2002:str":
        return node.value
    try:
        return yaml.SafeLoader(" ").construct_object(node)
    except yaml.YAMLError as exc:  # e.g. an unknown tag such as !!python/object
        problem = getattr(exc, "problem", None) or exc
        raise ModelError(f"{filename}:{node.start_mark.line + 1}: key {path!r}: {problem}") from None
    except (ValueError, OverflowError) as exc:  # e.g. an integer of more than 4300 digits
        raise ModelError(f"{filename}:{node.start_mark.line + 1}: key {path!r}: cannot read {node.value[:20]!r}... ({exc})") from None


def load_model_text(text: str, filename: str = "<model>", _loading: tuple[str, ...] = ()) -> ErrorModel:
    """Parse and validate a model from YAML text; see :func:`load_model`.

    ``_loading`` is the chain of model files being loaded (a transform file
    loads its base), so that a file that is its own base, directly or through
    others, is refused instead of recursing forever.
    """
    if len(text) > MAX_FILE_BYTES:
        raise ModelError(f"{filename}: {len(text)} characters; a model file may have at most {MAX_FILE_BYTES}")
    _check_flow_depth(text, filename)
    loader = None
    try:
        loader = _ModelLoader(text, filename)  # the reader refuses unprintable characters here
        root = loader.get_single_node()
    except yaml.YAMLError as exc:
        raise ModelError(_yaml_problem(exc, text, filename)) from None
    except RecursionError:
        raise ModelError(f"{filename}: not valid YAML (nested too deeply)") from None
    finally:
        if loader is not None:
            loader.dispose()
    if not isinstance(root, yaml.MappingNode):
        raise ModelError(f"{filename}: a model file must be a mapping with keys {sorted(_TOP_KEYS)}")
    lines: dict[str, str] = {}
    try:
        data = _plain(root, "", lines, filename)
    except RecursionError:
        raise ModelError(f"{filename}: not valid as a model (nested too deeply)") from None
    if "base" in data:  # a new state set made from another model (modelgen.model.transform_file)

        def load_base(path: str | Path) -> ErrorModel:
            return load_model(path, _loading=(*_loading, filename))

        return load_transformed_model(data, lines, filename, load_base)
    if "navigation" in data:  # an error model derived from the navigation equations (modelgen.model.navigation_model)
        return _with_check_scenario(derive_navigation_model(data, lines, filename).model, data, lines, filename)
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise ModelError(f"{lines[unknown[0]]}: unknown key {unknown[0]!r} (expected one of {sorted(_TOP_KEYS)})")
    for key in ("model", "states", "dynamics"):
        if key not in data:
            raise ModelError(f"{filename}: missing required key {key!r}")
    if uses_vector_syntax(data):  # vectors, matrices, definitions or the navigation library
        model, data = load_vector_model(data, lines, filename)
        return _with_check_scenario(model, data, lines, filename)

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
            for text_field in ("unit", "description"):
                if isinstance(entry.get(text_field), (list, dict)):
                    raise ModelError(f"{place}: {key}[{i}] {text_field!r} must be text, not a list or mapping")
            if key == "noises" and "psd" in entry and isinstance(entry["psd"], bool):
                raise ModelError(f"{place}: noise {entry['name']!r} psd {entry['psd']!r} is not numeric")
            fields_in = {
                k: (_scalar_text(v, lines.get(f"{key}[{i}].{k}", place), f"{key}[{i}].{k}") if k in {"psd", "expression", "variance"} else v)
                for k, v in entry.items()
            }
            if "value" in fields_in:
                fields_in["value"] = _as_float(fields_in["value"], lines.get(f"{key}[{i}].value", place))
                if "unit" in fields_in:  # a value given in deg/h, ppm, ug ... is converted to SI, and so is its unit
                    fields_in["value"], fields_in["unit"] = declared_value(
                        fields_in["value"], str(fields_in["unit"]), f"{lines.get(f'{key}[{i}].unit', place)}: {key}[{i}].unit"
                    )
            built.append(cls(**fields_in))
        items[key] = built

    dynamics = data["dynamics"]
    if not isinstance(dynamics, dict):
        raise ModelError(f"{lines['dynamics']}: 'dynamics' must map each state to its right-hand side")
    dynamics = {k: _scalar_text(v, lines.get(f"dynamics.{k}", filename), f"dynamics.{k}") for k, v in dynamics.items()}
    model = ErrorModel.build(
        name=str(data["model"]),
        states=items["states"],
        noises=items["noises"],
        parameters=items["parameters"],
        dynamics=dynamics,
        measurements=items["measurements"],
        title=free_text(data, "title", lines, filename),
        source=free_text(data, "source", lines, filename),
        frame=free_text(data, "frame", lines, filename),
        notes=notes_text(data, lines, filename),
        locations=lines,
    )
    undeclared = [str(entry["name"]) for key in _ITEM_FIELDS for entry in (data.get(key) or []) if "unit" not in entry]
    check_model_units(model, lines, undeclared)
    return _with_check_scenario(model, data, lines, filename)


def _with_check_scenario(model: ErrorModel, data: dict, lines: dict[str, str], filename: str) -> ErrorModel:
    """The model with its ``check:`` section (modelgen.model.check_scenario) validated against it, if it has one."""
    if "check" not in data:
        return model
    section = parse_check_section(data["check"], lines, filename)
    return replace(model, check=build_check_spec(section, model, lines.get("check", filename)))


#: Deepest nesting of YAML flow collections (``[`` and ``{``) accepted.  PyYAML
#: scans flow collections in time proportional to their depth for every token,
#: so 10^5 nested brackets would take hours; a model needs two or three levels.
MAX_FLOW_DEPTH = 50


def _check_flow_depth(text: str, filename: str) -> None:
    """Refuse text whose ``[``/``{`` brackets nest deeper than :data:`MAX_FLOW_DEPTH`.

    Counted over the raw text, brackets inside quoted text included: balanced
    brackets in a title do not add up, and 50 unclosed ones are not a model.
    """
    depth = 0
    for line_number, line in enumerate(text.split("\n"), start=1):
        for char in line:
            if char in "[{":
                depth += 1
                if depth > MAX_FLOW_DEPTH:
                    raise ModelError(
                        f"{filename}:{line_number}: not valid as a model (brackets nested more than {MAX_FLOW_DEPTH} deep; "
                        "nested too deeply)"
                    )
            elif char in "]}" and depth:
                depth -= 1


class _ModelLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing any alias (``*name``) where it appears.

    Aliases let a few lines expand to billions of nodes (an "alias bomb"), or
    to a node that contains itself; a model file needs none.
    """

    def __init__(self, text: str, filename: str):
        super().__init__(text)
        self.filename = filename

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise ModelError(
                f"{self.filename}:{event.start_mark.line + 1}: YAML aliases (*{event.anchor}) are not accepted "
                "in a model file; write the value out"
            )
        return super().compose_node(parent, index)


def _yaml_problem(exc: yaml.YAMLError, text: str, filename: str) -> str:
    """A YAML error as ``file:line: not valid YAML (problem, column c)``."""
    mark = getattr(exc, "problem_mark", None)
    if mark is not None:
        problem = " ".join(str(p) for p in (getattr(exc, "context", None), getattr(exc, "problem", None)) if p)
        return f"{filename}:{mark.line + 1}: not valid YAML ({problem}, column {mark.column + 1})"
    if isinstance(exc, yaml.reader.ReaderError):  # a character YAML does not accept, e.g. NUL or ESC
        line = text.count("\n", 0, exc.position) + 1
        return f"{filename}:{line}: not valid YAML (character U+{exc.character:04X} is not allowed in a YAML file)" if isinstance(
            exc.character, int
        ) else f"{filename}:{line}: not valid YAML ({exc.reason})"
    return f"{filename}: not valid YAML ({exc})"


def _read_model_file(path: Path) -> str:
    """The text of a model file, or a ModelError naming the file and why it cannot be read.

    Refused: a directory, an unreadable file, a file over :data:`MAX_FILE_BYTES`,
    a UTF-16 or UTF-32 file and any file that is not UTF-8 text.
    """
    try:
        if path.is_dir():
            raise ModelError(f"{path}: is a directory, not a model file")
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ModelError(f"{path}: {size} bytes; a model file may have at most {MAX_FILE_BYTES}")
        with path.open("rb") as stream:
            data = stream.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ModelError(f"{path}: cannot read the model file ({exc.strerror or exc})") from None
    if len(data) > MAX_FILE_BYTES:
        raise ModelError(f"{path}: more than {MAX_FILE_BYTES} bytes; a model file may have at most {MAX_FILE_BYTES}")
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise ModelError(f"{path}: is encoded as UTF-16 or UTF-32; save it as UTF-8")
    if b"\x00" in data:
        line = data.count(b"\n", 0, data.index(b"\x00")) + 1
        raise ModelError(f"{path}:{line}: contains a NUL byte; a model file is UTF-8 text, not binary")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ModelError(f"{path}:{line}: is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start})") from None
    return text[1:] if text.startswith("\ufeff") else text


def load_model(path: str | Path, _loading: tuple[str, ...] = ()) -> ErrorModel:
    """Load a model file, or a built-in model by name (``ned_doppler18``).

    ``_loading`` lists the files already being loaded (transform bases), see
    :func:`load_model_text`.
    """
    path = Path(path)
    if not path.is_file() and path.suffix == "" and builtin_model_path(str(path)) is not None:
        path = builtin_model_path(str(path))  # type: ignore[assignment]
    if not path.exists():
        raise ModelError(f"{path}: no such model file, and not a built-in model ({', '.join(builtin_models())})")
    chain = [*_loading, str(path)]
    resolved = [str(Path(p).resolve()) for p in chain]
    if resolved[-1] in resolved[:-1]:
        raise ModelError(
            f"{chain[0]}: the chain of base models loops back on itself ({' -> '.join(chain)}); "
            "a model cannot be its own base"
        )
    return load_model_text(_read_model_file(path), filename=str(path), _loading=tuple(_loading))


def builtin_models() -> list[str]:
    """Names of the models shipped in ``modelgen/models``."""
    return sorted(p.name[:-5] for p in package_path("models").iterdir() if p.name.endswith(".yaml"))


def builtin_model_path(name: str) -> Path | None:
    """The file of the built-in model ``name``, or None if there is no such model."""
    candidate = package_path("models", f"{name}.yaml")
    return candidate if candidate.is_file() else None
