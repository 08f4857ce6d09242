"""`modelgen simulate`: fly a flight profile, write PNG figures and a Markdown summary.

What it does, in order: generate the truth (the ideal IMU data comes piece by
piece, :mod:`modelgen.simulation.streaming`) while helper threads build the
filter code and draw the IMU errors; draw the other sensor errors;
fly the filter (the generated C by default, in the compiled loop of
:mod:`modelgen.simulation.native_loop`) on them in the three correction modes
(open loop, closed loop, seed 003's accumulated correction) in one pass over
the data, plus the free INS (the trajectory figure is drawn meanwhile); run a
Monte Carlo ensemble and test its NEES; plot and summarize.  Memory does not grow with the IMU data; histories hold at most
:data:`~modelgen.simulation.streaming.MAX_HISTORY_ROWS` rows per mode.  Progress goes to ``echo``.
"""

from __future__ import annotations

import math
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from modelgen.derive.symbolic import DerivedModel
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
             client: Any = None, history_csv: bool = False, journal: str | Path | None = None) -> Path:
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
    """
    import matplotlib

    matplotlib.use("Agg")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}

    echo(f"modelgen simulate: {profile.name}, {profile.path.duration / 3600:.2f} h, IMU {profile.imu_rate:g} Hz "
         f"({'numba' if HAVE_NUMBA else 'pure Python: slow'}), filter {derived.model.name}, {runs} Monte Carlo runs")
    results: dict[str, RunResult] = {}
    with tempfile.TemporaryDirectory(prefix="modelgen-simulate-") as code_dir, ThreadPoolExecutor(2) as helpers:
        # the filter code is generated and compiled (a compiler process) while the truth and the sensors are
        # made, and the IMU errors (the seed's first draws, they need no truth) are drawn while the truth is made
        building = helpers.submit(_timed, filter_factory, derived, implementation, code_dir)
        n_samples, record_every_sample = sample_counts(profile.path, profile.imu_rate, 1.0 / profile.filter.period)
        rng = np.random.default_rng(seed)
        drawing = helpers.submit(_timed, imu_error_stream, profile, n_samples, record_every_sample, rng)
        t = time.perf_counter()
        trajectory = generate_trajectory(profile.path, profile.imu_rate, 1.0 / profile.filter.period, streamed=True)
        timings["trajectory (truth; IMU increments are generated piece by piece in the flight)"] = time.perf_counter() - t
        echo(f"  trajectory: truth of {trajectory.n_samples} IMU samples in {time.perf_counter() - t:.1f} s")
        # drawn while the filter flies (a figure of the truth alone)
        trajectory_figure = helpers.submit(_plot_trajectory, trajectory, out_dir / "trajectory.png")
        layout = profile_layout(profile, derived, trajectory)
        imu_stream, drawn = drawing.result()
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

    units = {state.name: state.unit for state in derived.model.states}
    figures = [
        trajectory_figure.result(),
        _plot_modes(errors, out_dir / "correction_modes.png"),
        _plot_filter(results[profile.filter.mode], derived.model.state_names, units, out_dir / "filter_errors.png"),
    ]
    if monte_carlo is not None:
        figures.append(_plot_monte_carlo(monte_carlo, units, out_dir / "monte_carlo.png"))
        figures.append(_plot_nees(monte_carlo, out_dir / "nees.png"))
    summary = out_dir / "summary.md"
    summary.write_text(cite_sources(_summary(profile, derived.model.name, implementation, layout.conventions, trajectory, results, errors,
                                monte_carlo, timings, figures)), encoding="utf-8")
    echo(f"  wrote {summary} and {len(figures)} figures")
    return summary


# -- figures ------------------------------------------------------------------------


# The figures are matplotlib Figures of their own (no pyplot: no global figure registry to close, and the
# trajectory figure can be drawn by a helper thread while the filter flies).


def _fixed_margins(fig, left: float = 0.07, right: float = 0.98, bottom: float = 0.06, top: float = 0.93,
                   hspace: float = 0.3, wspace: float = 0.2) -> None:
    """Subplot margins set, not searched: ``tight_layout`` measures every tick label of every panel
    (half of the figures' time, 1.2 s of the 4-h ``modelgen simulate``); these figures' layout is known."""
    fig.subplots_adjust(left=left, right=right, bottom=bottom, top=top, hspace=hspace, wspace=wspace)


def _plot_trajectory(trajectory: Trajectory, path: Path) -> Path:
    """The truth's ground track, height, speeds and attitude; drawn by a helper thread while the filter flies
    (a Figure of its own, not pyplot's shared state)."""
    from matplotlib.figure import Figure

    truth = trajectory.truth
    hours = truth[:, 0] / 3600
    euler = np.degrees(dcm_to_euler(quaternion_to_dcm(truth[:, 7:11])))
    fig = Figure(figsize=(11, 7))
    ax = fig.subplots(2, 2)
    ax[0, 0].plot(np.degrees(truth[:, 2]), np.degrees(truth[:, 1]))
    ax[0, 0].set(xlabel="longitude [deg]", ylabel="latitude [deg]", title="ground track")
    ax[0, 1].plot(hours, truth[:, 3] / 1000)
    ax[0, 1].set(xlabel="time [h]", ylabel="height [km]", title="height")
    ax[1, 0].plot(hours, np.hypot(truth[:, 4], truth[:, 5]) * 3.6, label="ground speed")
    ax[1, 0].plot(hours, -truth[:, 6] * 3.6, label="climb rate")
    ax[1, 0].set(xlabel="time [h]", ylabel="km/h", title="speeds")
    ax[1, 0].legend()
    for i, name in enumerate(("roll", "pitch", "yaw")):
        ax[1, 1].plot(hours, euler[:, i], label=name)
    ax[1, 1].set(xlabel="time [h]", ylabel="deg", title="attitude")
    ax[1, 1].legend()
    fig.suptitle(f"Flight profile {trajectory.path.name}")
    _fixed_margins(fig, top=0.9, hspace=0.35, wspace=0.22)
    fig.savefig(path, dpi=110)
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


def _plot_modes(errors: dict[str, NavigationErrors], path: Path) -> Path:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 10))
    ax = fig.subplots(3, 1, sharex=True)
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
            a.semilogy(e.times / 3600, curves[label] + 1e-9, label=shown, **_MODE_STYLES.get(label, {}))
        a.set(ylabel=unit)
        a.legend(fontsize=8)
        a.grid(True, which="both", alpha=0.3)
    ax[0].set(title="Corrected outputs by correction mode (one run, same sensors)")
    ax[2].set(xlabel="time since start [h]")
    _fixed_margins(fig, left=0.08, top=0.96, hspace=0.12)
    fig.savefig(path, dpi=110)
    return path


def _plot_filter(result: RunResult, names: list[str], units: dict[str, str], path: Path) -> Path:
    from matplotlib.figure import Figure

    hours = result.times / 3600
    picks = [i for i in range(len(names))][: min(len(names), 18)]
    cols = 3
    rows = math.ceil(len(picks) / cols)
    fig = Figure(figsize=(13, 2.1 * rows))
    ax = fig.subplots(rows, cols, sharex=True)
    for k, i in enumerate(picks):
        a = ax.flat[k]
        a.plot(hours, result.estimation_error[:, i], lw=0.8, label="error")
        a.plot(hours, 3 * result.sigma[:, i], "r", lw=0.6, label="+-3 sigma")
        a.plot(hours, -3 * result.sigma[:, i], "r", lw=0.6)
        a.set_title(f"{names[i]} [{units.get(names[i], '?')}]", fontsize=8)
        a.tick_params(labelsize=7)
    for a in list(ax.flat)[len(picks):]:
        a.axis("off")
    _time_labels(ax, len(picks), cols)
    fig.suptitle(f"Estimation error and filter 3-sigma, {result.mode} ({result.filter_name}); each panel in its state's unit")
    _fixed_margins(fig, left=0.06, top=1 - 0.8 / fig.get_figheight(), hspace=0.6, wspace=0.25)
    fig.savefig(path, dpi=100)
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
    for i in range(n):
        a = ax.flat[i]
        a.plot(hours, rms[:, i], label=f"ensemble rms ({_runs(mc.runs)})")
        a.plot(hours, sigma[:, i], "--", label="filter covariance sigma")
        a.set_title(f"{mc.state_names[i]} [{units.get(mc.state_names[i], '?')}]", fontsize=8)
        a.tick_params(labelsize=7)
    ax.flat[0].legend(fontsize=7)
    for a in list(ax.flat)[n:]:
        a.axis("off")
    _time_labels(ax, n, cols)
    fig.suptitle(f"Monte Carlo: actual error rms vs covariance sigma ({mc.mode}, {_runs(mc.runs)}); each panel in its state's unit")
    _fixed_margins(fig, left=0.06, top=1 - 0.8 / fig.get_figheight(), hspace=0.6, wspace=0.25)
    fig.savefig(path, dpi=100)
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
