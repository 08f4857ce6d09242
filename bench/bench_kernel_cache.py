#!/usr/bin/env python
"""Benchmark (issue 29): a generated module's numba predict kernel compiled, and loaded from the kernel disk cache.

For each model named (default: ned_doppler18), its generated Python module is written
to a temporary folder; then fresh processes, one after another, load the module
with ``$MODELGEN_KERNEL_CACHE_DIR`` set to one empty temporary folder and make the
kernel's first call (``_compiled_predict`` on the module's own shapes): the first
process compiles the kernel and stores it, the later ones load it.  Each process
reports the CPU time (user + sys, ``resource.getrusage``) of that first call alone,
and numba's own count of cache hits and misses, so that a load is known to be one.
The load average is recorded before and after.

Writes bench/results/kernel_cache.json and .md.

usage: python bench/bench_kernel_cache.py [MODEL ...]
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
RESULTS = HERE / "results"
LOADS = 3  # processes after the compiling one

#: Run in a fresh process: load the module, time the kernel's first call, print the numbers as JSON.
FIRST_CALL = """
import json, resource, sys
import numpy as np
from modelgen.codegen.build import load_python_module
module = load_python_module(sys.argv[1])
n = module.N_STATES
x, P, Phi, Qd = np.zeros(n), np.eye(n), np.eye(n), np.eye(n) * 1e-3
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
start = cpu()
ok = module._compiled_predict(x, P, Phi, Qd, np.empty(n), np.empty((n, n)), True)
seconds = cpu() - start
stats = module._compiled_predict.stats
print(json.dumps({"ok": bool(ok), "cpu_s": seconds, "hits": sum(stats.cache_hits.values()),
                  "misses": sum(stats.cache_misses.values())}))
"""


def generated_module(model: str, folder: Path) -> Path:
    """The model's generated Python module, written into ``folder``."""
    from modelgen.codegen.backends.registry import backend
    from modelgen.codegen.generate import describe
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model

    files = backend("python").render(describe(derive(load_model(model))))
    for name, text in files.items():
        (folder / name).write_text(text)
    return folder / f"{model}.py"


def first_calls(module: Path, cache: Path) -> list[dict]:
    """The first call of the kernel in 1 + LOADS fresh processes sharing ``cache``."""
    env = {**os.environ, "MODELGEN_KERNEL_CACHE_DIR": str(cache), "PYTHONPATH": str(REPO)}
    runs = []
    for _ in range(1 + LOADS):
        done = subprocess.run([sys.executable, "-c", FIRST_CALL, str(module)], env=env, capture_output=True,
                              text=True, check=True)
        runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    return runs


def measure(model: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        folder, cache = Path(tmp) / "module", Path(tmp) / "kernels"
        folder.mkdir()
        runs = first_calls(generated_module(model, folder), cache)
    compiled, loads = runs[0], runs[1:]
    assert compiled["ok"] and compiled["misses"] == 1 and not compiled["hits"], compiled
    assert all(r["ok"] and r["hits"] == 1 and not r["misses"] for r in loads), loads
    return {"model": model, "compiled_cpu_s": compiled["cpu_s"], "loaded_cpu_s": [r["cpu_s"] for r in loads]}


def markdown(results: list[dict], load: tuple[float, float]) -> str:
    lines = ["# The predict kernel's first call: compiled, and loaded from the kernel disk cache (issue 29)", "",
             "Produced by `bench/bench_kernel_cache.py`: CPU time (user + sys) of the first `_compiled_predict` call "
             f"in fresh processes sharing one `$MODELGEN_KERNEL_CACHE_DIR`; load average {load[0]:.2f} before, "
             f"{load[1]:.2f} after.", "",
             "| model | compiled (first process) | loaded (later processes) |", "| --- | --- | --- |"]
    for r in results:
        lines.append(f"| {r['model']} | {r['compiled_cpu_s']:.2f} s | "
                     f"{', '.join(f'{s:.2f}' for s in r['loaded_cpu_s'])} s |")
    return "\n".join(lines) + "\n"


def main(models: list[str]) -> None:
    before = os.getloadavg()[0]
    results = [measure(m) for m in models]
    load = (before, os.getloadavg()[0])
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "kernel_cache.json").write_text(json.dumps({"load_average": load, "results": results}, indent=2) + "\n")
    (RESULTS / "kernel_cache.md").write_text(markdown(results, load))
    print(markdown(results, load))


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    main(sys.argv[1:] or ["ned_doppler18"])
