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

import difflib
import errno
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
    if len(chain) + 1 > MAX_DEPTH:  # ``base`` would be base number len(chain) + 1 of the configuration read first
        raise ModelError(f"{where}: extends {data['extends']!r}: more than {MAX_DEPTH} configurations extend one "
                         "another; merge some of them")
    try:
        base_data, base_lines = _read(base, (*chain, path))
    except OSError as exc:  # unreadable (permissions, an I/O error): at the line that names it
        raise ModelError(f"{where}: extends {data['extends']!r}: {base}: cannot be read "
                         f"({exc.strerror or exc})") from None
    own = {k: v for k, v in data.items() if k != "extends"}
    merged_lines = {k: v for k, v in base_lines.items() if not _replaced(k, own)}
    merged_lines.update(lines)
    return _merge(base_data, own), merged_lines


def builtin_configurations() -> list[str]:
    """The names ``extends`` takes for the configurations shipped in ``modelgen/data`` (``replay_*.yaml``)."""
    return sorted(p.stem for p in data_path().glob("replay_*.yaml") if p.is_file())


def _base_path(value: Any, path: Path, where: str) -> Path:
    """The file ``extends`` names: relative to the naming file's folder, or a built-in configuration's name.

    Anything else is refused at ``where`` (the ``extends`` line), saying what the name is: missing, a folder, a
    device or pipe, a symbolic link that leads nowhere (a loop or a missing target), a name the system refuses."""
    if not isinstance(value, str) or not value.strip():
        raise ModelError(f"{where}: extends must name a configuration file, got {value!r}")
    if "\0" in value:
        raise ModelError(f"{where}: extends {value!r}: a file name cannot hold a NUL character")
    candidate = Path(value) if Path(value).is_absolute() else path.parent / value
    try:
        if candidate.is_file():
            return candidate
        problem = _not_a_file(candidate)
    except OSError as exc:  # a name too long for the system, ...
        raise ModelError(f"{where}: extends {_short(value)}: not a usable file name ({exc.strerror or exc})") from None
    if problem:
        raise ModelError(f"{where}: extends {_short(value)}: {candidate} is {problem}, not a configuration file")
    names = builtin_configurations()
    stem = value[:-5] if value.endswith(".yaml") else value[:-4] if value.endswith(".yml") else value
    if "/" not in value and "\\" not in value and stem in names:
        return data_path(f"{stem}.yaml")
    close = difflib.get_close_matches(stem, names, n=1)
    raise ModelError(f"{where}: extends {_short(value)}: no such configuration file ({_short(str(candidate))}) and no "
                     f"built-in configuration of that name (built in: {', '.join(names)})"
                     + (f"; did you mean {close[0]!r}?" if close else ""))


def _not_a_file(candidate: Path) -> str:
    """What ``candidate`` is when it exists but is no regular file (or is a link to nothing); '' if it is absent."""
    if candidate.is_symlink() and not candidate.exists():
        try:
            candidate.resolve(strict=True)
        except RuntimeError:  # Python < 3.13 reports a loop so
            return "a symbolic link in a loop"
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                return "a symbolic link in a loop"
            return "a symbolic link to a file that does not exist"
        return "a symbolic link to a file that does not exist"
    if candidate.is_dir():
        return "a folder"
    if candidate.exists():
        return "not a regular file (a device, a pipe or a socket)"
    return ""


def _short(text: str, limit: int = 120) -> str:
    """``text`` quoted, its middle cut out when it is longer than ``limit`` (a refused 5000-character name)."""
    return repr(text) if len(text) <= limit else repr(f"{text[:limit // 2]}...{text[-limit // 2:]}")


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
