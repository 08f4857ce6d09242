"""Timing of the core paper's covariance analysis (Table 2, six systems, 4 h each).

Run: python bench/bench_covariance.py.  Prints the time of each stage; the
Table 2 computation itself (all six systems, 240 steps each) is the number
issue 3 asks about.  Not a test: timings depend on the machine.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from modelgen.analysis.budget import load_error_budget  # noqa: E402
from modelgen.analysis.report import run_covariance_analysis  # noqa: E402
from modelgen.analysis.scenario import load_scenario  # noqa: E402
from modelgen.analysis.systems import PaperModels, analyse_systems  # noqa: E402


def main() -> None:
    scenario, budget = load_scenario(), load_error_budget()
    t0 = time.perf_counter()
    models = PaperModels.build()
    t1 = time.perf_counter()
    repeats = 5
    for _ in range(repeats):
        analyse_systems(models, scenario, budget)
    t2 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        run_covariance_analysis(out, sensitivity=True, figures=True)
    t3 = time.perf_counter()
    print(f"derive 18-state, 16-state and reduced filter models (sympy + lambdify): {t1 - t0:6.2f} s")
    print(f"Table 2, six systems x {scenario.steps} steps (mean of {repeats}):            {(t2 - t1) / repeats:6.3f} s")
    print(f"whole report incl. inference, 11 sensitivity cases, 6 figures:  {t3 - t2:6.2f} s")


if __name__ == "__main__":
    main()
