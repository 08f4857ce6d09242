"""Free-text fields common to both kinds of model file (a model, and a transform of one).

``title``, ``source``, ``frame`` and ``notes`` are read the same way whether
the file declares a model (:mod:`modelgen.model.loading`) or makes one from a
base model (:mod:`modelgen.model.transform_file`); both import them from here,
so neither file reader depends on the other's internals.
"""

from __future__ import annotations

import re
from typing import Any

from modelgen.errors import ModelError


def free_text(data: dict, key: str, lines: dict[str, str], filename: str, default: str = "") -> str:
    """A top-level free-text field (title, source, frame) as text; a list or mapping is refused."""
    value = data.get(key, default)
    if isinstance(value, (list, dict)):
        raise ModelError(f"{lines.get(key, filename)}: {key!r} must be text, not a {'list' if isinstance(value, list) else 'mapping'}")
    return "" if value is None else str(value)


def notes_text(data: dict, lines: dict[str, str], filename: str) -> list[str]:
    """The ``notes`` field as a list of texts (one text or a list of texts)."""
    notes = data.get("notes") or []
    notes = notes if isinstance(notes, list) else [notes]
    for i, note in enumerate(notes):
        if isinstance(note, (list, dict)):
            raise ModelError(f"{lines.get(f'notes[{i}]', lines.get('notes', filename))}: notes[{i}] must be text")
    return [str(n) for n in notes]


def scalar_text(value: Any, place: str, key: str) -> str:
    """The text of one scalar expression; a list, mapping or empty value is refused."""
    if value is None or (isinstance(value, str) and not value.strip()):
        raise ModelError(f"{place}: {key!r} is empty (expected one expression)")
    if isinstance(value, (list, dict)):
        kind = f"a list of {len(value)} items" if isinstance(value, list) else "a mapping"
        raise ModelError(f"{place}: {key!r} is {kind}; dimension mismatch (expected one scalar expression)")
    return value if isinstance(value, str) else str(value)


#: A number written as text: a plain decimal with an optional exponent, or inf/nan (refused later as not finite).
#: Python's float() also reads '1_000' and surrounding white space: lax forms a model file may not use.
_NUMBER_TEXT = re.compile(r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf|infinity|nan)", re.IGNORECASE)


def is_number(value: Any) -> bool:
    """Whether a YAML value is a number (or text that reads as one: ``'1.5e-3'``); true, false and ``'1_000'`` are not."""
    if isinstance(value, bool):
        return False
    if isinstance(value, (int, float)):
        return True
    return isinstance(value, str) and _NUMBER_TEXT.fullmatch(value) is not None


def as_float(value: Any, where: str) -> float:
    """A parameter value as a float; an integer beyond a double becomes inf, which is then refused.

    A nonzero number written so small that a double holds it as 0 (``1e-999``)
    is refused at ``where``: read as 0 it would change the model silently.
    """
    try:
        number = float(value)
    except OverflowError:
        return float("inf") if int(value) > 0 else float("-inf")
    if number == 0.0 and underflows_to_zero(str(value)):
        raise ModelError(f"{where}: the value {str(value)[:40]} is nonzero but below the smallest double (about 4.9e-324): it would be read as 0")
    return number


def underflows_to_zero(literal: str) -> bool:
    """Whether a decimal literal has a nonzero digit before its exponent yet reads as the double 0."""
    mantissa = re.split(r"[eE]", literal.strip(), maxsplit=1)[0]
    return re.search(r"[1-9]", mantissa) is not None and float(literal) == 0.0
