"""Reading YAML data files (error budgets, scenarios, profiles) with useful errors."""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from modelgen.errors import ModelError


def package_path(*parts: str) -> Path:
    """Path of a file or folder shipped inside the installed package (``models``, ``data``...).

    The one lookup of shipped files: it goes through ``importlib.resources``,
    so it finds them in a source checkout, an editable install and a wheel alike.
    """
    place = resources.files("modelgen")
    for part in parts:
        place = place / part
    return Path(str(place))


def display_path(path: str | Path) -> str:
    """How a report names ``path``: never an absolute path of this machine.

    A file shipped in the package is ``modelgen/<its place in the package>``;
    a user's file is named relative to the working folder when it lies below
    it, else by its file name alone.
    """
    path = Path(path)
    try:
        resolved = path.resolve()
    except OSError:
        return path.name
    root = Path(str(resources.files("modelgen"))).resolve()
    for base, prefix in ((root, "modelgen"), (Path.cwd().resolve(), "")):
        try:
            relative = resolved.relative_to(base)
        except ValueError:
            continue
        return f"{prefix}/{relative.as_posix()}" if prefix else relative.as_posix()
    return path.name


#: Largest YAML data file read (scenarios, tables, configurations), in bytes, as a model file's limit.
MAX_DATA_FILE_BYTES = 1_000_000


def data_path(filename: str = "") -> Path:
    """Path of a file shipped in ``modelgen/data`` (the folder itself without a file name)."""
    return package_path("data", filename) if filename else package_path("data")


def read_yaml(path: str | Path, what: str = "data file") -> dict[str, Any]:
    """A YAML mapping from ``path``; ModelError naming the file otherwise."""
    return read_yaml_with_lines(path, what)[0]


def read_yaml_with_lines(path: str | Path, what: str = "data file") -> tuple[dict[str, Any], dict[str, str]]:
    """A YAML mapping from ``path`` and the ``file:line`` of each key (see ``key_lines``)."""
    path = Path(path)
    if path.is_dir():
        raise ModelError(f"{path}: is a folder, not a {what}")
    if not path.is_file():
        raise ModelError(f"{path}: no such {what}")
    size = path.stat().st_size
    if size > MAX_DATA_FILE_BYTES:  # refused by size before a byte is parsed (a 13 MB table ran over 2 min)
        raise ModelError(f"{path}: {size} bytes; a {what} may have at most {MAX_DATA_FILE_BYTES}")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        line = exc.object[:exc.start].count(b"\n") + 1
        raise ModelError(f"{path}:{line}: not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    try:
        data = yaml.safe_load(text)
        lines = key_lines(text, str(path))
    except yaml.YAMLError as exc:
        mark, context = getattr(exc, "problem_mark", None), getattr(exc, "context_mark", None)
        last = max(len(text.splitlines()), 1)  # the stream's end is past the last line: name the last one
        where = f"{path}:{min(mark.line + 1, last)}" if mark is not None else str(path)
        opened = (f"; {exc.context} at line {context.line + 1}"
                  if context is not None and getattr(exc, "context", None) and mark is not None
                  and context.line != mark.line else "")
        raise ModelError(f"{where}: not valid YAML ({getattr(exc, 'problem', None) or exc}{opened})") from None
    except RecursionError:
        raise ModelError(f"{path}: nested too deeply to read") from None
    except ModelError:  # a key given twice (key_lines); a ModelError is a ValueError, not a too long number
        raise
    except ValueError as exc:  # an integer of over 4300 digits (Python's limit on int(str))
        digits = re.search(r"[0-9]{4301,}", text)  # the loader's error has no mark: the line of the first such run
        where = f"{path}:{text.count(chr(10), 0, digits.start()) + 1}" if digits else str(path)
        raise ModelError(f"{where}: a number too long to read ({exc})") from None
    if not isinstance(data, dict):
        raise ModelError(f"{path}:{_first_content_line(text)}: expected a mapping at the top level, got "
                         f"{_kind(data)}")
    return data, lines


def _first_content_line(text: str) -> int:
    """The first line of ``text`` that holds YAML content (not blank, a comment or a directive), else 1."""
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped and not stripped.startswith(("#", "%")) and stripped != "---":
            return number
    return 1


def _kind(value: Any) -> str:
    """What a YAML document that is not a mapping holds, in words."""
    if value is None:
        return "nothing (an empty document)"
    if isinstance(value, list):
        return "a list"
    return f"a {type(value).__name__} ({str(value)[:40]!r})"


def key_lines(text: str, filename: str) -> dict[str, str]:
    """``file:line`` of every key and list item, by dotted path (``doppler.period_s``, ``segments[0].duration_h``).

    An aliased node is walked once (at its anchor), so an alias bomb costs
    no more than its text.  A key given twice in one mapping is refused at its second line (YAML would keep the
    second value silently, and the first's line).
    """
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    lines: dict[str, str] = {}
    seen: set[int] = set()
    pending = [(root, "")] if root is not None else []
    while pending:
        node, path = pending.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            first: dict[str, int] = {}
            for key, value in node.value:
                sub = f"{path}.{key.value}" if path else str(key.value)
                line = key.start_mark.line + 1
                if isinstance(key, yaml.ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
                    if key.value in first:  # YAML keeps the last silently, and a refusal would name the first's line
                        raise ModelError(f"{filename}:{line}: key {sub!r} appears twice (first at line "
                                         f"{first[key.value]})")
                    first[key.value] = line
                lines.setdefault(sub, f"{filename}:{line}")
                pending.append((value, sub))
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                sub = f"{path}[{i}]"
                lines.setdefault(sub, f"{filename}:{item.start_mark.line + 1}")
                pending.append((item, sub))
    return lines


def require(data: dict[str, Any], key: str, where: str) -> Any:
    """``data[key]``, or ModelError naming the missing key and where."""
    if not isinstance(data, dict) or key not in data:
        raise ModelError(f"{where}: missing key {key!r}")
    return data[key]
