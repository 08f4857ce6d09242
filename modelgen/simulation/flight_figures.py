"""The figures of ``modelgen simulate``: trajectory, correction modes, the filter's errors, Monte Carlo, NEES.

Each is a matplotlib Figure of its own (no pyplot: no global figure
registry to close, and a figure can be drawn in a forked copy of the process,
:mod:`modelgen.simulation.figure_process`); a figure's axes can be made before
its data (``*_axes``), and each time series is cut to what its pixel columns
show (:func:`pixel_envelope`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from modelgen.simulation.filter_loop import RunResult
from modelgen.simulation.flight_errors import ARCSEC, NMILE, NavigationErrors
from modelgen.simulation.montecarlo import MonteCarloResult
from modelgen.simulation.rotation import dcm_to_euler, quaternion_to_dcm
from modelgen.simulation.trajectory import Trajectory


#: the figures' engineering units for the model's SI units: (figure unit, SI value of one figure unit)
ENGINEERING_UNITS = {"rad": ("arcmin", math.pi / 180 / 60), "rad/s": ("deg/h", math.pi / 180 / 3600),
                     "m/s^2": ("mg", 9.80665e-3)}


def display_units(units: dict[str, str], positions: dict[str, str]) -> dict[str, str]:
    """Each state's unit on the figures: a latitude or longitude error (``positions``: the profile's
    ``filter.states.position`` mapping, state -> latitude or longitude) in metres north or east, other angles in
    arcmin, angular rates in deg/h, accelerations in mg; anything else in its own unit."""
    roles = {"latitude": "m north", "longitude": "m east"}
    return {name: roles[positions[name]] if unit == "rad" and positions.get(name) in roles
            else ENGINEERING_UNITS.get(unit, (unit, 1.0))[0] for name, unit in units.items()}


def display_factors(units: dict[str, str], positions: dict[str, str], latitude: float, height: float) -> dict[str, float]:
    """The factors from each state's SI value to its :func:`display_units` value; a latitude error takes
    R_M + h, a longitude error (R_N + h) cos(latitude) at the flight's mean ``latitude`` and ``height``."""
    from modelgen.simulation import earth

    meridian, prime_vertical = earth.radii_of_curvature(latitude)
    roles = {"latitude": meridian + height, "longitude": (prime_vertical + height) * math.cos(latitude)}
    return {name: roles[positions[name]] if unit == "rad" and positions.get(name) in roles
            else 1.0 / ENGINEERING_UNITS.get(unit, (unit, 1.0))[1] for name, unit in units.items()}

#: major ticks made per axis of a figure prepared before its data (:func:`_ready_ticks`): more than a
#: panel of these figures shows
FIGURE_TICKS = 10


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


def trajectory_axes(ticks: int = 0) -> tuple[Any, Any]:
    """The trajectory figure and its axes before any data (``ticks``: see :func:`_ready_ticks`)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 7))
    ax = fig.subplots(2, 2)
    _fixed_margins(fig, top=0.9, hspace=0.35, wspace=0.22)
    _ready_ticks(ax.flat, ticks)
    return fig, ax


def plot_trajectory(trajectory: Trajectory, path: Path, prepared: tuple[Any, Any] | None = None) -> Path:
    """The truth's ground track, height, speeds and attitude (a Figure of its own, not pyplot's shared state).

    ``prepared``: the figure and axes from :func:`trajectory_axes`, made before the data was (else made now).
    """
    truth = trajectory.truth
    hours = truth[:, 0] / 3600
    euler = np.degrees(dcm_to_euler(quaternion_to_dcm(truth[:, 7:11])))
    fig, ax = prepared or trajectory_axes()
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
#: lies on another's (closed loop and accumulated, by the accumulated-correction paper's theorem) stays visible
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


def modes_axes(ticks: int = 0) -> tuple[Any, Any]:
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


def plot_modes(errors: dict[str, NavigationErrors], path: Path, prepared: tuple[Any, Any] | None = None) -> Path:
    """Each correction mode's (and the free INS's) position, velocity and heading errors; ``prepared``: the figure
    and axes from :func:`modes_axes` (else made now)."""
    fig, ax = prepared or modes_axes()
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


def filter_axes(names: list[str], units: dict[str, str], ticks: int = 0) -> tuple[Any, Any]:
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


def plot_filter(result: RunResult, names: list[str], units: dict[str, str], factors: dict[str, float], path: Path,
                prepared: tuple[Any, Any] | None = None) -> Path:
    """Each state's estimation error and the filter's 3-sigma bounds, in the figures' units (``units`` from
    :func:`display_units`, ``factors`` from :func:`display_factors`); ``prepared``: the figure and axes from
    :func:`filter_axes` for these ``names`` and ``units`` (else made now)."""
    hours = result.times / 3600
    fig, ax = prepared or filter_axes(names, units)
    dpi = 100
    for k, i in enumerate(_filter_panels(names)):
        a = ax.flat[k]
        scale = factors.get(names[i], 1.0)
        _plot_series(a, hours, scale * result.estimation_error[:, i], dpi, lw=0.8, label="estimation error")
        _plot_series(a, hours, 3 * scale * result.sigma[:, i], dpi, "r", lw=0.6, label="filter's +-3 sigma")
        _plot_series(a, hours, -3 * scale * result.sigma[:, i], dpi, "r", lw=0.6)
    ax.flat[0].legend(fontsize=7, loc="upper right")
    fig.suptitle(f"Estimation error and the filter's 3 sigma, one run, {result.mode} ({result.filter_name})")
    fig.savefig(path, dpi=dpi)
    return path


def plot_monte_carlo(mc: MonteCarloResult, units: dict[str, str], factors: dict[str, float], path: Path) -> Path:
    """The runs' error against the filter's sigma per state, in the figures' units: the rms over the runs, or,
    for one run, that run's absolute error (one run is no ensemble)."""
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
    error = "|error| of the one run" if mc.runs == 1 else f"error rms over {runs_text(mc.runs)}"
    for i in range(n):
        a = ax.flat[i]
        scale = factors.get(mc.state_names[i], 1.0)
        _plot_series(a, hours, scale * rms[:, i], dpi, label=error)
        _plot_series(a, hours, scale * sigma[:, i], dpi, "--", label="filter's sigma" + ("" if mc.runs == 1 else " (mean)"))
        a.set_title(f"{mc.state_names[i]} [{units.get(mc.state_names[i], '?')}]", fontsize=8)
        a.tick_params(labelsize=7)
    ax.flat[0].legend(fontsize=7)
    for a in list(ax.flat)[n:]:
        a.axis("off")
    _time_labels(ax, n, cols)
    fig.suptitle(f"{'One Monte Carlo run' if mc.runs == 1 else f'Monte Carlo, {runs_text(mc.runs)}'} ({mc.mode}): "
                 f"{'its absolute error' if mc.runs == 1 else 'error rms'} against the filter's sigma")
    fig.savefig(path, dpi=dpi)
    return path


def _time_labels(ax, used: int, cols: int) -> None:
    """'time [h]' under the lowest used panel of each column."""
    for column in range(min(cols, used)):
        lowest = column + cols * ((used - 1 - column) // cols)
        ax.flat[lowest].set_xlabel("time [h]", fontsize=8)


def runs_text(count: int) -> str:
    """'1 run', '16 runs'."""
    return f"{count} run" + ("" if count == 1 else "s")


def nees_verdict(test: Any) -> str:
    """What the NEES test says, in words that claim no more than it measured: the fraction inside the band
    against the criterion (met or missed), for one run or the runs' mean."""
    return (f"{'NEES of the one run' if test.runs == 1 else f'mean NEES over {runs_text(test.runs)}'} inside the "
            f"{100 * test.confidence:.0f} % chi-square band at {100 * test.fraction_inside:.0f} % of the times "
            f"(criterion: at least {100 * (test.confidence - 0.1):.0f} %: {'met' if test.passed() else 'missed'})")


def plot_nees(mc: MonteCarloResult, path: Path) -> Path:
    """The NEES (of the one run, or the runs' mean) against its chi-square band."""
    from matplotlib.figure import Figure

    test = mc.nees_test(0.95, start_time=mc.times[1] if len(mc.times) > 1 else 0.0)
    fig = Figure(figsize=(10, 4))
    ax = fig.subplots()
    ax.plot(test.times / 3600, test.mean_nees,
            label="NEES of the one run" if mc.runs == 1 else f"mean NEES over {runs_text(mc.runs)}")
    ax.axhline(test.dimension, color="k", lw=0.8, label=f"n = {test.dimension} (its expected value)")
    band = f"{test.runs * test.dimension} degrees of freedom" + ("" if test.runs == 1 else f", divided by {test.runs}")
    ax.axhspan(test.lower, test.upper, color="g", alpha=0.15, label=f"95 % band (chi-square, {band})")
    verdict = nees_verdict(test)
    ax.set(xlabel="time [h]", ylabel="NEES", title=verdict[0].upper() + verdict[1:])
    ax.title.set_fontsize(9)
    ax.legend(fontsize=8)
    _fixed_margins(fig, left=0.08, bottom=0.12, top=0.9)
    fig.savefig(path, dpi=110)
    return path
