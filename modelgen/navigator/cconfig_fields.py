"""One field of the C navigator's configuration struct (:mod:`modelgen.navigator.cconfig` lists them all)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Field:
    """One configuration field: name, C type (double or int), count (1, a number, or "P") and meaning with unit."""

    name: str
    ctype: str
    count: int | str
    meaning: str
