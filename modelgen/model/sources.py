"""The source documents and how reports cite them.

Model files, data files and code comments refer to the four source documents
as "the core paper" ... "the accumulated-correction paper" (short, and stable while the texts are OCR'd).
A reader of a report needs the author and the title instead, so report
writers pass their text through :func:`cite_sources`, which replaces each
mention (and a file name printed after it) with a full citation from
``modelgen/data/sources.yaml``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path, read_yaml

SOURCES_FILE = "sources.yaml"

#: "the core paper", optionally followed by the file name in parentheses, as data files print it
_MENTION = re.compile(r"\bseed (\d{3})(?: \((\d{3}_[0-9a-f]{16}\.txt)\))?")


@dataclass(frozen=True)
class Source:
    """One source document."""

    key: str
    authors: str
    title: str
    venue: str
    file: str

    def citation(self) -> str:
        """Authors, *title*, venue (source file ...)."""
        return f"{self.authors}, *{self.title}*, {self.venue} (source file `{self.file}`)"


@lru_cache(maxsize=1)
def load_sources() -> dict[str, Source]:
    """The documents of ``modelgen/data/sources.yaml``, by their three-digit key."""
    path = data_path(SOURCES_FILE)
    entries = read_yaml(path).get("sources") or {}
    sources = {}
    for key, entry in entries.items():
        missing = [f for f in ("authors", "title", "venue", "file") if not entry.get(f)]
        if missing:
            raise ModelError(f"{path}: sources.{key}: missing {', '.join(missing)}")
        sources[str(key)] = Source(str(key), *(str(entry[f]) for f in ("authors", "title", "venue", "file")))
    return sources


def cite_sources(text: str) -> str:
    """``text`` with every "seed NNN [(file)]" replaced by the document's full citation.

    An unknown seed number is left as written (a report must never fail on its prose).
    """
    sources = load_sources()

    def replace(match: re.Match) -> str:
        source = sources.get(match.group(1))
        return source.citation() if source is not None else match.group(0)

    return _MENTION.sub(replace, text)
