"""Figures drawn in other processes (modelgen.simulation.figure_process): paths in order, errors raised here."""

import os
import threading

import pytest


def _write_text(text, path):
    path.write_text(text, encoding="utf-8")
    return path


def _fail(path):
    raise RuntimeError(f"cannot draw {path.name}")


def test_draw_figures_returns_the_paths_in_order_and_the_one_drawn_apart_is_written(tmp_path):
    from modelgen.simulation.figure_process import draw_figures

    drawings = [(_write_text, (name, tmp_path / f"{name}.txt")) for name in ("a", "b", "c")]
    assert draw_figures(drawings, apart=1) == [tmp_path / "a.txt", tmp_path / "b.txt", tmp_path / "c.txt"]
    assert [(tmp_path / f"{name}.txt").read_text(encoding="utf-8") for name in "abc"] == ["a", "b", "c"]


def test_draw_figures_raises_the_error_of_a_figure_drawn_apart(tmp_path):

    from modelgen.simulation.figure_process import draw_figures

    with pytest.raises(RuntimeError, match="cannot draw b.txt"):
        draw_figures([(_write_text, ("a", tmp_path / "a.txt")), (_fail, (tmp_path / "b.txt",))], apart=1)


def _write_pid(path):
    path.write_text(str(os.getpid()), encoding="utf-8")
    return path


def _figure_process():
    from modelgen.simulation.figure_process import FigureProcess

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


def _full_disk(path):
    import errno

    raise OSError(errno.ENOSPC, "No space left on device")  # as PIL's close() raises it: naming no file


def test_a_full_disk_while_drawing_names_the_figure_and_no_process_prints_a_traceback(tmp_path, capfd):
    """Issue 28: ``simulate`` into a full disk printed the copy's traceback, then an error naming no file."""
    from modelgen.simulation.figure_process import draw_figures

    if threading.active_count() > 1:
        pytest.skip("a thread runs in this test process: draw_figures forks no copy")
    for apart in (0, 1):
        with pytest.raises(OSError) as raised:
            draw_figures([(_write_text, ("a", tmp_path / "a.txt")), (_full_disk, (tmp_path / "b.png",))], apart=apart)
        assert raised.value.filename == str(tmp_path / "b.png")
    assert "Traceback" not in capfd.readouterr().err


def test_a_full_disk_in_the_figure_process_names_the_figure_and_prints_no_traceback(tmp_path, capfd):
    process = _figure_process()
    try:
        process.draw([(_write_text, ("a", tmp_path / "a.txt")), (_full_disk, (tmp_path / "b.png",))], apart=1)
        with pytest.raises(OSError) as raised:
            process.paths()
    finally:
        process.close()
    assert raised.value.filename == str(tmp_path / "b.png")
    assert "Traceback" not in capfd.readouterr().err
