"""The main job's report (``modelgen run``), section by section.

Each step of the main job hands back a :class:`ReportSection`: its Markdown,
the targets it measured (met, missed, or informative) and its figures with
their captions.  :func:`run_report` opens the report with every section's
targets, so a missed one cannot hide in a section's text, and
:func:`missed_targets` reads them back for the command's exit status.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from modelgen.model.sources import cite_sources

if TYPE_CHECKING:
    from modelgen.checks.mechanizations import MechanizationChecks
    from modelgen.checks.paper_check import VerificationResult


@dataclass(frozen=True)
class ReportSection:
    """One section of the main job's report: its Markdown, the targets it states and the figures it shows.

    Each target is a mapping with ``quantity``, ``reached``, ``target`` and
    ``met`` (True, False, or None for a row that only informs), as the step
    that measured it states it (the replay's come from its summary); the
    report lists them all at its top, and ``modelgen run`` does not say ok
    while one is missed.  ``figures`` maps a path relative to the report to
    the figure's one-line caption.
    """

    title: str
    text: str
    targets: tuple[dict, ...] = ()
    figures: tuple[tuple[str, str], ...] = ()

    def markdown(self) -> str:
        lines = [f"## {self.title}", "", self.text.rstrip()]
        for path, caption in self.figures:
            lines += ["", f"![{Path(path).stem}]({path})", "", caption]
        return "\n".join(lines)


#: how the report names each implementation that a check runs (others by their own name)
IMPLEMENTATION_NAMES = {"python": "Python", "c": "C", "cpp": "C++"}


def conformance_section(runs: list, out_root: Path) -> ReportSection:
    """The generated code's check: every model's differences from the reference beside the tolerance that bounds them.

    ``runs`` are the main job's :class:`modelgen.jobs.ModelRun` objects (each model's generation and checks).

    One pair of columns (scaled dP, scaled dx) per implementation the checks ran (Python, C, and C++ where a C++
    compiler is there), all bounded by the run's tolerance."""
    order = list(IMPLEMENTATION_NAMES)
    implementations = sorted({r.implementation for run in runs for r in run.checks},
                             key=lambda name: (order.index(name) if name in order else len(order), name))
    names = [IMPLEMENTATION_NAMES.get(name, name) for name in implementations]
    bounded = f"the {2 * len(names)} scaled columns"
    text = [
        f"Check: the generated {', '.join(names[:-1])} and {names[-1]} " if len(names) > 1 else f"Check: the generated {''.join(names)} ",
    ]
    text[0] += (
        "(the C compiled with "
        "`-std=c99 -Wall -Wextra -Werror -pedantic`) run beside `modelgen.derivation.reference` over each model's "
        "check scenario (the `check:` section of its file: a physical operating point, realistic sensor "
        "noise, the source's filter step; `ned_doppler18` flies the paper's 240 steps of 60 s). "
        "'scaled dP' is max |dP_ij| / sqrt(P_ii P_jj) and 'scaled dx' max |dx_i| / sqrt(P_ii) over all steps. "
        f"The tolerance bounds {bounded}: the verdict is ok when each of them is below it (and P stays "
        "symmetric positive definite). It is computed per run from the run's conditioning: 2 (2n + 1) u sum_k rho_k, "
        "with u = 2^-53 and rho_k the factor by which step k's arithmetic can magnify a rounding "
        "(`modelgen.checks.code_check.conformance_tolerance`). 'C elementwise dP', max |dP_ij| / |P_ij|, is shown for "
        "information and bounded by nothing: it is large where an entry of P is near zero."
    )
    scaled = "".join(f" | {n} scaled dP | {n} scaled dx" for n in names)
    text += [
        "",
        f"| model | states | scenario | folder | predict (C) | update{scaled} | tolerance (bounds {bounded}) "
        "| C elementwise dP (not bounded) | verdict |",
        "|---|---|---|---|---|---" + "|---" * (2 * len(names)) + "|---|---|---|",
    ]
    for run in runs:
        g = run.generation
        checks = {r.implementation: r for r in run.checks}
        update = g.code.costs.get("update")
        scenario = checks["c"].scenario.split(" (")[0]
        cells = "".join(f" | {checks[i].max_scaled_P:.1e} | {checks[i].max_scaled_x:.1e}" if i in checks else " | - | -"
                        for i in implementations)
        text.append(
            f"| {g.derived.model.name} | {g.derived.n_states} | {scenario} | `{out_root / g.derived.model.name}` "
            f"| {g.code.costs['predict (C)'].total} flops | {update.total if update else '-'}"
            f"{' flops' if update else ''}{cells} | {checks['c'].tolerance:.1e} "
            f"| {checks['c'].max_elementwise_P:.1e} | {'ok' if run.passed else 'FAILED'} |"
        )
    passed = sum(run.passed for run in runs)
    target = {"quantity": f"generated {', '.join(names)} within the conformance tolerance",
              "reached": f"{passed} of {len(runs)} models", "target": "every model", "met": passed == len(runs)}
    return ReportSection("Generated code, compiled and checked against the numpy reference", "\n".join(text), (target,))


def run_report(verification_summary: str, runs: list, out_root: Path, extra_sections: list,
               paper_targets: tuple[dict, ...] = ()) -> str:
    """The Markdown report of the main job (no timestamps: byte-stable).

    ``extra_sections`` are :class:`ReportSection` objects (or plain Markdown,
    which states no target); the report opens with every section's targets,
    met or missed, and shows every figure with its caption.
    """
    paper = ReportSection("Paper check (the table of F, G, H of the core paper)", verification_summary, paper_targets)
    sections = [paper, conformance_section(runs, out_root)]
    sections += [s if isinstance(s, ReportSection) else ReportSection("", s) for s in extra_sections]
    lines = ["# modelgen run: the core paper's model, end to end", ""]
    rows = [(s.title.split(" (")[0], t) for s in sections for t in s.targets]  # the section's name without its gloss
    stated = [(title, t) for title, t in rows if t["met"] is not None]
    missed = [(title, t) for title, t in stated if not t["met"]]
    lines += ["## Targets", "",
              f"{len(stated) - len(missed)} of {len(stated)} stated targets met"
              + (f", {len(missed)} missed." if missed else ".") + " Each is measured in the section named.", "",
              "| section | quantity | reached | target | |", "|---|---|---|---|---|"]
    lines += [f"| {title} | {t['quantity']} | {t['reached']} | {t['target']} | "
              f"{'' if t['met'] is None else 'met' if t['met'] else '**missed**'} |" for title, t in rows]
    lines.append("")
    for section in sections:
        lines += [section.markdown() if section.title else section.text.rstrip(), ""]
    return cite_sources("\n".join(lines).rstrip() + "\n")


def missed_targets(text: str) -> list[str]:
    """The targets the main job's report (its text) states as missed, each as 'section: quantity'."""
    table = text.split("\n## Targets\n", 1)[1].split("\n## ", 1)[0]
    rows = (line[2:-2].split(" | ") for line in table.splitlines() if line.endswith("| **missed** |"))
    return [f"{section}: {quantity} ({reached}, target {target})" for section, quantity, reached, target, _ in rows]


def verification_summary(result: VerificationResult, markdown: Path, data: Path) -> str:
    """The paper check in a few lines for the main job's report, with links to the full reports."""
    counts = result.counts()
    return (
        f"{len(result.entries)} entries: "
        + ", ".join(f"{counts[k]} {k}" for k in counts)
        + f"; {len(result.unexplained)} unexplained. Differences:\n\n"
        + "\n".join(f"- {e.matrix}({e.row},{e.column}) {e.status}: {e.classification} - {e.reason}" for e in result.differences)
        + f"\n\nFull report: [{markdown.name}]({markdown.name}), machine-readable: [{data.name}]({data.name})."
    )


def mechanizations_section(checks: MechanizationChecks) -> ReportSection:
    """The run report's section on :mod:`modelgen.checks.mechanizations`: its table, and its one target (no check failed)."""
    from modelgen.checks.mechanizations import report_section_text

    failed = checks.failed
    return ReportSection("Mechanizations cross-checked (ECEF and wander azimuth against local level)", report_section_text(checks),
                         ({"quantity": "mechanization cross-checks outside their bound (incl. the polar flight)",
                           "reached": str(len(failed)), "target": "0", "met": not failed},))


def replay_section(folder: Path, echo=print) -> ReportSection:
    """Fly the built-in recorded drive (``modelgen replay``) into ``folder``; the report's section on it.

    Its targets and figure captions are the replay's own (its summary's
    ``targets``, :data:`modelgen.navigator.report.FIGURE_CAPTIONS`).
    """
    from modelgen.navigator.config import builtin_config_path
    from modelgen.navigator.replay import run_replay

    flown = run_replay(builtin_config_path(), folder, echo=echo)
    s = flown.summary
    text = "\n".join([
        f"The generated C navigator ({s['navigator']}) flown forward in real time over the recorded drive with "
        f"{s['outage_count']} simulated GNSS outages: end-of-outage horizontal error RMS "
        f"{s['horizontal_error_end_rms_m']:.2f} m (median {s['horizontal_error_end_median_m']:.2f} m, max "
        f"{s['horizontal_error_end_max_m']:.2f} m), mean normalized squared horizontal error at the outage "
        f"ends {s['consistency']['nees_mean']:.1f} (2 for a consistent filter) with "
        f"{100 * s['consistency']['inside_95_fraction']:.0f} % inside the 95 % region, horizontal RMS against RTK outside outages "
        f"{s['horizontal_rms_outside_outages_m']:.3f} m.",
        "",
        "Details: [replay/summary.md](replay/summary.md)",
    ])
    captions = _replay_captions(folder)
    figures = tuple((f"replay/{name}", caption) for name, caption in captions.items() if (folder / name).is_file())
    return ReportSection("Recorded car drive (real IMU and RTK GNSS)", text, tuple(flown.targets()), figures)


def _replay_captions(folder: Path) -> dict[str, str]:
    """The replay's figures and their captions, as its summary.json states them (else the navigator's table)."""
    import json

    from modelgen.navigator.report import FIGURE_CAPTIONS

    try:
        return dict(json.loads((folder / "summary.json").read_text(encoding="utf-8")).get("figures") or FIGURE_CAPTIONS)
    except (OSError, ValueError):
        return dict(FIGURE_CAPTIONS)
