"""The paper check: derived F, G, H against a paper's printed table.

For every (matrix, row, column) in the union of the paper's printed entries
and the derived nonzeros, the derived entry is converted to the paper's units
(F_paper(i,j) = F_SI(i,j) s_i / s_j, G_paper(i,k) = G_SI(i,k) s_i / n_k,
H_paper(m,j) = H_SI(m,j) r_m / s_j, factors from the table file), the unit
factor M is replaced by its value and the two sides are compared
symbolically.  Each entry gets a status (match, differ, paper_only,
derived_only); every non-match gets the classification and reason a human
wrote in the table file, or "unexplained" if there is none.  The model is
never bent to the paper: a difference is reported, not hidden.

A user's own table (``verify(derived, "my_table.yaml", complete=False)``)
is completed from the model (see :mod:`modelgen.checks.paper_table`) and only
the entries it lists are compared unless ``complete``.  Every unexplained
difference gets the automatic hints of :mod:`modelgen.checks.hints` (sign
flip, unit factor, transposed or misplaced entry, missing term); records that
have hints carry a ``hints`` field.

Public API (used by ``modelgen verify`` and ``modelgen run``)::

    result = verify(derived)                    # table found from derived.model.name
    write_verification_report(result, "report")  # report/verification.md + .json
"""

from __future__ import annotations

import json
import random
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import sympy as sp

from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.fileio.output import write_text_atomically
from modelgen.model.sources import cite_sources
from modelgen.checks.hints import difference_hints
from modelgen.checks.paper_table import (
    MATRICES,
    STATUSES,
    Annotation,
    Key,
    PaperEntry,
    PaperTable,
    load_paper_table,
    paper_table_path,
)

UNEXPLAINED = "unexplained"
#: Fields of every JSON record (documented in the report and in README).
RECORD_FIELDS = (
    "matrix",
    "row",
    "column",
    "row_quantity",
    "column_quantity",
    "printed",
    "printed_expression",
    "paper_expression",
    "derived_expression",
    "status",
    "classification",
    "reason",
    "reading",
)
_NUMERIC_POINTS = 3
_NUMERIC_DIGITS = 30
_NUMERIC_RELATIVE_ZERO = sp.Float("1e-20")


@dataclass(frozen=True)
class EntryComparison:
    """The comparison of one (matrix, row, column), 1-based as in the paper.

    ``printed`` is the OCR'd line the entry comes from, ``printed_expression``
    its transcription as printed (references such as ``-F(1,2)`` kept);
    ``paper_expression`` is what was compared (references resolved, reading
    applied) and ``derived_expression`` the derived entry, both in the
    paper's units with the unit factor (M) kept as a symbol; ``None`` where a
    side has no entry.  ``reading`` says which reading of a garbled print was
    used, and why.
    """

    matrix: str
    row: int
    column: int
    row_quantity: str
    column_quantity: str
    printed: str | None
    printed_expression: str | None
    paper_expression: str | None
    derived_expression: str | None
    status: str
    classification: str | None
    reason: str | None
    reading: str | None
    hints: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        return f"{self.matrix}({self.row},{self.column})"

    @property
    def is_difference(self) -> bool:
        return self.status != "match"

    @property
    def is_unexplained(self) -> bool:
        return self.classification == UNEXPLAINED

    def record(self) -> dict[str, Any]:
        """The entry as a JSON-ready dict: :data:`RECORD_FIELDS`, plus ``hints`` where there are any."""
        record = {name: getattr(self, name) for name in RECORD_FIELDS}
        if self.hints:
            record["hints"] = list(self.hints)
        return record


@dataclass(frozen=True)
class VerificationResult:
    """Everything the report says; built by :func:`verify`."""

    model: str
    source: str
    table: str  # table file name
    unit_symbol: str
    unit_value: str
    entries: tuple[EntryComparison, ...]
    equation_1_checks: tuple[EntryComparison, ...]
    units: tuple[tuple[str, str, str, str, str], ...]  # (kind, quantity, model unit, paper unit, factor)
    inconsistencies: tuple[str, ...]
    unused_annotations: tuple[str, ...] = field(default_factory=tuple)

    @property
    def differences(self) -> list[EntryComparison]:
        return [e for e in self.entries if e.is_difference]

    @property
    def unexplained(self) -> list[EntryComparison]:
        return [e for e in (*self.entries, *self.equation_1_checks) if e.is_unexplained]

    @property
    def readings(self) -> list[EntryComparison]:
        return [e for e in self.entries if e.reading]

    def counts(self) -> dict[str, int]:
        """Number of table entries per status (all four statuses present)."""
        return {s: sum(e.status == s for e in self.entries) for s in STATUSES}

    def classification_counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for e in (*self.entries, *self.equation_1_checks):
            if e.classification:
                out[e.classification] = out.get(e.classification, 0) + 1
        return dict(sorted(out.items()))

    def summary(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "source": self.source,
            "table": self.table,
            "unit_factor": f"{self.unit_symbol} = {self.unit_value}",
            "entries": len(self.entries),
            "counts": self.counts(),
            "classifications": self.classification_counts(),
            "unexplained": len(self.unexplained),
            "equation_1_checks": {s: sum(e.status == s for e in self.equation_1_checks) for s in STATUSES},
            "unused_annotations": list(self.unused_annotations),
        }

    def to_json(self) -> str:
        data = {
            "summary": self.summary(),
            "record_fields": list(RECORD_FIELDS),
            "entries": [e.record() for e in self.entries],
            "equation_1_checks": [e.record() for e in self.equation_1_checks],
            "units": [dict(zip(("kind", "quantity", "model_unit", "paper_unit", "factor"), u)) for u in self.units],
            "paper_inconsistencies": list(self.inconsistencies),
        }
        return json.dumps(data, indent=2, sort_keys=True, ensure_ascii=False) + "\n"

    def to_markdown(self) -> str:
        return _markdown(self)

    def __repr__(self) -> str:
        """One line: the model, the table and the counts (the full comparison is ``.entries``)."""
        counts = ", ".join(f"{n} {s}" for s, n in self.counts().items())
        return (f"<VerificationResult {self.model!r} against {self.table}: {len(self.entries)} entries, {counts}; "
                f"{len(self.unexplained)} unexplained>")

    def _repr_markdown_(self) -> str:
        """What a notebook shows: the report up to its differences (units and every entry: ``to_markdown()``)."""
        return self.to_markdown().split("\n## Entries the table omits", 1)[0].split("\n## Readings", 1)[0] \
            .split("\n## Units", 1)[0].rstrip() + "\n"


# -- the comparison -----------------------------------------------------------
def verify(derived: DerivedModel, table_path: str | Path | None = None, complete: bool = True) -> VerificationResult:
    """Compare ``derived`` with a paper's printed table of F, G, H entries.

    ``table_path`` defaults to the table written for ``derived.model.name``
    (see :func:`modelgen.checks.paper_table.paper_table_path`); a model without one
    is refused with a ModelError.  A table given by path is read as a user
    table, completed from the model.  ``complete`` also compares every derived
    nonzero the table does not list (as ``derived_only``); otherwise only the
    listed entries are compared.  Takes about a second for the 18-state model.
    """
    model = derived.model
    if table_path is None:
        table_path = paper_table_path(model.name)
        if table_path is None:
            raise ModelError(f"model {model.name!r}: no paper table in modelgen/data/ to verify it against")
        table = load_paper_table(table_path)
    else:
        table = load_paper_table(table_path, model)
    scale = _unit_scales(derived, table)
    quantities = _quantity_names(derived)
    value = {table.unit_symbol: table.unit_value}
    annotations = {(a.against, a.key, a.status): a for a in table.annotations}
    used: set[tuple[str, Key, str]] = set()

    def derived_in_paper_units(key: Key) -> sp.Expr:
        m, i, j = key
        entry = getattr(derived, m)[i - 1, j - 1]
        if entry == 0:
            return sp.S.Zero
        return entry * scale[m][0][i - 1] / scale[m][1][j - 1]

    def compare(key: Key, paper: PaperEntry | None, against: str) -> EntryComparison:
        derived_value = derived_in_paper_units(key)
        note = None
        if paper is None:
            status = "derived_only"
        elif derived_value == 0 and paper.value == 0:
            status = "match"  # a table may list an entry as 0
        elif derived_value == 0:
            status = "paper_only"
        else:
            equal, note = _equal(paper.value, derived_value, value)
            status = "match" if equal else "differ"
        classification = reason = None
        hints: tuple[str, ...] = ()
        if status != "match":
            annotation: Annotation | None = annotations.get((against, key, status))
            if annotation is not None:
                used.add((against, key, status))
                classification, reason = annotation.classification, annotation.reason
            else:
                classification = UNEXPLAINED
                reason = f"no annotation for this {status} in {table.name}" + (f" ({note})" if note else "")
                hints = _hints(key, paper, derived_value)
        m, i, j = key
        return EntryComparison(
            matrix=m,
            row=i,
            column=j,
            row_quantity=quantities[m][0][i - 1],
            column_quantity=quantities[m][1][j - 1],
            printed=paper.printed if paper else None,
            printed_expression=paper.expression if paper else None,
            paper_expression=sp.sstr(paper.value) if paper else None,
            derived_expression=sp.sstr(derived_value) if derived_value != 0 else None,
            status=status,
            classification=classification,
            reason=reason,
            reading=(f"printed {paper.expression!r} read as {paper.reading!r}: {paper.why}" if paper and paper.reading else None),
            hints=hints,
        )

    derived_entries: dict[Key, sp.Expr] = {}

    def _hints(key: Key, paper: PaperEntry | None, derived_value: sp.Expr) -> tuple[str, ...]:
        """The automatic hints of an unexplained difference, all in the paper's units with M as a number."""
        if not derived_entries:
            derived_entries.update({k: derived_in_paper_units(k).xreplace(value) for k in _derived_nonzeros(derived)})
        written = paper.value.xreplace(value) if paper else None
        found = difference_hints(written, derived_value.xreplace(value), key, derived_entries)
        return tuple(h.text for h in found)

    paper_entries = {e.key: e for e in table.entries}
    keys = set(paper_entries) | (_derived_nonzeros(derived) if complete else set())
    entries = tuple(compare(k, paper_entries.get(k), "table") for k in sorted(keys, key=_order))
    checks = tuple(
        compare(e.key, e, "equation_1")
        for e in sorted(table.equation_1_entries, key=lambda e: _order(e.key))
        if e.key not in paper_entries
    )
    unused = tuple(
        f"{a.against}: {a.label} {a.status} ({a.classification})"
        for a in table.annotations
        if (a.against, a.key, a.status) not in used
    )
    units = tuple(
        (kind, q.symbol, q.unit, u.paper_unit, sp.sstr(u.factor))
        for kind, quantities_, factors in (
            ("state", model.states, table.state_units),
            ("noise", model.noises, table.noise_units),
            ("measurement", model.measurements, table.measurement_units),
        )
        for q, u in zip(quantities_, factors)
    )
    return VerificationResult(
        model=model.name,
        source=table.source,
        table=table.name,
        unit_symbol=str(table.unit_symbol),
        unit_value=sp.sstr(table.unit_value),
        entries=entries,
        equation_1_checks=checks,
        units=units,
        inconsistencies=table.inconsistencies,
        unused_annotations=unused,
    )


def _order(key: Key) -> tuple[int, int, int]:
    return (MATRICES.index(key[0]), key[1], key[2])


def _derived_nonzeros(derived: DerivedModel) -> set[Key]:
    out = set()
    for m in MATRICES:
        matrix = getattr(derived, m)
        for i in range(matrix.shape[0]):
            for j in range(matrix.shape[1]):
                if matrix[i, j] != 0:
                    out.add((m, i + 1, j + 1))
    return out


def _unit_scales(derived: DerivedModel, table: PaperTable) -> dict[str, tuple[list[sp.Expr], list[sp.Expr]]]:
    """Row and column unit factors of F, G, H; refuses a model the table does not describe."""
    model = derived.model
    for kind, declared, listed in (
        ("states", [s.symbol for s in model.states], [u.quantity for u in table.state_units]),
        ("noises", [w.symbol for w in model.noises], [u.quantity for u in table.noise_units]),
        ("measurements", [m.symbol for m in model.measurements], [u.quantity for u in table.measurement_units]),
    ):
        if declared != listed:
            raise ModelError(
                f"{table.name}: the table's {kind} ({', '.join(listed)}) are not the {kind} of model "
                f"{model.name!r} ({', '.join(declared)}), in that order"
            )
    parameters = {p.symbol for p in model.parameters}
    missing = sorted(v for v in table.symbols.values() if v not in parameters)
    if missing:
        raise ModelError(f"{table.name}: paper symbol(s) map to {', '.join(missing)}, not parameters of model {model.name!r}")
    s = [u.factor for u in table.state_units]
    n = [u.factor for u in table.noise_units]
    r = [u.factor for u in table.measurement_units]
    return {"F": (s, s), "G": (s, n), "H": (r, s)}


def _quantity_names(derived: DerivedModel) -> dict[str, tuple[list[str], list[str]]]:
    m = derived.model
    states = [s.symbol for s in m.states]
    return {
        "F": (states, states),
        "G": (states, [w.symbol for w in m.noises]),
        "H": ([q.symbol for q in m.measurements], states),
    }


def _equal(paper: sp.Expr, derived: sp.Expr, unit_value: dict[sp.Symbol, sp.Expr]) -> tuple[bool, str | None]:
    """Whether two entries are the same function of the parameters.

    Fast path: the expanded difference is zero.  Otherwise the difference is
    evaluated at a few fixed pseudo-random points with 30 digits; a clearly
    nonzero value proves a difference.  A difference that vanishes at every
    point must also simplify to zero symbolically (trig identities such as
    sec^2 = 1 + tan^2) to count as a match; if sympy cannot show it, the
    entry is reported as differing with a note rather than called equal.
    """
    difference = sp.expand((paper - derived).xreplace(unit_value))
    if difference == 0:
        return True, None
    symbols = sorted(difference.free_symbols | paper.free_symbols | derived.free_symbols, key=lambda s: s.name)
    rng = random.Random(1985)  # fixed: the report must be identical run to run
    for _ in range(_NUMERIC_POINTS):
        point = {s: sp.Float(rng.uniform(0.3, 1.1), _NUMERIC_DIGITS) for s in symbols}
        gap = abs(difference.evalf(_NUMERIC_DIGITS, subs=point))
        size = abs(paper.xreplace(unit_value).evalf(_NUMERIC_DIGITS, subs=point)) + abs(derived.xreplace(unit_value).evalf(_NUMERIC_DIGITS, subs=point))
        if gap > _NUMERIC_RELATIVE_ZERO * size:
            return False, None
    if sp.simplify(sp.trigsimp(difference.rewrite(sp.cos))) == 0:
        return True, None
    return False, "numerically equal at test points but not shown equal symbolically"


# -- the report ---------------------------------------------------------------
def write_verification_report(result: VerificationResult, folder: str | Path) -> tuple[Path, Path]:
    """Write ``verification.md`` and ``verification.json`` into ``folder``.

    Both files are written atomically (temporary file, then rename) and are
    byte-identical from run to run (fixed order, no timestamps).  Returns the
    two paths.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    markdown = folder / "verification.md"
    data = folder / "verification.json"
    write_text_atomically(markdown, result.to_markdown())
    write_text_atomically(data, result.to_json())
    return markdown, data


def _cell(text: str | None, code: bool = True) -> str:
    if text is None or text == "":
        return "—"
    text = " ".join(str(text).split()).replace("|", "\\|")
    return f"`{text}`" if code else text


def _markdown(result: VerificationResult) -> str:
    counts = result.counts()
    lines = [
        f"# Paper check: model `{result.model}`",
        "",
        f"Derived F, G, H compared entry by entry with {cite_sources(result.source)} (transcribed in `{result.table}`).",
        f"Derived entries are converted to the paper's units; {result.unit_symbol} = {result.unit_value}"
        " (radians to arc-seconds) is substituted before the symbolic comparison.",
        "",
        "## Summary",
        "",
        "| status | entries |",
        "|---|---|",
        *[f"| {s} | {counts[s]} |" for s in STATUSES],
        f"| **total** | {len(result.entries)} |",
        "",
        f"Unexplained differences: **{len(result.unexplained)}**.",
    ]
    if result.classification_counts():
        lines += ["", "| classification | entries |", "|---|---|"]
        lines += [f"| {c} | {n} |" for c, n in result.classification_counts().items()]
    if result.unused_annotations:
        lines += ["", "Annotations in the table file that no longer match any difference:", ""]
        lines += [f"- {a}" for a in result.unused_annotations]

    lines += ["", "## Differences", ""]
    if result.differences:
        lines += ["| entry | status | classification | paper | derived | reason |", "|---|---|---|---|---|---|"]
        for e in result.differences:
            reason = e.reason if not e.hints else f"{e.reason}; hint: {'; '.join(e.hints)}"
            lines.append(
                f"| {e.label} | {e.status} | {_cell(e.classification, False)} | {_cell(e.paper_expression)} "
                f"| {_cell(e.derived_expression)} | {_cell(reason, False)} |"
            )
    else:
        lines.append("None.")

    if result.equation_1_checks:
        lines += [
            "",
            "## Entries the table omits, checked against the paper's eq. (1)",
            "",
            "| entry | status | classification | eq. (1) | derived | reason |",
            "|---|---|---|---|---|---|",
        ]
        for e in result.equation_1_checks:
            lines.append(
                f"| {e.label} | {e.status} | {_cell(e.classification, False)} | {_cell(e.paper_expression)} "
                f"| {_cell(e.derived_expression)} | {_cell(e.reason, False)} |"
            )

    if result.readings:
        lines += ["", "## Readings of garbled print", ""]
        lines += [f"- {e.label}: {_cell(e.reading, False)}" for e in result.readings]

    lines += [
        "",
        "## Units",
        "",
        "x_paper = s · x_SI; F_paper(i,j) = F_SI(i,j) s_i / s_j (G and H likewise with noise and measurement factors).",
        "",
        "| kind | quantity | model unit | paper unit | factor s |",
        "|---|---|---|---|---|",
        *[f"| {k} | {q} | {mu} | {pu} | {_cell(f)} |" for k, q, mu, pu, f in result.units],
    ]

    lines += [
        "",
        "## Every entry",
        "",
        "| entry | row | column | printed | paper (paper units) | derived (paper units) | status | classification |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for e in result.entries:
        lines.append(
            f"| {e.label} | {e.row_quantity} | {e.column_quantity} | {_cell(e.printed)} | {_cell(e.paper_expression)} "
            f"| {_cell(e.derived_expression)} | {e.status} | {_cell(e.classification, False)} |"
        )

    lines += ["", "## The paper's own inconsistencies", ""]
    lines += [f"{k}. {_cell(text, False)}" for k, text in enumerate(result.inconsistencies, 1)] or ["None listed."]
    lines += [
        "",
        "## JSON",
        "",
        "`verification.json` holds `summary`, `entries` and `equation_1_checks` (one record per entry with fields "
        + ", ".join(f"`{f}`" for f in RECORD_FIELDS)
        + "), `units` and `paper_inconsistencies`.",
        "",
    ]
    return "\n".join(lines)
