"""Analogues of the paper's Figs 2-7: error standard deviations over the 4-h run.

Fig 2: pure inertial attitude and heading errors; Fig 3: pure inertial
velocity and position errors; Figs 4-7: integrated systems (optimal and
suboptimal I-IV) attitude, heading, velocity and position (CEP) errors.

The paper prints numbers only for the end of the run (Table 2 and the text of
section 3), so those are overlaid as markers at 4 h, in the colour of their
system's curve.  Curves that lie on top of each other are named in the legend
with the measured difference.  Each figure's one-line caption
(:func:`figure_captions`, written beside the figure in table2.md and the run's
report) says what is drawn: the markers only where the paper prints a value,
and which curves coincide and what their designs have in common (computed from
the designs and the curves, not written per figure).
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


def _save(fig, path: Path) -> Path:
    """The figure laid out to its own contents (its caption is a line of the report, not a footnote) and saved."""
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


#: Figs 2-7: file, then per panel (quantity key, title, unit, series label or None for the system's own),
#: whether the figure shows the pure-inertial system alone, its size, its y scale and what its caption says it shows
FIGURES: tuple[tuple[str, tuple[tuple[str, str, str, str | None], ...], bool, tuple[float, float], str, str], ...] = (
    ("fig2_pure_inertial_attitude.png",
     (("attitude_error_north", "Fig 2: pure inertial attitude errors", "arcsec (1 sigma)", "alpha (about north)"),
      ("attitude_error_east", "Fig 2: pure inertial attitude errors", "arcsec (1 sigma)", "beta (about east)"),
      ("heading_error", "Fig 2: pure inertial heading error", "deg (1 sigma)", "gamma (about down)")),
     True, (10, 4.4), "linear", "pure-inertial 1-sigma attitude errors alpha, beta (arcsec) and heading error gamma (deg)"),
    ("fig3_pure_inertial_velocity_position.png",
     (("velocity_error_north", "Fig 3: pure inertial velocity errors", "nmile/h (1 sigma)", "dV_n"),
      ("velocity_error_east", "Fig 3: pure inertial velocity errors", "nmile/h (1 sigma)", "dV_e"),
      ("position_cep", "Fig 3: pure inertial position error", "nmile", "CEP"),
      ("position_error_north", "Fig 3: pure inertial position error", "nmile", "north (1 sigma)"),
      ("position_error_east", "Fig 3: pure inertial position error", "nmile", "east (1 sigma)")),
     True, (10, 4.4), "linear", "pure-inertial 1-sigma velocity errors (nmile/h) and position error (CEP, 1-sigma north and east; nmile)"),
    ("fig4_integrated_attitude.png",
     (("attitude_error_north", "Fig 4: integrated, alpha", "arcsec (1 sigma, log scale)", None),
      ("attitude_error_east", "Fig 4: integrated, beta", "arcsec (1 sigma, log scale)", None)),
     False, (11, 4.4), "log", "1-sigma attitude errors alpha and beta (arcsec) of the optimal and suboptimal I-IV filters"),
    ("fig5_integrated_heading.png",
     (("heading_error", "Fig 5: integrated, heading error gamma", "deg (1 sigma)", None),),
     False, (7, 4.4), "linear", "1-sigma heading error gamma (deg) of the optimal and suboptimal I-IV filters"),
    ("fig6_integrated_velocity.png",
     (("velocity_error_north", "Fig 6: integrated, dV_n", "nmile/h (1 sigma)", None),
      ("velocity_error_east", "Fig 6: integrated, dV_e", "nmile/h (1 sigma)", None)),
     False, (11, 4.4), "linear", "1-sigma velocity errors dV_n, dV_e (nmile/h) of the optimal and suboptimal I-IV filters"),
    ("fig7_integrated_position.png",
     (("position_cep", "Fig 7: integrated, position error (CEP)", "nmile", None),),
     False, (7, 4.4), "linear", "position error (CEP, nmile) of the optimal and suboptimal I-IV filters"),
)


def _panels(spec) -> list[tuple[str, str, list[tuple[str, str | None]]]]:
    """A figure's panels: (title, unit, [(key, label)]), series with the same title sharing a panel."""
    panels: dict[str, tuple[str, str, list[tuple[str, str | None]]]] = {}
    for key, title, unit, label in spec:
        panels.setdefault(title, (title, unit, []))[2].append((key, label))
    return list(panels.values())


def _drawn_markers(systems: Sequence[str], keys: Sequence[str], paper: PaperTable | None) -> list[str]:
    """The keys of which the paper prints a 4-h value for at least one of ``systems`` (those get markers)."""
    if paper is None:
        return []
    return [k for k in keys if any(paper.values.get(s, {}).get(k) is not None for s in systems)]


def _clusters(results: Mapping[str, SystemResult], times_h, keys: Sequence[str]) -> list[tuple[list[str], float]]:
    """Groups of systems whose curves coincide in every one of ``keys`` (joined pairwise), with the largest
    median relative difference after the first hour among the pairs joined."""
    groups: list[set[str]] = []
    worst: dict[frozenset[str], float] = {}
    pairs = None
    for key in keys:
        found = {(a, b): med for a, b, med, _ in coinciding_pairs(results, times_h, key)}
        pairs = found if pairs is None else {p: max(m, found[p]) for p, m in pairs.items() if p in found}
    for (a, b), median in (pairs or {}).items():
        joined = [g for g in groups if a in g or b in g]
        merged = set().union(*joined, {a, b})
        groups = [g for g in groups if g not in joined] + [merged]
        worst[frozenset(merged)] = max([median, *(worst.pop(frozenset(g), 0.0) for g in joined)])
    order = list(results)
    return [(sorted(g, key=order.index), worst[frozenset(g)]) for g in sorted(groups, key=lambda g: order.index(min(g, key=order.index)))]


def _coincidence_clause(results, times_h, keys, designs: Mapping[str, FilterDesign]) -> str:
    """'sub II lies on optimal (same filter model, another gain schedule; ...)': the curves one cannot tell apart."""
    parts = []
    for members, median in _clusters(results, times_h, keys):
        labels = [results[m].label for m in members]
        gains_only = all(
            a in designs and b in designs and design_difference(designs[a], designs[b]).startswith("same filter model")
            for i, a in enumerate(members) for b in members[i + 1:])
        why = "same filter model, another gain schedule; " if gains_only else ""
        names = labels[1] if len(labels) == 2 else ", ".join(labels[1:-1]) + " and " + labels[-1]
        parts.append(f"{names} {'lies' if len(labels) == 2 else 'lie'} on {labels[0]} ({why}median difference after "
                     f"1 h at most {100 * median:.2g} %)")
    return "; ".join(parts)


def figure_captions(
    results: Mapping[str, SystemResult],
    times_h,
    paper: PaperTable | None = None,
    designs: Sequence[FilterDesign] = (),
) -> dict[str, str]:
    """One line per figure of :func:`write_figures` (file name -> caption): what it shows, the markers where
    the paper prints a value (and only then), and which curves lie on which."""
    by_key = {d.key: d for d in designs}
    integ = {k: r for k, r in results.items() if k != PURE_INERTIAL}
    captions = {}
    for name, spec, pure, _, _, shows in FIGURES:
        keys = [key for key, *_ in spec]
        systems = [PURE_INERTIAL] if pure else list(integ)
        marked = _drawn_markers(systems, keys, paper)
        text = f"{name.split('_')[0].replace('fig', 'Fig ')} analogue: {shows} over the 4-h flight"
        if marked:
            where = "the text of section 3" if pure and "heading_error" in marked else "Table 2"
            labels = {key: (label or key.replace("_", " ")) for key, _, _, label in spec}
            what = "" if len(marked) == len(keys) else " of " + ", ".join(labels[k] for k in marked)
            text += f"; diamonds: the paper's 4-h values{what} ({'Table 2 and ' + where if where != 'Table 2' else where})"
        else:
            text += "; the paper prints no 4-h value of it, so no marker is drawn"
        together = "" if pure else _coincidence_clause(integ, times_h, keys, by_key)
        captions[name] = text + (f"; {together}" if together else "") + "."
    return captions


def write_figures(
    results: Mapping[str, SystemResult],
    times_h,
    out_dir: str | Path,
    paper: PaperTable | None = None,
    designs: Sequence[FilterDesign] = (),
) -> list[Path]:
    """Write the Fig 2-7 analogues into ``out_dir``; returns their paths (their captions: :func:`figure_captions`).

    ``paper`` (Table 2) adds the paper's 4-h values as markers.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    integ = {k: r for k, r in results.items() if k != PURE_INERTIAL}
    pure = {PURE_INERTIAL: results[PURE_INERTIAL]}
    paths = []
    for name, spec, pure_only, size, scale, _ in FIGURES:
        panels = _panels(spec)
        fig, axes = plt.subplots(1, len(panels), figsize=size, squeeze=False)
        for ax, (title, unit, series) in zip(axes[0], panels):
            if pure_only:
                for key, label in series:
                    (line,) = ax.plot(times_h, results[PURE_INERTIAL].errors[key], label=label, linewidth=1.6)
                    _paper_markers(ax, pure, times_h, key, paper, {PURE_INERTIAL: line.get_color()})
                ax.set(title=title, xlabel="time since take-off (h)", ylabel=unit)
                ax.grid(True, alpha=0.3)
            else:
                (key, _), = series
                _panel(ax, integ, times_h, key, title, unit, paper)
            ax.set_yscale(scale)
            if scale == "log":  # plain numbers at every tick (30, 40, ... 100), not 3 x 10^1
                from matplotlib.ticker import ScalarFormatter

                ax.yaxis.set_major_formatter(ScalarFormatter())
                ax.yaxis.set_minor_formatter(ScalarFormatter())
            handles, labels = ax.get_legend_handles_labels()
            unique = dict(zip(labels, handles))
            ax.legend(unique.values(), unique.keys(), fontsize=8 if pure_only else 7)
        paths.append(_save(fig, out / name))
    return paths
