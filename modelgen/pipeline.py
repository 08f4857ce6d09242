"""The end-to-end job: model -> derived matrices -> code -> compiled check.

``generate`` writes one model's code into ``generated/<model>/``;
``check`` compiles it and runs it beside the numpy reference.  The paper's
model is checked over the paper's own scenario (level flight, Table 1
initial errors, 240 steps of 60 s); any other model over a synthetic
operating point, which checks the code, not the navigation.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from modelgen.codegen.generate import CodegenOptions, GeneratedCode, generate_code, write_atomically
from modelgen.conformance import ConformanceResult, Scenario, check_generated
from modelgen.derivation import DerivedModel, derive
from modelgen.modelfile import load_model

#: The C and Python must agree with the reference to this scaled difference.
CONFORMANCE_TOLERANCE = 1e-12


@dataclass(frozen=True)
class GenerationResult:
    derived: DerivedModel
    code: GeneratedCode
    folder: Path


def generate(model: str | Path, out_root: Path = Path("generated"), options: CodegenOptions | None = None) -> GenerationResult:
    """Load, derive and generate one model into ``out_root/<model>/`` atomically."""
    derived = derive(load_model(model))
    code = generate_code(derived, options)
    folder = write_atomically(Path(out_root) / derived.model.name, code.files)
    return GenerationResult(derived, code, folder)


def synthetic_scenario(derived: DerivedModel, seed: int = 0, steps: int = 100) -> Scenario:
    """A well-conditioned operating point for checking code of any model.

    Parameters without a default are drawn from [0.2, 1.0]; the step is
    chosen so that ||F T|| is about 0.5, which keeps the Taylor series and the
    covariance well scaled whatever the model's units.
    """
    rng = np.random.default_rng(seed)
    values = {p.name: float(rng.uniform(0.2, 1.0)) for p in derived.model.parameters if p.value is None}
    F = derived.numeric(values)["F"]
    norm = float(np.linalg.norm(F, 2))
    step = 0.5 / norm if norm > 0 else 1.0
    x0 = rng.standard_normal(derived.n_states)
    return Scenario(values, np.eye(derived.n_states), step=step, steps=steps, seed=seed, initial_state=x0)


def paper_scenario(derived: DerivedModel) -> Scenario:
    """Seed 000's 4-hour scenario: level flight, Table 1 errors, T = 60 s."""
    from modelgen.analysis.budget import load_error_budget
    from modelgen.analysis.scenario import load_scenario, operating_point

    flight, budget = load_scenario(), load_error_budget()
    values = {**budget.parameters, **operating_point(flight)}
    return Scenario(values, budget.initial_covariance(derived.model), step=flight.step_s, steps=flight.steps)


def check(
    derived: DerivedModel, folder: Path, scenario: Scenario | None = None, options: CodegenOptions | None = None
) -> list[ConformanceResult]:
    """Compile the generated C and run it and the Python beside the reference."""
    options = options or CodegenOptions()
    if scenario is None:
        scenario = paper_scenario(derived) if derived.model.name == "ned_doppler18" else synthetic_scenario(derived)
    with tempfile.TemporaryDirectory(prefix="modelgen-check-") as build_dir:
        return check_generated(folder, derived, scenario, Path(build_dir), options)


@dataclass(frozen=True)
class ModelRun:
    """What the main job did for one model."""

    generation: GenerationResult
    checks: list[ConformanceResult]

    @property
    def passed(self) -> bool:
        return all(r.passed(CONFORMANCE_TOLERANCE) for r in self.checks)


def generate_and_check_all(out_root: Path, progress=print) -> list[ModelRun]:
    """Generate every built-in model into ``out_root`` and check its code."""
    from modelgen.modelfile import builtin_models

    runs = []
    for name in builtin_models():
        progress(f"generate + check {name} ...")
        result = generate(name, out_root)
        runs.append(ModelRun(result, check(result.derived, result.folder)))
    return runs


def run_report(verification_summary: str, runs: list[ModelRun], out_root: Path, extra_sections: list[str]) -> str:
    """The short Markdown report of the main job (no timestamps: byte-stable)."""
    lines = ["# modelgen run: the core paper's model, end to end", ""]
    lines += ["## Paper check (seed 000 table of F, G, H)", "", verification_summary, ""]
    lines += ["## Generated code, compiled and checked against the numpy reference", ""]
    lines += [
        "Check: the generated Python and the C (compiled with "
        "`-std=c99 -Wall -Wextra -Werror -pedantic`) run beside `modelgen.reference`; "
        "'scaled dP' is max |dP_ij| / sqrt(P_ii P_jj) over all steps (tolerance "
        f"{CONFORMANCE_TOLERANCE:g}). The paper's model flies the paper's scenario "
        "(240 steps of 60 s, Doppler update each step); the others a synthetic operating point.",
        "",
        "| model | states | folder | predict (C) | update | Python scaled dP | C scaled dP | C elementwise dP | verdict |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for run in runs:
        g = run.generation
        checks = {r.implementation: r for r in run.checks}
        update = g.code.costs.get("update")
        lines.append(
            f"| {g.derived.model.name} | {g.derived.n_states} | `{out_root / g.derived.model.name}` "
            f"| {g.code.costs['predict (C)'].total} flops | {update.total if update else '-'}"
            f"{' flops' if update else ''} | {checks['python'].max_scaled_P:.1e} | {checks['c'].max_scaled_P:.1e} "
            f"| {checks['c'].max_elementwise_P:.1e} | {'ok' if run.passed else 'FAILED'} |"
        )
    lines.append("")
    for section in extra_sections:
        lines += [section, ""]
    return "\n".join(lines).rstrip() + "\n"


def write_text_atomically(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
