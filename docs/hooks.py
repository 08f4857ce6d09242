"""MkDocs hook: the docstrings' Sphinx roles (:func:`x`, :class:`~a.b.C`) shown as code, not as role markup.

modelgen's docstrings cross-reference in Sphinx's style; mkdocstrings renders the
role's name before the code.  This drops the role and, as Sphinx does for ``~``,
keeps only the last component of a name written with a tilde.
"""

from __future__ import annotations

import re

_ROLE = re.compile(r":(?:func|mod|class|meth|attr|data|exc|obj|const):<code>(~?)([^<]*)</code>")


def _code(match: re.Match) -> str:
    name = match.group(2).rsplit(".", 1)[-1] if match.group(1) else match.group(2)
    return f"<code>{name}</code>"


def on_page_content(html: str, **kwargs) -> str:
    """The page's HTML with every rendered role replaced by its code."""
    return _ROLE.sub(_code, html)
