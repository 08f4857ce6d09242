"""`modelgen simulate`'s flight report: a streamed flight, its figures, summary and history files."""

import os
import threading

import numpy as np
import pytest

from modelgen.simulation.flight_report import simulate
from modelgen.simulation.scenario import load_profile

pytestmark = pytest.mark.flight


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


def test_a_flight_started_before_the_model_is_derived_flies_the_same_histories(paper_derived, tmp_path):
    from modelgen.errors import ModelError
    from modelgen.simulation.flight_start import start_flight

    scenario = load_profile("profile_000").with_changes(hours=1 / 60, imu_rate=30.0)
    simulate(scenario, paper_derived, tmp_path / "here", runs=0, echo=lambda line: None, implementation="reference",
             history_csv=True)
    simulate(scenario, paper_derived, tmp_path / "early", runs=0, echo=lambda line: None, implementation="reference",
             history_csv=True, started=start_flight(scenario, 0))
    for mode in ("open_loop", "closed_loop", "accumulated"):
        assert (tmp_path / "here" / f"history_{mode}.csv").read_bytes() == \
            (tmp_path / "early" / f"history_{mode}.csv").read_bytes()
    with pytest.raises(ModelError, match="seed 1 is not this one"):
        simulate(scenario, paper_derived, tmp_path / "other", runs=0, echo=lambda line: None,
                 implementation="reference", started=start_flight(scenario, 1))


def test_figures_drawn_by_the_figure_process_are_the_bytes_drawn_here(paper_derived, tmp_path):
    from modelgen.simulation.flight_start import start_flight

    scenario = load_profile("profile_000").with_changes(hours=1 / 60, imu_rate=30.0)
    started = start_flight(scenario, 0)
    if started.figures is None:
        assert threading.active_count() > 1
        pytest.skip("a thread runs in this test process: it forks no figure process")
    simulate(scenario, paper_derived, tmp_path / "apart", runs=0, echo=lambda line: None, implementation="reference",
             started=started)
    simulate(scenario, paper_derived, tmp_path / "here", runs=0, echo=lambda line: None, implementation="reference",
             started=start_flight(scenario, 0, figure_process=False))
    for name in ("trajectory.png", "correction_modes.png", "filter_errors.png"):
        assert (tmp_path / "apart" / name).read_bytes() == (tmp_path / "here" / name).read_bytes()
    with pytest.raises(ChildProcessError):
        os.waitpid(started.figures.pid, os.WNOHANG)
