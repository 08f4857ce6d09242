"""A replay configuration read with the configurations it extends (``extends:``).

A configuration may start from another one, ``extends: FILE``, and give only
what differs: the ECEF drive is the 15-state drive's configuration with
another ``model:``, so it extends it instead of repeating 150 lines that then
drift apart.  The base is read first, then the configuration's own keys are
laid over it: a mapping is merged key by key, any other value (a number, a
text, a list) replaces the base's.  ``FILE`` is relative to the folder of the
configuration that names it, or the name of a built-in configuration
(``replay_drive_0708``, in ``modelgen/data/``).

Every key keeps the ``file:line`` of the file that wrote it, so a refusal of
an inherited value names the base's line, and a relative path (a log's
``file``, ``output.folder``, a model file) is taken from that file's folder.
A chain longer than :data:`MAX_DEPTH`, a cycle, or an ``extends`` that is not
a file is refused at its line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path, read_yaml_with_lines

#: The longest chain of bases a configuration may have (a deeper one is surely a mistake).
MAX_DEPTH = 8

WHAT = "navigator configuration file"


def read_config_with_bases(path: str | Path) -> tuple[dict[str, Any], dict[str, str]]:
    """The configuration's mapping with its bases merged in, and the ``file:line`` of every key.

    The ``extends`` key itself is not in the mapping returned (its line is).
    """
    return _read(Path(path), ())


def closest_key(lines: dict[str, str], key: str) -> str:
    """``key`` if ``lines`` has it, else its closest enclosing key that has, else ''."""
    probe = key
    while probe and probe not in lines:
        probe = probe.rpartition(".")[0]
    return probe


def origin_of(lines: dict[str, str], key: str, default: Path) -> Path:
    """The file that wrote ``key`` (or its closest enclosing key); relative paths at the key start from its folder."""
    probe = closest_key(lines, key)
    return Path(lines[probe].rsplit(":", 1)[0]) if probe else default


def _read(path: Path, chain: tuple[Path, ...]) -> tuple[dict[str, Any], dict[str, str]]:
    data, lines = read_yaml_with_lines(path, WHAT)
    if "extends" not in data:
        return data, lines
    where = lines.get("extends", str(path))
    base = _base_path(data["extends"], path, where)
    resolved = tuple(p.resolve() for p in chain)
    if base.resolve() in resolved or base.resolve() == path.resolve():
        raise ModelError(f"{where}: extends {data['extends']!r}: the configurations extend each other in a cycle "
                         f"({' -> '.join(p.name for p in (*chain, path, base))})")
    if len(chain) + 1 >= MAX_DEPTH:
        raise ModelError(f"{where}: extends {data['extends']!r}: more than {MAX_DEPTH} configurations extend one "
                         "another; merge some of them")
    base_data, base_lines = _read(base, (*chain, path))
    own = {k: v for k, v in data.items() if k != "extends"}
    merged_lines = {k: v for k, v in base_lines.items() if not _replaced(k, own)}
    merged_lines.update(lines)
    return _merge(base_data, own), merged_lines


def _base_path(value: Any, path: Path, where: str) -> Path:
    """The file ``extends`` names: relative to the naming file's folder, or a built-in configuration's name."""
    if not isinstance(value, str) or not value.strip():
        raise ModelError(f"{where}: extends must name a configuration file, got {value!r}")
    candidate = Path(value) if Path(value).is_absolute() else path.parent / value
    if candidate.is_file():
        return candidate
    if "/" not in value and "\\" not in value:
        builtin = data_path(value if value.endswith((".yaml", ".yml")) else f"{value}.yaml")
        if builtin.is_file():
            return builtin
    raise ModelError(f"{where}: extends {value!r}: no such configuration file ({candidate}) and no built-in "
                     "configuration of that name")


def _merge(base: Any, own: Any) -> Any:
    """``own`` laid over ``base``: mappings key by key, anything else replaced."""
    if not (isinstance(base, dict) and isinstance(own, dict)):
        return own
    merged = dict(base)
    for key, value in own.items():
        merged[key] = _merge(base[key], value) if key in base else value
    return merged


def _replaced(key: str, own: dict[str, Any]) -> bool:
    """True when the base's key path ``key`` lies under a value of ``own`` that replaces it (not a merged mapping)."""
    node: Any = own
    for part in key.split("[", 1)[0].split("."):  # a list item's path stops at its list, which own replaces whole
        if not isinstance(node, dict) or part not in node:
            return False
        node = node[part]
        if not isinstance(node, dict):
            return True
    return False
