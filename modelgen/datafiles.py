"""Reading YAML data files (error budgets, scenarios, profiles) with useful errors."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from modelgen.errors import ModelError


def data_path(filename: str) -> Path:
    """Path of a file shipped in ``modelgen/data``."""
    return Path(str(resources.files("modelgen") / "data" / filename))


def read_yaml(path: str | Path, what: str = "data file") -> dict[str, Any]:
    """A YAML mapping from ``path``; ModelError naming the file otherwise."""
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"{path}: no such {what}")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise ModelError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(data, dict):
        raise ModelError(f"{path}: expected a mapping at the top level")
    return data


def require(data: dict[str, Any], key: str, where: str) -> Any:
    """``data[key]``, or ModelError naming the missing key and where."""
    if not isinstance(data, dict) or key not in data:
        raise ModelError(f"{where}: missing key {key!r}")
    return data[key]
