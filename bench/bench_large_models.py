#!/usr/bin/env python
"""Benchmark: generated code for large models, unrolled against compact prediction kernels.

For the paper's 18-state model, the 32-state augmented model and augmented
models of 48 to 200 states (``tests/codegen/large_model_support.large_model``:
``ned_doppler32_augmented`` plus Gauss-Markov and random-constant sensor
errors), per model:

* derive and codegen wall time in process (``generate_code``, both languages,
  first call in the process: cold caches), the largest generated file;
* for each prediction kernel -- ``unrolled`` (straight-line code over the
  structural nonzeros of Phi) and ``compact`` (loops over the CSR pattern of
  Phi, ``modelgen.codegen.kernels``), forced by setting
  ``kernels.COMPACT_ABOVE_FLOPS`` -- the C compile time of the filter at -O2,
  its .text size, and the wall time per covariance prediction in the
  benchmark harness (bench/harness.c, best of three runs);
* instructions per prediction (valgrind's callgrind: deterministic, where
  the wall time on a shared machine is not);
* the wall time and instructions of the same prediction by the dense C filter
  (bench/dense_filter.c: P = Phi P Phi^T + Q_d with triple loops), the
  baseline of the ratios, measured in the same run.

The unrolled kernel of the largest models takes minutes to compile, so it is
measured only up to ``--unrolled-up-to`` states (default 64).  The default
rule (what ``modelgen generate`` emits) is shown beside each row; the
threshold ``COMPACT_ABOVE_FLOPS`` is justified by the rows below and above
it.  Writes bench/results/large_models.json, .md and .png.

Targets (issue 14, item 4): 100 states codegen <= 3 s, compile <= 10 s at
-O2, .text <= 300 kB, prediction <= 0.05x dense C; 200 states codegen
<= 15 s and no file over 5 MB; the paper's model codegen <= 0.3 s.

usage: nice python bench/bench_large_models.py [--sizes 18 32 48 64 100 200] [--unrolled-up-to 64]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))  # runs from a fresh clone without installing
sys.path.insert(0, str(HERE))

from bench_codegen import GLUE_DENSE, build_harness, callgrind_instructions, glue_generated, input_file, run  # noqa: E402

from modelgen.checks.code_check import measurement_sequence  # noqa: E402
from modelgen.codegen import kernels  # noqa: E402
from modelgen.codegen.generate import describe, generate_code, write_atomically  # noqa: E402
from modelgen.derivation import reference  # noqa: E402
from modelgen.derivation.discretization import taylor_discretization, taylor_process_noise  # noqa: E402
from modelgen.derivation.symbolic import derive  # noqa: E402
from modelgen.jobs import synthetic_scenario  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402
from tests.codegen.large_model_support import large_model  # noqa: E402

OPT = "-O2"
RESULTS = HERE / "results"
START = time.perf_counter()
BUILTIN = {18: "ned_doppler18", 32: "ned_doppler32_augmented"}


def progress(message: str) -> None:
    print(f"[{time.perf_counter() - START:7.1f} s] {message}", flush=True)


def model_of(n: int):
    """The built-in model of that size, else an augmented one."""
    return load_model(BUILTIN[n]) if n in BUILTIN else large_model(n)


def problem(derived) -> dict:
    """Numeric Phi, Q_d and a covariance after ten filter cycles on the synthetic scenario (harness input)."""
    scenario = synthetic_scenario(derived)
    m = derived.numeric(scenario.parameters)
    phi, gamma = taylor_discretization(m["F"], m["G"], scenario.step, 9)
    qd = taylor_process_noise(gamma, m["Q"], scenario.step)
    x, P = scenario.x0(), scenario.initial_covariance.copy()
    zs = measurement_sequence(derived, scenario)
    for z in zs[:10]:
        x = phi @ x
        P = reference.predict_covariance(P, phi, qd)
        x, P = reference.update(x, P, z, m["H"], m["R"])
    return {"Phi": phi, "Qd": qd, "P": P, "x": x, "H": m["H"], "r": np.diag(m["R"]).copy(), "z": zs[10],
            "n": derived.n_states, "m": derived.n_measurements}


def generate(derived, compact: bool | None) -> tuple[float, dict[str, str]]:
    """(codegen seconds, files) with the default rule (None) or a forced kernel."""
    saved = kernels.COMPACT_ABOVE_FLOPS
    if compact is not None:
        kernels.COMPACT_ABOVE_FLOPS = -1 if compact else 10**12
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            start = time.perf_counter()
            code = generate_code(derived)
            return time.perf_counter() - start, code.files
    finally:
        kernels.COMPACT_ABOVE_FLOPS = saved


def compile_seconds_and_text(source: Path) -> tuple[float, int]:
    """gcc OPT -c wall time and the object's .text bytes."""
    obj = source.with_suffix(".o")
    start = time.perf_counter()
    subprocess.run(["gcc", "-std=c99", OPT, "-c", str(source), "-o", str(obj)], check=True)
    seconds = time.perf_counter() - start
    text = int(subprocess.run(["size", str(obj)], capture_output=True, text=True, check=True).stdout.split("\n")[1].split()[0])
    return seconds, text


def wall_ns(exe: Path, data: Path, n: int) -> float:
    """Best of three harness runs, ns per prediction; about 2e8 dense flops per run whatever the size."""
    iterations = max(20, min(20000, int(5e7 / n**3)))
    return min(float(run([str(exe), str(data), "time", "predict", str(iterations)]).stdout.split()[0]) for _ in range(3))


def kernel_row(derived, p: dict, data: Path, folder: Path, compact: bool) -> dict:
    name = derived.model.name
    seconds, files = generate(derived, compact)
    gen = folder / ("compact" if compact else "unrolled")
    write_atomically(gen, files)
    compile_s, text = compile_seconds_and_text(gen / f"{name}.c")
    exe = build_harness(Path(tempfile.mkdtemp(dir=folder)), glue_generated(name), [gen / f"{name}.c"], p, includes=(gen,))
    return {"codegen_s": seconds, "compile_s": compile_s, "text_bytes": text, "c_bytes": len(files[f"{name}.c"]),
            "predict_ns": wall_ns(exe, data, derived.n_states),
            "predict_instructions": callgrind_instructions(exe, data, "predict")}


def measure(n: int, unrolled_up_to: int, folder: Path) -> dict:
    progress(f"{n} states: deriving")
    start = time.perf_counter()
    derived = derive(model_of(n))
    derive_s = time.perf_counter() - start
    codegen_s, files = generate(derived, None)  # the first generation in this process: cold caches
    description = describe(derived)
    structure = description.structure
    row = {
        "states": n, "model": derived.model.name, "derive_s": derive_s, "codegen_s": codegen_s,
        "largest_file_bytes": max(len(t.encode()) for t in files.values()),
        "phi_nonzeros": int(structure.Phi.sum()), "unrolled_flops": kernels.unrolled_predict_flops(structure),
        "default": "compact" if description.compact else "unrolled",
    }
    progress(f"{n} states: codegen {codegen_s:.2f} s ({row['default']}); compiling and timing")
    p = problem(derived)
    data = input_file(p, folder)
    dense = build_harness(Path(tempfile.mkdtemp(dir=folder)), GLUE_DENSE, [HERE / "dense_filter.c"], p)
    row["dense_predict_ns"] = wall_ns(dense, data, n)
    row["dense_predict_instructions"] = callgrind_instructions(dense, data, "predict")
    for compact in (False, True):
        if not compact and n > unrolled_up_to:
            continue
        kind = "compact" if compact else "unrolled"
        row[kind] = kernel_row(derived, p, data, folder, compact)
        row[kind]["ratio_to_dense"] = row[kind]["predict_ns"] / row["dense_predict_ns"]
        row[kind]["instruction_ratio_to_dense"] = row[kind]["predict_instructions"] / row["dense_predict_instructions"]
        progress(f"  {kind}: compile {row[kind]['compile_s']:.1f} s, .text {row[kind]['text_bytes'] / 1e3:.0f} kB, "
                 f"predict {row[kind]['predict_ns'] / 1e3:.1f} us = {row[kind]['ratio_to_dense']:.3f}x dense C, "
                 f"{row[kind]['predict_instructions']:.0f} instructions = {row[kind]['instruction_ratio_to_dense']:.3f}x")
    return row


def markdown(rows: list[dict]) -> str:
    lines = [
        "| states | Phi nonzeros | unrolled flops | default | codegen s | largest file kB | kernel | compile s (-O2) "
        "| .text kB | predict us | dense C us | ratio to dense | predict instructions | ratio to dense |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for kind in ("unrolled", "compact"):
            if kind not in r:
                continue
            k = r[kind]
            lines.append(
                f"| {r['states']} | {r['phi_nonzeros']} | {r['unrolled_flops']} | {r['default']} | {r['codegen_s']:.2f} "
                f"| {r['largest_file_bytes'] / 1e3:.0f} | {kind} | {k['compile_s']:.2f} | {k['text_bytes'] / 1e3:.0f} "
                f"| {k['predict_ns'] / 1e3:.2f} | {r['dense_predict_ns'] / 1e3:.1f} | {k['ratio_to_dense']:.3f} "
                f"| {k['predict_instructions']:.0f} | {k['instruction_ratio_to_dense']:.4f} |"
            )
    return "\n".join(lines) + "\n"


def figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for kind, marker in (("unrolled", "o-"), ("compact", "s-")):
        sub = [r for r in rows if kind in r]
        n = [r["states"] for r in sub]
        axes[0].loglog(n, [r[kind]["compile_s"] for r in sub], marker, label=kind)
        axes[1].loglog(n, [r[kind]["text_bytes"] / 1e3 for r in sub], marker, label=kind)
        axes[2].semilogx(n, [r[kind]["ratio_to_dense"] for r in sub], marker, label=kind)
    axes[0].set(xlabel="states", ylabel="gcc -O2 compile time [s]", title="compile time")
    axes[1].set(xlabel="states", ylabel=".text [kB]", title="object code size")
    axes[2].set(xlabel="states", ylabel="prediction time / dense C [-]", title="wall time per prediction")
    axes[2].axhline(0.05, color="gray", linestyle=":", label="target 0.05 (100 states)")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[18, 32, 48, 64, 100, 200])
    parser.add_argument("--unrolled-up-to", type=int, default=64)
    args = parser.parse_args()
    RESULTS.mkdir(exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            rows.append(measure(n, args.unrolled_up_to, Path(tmp)))
    table = markdown(rows)
    (RESULTS / "large_models.json").write_text(json.dumps(rows, indent=2) + "\n")
    (RESULTS / "large_models.md").write_text(
        "# Large models: unrolled and compact prediction kernels (bench/bench_large_models.py)\n\n"
        f"Threshold: compact above {kernels.COMPACT_ABOVE_FLOPS} unrolled flops (modelgen.codegen.kernels).\n\n" + table
    )
    figure(rows, RESULTS / "large_models.png")
    print(table)
    progress(f"wrote {RESULTS / 'large_models.json'}, .md and .png")


if __name__ == "__main__":
    main()
