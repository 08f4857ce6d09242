"""Run the ``modelgen`` command line inside the test process, as a fresh process would run it.

Starting a process costs about a second of CPU (the interpreter, sympy, numpy,
click, modelgen), far more than refusing a bad input: the hostile-input corpus
(tests/test_corpus.py) therefore runs most of its cases here.  The run is
faithful to ``python -m modelgen ARGV`` with standard input from /dev/null and
the outputs on pipes:

- **exit code**: ``SystemExit`` as the interpreter turns it into a status
  (None 0, an integer modulo 256, anything else printed and 1); an exception
  that escapes ``main`` is printed as the interpreter prints it (a
  ``Traceback``, which the corpus refuses) with status 1, and an escaping
  ``KeyboardInterrupt`` ends as a process killed by SIGINT would (-2);
- **outputs**: file descriptors 1 and 2 go to files of their own for the run
  and ``sys.stdout``/``sys.stderr`` are new UTF-8 streams over them (strict and
  backslashreplace, as for pipes), so what the compiler, a child process or C
  code writes is captured too, in the order it was written to each;
- **warnings**: the filters of a fresh interpreter (``PYTHONWARNINGS`` and the
  default list) and the standard printing to ``sys.stderr``; logging: no
  handler on the root logger (a fresh process prints warnings through
  ``logging.lastResort``), and stream handlers that wrote to the test's
  outputs write to the run's;
- **process state** set for the run and restored after it, whatever happened:
  the working folder, the environment (plus ``MPLBACKEND=Agg`` and
  ``PYTHONDONTWRITEBYTECODE=1``, as the corpus gives its processes),
  ``sys.argv``, standard input, the handlers of SIGINT, SIGTERM, SIGHUP and
  SIGALRM, the umask, the recursion limit, and modelgen's process-wide
  registries that a fresh process starts empty (:data:`PROCESS_REGISTRIES`);
- **time limit**: a watchdog (``SIGALRM``, main thread only) stops a run that
  outlives its timeout and the run reports a hang (None), as the process
  runner does when it kills the process; threads the command started and did
  not finish are waited for, as the interpreter waits for them at exit.

What this cannot give a case is a process of its own: a memory limit
(``RLIMIT_AS``), a run that must not share the test's stack depth (deep
recursion), a hang in C code that no signal handler interrupts, a crash, a
signal to the whole process, or the interpreter's exit itself.  Such cases say
``process: true`` and run as processes (tests/test_corpus.py).
"""

from __future__ import annotations

import importlib
import io
import logging
import os
import signal
import subprocess
import sys
import tempfile
import threading
import traceback
import warnings
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Iterator, Mapping, Sequence

#: Environment the corpus gives every run (a process runner sets the same).
RUN_ENVIRONMENT = {"MPLBACKEND": "Agg", "PYTHONDONTWRITEBYTECODE": "1"}

#: (module, attribute) of modelgen's process-wide registries: a fresh process starts with
#: them empty, so a run starts with them empty and gets back what was there after it.
#: A registry that does not exist (yet, or any more) is skipped.
PROCESS_REGISTRIES = (("modelgen.model.navigation_model", "_DERIVED"),)

#: The signals whose handlers a run may change (modelgen holds INT/TERM/HUP while it swaps folders).
_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGALRM)

#: The interpreter's warning filters without -W options or PYTHONWARNINGS (Python 3.10-3.13, release builds).
_DEFAULT_FILTERS = (
    ("default", DeprecationWarning, "__main__"),
    ("ignore", DeprecationWarning, None),
    ("ignore", PendingDeprecationWarning, None),
    ("ignore", ImportWarning, None),
    ("ignore", ResourceWarning, None),
)


class _Watchdog(BaseException):
    """Raised in the run by the timer: a BaseException, so that modelgen's boundary (``except Exception``) lets it pass."""


def run_modelgen(argv: Sequence[object], cwd: Path, timeout: float,
                 environment: Mapping[str, str] = RUN_ENVIRONMENT) -> subprocess.CompletedProcess | None:
    """``python -m modelgen ARGV`` in ``cwd``, in this process; None when it outlived ``timeout`` seconds."""
    args = [str(a) for a in argv]
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        with ExitStack() as restore:
            for context in (_working_folder(cwd), _environment(environment), _argv(args), _registries(),
                            _signal_handlers(), _umask_and_recursion_limit()):
                restore.enter_context(context)
            with _descriptors(out, err) as before, _warnings(), _logging(before):
                status = _invoke(args, timeout)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode("utf-8", "replace"), err.read().decode("utf-8", "replace")
    if status is None:
        return None
    return subprocess.CompletedProcess(args, status, stdout, stderr)


def _invoke(args: list[str], timeout: float) -> int | None:
    """The exit status of ``main(args)`` as the interpreter would report it; None on a hang."""
    from modelgen.cli import main

    threads_before = set(threading.enumerate())
    try:
        with _time_limit(timeout):
            try:
                main.main(args=args, prog_name="modelgen", standalone_mode=True)
                status = 0
            except SystemExit as stop:
                status = _exit_status(stop.code)
            except KeyboardInterrupt:
                traceback.print_exc()
                status = -signal.SIGINT
            except Exception:  # noqa: BLE001 - an escaping exception: what the interpreter prints
                traceback.print_exc()
                status = 1
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
            if not _threads_finished(threads_before, timeout):
                return None
    except _Watchdog:
        return None
    return status


def _exit_status(code: object) -> int:
    """What ``sys.exit(code)`` makes the process's exit status."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code % 256
    print(code, file=sys.stderr)
    return 1


def _threads_finished(before: set[threading.Thread], timeout: float) -> bool:
    """Wait, as the interpreter does at exit, for the non-daemon threads the run started."""
    for thread in set(threading.enumerate()) - before:
        if not thread.daemon:
            thread.join(timeout)
            if thread.is_alive():
                return False
    return True


@contextmanager
def _time_limit(timeout: float) -> Iterator[None]:
    if threading.current_thread() is not threading.main_thread():
        yield  # signals reach the main thread only: no watchdog (the process runner has its own)
        return

    def expire(signum, frame):
        raise _Watchdog()

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@contextmanager
def _working_folder(cwd: Path) -> Iterator[None]:
    before = os.getcwd()
    os.chdir(cwd)
    try:
        yield
    finally:
        os.chdir(before)


@contextmanager
def _environment(extra: Mapping[str, str]) -> Iterator[None]:
    before = dict(os.environ)
    os.environ.update(extra)
    try:
        yield
    finally:
        os.environ.clear()
        os.environ.update(before)


@contextmanager
def _argv(args: list[str]) -> Iterator[None]:
    import modelgen

    before = sys.argv
    sys.argv = [str(Path(modelgen.__file__).parent / "__main__.py"), *args]  # what `python -m modelgen` sees
    try:
        yield
    finally:
        sys.argv = before


@contextmanager
def _registries() -> Iterator[None]:
    saved = []
    for module_name, attribute in PROCESS_REGISTRIES:
        try:
            registry = getattr(importlib.import_module(module_name), attribute)
        except (ImportError, AttributeError):
            continue
        saved.append((registry, dict(registry)))
        registry.clear()
    try:
        yield
    finally:
        for registry, contents in saved:
            registry.clear()
            registry.update(contents)


@contextmanager
def _signal_handlers() -> Iterator[None]:
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = {signum: signal.getsignal(signum) for signum in _SIGNALS}
    signal.signal(signal.SIGINT, signal.default_int_handler)  # a fresh interpreter's handlers
    for signum in (signal.SIGTERM, signal.SIGHUP, signal.SIGALRM):
        signal.signal(signum, signal.SIG_DFL)
    try:
        yield
    finally:
        for signum, handler in before.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)


@contextmanager
def _umask_and_recursion_limit() -> Iterator[None]:
    mask = os.umask(0o022)
    os.umask(mask)
    limit = sys.getrecursionlimit()
    try:
        yield
    finally:
        os.umask(mask)
        sys.setrecursionlimit(limit)


@contextmanager
def _descriptors(out, err) -> Iterator[tuple]:
    """Descriptors 0, 1, 2 on /dev/null and the two files, with new ``sys`` streams over them; yields the test's streams."""
    streams = (sys.stdin, sys.stdout, sys.stderr)
    for stream in streams[1:]:
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    saved = [os.dup(fd) for fd in (0, 1, 2)]
    null = os.open(os.devnull, os.O_RDONLY)
    try:
        os.dup2(null, 0)
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        # Streams over the descriptors themselves (never closed): a handler or library that keeps one
        # after the run writes to whatever the descriptor is then, never to a closed stream.
        sys.stdin = io.TextIOWrapper(io.FileIO(0, "r", closefd=False), encoding="utf-8")
        sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), encoding="utf-8", errors="strict")
        sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), encoding="utf-8", errors="backslashreplace",
                                      line_buffering=True)
        yield streams
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        sys.stdin, sys.stdout, sys.stderr = streams
        for fd, copy in zip((0, 1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(null)


def _show_warning_message(message: warnings.WarningMessage) -> None:
    """The interpreter's own printing of a warning (``warnings._showwarnmsg_impl``)."""
    file = message.file if message.file is not None else sys.stderr
    try:
        file.write(warnings._formatwarnmsg(message))  # type: ignore[attr-defined]
    except OSError:
        pass


@contextmanager
def _warnings() -> Iterator[None]:
    with warnings.catch_warnings():
        warnings.resetwarnings()
        for action, category, module in reversed(_DEFAULT_FILTERS):
            warnings.filterwarnings(action, category=category, module=module or "")
        options = [o for o in os.environ.get("PYTHONWARNINGS", "").split(",") if o]
        if options:
            warnings._processoptions(options)  # type: ignore[attr-defined]
        warnings.showwarning = warnings._showwarning_orig  # type: ignore[attr-defined]
        warnings._showwarnmsg_impl = _show_warning_message  # type: ignore[attr-defined]
        yield


@contextmanager
def _logging(before: tuple) -> Iterator[None]:
    """No root handler (``logging.lastResort`` then prints to the run's stderr); stream handlers follow the outputs.

    ``before`` is (stdin, stdout, stderr) of the test: a handler that writes to
    the test's stdout or stderr (or the interpreter's) writes to the run's.
    """
    root = logging.getLogger()
    root_handlers, root.handlers = root.handlers[:], []
    targets = {id(before[1]): sys.stdout, id(sys.__stdout__): sys.stdout,
               id(before[2]): sys.stderr, id(sys.__stderr__): sys.stderr}
    moved = []
    for logger in logging.Logger.manager.loggerDict.values():
        for handler in getattr(logger, "handlers", ()):
            stream = getattr(handler, "stream", None)
            if isinstance(handler, logging.StreamHandler) and id(stream) in targets:
                moved.append((handler, stream))
                handler.setStream(targets[id(stream)])
    try:
        yield
    finally:
        for handler, stream in moved:
            handler.setStream(stream)
        root.handlers = root_handlers
