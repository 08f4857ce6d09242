"""The run's mechanization cross-checks (modelgen.checks.mechanizations): the report section and files they give.

The comparisons themselves are tested in tests/model/test_ecef_mechanization.py and
tests/model/test_wander_azimuth_mechanization.py; here the whole check is run once, as
``modelgen run`` runs it, and its section of the run report and mechanizations.md/.json read.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from modelgen.checks import mechanizations as mech
from modelgen.jobs import mechanizations_section, missed_targets, run_report


@pytest.fixture(scope="module")
def checks(mechanization_models):
    """The run's checks over the session's derived models (tests/conftest.py: derive_mechanization_models(), once)."""
    return mech.run_mechanization_checks(mechanization_models)


def _report(checks) -> str:
    return run_report("65 entries; 0 unexplained.", [], Path("generated"), [mechanizations_section(checks)],
                      paper_targets=({"quantity": "unexplained", "reached": "0", "target": "0", "met": True},))


def test_the_run_reports_every_mechanization_check_passed_with_its_numbers(checks, tmp_path):
    assert checks.passed, checks.failed
    points = {c.point for c in checks.comparisons}
    assert points == set(mech.POINT_IDS)  # ECEF at all five points (89.9 N included), wander at the four local level takes
    assert {c.point for c in checks.comparisons if c.check == "wander_vs_local_level"} == set(mech.POINT_IDS[:4])
    text = _report(checks)
    targets = text.split("## Targets\n", 1)[1].split("\n## ", 1)[0]
    assert "| Mechanizations cross-checked | mechanization cross-checks outside their bound (incl. the polar flight) | 0 | 0 | met |" in targets
    section = text.split("## Mechanizations cross-checked (ECEF and wander azimuth against local level)\n", 1)[1]
    assert "Every check passed: **yes**" in section and "within 1 deg of a pole" in section and "(ok)" in section
    n_ecef = len([c for c in checks.comparisons if c.check == "ecef_vs_local_level"])
    assert f"| ECEF against local level through T = diag(C_n^e, C_n^e, C_n^e, I) | {n_ecef} | {n_ecef} |" in section
    markdown, data = mech.write_mechanizations_report(checks, tmp_path)
    written = json.loads(data.read_text())
    assert written["passed"] and len(written["comparisons"]) == len(checks.comparisons)
    assert all(r["passed"] == (r["difference"] <= r["bound"]) for r in written["comparisons"] if not r["at_least"])
    assert written["polar"]["local_level_message"].startswith(f"{mech.LOCAL_LEVEL_MODEL}_polar.yaml:")
    assert "| 45N_10E_300m | G |" in markdown.read_text() and "**FAILED**" not in markdown.read_text()


def test_a_failed_mechanization_check_is_a_missed_target_and_says_so(checks):
    worst = checks.comparisons[0]
    broken = dataclasses.replace(checks, comparisons=(dataclasses.replace(worst, difference=2 * worst.bound + 1.0),
                                                      *checks.comparisons[1:]))
    assert broken.failed == [f"{worst.check} {worst.point} {worst.matrix}"]
    text = _report(broken)
    assert missed_targets(text) == ["Mechanizations cross-checked: mechanization cross-checks outside their bound "
                                    "(incl. the polar flight) (1, target 0)"]
    assert "Every check passed: **no**" in text and "**FAILED**" in mech.mechanizations_markdown(broken)
    unrefused = dataclasses.replace(checks, polar=dataclasses.replace(checks.polar, local_level_refused=False, local_level_message=""))
    assert unrefused.failed == ["polar flight"]
