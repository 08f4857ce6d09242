"""Our Table 2 beside the paper's: values, ratios ours/paper, improvement ratios.

The paper's numbers (``paper_000_table2.yaml``) are only printed beside ours
and divided into them; nothing here feeds them back into a result.
Improvement ratio, as the paper's note defines it:
(pure-inertial error - integrated error) / pure-inertial error.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

from modelgen.fileio.datafiles import data_path, read_yaml, require
from modelgen.table2.systems import PURE_INERTIAL, SystemResult
from modelgen.table2.metrics import final_values
from modelgen.errors import ModelError

PAPER_TABLE_FILE = "paper_000_table2.yaml"


@dataclass(frozen=True)
class Column:
    key: str
    header: str
    unit: str
    decimals: int


#: Table 2's columns, then two the paper gives only in its text.
COLUMNS: tuple[Column, ...] = (
    Column("attitude_error_north", "alpha", "arcsec", 2),
    Column("attitude_error_east", "beta", "arcsec", 2),
    Column("velocity_error_north", "dV_n", "nmile/h", 3),
    Column("velocity_error_east", "dV_e", "nmile/h", 3),
    Column("position_cep", "CEP", "nmile", 2),
    Column("doppler_bias_error_north", "dV_dn", "nmile/h", 3),
    Column("doppler_bias_error_east", "dV_de", "nmile/h", 3),
    Column("heading_error", "gamma", "deg", 3),
    Column("average_drift_rate", "drift", "nmile/h", 3),
)
IMPROVEMENT_COLUMNS = ("attitude_error_north", "attitude_error_east", "velocity_error_north", "velocity_error_east", "position_cep")


@dataclass(frozen=True)
class PaperTable:
    labels: dict[str, str]
    values: dict[str, dict[str, float]]
    improvement: dict[str, dict[str, float]]


def load_paper_table(path: str | Path | None = None) -> PaperTable:
    """The paper's Table 2 (and the pure-inertial numbers of its text)."""
    path = Path(path) if path is not None else data_path(PAPER_TABLE_FILE)
    data = read_yaml(path)
    systems = require(data, "systems", str(path))
    labels, values, improvement = {}, {}, {}
    for key, entry in systems.items():
        where = f"{path}: systems.{key}"
        labels[key] = str(require(entry, "label", where))
        values[key] = {k: float(v) for k, v in require(entry, "values", where).items()}
        improvement[key] = {k: float(v) for k, v in entry.get("improvement", {}).items()}
        unknown = sorted(set(values[key]) - {c.key for c in COLUMNS})
        if unknown:
            raise ModelError(f"{where}: unknown column(s) {', '.join(unknown)}")
    return PaperTable(labels, values, improvement)


@dataclass(frozen=True)
class Row:
    """One system: our final values, the paper's, ratios and improvement ratios."""

    key: str
    label: str
    filter_states: int
    ours: dict[str, float]
    paper: dict[str, float]
    improvement_ours: dict[str, float]
    improvement_paper: dict[str, float]

    def ratio(self, column: str) -> float | None:
        """ours / paper for a cell both have, else None."""
        if column in self.ours and column in self.paper and self.paper[column] != 0:
            return self.ours[column] / self.paper[column]
        return None


def table_rows(results: Mapping[str, SystemResult], paper: PaperTable) -> list[Row]:
    """Rows in the order of ``results`` (the paper's: optimal ... sub IV, pure inertial)."""
    pure = final_values(results[PURE_INERTIAL].errors)
    rows = []
    for key, result in results.items():
        ours = {c.key: v for c, v in ((c, final_values(result.errors).get(c.key)) for c in COLUMNS) if v is not None}
        improvement = {}
        if key != PURE_INERTIAL:
            improvement = {c: (pure[c] - ours[c]) / pure[c] for c in IMPROVEMENT_COLUMNS}
        rows.append(
            Row(
                key=key,
                label=result.label,
                filter_states=result.filter_states,
                ours=ours,
                paper=paper.values.get(key, {}),
                improvement_ours=improvement,
                improvement_paper=paper.improvement.get(key, {}),
            )
        )
    return rows


def _cell(value: float | None, decimals: int) -> str:
    return "-" if value is None else f"{value:.{decimals}f}"


def markdown_table(rows: Sequence[Row]) -> str:
    """Table 2 analogue: for each system, lines ours / paper / ours:paper."""
    head = "| system | | " + " | ".join(f"{c.header} ({c.unit})" for c in COLUMNS) + " |"
    rule = "|---|---|" + "---:|" * len(COLUMNS)
    lines = [head, rule]
    for row in rows:
        states = f", {row.filter_states} states" if row.filter_states else ""
        lines.append(f"| {row.label}{states} | ours | " + " | ".join(_cell(row.ours.get(c.key), c.decimals) for c in COLUMNS) + " |")
        lines.append("| | paper | " + " | ".join(_cell(row.paper.get(c.key), c.decimals) for c in COLUMNS) + " |")
        lines.append("| | ours/paper | " + " | ".join(_cell(row.ratio(c.key), 2) for c in COLUMNS) + " |")
    return "\n".join(lines)


def markdown_improvement(rows: Sequence[Row]) -> str:
    """Improvement ratios (pure - integrated) / pure, ours and the paper's, in %."""
    cols = [c for c in COLUMNS if c.key in IMPROVEMENT_COLUMNS]
    lines = [
        "| system | | " + " | ".join(c.header for c in cols) + " |",
        "|---|---|" + "---:|" * len(cols),
    ]
    for row in rows:
        if not row.improvement_ours:
            continue
        lines.append(f"| {row.label} | ours | " + " | ".join(f"{100 * row.improvement_ours[c.key]:.1f}%" for c in cols) + " |")
        paper = [row.improvement_paper.get(c.key) for c in cols]
        lines.append("| | paper | " + " | ".join("-" if v is None else f"{100 * v:.1f}%" for v in paper) + " |")
    return "\n".join(lines)


def csv_text(rows: Sequence[Row]) -> str:
    """Long-format CSV: one line per system and quantity."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["system", "label", "filter_states", "quantity", "unit", "ours", "paper", "ours_over_paper", "improvement_ours", "improvement_paper"])
    for row in rows:
        for c in COLUMNS:
            if c.key not in row.ours:
                continue
            ratio = row.ratio(c.key)
            writer.writerow(
                [
                    row.key,
                    row.label,
                    row.filter_states,
                    c.key,
                    c.unit,
                    f"{row.ours[c.key]:.6g}",
                    "" if c.key not in row.paper else f"{row.paper[c.key]:.6g}",
                    "" if ratio is None else f"{ratio:.4f}",
                    "" if c.key not in row.improvement_ours else f"{row.improvement_ours[c.key]:.4f}",
                    "" if c.key not in row.improvement_paper else f"{row.improvement_paper[c.key]:.4f}",
                ]
            )
    return buf.getvalue()
