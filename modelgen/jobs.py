"""The jobs: what each command does, composed from the layers below.

Every command of :mod:`modelgen.cli` calls one function here and prints what
it returns.  A job loads and derives a model once and hands the
:class:`~modelgen.derivation.symbolic.DerivedModel` to every step that needs it
(paper check, code generation, covariance analysis, simulation): no step
derives it again, and no step recognises a model by its name; which model is
the paper's comes from the paper table's data (its ``model:`` key).

``generate`` writes one model's code into ``generated/<model>/``;
``check`` compiles it and runs it beside the numpy reference over the
model's check scenario (the ``check:`` section of its file; the paper's model
declares the paper's level flight, Table 1 initial errors, 240 steps of 60 s).
A user model without one is checked over a synthetic operating point, which
checks the code, not the navigation, and is labelled so.  The pass criterion
is computed per run from its conditioning (modelgen.checks.code_check).
:func:`main_job` is ``modelgen run``.
"""

from __future__ import annotations

import importlib
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from modelgen.codegen.options import CodegenOptions
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path
from modelgen.fileio.output import FolderUpdate, write_text_atomically
from modelgen.model.sources import cite_sources

if TYPE_CHECKING:
    from modelgen.derivation.symbolic import DerivedModel
    from modelgen.checks.code_check import CheckScenario, ConformanceResult
    from modelgen.checks.paper_check import VerificationResult
    from modelgen.checks.paper_equations import PaperEquationsResult
    from modelgen.checks.mechanizations import MechanizationChecks
    from modelgen.checks.twins import TwinChecks
    from modelgen.codegen.generate import GeneratedCode

#: names the command line and the Python API take from this module (they import only jobs; builtin_models and
#: CodegenOptions too), by the module that defines them: imported on first use, as each job imports the layers it
#: uses (the checks are 0.2 s of imports that ``modelgen simulate`` does not need before its flight starts)
_REEXPORTED = {
    "verify": "modelgen.checks.paper_check",
    "write_verification_report": "modelgen.checks.paper_check",
    "differences_summary": "modelgen.checks.paper_equations",
    "write_paper_equations_report": "modelgen.checks.paper_equations",
    "check_worker_count": "modelgen.cluster",
}


def __getattr__(name: str) -> Any:
    """A name of :data:`_REEXPORTED`, imported from its module on first use."""
    if name in _REEXPORTED:
        value = getattr(importlib.import_module(_REEXPORTED[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def load_model(model: str | Path):
    """:func:`modelgen.model.loading.load_model`, imported on first use: sympy (30 MiB, 0.5 s) only for the jobs
    that load a model here (``modelgen simulate`` derives its model in a forked process, the flight imports none)."""
    from modelgen.model.loading import load_model as load

    return load(model)


def builtin_models() -> list[str]:
    """:func:`modelgen.model.loading.builtin_models`, imported on first use (see :func:`load_model`)."""
    from modelgen.model.loading import builtin_models as names

    return names()


def derive(model):
    """:func:`modelgen.derivation.symbolic.derive`, imported on first use (see :func:`load_model`)."""
    from modelgen.derivation.symbolic import derive as derived

    return derived(model)


def load_and_derive(model: str | Path) -> DerivedModel:
    """A model file, or a built-in model by name, loaded and derived: the first step of every job."""
    return derive(load_model(model))


class DerivedModels:
    """Models derived at most once in a job, by the reference (file or built-in name) they were loaded from.

    The main job derives the paper's model first and registers it, so that
    code generation, the covariance analysis and the simulation all get that
    same object instead of deriving the model again.
    """

    def __init__(self) -> None:
        self._derived: dict[str, DerivedModel] = {}

    def add(self, reference: str | Path, derived: DerivedModel) -> DerivedModel:
        """Remember ``derived`` as the model loaded from ``reference``; returns it."""
        self._derived[str(reference)] = derived
        return derived

    def get(self, reference: str | Path) -> DerivedModel:
        """The model loaded from ``reference``, derived on first use."""
        key = str(reference)
        if key not in self._derived:
            self._derived[key] = load_and_derive(reference)
        return self._derived[key]



@dataclass(frozen=True)
class GenerationResult:
    """One model's generated code and where it went.

    ``files`` are the paths written, in name order (none when a failing
    check kept the previous output: ``written`` is then False); ``checks``
    holds the conformance results when the code was checked.
    """

    derived: DerivedModel
    code: GeneratedCode
    folder: Path
    checks: tuple[ConformanceResult, ...] = ()
    files: tuple[Path, ...] = ()

    @property
    def written(self) -> bool:
        """True if the code replaced the folder's previous output (False: a check failed, nothing was written)."""
        return bool(self.files)

    @property
    def passed(self) -> bool:
        """True if every check (if any was run) is within tolerance."""
        return checks_passed(self.checks)

    def __repr__(self) -> str:
        checked = "" if not self.checks else "; checks " + ", ".join(
            f"{r.implementation} {'ok' if r.passed() else 'FAILED'}" for r in self.checks)
        wrote = f"{len(self.files)} files in {self.folder}" if self.written else f"nothing written to {self.folder}"
        return f"<GenerationResult {self.derived.model.name!r}: {wrote}{checked}>"

    def _repr_markdown_(self) -> str:
        """What a notebook shows: the files (with sizes) and each check against its tolerance."""
        lines = [f"**GenerationResult `{self.derived.model.name}`**: "
                 + (f"{len(self.files)} files in `{self.folder}`" if self.written else
                    f"nothing written (a check failed; `{self.folder}` keeps its previous output)"), ""]
        if self.written:
            lines += ["| file | bytes |", "|---|---:|"]
            lines += [f"| `{name}` | {len(self.code.files[name].encode())} |" for name in sorted(self.code.files)]
        if self.checks:
            lines += ["", "| implementation | scaled dP | scaled dx | tolerance (bounds both) | verdict |", "|---|---:|---:|---:|---|"]
            lines += [f"| {r.implementation} | {r.max_scaled_P:.1e} | {r.max_scaled_x:.1e} | {r.tolerance:.1e} | "
                      f"{'ok' if r.passed() else 'FAILED'} |" for r in self.checks]
        return "\n".join(lines) + "\n"


def checks_passed(results) -> bool:
    """The pass criterion of ``--check``: every implementation within the conformance tolerance."""
    return all(r.passed() for r in results)


def generate(
    model: str | Path | DerivedModel,
    out_root: Path = Path("generated"),
    options: CodegenOptions | None = None,
    force: bool = False,
    with_check: bool = False,
) -> GenerationResult:
    """Load, derive and generate one model into ``out_root/<model>/`` atomically.

    ``model`` is a model file, a built-in name, or a model already derived.

    The code is written to a staging folder beside the output (see
    ``modelgen.fileio.output``).  With ``with_check`` it is compiled and checked
    there, and it replaces the previous output only if the check passes: a
    failing check leaves the last good output as it was.  ``force`` lets the
    new files overwrite files in the folder that modelgen did not write or
    that were edited since.
    """
    from modelgen.codegen.generate import generate_code

    from modelgen.derivation.symbolic import DerivedModel

    derived = model if isinstance(model, DerivedModel) else load_and_derive(model)
    options = options or CodegenOptions()
    code = generate_code(derived, options)
    folder = Path(out_root) / derived.model.name
    with FolderUpdate(folder, force=force) as update:
        staged = update.stage(code.files)
        checks = tuple(check(derived, staged, options=options)) if with_check else ()
        if not checks_passed(checks):
            return GenerationResult(derived, code, folder, checks)
        update.commit()
    return GenerationResult(derived, code, folder, checks, tuple(folder / name for name in sorted(code.files)))


def synthetic_scenario(derived: DerivedModel, seed: int = 0, steps: int = 100) -> CheckScenario:
    """A well-conditioned operating point for checking code of a model without a ``check:`` section.

    Parameters without a default are drawn from [0.2, 1.0]; the step is
    chosen so that ||F T|| is about 0.5, which keeps the Taylor series and the
    covariance well scaled whatever the model's units.  It checks the code,
    not the navigation (an attitude matrix drawn so is no rotation), and says
    so in its label.
    """
    from modelgen.checks.code_check import CheckScenario

    rng = np.random.default_rng(seed)
    values = {p.name: float(rng.uniform(0.2, 1.0)) for p in derived.model.parameters if p.value is None}
    F = derived.numeric(values)["F"]
    norm = float(np.linalg.norm(F, 2))
    step = 0.5 / norm if norm > 0 else 1.0
    x0 = rng.standard_normal(derived.n_states)
    label = "synthetic operating point (the model declares no check: section; parameters drawn from [0.2, 1])"
    return CheckScenario(values, np.eye(derived.n_states), step=step, steps=steps, seed=seed, initial_state=x0, label=label)


def paper_parameters() -> dict[str, float]:
    """The core paper's level-flight operating point and Table 1 statistics, by ned_doppler18 parameter name."""
    from modelgen.table2.budget import load_error_budget
    from modelgen.table2.scenario import load_analysis_scenario, operating_point

    return {**load_error_budget().parameters, **operating_point(load_analysis_scenario())}


def paper_scenario(derived: DerivedModel) -> CheckScenario:
    """The core paper's 4-hour scenario: level flight, Table 1 errors, T = 60 s."""
    from modelgen.table2.budget import load_error_budget
    from modelgen.table2.scenario import load_analysis_scenario
    from modelgen.checks.code_check import CheckScenario

    flight, budget = load_analysis_scenario(), load_error_budget()
    values = paper_parameters()
    label = "the core paper's scenario (level flight east at 30 N, Table 1, 240 steps of 60 s)"
    return CheckScenario(values, budget.initial_covariance(derived.model), step=flight.step_s, steps=flight.steps, label=label)


def declared_scenario(derived: DerivedModel) -> CheckScenario | None:
    """The scenario of the model file's ``check:`` section (modelgen.model.check_scenario), if it has one.

    The initial state is drawn from N(0, P(0)) with the section's seed, so the
    state propagation is exercised too, not only the covariance.
    """
    from modelgen.checks.code_check import CheckScenario

    spec = derived.model.check
    if spec is None:
        return None
    P0 = spec.covariance(derived.model.state_names, derived.model.name)
    rng = np.random.default_rng(spec.seed + 1)  # not the measurement stream's seed
    x0 = np.sqrt(np.diag(P0)) * rng.standard_normal(derived.n_states)
    label = f"the model's check scenario ({spec.steps} steps of {spec.step_s:g} s)"
    return CheckScenario(spec.parameter_values(), P0, step=spec.step_s, steps=spec.steps, seed=spec.seed, initial_state=x0, label=label,
                         where=spec.where)


def check_scenario(derived: DerivedModel) -> CheckScenario:
    """What ``--check`` flies: the model's declared scenario, else the synthetic one (labelled so)."""
    return declared_scenario(derived) or synthetic_scenario(derived)


def check(
    derived: DerivedModel, folder: Path, scenario: CheckScenario | None = None, options: CodegenOptions | None = None
) -> list[ConformanceResult]:
    """Compile the generated C and run it and the Python beside the reference.

    Each result carries its own tolerance, computed from the run's
    conditioning (modelgen.checks.code_check.conformance_tolerance).
    """
    from modelgen.checks.code_check import check_generated

    options = options or CodegenOptions()
    scenario = scenario or check_scenario(derived)
    with tempfile.TemporaryDirectory(prefix="modelgen-check-") as build_dir:
        return check_generated(folder, derived, scenario, Path(build_dir), options)


@dataclass(frozen=True)
class ModelRun:
    """What the main job did for one model."""

    generation: GenerationResult
    checks: list[ConformanceResult]

    @property
    def passed(self) -> bool:
        return checks_passed(self.checks)


def generate_and_check_all(
    out_root: Path, progress=print, force: bool = False, models: DerivedModels | None = None
) -> list[ModelRun]:
    """Generate every built-in model into ``out_root``, checked before it replaces the previous output.

    ``models`` holds the models the caller has derived already (they are not derived again).
    """
    models = models if models is not None else DerivedModels()
    runs = []
    for name in builtin_models():
        progress(f"generate + check {name} ...")
        result = generate(models.get(name), out_root, force=force, with_check=True)
        runs.append(ModelRun(result, list(result.checks)))
    return runs


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


def conformance_section(runs: list[ModelRun], out_root: Path) -> ReportSection:
    """The generated code's check: every model's differences from the reference beside the tolerance that bounds them.

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


def run_report(verification_summary: str, runs: list[ModelRun], out_root: Path, extra_sections: list,
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


def paper_operating_point(derived: DerivedModel) -> dict[str, float] | None:
    """The paper's level-flight values, when they cover every parameter of the model."""
    values = paper_parameters() if derived.model.frame == "NED" else {}
    needed = {p.name for p in derived.model.parameters if p.value is None}
    return values if values and needed <= set(values) else None


def observability_defaults(derived: DerivedModel) -> tuple[str, dict[str, float], float | None] | None:
    """The operating point ``modelgen observability`` uses without a scenario file: label, values, step.

    The core paper's level flight where it covers the model's parameters, else
    the model file's own check scenario (its values and step), else none.
    """
    paper = paper_operating_point(derived)
    if paper:
        return "the core paper's level flight (30 N, east, 300 km/h, Table 1 statistics)", paper, None
    spec = derived.model.check
    if spec is not None:
        return f"the model's check scenario (steps of {spec.step_s:g} s)", spec.parameter_values(), spec.step_s
    return None


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


@dataclass(frozen=True)
class MainJobResult:
    """What ``modelgen run`` did: the report's text, each model's run and the paper check."""

    text: str
    runs: list[ModelRun]
    verification: VerificationResult
    twins: TwinChecks | None = None  # the cross-check of every hand model and its twin, and the paper from first principles
    mechanizations: MechanizationChecks | None = None  # ECEF and wander azimuth against local level, the polar flight

    @property
    def failed_models(self) -> list[str]:
        """Names of the models whose generated code failed its check."""
        return [r.generation.derived.model.name for r in self.runs if not r.passed]

    @property
    def missed_targets(self) -> list[str]:
        """The targets the report states as missed ('section: quantity (reached, target ...)')."""
        return missed_targets(self.text)


def main_job(
    report: Path, out_root: Path, figures: bool = True, with_simulation: bool = True, force: bool = False,
    progress=print, echo=print, with_replay: bool = True,
) -> MainJobResult:
    """``modelgen run``: the paper's model derived once, then checked, generated, analysed and flown.

    The paper's model is the one the paper table names (data, not code).  It
    is derived here and handed to the paper check, to code generation (with
    every other built-in model), to the covariance analysis and to the
    simulation.  The report goes into ``report`` (the caller's staging
    folder); ``progress`` announces the steps and ``echo`` relays the steps'
    own messages.
    """
    from modelgen.table2.report import run_covariance_analysis
    from modelgen.table2.systems import PaperModels
    from modelgen.checks.paper_check import verify, write_verification_report
    from modelgen.checks.paper_table import CORE_PAPER_TABLE, paper_table_model
    from modelgen.checks.mechanizations import run_mechanization_checks, write_mechanizations_report
    from modelgen.checks.twins import report_section, run_twin_checks, write_twin_reports

    paper_model = paper_table_model(data_path(CORE_PAPER_TABLE))
    models = DerivedModels()
    progress(f"derive {paper_model} ...")
    derived = models.add(paper_model, load_and_derive(paper_model))
    progress("verify against the paper's table ...")
    result = verify(derived)
    summary = verification_summary(result, *write_verification_report(result, report))
    runs = generate_and_check_all(Path(out_root), progress=progress, force=force, models=models)
    progress("cross-check the hand-written models against their twins; the paper from first principles ...")
    twins = run_twin_checks(models.get, paper_model=paper_model)
    write_twin_reports(twins, report)
    progress("cross-check the mechanizations: ECEF and wander azimuth against local level, a polar flight ...")
    mechanizations = run_mechanization_checks()
    write_mechanizations_report(mechanizations, report)
    progress("covariance analysis (Table 2, Figs 2-7) ...")
    analysis = run_covariance_analysis(report / "covariance", PaperModels.build(derived), figures=figures, progress=echo)
    twin_text = report_section(twins).split("\n", 2)[2]
    sections: list = [ReportSection("Hand-written models against their twins derived from the navigation equations",
                                    twin_text, ({"quantity": "unexplained differences between hand-written models and their twins",
                                                 "reached": str(twins.unexplained), "target": "0",
                                                 "met": twins.unexplained == 0},))]
    sections.append(mechanizations_section(mechanizations))
    sections.append(ReportSection(
        "Covariance analysis (Table 2 analogue)",
        analysis.table + "\n\nDetails: [covariance/table2.md](covariance/table2.md)",
        tuple(analysis.targets), tuple((f"covariance/{name}", caption) for name, caption in analysis.captions.items())))
    if with_simulation:
        from modelgen.simulation.flight_report import simulation_report
        from modelgen.simulation.scenario import load_profile

        progress("simulate the paper's flight (profile_000, one run) ...")
        profile = load_profile("profile_000")
        flown = simulation_report(profile, models.get(profile.filter.model), report / "simulation", runs=1, seed=1,
                                  echo=echo)
        name = flown.summary.name
        sections.append(ReportSection(
            "Simulation", f"The paper's profile flown once with the generated C filter: [simulation/{name}](simulation/{name}).",
            tuple(flown.targets), tuple((f"simulation/{path.name}", caption) for path, caption in flown.figures.items())))
    if with_replay:
        progress("replay the recorded car drive with the generated C navigator ...")
        sections.append(replay_section(report / "replay", echo))
    paper_target = {"quantity": "differences from the paper's table that no annotation explains",
                    "reached": str(len(result.unexplained)), "target": "0", "met": not result.unexplained}
    text = run_report(summary, runs, Path(out_root), sections, paper_targets=(paper_target,))
    write_text_atomically(report / "README.md", text)
    return MainJobResult(text, runs, result, twins, mechanizations)


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


def derived_export(model: str | Path, fmt: str, name: str | None = None) -> str:
    """``modelgen derive --format``: MODEL's F, G, H, Q, R as text, json, latex, octave or casadi (see :mod:`modelgen.export`).

    ``name`` names the Octave function (the output file's stem); CasADi
    names its function ``<model>_matrices``.
    """
    derived = load_and_derive(model)
    if fmt == "casadi":
        from modelgen.export.casadi_file import to_casadi

        return to_casadi(derived)
    from modelgen.export.formats import to_format

    return to_format(derived, fmt, name)


def verified_model(model: str | Path | None, table: str | Path | None) -> str | Path:
    """The model ``modelgen verify`` checks: ``model`` if given, else the one ``table`` names, else the paper's.

    A table says which model it was written for in its ``model:`` key
    (the shipped paper table names the core paper's model), so
    ``modelgen verify --table FILE`` needs no model argument.  A table without
    the key needs one, and the message says so.
    """
    from modelgen.checks.paper_table import CORE_PAPER_TABLE, paper_table_model
    from modelgen.fileio.datafiles import read_yaml

    if model is not None:
        return model
    if table is None:
        return paper_table_model(data_path(CORE_PAPER_TABLE))
    named = read_yaml(Path(table), "paper-table file").get("model")
    if not isinstance(named, str) or not named:
        raise ModelError(f"{table}: the table has no 'model:' key: name the model (modelgen verify MODEL --table "
                         f"{Path(table).name}) or add 'model: <name>' to the table")
    if named not in builtin_models():  # a name, never a path: a model file is given as MODEL
        raise ModelError(f"{table}: the table is written for model {named!r}, which is not a built-in model: give its "
                         f"file (modelgen verify MODEL.yaml --table {Path(table).name})")
    return named


def paper_check_of(
    model: str | Path | None, table: str | Path | None = None, complete: bool | None = None
) -> tuple[str, VerificationResult | None]:
    """``modelgen verify``: the model's name and its paper check (None: no table given and none names this model).

    ``model`` None takes the model from the table (:func:`verified_model`).
    ``table`` is a user's table file (docs "Verifying a paper");
    ``complete`` (default: only for the shipped table) also compares the
    derived nonzeros the table does not list.
    """
    from modelgen.checks.paper_check import verify
    from modelgen.checks.paper_table import paper_table_path

    loaded = load_model(verified_model(model, table))
    if table is None and paper_table_path(loaded.name) is None:
        return loaded.name, None
    if complete is None:
        complete = table is None
    return loaded.name, verify(derive(loaded), table, complete=complete)


def first_principles_of(model_name: str) -> PaperEquationsResult | None:
    """``modelgen verify``: the paper's printed equations against the model's twin (None: no transcription names the model)."""
    from modelgen.checks.twins import first_principles_check

    return first_principles_check(model_name, load_and_derive)


def embedded_inputs(model: str | Path, qemu: bool):
    """``modelgen embedded``'s inputs: the derived model and, with ``qemu``, the check scenario it flies (else None)."""
    derived = load_and_derive(model)
    return derived, (check_scenario(derived) if qemu else None)


def embedded_report(derived: DerivedModel, scenario: CheckScenario | None, folder: Path):
    """``modelgen embedded``: the Cortex-M4F builds and the qemu runs (an :class:`EmbeddedReport`) into ``folder``."""
    from modelgen.checks.embedded_check import embedded_report as build_and_run

    return build_and_run(derived, scenario, folder)


def recommended_form(runs) -> str:
    """Which single-precision form to use, from the measured qemu runs (modelgen.checks.embedded_check)."""
    from modelgen.checks.embedded_check import recommended_form as recommend

    return recommend(runs)


def observability_analysis(
    derived: DerivedModel, scenario_file: str | None = None, assignments: tuple[str, ...] = (), step: float | None = None,
    steps: int | None = None, weak_rtol: float = 1e-3,
):
    """``modelgen observability``: the default operating point's label (None with a scenario file) and the report.

    Without a scenario file the operating point is :func:`observability_defaults`'
    (its step too, unless ``step`` is given), overridden by the ``NAME=VALUE``
    assignments.
    """
    from modelgen.analysis.observability import analyse, command_line_scenario

    defaults = observability_defaults(derived) if scenario_file is None else None
    label = base = None
    if defaults:
        label, base, default_step = defaults
        step = step if step is not None else default_step
    scenario = command_line_scenario(
        scenario_file, assignments, step, steps, default_steps=derived.n_states, base_values=base
    )
    return label, analyse(derived, scenario, weak_rtol=weak_rtol)


def observability_report(report) -> str:
    """The text report of an observability analysis (what ``modelgen observability`` prints)."""
    from modelgen.analysis.observability import format_report

    return format_report(report)


def covariance_analysis(folder: Path, sensitivity: bool, figures: bool, progress=None):
    """``modelgen covariance``: Table 2 and Figs 2-7 into ``folder`` (a :class:`CovarianceReport`)."""
    from modelgen.table2.report import run_covariance_analysis
    from modelgen.table2.systems import PaperModels
    from modelgen.checks.paper_table import CORE_PAPER_TABLE, paper_table_model

    say = progress or (lambda message: None)
    paper_model = paper_table_model(data_path(CORE_PAPER_TABLE))
    say(f"deriving {paper_model} and the reduced models made from it")
    models = PaperModels.build(load_and_derive(paper_model))
    return run_covariance_analysis(folder, models, sensitivity=sensitivity, figures=figures, progress=progress)


def flight_scenario(profile: str, hours: float | None = None, imu_rate: float | None = None, model: str | None = None):
    """``modelgen simulate``'s scenario: a profile (file or built-in name), optionally shortened, at another
    IMU rate or with another filter model."""
    from modelgen.simulation.scenario import load_profile

    changes: dict[str, float | str] = {"imu_rate": imu_rate} if imu_rate is not None else {}
    if hours is not None:
        changes["hours"] = hours
    if model is not None:
        changes["model"] = model
    scenario = load_profile(profile).with_changes(**changes)
    if model is None:
        check_filter_constants(scenario)
    return scenario


def check_filter_constants(scenario) -> None:
    """A profile's ``filter.parameters`` name parameters of its own ``filter.model``: a misspelt name is refused.

    A constant the model does not have would otherwise be ignored, and the
    parameter it was meant for would fly at its default.  (With ``--model``
    the profile's constants were written for another model and are taken
    only where the names match.)
    """
    import difflib

    if not scenario.filter.parameters:
        return
    names = load_model(scenario.filter.model).parameter_names
    unknown = sorted(set(scenario.filter.parameters) - set(names))
    if unknown:
        close = difflib.get_close_matches(unknown[0], names, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ModelError(f"profile {scenario.name!r}: filter.parameters: {', '.join(map(repr, unknown))} "
                         f"{'is' if len(unknown) == 1 else 'are'} not a parameter of model {scenario.filter.model!r}{hint}; "
                         f"its parameters: {', '.join(names)}")


def simulate_flight(scenario, folder: Path, runs: int, seed: int, implementation: str, echo=print,
                    scheduler: str | None = None, workers: int | None = None, history_csv: bool = False,
                    journal: str | Path | None = None, connect_timeout_s: float | None = None) -> Path:
    """``modelgen simulate``: fly the scenario (truth, sensors, filter, Monte Carlo) into ``folder``; the summary's path.

    The Monte Carlo runs go to ``scheduler`` (an existing dask cluster) or,
    for two runs or more, to a local cluster of ``workers`` processes (default:
    one per core), opened first so that an unreachable address fails at once.
    ``journal`` keeps the completed runs on disk; a rerun of the same study
    with it flies only the missing ones (and opens no local cluster when none
    is missing); a journal of another study is refused before anything is flown.  ``connect_timeout_s``: how
    long ``scheduler`` is waited for (default :data:`modelgen.cluster.CONNECT_TIMEOUT_S`).
    """
    from modelgen.cluster import dask_client, describe_client
    from modelgen.simulation.flight_report import check_monte_carlo_journal, simulate, start_flight
    from modelgen.simulation.model_process import ModelProcess

    # the generated C filter needs only plain data of the derived model: the model is derived, its code generated
    # and its layout made in a forked copy of this process (before the flight's threads start), so that the flight
    # holds none of sympy (bench/bench_simulate_memory.py); the Python and reference filters need the model here
    preparing = ModelProcess.start(scenario, implementation, runs) if implementation == "c" else None
    started = start_flight(scenario, seed)  # the truth and IMU errors are made while the model is derived
    derived = preparing.result() if preparing is not None else load_and_derive(scenario.filter.model)
    # a journal of another study is refused before a cluster is opened; one holding every run needs none
    complete = check_monte_carlo_journal(journal, scenario, derived, runs, seed, implementation, started)
    if (runs < 2 or complete) and scheduler is None:
        return simulate(scenario, derived, folder, runs=runs, seed=seed, echo=echo, implementation=implementation,
                        history_csv=history_csv, journal=journal, started=started)
    with dask_client(scheduler, workers, timeout_s=connect_timeout_s) as client:
        echo(f"  Monte Carlo on {describe_client(client)}")
        return simulate(scenario, derived, folder, runs=runs, seed=seed, echo=echo, implementation=implementation,
                        client=client, history_csv=history_csv, journal=journal, started=started)


def trade_study(study_file: str | Path, folder: Path, scheduler: str | None = None, workers: int | None = None,
                echo=print, journal: str | Path | None = None, connect_timeout_s: float | None = None) -> list[Path]:
    """``modelgen trade``: check the study file, run its cases on a dask cluster, write its outputs into ``folder``.

    The whole file is checked (and its Monte Carlo profiles built) before the
    cluster is opened or any task submitted.  ``journal`` keeps completed
    covariance tasks on disk (see :class:`modelgen.cluster.Journal`).  ``connect_timeout_s``: how long
    ``scheduler`` is waited for (default :data:`modelgen.cluster.CONNECT_TIMEOUT_S`).
    """
    from modelgen.cluster import dask_client
    from modelgen.study.outputs import write_outputs
    from modelgen.study.studyfile import load_study
    from modelgen.study.trade import monte_carlo_profiles, run_trade

    study = load_study(study_file)
    profiles = monte_carlo_profiles(study)
    echo(f"modelgen trade: {study.name}, {study.case_count} covariance cases"
         + (f", {len(profiles)} Monte Carlo cases" if profiles else ""))
    with dask_client(scheduler, workers, timeout_s=connect_timeout_s) as client:
        result = run_trade(study, client, progress=echo, profiles=profiles, journal=journal)
    return write_outputs(result, folder)
