"""`modelgen simulate`: fly a flight profile, write PNG figures and a Markdown summary.

What it does, in order: generate the truth (the ideal IMU data comes piece by
piece, :mod:`modelgen.simulation.streaming`) and draw the IMU errors, in two
threads started before the filter model is derived (:func:`start_flight`),
while a helper thread builds the filter code; draw the other sensor errors;
fly the filter (the generated C by default, in the compiled loop of
:mod:`modelgen.simulation.native_loop`) on them in the three correction modes
(open loop, closed loop, seed 003's accumulated correction) in one pass over
the data, plus the free INS; run a Monte Carlo ensemble and test its NEES;
plot (in a copy of the process forked at the start, which imports matplotlib
while this one flies, :class:`FigureProcess`; the filter's figure in a copy
of that copy while it draws the others, :func:`draw_figures`; each line cut
to what its pixel columns show, :func:`pixel_envelope`) and summarize.  Memory does not grow with the IMU data; histories hold at most
:data:`~modelgen.simulation.streaming.MAX_HISTORY_ROWS` rows per mode.  Progress goes to ``echo``.
"""

from __future__ import annotations

import functools
import math
import os
import signal
import sys
import tempfile
import threading
import time
import traceback
import weakref
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from modelgen.derive.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import display_path
from modelgen.model.sources import cite_sources
from modelgen.simulation import earth
from modelgen.simulation.filter_loop import MODES, RunResult
from modelgen.simulation.filters import filter_factory
from modelgen.simulation.flight import imu_error_stream, profile_layout, simulate_sensors
from modelgen.simulation.jit import HAVE_NUMBA
from modelgen.simulation.montecarlo import MonteCarloResult, run_monte_carlo
from modelgen.simulation.rotation import dcm_to_euler, navigation_frame_attitude_error, quaternion_to_dcm
from modelgen.simulation.scenario import FlightProfile
from modelgen.simulation.history import CsvHistory
from modelgen.simulation.streaming import fly_modes, history_every
from modelgen.simulation.trajectory import Trajectory, generate_trajectory, sample_counts

ARCSEC = math.pi / 180 / 3600
NMILE = 1852.0
#: major ticks made per axis of a figure prepared before its data (:func:`_ready_ticks`): more than a
#: panel of these figures shows
FIGURE_TICKS = 10
#: the figure process's niceness: a lower priority than the flight's, whose cores it shares while the flight goes
FIGURE_NICE = 10


@dataclass
class NavigationErrors:
    """Errors of navigation outputs against truth: horizontal position [m], velocity [m/s], attitude [rad]."""

    times: np.ndarray
    position: np.ndarray  # (T, 2) north, east
    velocity: np.ndarray  # (T, 2) north, east
    attitude: np.ndarray  # (T, 3) about N, E, D


def navigation_errors(outputs: np.ndarray, trajectory: Trajectory, times: np.ndarray | None = None) -> NavigationErrors:
    """Errors of ``outputs`` (one row per truth record, or per record at ``times`` of a decimated run)."""
    truth = trajectory.truth
    if times is not None:
        truth = truth[np.rint(times / trajectory.record_period).astype(int)]
    lat = truth[:, 1]
    meridian, prime_vertical = np.vectorize(earth.radii_of_curvature)(lat)
    position = np.stack([(outputs[:, 0] - lat) * (meridian + truth[:, 3]),
                         (outputs[:, 1] - truth[:, 2]) * (prime_vertical + truth[:, 3]) * np.cos(lat)], axis=1)
    velocity = outputs[:, 3:5] - truth[:, 4:6]
    attitude = navigation_frame_attitude_error(outputs[:, 6:10], truth[:, 7:11])
    return NavigationErrors(truth[:, 0], position, velocity, attitude)


def _timed(function: Callable, *args: Any) -> tuple[Any, float]:
    """``function(*args)`` and the seconds it took."""
    start = time.perf_counter()
    return function(*args), time.perf_counter() - start


def _in_background(function: Callable, *args: Any) -> tuple[Future, threading.Thread]:
    """``_timed(function, *args)`` started in a daemon thread: its future and the thread.

    A daemon thread, not a pool's: if the caller fails before asking for the
    result (a model that does not derive), the process exits at once instead
    of waiting for the work to finish.
    """
    future: Future = Future()

    def run() -> None:
        if future.set_running_or_notify_cancel():
            try:
                future.set_result(_timed(function, *args))
            except BaseException as error:  # handed to whoever asks for the result
                future.set_exception(error)

    thread = threading.Thread(target=run, name=f"modelgen-{function.__name__}", daemon=True)
    thread.start()
    return future, thread


def _finished(started: tuple[Future, threading.Thread]) -> Any:
    """The result of work started by :func:`_in_background` (its error raised), once its thread has ended."""
    future, thread = started
    result = future.result()
    thread.join()
    return result


class FlightStart:
    """A flight's truth and IMU errors, being made in two background threads (compiled code, no GIL held).

    Neither needs the filter model, so ``modelgen simulate`` starts them
    (:func:`start_flight`) before it derives the model, and the derivation,
    the imports after it and the filter's code generation overlap them.  When
    the aiding sensor does not read the truth position (the Doppler radar) the
    truth leaves it to the flight's pieces (``positions_in_pieces``), which
    integrate it anyway for the increments.  The
    IMU errors are the seed's first draws (:func:`~modelgen.simulation.flight.imu_error_stream`);
    :attr:`rng` continues from there once :meth:`imu_errors` has returned.
    Before the threads start (a process with threads running does not fork),
    the flight's :class:`FigureProcess` is forked (:attr:`figures`; None where
    it cannot be, or with ``figure_process=False``): it imports matplotlib
    while this process derives the model.
    """

    def __init__(self, profile: FlightProfile, seed: int, figure_process: bool = True):
        self.profile, self.seed = profile, seed
        self.figures = FigureProcess.start() if figure_process else None
        n_samples, record_every = sample_counts(profile.path, profile.imu_rate, 1.0 / profile.filter.period)
        self.rng = np.random.default_rng(seed)
        # the truth positions are integrated by the flight's pieces (once, not twice) unless the aiding sensor
        # reads them when its record is drawn, before the flight
        later = not getattr(profile.aiding_sensor, "reads_truth_position", True)
        self._truth = _in_background(generate_trajectory, profile.path, profile.imu_rate, 1.0 / profile.filter.period,
                                     True, later)
        self._imu = _in_background(imu_error_stream, profile, n_samples, record_every, self.rng)

    def trajectory(self) -> tuple[Trajectory, float]:
        """The streamed trajectory (truth rows; increments come piece by piece) and the seconds it took."""
        return _finished(self._truth)

    def imu_errors(self) -> tuple[Any, float]:
        """The :class:`~modelgen.simulation.imu.ImuErrorStream` and the seconds its draws took."""
        return _finished(self._imu)


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
            except BaseException:
                traceback.print_exc()
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
            self.connection.send(("draw", drawings, apart))
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
    _import_plotting()
    prepared: dict[str, Any] = {}
    while True:
        try:
            message = connection.recv()
        except EOFError:
            return
        if message is None:
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


def _import_plotting() -> None:
    """Import what the figures need (matplotlib, its Figure and Agg canvas: 0.4 s) ahead of drawing them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.backends.backend_agg  # noqa: F401
    import matplotlib.figure  # noqa: F401


def start_flight(profile: FlightProfile, seed: int, figure_process: bool = True) -> FlightStart:
    """Start making ``profile``'s truth and drawing its IMU errors (seed ``seed``) now, and (``figure_process``)
    fork the process that will draw its figures; see :class:`FlightStart`."""
    return FlightStart(profile, seed, figure_process)


def _echo_progress(echo: Callable[[str], None], label: str) -> Callable[[int, int], None]:
    state = {"next": 0.1, "start": time.perf_counter()}

    def report(done: int, total: int) -> None:
        if done / total >= state["next"] or done == total:
            echo(f"  {label}: {100 * done / total:5.1f} %  ({time.perf_counter() - state['start']:.1f} s)")
            while state["next"] <= done / total:
                state["next"] += 0.1

    return report


def simulate(profile: FlightProfile, derived: DerivedModel, out_dir: Path, runs: int = 20, seed: int = 0,
             workers: int = 2, echo: Callable[[str], None] = print, implementation: str = "c",
             client: Any = None, history_csv: bool = False, journal: str | Path | None = None,
             started: FlightStart | None = None) -> Path:
    """Fly ``profile`` with its filter model ``derived`` (module docstring); the summary's path.

    ``implementation`` is the filter of the three correction-mode runs: the
    generated ``c`` (compiled now) or ``python``, or the numpy ``reference``.
    The Monte Carlo runs fly the same filter, as dask tasks on ``client``
    (a local cluster of ``workers`` when None).
    ``derived`` is the profile's ``filter.model``, derived by the caller (the
    main job hands down the model it derived once).  ``history_csv`` also
    writes each mode's history, as it is flown, to ``history_<mode>.csv``
    (:mod:`modelgen.simulation.history`) in ``out_dir``.  ``journal`` keeps
    the completed Monte Carlo runs (:func:`modelgen.simulation.montecarlo.run_monte_carlo`).
    ``started``: this flight's truth and IMU errors, already being made (:func:`start_flight` with this
    profile object and seed); they are started here otherwise.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}

    echo(f"modelgen simulate: {profile.name}, {profile.path.duration / 3600:.2f} h, IMU {profile.imu_rate:g} Hz "
         f"({'numba' if HAVE_NUMBA else 'pure Python: slow'}), filter {derived.model.name}, {runs} Monte Carlo runs")
    results: dict[str, RunResult] = {}
    if started is None:
        started = start_flight(profile, seed)
    elif started.profile is not profile or started.seed != seed:
        raise ModelError(f"simulate: the flight started for profile {started.profile.name!r}, seed {started.seed} "
                         f"is not this one ({profile.name!r}, seed {seed})")
    with tempfile.TemporaryDirectory(prefix="modelgen-simulate-") as code_dir, ThreadPoolExecutor(1) as helpers:
        # the filter code is generated and compiled (a compiler process) while the truth is made and the IMU
        # errors (the seed's first draws, they need no truth) are drawn, both in threads of ``started``
        building = helpers.submit(_timed, filter_factory, derived, implementation, code_dir)
        trajectory, seconds = started.trajectory()
        later = "its positions and " if trajectory.positions_in_pieces else ""
        timings[f"trajectory (truth; {later}IMU increments are generated piece by piece in the flight)"] = seconds
        echo(f"  trajectory: truth of {trajectory.n_samples} IMU samples in {seconds:.1f} s")
        layout = profile_layout(profile, derived, trajectory)
        imu_stream, drawn = started.imu_errors()
        rng = started.rng
        timings["IMU errors (drawn alongside the trajectory)"] = drawn
        t = time.perf_counter()
        sensors = simulate_sensors(profile, trajectory, rng, imu_stream=imu_stream)
        timings["sensors (initial errors, reference altitude, aiding)"] = time.perf_counter() - t
        make_filter, build = building.result()
        timings[f"filter code ({implementation}: generate, compile or import; alongside the above)"] = build
        echo(f"  filter: {implementation} ({build:.1f} s to build, alongside the trajectory and sensors)")
        t = time.perf_counter()
        n_cycles = len(trajectory.truth) - 1
        record_every = history_every(n_cycles)
        histories = {mode: CsvHistory(out_dir / f"history_{mode}.csv", derived.model.state_names)
                     for mode in MODES} if history_csv else {}
        # without a figure process, the figures' imports (0.4 s) are done while the flight goes: its thread
        # making the IMU increments sets the pace, the flying thread's core has time to spare
        plotting = _in_background(_import_plotting) if started.figures is None else None
        units = {state.name: state.unit for state in derived.model.states}
        if started.figures is not None:  # their figures and axes made while the flight goes
            started.figures.prepare(_plot_trajectory, _trajectory_axes, (FIGURE_TICKS,))
            started.figures.prepare(_plot_modes, _modes_axes, (FIGURE_TICKS,))
            started.figures.prepare(_plot_filter, _filter_axes, (derived.model.state_names, units, FIGURE_TICKS))
        try:
            results = fly_modes(profile, derived, trajectory, sensors, layout, make_filter, MODES,
                                progress=lambda mode: _echo_progress(echo, f"{mode} filter"),
                                record_every=record_every, histories=histories)
        finally:
            for history in histories.values():
                history.close()
        timings["IMU + mechanization + filter, three modes in one streamed pass"] = time.perf_counter() - t
    errors = {mode: navigation_errors(r.outputs, trajectory, r.times) for mode, r in results.items()}
    errors["free INS"] = navigation_errors(results["open_loop"].raw_outputs, trajectory, results["open_loop"].times)

    monte_carlo = None
    if runs > 0:
        t = time.perf_counter()
        monte_carlo = run_monte_carlo(profile, derived, runs, seed=seed + 1, workers=workers, client=client,
                                      progress=_echo_progress(echo, "Monte Carlo runs"), implementation=implementation,
                                      journal=journal)
        timings[f"Monte Carlo ({_runs(runs)}, {monte_carlo.where})"] = time.perf_counter() - t

    drawings: list[tuple[Callable[..., Path], tuple]] = [
        (_plot_trajectory, (trajectory, out_dir / "trajectory.png")),
        (_plot_modes, (errors, out_dir / "correction_modes.png")),
        (_plot_filter, (results[profile.filter.mode], derived.model.state_names, units, out_dir / "filter_errors.png")),
    ]
    if monte_carlo is not None:
        drawings.append((_plot_monte_carlo, (monte_carlo, units, out_dir / "monte_carlo.png")))
        drawings.append((_plot_nees, (monte_carlo, out_dir / "nees.png")))
    if started.figures is None:
        _finished(plotting)
        figures = draw_figures(drawings, apart=2)  # the filter's 18 panels: the longest drawing
    else:
        try:
            started.figures.draw(drawings, apart=2)
            figures = started.figures.paths()
        finally:
            started.figures.close()
    summary = out_dir / "summary.md"
    summary.write_text(cite_sources(_summary(profile, derived.model.name, implementation, layout.conventions, trajectory, results, errors,
                                monte_carlo, timings, figures)), encoding="utf-8")
    echo(f"  wrote {summary} and {len(figures)} figures")
    return summary


# -- figures ------------------------------------------------------------------------


# The figures are matplotlib Figures of their own (no pyplot: no global figure registry to close, and a
# figure can be drawn in a forked copy of the process, :func:`draw_figures`).


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
        return [function(*args) for function, args in drawings]
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # the copy: draw one figure, leave without running this process's exit handlers
        status = 1
        try:
            function, args = drawings[apart]
            function(*args)
            status = 0
        except BaseException:
            traceback.print_exc()
        finally:
            os._exit(status)
    try:
        paths = [function(*args) for index, (function, args) in enumerate(drawings) if index != apart]
    finally:
        _, status = os.waitpid(pid, 0)
    function, args = drawings[apart]
    path = args[-1] if os.waitstatus_to_exitcode(status) == 0 else function(*args)
    paths.insert(apart, Path(path))
    return paths


def _fixed_margins(fig, left: float = 0.07, right: float = 0.98, bottom: float = 0.06, top: float = 0.93,
                   hspace: float = 0.3, wspace: float = 0.2) -> None:
    """Subplot margins set, not searched: ``tight_layout`` measures every tick label of every panel
    (half of the figures' time, 1.2 s of the 4-h ``modelgen simulate``); these figures' layout is known."""
    fig.subplots_adjust(left=left, right=right, bottom=bottom, top=top, hspace=hspace, wspace=wspace)


def _ready_ticks(axes: Any, count: int) -> None:
    """Make ``count`` major ticks of each axis of ``axes`` now (matplotlib makes them while it draws, copying the
    first: half the time of a figure of many panels), for a figure prepared before its data is there."""
    if count <= 0:
        return
    for a in axes:
        a.xaxis.get_major_ticks(count)
        a.yaxis.get_major_ticks(count)


def pixel_envelope(values: np.ndarray, columns: int) -> np.ndarray:
    """Indices of the samples of a time series that draw the same line in ``columns`` pixel columns.

    The series is cut into ``columns`` consecutive runs of samples (one per
    pixel column of the axes); of each run the first, last, smallest and
    largest sample are kept (the M4 aggregation: a polyline through them covers
    the same pixels as through every sample), and every non-finite sample (a
    gap in the line).  A 4-h history has 14,400 rows per curve, an axes some
    400 pixel columns: the 54 curves of the filter's figure drawn from the kept
    1,600 points each take 0.52 s instead of 0.61 s of CPU.
    Returns sorted indices; all of them when there are few samples already.
    """
    n = len(values)
    if columns < 1:
        raise ValueError(f"pixel_envelope: columns must be positive, got {columns}")
    if n <= 4 * columns:
        return np.arange(n)
    edges = np.linspace(0, n, columns + 1).round().astype(np.intp)
    column = np.repeat(np.arange(columns), np.diff(edges))
    by_value = np.lexsort((values, column))  # per column, ascending value, NaN last
    numbers = np.add.reduceat(~np.isnan(values), edges[:-1])  # each column has 4 samples or more
    largest = by_value[edges[:-1] + np.maximum(numbers, 1) - 1]
    kept = np.concatenate([edges[:-1], edges[1:] - 1, by_value[edges[:-1]], largest,
                           np.flatnonzero(~np.isfinite(values))])
    return np.unique(kept)


def _pixel_columns(ax, dpi: float) -> int:
    """Pixel columns of an axes' plotting area in a figure saved at ``dpi`` (its position set already)."""
    return max(1, math.ceil(ax.get_position().width * ax.get_figure().get_figwidth() * dpi))


def _plot_series(ax, x: np.ndarray, y: np.ndarray, dpi: float, *args, semilog: bool = False, **kwargs) -> None:
    """``ax.plot`` (or ``semilogy``) of a time series, the samples reduced to its :func:`pixel_envelope`."""
    keep = pixel_envelope(y, _pixel_columns(ax, dpi))
    (ax.semilogy if semilog else ax.plot)(x[keep], y[keep], *args, **kwargs)


def _trajectory_axes(ticks: int = 0) -> tuple[Any, Any]:
    """The trajectory figure and its axes before any data (``ticks``: see :func:`_ready_ticks`)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 7))
    ax = fig.subplots(2, 2)
    _fixed_margins(fig, top=0.9, hspace=0.35, wspace=0.22)
    _ready_ticks(ax.flat, ticks)
    return fig, ax


def _plot_trajectory(trajectory: Trajectory, path: Path, prepared: tuple[Any, Any] | None = None) -> Path:
    """The truth's ground track, height, speeds and attitude (a Figure of its own, not pyplot's shared state).

    ``prepared``: the figure and axes from :func:`_trajectory_axes`, made before the data was (else made now).
    """
    truth = trajectory.truth
    hours = truth[:, 0] / 3600
    euler = np.degrees(dcm_to_euler(quaternion_to_dcm(truth[:, 7:11])))
    fig, ax = prepared or _trajectory_axes()
    dpi = 110
    ax[0, 0].plot(np.degrees(truth[:, 2]), np.degrees(truth[:, 1]))  # a path, not a time series: every point
    ax[0, 0].set(xlabel="longitude [deg]", ylabel="latitude [deg]", title="ground track")
    _plot_series(ax[0, 1], hours, truth[:, 3] / 1000, dpi)
    ax[0, 1].set(xlabel="time [h]", ylabel="height [km]", title="height")
    _plot_series(ax[1, 0], hours, np.hypot(truth[:, 4], truth[:, 5]) * 3.6, dpi, label="ground speed")
    _plot_series(ax[1, 0], hours, -truth[:, 6] * 3.6, dpi, label="climb rate")
    ax[1, 0].set(xlabel="time [h]", ylabel="km/h", title="speeds")
    ax[1, 0].legend()
    for i, name in enumerate(("roll", "pitch", "yaw")):
        _plot_series(ax[1, 1], hours, euler[:, i], dpi, label=name)
    ax[1, 1].set(xlabel="time [h]", ylabel="deg", title="attitude")
    ax[1, 1].legend()
    fig.suptitle(f"Flight profile {trajectory.path.name}")
    fig.savefig(path, dpi=dpi)
    return path


#: line styles of the correction modes: drawn widest first, so a mode whose curve
#: lies on another's (closed loop and accumulated, by seed 003's theorem) stays visible
_MODE_STYLES = {
    "open_loop": {"linewidth": 3.2, "alpha": 0.55},
    "closed_loop": {"linewidth": 1.8, "linestyle": "--"},
    "accumulated": {"linewidth": 1.2, "linestyle": (0, (1, 1.5))},
    "free INS": {"linewidth": 1.0, "linestyle": "-."},
}


def coinciding_modes(curves: dict[str, np.ndarray], tolerance: float = 0.01) -> dict[str, tuple[str, float]]:
    """For each curve lying on an earlier one (median relative difference below ``tolerance``): (that one, difference)."""
    notes: dict[str, tuple[str, float]] = {}
    labels = list(curves)
    for i, label in enumerate(labels):
        for earlier in labels[:i]:
            a, b = curves[earlier], curves[label]
            scale = np.maximum(np.abs(a), 1e-12)
            median = float(np.median(np.abs(a - b) / scale)) if a.size else 0.0
            if median < tolerance:
                notes[label] = (earlier, median)
                break
    return notes


def _modes_axes(ticks: int = 0) -> tuple[Any, Any]:
    """The correction modes' figure and its axes before any data, each on the log scale its curves are drawn on
    (set before ``ticks`` are made, see :func:`_ready_ticks`: a new scale makes new ticks)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 10))
    ax = fig.subplots(3, 1, sharex=True)
    _fixed_margins(fig, left=0.08, top=0.96, hspace=0.12)
    for a in ax:
        a.set_yscale("log")
    _ready_ticks(ax, ticks)
    return fig, ax


def _plot_modes(errors: dict[str, NavigationErrors], path: Path, prepared: tuple[Any, Any] | None = None) -> Path:
    """Each correction mode's (and the free INS's) position, velocity and heading errors; ``prepared``: the figure
    and axes from :func:`_modes_axes` (else made now)."""
    fig, ax = prepared or _modes_axes()
    dpi = 110
    panels = (
        ("horizontal position error [nmile]", lambda e: np.hypot(*e.position.T) / NMILE),
        ("horizontal velocity error [m/s]", lambda e: np.hypot(*e.velocity.T)),
        ("heading error [arcsec]", lambda e: np.abs(e.attitude[:, 2]) / ARCSEC),
    )
    for a, (unit, quantity) in zip(ax, panels):
        curves = {label: quantity(e) for label, e in errors.items()}
        notes = coinciding_modes(curves)
        for label, e in errors.items():
            shown = label if label not in notes else f"{label} (on {notes[label][0]}: median diff. {100 * notes[label][1]:.2g} %)"
            _plot_series(a, e.times / 3600, curves[label] + 1e-9, dpi, semilog=True, label=shown,
                         **_MODE_STYLES.get(label, {}))
        a.set(ylabel=unit)
        a.legend(fontsize=8)
        a.grid(True, which="both", alpha=0.3)
    ax[0].set(title="Corrected outputs by correction mode (one run, same sensors)")
    ax[2].set(xlabel="time since start [h]")
    fig.savefig(path, dpi=dpi)
    return path


def _filter_axes(names: list[str], units: dict[str, str], ticks: int = 0) -> tuple[Any, Any]:
    """The filter's figure before any data: a titled panel per state (the first 18), each in its unit.

    The titles sit where matplotlib would place them (``y=1.0``: no tick
    label above the panels), given rather than measured (a tenth of the
    figure's time).  ``ticks``: see :func:`_ready_ticks`.
    """
    from matplotlib.figure import Figure

    picks = _filter_panels(names)
    cols = 3
    rows = math.ceil(len(picks) / cols)
    fig = Figure(figsize=(13, 2.1 * rows))
    ax = fig.subplots(rows, cols, sharex=True)
    _fixed_margins(fig, left=0.06, top=1 - 0.8 / fig.get_figheight(), hspace=0.6, wspace=0.25)
    for k, i in enumerate(picks):
        a = ax.flat[k]
        a.set_title(f"{names[i]} [{units.get(names[i], '?')}]", fontsize=8, y=1.0)
        a.tick_params(labelsize=7)
    for a in list(ax.flat)[len(picks):]:
        a.axis("off")
    _time_labels(ax, len(picks), cols)
    _ready_ticks(ax.flat[:len(picks)], ticks)
    return fig, ax


def _filter_panels(names: list[str]) -> list[int]:
    """The states the filter's figure shows: the first 18."""
    return list(range(min(len(names), 18)))


def _plot_filter(result: RunResult, names: list[str], units: dict[str, str], path: Path,
                 prepared: tuple[Any, Any] | None = None) -> Path:
    """Each state's estimation error and the filter's 3-sigma bounds; ``prepared``: the figure and axes from
    :func:`_filter_axes` for these ``names`` and ``units`` (else made now)."""
    hours = result.times / 3600
    fig, ax = prepared or _filter_axes(names, units)
    dpi = 100
    for k, i in enumerate(_filter_panels(names)):
        a = ax.flat[k]
        _plot_series(a, hours, result.estimation_error[:, i], dpi, lw=0.8, label="error")
        _plot_series(a, hours, 3 * result.sigma[:, i], dpi, "r", lw=0.6, label="+-3 sigma")
        _plot_series(a, hours, -3 * result.sigma[:, i], dpi, "r", lw=0.6)
    fig.suptitle(f"Estimation error and filter 3-sigma, {result.mode} ({result.filter_name}); each panel in its state's unit")
    fig.savefig(path, dpi=dpi)
    return path


def _plot_monte_carlo(mc: MonteCarloResult, units: dict[str, str], path: Path) -> Path:
    from matplotlib.figure import Figure

    hours = mc.times / 3600
    rms, sigma = mc.ensemble_rms(), mc.mean_sigma()
    n = len(mc.state_names)
    cols = 3
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(13, 2.1 * rows))
    ax = fig.subplots(rows, cols, sharex=True)
    _fixed_margins(fig, left=0.06, top=1 - 0.8 / fig.get_figheight(), hspace=0.6, wspace=0.25)
    dpi = 100
    for i in range(n):
        a = ax.flat[i]
        _plot_series(a, hours, rms[:, i], dpi, label=f"ensemble rms ({_runs(mc.runs)})")
        _plot_series(a, hours, sigma[:, i], dpi, "--", label="filter covariance sigma")
        a.set_title(f"{mc.state_names[i]} [{units.get(mc.state_names[i], '?')}]", fontsize=8)
        a.tick_params(labelsize=7)
    ax.flat[0].legend(fontsize=7)
    for a in list(ax.flat)[n:]:
        a.axis("off")
    _time_labels(ax, n, cols)
    fig.suptitle(f"Monte Carlo: actual error rms vs covariance sigma ({mc.mode}, {_runs(mc.runs)}); each panel in its state's unit")
    fig.savefig(path, dpi=dpi)
    return path


def _time_labels(ax, used: int, cols: int) -> None:
    """'time [h]' under the lowest used panel of each column."""
    for column in range(min(cols, used)):
        lowest = column + cols * ((used - 1 - column) // cols)
        ax.flat[lowest].set_xlabel("time [h]", fontsize=8)


def _runs(count: int) -> str:
    """'1 run', '16 runs'."""
    return f"{count} run" + ("" if count == 1 else "s")


def _plot_nees(mc: MonteCarloResult, path: Path) -> Path:
    from matplotlib.figure import Figure

    test = mc.nees_test(0.95, start_time=mc.times[1] if len(mc.times) > 1 else 0.0)
    fig = Figure(figsize=(10, 4))
    ax = fig.subplots()
    ax.plot(test.times / 3600, test.mean_nees, label=f"ensemble mean NEES ({_runs(mc.runs)})")
    ax.axhline(test.dimension, color="k", lw=0.8, label=f"n = {test.dimension}")
    ax.axhspan(test.lower, test.upper, color="g", alpha=0.15, label="95 % chi-square band")
    ax.set(xlabel="time [h]", ylabel="NEES", title=f"NEES consistency: {100 * test.fraction_inside:.0f} % of times inside")
    ax.legend()
    _fixed_margins(fig, left=0.08, bottom=0.12, top=0.9)
    fig.savefig(path, dpi=110)
    return path


# -- summary ------------------------------------------------------------------------


_IMPLEMENTATION_TEXT = {
    "c": "the generated C (modelgen generate, default options), compiled for this run and driven, with the "
         "strapdown and the glue, by one compiled loop (modelgen/simulation/native_loop.py)",
    "python": "the generated Python module (modelgen generate, default options)",
    "reference": "the dense numpy reference filter (modelgen/derive/reference.py)",
}


def _summary(profile, model_name, implementation, conventions, trajectory, results, errors, mc, timings, figures) -> str:
    lines = [
        f"# Simulation: {profile.title or profile.name}",
        "",
        f"Scenario `{profile.name}` ({display_path(profile.source_file) if profile.source_file else 'built in code'}), {profile.path.duration / 3600:.2f} h, "
        f"IMU {profile.imu_rate:g} Hz with {profile.coning}-sample coning/sculling, filter model `{model_name}`, "
        f"aiding {profile.filter.aiding} every {profile.aiding_period:g} s, "
        f"filter cycle {profile.filter.period:g} s.",
        "",
        ("Sign conventions identified from the model's F and H (+1: as the simulation defines them; "
         "see modelgen/simulation/error_layout.py): " + ", ".join(f"{k} {v:+.0f}" for k, v in conventions.items()) + "."
         if conventions else
         "Error states mapped explicitly (psi-angle attitude, ENU position in metres, receiver clock ranges; "
         "see modelgen/simulation/pseudorange.py)."),
        "",
        "## Correction modes (one run, identical sensor data)",
        "",
        f"Filter: {_IMPLEMENTATION_TEXT[implementation]}.",
        "",
        "| output | final horizontal position error [m] | rms horizontal velocity error, last hour [m/s] | "
        "final heading error [arcsec] | updates | gate rejections | outage skips | refused |",
        "|---|---|---|---|---|---|---|---|",
    ]
    last_hour = errors["closed_loop"].times >= trajectory.truth[-1, 0] - 3600
    for label, e in errors.items():
        r = results.get(label)
        counts = f"{r.updates} | {len(r.rejected)} | {r.skipped} | {len(r.refused)}" if r else "- | - | - | -"
        lines.append(
            f"| {label} | {np.hypot(*e.position[-1]):.1f} | {np.sqrt(np.mean(np.sum(e.velocity[last_hour] ** 2, axis=1))):.3f} | "
            f"{e.attitude[-1, 2] / ARCSEC:.1f} | {counts} |"
        )
    cl, ac = errors["closed_loop"], errors["accumulated"]
    lines += [
        "",
        "Seed 003's theorem says accumulated correction equals closed-loop feedback in the linear case "
        "(tests/simulation/test_integration.py checks it to 1e-9).  On this nonlinear flight the largest "
        f"difference between the two corrected outputs is {np.max(np.hypot(*(cl.position - ac.position).T)):.3g} m in position "
        f"and {np.max(np.abs(cl.attitude - ac.attitude)) / ARCSEC:.3g} arcsec in attitude.",
        "",
    ]
    free_ins = np.hypot(*errors["free INS"].position[-1])
    for mode, result in results.items():
        offered = result.updates + len(result.rejected)
        if offered and len(result.rejected) > 0.01 * offered:
            why = (f"In this mode the INS runs uncorrected and its error reaches {free_ins:.3g} m; at that size the "
                   "terms the first-order error model neglects (they grow with the square of the error) can exceed "
                   "the filter's sigma.  Closed-loop feedback keeps the errors small enough for the model to hold."
                   if mode != "closed_loop" else
                   "With feedback the errors stay small, so this points at the filter's tuning or model.")
            lines += [f"**{mode}: the gate rejected {len(result.rejected)} of {offered} measurements "
                      f"({100 * len(result.rejected) / offered:.0f} %).**  {why}", ""]
    if mc is not None:
        test = mc.nees_test(0.95, start_time=mc.times[1] if len(mc.times) > 1 else 0.0)
        rms, sigma = mc.ensemble_rms(), mc.mean_sigma()
        lines += [
            f"## Monte Carlo ({_runs(mc.runs)}, {mc.mode}, {mc.seconds:.1f} s)",
            "",
            f"Filter: {_IMPLEMENTATION_TEXT[implementation]}, built once per worker.",
            "",
            f"Ensemble mean NEES inside the 95 % chi-square band [{test.lower:.2f}, {test.upper:.2f}] "
            f"(n = {test.dimension}) at {100 * test.fraction_inside:.0f} % of the {len(test.times)} stored times: "
            f"{'consistent' if test.passed() else 'NOT consistent'} (criterion: at least 85 %).  "
            f"Gate rejections over all runs: {int(mc.rejected.sum())}.",
            "",
            "| state | ensemble rms at end | filter sigma at end | ratio |",
            "|---|---|---|---|",
        ]
        for i, name in enumerate(mc.state_names):
            ratio = rms[-1, i] / sigma[-1, i] if sigma[-1, i] > 0 else math.nan
            lines.append(f"| {name} | {rms[-1, i]:.4g} | {sigma[-1, i]:.4g} | {ratio:.2f} |")
        lines.append("")
    lines += ["## Timings", "", "| step | seconds |", "|---|---|"]
    lines += [f"| {k} | {v:.2f} |" for k, v in timings.items()]
    lines += ["", "## Figures", ""] + [f"![{p.stem}]({p.name})" for p in figures] + [""]
    return "\n".join(lines)
