"""The twins in a run: every hand-written model against its twin, and the paper from first principles.

Composes :mod:`modelgen.checks.crosscheck` (each pair of
``modelgen/data/crosscheck.yaml``) and :mod:`modelgen.checks.paper_equations`
(the transcribed paper equations against the twin they name) into the files
``modelgen run`` writes beside its report and the report's section on them.
Models are obtained through the caller's ``derived_of`` (the run derives each
model once) and the engine's neglected terms through ``neglected_of``.

A pair whose twin file is missing is an error, not a skip: the run fails
loudly rather than reporting fewer pairs than the data lists.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from modelgen.checks.crosscheck import (
    STATUSES,
    CrossCheckResult,
    NeglectedTerm,
    cross_check,
    load_pairs,
    write_crosscheck_report,
)
from modelgen.checks.paper_equations import (
    PaperEquationsResult,
    differences_summary,
    paper_equations_check,
    paper_equations_path,
    write_paper_equations_report,
)
from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import read_yaml
from modelgen.model.loading import builtin_model_path

DerivedOf = Callable[[str], DerivedModel]
NeglectedOf = Callable[[str], Sequence[NeglectedTerm]]


def engine_neglected_terms(model_name: str) -> Sequence[NeglectedTerm]:
    """The terms the derivation engine's declared approximations dropped from a twin loaded in this process."""
    from modelgen.model.loading import load_model

    return load_model(model_name).neglected  # carried on the model (run_twin_checks uses the derived twin's own)


@dataclass(frozen=True)
class TwinChecks:
    """What the twins showed: one cross-check per pair and the paper's first-principles check."""

    crosschecks: tuple[CrossCheckResult, ...]
    paper: PaperEquationsResult | None

    @property
    def unexplained(self) -> int:
        return sum(len(r.unexplained) for r in self.crosschecks)


def require_twin(name: str) -> None:
    """Refuse a pair whose twin is not a built-in model (the data lists it: it must exist)."""
    if builtin_model_path(name) is None:
        raise ModelError(f"cross-check pair names twin {name!r}, but modelgen/models/{name}.yaml does not exist")


def run_twin_checks(derived_of: DerivedOf, neglected_of: NeglectedOf = engine_neglected_terms, paper_model: str | None = None) -> TwinChecks:
    """Cross-check every pair, and check the paper whose equations file names ``paper_model`` against its twin."""
    results = []
    for pair in load_pairs():
        require_twin(pair.twin)
        twin = derived_of(pair.twin)
        neglected = twin.model.neglected if neglected_of is engine_neglected_terms else neglected_of(pair.twin)  # carried on the model
        results.append(cross_check(pair, derived_of(pair.hand), twin, neglected))
    paper = first_principles_check(paper_model, derived_of) if paper_model else None
    return TwinChecks(tuple(results), paper)


def first_principles_check(model_name: str, derived_of: DerivedOf) -> PaperEquationsResult | None:
    """The paper check from first principles for the paper model ``model_name`` (None: no transcription names it)."""
    path = paper_equations_path(model_name)
    if path is None:
        return None
    twin_name = str(read_yaml(path, "paper-equations file").get("twin"))
    require_twin(twin_name)
    return paper_equations_check(derived_of(twin_name), path)


def write_twin_reports(checks: TwinChecks, folder: Path) -> list[Path]:
    """crosscheck.md/.json and (if the paper was checked) paper_equations.md/.json into ``folder``."""
    written = list(write_crosscheck_report(checks.crosschecks, folder))
    if checks.paper is not None:
        written += write_paper_equations_report(checks.paper, folder)
    return written


def report_section(checks: TwinChecks) -> str:
    """The run report's section: counts per pair, the paper's differences with their classification, links."""
    lines = [
        "## Hand-written models against their twins derived from the navigation equations",
        "",
        "Each entry of F, G, H compared with the twin's full first-order linearization; a difference is a declared "
        "approximation (with its size), a stated convention or a hand-model error, else unexplained.",
        "",
        "| model | twin | " + " | ".join(STATUSES) + " |",
        "|---|---|" + "---|" * len(STATUSES),
    ]
    for r in checks.crosschecks:
        counts = r.counts()
        lines.append(f"| {r.hand} | {r.twin} | " + " | ".join(str(counts[s]) for s in STATUSES) + " |")
    lines += ["", f"Unexplained: **{checks.unexplained}**. Every entry: [crosscheck.md](crosscheck.md), [crosscheck.json](crosscheck.json)."]
    if checks.paper is not None:
        p = checks.paper
        counts = p.classification_counts()
        lines += [
            "",
            "## The paper from first principles (eqs. (1)-(6))",
            "",
            f"The paper's equations, transcribed term by term, against `{p.twin}` (derived from the navigation equations "
            f"under the paper's assumptions): {p.compared} entries compared, {len(p.differences)} differ ("
            + ", ".join(f"{n} {c}" for c, n in counts.items() if n) + "). Each difference, found by the comparison and "
            "classified by rule:",
            "",
            *[f"- {line}" for line in differences_summary(p)],
            "",
            "Details: [paper_equations.md](paper_equations.md), [paper_equations.json](paper_equations.json).",
        ]
    return "\n".join(lines)
