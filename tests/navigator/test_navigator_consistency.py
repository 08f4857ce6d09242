"""Consistency measured honestly (issue 26 item 4): e^T P_h^-1 e at the outage ends from the filter's 2x2
horizontal covariance, its mean and the fraction inside the 95 % region, per schedule and pooled."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from modelgen.errors import ModelError

pytestmark = pytest.mark.flight

DATA = Path(__file__).parent / "data"


def test_normalized_squared_error_uses_the_full_2x2_covariance():
    from modelgen.navigator.metrics import NEES_BOUND_95, consistency, normalized_squared_error

    P = np.array([[4.0, 1.9], [1.9, 1.0]])  # strongly correlated north and east
    e = np.array([2.0, -1.0])  # across the correlation: far outside although each axis is within 1 sigma
    assert normalized_squared_error(e, P) == pytest.approx(e @ np.linalg.solve(P, e))
    assert normalized_squared_error(e, P) > 30
    assert np.isnan(normalized_squared_error(e, np.array([[1.0, 2.0], [2.0, 1.0]])))  # not positive definite
    assert NEES_BOUND_95 == pytest.approx(chi2.ppf(0.95, 2))
    stats = consistency([1.0, 3.0, 8.0, float("nan")])
    assert stats["count"] == 3 and stats["nees_mean"] == pytest.approx(4.0)
    assert stats["inside_95_fraction"] == pytest.approx(2 / 3)


def test_a_consistent_gaussian_error_gives_mean_two_and_95_percent_inside():
    from modelgen.navigator.metrics import consistency, normalized_squared_error

    rng = np.random.default_rng(1)
    P = np.array([[2.0, 0.7], [0.7, 0.5]])
    errors = rng.multivariate_normal([0.0, 0.0], P, size=4000)
    stats = consistency([normalized_squared_error(e, P) for e in errors])
    assert stats["nees_mean"] == pytest.approx(2.0, rel=0.05)
    assert stats["inside_95_fraction"] == pytest.approx(0.95, abs=0.01)


def _with_evaluation(tmp_path: Path) -> Path:
    text = (DATA / "excerpt.yaml").read_text(encoding="utf-8")
    for name in ("excerpt_imu.csv.gz", "excerpt.pos"):
        text = text.replace(f"file: {name}", f"file: {DATA / name}")
    text += ("evaluation:\n  target_nees_mean: [1.0, 4.0]\n  target_inside_95_fraction: 0.8\n"
             "  schedules:\n    - {name: later, windows: [[20.0, 10.0]], target_end_rms_m: 4.0}\n")
    path = tmp_path / "excerpt_eval.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_replay_states_nees_per_outage_end_per_schedule_and_pooled(tmp_path):
    from click.testing import CliRunner

    from modelgen.cli import main

    out = tmp_path / "replay"
    result = CliRunner().invoke(main, ["replay", str(_with_evaluation(tmp_path)), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "3 sigma" not in result.output and "mean NEES" in result.output
    summary = json.loads((out / "summary.json").read_text())
    assert "outage_ends_inside_3sigma_fraction" not in summary
    record = summary["outages"][0]
    assert "inside_3sigma" not in record and record["nees_horizontal_end"] > 0
    assert record["inside_95"] == (record["nees_horizontal_end"] <= chi2.ppf(0.95, 2))
    names = [s["name"] for s in summary["schedules"]]
    assert names == ["configured", "later"]
    later = summary["schedules"][1]
    assert later["outage_count"] == 1 and later["ends"][0]["duration_s"] == 10.0
    ends = [e["nees_horizontal_end"] for s in summary["schedules"] for e in s["ends"]]
    assert summary["consistency_pooled"]["count"] == 2
    assert summary["consistency_pooled"]["nees_mean"] == pytest.approx(np.mean(ends))
    quantities = [t["quantity"] for t in summary["targets"]]
    assert any("pooled over 2 schedule(s)" in q for q in quantities)
    assert not any("3 sigma" in q for q in quantities)
    md = (out / "summary.md").read_text()
    assert "## Consistency over outage schedules" in md and "| later | 1 | 10 |" in md
    assert "3 sigma" not in md
    svg = (out / "consistency.svg").read_text()
    assert "95 % bound" in svg and "dimensionless" in svg
    assert "consistency.svg" in summary["figures"]


def test_the_horizontal_covariance_is_the_filters_and_the_c_matches_python():
    """The C and the Python record the same north-east cross covariance (it is not zero in a turn)."""
    from modelgen.navigator.metrics import COLUMN
    from modelgen.navigator.replay import run_replay

    both = run_replay(DATA / "excerpt.yaml", None, echo=lambda _: None, navigator="both")
    column = COLUMN["cov_north_east"]
    c = both.flight.outputs[:, column]
    assert np.abs(c).max() > 0
    sn, se = both.flight.outputs[:, COLUMN["sigma_north"]], both.flight.outputs[:, COLUMN["sigma_east"]]
    assert np.all(np.abs(c) <= sn * se * (1 + 1e-9))  # a correlation within [-1, 1]


def test_bad_evaluation_schedules_are_refused_with_their_line(tmp_path):
    from modelgen.navigator.config import load_config

    path = _with_evaluation(tmp_path)
    text = path.read_text().replace("windows: [[20.0, 10.0]]", "first_after_s: 1.0, length_s: 5.0")
    path.write_text(text)
    with pytest.raises(ModelError, match=r"excerpt_eval\.yaml:\d+: evaluation\.schedules\.period_s must be a positive"):
        load_config(path)
    path.write_text(text.replace("first_after_s: 1.0, length_s: 5.0", "lenght_s: 5.0"))
    with pytest.raises(ModelError, match=r"unknown key 'lenght_s' in evaluation\.schedules"):
        load_config(path)
