"""Analogues of the paper's Figs 2-7: error standard deviations over the 4-h run.

Fig 2: pure inertial attitude and heading errors; Fig 3: pure inertial
velocity and position errors; Figs 4-7: integrated systems (optimal and
suboptimal I-IV) attitude, heading, velocity and position (CEP) errors.

The paper prints numbers only for the end of the run (Table 2 and the text of
section 3), so those are overlaid as markers at 4 h, in the colour of their
system's curve.  Curves that lie on top of each other are named in the legend
with the measured difference, and the caption says what the two designs have
in common (computed from the designs, not written per figure).
PNG via matplotlib's Agg backend, without date metadata.
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from typing import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from modelgen.table2.suboptimal import FilterDesign  # noqa: E402
from modelgen.table2.systems import PURE_INERTIAL, SystemResult  # noqa: E402
from modelgen.table2.comparison import PaperTable  # noqa: E402

_METADATA = {"Software": None}  # no version/date strings in the PNG

#: two curves "coincide" when their median relative difference after the
#: first hour is below this; at the figures' line widths they are then
#: indistinguishable, so the legend says so instead of hiding one of them.
COINCIDENCE = 0.01


def _save(fig, path: Path, caption: str = "") -> Path:
    if caption:
        wrapped = sum(1 + len(line) // 150 for line in caption.split("\n"))
        fig.text(0.01, 0.01, caption, fontsize=7.5, ha="left", va="bottom", wrap=True)
        fig.tight_layout(rect=(0, min(0.5, 0.02 + 0.032 * wrapped), 1, 1))
    else:
        fig.tight_layout()
    fig.savefig(path, dpi=110, metadata=_METADATA)
    plt.close(fig)
    return path


def relative_difference(a: np.ndarray, b: np.ndarray, times_h: np.ndarray) -> tuple[float, float]:
    """Median and maximum of |a - b| / |a| after the first hour (the settling transient excluded)."""
    settled = (np.asarray(times_h) >= 1.0) & (np.abs(a) > 0)
    if not settled.any():
        return float("inf"), float("inf")
    r = np.abs(a[settled] - b[settled]) / np.abs(a[settled])
    return float(np.median(r)), float(np.max(r))


def coinciding_pairs(
    results: Mapping[str, SystemResult], times_h, key: str, tolerance: float = COINCIDENCE
) -> list[tuple[str, str, float, float]]:
    """Pairs of systems (first, second, median, max relative difference) whose ``key`` curves coincide."""
    systems = list(results)
    pairs = []
    for i, first in enumerate(systems):
        for second in systems[i + 1 :]:
            median, largest = relative_difference(results[first].errors[key], results[second].errors[key], times_h)
            if median < tolerance:
                pairs.append((first, second, median, largest))
    return pairs


def design_difference(first: FilterDesign, second: FilterDesign) -> str:
    """What two filter designs differ in, in words (the reason their curves may coincide)."""
    differing = [f.name for f in fields(FilterDesign) if f.name not in ("key", "label") and getattr(first, f.name) != getattr(second, f.name)]
    if differing and set(differing) <= {"gain_period", "manoeuvre_gain_period"}:
        return (
            f"same filter model; they differ only in the gain schedule (gain recomputed every "
            f"{first.gain_period} vs every {second.gain_period} steps, {first.manoeuvre_gain_period} vs "
            f"{second.manoeuvre_gain_period} while manoeuvring), which this error hardly feels"
        )
    if not differing:
        return "identical designs"
    return "they differ in " + ", ".join(d.replace("_", " ") for d in differing)


def _paper_markers(ax, results: Mapping[str, SystemResult], times_h, key: str, paper: PaperTable | None, colours: Mapping[str, str]) -> None:
    """The paper's 4-h value of ``key`` for each plotted system, as a marker at the end of the run."""
    if paper is None:
        return
    end = float(np.asarray(times_h)[-1])
    labelled = False
    for system in results:
        value = paper.values.get(system, {}).get(key)
        if value is None:
            continue
        ax.plot([end], [value], marker="D", markersize=6, linestyle="none", color=colours.get(system, "k"),
                markeredgecolor="k", label=None if labelled else "paper, 4 h (Table 2 / text)")
        labelled = True


def _panel(ax, results: Mapping[str, SystemResult], times_h, key: str, title: str, unit: str,
           paper: PaperTable | None, labels: Mapping[str, str] | None = None) -> None:
    """One quantity of several systems against time, with the paper's end values and coinciding curves named."""
    styles = ("-", "--", "-.", ":", (0, (5, 1, 1, 1)))
    notes = {second: f"{results[second].label} (on {results[first].label}: median diff. {100 * med:.2f} %)"
             for first, second, med, _ in coinciding_pairs(results, times_h, key)}
    colours = {}
    for i, (system, r) in enumerate(results.items()):
        label = (labels or {}).get(system, notes.get(system, r.label))
        (line,) = ax.plot(times_h, r.errors[key], label=label, linestyle=styles[i % len(styles)], linewidth=2.0 if i == 0 else 1.4)
        colours[system] = line.get_color()
    _paper_markers(ax, results, times_h, key, paper, colours)
    ax.set(title=title, xlabel="time since take-off (h)", ylabel=unit)
    ax.grid(True, alpha=0.3)


def _caption(results: Mapping[str, SystemResult], times_h, keys: Sequence[str], designs: Mapping[str, FilterDesign]) -> str:
    """Why the curves that coincide in these panels coincide (one line per pair of systems)."""
    found: dict[tuple[str, str], list[tuple[str, float, float]]] = {}
    for key in keys:
        for first, second, median, largest in coinciding_pairs(results, times_h, key):
            found.setdefault((first, second), []).append((key, median, largest))
    lines = []
    for (first, second), entries in found.items():
        why = design_difference(designs[first], designs[second]) if first in designs and second in designs else ""
        quantities = ", ".join(key.replace("_", " ") for key, _, _ in entries)
        median = max(m for _, m, _ in entries)
        largest = max(x for _, _, x in entries)
        lines.append(
            f"{results[second].label} lies on {results[first].label} ({quantities}; after 1 h the relative "
            f"difference is at most {100 * median:.2f} % in median, {100 * largest:.2f} % at worst)" + (f": {why}." if why else ".")
        )
    return "\n".join(lines)


def write_figures(
    results: Mapping[str, SystemResult],
    times_h,
    out_dir: str | Path,
    paper: PaperTable | None = None,
    designs: Sequence[FilterDesign] = (),
) -> list[Path]:
    """Write the Fig 2-7 analogues into ``out_dir``; returns their paths.

    ``paper`` (Table 2) adds the paper's 4-h values as markers; ``designs``
    lets the captions say what coinciding filters have in common.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    integ = {k: r for k, r in results.items() if k != PURE_INERTIAL}
    pure = {PURE_INERTIAL: results[PURE_INERTIAL]}
    by_key = {d.key: d for d in designs}
    paths = []

    def pure_series(ax, key: str, label: str) -> None:
        """One pure-inertial series, with the paper's 4-h value of it (if printed) as a marker of its colour."""
        (line,) = ax.plot(times_h, results[PURE_INERTIAL].errors[key], label=label, linewidth=1.6)
        _paper_markers(ax, pure, times_h, key, paper, {PURE_INERTIAL: line.get_color()})

    def pure_figure(name: str, panels: Sequence[tuple[str, str, Sequence[tuple[str, str]]]], caption: str) -> None:
        fig, axes = plt.subplots(1, len(panels), figsize=(10, 4.4))
        for ax, (title, unit, series) in zip(axes, panels):
            for key, label in series:
                pure_series(ax, key, label)
            ax.set(title=title, xlabel="time since take-off (h)", ylabel=unit)
            ax.grid(True, alpha=0.3)
            handles, labels = ax.get_legend_handles_labels()
            unique = dict(zip(labels, handles))
            ax.legend(unique.values(), unique.keys(), fontsize=8)
        paths.append(_save(fig, out / name, caption))

    pure_figure(
        "fig2_pure_inertial_attitude.png",
        [("Fig 2: pure inertial attitude errors", "arcsec (1 sigma)",
          [("attitude_error_north", "alpha (about north)"), ("attitude_error_east", "beta (about east)")]),
         ("Fig 2: pure inertial heading error", "deg (1 sigma)", [("heading_error", "gamma (about down)")])],
        "Markers: the paper's 4-h values (alpha, beta from Table 2; gamma from the text of section 3).",
    )
    pure_figure(
        "fig3_pure_inertial_velocity_position.png",
        [("Fig 3: pure inertial velocity errors", "nmile/h (1 sigma)",
          [("velocity_error_north", "dV_n"), ("velocity_error_east", "dV_e")]),
         ("Fig 3: pure inertial position error", "nmile",
          [("position_cep", "CEP"), ("position_error_north", "north (1 sigma)"), ("position_error_east", "east (1 sigma)")])],
        "Markers: the paper's 4-h values (dV_n, dV_e and CEP, Table 2).",
    )

    def integrated(name: str, panels: Sequence[tuple[str, str, str]], size: tuple[float, float]) -> None:
        fig, axes = plt.subplots(1, len(panels), figsize=size, squeeze=False)
        for ax, (key, title, unit) in zip(axes[0], panels):
            _panel(ax, integ, times_h, key, title, unit, paper)
            ax.legend(fontsize=7)
        caption = "\n".join(filter(None, ["Markers: the paper's Table 2 values at 4 h, in the colour of each filter.",
                                          _caption(integ, times_h, [k for k, _, _ in panels], by_key)]))
        paths.append(_save(fig, out / name, caption))

    integrated("fig4_integrated_attitude.png", [("attitude_error_north", "Fig 4: integrated, alpha", "arcsec (1 sigma)"),
                                                ("attitude_error_east", "Fig 4: integrated, beta", "arcsec (1 sigma)")], (11, 5))
    integrated("fig5_integrated_heading.png", [("heading_error", "Fig 5: integrated, heading error gamma", "deg (1 sigma)")], (7, 5))
    integrated("fig6_integrated_velocity.png", [("velocity_error_north", "Fig 6: integrated, dV_n", "nmile/h (1 sigma)"),
                                                ("velocity_error_east", "Fig 6: integrated, dV_e", "nmile/h (1 sigma)")], (11, 5))
    integrated("fig7_integrated_position.png", [("position_cep", "Fig 7: integrated, position error (CEP)", "nmile")], (7, 5))
    return paths
