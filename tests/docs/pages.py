"""The documentation's pages and their code blocks, for the tests that build the site and run its examples."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
#: the pages whose examples are run: the site's, and the README's short tour
PAGES = (REPO / "README.md", *sorted(DOCS.rglob("*.md")))

_FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)


@dataclass(frozen=True)
class Block:
    """One fenced code block: its page, the line its text starts on, its language and text."""

    page: Path
    line: int
    language: str
    text: str

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(REPO)}:{self.line}"


def blocks(language: str | None = None, pages=PAGES) -> list[Block]:
    """Every fenced block of the pages (of one language), in page order."""
    found = []
    for page in pages:
        text = page.read_text(encoding="utf-8")
        for match in _FENCE.finditer(text):
            if language is None or match.group(1) == language:
                found.append(Block(page, text[: match.start(2)].count("\n") + 1, match.group(1), match.group(2)))
    return found


def page_text(name: str) -> str:
    """A page of the site by its file name (``model-language.md``)."""
    return (DOCS / name).read_text(encoding="utf-8")


def section(name: str, title: str) -> str:
    """The text of the section headed ``title`` (any level) of a page, up to the next heading of that level."""
    text = page_text(name)
    match = re.search(rf"^(#+) {re.escape(title)}\n", text, re.M)
    assert match, f"{name} has no section {title!r}"
    rest = text[match.end():]
    end = re.search(rf"^#{{1,{len(match.group(1))}}} ", rest, re.M)
    return rest[: end.start()] if end else rest


def yaml_block(page: str, starting: str) -> str:
    """The YAML block of ``page`` whose text starts with ``starting``."""
    found = [b.text for b in blocks("yaml", [DOCS / page]) if b.text.startswith(starting)]
    assert len(found) == 1, f"{page}: {len(found)} yaml blocks start with {starting!r}"
    return found[0]
