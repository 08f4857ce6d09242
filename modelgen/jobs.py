"""The end-to-end job: model -> derived matrices -> code -> compiled check.

``generate`` writes one model's code into ``generated/<model>/``;
``check`` compiles it and runs it beside the numpy reference over the
model's check scenario (the ``check:`` section of its file; the paper's model
declares the paper's level flight, Table 1 initial errors, 240 steps of 60 s).
A user model without one is checked over a synthetic operating point, which
checks the code, not the navigation, and is labelled so.  The pass criterion
is computed per run from its conditioning (modelgen.checks.code_check).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from modelgen.codegen.generate import CodegenOptions, GeneratedCode, generate_code
from modelgen.checks.code_check import ConformanceResult, Scenario, check_generated
from modelgen.derive.symbolic import DerivedModel, derive
from modelgen.model.loading import load_model
from modelgen.fileio.output import FolderUpdate



@dataclass(frozen=True)
class GenerationResult:
    """One model's generated code and where it went.

    ``checks`` holds the conformance results when the code was checked;
    ``written`` is False when a failing check kept the previous output.
    """

    derived: DerivedModel
    code: GeneratedCode
    folder: Path
    checks: tuple[ConformanceResult, ...] = ()
    written: bool = True

    @property
    def passed(self) -> bool:
        """True if every check (if any was run) is within tolerance."""
        return checks_passed(self.checks)


def checks_passed(results) -> bool:
    """The pass criterion of ``--check``: every implementation within the conformance tolerance."""
    return all(r.passed() for r in results)


def generate(
    model: str | Path,
    out_root: Path = Path("generated"),
    options: CodegenOptions | None = None,
    force: bool = False,
    with_check: bool = False,
) -> GenerationResult:
    """Load, derive and generate one model into ``out_root/<model>/`` atomically.

    The code is written to a staging folder beside the output (see
    ``modelgen.fileio.output``).  With ``with_check`` it is compiled and checked
    there, and it replaces the previous output only if the check passes: a
    failing check leaves the last good output as it was.  ``force`` lets the
    new files overwrite files in the folder that modelgen did not write or
    that were edited since.
    """
    derived = derive(load_model(model))
    options = options or CodegenOptions()
    code = generate_code(derived, options)
    folder = Path(out_root) / derived.model.name
    with FolderUpdate(folder, force=force) as update:
        staged = update.stage(code.files)
        checks = tuple(check(derived, staged, options=options)) if with_check else ()
        if not checks_passed(checks):
            return GenerationResult(derived, code, folder, checks, written=False)
        update.commit()
    return GenerationResult(derived, code, folder, checks)


def synthetic_scenario(derived: DerivedModel, seed: int = 0, steps: int = 100) -> Scenario:
    """A well-conditioned operating point for checking code of a model without a ``check:`` section.

    Parameters without a default are drawn from [0.2, 1.0]; the step is
    chosen so that ||F T|| is about 0.5, which keeps the Taylor series and the
    covariance well scaled whatever the model's units.  It checks the code,
    not the navigation (an attitude matrix drawn so is no rotation), and says
    so in its label.
    """
    rng = np.random.default_rng(seed)
    values = {p.name: float(rng.uniform(0.2, 1.0)) for p in derived.model.parameters if p.value is None}
    F = derived.numeric(values)["F"]
    norm = float(np.linalg.norm(F, 2))
    step = 0.5 / norm if norm > 0 else 1.0
    x0 = rng.standard_normal(derived.n_states)
    label = "synthetic operating point (the model declares no check: section; parameters drawn from [0.2, 1])"
    return Scenario(values, np.eye(derived.n_states), step=step, steps=steps, seed=seed, initial_state=x0, label=label)


def paper_parameters() -> dict[str, float]:
    """Seed 000's level-flight operating point and Table 1 statistics, by ned_doppler18 parameter name."""
    from modelgen.analysis.budget import load_error_budget
    from modelgen.analysis.scenario import load_scenario, operating_point

    return {**load_error_budget().parameters, **operating_point(load_scenario())}


def paper_scenario(derived: DerivedModel) -> Scenario:
    """Seed 000's 4-hour scenario: level flight, Table 1 errors, T = 60 s."""
    from modelgen.analysis.budget import load_error_budget
    from modelgen.analysis.scenario import load_scenario

    flight, budget = load_scenario(), load_error_budget()
    values = paper_parameters()
    label = "the core paper's scenario (seed 000: level flight east at 30 N, Table 1, 240 steps of 60 s)"
    return Scenario(values, budget.initial_covariance(derived.model), step=flight.step_s, steps=flight.steps, label=label)


def declared_scenario(derived: DerivedModel) -> Scenario | None:
    """The scenario of the model file's ``check:`` section (modelgen.model.check_scenario), if it has one.

    The initial state is drawn from N(0, P(0)) with the section's seed, so the
    state propagation is exercised too, not only the covariance.
    """
    spec = derived.model.check
    if spec is None:
        return None
    P0 = spec.covariance(derived.model.state_names, derived.model.name)
    rng = np.random.default_rng(spec.seed + 1)  # not the measurement stream's seed
    x0 = np.sqrt(np.diag(P0)) * rng.standard_normal(derived.n_states)
    label = f"the model's check scenario ({spec.steps} steps of {spec.step_s:g} s)"
    return Scenario(spec.parameter_values(), P0, step=spec.step_s, steps=spec.steps, seed=spec.seed, initial_state=x0, label=label)


def check_scenario(derived: DerivedModel) -> Scenario:
    """What ``--check`` flies: the model's declared scenario, else the synthetic one (labelled so)."""
    return declared_scenario(derived) or synthetic_scenario(derived)


def check(
    derived: DerivedModel, folder: Path, scenario: Scenario | None = None, options: CodegenOptions | None = None
) -> list[ConformanceResult]:
    """Compile the generated C and run it and the Python beside the reference.

    Each result carries its own tolerance, computed from the run's
    conditioning (modelgen.checks.code_check.conformance_tolerance).
    """
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


def generate_and_check_all(out_root: Path, progress=print, force: bool = False) -> list[ModelRun]:
    """Generate every built-in model into ``out_root``, checked before it replaces the previous output."""
    from modelgen.model.loading import builtin_models

    runs = []
    for name in builtin_models():
        progress(f"generate + check {name} ...")
        result = generate(name, out_root, force=force, with_check=True)
        runs.append(ModelRun(result, list(result.checks)))
    return runs


def run_report(verification_summary: str, runs: list[ModelRun], out_root: Path, extra_sections: list[str]) -> str:
    """The short Markdown report of the main job (no timestamps: byte-stable)."""
    lines = ["# modelgen run: the core paper's model, end to end", ""]
    lines += ["## Paper check (seed 000 table of F, G, H)", "", verification_summary, ""]
    lines += ["## Generated code, compiled and checked against the numpy reference", ""]
    lines += [
        "Check: the generated Python and the C (compiled with "
        "`-std=c99 -Wall -Wextra -Werror -pedantic`) run beside `modelgen.derive.reference` over each model's "
        "check scenario (the `check:` section of its file: a physical operating point, realistic sensor "
        "noise, the source's filter step; `ned_doppler18` flies the paper's 240 steps of 60 s). "
        "'scaled dP' is max |dP_ij| / sqrt(P_ii P_jj) over all steps. The tolerance is computed per run "
        "from the run's conditioning: 2 (2n + 1) u sum_k rho_k, with u = 2^-53 and rho_k the factor by "
        "which step k's arithmetic can magnify a rounding (`modelgen.checks.code_check.conformance_tolerance`).",
        "",
        "| model | states | scenario | folder | predict (C) | update | Python scaled dP | C scaled dP | C elementwise dP | tolerance | verdict |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for run in runs:
        g = run.generation
        checks = {r.implementation: r for r in run.checks}
        update = g.code.costs.get("update")
        scenario = checks["c"].scenario.split(" (")[0]
        lines.append(
            f"| {g.derived.model.name} | {g.derived.n_states} | {scenario} | `{out_root / g.derived.model.name}` "
            f"| {g.code.costs['predict (C)'].total} flops | {update.total if update else '-'}"
            f"{' flops' if update else ''} | {checks['python'].max_scaled_P:.1e} | {checks['c'].max_scaled_P:.1e} "
            f"| {checks['c'].max_elementwise_P:.1e} | {checks['c'].tolerance:.1e} | {'ok' if run.passed else 'FAILED'} |"
        )
    lines.append("")
    for section in extra_sections:
        lines += [section, ""]
    return "\n".join(lines).rstrip() + "\n"
