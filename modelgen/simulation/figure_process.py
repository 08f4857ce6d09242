"""Drawing a flight's figures in other processes: a forked copy that imports matplotlib early, and one more.

matplotlib's import and drawing hold the GIL; :class:`FigureProcess` (forked
at the start of a flight) imports it on the other core while the flight goes,
and :func:`draw_figures` draws one figure in a forked copy while this process
draws the rest.  What is drawn is the business of
:mod:`modelgen.simulation.flight_figures`.
"""

from __future__ import annotations

import functools
import os
import pickle
import signal
import sys
import threading
import traceback
import weakref
from pathlib import Path
from typing import Any, Callable


#: the figure process's niceness: a lower priority than the flight's, whose cores it shares while the flight goes
FIGURE_NICE = 10


class FigureProcess:
    """A forked copy of this process that imports matplotlib and draws the figures it is sent.

    matplotlib's import (0.4 s) holds the GIL: in a thread it slows the
    flight's own threads, after the flight it comes before the figures.  A
    copy forked at the start of the flight, when no thread runs yet, imports
    it on the other core while this process derives the model and flies;
    after the flight it is sent the drawings (functions and their data,
    pickled through a pipe) and draws them, ``apart`` one by a forked copy of
    its own (:func:`draw_figures`), while this process never imports
    matplotlib.  While the flight goes it can also make a drawing's figure
    and axes, which need no data (:meth:`prepare`): the drawing then only
    adds its data.  Should it fail (or die), :meth:`paths` draws the batch here,
    so that its error is raised.  :meth:`close` ends it (so does this
    object's collection, or this process's exit: a flight that fails leaves
    no process behind); it ignores Ctrl-C, which this process handles, and
    runs at a lower priority (:data:`FIGURE_NICE`).
    """

    def __init__(self, pid: int, connection: Any):
        self.pid, self.connection = pid, connection
        # each batch asked for, and whether it went to the process (else it is drawn here)
        self._batches: list[tuple[list[tuple[Callable[..., Path], tuple]], int, bool]] = []
        self._end = weakref.finalize(self, _end_figure_process, pid, connection)

    @classmethod
    def start(cls) -> "FigureProcess | None":
        """Fork the figure process now; None where there is no fork or another thread runs (its locks would be
        copied held)."""
        if not hasattr(os, "fork") or threading.active_count() > 1:
            return None
        from multiprocessing import Pipe

        here, there = Pipe()
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # the copy: serve drawings, leave without running this process's exit handlers
            status = 1
            try:
                signal.signal(signal.SIGINT, signal.SIG_IGN)
                # its work while the flight goes takes what the flight leaves of the cores: the flight's threads
                # come first (after the flight this process only waits for it)
                os.nice(FIGURE_NICE)
                here.close()
                _serve_figures(there)
                status = 0
            except BaseException:  # noqa: S110 - silent: the batch is then drawn here (paths), which raises the error
                pass
            finally:
                os._exit(status)
        there.close()
        return cls(pid, here)

    def draw(self, drawings: list[tuple[Callable[..., Path], tuple]], apart: int) -> None:
        """Send ``drawings`` to be drawn as :func:`draw_figures` draws them (``apart`` by a copy of the copy).

        Drawings that cannot be sent (the process gone, or data that does not
        pickle: nothing is written then) are drawn here by :meth:`paths`.
        """
        try:
            send_out_of_band(self.connection, ("draw", drawings, apart))
            sent = True
        except Exception:
            sent = False
        self._batches.append((drawings, apart, sent))

    def prepare(self, drawing: Callable[..., Path], make: Callable[..., Any], args: tuple) -> None:
        """Have the process make ``make(*args)`` now, to be handed to ``drawing`` as its ``prepared`` figure
        and axes when it is drawn (a figure it fails to make is made by the drawing)."""
        try:
            self.connection.send(("prepare", drawing.__name__, make, args))
        except Exception:  # gone, or does not pickle: the drawing makes its own
            pass

    def paths(self) -> list[Path]:
        """The paths of every drawing asked for, in order, once drawn (here, for a batch the process did not draw)."""
        paths: list[Path] = []
        for drawings, apart, sent in self._batches:
            status, drawn = "not sent", None
            if sent:
                try:
                    status, drawn = self.connection.recv()
                except (EOFError, OSError):
                    status = "gone"
            paths += [Path(p) for p in drawn] if status == "drawn" else draw_figures(drawings, apart)
        self._batches = []
        return paths

    def close(self) -> None:
        """Tell the process to leave once its batch is drawn, and wait for it (once; later calls do nothing)."""
        self._end()


#: the message announcing a message sent by :func:`send_out_of_band`
OUT_OF_BAND = "out-of-band"


def send_out_of_band(connection: Any, message: Any) -> None:
    """Send ``message`` through ``connection`` with its arrays' data out of band (pickle protocol 5).

    ``connection.send`` pickles the whole message into one bytes object
    first: for a long flight's drawings (its truth and histories) a copy of
    all their data, tens of MiB of this process's peak memory.  Here only the
    pickle's frame is made; each array's data goes from its own memory
    straight to the pipe, and :func:`receive_out_of_band` puts the message
    together again (writable arrays, equal to the ones sent).
    """
    buffers: list[pickle.PickleBuffer] = []
    frame = pickle.dumps(message, protocol=5, buffer_callback=buffers.append)
    connection.send(OUT_OF_BAND)
    connection.send((len(frame), [len(buffer.raw()) for buffer in buffers]))
    connection.send_bytes(frame)
    for buffer in buffers:
        connection.send_bytes(buffer.raw())


def receive_out_of_band(connection: Any) -> Any:
    """The message :func:`send_out_of_band` sent (its announcement already received)."""
    _, sizes = connection.recv()
    frame = connection.recv_bytes()
    buffers = []
    for size in sizes:
        buffer = bytearray(size)
        if size:
            connection.recv_bytes_into(buffer)
        else:
            connection.recv_bytes()
        buffers.append(buffer)
    return pickle.loads(frame, buffers=buffers)


def _end_figure_process(pid: int, connection: Any) -> None:
    """Send the figure process its last message (None), close the pipe and wait for the process to leave."""
    try:
        connection.send(None)
    except (OSError, ValueError):  # gone already
        pass
    connection.close()
    try:
        os.waitpid(pid, 0)
    except ChildProcessError:  # waited for already (by whoever reaps this process's children)
        pass


def _serve_figures(connection: Any) -> None:
    """The figure process: import matplotlib, then serve each message received until None (or the pipe closes).

    ("prepare", drawing's name, make, args): keep ``make(*args)`` for that
    drawing.  ("draw", drawings, apart): draw them (:func:`draw_figures`),
    each with its prepared figure if there is one, and answer ("drawn",
    paths) or ("failed", the traceback).  A reader gone is no error of its own.
    """
    import_plotting()
    prepared: dict[str, Any] = {}
    while True:
        try:
            message = connection.recv()
        except EOFError:
            return
        if message is None:
            return
        if message == OUT_OF_BAND:
            try:
                message = receive_out_of_band(connection)
            except EOFError:
                return
        if message[0] == "prepare":
            _, name, make, args = message
            try:
                prepared[name] = make(*args)
            except Exception:  # the drawing makes its figure itself, and raises the error if there is one
                pass
            continue
        _, drawings, apart = message
        drawings = [(functools.partial(function, prepared=prepared.pop(getattr(function, "__name__", None)))
                     if getattr(function, "__name__", None) in prepared else function, args) for function, args in drawings]
        try:
            answer = ("drawn", [str(p) for p in draw_figures(drawings, apart)])
        except Exception:
            answer = ("failed", traceback.format_exc())
        try:
            connection.send(answer)
        except OSError:  # this process stopped waiting (it failed or was interrupted)
            return


def import_plotting() -> None:
    """Import what the figures need (matplotlib, its Figure and Agg canvas: 0.4 s) ahead of drawing them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.backends.backend_agg  # noqa: F401
    import matplotlib.figure  # noqa: F401


def draw_figures(drawings: list[tuple[Callable[..., Path], tuple]], apart: int) -> list[Path]:
    """Call each ``(function, args)`` of ``drawings`` (each draws one figure and saves it to ``args[-1]``, the
    path it returns); their paths, in order.

    matplotlib holds the GIL while it draws, so two figures drawn by two
    threads take as long as one after the other; instead ``drawings[apart]``
    is drawn by a forked copy of this process while this one draws the rest
    (the two cores share the figures' second of work).  Only a process with
    no other thread running forks (a thread's locks would be copied held);
    otherwise, and where there is no fork, all are drawn here.  Should the
    copy fail, the figure is drawn again here, so that its error is raised.
    """
    if not hasattr(os, "fork") or threading.active_count() > 1 or len(drawings) < 2:
        return [_draw(function, args) for function, args in drawings]
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # the copy: draw one figure, leave without running this process's exit handlers
        status = 1
        try:
            function, args = drawings[apart]
            function(*args)
            status = 0
        except BaseException:  # noqa: S110 - silent: the figure is drawn again here, which raises the error
            pass
        finally:
            os._exit(status)
    try:
        paths = [_draw(function, args) for index, (function, args) in enumerate(drawings) if index != apart]
    finally:
        _, status = os.waitpid(pid, 0)
    function, args = drawings[apart]
    path = args[-1] if os.waitstatus_to_exitcode(status) == 0 else _draw(function, args)
    paths.insert(apart, Path(path))
    return paths


def _draw(function: Callable[..., Path], args: tuple) -> Path:
    """``function(*args)``; an OSError that names no file (a full disk while the PNG is written) names its path."""
    try:
        return function(*args)
    except OSError as exc:
        if exc.filename is None and args:
            raise OSError(exc.errno, exc.strerror or str(exc), str(args[-1])) from exc
        raise
