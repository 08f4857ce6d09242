"""Free text of a model is data in every generated language: nothing in it runs, and it stays readable.

Each hostile or awkward text goes into the title, source, a unit and a
description; the C is compiled strictly and loaded (a constructor would run
at load), the Python module imported, and no file named PWNED may appear.
"""

import ctypes
import shutil
import subprocess

import pytest
import yaml

from modelgen.codegen.escape import c_comment, hash_comment, md_text, one_line, py_comment
from tests.codegen.generated_support import build_text

PYTHON_ESCAPE = "x\"\"\"; open('PWNED', 'w'); \"\"\""
C_ESCAPE = '*/ __attribute__((constructor)) static void pwned(void) { extern void *fopen(const char *, const char *); fopen("PWNED", "w"); } /*'
C_LINE_SPLICE = "ends in a backslash \\"
HOSTILE = {
    "python_docstring_escape": PYTHON_ESCAPE,
    "c_comment_escape": C_ESCAPE,
    "star_slash": "a*/b",
    "triple_quotes": 'say """hi"""',
    "windows_path": "C:\\path\\to\\",
    "line_splice": C_LINE_SPLICE,
    "trigraph_backslash": "what??/",
    "markdown_html": "<img src=x onerror=alert(1)> [link](http://x) # heading | cell",
    "utf8": "Müller, 3°/h ± 0.5 — gyro",
}


def model_text(text: str) -> str:
    """A small valid model whose every free-text field is ``text``."""
    return yaml.safe_dump(
        {
            "model": "freetext",
            "title": text,
            "source": text,
            "frame": "NED",
            "parameters": [{"name": "rate", "symbol": "mu", "unit": "1/s", "description": text, "value": 0.01}],
            "states": [
                {"name": "bias", "symbol": "b", "unit": "m/s", "description": text},
                {"name": "drift", "symbol": "d", "unit": "m"},
            ],
            "noises": [{"name": "bias_noise", "symbol": "w", "psd": "mu"}],
            "dynamics": {"b": "-mu*b + w", "d": "b"},
            "measurements": [{"name": "drift_measured", "symbol": "z", "unit": "m", "expression": "d", "variance": "1"}],
        },
        allow_unicode=True,
        sort_keys=False,
    )


@pytest.mark.compile
@pytest.mark.parametrize("text", list(HOSTILE.values()), ids=list(HOSTILE))
def test_free_text_runs_nothing_and_stays_readable(text, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    built = build_text(model_text(text), tmp_path / "out")  # compiles with -Werror -pedantic
    ctypes.CDLL(str(built.library))  # a constructor smuggled into the C would run here
    assert built.python.TITLE == text and built.python.SOURCE == text  # the import ran nothing else
    assert not list(tmp_path.rglob("PWNED"))
    files = built.code.files
    assert c_comment(text) in files["freetext.h"]
    assert py_comment(text) in files["freetext.py"]
    assert md_text(text) in files["README.md"]


@pytest.mark.compile
def test_python_docstring_escape_stays_inside_a_comment_and_a_string(tmp_path):
    source = build_text(model_text(PYTHON_ESCAPE), tmp_path / "out").code.files["freetext.py"]
    assert f"# Model freetext: {PYTHON_ESCAPE}" in source
    assert f"TITLE = {PYTHON_ESCAPE!r}" in source
    assert PYTHON_ESCAPE not in source.split('"""')[1]  # the docstring does not carry it


def test_c_comment_cannot_be_closed_nested_or_spliced():
    assert c_comment("a*/b") == "a* /b"
    assert c_comment("a/*b") == "a/ *b"
    assert c_comment("a**//b") == "a** //b"
    assert "??" not in c_comment("what??/") and "??" not in c_comment("???")
    assert c_comment(C_LINE_SPLICE).endswith("\\ ")
    assert "*/" not in c_comment(C_ESCAPE)


def test_line_breaks_and_invisible_characters_become_spaces():
    assert one_line("first line\nsecond\r\nthird\u2028fourth\tend") == "first line second third fourth end"
    assert one_line("abc\u202edcba") == "abc dcba"
    assert one_line("Müller, 3°/h") == "Müller, 3°/h"  # UTF-8 letters stay (C99 and Python accept them in comments)


def test_markdown_text_cannot_open_markup():
    assert md_text("<b>x</b> & *y*") == "&lt;b\\>x&lt;/b\\> &amp; \\*y\\*"
    assert md_text("# title") == "\\# title"
    assert md_text("- item") == "\\- item"
    assert md_text("1. item") == "1\\. item"
    assert md_text("Single-axis (loop), 2.5 m") == "Single-axis (loop), 2.5 m"  # ordinary punctuation stays


def test_hash_comment_cannot_continue_a_makefile_comment_or_open_a_cmake_bracket():
    assert hash_comment("path\\") == "path\\ "
    assert hash_comment("[[bracket") == " [[bracket"


@pytest.mark.compile
@pytest.mark.skipif(shutil.which("make") is None, reason="no make")
@pytest.mark.parametrize("text", [C_LINE_SPLICE, "C:\\path\\to\\"], ids=["line_splice", "windows_path"])
def test_a_title_ending_in_a_backslash_does_not_swallow_the_next_makefile_line(text, tmp_path):
    """A backslash at the end of a Makefile comment continues it: the CFLAGS line after the title would vanish."""
    built = build_text(model_text(text), tmp_path / "out")
    assert hash_comment(text) in built.code.files["Makefile"] and hash_comment(text) in built.code.files["CMakeLists.txt"]
    dry_run = subprocess.run(["make", "-n", "-C", str(built.folder)], capture_output=True, text=True, env={"PATH": "/usr/bin:/bin"})
    assert dry_run.returncode == 0, dry_run.stderr
    assert "-std=c99" in dry_run.stdout
