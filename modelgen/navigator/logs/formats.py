"""What a log format declares: its configuration keys (typed, with defaults) and its readers.

A format is one module with one :class:`LogFormat` entry (``FORMAT``), listed
once in :mod:`modelgen.navigator.logs.registry`.  Its keys live in the
configuration's ``imu:`` or ``gnss:`` section beside the keys every format
shares; the configuration loader builds its schema from these declarations and
validates every value here (:func:`validate_options`), so that a format's keys
are checked, defaulted and documented in one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from modelgen.errors import ModelError

REQUIRED: Any = object()
KINDS = ("text", "choice", "integer", "number", "columns3")


@dataclass(frozen=True)
class Option:
    """One configuration key of a format: ``key`` may be a path ("columns.count") under the section."""

    key: str
    kind: str  # one of KINDS
    default: Any = REQUIRED
    choices: tuple[str, ...] = ()
    doc: str = ""
    what: str = ""  # how a refusal names the value ("gyro unit"); the key path if empty


@dataclass(frozen=True)
class LogSource:
    """One log to read: the configuration's ``imu:`` or ``gnss:`` section, validated."""

    section: str  # "imu" or "gnss"
    format: str
    path: Path
    options: Mapping[str, Any]  # every Option of the format (defaults filled in)
    where: Callable[[str], str] = field(default=lambda key: "", compare=False)  # 'config:line' of a key

    def option(self, key: str) -> Any:
        return self.options[key]


@dataclass(frozen=True)
class LogFormat:
    """A format: its name, what it reads (IMU, GNSS or both), its keys and readers.

    ``read_imu(source) -> ImuLog`` and ``read_gnss(source) -> GnssLog`` return
    the log before the format-independent checks (gaps, fixes); ``folder``
    says whether the ``file`` key may name a folder (a ROS 2 bag); ``extra``
    names the pip extra the format needs (``modelgen-nav[logs]``), imported only
    when such a log is read.
    """

    name: str
    summary: str
    imu_options: tuple[Option, ...] = ()
    gnss_options: tuple[Option, ...] = ()
    read_imu: Callable[[LogSource], Any] | None = None
    read_gnss: Callable[[LogSource], Any] | None = None
    folder: bool = False
    extra: str | None = None

    def options(self, section: str) -> tuple[Option, ...]:
        return self.imu_options if section == "imu" else self.gnss_options

    def reads(self, section: str) -> bool:
        return (self.read_imu if section == "imu" else self.read_gnss) is not None


def _lookup(raw: Mapping[str, Any], key: str) -> Any:
    node: Any = raw
    for part in key.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return REQUIRED
        node = node[part]
    return node


def validate_option(option: Option, raw: Mapping[str, Any], section: str, where: Callable[[str], str]) -> Any:
    """The value of one option from the raw section, checked against its kind (or its default)."""
    name = f"{section}.{option.key}"
    value = _lookup(raw, option.key)
    if value is REQUIRED:
        if option.default is REQUIRED:
            raise ModelError(f"{where(name)}: missing key {name!r}")
        return option.default
    here = where(name)
    if option.kind == "text":
        if not isinstance(value, str) or not value.strip():
            raise ModelError(f"{here}: {name} must be text, got {value!r}")
        return value
    if option.kind == "choice":
        if not isinstance(value, str) or value not in option.choices:
            what = option.what or name
            raise ModelError(f"{here}: {what} {value!r} cannot be parsed (accepted: {', '.join(option.choices)})")
        return value
    if option.kind == "integer":
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ModelError(f"{here}: {name} must be an integer >= 0, got {value!r}")
        return value
    if option.kind == "number":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise ModelError(f"{here}: {name} must be a positive finite number, got {value!r}")
        return float(value)
    if option.kind == "columns3":
        if (not isinstance(value, list) or len(value) != 3
                or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value)):
            raise ModelError(f"{here}: {name} must be a list of 3 column numbers (1-based), got {value!r}")
        return tuple(value)
    raise ModelError(f"{here}: {name}: unknown option kind {option.kind!r}")  # a format's own mistake


def validate_options(fmt: LogFormat, section: str, raw: Mapping[str, Any],
                     where: Callable[[str], str]) -> dict[str, Any]:
    """Every option of ``fmt`` for ``section`` from the raw mapping, validated and defaulted."""
    return {o.key: validate_option(o, raw, section, where) for o in fmt.options(section)}
