"""A trade study's outputs: the table (CSV, Parquet), figures and a Markdown summary.

The table has one row per case: the parameters' values (their units in the
column names), the filter, and the final value of every reported error in
the paper's units (``position_cep_nmile``...).  CSV is always written;
Parquet is written with pyarrow (``pip install 'modelgen-nav[parquet]'``; the
test extra installs it) and, without it, the summary says so rather than
failing the study: pyarrow is large, and the core install stays light.

The figure puts the study's metric against its ``plot.x`` parameter, one line
per filter, one panel per value of the next parameter (at most four, spread
over its values), with both axes' units.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from modelgen.study.studyfile import METRICS, Study
from modelgen.study.trade import CaseResult, TradeResult

#: Panels of the figure, at most.
MAX_PANELS = 4


def column_name(name: str, unit: str) -> str:
    """``gyro_drift`` in ``deg/h`` -> ``gyro_drift_deg_per_h`` (a column name that says its unit)."""
    return f"{name}_{unit.replace('/', '_per_').replace('^', '').replace(' ', '_')}"


def table_columns(study: Study) -> list[str]:
    """Column names of the case table, in order."""
    return ([column_name(p.name, p.unit) for p in study.parameters] + ["filter", "label", "filter_states"]
            + [column_name(m, u) for m, u in METRICS])


def table_rows(result: TradeResult) -> list[list]:
    """One row per case, values in the order of :func:`table_columns` (missing metrics as NaN)."""
    return [[*c.point, c.filter, c.label, c.filter_states, *(c.final.get(m, math.nan) for m, _ in METRICS)]
            for c in result.cases]


def csv_text(result: TradeResult) -> str:
    """The case table as CSV (numbers with 10 significant digits)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(table_columns(result.study))
    for row in table_rows(result):
        writer.writerow([f"{v:.10g}" if isinstance(v, float) else v for v in row])
    return buffer.getvalue()


def write_parquet(result: TradeResult, path: Path) -> Path | None:
    """The case table as Parquet (pyarrow); None when pyarrow is not installed."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    columns = table_columns(result.study)
    rows = table_rows(result)
    table = pa.table({name: [row[i] for row in rows] for i, name in enumerate(columns)})
    pq.write_table(table, path)
    return path


def monte_carlo_csv(result: TradeResult) -> str:
    """Each Monte Carlo case: per state, ensemble rms and mean filter sigma at the end (SI), their ratio, NEES."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    study = result.study
    writer.writerow([column_name(p.name, p.unit) for p in study.parameters]
                    + ["runs", "state", "ensemble_rms_at_end_si", "filter_sigma_at_end_si", "ratio",
                       "nees_fraction_inside_95"])
    for case in result.monte_carlo:
        mc = case.result
        rms, sigma = mc.ensemble_rms()[-1], mc.mean_sigma()[-1]
        inside = mc.nees_test(0.95, start_time=mc.times[1] if len(mc.times) > 1 else 0.0).fraction_inside
        for i, state in enumerate(mc.state_names):
            ratio = rms[i] / sigma[i] if sigma[i] > 0 else math.nan
            writer.writerow([f"{v:.10g}" for v in case.point]
                            + [mc.runs, state, f"{rms[i]:.6g}", f"{sigma[i]:.6g}", f"{ratio:.4f}", f"{inside:.4f}"])
    return buffer.getvalue()


def panel_values(values: Sequence[float], count: int = MAX_PANELS) -> list[float]:
    """Up to ``count`` of ``values`` (distinct, sorted), spread evenly from the smallest to the largest."""
    distinct = sorted(set(values))
    if len(distinct) <= count:
        return distinct
    return [distinct[int(round(i))] for i in np.linspace(0, len(distinct) - 1, count)]


def _metric_unit(metric: str) -> str:
    return dict(METRICS)[metric]


def plot_metric(result: TradeResult, path: Path) -> Path:
    """The study's metric against ``plot.x``, one line per filter, a panel per value of the next parameter.

    Parameters other than these two are held at their first value in the table.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    study = result.study
    names = [p.name for p in study.parameters]
    ix = names.index(study.plot_x)
    others = [i for i in range(len(names)) if i != ix]
    panel_index = others[0] if others else None
    panels = panel_values([c.point[panel_index] for c in result.cases]) if panel_index is not None else [None]
    held = {i: result.cases[0].point[i] for i in others[1:]}
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels) + 1.5, 4.2), squeeze=False, sharey=True)
    x_parameter = study.parameters[ix]
    for ax, value in zip(axes[0], panels):
        for choice in study.filters:
            chosen = [c for c in result.cases if c.filter == choice.name
                      and (value is None or c.point[panel_index] == value)
                      and all(c.point[i] == v for i, v in held.items())]
            chosen.sort(key=lambda c: c.point[ix])
            xs = [c.point[ix] for c in chosen]
            ys = [c.final.get(study.metric, math.nan) for c in chosen]
            ax.plot(xs, ys, marker="o", ms=3, label=chosen[0].label if chosen else choice.name)
        if x_parameter.log_spaced:
            ax.set_xscale("log")
        ax.set_xlabel(f"{x_parameter.name} [{x_parameter.unit}]")
        if value is not None:
            p = study.parameters[panel_index]
            ax.set_title(f"{p.name} = {value:.4g} {p.unit}", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
    hours = study.scenario.duration_s / 3600
    axes[0][0].set_ylabel(f"{study.metric} at {hours:g} h [{_metric_unit(study.metric)}]")
    axes[0][-1].legend(fontsize=7)
    held_text = ", ".join(f"{names[i]} = {v:.4g} {study.parameters[i].unit}" for i, v in held.items())
    fig.suptitle(f"Trade study {study.name}: {study.metric} at {hours:g} h against {x_parameter.name}"
                 + (f" ({held_text})" if held_text else ""), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def best_filters(cases: Sequence[CaseResult], metric: str) -> dict[str, int]:
    """How many points each filter is best at (smallest metric)."""
    by_point: dict[tuple, CaseResult] = {}
    for c in cases:
        value = c.final.get(metric, math.nan)
        if math.isnan(value):
            continue
        best = by_point.get(c.point)
        if best is None or value < best.final[metric]:
            by_point[c.point] = c
    counts: dict[str, int] = {}
    for c in by_point.values():
        counts[c.filter] = counts.get(c.filter, 0) + 1
    return counts


def summary_markdown(result: TradeResult, files: Sequence[Path], parquet_written: bool) -> str:
    """What was computed, where, how long; the metric's range per filter; the figures and tables."""
    study = result.study
    unit = _metric_unit(study.metric)
    lines = [
        f"# Trade study: {study.title}",
        "",
        f"Study `{study.name}` ({study.source_file}): truth model `{study.model.name}`, scenario "
        f"`{study.scenario.name}`, budget `{study.budget.name}`.  {len(study.points)} points x "
        f"{len(study.filters)} filters = {study.case_count} covariance cases in {result.covariance_seconds:.1f} s "
        f"(the whole study {result.seconds:.1f} s) on {result.where}.",
        "",
        "Parameters: " + "; ".join(f"`{p.name}` [{p.unit}] sets {', '.join(p.sets)}" for p in study.parameters) + ".",
        "",
        f"| filter | states | min {study.metric} [{unit}] | max {study.metric} [{unit}] | best at points |",
        "|---|---:|---:|---:|---:|",
    ]
    best = best_filters(result.cases, study.metric)
    for choice in study.filters:
        values = np.array([c.final.get(study.metric, math.nan) for c in result.cases if c.filter == choice.name])
        states = next(c.filter_states for c in result.cases if c.filter == choice.name)
        lines.append(f"| {choice.name} | {states} | {np.nanmin(values):.4g} | {np.nanmax(values):.4g} | "
                     f"{best.get(choice.name, 0)} |")
    lines.append("")
    if result.monte_carlo:
        lines += ["## Monte Carlo", "", "| case | runs | NEES inside 95 % band | seconds |", "|---|---:|---:|---:|"]
        for case in result.monte_carlo:
            mc = case.result
            inside = mc.nees_test(0.95, start_time=mc.times[1] if len(mc.times) > 1 else 0.0).fraction_inside
            text = ", ".join(f"{p.name} = {v:g} {p.unit}" for p, v in zip(study.parameters, case.point))
            lines.append(f"| {text} | {mc.runs} | {100 * inside:.0f} % | {mc.seconds:.1f} |")
        lines.append("")
    if not parquet_written:
        lines += ["Parquet table not written: pyarrow is not installed (`pip install 'modelgen-nav[parquet]'`).", ""]
    lines += ["## Files", ""] + [f"- [{p.name}]({p.name})" for p in files] + [""]
    return "\n".join(lines)


def write_outputs(result: TradeResult, folder: Path) -> list[Path]:
    """Write trade.csv, trade.parquet (with pyarrow), monte_carlo.csv (if any), the figure and summary.md."""
    folder = Path(folder)
    files = []
    table = folder / "trade.csv"
    table.write_text(csv_text(result), encoding="utf-8")
    files.append(table)
    parquet = write_parquet(result, folder / "trade.parquet")
    if parquet is not None:
        files.append(parquet)
    if result.monte_carlo:
        mc = folder / "monte_carlo.csv"
        mc.write_text(monte_carlo_csv(result), encoding="utf-8")
        files.append(mc)
    files.append(plot_metric(result, folder / f"{result.study.metric}_vs_{result.study.plot_x}.png"))
    summary = folder / "summary.md"
    summary.write_text(summary_markdown(result, files, parquet is not None), encoding="utf-8")
    return [summary, *files]
