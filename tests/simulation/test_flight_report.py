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


def test_summary_names_no_absolute_path_and_counts_one_run_as_one_run(paper_derived, tmp_path):
    scenario = load_profile("profile_000").with_changes(hours=1 / 20, imu_rate=30.0)
    summary = simulate(scenario, paper_derived, tmp_path, runs=1, echo=lambda line: None, implementation="reference")
    text = summary.read_text(encoding="utf-8")
    assert "(modelgen/data/profile_000.yaml)" in text
    assert "Yuan Xin and Yu Zaixin, *Low-cost Doppler-aided strapdown inertial navigation system*" in text
    assert "site-packages" not in text and str(tmp_path) not in text and "/work/" not in text
    assert "## Monte Carlo (1 run, " in text and "1 runs" not in text
    assert "Filter: the dense numpy reference filter" in text.split("## Monte Carlo")[1]


def test_coinciding_modes_names_a_curve_lying_on_an_earlier_one_only():
    from modelgen.simulation.flight_report import coinciding_modes

    base = np.linspace(1.0, 2.0, 50)
    notes = coinciding_modes({"open_loop": base, "closed_loop": base * 1.5, "accumulated": base * 1.5 * (1 + 1e-6)})
    assert list(notes) == ["accumulated"]
    assert notes["accumulated"][0] == "closed_loop" and notes["accumulated"][1] < 1e-5
