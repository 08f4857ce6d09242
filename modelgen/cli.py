"""The ``modelgen`` command line.

Each subcommand is a thin wrapper: it parses options, calls one module's
public function and prints where the results went.  ``modelgen run`` is the
main job: derive, verify, generate, compile-check and report.

Errors are handled once, in ``ModelgenGroup.invoke`` (the error boundary):
bad input of any kind (model, scenario, unreadable or unwritable file)
prints ``modelgen: error: <file>[:line]: <what>`` and exits 2, a failed
check exits 1, an interrupt exits 130 and an internal error exits 3; no
traceback is shown unless ``--debug`` is given.  Usage errors keep click's
exit code 2.
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import traceback
import warnings
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType
from typing import Iterator

import click

from modelgen.errors import ModelError
from modelgen.version import __version__

#: Exit codes of every command (README, "Commands").
EXIT_CHECK_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERNAL_ERROR = 3
EXIT_INTERRUPTED = 130

_PRINTER_MODULES = (os.path.join("sympy", "printing"), os.path.join("modelgen", "codegen", "backends"))


def _raised_while_printing(tb: TracebackType | None) -> bool:
    """True if the traceback passes through a code printer (sympy's or modelgen's)."""
    return any(any(m in frame.f_code.co_filename for m in _PRINTER_MODULES) for frame, _ in traceback.walk_tb(tb))


def _os_error_message(exc: OSError) -> str:
    """``<file>: <what>`` for an OSError, naming both files of a rename."""
    what = exc.strerror or str(exc)
    if exc.errno == errno.ENOSPC:
        what += " (the file system is full; nothing was half-written)"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        what += " (choose a writable folder with --out)"
    if exc.filename is not None and exc.filename2 is not None:
        return f"{exc.filename} -> {exc.filename2}: {what}"
    if exc.filename is not None:
        return f"{exc.filename}: {what}"
    return what


def error_message(exc: BaseException) -> tuple[str, int] | None:
    """The user's message and exit code for an exception the boundary handles, else None (internal error)."""
    if isinstance(exc, ModelError):
        return str(exc), EXIT_BAD_INPUT
    if isinstance(exc, UnicodeError):
        reason = exc.reason if isinstance(exc, UnicodeDecodeError) else str(exc)
        return f"input is not UTF-8 text ({reason})", EXIT_BAD_INPUT
    if isinstance(exc, OSError):
        return _os_error_message(exc), EXIT_BAD_INPUT
    if isinstance(exc, RecursionError):
        return "input nested too deeply to process (Python's recursion limit was reached)", EXIT_BAD_INPUT
    if isinstance(exc, MemoryError):
        return "out of memory: the input is too large to process", EXIT_BAD_INPUT
    if isinstance(exc, subprocess.TimeoutExpired):
        command = exc.cmd if isinstance(exc.cmd, str) else " ".join(map(str, exc.cmd))
        return f"{command}: did not finish within {exc.timeout:g} s", EXIT_BAD_INPUT
    if isinstance(exc, (NotImplementedError, TypeError, ValueError)) and _raised_while_printing(exc.__traceback__):
        return f"an expression cannot be printed as code: {exc}", EXIT_BAD_INPUT
    return None


def _forget_nested_interrupt() -> None:
    """Clear CPython's "unhandled KeyboardInterrupt" flag, so that the process exits 130.

    CPython sets that flag whenever a KeyboardInterrupt leaves code run by
    ``eval``/``exec`` of a string (sympy's parser, ``lambdify``), even when
    the exception is caught later, and then ends the process by SIGINT
    instead of with its exit code.  Every string ``exec`` resets the flag first.
    """
    exec("pass")  # noqa: S102 - a constant string: resets the flag, runs nothing


#: How long after a swallowed Ctrl-C it is delivered again (the hook that saw it has long returned by then).
REDELIVERY_DELAY_S = 0.01


@contextmanager
def _interrupts_not_swallowed() -> Iterator[None]:
    """A KeyboardInterrupt that C code swallowed is delivered again, not printed as a traceback.

    Ctrl-C that lands while C calls back into Python (llvmlite's object-cache
    callback while numba compiles, any ctypes callback) raises inside the
    callback, where it cannot propagate: CPython hands it to
    ``sys.unraisablehook``, which printed "Exception ignored ... Traceback" and
    dropped the interrupt, so the command ran on to exit 0.  Here the hook
    has SIGINT sent again to the main thread a moment later (from a timer
    thread: raised in the hook itself it would be swallowed once more, and a
    real signal also ends a blocking wait), which takes it once the C code has
    returned (a callback still inside it is handed here again): one "modelgen:
    interrupted" and exit 130, as for any other Ctrl-C.  Other unraisable
    errors go to the hook that was there before.
    """
    import signal
    import threading

    previous = sys.unraisablehook
    main = threading.main_thread().ident

    def hook(unraisable) -> None:
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            again = threading.Timer(REDELIVERY_DELAY_S, signal.pthread_kill, (main, signal.SIGINT))
            again.daemon = True
            again.start()
        else:
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = previous


def _mapped_echo(update, err: bool = False):
    """``click.echo`` that shows paths in a report's staging folder as their final paths."""
    return lambda message: click.echo(str(message).replace(str(update.staging), str(update.folder)), err=err)


_FORCE_REPORT_HELP = "Overwrite report files of the same name that modelgen did not write or that were edited since."
_SCHEDULER_HELP = ("Address of an existing dask scheduler (tcp://HOST:8786) to run the runs on; default: a local "
                   "cluster started for this command.")
_WORKERS_HELP = "Worker processes of the local cluster (default: one per core; at most 4 per core)."
# the default is modelgen.cluster.CONNECT_TIMEOUT_S, which the CLI does not import (tests/test_architecture.py):
# None passes it on, and tests/test_cli.py checks that the help names its value
_CONNECT_TIMEOUT_HELP = ("Seconds to wait for the dask scheduler at --scheduler before calling it unreachable (exit 2); "
                         "default: 10 s.")


def _connect_timeout_option(command):
    """``--connect-timeout SECONDS`` (None: :data:`modelgen.cluster.CONNECT_TIMEOUT_S`): how long --scheduler is waited for."""
    return click.option("--connect-timeout", "connect_timeout", type=click.FloatRange(min=0, min_open=True),
                        default=None, metavar="SECONDS", help=_CONNECT_TIMEOUT_HELP)(command)


def _check_workers(ctx: click.Context, param: click.Parameter, value: int | None) -> int | None:
    """--workers is refused over its limit as it is parsed, before a model is derived or a flight started."""
    from modelgen.jobs import check_worker_count

    check_worker_count(value)
    return value


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Python warnings as one line, the way users read modelgen's messages."""
    click.echo(f"modelgen: warning: {message}", err=True)


class ModelgenGroup(click.Group):
    """The command group, with the one error boundary around every command."""

    def invoke(self, ctx: click.Context):
        debug = bool(ctx.params.get("debug"))
        with warnings.catch_warnings(), _interrupts_not_swallowed():
            warnings.showwarning = _show_warning
            try:
                return super().invoke(ctx)
            except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
                raise
            except KeyboardInterrupt:
                if debug:
                    raise
                click.echo("modelgen: interrupted", err=True)
                _forget_nested_interrupt()
                raise click.exceptions.Exit(EXIT_INTERRUPTED) from None
            except Exception as exc:  # the one place that turns failures into messages
                if debug or (isinstance(exc, OSError) and exc.errno == errno.EPIPE):
                    raise
                handled = error_message(exc)
                if handled is None:
                    click.echo(
                        f"modelgen: error: internal error: {type(exc).__name__}: {exc} "
                        "(run `modelgen --debug ...` for the traceback, and please report it)",
                        err=True,
                    )
                    raise click.exceptions.Exit(EXIT_INTERNAL_ERROR) from None
                message, code = handled
                click.echo(f"modelgen: error: {message}", err=True)
                raise click.exceptions.Exit(code) from None


@click.group(cls=ModelgenGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(version=__version__, prog_name="modelgen")
@click.option("--debug", is_flag=True, help="Show the Python traceback of an error instead of a one-line message.")
def main(debug: bool) -> None:
    """Turn inertial-navigation error models into verified Kalman-filter code.

    Exit codes: 0 ok, 1 a check failed, 2 bad input or usage (the message
    names the file and line), 3 internal error, 130 interrupted.
    """


@main.command()
@click.argument("model", default="ned_doppler18")
@click.option("--format", "fmt", type=click.Choice(["text", "json", "latex", "octave", "casadi"]), default="text", show_default=True, help="text: one line per entry; json: entries as sympy strings; latex: a table like a paper's; octave: a function file [F,G,H,Q,R] = NAME(p); casadi: a serialized casadi.Function of the parameter vector (needs --out).")
@click.option("--out", "out_file", type=click.Path(dir_okay=False), default=None, help="Write to FILE (atomically) instead of printing; for octave the function is named after FILE's stem.")
@click.option("--force", is_flag=True, help="Replace FILE when it already exists (without it, an existing file is never overwritten).")
def derive(model: str, fmt: str, out_file: str | None, force: bool) -> None:
    """Derive F, G, H, Q, R from MODEL's equations and print the nonzero entries.

    MODEL is a model file (YAML) or the name of a built-in model.  Entries are
    printed simplified for reading (denominators factored, R_M + h kept
    together); --format exports them for LaTeX, Octave/MATLAB, CasADi or JSON.
    """
    from modelgen.errors import ModelError
    from modelgen.fileio.output import refuse_non_regular, write_text_atomically
    from modelgen.jobs import derived_export

    if fmt == "casadi" and out_file is None:
        raise ModelError("--format casadi writes a file: give --out FILE (e.g. --out model.casadi)")
    if out_file is not None:
        refuse_non_regular(Path(out_file))  # before the derivation: a device or pipe is never replaced
    if out_file is not None and Path(out_file).exists() and not force:
        raise ModelError(f"{out_file}: already exists and modelgen does not overwrite a file unasked: "
                         f"give another --out, or --force to replace it")
    name = Path(out_file).stem if out_file is not None and fmt == "octave" else None
    text = derived_export(model, fmt, name)
    if out_file is None:
        click.echo(text, nl=False)
        return
    write_text_atomically(Path(out_file), text)
    click.echo(f"wrote {out_file}")


@main.command()
@click.argument("models", nargs=-1)
@click.option("--out", "out_root", default="generated", show_default=True, type=click.Path(file_okay=False), help="Root folder; code goes to OUT/<model>/.")
@click.option("--taylor-order", default=9, show_default=True, help="Highest order of the Taylor series for Phi and Gamma (eqs. 10-11).")
@click.option("--taylor-tolerance", default=1e-12, show_default=True, type=float, help="Relative accuracy of Phi that chooses the order and doublings at run time (0: the fixed order).")
@click.option("--recompute-threshold", default=None, type=float, help="C discretize keeps its last transition while T is the same and no entry of F, G, q moved by more than this fraction.")
@click.option("--process-noise", type=click.Choice(["taylor", "van-loan"]), default="taylor", show_default=True, help="Q_d as the paper's Gamma (Q/T) Gamma^T (Taylor series), or exact by Van Loan's block exponential (covariance form only).")
@click.option("--scalar", type=click.Choice(["double", "float"]), default="double", show_default=True, help="C scalar type.")
@click.option("--form", type=click.Choice(["covariance", "ud"]), default="covariance", show_default=True, help="Store P, or its UD factors (Thornton time update, Bierman measurement update).")
@click.option("--storage", type=click.Choice(["full", "packed"]), default="full", show_default=True, help="P as N x N or as its packed upper triangle (covariance form).")
@click.option("--update", type=click.Choice(["vector", "sequential"]), default="vector", show_default=True, help="All measurements at once (Cholesky solve) or one scalar at a time (covariance form).")
@click.option("--covariance-update", type=click.Choice(["joseph", "standard"]), default="joseph", show_default=True, help="Joseph form or P - K H P (covariance form).")
@click.option("--all", "all_models", is_flag=True, help="Generate every built-in model.")
@click.option("--check/--no-check", default=False, help="Also compile the C and run it beside the numpy reference, in a staging folder: only code that passes replaces OUT/<model>/ (a failure exits 1 and keeps the previous output).")
@click.option("--force", is_flag=True, help="Overwrite files in OUT/<model>/ that modelgen did not write or that were edited since (files with other names are always kept).")
def generate(
    models: tuple[str, ...], out_root: str, taylor_order: int, taylor_tolerance: float, recompute_threshold: float | None,
    process_noise: str, scalar: str, form: str, storage: str, update: str, covariance_update: str, all_models: bool, check: bool, force: bool,
) -> None:
    """Generate Python and C99 filter code for MODELS (files or built-in names).

    Each model is derived, its code rendered from templates/ and written
    atomically to OUT/<model>/: a failure leaves the previous output intact.
    OUT/<model>/.modelgen-manifest.json records the files modelgen wrote and
    their sha256.  Files and folders it did not write (your main.c, a build/
    folder) are kept.  If a generated file was edited since, or a file of
    yours has the name of a generated file, or the folder exists without a
    manifest, nothing is written unless --force is given.  Concurrent runs
    into one folder wait for each other (lock file OUT/.<model>.lock).
    """
    from pathlib import Path

    from modelgen.jobs import CodegenOptions, builtin_models
    from modelgen.jobs import generate as generate_model

    names = list(models) or (builtin_models() if all_models else ["ned_doppler18"])
    options = CodegenOptions(
        taylor_order=taylor_order, scalar=scalar, form=form, storage=storage, update=update, covariance_update=covariance_update,
        taylor_tolerance=taylor_tolerance or None, recompute_threshold=recompute_threshold, process_noise=process_noise,
    )
    for name in names:
        result = generate_model(name, Path(out_root), options, force=force, with_check=check and scalar == "double")
        model_name = result.derived.model.name
        click.echo(f"{model_name}: {', '.join(sorted(result.code.files))}")
        click.echo(f"  filter: {options.describe()}")
        for kernel, cost in result.code.costs.items():
            click.echo(f"  {kernel}: {cost}")
        if check and scalar == "float":
            click.echo("  check: float code is checked against the double reference by `modelgen embedded`")
        if result.checks:
            click.echo(f"  check scenario: {result.checks[0].scenario}")
        for r in result.checks:
            verdict = "ok" if r.passed() else "FAILED"
            click.echo(
                f"  check {r.implementation}: {r.steps} steps, max scaled dP {r.max_scaled_P:.2e}, "
                f"dx {r.max_scaled_x:.2e}, tolerance {r.tolerance:.1e} -> {verdict}"
            )
        if not result.written:
            click.echo(f"{model_name}: check FAILED; {result.folder} was left as it was", err=True)
            sys.exit(EXIT_CHECK_FAILED)
        click.echo(f"  wrote {result.folder}")


@main.command()
@click.option("--out", "out_root", default="generated", show_default=True, type=click.Path(file_okay=False), help="Root folder for generated code.")
@click.option("--report", "report_dir", default="report", show_default=True, type=click.Path(file_okay=False), help="Folder for the reports.")
@click.option("--no-figures", is_flag=True, help="Skip the covariance-analysis figures.")
@click.option("--simulate/--no-simulate", "with_simulation", default=True, show_default=True, help="Also fly the paper's 4-h profile once (300 Hz strapdown, Doppler filter).")
@click.option("--replay/--no-replay", "with_replay", default=True, show_default=True, help="Also fly the recorded car drive with the generated C navigator (modelgen replay).")
@click.option("--force", is_flag=True, help="As for generate: overwrite files in OUT/<model>/ and in REPORT that modelgen did not write or that were edited.")
def run(out_root: str, report_dir: str, no_figures: bool, with_simulation: bool, with_replay: bool, force: bool) -> None:
    """The main job, end to end on the core paper's 18-state model.

    Derives the model, verifies it entry by entry against the paper's table,
    generates Python and C for every built-in model into OUT/<model>/,
    compiles the C strictly and checks both against the numpy reference,
    cross-checks every hand-written model against its twin derived from the
    navigation equations and the paper's eqs. (1)-(6) from first principles
    (crosscheck.md, paper_equations.md), cross-checks the ECEF and
    wander-azimuth mechanizations against local level (mechanizations.md), runs the paper's covariance
    analysis (Table 2, Figs 2-7), flies the paper's
    profile and the recorded car drive, and writes REPORT/README.md with
    links to everything.
    """
    from pathlib import Path

    from modelgen.fileio.output import ReportUpdate
    from modelgen.jobs import main_job

    with ReportUpdate(Path(report_dir), force=force) as staged:
        job = main_job(staged.staging, Path(out_root), figures=not no_figures, with_simulation=with_simulation,
                       force=force, progress=click.echo, echo=_mapped_echo(staged), with_replay=with_replay)
        staged.commit()
    report = Path(report_dir)
    click.echo(job.text)
    twins_unexplained = job.twins.unexplained if job.twins is not None else 0
    mechanizations_failed = job.mechanizations.failed if job.mechanizations is not None else []
    if job.failed_models or job.verification.unexplained or twins_unexplained or mechanizations_failed:
        reason = ", ".join(job.failed_models) or (
            "unexplained paper differences" if job.verification.unexplained
            else f"{twins_unexplained} unexplained differences between hand-written models and their twins (crosscheck.md)"
            if twins_unexplained else f"mechanization cross-checks failed: {', '.join(mechanizations_failed)} (mechanizations.md)"
        )
        click.echo(f"modelgen run: FAILED ({reason})", err=True)
        sys.exit(EXIT_CHECK_FAILED)
    missed = job.missed_targets
    if missed:  # the checks passed, but a stated target was not reached: said, not called ok (the exit code stays 0)
        click.echo(f"modelgen run: checks passed, {len(missed)} target(s) missed: {'; '.join(missed)}; "
                   f"report in {report / 'README.md'}, code in {out_root}/")
        return
    click.echo(f"modelgen run: ok, every target met; report in {report / 'README.md'}, code in {out_root}/")


@main.command()
@click.argument("model", default="ned_doppler18")
@click.option("--out", "out_dir", default="report", show_default=True, type=click.Path(file_okay=False), help="Folder for embedded.md.")
@click.option("--qemu/--no-qemu", default=True, help="Also run the arm-linux-gnueabihf build under qemu-arm against the reference.")
@click.option("--force", is_flag=True, help=_FORCE_REPORT_HELP)
def embedded(model: str, out_dir: str, qemu: bool, force: bool) -> None:
    """Build MODEL's filter (float: default, UD, packed sequential) for a Cortex-M4F; report size and stack.

    Links a bare-metal image with no heap (the map must show no malloc, free
    or printf), reads .text/.data/.bss and the worst-case stack, and with
    --qemu runs the same code under qemu-arm over the model's check scenario
    against the double reference.  Writes OUT/embedded.md.
    """
    from modelgen.fileio.output import ReportUpdate
    from modelgen.jobs import embedded_inputs, embedded_report, recommended_form

    derived, scenario = embedded_inputs(model, qemu)
    if scenario is not None:
        click.echo(f"scenario: {scenario.label}")
    with ReportUpdate(Path(out_dir), force=force) as staged:
        report = embedded_report(derived, scenario, staged.staging)
        markdown = staged.final(report.markdown)
        staged.commit()
    for slug, b in report.builds.items():
        click.echo(
            f"{slug}: filter .text {b.filter_object.text} .data {b.filter_object.data} .bss {b.filter_object.bss}; "
            f"image .bss {b.image.bss}; worst-case stack predict {b.worst_case_stack.get(derived.model.name + '_predict')} B, "
            f"update {b.worst_case_stack.get(derived.model.name + '_update', '-')} B; heap/stdio: {', '.join(b.forbidden_symbols) or 'none'}"
        )
    failed = False
    for r in report.runs:
        ok = r.within() and r.positive_definite_where_resolvable
        failed |= not ok
        click.echo(
            f"{r.options.slug()} on qemu-arm: max scaled dP {r.max_scaled_P:.2e}, dx {r.max_scaled_x:.2e}, "
            f"tolerance {r.tolerance:.1e} -> {'ok' if ok else 'FAILED'}"
        )
    if report.runs:
        click.echo(recommended_form(report.runs).replace("**", ""))
    click.echo(f"wrote {markdown}")
    if failed or any(b.forbidden_symbols for b in report.builds.values()):
        sys.exit(1)


@main.command()
@click.argument("model", required=False, default=None)
@click.option("--out", "out_dir", default="report", show_default=True, type=click.Path(file_okay=False), help="Folder for verification.md and verification.json.")
@click.option("--table", "table_file", type=click.Path(dir_okay=False), default=None, help="Your own table of F, G, H entries (YAML; README 'Verifying your own paper').")
@click.option("--complete", is_flag=True, default=None, help="Also report every derived nonzero the table does not list (default only for the built-in paper table).")
@click.option("--force", is_flag=True, help=_FORCE_REPORT_HELP)
def verify(model: str | None, out_dir: str, table_file: str | None, complete: bool | None, force: bool) -> None:
    """Check MODEL's derived F, G, H against a paper's printed table.

    MODEL defaults to the model the table names in its `model:` key (with
    --table FILE), else to the core paper's model (ned_doppler18).

    Every entry is compared symbolically after converting to the table's units
    (M = 180*3600/pi); each difference is listed with the classification and
    reason recorded in the table file, and an unexplained one with automatic
    hints (sign flip, unit factor, transposed or misplaced entry, missing
    term).  Without --table the built-in paper table of MODEL is used; with
    it, only the entries the table lists are compared unless --complete.
    Writes OUT/verification.md and OUT/verification.json.  Models without a
    paper table are reported and skipped (exit 0); exit 1 if a difference has
    no annotation (unexplained).
    """
    from modelgen.fileio.output import ReportUpdate
    from modelgen.jobs import differences_summary, first_principles_of, paper_check_of, write_paper_equations_report, write_verification_report

    name, result = paper_check_of(model, table_file, complete or None)
    if result is None:
        click.echo(f"model {name}: no paper table to verify against (only the built-in paper model has one; give yours with --table)")
        return
    first = first_principles_of(name) if table_file is None else None
    with ReportUpdate(Path(out_dir), force=force) as staged:
        markdown, data = (staged.final(p) for p in write_verification_report(result, staged.staging))
        first_files = [staged.final(p) for p in write_paper_equations_report(first, staged.staging)] if first else []
        staged.commit()
    counts = result.counts()
    click.echo(f"model {result.model} against {result.table}: {len(result.entries)} entries, " + ", ".join(f"{n} {s}" for s, n in counts.items()))
    for e in result.differences:
        click.echo(f"  {e.label} {e.status}: {e.classification} - {e.reason}")
        for hint in e.hints:
            click.echo(f"    hint: {hint}")
    for e in result.equation_1_checks:
        if e.is_difference:
            click.echo(f"  {e.label} {e.status} from eq. (1): {e.classification} - {e.reason}")
    for note in result.unused_annotations:
        click.echo(f"  warning: annotation matches no difference: {note}")
    if first is not None:
        click.echo(
            f"the paper from first principles: {first.equations_file} against {first.twin} (derived from the navigation "
            f"equations): {first.compared} entries, {len(first.differences)} differ"
        )
        for line in differences_summary(first):
            click.echo(f"  {line}")
        click.echo(f"wrote {' and '.join(map(str, first_files))}")
    click.echo(f"wrote {markdown} and {data}")
    if result.unexplained:
        click.echo(f"{len(result.unexplained)} unexplained difference(s)", err=True)
        sys.exit(1)


@main.command()
@click.argument("model", default="ned_doppler18")
@click.option("--scenario", "scenario_file", type=click.Path(dir_okay=False), help="Scenario YAML: step, parameters, steps or segments.")
@click.option("--set", "assignments", multiple=True, metavar="NAME=VALUE", help="Parameter value for every segment (repeatable; overrides the scenario file).")
@click.option("--step", type=float, default=None, help="Step T in seconds (default: the scenario's, else 60).")
@click.option("--steps", type=int, default=None, help="Steps of a one-segment scenario (default: the scenario's, else the number of states).")
@click.option("--weak", "weak_rtol", type=float, default=1e-3, show_default=True, help="Relative singular value below which a direction is weakly observable.")
def observability(model: str, scenario_file: str | None, assignments: tuple[str, ...], step: float | None, steps: int | None, weak_rtol: float) -> None:
    """Rank of MODEL's observability matrix over a scenario, and the directions it cannot see.

    Builds O = [H; H Phi; H Phi^2; ...] from the derived F and H at the
    scenario's operating point(s) and names the unobservable and weakly
    observable directions as combinations of states.
    """
    from modelgen.jobs import load_and_derive, observability_analysis, observability_report

    label, report = observability_analysis(load_and_derive(model), scenario_file, assignments, step, steps, weak_rtol)
    if label:
        click.echo(f"scenario: {label}")
    click.echo(observability_report(report))



@main.command()
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="report/covariance", show_default=True, help="Directory for table2.md, table2.csv and the Fig 2-7 PNGs.")
@click.option("--no-figures", is_flag=True, help="Skip the PNG figures.")
@click.option("--no-sensitivity", is_flag=True, help="Skip the sensitivity study.")
@click.option("--force", is_flag=True, help=_FORCE_REPORT_HELP)
def covariance(out_dir: str, no_figures: bool, no_sensitivity: bool, force: bool) -> None:
    """Reproduce the core paper's covariance analysis: Table 2 and Figs 2-7.

    Pure inertial (16 states), optimal Doppler-aided filter (18 states) and the
    four suboptimal filters (true covariance against the 18-state truth model);
    prints our Table 2 beside the paper's with the ratio ours/paper.
    """
    from modelgen.fileio.output import ReportUpdate
    from modelgen.jobs import covariance_analysis

    with ReportUpdate(Path(out_dir), force=force) as staged:
        report = covariance_analysis(
            staged.staging, sensitivity=not no_sensitivity, figures=not no_figures, progress=_mapped_echo(staged, err=True)
        )
        files = [staged.final(p) for p in report.files]
        staged.commit()
    click.echo(report.table)
    click.echo("wrote " + ", ".join(str(p) for p in files))


@main.command()
@click.option("--profile", default="profile_000", show_default=True, help="Scenario file, or a built-in one (modelgen/data/profile_*.yaml).")
@click.option("--hours", type=float, default=None, help="Fly only the first HOURS of the profile (default: all of it).")
@click.option("--runs", type=click.IntRange(min=0), default=20, show_default=True, help="Monte Carlo runs (0: none).")
@click.option("--imu-rate", type=float, default=None, help="IMU rate in Hz (default: the scenario's).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--filter", "implementation", type=click.Choice(["c", "python", "reference"]), default="c", show_default=True, help="Filter of the correction-mode runs: the generated C (compiled now), the generated Python, or the numpy reference.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="report/simulation", show_default=True, help="Directory for summary.md and the PNG figures.")
@click.option("--force", is_flag=True, help=_FORCE_REPORT_HELP)
@click.option("--scheduler", default=None, metavar="ADDRESS", help=_SCHEDULER_HELP)
@_connect_timeout_option
@click.option("--workers", type=click.IntRange(min=1), default=None, help=_WORKERS_HELP, callback=_check_workers)
@click.option("--history-csv", is_flag=True, help="Also write each correction mode's history (output, estimation error, sigma, NEES per recorded cycle) to history_<mode>.csv as it is flown.")
@click.option("--model", "model", default=None, metavar="MODEL", help="Filter model (a built-in name or a model file) instead of the profile's filter.model; its parameters are taken by name from the simulation, its filter.parameters constants or its own defaults (README: 'Flying your own model').")
@click.option("--journal", "journal", type=click.Path(dir_okay=False), default=None, metavar="FILE", help="Keep each completed Monte Carlo run in FILE (JSON lines, written as runs complete); run again with the same FILE to fly only the runs missing from it. A journal of another study (profile, model, filter, seed, runs) is refused.")
def simulate(profile: str, hours: float | None, runs: int, imu_rate: float | None, seed: int, out_dir: str,
             implementation: str, force: bool, scheduler: str | None, connect_timeout: float | None, workers: int | None,
             history_csv: bool, model: str | None, journal: str | None) -> None:
    """Fly a scenario: truth, IMU/Doppler/GPS, strapdown, filter in three correction modes, Monte Carlo.

    Writes summary.md (errors per correction mode, NEES test, timings) and PNG
    figures.  The Monte Carlo runs are dask tasks: on a local cluster (one
    worker per core) unless --scheduler names an existing one; each run's
    seed comes from --seed and its index, so results do not depend on where
    it ran.
    """
    from modelgen.fileio.output import ReportUpdate
    from modelgen.jobs import flight_scenario, simulate_flight

    scenario = flight_scenario(profile, hours, imu_rate, model)
    with ReportUpdate(Path(out_dir), force=force) as staged:
        summary = simulate_flight(scenario, staged.staging, runs, seed, implementation, echo=_mapped_echo(staged, err=True),
                                  scheduler=scheduler, workers=workers, history_csv=history_csv, journal=journal,
                                  connect_timeout_s=connect_timeout)
        summary = staged.final(summary)
        staged.commit()
    click.echo(f"wrote {summary}")
    # the report is written and closed: at exit, skip the interpreter's last garbage collection, a walk over every
    # object of sympy, numba and matplotlib (0.5 s of a 4-s run); the operating system frees the memory
    import atexit
    import gc

    atexit.unregister(gc.freeze)  # once, however often the command runs in one process (tests)
    atexit.register(gc.freeze)


@main.command()
@click.argument("study_file", metavar="STUDY.yaml")
@click.option("--scheduler", default=None, metavar="ADDRESS", help=_SCHEDULER_HELP)
@_connect_timeout_option
@click.option("--workers", type=click.IntRange(min=1), default=None, help=_WORKERS_HELP, callback=_check_workers)
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="report/trade", show_default=True, help="Directory for trade.csv, trade.parquet, the figure and summary.md.")
@click.option("--force", is_flag=True, help=_FORCE_REPORT_HELP)
@click.option("--journal", "journal", type=click.Path(dir_okay=False), default=None, metavar="FILE", help="Keep each completed covariance task in FILE (JSON lines, written as tasks complete); run again with the same FILE to take a stopped study up where it stopped.")
def trade(study_file: str, scheduler: str | None, connect_timeout: float | None, workers: int | None, out_dir: str,
          force: bool, journal: str | None) -> None:
    """Run a trade study: covariance analysis of every case of a grid (or list), Monte Carlo of selected ones.

    STUDY.yaml is a study file or a built-in study's name
    (modelgen/data/studies/).  The file is checked completely before any
    task is submitted.  Writes the case table (CSV and Parquet), a figure of
    the study's metric against its plot parameter per filter, and summary.md.
    """
    from modelgen.fileio.output import ReportUpdate
    from modelgen.jobs import trade_study

    with ReportUpdate(Path(out_dir), force=force) as staged:
        files = trade_study(study_file, staged.staging, scheduler, workers, echo=_mapped_echo(staged, err=True),
                            journal=journal, connect_timeout_s=connect_timeout)
        files = [staged.final(p) for p in files]
        staged.commit()
    click.echo("wrote " + ", ".join(str(p) for p in files))


from modelgen.navigator.cli import replay  # noqa: E402  (`modelgen replay`: the navigator flown on recorded logs)

main.add_command(replay)


if __name__ == "__main__":
    main(prog_name="modelgen")
