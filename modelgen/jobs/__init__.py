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

Two parts live in modules of their own: :mod:`modelgen.jobs.scenarios` (the
operating points a model is checked and analysed at) and
:mod:`modelgen.jobs.run_report` (the main job's report, section by section).
"""

from __future__ import annotations

import importlib
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from modelgen.codegen.options import CodegenOptions
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path
from modelgen.fileio.output import FolderUpdate, write_text_atomically
# the jobs' API includes the main job's report sections and the scenarios a model is checked at (their modules)
from modelgen.jobs.run_report import (  # noqa: F401
    ReportSection, conformance_section, mechanizations_section, missed_targets, replay_section, run_report,
    verification_summary)
from modelgen.jobs.scenarios import (  # noqa: F401
    check_scenario, declared_scenario, observability_defaults, paper_operating_point, paper_parameters, paper_scenario,
    synthetic_scenario)

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
