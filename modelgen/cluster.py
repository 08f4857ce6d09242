"""Many independent tasks on a dask cluster: Monte Carlo runs and trade-study cases.

modelgen hands its many-run work to ``dask.distributed`` (a well-kept engine
that runs on one machine or on many) instead of a process pool of its own:

* :func:`dask_client` opens a client on an existing scheduler (``--scheduler
  tcp://host:8786``, started by the user with ``dask scheduler`` / ``dask
  worker``, or any deployment dask supports) or, by default, on a local
  cluster sized to the machine (one single-threaded worker process per core,
  no setup).  An unreachable address is a :class:`~modelgen.errors.ModelError`
  within ``timeout_s``.
* :func:`run_tasks` submits one task per argument tuple with ``retries`` (a
  task whose worker fails or is lost is run again elsewhere), and gathers
  each result as soon as its task completes: a completed result is then in
  the caller's hands and releasing its future keeps a later worker loss from
  recomputing it.  Progress is reported as tasks complete; results come back
  in submission order, so they do not depend on which worker ran what.  A
  :class:`Journal` writes each result to disk as it arrives, so a study
  whose client stops is taken up again where it stopped.
  Without a client the same functions run one after another in this process
  (one run, tests, or a study too small to be worth a cluster).
* :func:`worker_cached` keeps what every task of a study shares (a derived
  model, a trajectory, a compiled filter) once per worker process.

Workers need only ``pip install modelgen-nav``: task functions are modelgen's own,
and their arguments are plain data (model declarations, profiles, seeds), never
derived objects holding compiled code.
"""

from __future__ import annotations

import gc
import importlib
import json
import logging
import os
import signal
import sys
import threading
import uuid
from collections import OrderedDict
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence, TypeVar

from modelgen.errors import ModelError

T = TypeVar("T")

#: Seconds to wait for a scheduler before calling its address unreachable.
CONNECT_TIMEOUT_S = 10.0
#: How many times a failed task is tried again (dask ``retries=``).
TASK_RETRIES = 2

#: The local cluster's diagnostics, set so that they stay out of the runs' way: a worker's statistical profiler
#: (for the status page's profile; it samples the task thread's stack every 10 ms, taking the GIL from it) is off,
#: and the event-loop tick and system monitor (the page's load figures) run less often.  Idle, the caller (with
#: the scheduler) and two workers then use 3 % of a core instead of 9 %: on a machine whose cores all fly runs,
#: that time came from the runs.  A cluster at --scheduler keeps its own settings.
LOCAL_CLUSTER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}

#: What one worker process keeps between tasks: the last few studies' shared set-ups.
CACHE_SIZE = 3
_CACHE: OrderedDict[Any, Any] = OrderedDict()


def worker_cached(key: Any, build: Callable[[], T]) -> T:
    """``build()``, computed once per process (a dask worker keeps it for every later task of the study).

    Only the ``CACHE_SIZE`` most recently used set-ups are kept: a trajectory
    of a long flight is large, and a worker serves study after study.  The
    build runs with the cyclic garbage collector paused (:func:`collector_paused`).
    """
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    with collector_paused():
        value = _CACHE[key] = build()
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return value


_PAUSES = 0  # blocks of collector_paused running now, in any thread
_RESUME = False  # whether the collector was on when the first of them began
_PAUSE_LOCK = threading.Lock()


@contextmanager
def collector_paused() -> Iterator[None]:
    """Python's cyclic garbage collector off for the block, then on again (if it was on).

    A set-up or an import makes hundreds of thousands of objects that live on
    (sympy expressions, numba's type registries, modules), and the collector,
    run every few hundred allocations, would walk them again and again as
    they age: 0.15-0.2 s of CPU of a fresh Monte Carlo worker's set-up before
    its first run (bench/results/montecarlo.md).  Objects without cycles are
    still freed as usual; the cycles made meanwhile wait for the next collection.
    Blocks may overlap in threads (a worker's import and a task's set-up):
    the collector is on again when the last one ends, if it was when the first began.
    """
    global _PAUSES, _RESUME
    with _PAUSE_LOCK:
        if _PAUSES == 0:
            _RESUME = gc.isenabled()
            gc.disable()
        _PAUSES += 1
    try:
        yield
    finally:
        with _PAUSE_LOCK:
            _PAUSES -= 1
            if _PAUSES == 0 and _RESUME:
                gc.enable()


def forget_cached(key: Any) -> None:
    """Drop one set-up from this process's cache (the caller's own, once its in-process study is done)."""
    _CACHE.pop(key, None)


#: Local worker processes per core at most (--workers 100000 would try to start them all).  Each is a Python
#: process with numpy, sympy and numba (about 300 MB); beyond a few per core they only wait for the cores.
MAX_WORKERS_PER_CORE = 4
#: ... and never fewer than this many allowed, whatever the core count.
MIN_WORKERS_ALLOWED = 8


def max_local_workers() -> int:
    """The most worker processes a local cluster may have on this machine."""
    return max(MIN_WORKERS_ALLOWED, MAX_WORKERS_PER_CORE * (os.cpu_count() or 1))


def check_worker_count(requested: int | None) -> None:
    """Refuse a --workers below 1 or over :func:`max_local_workers`, naming the limit."""
    if requested is None:
        return
    if requested < 1:
        raise ModelError(f"--workers: need at least one worker, got {requested}")
    limit = max_local_workers()
    if requested > limit:
        raise ModelError(f"--workers {requested}: at most {limit} worker processes on this machine "
                         f"({MAX_WORKERS_PER_CORE} per core, {os.cpu_count() or 1} cores; each worker is a "
                         "Python process of its own)")


def local_worker_count(requested: int | None = None) -> int:
    """Workers of the local cluster: ``requested`` (at most :func:`max_local_workers`), else one per core of this machine."""
    check_worker_count(requested)
    return requested or os.cpu_count() or 1


#: Protocols of a --scheduler address: plain TCP (``tls://`` needs certificates modelgen does not
#: configure, ``ucx://`` the ucx-py package; distributed fails on either with a TypeError).
SCHEDULER_PROTOCOLS = ("tcp",)


def _check_scheduler_protocol(scheduler: str) -> None:
    """Refuse a --scheduler address whose protocol is not plain TCP, naming the one given (no protocol: tcp)."""
    protocol = scheduler.split("://", 1)[0].lower() if "://" in scheduler else "tcp"
    if protocol not in SCHEDULER_PROTOCOLS:
        raise ModelError(
            f"--scheduler {scheduler}: not a dask scheduler address modelgen can use: protocol {protocol}:// "
            "(tls:// needs certificates and ucx:// "
            "the ucx-py package, neither configured by modelgen); give a tcp://HOST:PORT address"
        )


def _connect_within(connect: Callable[[], Any], scheduler: str, timeout_s: float) -> Any:
    """``connect()`` run in a thread of its own, given up after ``timeout_s``.

    distributed's own timeout covers the TCP connection, not the handshake:
    a service that accepts the connection and never answers as dask does (a
    web server) held the client for minutes.  The abandoned thread is a
    daemon; the caller reports the address and exits.
    """
    outcome: dict[str, Any] = {}

    def attempt() -> None:
        try:
            outcome["client"] = connect()
        except BaseException as exc:  # handed to the caller's thread
            outcome["error"] = exc

    thread = threading.Thread(target=attempt, name="modelgen-scheduler-connect", daemon=True)
    thread.start()
    thread.join(timeout_s)
    if thread.is_alive():
        raise ModelError(f"--scheduler {scheduler}: no dask scheduler answered within {timeout_s:g} s "
                         "(the address accepts connections but does not speak dask's protocol)")
    if "error" in outcome:
        raise outcome["error"]
    return outcome["client"]


@contextmanager
def _workers_ignore_interrupts() -> Iterator[None]:
    """SIGINT ignored while the local cluster's worker processes are spawned: they inherit it.

    Ctrl-C reaches every process of the terminal's process group: each
    worker would print its own KeyboardInterrupt traceback while
    this process, which handles the interrupt (exit 130, one line), closes
    the cluster and so ends them.  Only SIG_IGN survives the exec of a
    spawned worker (a handler of this process would not), so a Ctrl-C in
    the second or two the workers take to start is dropped; the next one
    is taken.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous if previous is not None else signal.default_int_handler)


@contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None,
                timeout_s: float | None = None) -> Iterator[Any]:
    """A ``distributed.Client`` on ``scheduler`` (an address) or on a new local cluster of ``workers`` processes.

    The local cluster has one single-threaded worker process per core (the
    filter loops hold the GIL), listens on the loopback address only (its
    status page on a free port), logs only errors and keeps its diagnostics
    quiet (:data:`LOCAL_CLUSTER_CONFIG`); it is closed on the way out.  A scheduler that does not answer within ``timeout_s`` is
    refused with a message naming the address (None: :data:`CONNECT_TIMEOUT_S`, as in the production default).
    """
    import dask
    from distributed import Client, LocalCluster

    if timeout_s is None:
        timeout_s = CONNECT_TIMEOUT_S
    if scheduler is not None:
        if workers is not None:
            raise ModelError(f"--workers {workers}: sizes the local cluster only; the cluster at --scheduler "
                             f"{scheduler} has the workers started there")
        _check_scheduler_protocol(scheduler)
        try:
            client = _connect_within(lambda: Client(scheduler, timeout=f"{timeout_s}s"), scheduler, timeout_s)
        except ModelError:
            raise
        except (ValueError, TypeError) as exc:  # TypeError: a protocol distributed has no working connector for
            raise ModelError(f"--scheduler {scheduler}: not a dask scheduler address modelgen can reach ({exc})") from None
        except (OSError, TimeoutError) as exc:
            raise ModelError(f"--scheduler {scheduler}: no dask scheduler answered within {timeout_s:g} s "
                             f"({type(exc).__name__}: {exc})") from None
        except MemoryError:  # a service that answers, not as dask does: its reply's first bytes read as a frame length
            raise ModelError(f"--scheduler {scheduler}: the address answered, but not as a dask scheduler "
                             "(its reply decodes as a message too large to hold)") from None
        except Exception as exc:  # any other reply distributed cannot read
            raise ModelError(f"--scheduler {scheduler}: the address answered, but not as a dask scheduler "
                             f"({type(exc).__name__}{': ' + str(exc)[:80] if str(exc) else ''})") from None
        try:
            yield client
        finally:
            client.close()
        return
    # the scheduler reads the configuration here, the worker processes get it (and SIGINT ignored) at spawn
    with dask.config.set(LOCAL_CLUSTER_CONFIG), _workers_ignore_interrupts():
        cluster = LocalCluster(n_workers=local_worker_count(workers), threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()


def import_on_workers(client: Any, module: str, warm_up: str | None = None) -> None:
    """Have every worker of ``client`` import ``module`` now, all at once, without waiting for them.

    A fresh worker otherwise imports a study's task code only when its first
    task arrives, and a task that needs a result held by another worker (the
    study's shared set-up) arrives only after that worker has imported the
    code and computed it: the fresh workers' imports (0.4 s for the Monte
    Carlo code) would follow one another instead of overlapping.  Each
    worker imports in a thread of its own, so that its event loop goes on
    meanwhile: it takes tasks and serves the data it holds (a study's
    set-up, to the other workers) while it imports.  A worker
    that already has the module does nothing; one that fails to import it
    fails again, with its message, on its first task.  The imported objects
    live as long as the worker: they are moved out of the collector's sight
    (``gc.freeze``), so its later collections do not walk them.  ``warm_up``
    names a function of ``module`` the thread calls next (what the worker's
    first task would otherwise pay for), once per worker process.
    """
    client.run(_import_module, module, warm_up, wait=False)


def import_long_lived(module: str, warm_up: str | None = None) -> None:
    """Import ``module`` with the collector paused, then keep everything made so far out of its sight (``gc.freeze``).

    Only a first import freezes (and calls ``module.warm_up``): a worker asked
    again, study after study, must not freeze the garbage cycles of its
    earlier studies for good.
    """
    if module in sys.modules:
        return
    with collector_paused():
        imported = importlib.import_module(module)
        if warm_up is not None:
            getattr(imported, warm_up)()
    gc.freeze()


async def _import_module(module: str, warm_up: str | None = None) -> None:
    """On a worker: :func:`import_long_lived` in a thread (a coroutine: what ``Client.run`` can start without waiting for it)."""
    threading.Thread(target=import_long_lived, args=(module, warm_up), name=f"modelgen-import {module}",
                     daemon=True).start()


def held(value: T) -> T:
    """``value`` as a task's result: held by a worker, fetched by the others, recomputed from the graph if lost."""
    return value


def call_by_name(module: str, name: str, *args: Any) -> Any:
    """``module.name(*args)``: a task whose function is named, not pickled, so a worker imports its module only to run it.

    A worker unpickles a task as its message arrives, on its event loop; a
    function pickled by reference would have the loop import its module
    there (0.45 s for the Monte Carlo code), or wait for the import under
    way in another thread (:func:`import_on_workers`), answering nothing
    meanwhile: not even another worker asking for the data the task needs.
    """
    return getattr(importlib.import_module(module), name)(*args)


def _named(function: Callable[..., T]) -> tuple[Callable[..., Any], tuple]:
    """(:func:`call_by_name`, (module, name)) for a module-level function of modelgen; else (``function``, ())."""
    module, name = getattr(function, "__module__", None) or "", getattr(function, "__qualname__", "")
    if module.startswith("modelgen.") and getattr(sys.modules.get(module), name, None) is function:
        return call_by_name, (module, name)
    return function, ()


def describe_client(client: Any) -> str:
    """``'local cluster, 2 workers'`` / ``'tcp://host:8786, 4 workers'`` / ``'this process'`` for progress lines."""
    if client is None:
        return "this process"
    workers = len(client.scheduler_info().get("workers", {}))
    where = "local cluster" if type(client.cluster).__name__ == "LocalCluster" else client.scheduler.address
    return f"{where}, {workers} worker{'s' if workers != 1 else ''}"


class Journal:
    """A study's completed task results, one JSON line each, appended and flushed to disk as they arrive.

    The first line names the study (a digest of its inputs and task split)
    and its number of tasks.  A study stopped part-way (its client killed, a
    task failing after its retries) is taken up again from its journal: the
    tasks recorded there are not run again.  A journal of another study is
    refused; a last line cut short by the stop is ignored.  Results are
    kept as ``encode(result)``, which must be JSON data (numbers, strings,
    lists, mappings; NaN allowed), and read back as ``decode(data)``
    (default: results are JSON data themselves).
    """

    def __init__(self, path: str | Path, study: str, tasks: int, encode: Callable[[Any], Any] | None = None,
                 decode: Callable[[Any], Any] | None = None) -> None:
        self.path, self.study, self.tasks = Path(path), study, tasks
        self.encode = encode or (lambda result: result)
        self.decode = decode or (lambda data: data)

    def completed(self) -> dict[int, Any]:
        """Results already recorded, by task index (the journal is started with its header if absent)."""
        if not self.path.exists() or self.path.stat().st_size == 0:
            self._append({"study": self.study, "tasks": self.tasks})
            return {}
        return self._read(repair=True)

    def check(self) -> int:
        """Refuse now, as :meth:`completed` would, a journal of another study or with an entry that is not this
        study's, before any work: nothing is written (an absent journal passes; a last line cut short is left
        for :meth:`completed` to drop).  Returns how many tasks it holds."""
        if self.path.exists() and self.path.stat().st_size > 0:
            return len(self._read(repair=False))
        return 0

    def _read(self, repair: bool) -> dict[int, Any]:
        """The recorded results; ModelError, naming the line, for anything not of this study.  ``repair``: drop
        a last line cut short (by the stop that ended the study) from the file, else only leave it out."""
        lines = self.path.read_text(encoding="utf-8").splitlines()
        try:
            header = json.loads(lines[0])
        except (json.JSONDecodeError, IndexError):
            raise ModelError(f"{self.path}:1: not a modelgen journal (its first line is not a study header)") from None
        if not isinstance(header, dict) or header.get("study") != self.study or header.get("tasks") != self.tasks:
            held = (f"study {header.get('study')!r} of {header.get('tasks')!r} tasks" if isinstance(header, dict)
                    else f"{header!r:.120}")
            raise ModelError(f"{self.path}:1: journal of another study or task split (it holds {held}; this is "
                             f"study {self.study!r} of {self.tasks} tasks); give a new --journal file or remove "
                             f"this one")
        done: dict[int, Any] = {}
        for number, line in enumerate(lines[1:], start=2):
            try:
                entry = json.loads(line)
                index = entry["index"]
            except (json.JSONDecodeError, KeyError, TypeError):
                if number == len(lines):  # cut short by the stop that ended the study: drop it
                    if repair:
                        good = "".join(f"{kept}\n" for kept in lines[:-1])
                        os.truncate(self.path, len(good.encode("utf-8")))
                    break
                raise ModelError(f"{self.path}:{number}: not a journal entry") from None
            if not isinstance(index, int) or not 0 <= index < self.tasks:
                raise ModelError(f"{self.path}:{number}: task index {index!r} out of range [0, {self.tasks})")
            try:
                done[index] = self.decode(entry.get("result"))
            except (KeyError, TypeError, ValueError) as exc:
                raise ModelError(f"{self.path}:{number}: not a result of this study ({type(exc).__name__}: {exc})") from None
        return done

    def record(self, index: int, result: Any) -> None:
        """Append one completed task's result."""
        self._append({"index": index, "result": self.encode(result)})

    def _append(self, entry: dict) -> None:
        with self.path.open("a", encoding="utf-8") as handle:
            handle.write(json.dumps(entry, separators=(",", ":")) + "\n")
            handle.flush()
            os.fsync(handle.fileno())


def run_tasks(function: Callable[..., T], arguments: Sequence[tuple], client: Any = None,
              progress: Callable[[int, int], None] | None = None, retries: int = TASK_RETRIES,
              on_result: Callable[[int, T], None] | None = None, label: str = "task",
              journal: Journal | None = None) -> list[T]:
    """``[function(*a) for a in arguments]``, as dask tasks on ``client`` (or here, in order, without one).

    ``progress(done, total)`` is called as each task completes and
    ``on_result(index, result)`` with each result as it arrives.  With a
    ``journal`` each result is written to it as it arrives, and the tasks it
    already holds are not run again.  A task that still fails after
    ``retries`` more tries raises its error here.
    """
    total = len(arguments)
    results: list[Any] = [None] * total
    recorded = journal.completed() if journal is not None else {}
    for i, value in recorded.items():
        results[i] = value
    pending = [i for i in range(total) if i not in recorded]
    done = len(recorded)

    def arrived(i: int, value: Any) -> None:
        nonlocal done
        results[i] = value
        done += 1
        if journal is not None:
            journal.record(i, value)
        if on_result:
            on_result(i, value)
        if progress:
            progress(done, total)

    if client is None:
        for i in pending:
            arrived(i, function(*arguments[i]))
        return results
    from distributed import as_completed

    study = uuid.uuid4().hex[:12]
    task, named = _named(function)  # a modelgen function travels by name (call_by_name)
    futures = [client.submit(task, *named, *arguments[i], retries=retries, pure=False, key=f"modelgen-{label}-{study}-{i}")
               for i in pending]
    index = {f.key: i for i, f in zip(pending, futures)}
    try:
        for future in as_completed(futures):
            value = future.result()
            future.release()
            arrived(index[future.key], value)
    finally:
        client.cancel([f for f in futures if not f.done()])
    return results
