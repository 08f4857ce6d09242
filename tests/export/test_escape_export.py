"""The LaTeX and Octave escapers of modelgen.codegen.escape: hostile free text stays inert, on one line."""

from __future__ import annotations

import pytest

from modelgen.codegen.escape import latex_text, octave_comment, octave_string

HOSTILE = [
    "\\input{/etc/passwd}",
    "\\immediate\\write18{touch PWNED}",
    "$x^2$ & y # 100% _ ~ {",
    "line one\nline two\r\n\u2028\u202e",
    "%{\nblock\n%}",
    "it's ' quoted",
]


@pytest.mark.parametrize("text", HOSTILE)
def test_latex_text_has_no_active_character_left(text):
    out = latex_text(text)
    assert "\n" not in out and "\r" not in out
    stripped = out
    for safe in ("\\textbackslash{}", "\\textasciicircum{}", "\\textasciitilde{}", "\\{", "\\}", "\\$", "\\&", "\\#", "\\%", "\\_"):
        stripped = stripped.replace(safe, "")
    assert not set(stripped) & set("\\{}$&#%_^~")


def test_latex_text_keeps_the_words():
    assert latex_text("gyro_drift 0.1 deg/h & 50%") == "gyro\\_drift 0.1 deg/h \\& 50\\%"


@pytest.mark.parametrize("text", HOSTILE)
def test_octave_comment_is_one_line_that_cannot_open_a_block_comment(text):
    out = octave_comment(text)
    assert "\n" not in out and "\r" not in out
    assert "%{" not in out and "%}" not in out and "#{" not in out


@pytest.mark.parametrize("text", HOSTILE)
def test_octave_string_is_one_literal(text):
    out = octave_string(text)
    assert out.startswith("'") and out.endswith("'") and "\n" not in out
    assert "'" not in out[1:-1].replace("''", "")


def test_octave_string_value_round_trips():
    assert octave_string("it's") == "'it''s'"
