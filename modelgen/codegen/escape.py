"""Free text of a model rendered as inert text in every generated language.

A model file is untrusted data, and its free-text fields (title, source,
notes, units, descriptions) end up in comments of the generated C, Python,
Markdown, CMake and Makefile.  Text that could close the comment (``*/``,
a line break), start another one, splice lines (a backslash at the end of a
line continues a Makefile comment; the trigraph ``??/`` is a backslash in
C) or reorder what a reader sees (bidirectional overrides, "Trojan Source")
must never get through.  Each function here takes any string and returns
one line that is safe in its one context; the templates apply them as jinja2
filters (``|c_comment``, ``|py_comment``, ``|md_text``, ``|hash_comment``,
``|py_string``), so no template pastes free text raw.  jinja2's autoescape
is off: it escapes for HTML, which is none of these languages.

Text keeps its meaning for a reader: line breaks become spaces, ``*/``
becomes ``* /``, and UTF-8 letters stay (C99 and Python 3 accept them in
comments; gcc, clang and arm-none-eabi-gcc read UTF-8 source).
"""

from __future__ import annotations

import re
import unicodedata

_INVISIBLE = ("Cc", "Cf", "Zl", "Zp", "Cs", "Co", "Cn")


def one_line(text: object) -> str:
    """``text`` on one line: every control, format (bidi override) or separator character is a space.

    Runs of white space collapse to one space and the ends are stripped, so
    that a multi-line description reads as one sentence.
    """
    chars = [" " if (ch.isspace() or unicodedata.category(ch) in _INVISIBLE) else ch for ch in str(text)]
    return re.sub(r" {2,}", " ", "".join(chars)).strip()


def c_comment(text: object) -> str:
    """Text for the inside of a C ``/* ... */`` comment, on one line.

    ``*/`` and ``/*`` are split by a space (neither can close the comment or
    nest a new one), ``??`` becomes ``? ?`` (no trigraph, so no ``??/`` line
    splice), and a final backslash gets a space after it (no line splice if
    a template ends the line there).
    """
    line = one_line(text)
    while "*/" in line or "/*" in line or "??" in line:
        line = line.replace("*/", "* /").replace("/*", "/ *").replace("??", "? ?")
    return line + " " if line.endswith("\\") else line


def py_comment(text: object) -> str:
    """Text for a Python ``#`` comment, on one line: nothing but a line break ends one."""
    return one_line(text)


def py_string(text: object) -> str:
    """A Python string literal whose value is ``text`` (``repr``: quotes and backslashes escaped)."""
    return repr(str(text))


def hash_comment(text: object) -> str:
    """Text for a ``#`` comment in a Makefile or CMakeLists.txt, on one line.

    A final backslash would continue a Makefile comment onto the next line,
    so it gets a space after it; ``[[``/``[=`` right after ``#`` would open
    a CMake bracket comment, so a leading ``[`` is preceded by a space.
    """
    line = one_line(text)
    if line.startswith("["):
        line = " " + line
    return line + " " if line.endswith("\\") else line


_MARKDOWN_SPECIAL = re.compile(r"([\\`*_\[\]#!|~>])")
_MARKDOWN_BULLET = re.compile(r"^([-+=])")
_MARKDOWN_ORDERED = re.compile(r"^(\d+)([.)])")


def md_text(text: object) -> str:
    """Text for Markdown prose, on one line: markup characters backslash-escaped, ``<``/``&`` as entities.

    The result renders as the literal text: no emphasis, link, image, code
    span, heading, list, table cell or raw HTML can come out of it, even at
    the start of a line.  Ordinary punctuation (``-``, ``.``, parentheses)
    stays as it is inside the text.
    """
    line = one_line(text).replace("&", "&amp;").replace("<", "&lt;")
    line = _MARKDOWN_SPECIAL.sub(r"\\\1", line)
    line = _MARKDOWN_BULLET.sub(r"\\\1", line)
    return _MARKDOWN_ORDERED.sub(r"\1\\\2", line)


_LATEX_SPECIAL = {
    "\\": r"\textbackslash{}",
    "{": r"\{",
    "}": r"\}",
    "$": r"\$",
    "&": r"\&",
    "#": r"\#",
    "%": r"\%",
    "_": r"\_",
    "^": r"\textasciicircum{}",
    "~": r"\textasciitilde{}",
}


def latex_text(text: object) -> str:
    """Text for LaTeX prose or a table cell, on one line: every special character typeset literally.

    Backslash, braces, ``$ & # % _ ^ ~`` are replaced by their text forms, so
    no command (``\\input``, ``\\write18``), group, math mode, alignment tab or
    comment can come out of the text; a line break cannot end a ``%``
    comment line or start a paragraph.
    """
    return "".join(_LATEX_SPECIAL.get(ch, ch) for ch in one_line(text))


def octave_comment(text: object) -> str:
    """Text for an Octave/MATLAB ``%`` comment line, on one line.

    Only a line break ends such a comment; a line holding just ``%{`` or
    ``#{`` would open a block comment, so braces after a comment character
    are split by a space.
    """
    line = one_line(text)
    for opener in ("%{", "%}", "#{", "#}"):
        line = line.replace(opener, opener[0] + " " + opener[1])
    return line


def octave_string(text: object) -> str:
    """An Octave/MATLAB single-quoted string literal whose value is ``text`` on one line (quotes doubled)."""
    return "'" + one_line(text).replace("'", "''") + "'"


FILTERS = {
    "c_comment": c_comment,
    "py_comment": py_comment,
    "py_string": py_string,
    "hash_comment": hash_comment,
    "md_text": md_text,
    "latex_text": latex_text,
    "octave_comment": octave_comment,
    "octave_string": octave_string,
}
