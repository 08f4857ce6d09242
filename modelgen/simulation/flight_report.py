"""`modelgen simulate`: fly a flight profile, write PNG figures and a Markdown summary.

What it does, in order: generate the truth (the ideal IMU data comes piece by
piece, :mod:`modelgen.simulation.streaming`) and draw the IMU errors, in two
threads started before the filter model is derived
(:func:`~modelgen.simulation.flight_start.start_flight`), while a helper
thread builds the filter code; draw the other sensor errors; fly the filter
(the generated C by default, in the compiled loop of
:mod:`modelgen.simulation.native_loop`) on them in the three correction modes
(open loop, closed loop, the accumulated-correction paper's accumulated correction) in one pass over
the data, plus the free INS; run a Monte Carlo ensemble and test its NEES;
plot (:mod:`modelgen.simulation.flight_figures`, drawn in a copy of the
process forked at the start, :mod:`modelgen.simulation.figure_process`) and
summarize (:mod:`modelgen.simulation.flight_summary`).  Memory does not grow
with the IMU data; histories hold at most
:data:`~modelgen.simulation.streaming.MAX_HISTORY_ROWS` rows per mode.
Progress goes to ``echo``.
"""

from __future__ import annotations

import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from modelgen.errors import ModelError
from modelgen.model.sources import cite_sources
from modelgen.simulation.figure_process import draw_figures, import_plotting
from modelgen.simulation.filter_loop import MODES, RunResult
from modelgen.simulation.filters import filter_factory
from modelgen.simulation.flight import profile_layout, simulate_sensors
from modelgen.simulation.flight_errors import navigation_errors
from modelgen.simulation.flight_figures import (
    FIGURE_TICKS,
    display_factors,
    display_units,
    filter_axes,
    modes_axes,
    plot_filter,
    plot_modes,
    plot_monte_carlo,
    plot_nees,
    plot_trajectory,
    runs_text,
    trajectory_axes,
)
from modelgen.simulation.flight_start import FlightStart, finished, in_background, start_flight, timed
from modelgen.simulation.flight_summary import figure_captions, summary_markdown, targets
from modelgen.simulation.history import CsvHistory
from modelgen.simulation.jit import HAVE_NUMBA
from modelgen.simulation.model_process import PreparedModel
from modelgen.simulation.montecarlo import check_journal, run_monte_carlo
from modelgen.simulation.scenario import FlightProfile
from modelgen.simulation.streaming import flies_compiled_loop, fly_modes, history_every

if TYPE_CHECKING:  # sympy-based: a flight given a PreparedModel imports no sympy
    from modelgen.derivation.symbolic import DerivedModel

__all__ = ["simulate", "simulation_report", "FlightReport", "start_flight", "FlightStart"]


@dataclass(frozen=True)
class FlightReport:
    """What a flight's report says, for the reports that show it (``modelgen run``): its summary.md, each figure
    with its one-line caption, and its stated targets (each ``quantity``, ``reached``, ``target``, ``met``)."""

    summary: Path
    figures: dict[Path, str]
    targets: list[dict]


def _echo_progress(echo: Callable[[str], None], label: str) -> Callable[[int, int], None]:
    state = {"next": 0.1, "start": time.perf_counter()}

    def report(done: int, total: int) -> None:
        if done / total >= state["next"] or done == total:
            echo(f"  {label}: {100 * done / total:5.1f} %  ({time.perf_counter() - state['start']:.1f} s)")
            while state["next"] <= done / total:
                state["next"] += 0.1

    return report


def state_units(derived: "DerivedModel | PreparedModel") -> dict[str, str]:
    """Each state's unit, by name."""
    if isinstance(derived, PreparedModel):
        return dict(derived.units)
    return {state.name: state.unit for state in derived.model.states}


def simulation_report(profile: FlightProfile, derived: "DerivedModel | PreparedModel", out_dir: Path, runs: int = 20, seed: int = 0,
             workers: int = 2, echo: Callable[[str], None] = print, implementation: str = "c",
             client: Any = None, history_csv: bool = False, journal: str | Path | None = None,
             started: FlightStart | None = None) -> FlightReport:
    """Fly ``profile`` with its filter model ``derived`` (module docstring): the summary, figures and targets.

    ``implementation`` is the filter of the three correction-mode runs: the
    generated ``c`` (compiled now) or ``python``, or the numpy ``reference``.
    The Monte Carlo runs fly the same filter, as dask tasks on ``client``
    (a local cluster of ``workers`` when None).
    ``derived`` is the profile's ``filter.model``, derived by the caller (the
    main job hands down the model it derived once), or what the flight needs of it, prepared
    (:class:`~modelgen.simulation.model_process.PreparedModel`: ``modelgen simulate``'s C filter; the same numbers).  ``history_csv`` also
    writes each mode's history, as it is flown, to ``history_<mode>.csv``
    (:mod:`modelgen.simulation.history`) in ``out_dir``.  ``journal`` keeps
    the completed Monte Carlo runs (:func:`modelgen.simulation.montecarlo.run_monte_carlo`).
    ``started``: this flight's truth and IMU errors, already being made (:func:`start_flight` with this
    profile object and seed); they are started here otherwise.
    """
    check_monte_carlo_journal(journal, profile, derived, runs, seed, implementation, started)  # before anything is flown
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
        prepared = derived if isinstance(derived, PreparedModel) else None
        if prepared is not None:
            if implementation != "c":
                raise ModelError(f"simulate: a prepared model flies the generated C filter, not {implementation!r}")
            building = helpers.submit(timed, filter_factory, prepared.outline, implementation, code_dir, prepared.files)
        else:
            building = helpers.submit(timed, filter_factory, derived, implementation, code_dir)
        trajectory, seconds = started.trajectory()
        later = "its positions and " if trajectory.positions_in_pieces else ""
        timings[f"trajectory (truth; {later}IMU increments are generated piece by piece in the flight)"] = seconds
        echo(f"  trajectory: truth of {trajectory.n_samples} IMU samples in {seconds:.1f} s")
        if prepared is None:
            layout, flown = profile_layout(profile, derived, trajectory), derived
        imu_stream, drawn = started.imu_errors()
        rng = started.rng
        timings["IMU errors (drawn alongside the trajectory)"] = drawn
        t = time.perf_counter()
        sensors = simulate_sensors(profile, trajectory, rng, imu_stream=imu_stream)
        timings["sensors (initial errors, reference altitude, aiding)"] = time.perf_counter() - t
        make_filter, build = building.result()
        timings[f"filter code ({implementation}: generate, compile or import; alongside the above)"] = build
        echo(f"  filter: {implementation} ({build:.1f} s to build, alongside the trajectory and sensors)")
        if prepared is not None and flies_compiled_loop(profile.aiding_sensor, make_filter):
            layout, flown = prepared.layout, prepared.outline  # all that the compiled loop reads of the model
        elif prepared is not None:  # the Python loop evaluates the symbolic H and R: the derived model (sympy)
            flown = prepared.symbolic_model()
            layout = profile_layout(profile, flown, trajectory)
        t = time.perf_counter()
        n_cycles = len(trajectory.truth) - 1
        record_every = history_every(n_cycles)
        histories = {mode: CsvHistory(out_dir / f"history_{mode}.csv", derived.model.state_names)
                     for mode in MODES} if history_csv else {}
        # without a figure process, the figures' imports (0.4 s) are done while the flight goes: its thread
        # making the IMU increments sets the pace, the flying thread's core has time to spare
        plotting = in_background(import_plotting) if started.figures is None else None
        positions = profile.filter.states.get("position", {})
        units = display_units(state_units(derived), positions)
        if started.figures is not None:  # their figures and axes made while the flight goes
            started.figures.prepare(plot_trajectory, trajectory_axes, (FIGURE_TICKS,))
            started.figures.prepare(plot_modes, modes_axes, (FIGURE_TICKS,))
            started.figures.prepare(plot_filter, filter_axes, (derived.model.state_names, units, FIGURE_TICKS))
        try:
            results = fly_modes(profile, flown, trajectory, sensors, layout, make_filter, MODES,
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
        monte_carlo = run_monte_carlo(profile, flown, runs, seed=monte_carlo_seed(seed), workers=workers, client=client,
                                      progress=_echo_progress(echo, "Monte Carlo runs"), implementation=implementation,
                                      journal=journal, setup=prepared.monte_carlo if prepared is not None else None)
        timings[f"Monte Carlo ({runs_text(runs)}, {monte_carlo.where})"] = time.perf_counter() - t

    factors = display_factors(state_units(derived), positions,
                              float(np.mean(trajectory.truth[:, 1])), float(np.mean(trajectory.truth[:, 3])))
    drawings: list[tuple[Callable[..., Path], tuple]] = [
        (plot_trajectory, (trajectory, out_dir / "trajectory.png")),
        (plot_modes, (errors, out_dir / "correction_modes.png")),
        (plot_filter, (results[profile.filter.mode], derived.model.state_names, units, factors,
                       out_dir / "filter_errors.png")),
    ]
    if monte_carlo is not None:
        drawings.append((plot_monte_carlo, (monte_carlo, units, factors, out_dir / "monte_carlo.png")))
        drawings.append((plot_nees, (monte_carlo, out_dir / "nees.png")))
    if started.figures is None:
        finished(plotting)
        figures = draw_figures(drawings, apart=2)  # the filter's 18 panels: the longest drawing
    else:
        try:
            started.figures.draw(drawings, apart=2)
            figures = started.figures.paths()
        finally:
            started.figures.close()
    summary = out_dir / "summary.md"
    summary.write_text(cite_sources(summary_markdown(profile, derived.model.name, implementation, layout.conventions, trajectory, results, errors,
                                monte_carlo, timings, figures, units)), encoding="utf-8")
    echo(f"  wrote {summary} and {len(figures)} figures")
    captions = figure_captions(profile, trajectory, results, monte_carlo, units)
    return FlightReport(summary, {path: captions.get(path.name, path.stem) for path in figures}, targets(monte_carlo))


def monte_carlo_seed(seed: int) -> int:
    """The seed of a flight's Monte Carlo runs: not the single flight's own (``seed``)."""
    return seed + 1


def check_monte_carlo_journal(journal: str | Path | None, profile: FlightProfile, derived: Any, runs: int, seed: int,
                              implementation: str, started: FlightStart | None = None) -> bool:
    """Refuse a journal of another study before anything is flown (``derived``: as :func:`simulation_report` takes it);
    the figure process of ``started``, the flight begun, is closed then.  True when the journal holds every run
    (none is flown: no cluster is needed)."""
    if journal is None or runs < 1:
        return False
    prepared = derived if isinstance(derived, PreparedModel) else None
    try:
        held = check_journal(journal, profile, None if prepared else derived, runs, monte_carlo_seed(seed), implementation,
                             setup=prepared.monte_carlo if prepared else None)
    except ModelError:
        if started is not None and started.figures is not None:
            started.figures.close()
        raise
    return held == runs


def simulate(*args: Any, **kwargs: Any) -> Path:
    """:func:`simulation_report` (same arguments), returning only the summary's path (``modelgen simulate``)."""
    return simulation_report(*args, **kwargs).summary
