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


def test_coinciding_modes_names_a_curve_lying_on_an_earlier_one_only():
    from modelgen.simulation.flight_report import coinciding_modes

    base = np.linspace(1.0, 2.0, 50)
    notes = coinciding_modes({"open_loop": base, "closed_loop": base * 1.5, "accumulated": base * 1.5 * (1 + 1e-6)})
    assert list(notes) == ["accumulated"]
    assert notes["accumulated"][0] == "closed_loop" and notes["accumulated"][1] < 1e-5


def test_pixel_envelope_keeps_each_pixel_columns_first_last_smallest_and_largest_sample():
    from modelgen.simulation.flight_report import pixel_envelope

    rng = np.random.default_rng(3)
    values = np.cumsum(rng.standard_normal(10_000))
    values[1234] = np.nan
    columns = 97
    kept = pixel_envelope(values, columns)
    assert np.all(np.diff(kept) > 0) and len(kept) <= 4 * columns + 1
    assert 1234 in kept
    edges = np.linspace(0, len(values), columns + 1).round().astype(int)
    for start, stop in zip(edges[:-1], edges[1:]):
        run = values[start:stop]
        mine = values[kept[(kept >= start) & (kept < stop)]]
        assert start in kept and stop - 1 in kept
        assert np.nanmin(mine) == np.nanmin(run) and np.nanmax(mine) == np.nanmax(run)


def test_pixel_envelope_keeps_every_sample_of_a_short_series_and_refuses_no_columns():

    from modelgen.simulation.flight_report import pixel_envelope

    assert list(pixel_envelope(np.arange(40.0), 10)) == list(range(40))
    with pytest.raises(ValueError, match="columns must be positive"):
        pixel_envelope(np.arange(40.0), 0)


def _write_text(text, path):
    path.write_text(text, encoding="utf-8")
    return path


def _fail(path):
    raise RuntimeError(f"cannot draw {path.name}")


def test_draw_figures_returns_the_paths_in_order_and_the_one_drawn_apart_is_written(tmp_path):
    from modelgen.simulation.flight_report import draw_figures

    drawings = [(_write_text, (name, tmp_path / f"{name}.txt")) for name in ("a", "b", "c")]
    assert draw_figures(drawings, apart=1) == [tmp_path / "a.txt", tmp_path / "b.txt", tmp_path / "c.txt"]
    assert [(tmp_path / f"{name}.txt").read_text(encoding="utf-8") for name in "abc"] == ["a", "b", "c"]


def test_draw_figures_raises_the_error_of_a_figure_drawn_apart(tmp_path):

    from modelgen.simulation.flight_report import draw_figures

    with pytest.raises(RuntimeError, match="cannot draw b.txt"):
        draw_figures([(_write_text, ("a", tmp_path / "a.txt")), (_fail, (tmp_path / "b.txt",))], apart=1)


def test_a_flight_started_before_the_model_is_derived_flies_the_same_histories(paper_derived, tmp_path):
    from modelgen.errors import ModelError
    from modelgen.simulation.flight_report import start_flight

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


def _write_pid(path):
    path.write_text(str(os.getpid()), encoding="utf-8")
    return path


def _figure_process():
    from modelgen.simulation.flight_report import FigureProcess

    process = FigureProcess.start()
    assert process is not None or threading.active_count() > 1  # only a process running another thread does not fork
    if process is None:
        pytest.skip("a thread runs in this test process: it forks no figure process")
    return process


def test_the_figure_process_draws_in_another_process_and_returns_the_paths_in_order(tmp_path):
    process = _figure_process()
    try:
        process.draw([(_write_pid, (tmp_path / f"{name}.txt",)) for name in "abc"], apart=1)
        assert process.paths() == [tmp_path / "a.txt", tmp_path / "b.txt", tmp_path / "c.txt"]
    finally:
        process.close()
    writers = {(tmp_path / f"{name}.txt").read_text(encoding="utf-8") for name in "abc"}
    assert str(os.getpid()) not in writers and len(writers) == 2  # the figure process and its copy for "b"
    with pytest.raises(ChildProcessError):
        os.waitpid(process.pid, os.WNOHANG)  # waited for: gone


def test_a_figure_the_figure_process_fails_to_draw_is_drawn_here_and_raises_its_error(tmp_path):
    process = _figure_process()
    try:
        process.draw([(_write_text, ("a", tmp_path / "a.txt")), (_fail, (tmp_path / "b.txt",))], apart=0)
        with pytest.raises(RuntimeError, match="cannot draw b.txt"):
            process.paths()
    finally:
        process.close()


def test_drawings_that_do_not_pickle_are_drawn_here(tmp_path):
    process = _figure_process()
    try:
        process.draw([(lambda path: _write_pid(path), (tmp_path / "a.txt",))], apart=0)
        assert process.paths() == [tmp_path / "a.txt"]
    finally:
        process.close()
    assert (tmp_path / "a.txt").read_text(encoding="utf-8") == str(os.getpid())


def test_figures_drawn_by_the_figure_process_are_the_bytes_drawn_here(paper_derived, tmp_path):
    from modelgen.simulation.flight_report import start_flight

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
