"""What Van Loan's exact Q_d costs in the generated C, against the default Taylor discretize.

    python bench/bench_van_loan.py            # writes bench/results/van_loan.json and .md

Both sides are the generated ``<model>_discretize`` of the paper's model
(ned_doppler18, double, covariance form, full storage, gcc -O2), called with
the same matrices (the paper's level-flight operating point) and step:

* ``taylor`` (the default): Phi by the structured Taylor series and
  Q_d = Gamma (Q/T) Gamma^T (eq. (9)), order and doublings by the accuracy rule;
* ``van-loan`` (``--process-noise van-loan``): Phi and the exact
  Q_d = int_0^T e^{F s} G Q G^T e^{F^T s} ds by the block Taylor series of
  modelgen.codegen.van_loan, under the same rule (plus QD_MARGIN orders).

Per side and step: callgrind instructions per call (deterministic, so the
machine's load does not enter), the workspace struct's bytes, and the
largest error of Phi and Q_d against scipy's expm of Van Loan's block
(modelgen.derivation.discretization.van_loan_discretization) relative to their
largest entry.  The Taylor Q_d's error is its approximation, not rounding.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from modelgen.codegen.backends.c.context import c_context
from modelgen.codegen.build import CompiledFilter, compile_shared_library
from modelgen.codegen.generate import describe, generate_code, write_atomically
from modelgen.codegen.layout import ModelSizes
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.discretization import van_loan_discretization
from modelgen.derivation.symbolic import parameter_vector
from modelgen.jobs import load_and_derive, paper_parameters

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
MODEL = "ned_doppler18"
STEPS = (1.0, 60.0)
CALLS = 20
SIDES = {"taylor": CodegenOptions(), "van-loan": CodegenOptions(process_noise="van-loan")}

DRIVER = """#include <stdio.h>
#include <stdlib.h>
#include "{p}.h"

static {p}_params params;
static {p}_matrices matrices;
static {p}_transition transition;
static {p}_workspace work;

__attribute__((noinline)) int bench_discretize_once(double T)
{{
    return {p}_discretize(&matrices, T, &transition, &work);
}}

int main(int argc, char **argv)
{{
    const double T = atof(argv[1]);
    int k, status = 0;
    {p}_default_params(&params);
{assignments}
    if ({p}_matrices_evaluate(&params, &matrices) != {P}_OK) {{
        return 2;
    }}
    for (k = 0; k < {calls}; ++k) {{
        status |= bench_discretize_once(T);
    }}
    printf("%d\\n", status);
    return status;
}}
"""


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def driver(derived, values: dict[str, float]) -> str:
    """The C driver: the paper's parameters set by name, CALLS calls of discretize."""
    p = derived.model.name
    lines = "\n".join(f"    params.{name} = {float(v)!r};" for name, v in values.items())
    return DRIVER.format(p=p, P=p.upper(), assignments=lines, calls=CALLS)


def instructions_per_call(exe: Path, T: float) -> float:
    """callgrind's instructions inside bench_discretize_once, per call."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        subprocess.run(
            ["valgrind", "--tool=callgrind", "--toggle-collect=bench_discretize_once", f"--callgrind-out-file={out}", str(exe), repr(T)],
            check=True,
            capture_output=True,
        )
        total = int(re.search(r"^(?:totals|summary):\s*(\d+)", out.read_text(), re.M).group(1))
    return total / CALLS


def accuracy(folder: Path, derived, options: CodegenOptions, values: dict[str, float], T: float) -> tuple[float, float]:
    """Largest |error| of Phi and Q_d over their largest entry, against expm of Van Loan's block."""
    name = derived.model.name
    library = compile_shared_library([folder / f"{name}.c"], folder / f"lib{name}.so", ("-O2",))
    filt = CompiledFilter(library, name, ModelSizes.of(derived), derived.model.parameter_names, options=options)
    filt.set_parameters(values)
    if filt.discretize(T) != 0:
        raise RuntimeError(f"{options.slug()}: discretize refused T = {T}")
    m = derived.numeric(values)
    phi, qd = van_loan_discretization(m["F"], m["G"], m["Q"], T)
    return (
        float(np.abs(filt.Phi - phi).max() / np.abs(phi).max()),
        float(np.abs(filt.Qd - qd).max() / np.abs(qd).max()),
    )


def measure(root: Path) -> list[dict]:
    derived = load_and_derive(MODEL)
    values = dict(zip(derived.model.parameter_names, parameter_vector(derived.model, paper_parameters())))
    rows = []
    for side, options in SIDES.items():
        progress(f"{side}: generate and compile")
        folder = write_atomically(root / side, generate_code(derived, options).files)
        (folder / "driver.c").write_text(driver(derived, values))
        exe = folder / "driver"
        subprocess.run(
            ["gcc", "-std=c99", "-O2", "-I", str(folder), str(folder / "driver.c"), str(folder / f"{MODEL}.c"), "-o", str(exe), "-lm"],
            check=True,
        )
        workspace = c_context(describe(derived, options))["struct_bytes"]["workspace"]
        for T in STEPS:
            progress(f"{side}: T = {T:g} s under callgrind")
            phi_error, qd_error = accuracy(folder, derived, options, values, T)
            rows.append(
                {
                    "side": side,
                    "computes": options.describe(),
                    "T": T,
                    "instructions": instructions_per_call(exe, T),
                    "workspace_bytes": workspace,
                    "phi_error": phi_error,
                    "qd_error": qd_error,
                }
            )
    return rows


def markdown(rows: list[dict]) -> str:
    taylor = {r["T"]: r["instructions"] for r in rows if r["side"] == "taylor"}
    lines = [
        f"# Van Loan's exact Q_d against the Taylor discretize ({MODEL}, double, gcc -O2)",
        "",
        "Each row is the generated `discretize` (Phi and Q_d from F, G, q at the paper's level-flight operating point):",
        "`taylor` computes Q_d = Gamma (Q/T) Gamma^T (eq. 9), `van-loan` the exact Q_d by Van Loan's block exponential.",
        "Errors against scipy's expm of Van Loan's block, relative to the largest entry.",
        "",
        "| side | T [s] | instructions per call | ratio to taylor | workspace [B] | Phi error | Q_d error |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['side']} | {r['T']:g} | {r['instructions']:,.0f} | {r['instructions'] / taylor[r['T']]:.2f} | "
            f"{r['workspace_bytes']:,} | {r['phi_error']:.1e} | {r['qd_error']:.1e} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="bench-van-loan-") as tmp:
        rows = measure(Path(tmp))
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "van_loan.json").write_text(json.dumps(rows, indent=2) + "\n")
    (RESULTS / "van_loan.md").write_text(markdown(rows))
    print(markdown(rows))


if __name__ == "__main__":
    main()
