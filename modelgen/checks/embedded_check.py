"""The embedded proof: the generated filter on ARM, against the double reference.

Two builds of the same generated C (``modelgen.codegen.toolchain``):

* a bare-metal Cortex-M4F image (single-precision FPU, no heap, no I/O) whose
  link map must hold no allocator or stdio symbol, with its .text/.data/.bss
  and worst-case stack per function;
* a static arm-linux-gnueabihf program run by qemu-arm over the core paper's
  4-hour scenario (240 steps of 60 s, level flight, a Doppler update every
  step), its every step compared with the dense numpy filter in double.

Single-precision tolerance (per run, ``float_tolerance``).  The comparison
uses the scaled differences of ``modelgen.checks.code_check`` (|dP_ij| /
sqrt(P_ii P_jj), |dx_i| / sqrt(P_ii)) and the same a-priori bound as the
double check, with the unit roundoff of float, u = 2^-24 = 6.0e-8, and one
implementation in error (the double reference's own error is 2^29 times
smaller): (2n + 1) u sum_k rho_k, where rho_k measures how much step k's
arithmetic cancels (``modelgen.checks.code_check.step_conditioning``).  For the
paper's 18 states over 240 steps sum_k rho_k is about 1.5e3, so the bound
is 3.3e-3.  It is a worst case; the report gives the measured number beside
it, and says which form to use: the passing form with the smaller measured
error, or the U-D form when it is within a factor 2 of that.  The
covariance form works with P itself, whose condition number the
U-D factors (Bierman/Thornton) halve in digits, so the U-D form is the safe
choice: measured over the built-in check scenarios, gps_pseudorange11 gives
5.3e-4 in the covariance form against 5.2e-6 in U-D (both within its bound
of 2.3e-3); on the other models the two are within a factor 3.

Positive definiteness in single precision.  P is checked through its
correlation matrix C = D^-1/2 P D^-1/2 (Cholesky in double of the float
values).  Entry errors of size e move the eigenvalues of C by at most N e
(Weyl), so a float P can only be required to be positive definite where the
reference's smallest correlation eigenvalue exceeds N times the run's
measured largest entry error e (the measured one, not the a-priori
tolerance: the tolerance is a worst case 100 times the measured error, and
N times it would excuse every step of the paper's scenario).  The paper's
scenario starts from exact zero velocity and position variances, and
right after the first update that eigenvalue is 3e-8, below float
resolution.  The UD form does not need this allowance: its P = U D U^T is
positive definite exactly when every D_i > 0, which is checked at every step.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from modelgen.codegen import toolchain
from modelgen.codegen.options import CodegenOptions
from modelgen.checks.code_check import FLOAT_UNIT_ROUNDOFF, CheckScenario, measurement_sequence, reference_run, scaled_differences, scenario_tolerance
from modelgen.derivation.symbolic import DerivedModel, parameter_vector
from modelgen.errors import ModelError



def float_tolerance(derived: DerivedModel, scenario: CheckScenario, order: int) -> float:
    """Scaled float-vs-double difference allowed over ``scenario`` (see module doc)."""
    return scenario_tolerance(derived, scenario, order, FLOAT_UNIT_ROUNDOFF, 1)


def double_tolerance(derived: DerivedModel, scenario: CheckScenario, order: int) -> float:
    """The double check's tolerance (two double implementations), for the double build under qemu."""
    return scenario_tolerance(derived, scenario, order)

#: What the embedded checks build by default: the default filter in float, and the UD form.
EMBEDDED_OPTIONS = (CodegenOptions(scalar="float"), CodegenOptions(scalar="float", form="ud"))
#: What the report also shows: the leanest covariance form (packed, sequential, standard).
REPORT_OPTIONS = (*EMBEDDED_OPTIONS, CodegenOptions(scalar="float", storage="packed", update="sequential", covariance_update="standard"))
CROSS_TOOLS = (toolchain.ARM_LINUX_CC, toolchain.QEMU_ARM)
FIRMWARE_TOOLS = (toolchain.ARM_EMBEDDED_CC, toolchain.ARM_EMBEDDED_SIZE)


def smallest_correlation_eigenvalue(P: np.ndarray) -> float:
    """lambda_min of D^-1/2 P D^-1/2 (-inf when a variance is not positive)."""
    d = np.diag(P)
    if not np.all(d > 0):
        return float("-inf")
    s = np.sqrt(d)
    return float(np.linalg.eigvalsh(P / np.outer(s, s)).min())


@dataclass
class QemuRun:
    """The qemu-arm run of one option combination, compared with the reference."""

    options: CodegenOptions
    steps: int
    statuses_ok: bool
    max_scaled_P: float
    max_scaled_x: float
    symmetric: bool
    min_correlation_eigenvalue: list[float]  # per step, float result
    reference_min_correlation_eigenvalue: list[float]  # per step, double reference
    n_states: int
    min_D: float | None = None  # UD: smallest D_i over all steps
    seconds: float = 0.0
    tolerance: float = float("nan")  # this run's bound (float_tolerance or double_tolerance)

    @property
    def resolvable_steps(self) -> list[int]:
        """Steps whose reference P is far enough from singular for float to resolve it (Weyl, module doc)."""
        limit = self.n_states * self.max_scaled_P
        return [k for k, lam in enumerate(self.reference_min_correlation_eigenvalue) if lam > limit]

    @property
    def not_positive_definite(self) -> list[int]:
        """Steps whose float P (as stored, or as U D U^T) is not positive definite."""
        return [k for k, lam in enumerate(self.min_correlation_eigenvalue) if not lam > 0]

    @property
    def positive_definite_where_resolvable(self) -> bool:
        bad = set(self.not_positive_definite)
        return not any(k in bad for k in self.resolvable_steps)

    def within(self, tolerance: float | None = None) -> bool:
        """Statuses ok, P symmetric and scaled differences below ``tolerance`` (default: the run's own)."""
        limit = self.tolerance if tolerance is None else tolerance
        return self.statuses_ok and self.max_scaled_P < limit and self.max_scaled_x < limit and self.symmetric


def scenario_inputs(derived: DerivedModel, scenario: CheckScenario) -> tuple[np.ndarray, np.ndarray]:
    """(parameter vector in the params struct's order, measurements per step)."""
    return parameter_vector(derived.model, scenario.parameters), measurement_sequence(derived, scenario)


def qemu_run(derived: DerivedModel, scenario: CheckScenario, options: CodegenOptions, workdir: Path) -> QemuRun:
    """Generate, cross-build, run under qemu-arm and compare every step with the reference."""
    workdir = Path(workdir)
    name = derived.model.name
    folder = toolchain.write_filter(derived, options, workdir / options.slug())
    exe = toolchain.build_arm_linux_driver(folder, name, workdir / f"{options.slug()}.arm")
    params, z = scenario_inputs(derived, scenario)
    data = toolchain.encode_scenario(scenario.steps, params, scenario.step, scenario.x0(), scenario.initial_covariance, z, options.scalar)
    start = time.perf_counter()
    out = toolchain.run_driver(exe, ["run"], stdin=data, qemu=True).stdout
    seconds = time.perf_counter() - start
    steps = toolchain.decode_run(out, derived.n_states, options.scalar, options.ud)
    if len(steps) != scenario.steps:
        raise ModelError(f"qemu run of {name} ({options.slug()}) returned {len(steps)} of {scenario.steps} steps")
    tolerance = (float_tolerance if options.scalar == "float" else double_tolerance)(derived, scenario, options.taylor_order)
    return compare_run(steps, reference_run(derived, scenario, options.taylor_order, options.taylor_tolerance), options, seconds, tolerance)


def compare_run(
    steps: list[toolchain.DriverStep],
    ref: list[tuple[np.ndarray, np.ndarray]],
    options: CodegenOptions,
    seconds: float = 0.0,
    tolerance: float = float("nan"),
) -> QemuRun:
    """Scaled differences, symmetry and definiteness of a driver run against the reference."""
    scaled = [scaled_differences(s.x, s.P, xr, Pr) for s, (xr, Pr) in zip(steps, ref)]
    if options.ud:
        # P = U D U^T: positive definite exactly when every D_i > 0
        lam = [float(s.D.min()) if np.all(s.D > 0) else float("-inf") for s in steps]
    else:
        lam = [smallest_correlation_eigenvalue(s.P) for s in steps]
    run = QemuRun(
        options=options,
        steps=len(steps),
        statuses_ok=all(s.predict_status == 0 and s.update_status == 0 for s in steps),
        max_scaled_P=max(d[0] for d in scaled),
        max_scaled_x=max(d[1] for d in scaled),
        symmetric=all(np.array_equal(s.P, s.P.T) for s in steps),
        min_correlation_eigenvalue=lam,
        reference_min_correlation_eigenvalue=[smallest_correlation_eigenvalue(Pr) for _, Pr in ref],
        n_states=ref[0][1].shape[0],
        min_D=min(float(s.D.min()) for s in steps) if options.ud else None,
        seconds=seconds,
        tolerance=tolerance,
    )
    return run


def firmware(derived: DerivedModel, options: CodegenOptions, workdir: Path) -> toolchain.FirmwareBuild:
    """The bare-metal Cortex-M4F image of the generated filter."""
    workdir = Path(workdir)
    folder = toolchain.write_filter(derived, options, workdir / options.slug())
    return toolchain.build_cortex_m4(folder, derived.model.name, workdir / f"{options.slug()}-m4")


API_FUNCTIONS = ("default_params", "matrices_evaluate", "discretize", "set_covariance", "get_covariance", "predict", "update")


def _meets_tolerance(run: QemuRun) -> bool:
    return run.within() and run.positive_definite_where_resolvable


def _worst_error(run: QemuRun) -> float:
    return max(run.max_scaled_P, run.max_scaled_x)


def recommended_form(runs: list[QemuRun]) -> str:
    """Which single-precision form to use, from the measured runs.

    The passing run with the smallest error, except that the U-D form is
    preferred when its error is within a factor 2 of that: its P = U D U^T is
    positive definite by construction, which the covariance form's is not.
    """
    floats = [r for r in runs if r.options.scalar == "float"]
    if not floats:
        return "No single-precision run: no form to recommend."
    passing = [r for r in floats if _meets_tolerance(r)]
    if not passing:
        return "**No single-precision form meets its tolerance on this scenario: use double precision.**"
    smallest = min(_worst_error(r) for r in passing)
    close = [r for r in passing if _worst_error(r) <= 2 * smallest]
    best = next((r for r in close if r.options.ud), min(close, key=_worst_error))
    failing = [r.options.slug() for r in floats if not _meets_tolerance(r)]
    text = f"**Use `--form {best.options.form}` in single precision** ({best.options.slug()}: measured {best.max_scaled_P:.1e}, tolerance {best.tolerance:.1e})"
    return text + (f"; {', '.join(failing)} do not meet the tolerance." if failing else "; every float form meets its tolerance.")


def report_markdown(model: str, builds: dict[str, toolchain.FirmwareBuild], runs: list[QemuRun], scenario_label: str = "") -> str:
    """The embedded report: sizes, stack, heap-freedom and the qemu comparison."""
    lines = [f"# Embedded report: {model}", ""]
    if builds:
        lines += [
            "## Cortex-M4F (arm-none-eabi-gcc -O2 -mcpu=cortex-m4 -mfpu=fpv4-sp-d16 -mfloat-abi=hard -mthumb)",
            "",
            "Sizes in bytes.  *filter* is the generated object alone; *image* is the linked",
            "bare-metal program (firmware main with every struct in static storage: its .bss is",
            "the RAM the filter needs).  Stack: worst case of the function and its callees",
            "(-fstack-usage, -fcallgraph-info).",
            "",
            "| filter | filter .text | filter .data | filter .bss | image .text | image .data | image .bss | heap/stdio symbols |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for slug, b in builds.items():
            forbidden = ", ".join(b.forbidden_symbols) or "none"
            lines.append(
                f"| {slug} | {b.filter_object.text} | {b.filter_object.data} | {b.filter_object.bss} | "
                f"{b.image.text} | {b.image.data} | {b.image.bss} | {forbidden} |"
            )
        lines += ["", "| filter | " + " | ".join(API_FUNCTIONS) + " | whole program (main) |", "| --- |" + " --- |" * (len(API_FUNCTIONS) + 1)]
        for slug, b in builds.items():
            cells = [str(b.worst_case_stack.get(f"{model}_{fn}", "-")) for fn in API_FUNCTIONS]
            lines.append(f"| {slug} | " + " | ".join(cells) + f" | {b.worst_case_stack.get('main', '-')} |")
        lines.append("")
    if runs:
        lines += [
            f"## qemu-arm (arm-linux-gnueabihf, static) over {scenario_label or 'the check scenario'}",
            "",
            "Scaled differences from the numpy double reference.  Tolerance per run: (2n + 1) u sum_k rho_k",
            "with u = 2^-24 for float (2^-53 and a factor 2 for double), rho_k the cancellation factor of",
            "step k (see modelgen/checks/embedded_check.py and modelgen/checks/code_check.py).",
            "",
            "| filter | steps | max scaled dP | max scaled dx | tolerance | symmetric | steps not positive definite | min D (UD) | run time [s] | verdict |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for r in runs:
            bad = r.not_positive_definite
            bad_text = "none" if not bad else f"{len(bad)} (steps {', '.join(map(str, bad[:5]))}; reference lambda_min {r.reference_min_correlation_eigenvalue[bad[0]]:.1e})"
            verdict = "ok" if r.within() and r.positive_definite_where_resolvable else "FAILED"
            min_d = f"{r.min_D:.2e}" if r.min_D is not None else "-"
            lines.append(
                f"| {r.options.slug()} | {r.steps} | {r.max_scaled_P:.2e} | {r.max_scaled_x:.2e} | {r.tolerance:.1e} | {r.symmetric} | "
                f"{bad_text} | {min_d} | {r.seconds:.2f} | {verdict} |"
            )
        lines += ["", recommended_form(runs), ""]
    return "\n".join(lines)


@dataclass
class EmbeddedReport:
    markdown: Path
    builds: dict[str, toolchain.FirmwareBuild] = field(default_factory=dict)
    runs: list[QemuRun] = field(default_factory=list)


def embedded_report(derived: DerivedModel, scenario: CheckScenario | None, out_dir: Path, options: tuple[CodegenOptions, ...] = REPORT_OPTIONS) -> EmbeddedReport:
    """Build every option combination for the Cortex-M4F and (given a scenario) run it under qemu-arm."""
    missing = toolchain.missing_tools(*FIRMWARE_TOOLS, *(CROSS_TOOLS if scenario is not None else ()))
    if missing:
        skip = ", or pass --no-qemu to skip the qemu-arm run" if set(missing) & set(CROSS_TOOLS) else ""
        raise ModelError(
            f"missing tools: {', '.join(missing)}; install them (Debian/Ubuntu: apt-get install gcc-arm-none-eabi "
            f"libnewlib-arm-none-eabi gcc-arm-linux-gnueabihf libc6-dev-armhf-cross qemu-user){skip}"
        )
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    report = EmbeddedReport(out_dir / "embedded.md")
    with tempfile.TemporaryDirectory(prefix="modelgen-embedded-") as work:
        for opt in options:
            report.builds[opt.slug()] = firmware(derived, opt, Path(work))
            if scenario is not None:
                report.runs.append(qemu_run(derived, scenario, opt, Path(work)))
    label = scenario.label if scenario is not None else ""
    report.markdown.write_text(report_markdown(derived.model.name, report.builds, report.runs, label), encoding="utf-8")
    return report
