"""`modelgen simulate`'s flight report: a streamed flight, its figures, summary and history files."""

import numpy as np

from modelgen.simulation.flight_report import simulate
from modelgen.simulation.scenario import load_profile


def test_simulate_writes_summary_figures_and_the_histories_it_was_asked_for(paper_derived, tmp_path):
    scenario = load_profile("profile_000").with_changes(hours=1 / 20, imu_rate=30.0)
    lines = []
    summary = simulate(scenario, paper_derived, tmp_path, runs=0, echo=lines.append, implementation="reference",
                       history_csv=True)
    text = summary.read_text(encoding="utf-8")
    assert "three modes in one streamed pass" in text and "| closed_loop |" in text
    assert any("closed_loop filter: 100.0 %" in line for line in lines)
    for mode in ("open_loop", "closed_loop", "accumulated"):
        table = np.genfromtxt(tmp_path / f"history_{mode}.csv", delimiter=",", names=True)
        assert len(table) == 181 and table["time_s"][-1] == 180.0  # every filter cycle of 3 minutes and t = 0
    assert (tmp_path / "correction_modes.png").is_file()
