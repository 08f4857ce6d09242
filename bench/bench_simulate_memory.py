#!/usr/bin/env python
"""Benchmark (issue 31): peak RSS of `modelgen simulate`, each case a fresh process under /usr/bin/time -v.

Cases: --runs 2 --hours 1 and 4 (target: 4 h <= 300 MiB and <= 1.15x the 1-h figure), --runs 0
--hours 24 (target <= 250 MiB).  One local dask worker (--workers 1).  "Maximum resident set size"
is the largest of the command's processes (the caller, the dask worker, the figure process, the
process deriving the model).  A short flight first fills the compile and trajectory caches and numba's
(not measured), so each case measures a warm start.  Writes bench/results/simulate_memory.json and .md.

usage: nice python bench/bench_simulate_memory.py
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
CASES = [(2, 1.0), (2, 4.0), (0, 24.0)]
#: issue 31: --runs 2 --hours 4 at most 300 MiB and 1.15 times the 1-h figure, --runs 0 --hours 24 at most 250 MiB
TARGETS = {"runs2_4h_mib": 300.0, "ratio_4h_to_1h": 1.15, "runs0_24h_mib": 250.0}


def peak_mib(runs: int, hours: float) -> tuple[float, float]:
    with tempfile.TemporaryDirectory() as out:
        done = subprocess.run(["/usr/bin/time", "-v", sys.executable, "-m", "modelgen", "simulate", "--runs", str(runs), "--hours", str(hours),
                               "--workers", "1", "--out", out, "--force"], capture_output=True, text=True, timeout=900)
    if done.returncode:
        raise RuntimeError(done.stderr[-2000:])
    kib = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", done.stderr).group(1))
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", done.stderr).group(1)
    return kib / 1024.0, wall


def commit() -> str:
    done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parent)
    return done.stdout.strip() or "unknown"


def main() -> None:
    peak_mib(0, 0.05)  # warm-up: the caches, as a user's second run finds them
    rows = []
    for runs, hours in CASES:
        load = os.getloadavg()[0]
        mib, wall = peak_mib(runs, hours)
        rows.append({"runs": runs, "hours": hours, "peak_rss_mib": round(mib, 1), "wall": wall, "load": load})
        print(rows[-1], flush=True)
    one, four = rows[0]["peak_rss_mib"], rows[1]["peak_rss_mib"]
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "simulate_memory.json").write_text(json.dumps({"commit": commit(), "rows": rows, "ratio_4h_to_1h": four / one,
                                                                 "targets": TARGETS}, indent=1) + "\n")
    lines = ["# Peak RSS of `modelgen simulate` (bench/bench_simulate_memory.py)", "",
             "| runs | hours | peak RSS MiB | wall | load |", "|---|---|---|---|---|"]
    lines += [f"| {r['runs']} | {r['hours']:g} | {r['peak_rss_mib']:.1f} | {r['wall']} | {r['load']:.2f} |" for r in rows]
    lines += ["", f"4 h / 1 h (--runs 2): {four / one:.3f} (target <= {TARGETS['ratio_4h_to_1h']}); "
              f"targets: --runs 2 4 h <= {TARGETS['runs2_4h_mib']:g} MiB, --runs 0 24 h <= {TARGETS['runs0_24h_mib']:g} MiB"]
    (RESULTS / "simulate_memory.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
