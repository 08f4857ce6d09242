"""The ``modelgen`` command line.

Each subcommand is a thin wrapper: it parses options, calls one module's
public function and prints where the results went.  ``modelgen run`` is the
main job: derive, verify, generate, compile-check and report.
"""

from __future__ import annotations

import sys

import click

from modelgen.errors import ModelError


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="modelgen")
def main() -> None:
    """Turn inertial-navigation error models into verified Kalman-filter code."""


def fail(exc: Exception) -> None:
    """Print a bad-input error the way a user wants to read it, and exit 2."""
    click.echo(f"modelgen: error: {exc}", err=True)
    sys.exit(2)


@main.command()
@click.argument("model", default="ned_doppler18")
def derive(model: str) -> None:
    """Derive F, G, H, Q, R from MODEL's equations and print the nonzero entries.

    MODEL is a model file (YAML) or the name of a built-in model.
    """
    from modelgen.derivation import derive as derive_model
    from modelgen.modelfile import load_model

    try:
        derived = derive_model(load_model(model))
    except ModelError as exc:
        fail(exc)
    m = derived.model
    click.echo(f"model {m.name}: {derived.n_states} states, {derived.n_noises} noises, {derived.n_measurements} measurements")
    for label, matrix, rows, cols in (
        ("F", derived.F, m.state_names, m.state_names),
        ("G", derived.G, m.state_names, m.noise_names),
        ("H", derived.H, m.measurement_names, m.state_names),
    ):
        for i in range(matrix.shape[0]):
            for j in range(matrix.shape[1]):
                if matrix[i, j] != 0:
                    click.echo(f"{label}({i + 1},{j + 1}) [{rows[i]}, {cols[j]}] = {matrix[i, j]}")


@main.command()
@click.argument("models", nargs=-1)
@click.option("--out", "out_root", default="generated", show_default=True, type=click.Path(file_okay=False), help="Root folder; code goes to OUT/<model>/.")
@click.option("--taylor-order", default=9, show_default=True, help="Terms of the Taylor series for Phi and Gamma (eqs. 10-11).")
@click.option("--scalar", type=click.Choice(["double", "float"]), default="double", show_default=True, help="C scalar type.")
@click.option("--all", "all_models", is_flag=True, help="Generate every built-in model.")
@click.option("--check/--no-check", default=False, help="Also compile the C and run it beside the numpy reference.")
def generate(models: tuple[str, ...], out_root: str, taylor_order: int, scalar: str, all_models: bool, check: bool) -> None:
    """Generate Python and C99 filter code for MODELS (files or built-in names).

    Each model is derived, its code rendered from templates/ and written
    atomically to OUT/<model>/: a failure leaves the previous output intact.
    """
    from pathlib import Path

    from modelgen.codegen.generate import CodegenOptions
    from modelgen.modelfile import builtin_models
    from modelgen.pipeline import CONFORMANCE_TOLERANCE, check as check_code, generate as generate_model

    names = list(models) or (builtin_models() if all_models else ["ned_doppler18"])
    try:
        options = CodegenOptions(taylor_order=taylor_order, scalar=scalar)
        for name in names:
            result = generate_model(name, Path(out_root), options)
            click.echo(f"{result.derived.model.name}: wrote {', '.join(sorted(result.code.files))} to {result.folder}")
            for kernel, cost in result.code.costs.items():
                click.echo(f"  {kernel}: {cost}")
            if check and scalar == "double":
                for r in check_code(result.derived, result.folder, options=options):
                    verdict = "ok" if r.passed(CONFORMANCE_TOLERANCE) else "FAILED"
                    click.echo(
                        f"  check {r.implementation}: {r.steps} steps, max scaled dP {r.max_scaled_P:.2e}, "
                        f"dx {r.max_scaled_x:.2e} -> {verdict}"
                    )
                    if verdict != "ok":
                        sys.exit(1)
    except ModelError as exc:
        fail(exc)


@main.command()
@click.argument("model", default="ned_doppler18")
@click.option("--out", "out_dir", default="report", show_default=True, type=click.Path(file_okay=False), help="Folder for verification.md and verification.json.")
def verify(model: str, out_dir: str) -> None:
    """Check MODEL's derived F, G, H against the paper's printed table.

    Every entry is compared symbolically after converting to the paper's units
    (M = 180*3600/pi); each difference is listed with the classification and
    reason recorded in the table file.  Writes OUT/verification.md and
    OUT/verification.json.  Models without a paper table are reported and
    skipped (exit 0); exit 1 if a difference has no annotation (unexplained).
    """
    from modelgen.derivation import derive as derive_model
    from modelgen.modelfile import load_model
    from modelgen.paper_table import paper_table_path
    from modelgen.verification import verify as verify_model, write_verification_report

    try:
        loaded = load_model(model)
        if paper_table_path(loaded.name) is None:
            click.echo(f"model {loaded.name}: no paper table to verify against (only the built-in paper model has one)")
            return
        result = verify_model(derive_model(loaded))
        markdown, data = write_verification_report(result, out_dir)
    except ModelError as exc:
        fail(exc)
    counts = result.counts()
    click.echo(f"model {result.model} against {result.table}: {len(result.entries)} entries, " + ", ".join(f"{n} {s}" for s, n in counts.items()))
    for e in result.differences:
        click.echo(f"  {e.label} {e.status}: {e.classification} - {e.reason}")
    for e in result.equation_1_checks:
        if e.is_difference:
            click.echo(f"  {e.label} {e.status} from eq. (1): {e.classification} - {e.reason}")
    for note in result.unused_annotations:
        click.echo(f"  warning: annotation matches no difference: {note}")
    click.echo(f"wrote {markdown} and {data}")
    if result.unexplained:
        click.echo(f"{len(result.unexplained)} unexplained difference(s)", err=True)
        sys.exit(1)


if __name__ == "__main__":
    main()
