#!/usr/bin/env python
"""Benchmark (issue 31): the generated Python predict against dense numpy and a numba CSR loop, in one process.

For the paper's 18-state model (its check scenario, `modelgen.jobs.check_scenario`), the 32-state augmented model and a
100-state augmented model (``tests/codegen/large_model_support``; both the synthetic
scenario, their own check scenario for 32 beside it), every side computes the same
function on the same inputs (Phi and Q_d from the reference discretization, P after ten
filter cycles) and returns the same numbers (checked, P exactly symmetric):

* bare dense numpy: ``Phi @ x``, ``Phi @ P @ Phi.T + Qd`` mirrored, no checks (the baseline);
* numba CSR loop: ``bench/numba_csr_predict.py``'s kernel over Phi's structural pattern
  (outputs preallocated outside the timing, no argument checks);
* the generated ``Filter.predict(Phi, Qd)`` (owns x and P, updates them in place) and the
  functional ``predict(x, P, Phi, Qd)`` (proves P every call: exact symmetry and a
  Cholesky factorization), each with the compiled kernel (``COMPILED = True``, numba) and
  with the numpy path only (``COMPILED = False``, what runs without numba).

Filter timing: each timeit repeat starts from the same x and P, copied into the filter in
the repeat's setup (not timed); within a repeat P evolves call by call (P = Phi P Phi^T +
Q_d, every call the same arithmetic: no value-dependent branch).  CPU time per call (best
of ROUNDS interleaved rounds of 7 repeats; BLAS on one thread).  ratio = dense numpy time /
side's time.  The load average is recorded before and after.

Writes bench/results/python_predict.json and .md.

usage: nice python bench/bench_python_predict.py [18 32 100]
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
import timeit
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import numpy as np  # noqa: E402

from bench_python_module import BUILTIN, dense_predict, inputs, module_for  # noqa: E402
from numba_csr_predict import make as numba_csr_kernel  # noqa: E402
from modelgen.codegen.generate import describe  # noqa: E402
from modelgen.derivation.symbolic import derive  # noqa: E402
from modelgen.jobs import check_scenario, synthetic_scenario  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402
from tests.codegen.large_model_support import large_model  # noqa: E402

RESULTS = HERE / "results"
ROUNDS = 5
NUMBER = 2000  # calls per timeit repeat


def per_call_us(function, setup=lambda: None) -> float:
    timer = timeit.Timer(function, setup=setup, timer=time.process_time)
    return min(timer.repeat(7, NUMBER)) / NUMBER * 1e6


def best(function, setup=lambda: None) -> float:
    return min(per_call_us(function, setup) for _ in range(ROUNDS))


def agree(got, want, what):
    for g, w in zip(got, want):
        assert np.allclose(g, w, rtol=1e-9, atol=1e-12 * np.abs(w).max()), f"{what}: differs from dense numpy"
    assert np.array_equal(got[1], got[1].T), f"{what}: P not exactly symmetric"


def measure(n: int, scenario_kind: str, folder: Path) -> dict:
    derived = derive(load_model(BUILTIN[n]) if n in BUILTIN else large_model(n))
    scenario = check_scenario(derived) if scenario_kind == "check" else synthetic_scenario(derived)
    a = inputs(derived, scenario)
    x, P, Phi, Qd = a["x"], a["P"], a["Phi"], a["Qd"]
    lower = np.tril(np.ones((n, n), dtype=bool), -1)
    dense = dense_predict(lower)
    want = dense(x, P, Phi, Qd)
    module = module_for(derived, folder / f"{n}_{scenario_kind}", None)
    csr = numba_csr_kernel(describe(derived).structure.Phi)
    x_csr, P_csr = np.empty(n), np.empty((n, n))
    csr(Phi, x, P, Qd, x_csr, P_csr, False)
    agree((x_csr, P_csr), want, "numba CSR")
    f = module.Filter(x, P)

    def restore():
        np.copyto(f._x, x)
        np.copyto(f._P, P)

    row = {"states": n, "model": derived.model.name, "scenario": scenario_kind, "load_before": os.getloadavg()}
    times = {}
    for compiled in (True, False):
        module.COMPILED = compiled
        tag = "compiled" if compiled else "numpy"
        agree(module.predict(x, P, Phi, Qd), want, f"functional {tag}")
        restore()
        f.predict(Phi, Qd)
        agree((f.get_state(), f.get_covariance()), want, f"Filter {tag}")
        restore()
        times[f"filter_{tag}"] = best(lambda: f.predict(Phi, Qd), restore)
        times[f"functional_{tag}"] = best(lambda: module.predict(x, P, Phi, Qd))
    module.COMPILED = True
    times["dense_numpy"] = best(lambda: dense(x, P, Phi, Qd))
    times["numba_csr"] = best(lambda: csr(Phi, x, P, Qd, x_csr, P_csr, False))
    row.update({f"{k}_us": v for k, v in times.items()})
    row.update({f"{k}_ratio": times["dense_numpy"] / v for k, v in times.items() if k != "dense_numpy"})
    row["load_after"] = os.getloadavg()
    return row


def markdown(rows: list[dict]) -> str:
    lines = ["# Generated Python predict against dense numpy and a numba CSR loop (bench/bench_python_predict.py)", "",
             "CPU time per call, best of 5 rounds x 7 repeats, BLAS on one thread, all sides in one process on the",
             "same inputs with the same results.  ratio = dense numpy us / side us (>= 2 the Filter's target, >= 1 the",
             "functional API's).  compiled: numba kernel; numpy: the path without numba.", "",
             "| states | scenario | dense numpy us | numba CSR us (ratio) | Filter compiled us (ratio) | Filter numpy us (ratio) "
             "| functional compiled us (ratio) | functional numpy us (ratio) | load before / after |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        cell = lambda k: f"{r[k + '_us']:.2f} ({r[k + '_ratio']:.2f})"  # noqa: E731
        lines.append(f"| {r['states']} | {r['scenario']} | {r['dense_numpy_us']:.2f} | {cell('numba_csr')} | {cell('filter_compiled')} "
                     f"| {cell('filter_numpy')} | {cell('functional_compiled')} | {cell('functional_numpy')} "
                     f"| {r['load_before'][0]:.2f} / {r['load_after'][0]:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    warnings.simplefilter("ignore")
    sizes = [int(s) for s in sys.argv[1:]] or [18, 32, 100]
    cases = [(n, kind) for n in sizes for kind in (("check",) if n == 18 else ("synthetic", "check") if n == 32 else ("synthetic",))]
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for n, kind in cases:
            rows.append(measure(n, kind, Path(folder)))
            print(markdown(rows[-1:]).splitlines()[-1], flush=True)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "python_predict.json").write_text(json.dumps(rows, indent=1) + "\n")
    (RESULTS / "python_predict.md").write_text(markdown(rows))
    print(markdown(rows))


if __name__ == "__main__":
    main()
