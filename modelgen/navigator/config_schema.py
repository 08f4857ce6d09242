"""The replay configuration's JSON schema (``modelgen/data/replay_config.schema.json``): loaded, enforced, documented.

The schema file is the one list of the configuration's keys: their types,
ranges, units (``x-unit``), defaults and descriptions.  From it come

* the key sets :func:`key_sets` the loader refuses unknown keys with
  (:func:`modelgen.navigator.config.load_config`, naming file:line and the keys known there);
* the validation :func:`validate` every loaded configuration passes (the
  ``jsonschema`` library, Draft 2020-12), its first error named by file:line;
* the key table of the documentation (:func:`key_table_markdown`,
  ``docs/replay-configuration.md``; a test keeps the page equal to it).

The ``imu:`` and ``gnss:`` sections hold the keys every log format shares and
each format's own (declared with the format, :mod:`modelgen.navigator.logs.registry`;
a test checks the schema's per-format branches against those declarations).
"""

from __future__ import annotations

import json
from functools import lru_cache
from typing import Any, Callable, Iterator

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path

SCHEMA_FILE = "replay_config.schema.json"
#: Where the documentation's key table sits in docs/replay-configuration.md (between these two lines).
TABLE_START = "<!-- replay-configuration-keys: generated from modelgen/data/replay_config.schema.json -->"
TABLE_END = "<!-- end of replay-configuration-keys -->"


@lru_cache(maxsize=1)
def load_schema() -> dict[str, Any]:
    """The schema as shipped (read once)."""
    return json.loads(data_path(SCHEMA_FILE).read_text(encoding="utf-8"))


def _properties(node: dict[str, Any]) -> dict[str, Any]:
    """A node's keys: its ``properties``, or for the outages ``$ref`` the schedule and windows keys (``x-keys``)."""
    return node.get("properties") or node.get("x-keys") or {}


def key_sets() -> dict[str, set[str]]:
    """Every mapping's known keys by dotted path ('' the top level, 'imu.columns' ...), as the loader checks them.

    A mapping that takes any key (``parameters``, ``gnss.quality_factor``) has no entry: its keys are not checked
    here.
    """
    out: dict[str, set[str]] = {}

    def walk(node: dict[str, Any], prefix: str) -> None:
        props = _properties(node)
        if not props or node.get("additionalProperties", False) is not False and "x-keys" not in node:
            return
        out[prefix] = set(props)
        for key, sub in props.items():
            walk(sub, f"{prefix}.{key}" if prefix else key)
        for branch in node.get("allOf", []):  # a log format's own nested keys (imu.columns, imu.units)
            for key, sub in branch.get("then", {}).get("properties", {}).items():
                walk(sub, f"{prefix}.{key}" if prefix else key)

    walk(load_schema(), "")
    return out


def _dotted(path: Any) -> str:
    """A jsonschema error path (deque of keys and indices) as the loader's key path ('evaluation.schedules[0].name')."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


@lru_cache(maxsize=1)
def _validator() -> Any:
    try:
        import jsonschema
    except ImportError:  # a dependency of modelgen-nav; only a broken installation lacks it
        raise ModelError("the replay configuration is validated with jsonschema: pip install jsonschema") from None
    return jsonschema.Draft202012Validator(load_schema())


def validate(data: dict[str, Any], where: Callable[[str], str]) -> None:
    """Refuse a configuration the schema does not accept: one error, the first in the file, named by file:line."""
    errors = list(_validator().iter_errors(data))
    if not errors:
        return
    lines = {id(e): where(_dotted(e.absolute_path)) for e in errors}

    def order(error: Any) -> tuple[int, int, str]:
        line = lines[id(error)].rpartition(":")[2]
        return (int(line) if line.isdigit() else 0, -len(error.absolute_path), error.message)

    error = min(errors, key=order)
    while error.context:  # oneOf / if-then: the branch's own first error says more than "is not valid under"
        error = min(error.context, key=lambda e: (-len(e.absolute_path), e.message))
    key = _dotted(error.absolute_path) or "the configuration"
    raise ModelError(f"{where(_dotted(error.absolute_path))}: {key}: {error.message} "
                     f"(schema: modelgen/data/{SCHEMA_FILE})")


def keys() -> Iterator[tuple[str, dict[str, Any]]]:
    """Every documented key: (dotted path, its schema node), leaves and sections, in the schema's order.

    The per-format keys of ``imu:`` and ``gnss:`` come with their format's node (a key two formats share appears
    once per format, its path marked ``(format)``).
    """
    def walk(node: dict[str, Any], prefix: str) -> Iterator[tuple[str, dict[str, Any]]]:
        for key, sub in _properties(node).items():
            path = f"{prefix}.{key}" if prefix else key
            if "x-formats" in sub:
                continue  # listed under each format below
            yield path, sub
            yield from walk(sub, path)
        for branch in node.get("allOf", []):
            fmt = branch["if"]["properties"]["format"]["const"]
            for key, sub in branch["then"]["properties"].items():
                path = f"{prefix}.{key}"
                yield f"{path} ({fmt})", {**sub, "x-required": key in branch["then"].get("required", [])}
                for inner, leaf in _properties(sub).items():
                    yield (f"{path}.{inner} ({fmt})",
                           {**leaf, "x-required": inner in sub.get("required", [])})

    yield from walk(load_schema(), "")


def _kind(node: dict[str, Any]) -> str:
    if "enum" in node:
        return ", ".join(f"`{v}`" for v in node["enum"])
    kind = node.get("type", "mapping" if "x-keys" in node else "")
    if kind == "number" or kind == "integer":
        bounds = []
        if "exclusiveMinimum" in node:
            bounds.append(f"> {node['exclusiveMinimum']:g}")
        if "minimum" in node:
            bounds.append(f">= {node['minimum']:g}")
        if "maximum" in node:
            bounds.append(f"<= {node['maximum']:g}")
        return kind + (f" {', '.join(bounds)}" if bounds else "")
    if kind == "array":
        size = node.get("minItems")
        return f"list of {size}" if size is not None and size == node.get("maxItems") else "list"
    if kind == "object":
        return "mapping"
    return kind or "mapping"


def _required_paths() -> dict[str, str]:
    """Dotted paths of the keys the schema requires where their section is given: 'required', or for a key of one
    of a section's alternatives (the outages' schedule) 'required in <the alternative>'."""
    out: dict[str, str] = {}
    schema = load_schema()

    def walk(node: dict[str, Any], prefix: str) -> None:
        for key in node.get("required", []):
            out[f"{prefix}.{key}" if prefix else key] = "required"
        if "$ref" in node:
            for branch in schema["$defs"][node["$ref"].rpartition("/")[2]].get("oneOf", []):
                for key in branch.get("required", []):
                    out.setdefault(f"{prefix}.{key}", f"required in {branch.get('description', 'its alternative')}")
        for key, sub in _properties(node).items():
            walk(sub, f"{prefix}.{key}" if prefix else key)

    walk(schema, "")
    return out


def key_table_markdown() -> str:
    """The documentation's table of every key: key, type, unit, default (or required), what it means."""
    required = _required_paths()
    rows = ["| key | type | unit | default | meaning |", "|---|---|---|---|---|"]
    for path, node in keys():
        plain = path.split(" (")[0]
        needed = "required" if node.get("x-required") else required.get(plain) if "x-required" not in node else None
        if "default" in node:
            default = f"`{json.dumps(node['default'])}`"
        else:
            default = needed or "-"
        description = node.get("description", "").replace("|", "\\|")
        rows.append(f"| `{path}` | {_kind(node)} | {node.get('x-unit', '')} | {default} | {description} |")
    return "\n".join(rows) + "\n"


def with_key_table(page: str) -> str:
    """``page`` (docs/replay-configuration.md) with the text between its table markers replaced by the key table."""
    if TABLE_START not in page or TABLE_END not in page:
        raise ModelError(f"the page has no {TABLE_START!r} ... {TABLE_END!r} markers for the key table")
    head, _, rest = page.partition(TABLE_START)
    _, _, tail = rest.partition(TABLE_END)
    return f"{head}{TABLE_START}\n\n{key_table_markdown()}\n{TABLE_END}{tail}"


if __name__ == "__main__":  # python -m modelgen.navigator.config_schema docs/replay-configuration.md
    import sys
    from pathlib import Path

    for name in sys.argv[1:]:
        Path(name).write_text(with_key_table(Path(name).read_text(encoding="utf-8")), encoding="utf-8")
