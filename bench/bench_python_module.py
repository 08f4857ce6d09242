#!/usr/bin/env python
"""Benchmark: the generated Python module against plain dense numpy, per call, in one run.

For the paper's 18-state model, the 32-state augmented model and a
100-state augmented model (``tests/codegen/large_model_support``), with the
same inputs for both sides (Phi and Q_d from the reference discretization,
a covariance after ten filter cycles):

* ``predict`` -- generated ``predict(x, P, Phi, Qd)``, which checks its
  arguments against the contract (finite; P symmetric and positive
  semidefinite by a Cholesky factorization) and the result, against plain
  dense numpy computing the same function with no checks:
  ``x = Phi @ x``, ``P = Phi @ P @ Phi.T + Qd`` and the same symmetrization
  (upper triangle mirrored into the lower, ``np.copyto(..., where=lower)``);
* ``update`` -- generated ``update(x, P, z, H, r)`` against dense numpy doing
  the same Kalman update form: ``S = H P H^T + R``, ``K = solve(S, H P)^T``,
  the Joseph form ``(P - K H P) - (P - K H P) H^T K^T + K R K^T``, mirrored;
* ``discretize`` -- generated ``discretize(F, G, q, T)`` against
  ``modelgen.derive.discretization`` (the numpy reference: the same balancing,
  order rule, Taylor series and doublings) and ``taylor_process_noise``.

Each side is timed best-of-several with interleaved repeats (CPU time of
the process, BLAS on one thread); the ratio is
baseline time / generated time (>= 1: the generated module is at least as
fast).  The ``checks`` column is what the contract's checks of the
arguments cost in the generated predict and update (timed alone).  For
predict the two kernels the generator chooses between (dense BLAS products,
or gathers by row class of Phi: unit, diagonal, general) are both timed, to
justify the rule ``kernels.python_predict_kernel``.  Writes
bench/results/python_module.json, .md and .png.

Target (issue 14, item 3): ratio >= 1.0 for predict, update and discretize
at 18, 32 and 100 states.

usage: nice python bench/bench_python_module.py [--sizes 18 32 100]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import timeit
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads: one core for both sides
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))  # runs from a fresh clone without installing

from modelgen.checks.code_check import measurement_sequence  # noqa: E402
from modelgen.codegen import kernels  # noqa: E402
from modelgen.codegen.build import load_python_module  # noqa: E402
from modelgen.codegen.backends.registry import backend  # noqa: E402
from modelgen.codegen.generate import describe, write_atomically  # noqa: E402
from modelgen.derive import reference  # noqa: E402
from modelgen.derive.discretization import DEFAULT_TOLERANCE, taylor_discretization, taylor_process_noise  # noqa: E402
from modelgen.derive.symbolic import derive  # noqa: E402
from modelgen.jobs import paper_scenario, synthetic_scenario  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402
from tests.codegen.large_model_support import large_model  # noqa: E402

RESULTS = HERE / "results"
BUILTIN = {18: "ned_doppler18", 32: "ned_doppler32_augmented"}
START = time.perf_counter()


def progress(message: str) -> None:
    print(f"[{time.perf_counter() - START:7.1f} s] {message}", flush=True)


def per_call_us(function, repeats: int = 7) -> float:
    """Best CPU time of this process per call in microseconds (timeit, calls batched to about 20 ms).

    CPU time rather than wall time: on a shared machine the wall clock also
    counts the time other processes hold the core (BLAS is kept to one
    thread: OPENBLAS_NUM_THREADS=1 is set before numpy loads).
    """
    timer = timeit.Timer(function, timer=time.process_time)
    number, _ = timer.autorange()
    number = max(1, number // 10)
    return min(timer.repeat(repeats, number)) / number * 1e6


def module_for(derived, folder: Path, kernel: str | None):
    """The generated Python module with the default kernel rule (None) or a forced predict kernel."""
    saved = kernels.PYTHON_STRUCTURED_SAVING_FLOPS
    if kernel is not None:
        kernels.PYTHON_STRUCTURED_SAVING_FLOPS = -10**12 if kernel == "structured" else 10**15
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            files = backend("python").render(describe(derived))  # the Python module only
    finally:
        kernels.PYTHON_STRUCTURED_SAVING_FLOPS = saved
    out = folder / (kernel or "default")
    write_atomically(out, files)
    return load_python_module(out / f"{derived.model.name}.py")


def inputs(derived, scenario) -> dict:
    m = derived.numeric(scenario.parameters)
    T = scenario.step
    phi, gamma = taylor_discretization(m["F"], m["G"], T, 9, tolerance=DEFAULT_TOLERANCE)
    qd = taylor_process_noise(gamma, m["Q"], T)
    x, P = scenario.x0(), scenario.initial_covariance.copy()
    zs = measurement_sequence(derived, scenario)
    for z in zs[:10]:  # a covariance with the filter's real correlations
        x = phi @ x
        P = reference.predict_covariance(P, phi, qd)
        x, P = reference.update(x, P, z, m["H"], m["R"])
    P = 0.5 * (P + P.T)
    return {"F": m["F"], "G": m["G"], "q": np.diag(m["Q"]).copy(), "T": T, "Phi": phi, "Qd": qd, "x": x, "P": P,
            "H": m["H"], "r": np.diag(m["R"]).copy(), "z": zs[10]}


def dense_predict(lower):
    def predict(x, P, Phi, Qd):
        x_new = Phi @ x
        P_new = Phi @ P @ Phi.T + Qd
        np.copyto(P_new, P_new.T, where=lower)
        return x_new, P_new
    return predict


def dense_update(lower):
    def update(x, P, z, H, r):
        HP = H @ P
        S = HP @ H.T + np.diag(r)
        K = np.linalg.solve(S, HP).T
        x_new = x + K @ (z - H @ x)
        B = P - K @ HP
        P_new = B - (B @ H.T) @ K.T + (K * r) @ K.T
        np.copyto(P_new, P_new.T, where=lower)
        return x_new, P_new
    return update


def dense_discretize(F, G, q, T):
    phi, gamma = taylor_discretization(F, G, T, 9, tolerance=DEFAULT_TOLERANCE)
    return phi, taylor_process_noise(gamma, np.diag(q), T)


def measure(n: int, folder: Path) -> dict:
    derived = derive(load_model(BUILTIN[n]) if n in BUILTIN else large_model(n))
    scenario = paper_scenario(derived) if n == 18 else synthetic_scenario(derived)
    a = inputs(derived, scenario)
    lower = np.tril(np.ones((n, n), dtype=bool), -1)
    chosen = kernels.python_predict_kernel(describe(derived).structure)
    gen = module_for(derived, folder, None)
    variants = {k: module_for(derived, folder, k) for k in ("factored", "structured")}
    x, P, Phi, Qd, H, r, z = (a[k] for k in ("x", "P", "Phi", "Qd", "H", "r", "z"))
    # the same numbers from both sides, so that both compute the same function
    for got, want in ((gen.predict(x, P, Phi, Qd), dense_predict(lower)(x, P, Phi, Qd)),
                      (gen.update(x, P, z, H, r), dense_update(lower)(x, P, z, H, r)),
                      (gen.discretize(a["F"], a["G"], a["q"], a["T"]), dense_discretize(a["F"], a["G"], a["q"], a["T"]))):
        for g, w in zip(got, want):
            assert np.allclose(g, w, rtol=1e-9, atol=1e-12 * np.abs(w).max()), "generated and dense numpy differ"
    row = {"states": n, "model": derived.model.name, "predict_kernel": chosen}
    cases = {
        "predict": (lambda: gen.predict(x, P, Phi, Qd), lambda: dense_predict(lower)(x, P, Phi, Qd)),
        "update": (lambda: gen.update(x, P, z, H, r), lambda: dense_update(lower)(x, P, z, H, r)),
        "discretize": (lambda: gen.discretize(a["F"], a["G"], a["q"], a["T"]),
                       lambda: dense_discretize(a["F"], a["G"], a["q"], a["T"])),
    }
    for name, (generated, baseline) in cases.items():
        g = b = float("inf")
        for _ in range(3):  # interleaved, so that a busy spell hits both sides
            g = min(g, per_call_us(generated))
            b = min(b, per_call_us(baseline))
        row[name] = {"generated_us": g, "dense_numpy_us": b, "ratio": b / g}
        progress(f"{n} states {name}: generated {g:.1f} us, dense numpy {b:.1f} us, ratio {b / g:.2f}")
    row["predict"]["checks_us"] = per_call_us(lambda: (gen._check_finite("predict", x=x, Phi=Phi, Qd=Qd),
                                                      gen._check_covariance("predict", P)))
    row["update"]["checks_us"] = per_call_us(lambda: (gen._check_finite("update", x=x, z=z, H=H, r=r),
                                                     gen._check_covariance("update", P)))
    for kernel, module in variants.items():
        row["predict"][f"{kernel}_kernel_us"] = min(per_call_us(lambda: module.predict(x, P, Phi, Qd)) for _ in range(3))
    progress(f"{n} states predict kernels: factored {row['predict']['factored_kernel_us']:.1f} us, "
             f"structured {row['predict']['structured_kernel_us']:.1f} us; the rule chose {chosen}")
    return row


def markdown(rows: list[dict]) -> str:
    lines = ["| states | function | generated us | dense numpy us | ratio (>= 1: generated faster) | checks us "
             "| predict kernel: factored us | structured us | chosen |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for name in ("predict", "update", "discretize"):
            c = r[name]
            kernel = (f"{c['factored_kernel_us']:.1f} | {c['structured_kernel_us']:.1f} | {r['predict_kernel']}"
                      if name == "predict" else " | | ")
            checks = f"{c['checks_us']:.1f}" if "checks_us" in c else ""
            lines.append(f"| {r['states']} | {name} | {c['generated_us']:.1f} | {c['dense_numpy_us']:.1f} "
                         f"| {c['ratio']:.2f} | {checks} | {kernel} |")
    return "\n".join(lines) + "\n"


def figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    names = ("predict", "update", "discretize")
    width = 0.8 / len(rows)
    for k, r in enumerate(rows):
        ax.bar(np.arange(3) + k * width, [r[nm]["ratio"] for nm in names], width, label=f"{r['states']} states")
    ax.axhline(1.0, color="gray", linestyle=":", label="as fast as dense numpy")
    ax.set_xticks(np.arange(3) + width * (len(rows) - 1) / 2, names)
    ax.set_ylabel("dense numpy time / generated time [-]")
    ax.set_title("generated Python module against dense numpy (per call)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[18, 32, 100])
    args = parser.parse_args()
    RESULTS.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        rows = [measure(n, Path(tmp)) for n in args.sizes]
    table = markdown(rows)
    (RESULTS / "python_module.json").write_text(json.dumps(rows, indent=2) + "\n")
    (RESULTS / "python_module.md").write_text(
        "# Generated Python module against dense numpy (bench/bench_python_module.py)\n\n" + table)
    figure(rows, RESULTS / "python_module.png")
    print(table)
    progress(f"wrote {RESULTS / 'python_module.json'}, .md and .png")


if __name__ == "__main__":
    main()
