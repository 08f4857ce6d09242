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

from modelgen.table2.budget import load_error_budget  # noqa: E402
from modelgen.table2.report import run_covariance_analysis  # noqa: E402
from modelgen.table2.scenario import load_analysis_scenario  # noqa: E402
from modelgen.table2.scenario import operating_point  # noqa: E402
from modelgen.table2.systems import PaperModels, analyse_systems  # noqa: E402
from modelgen.derivation import reference  # noqa: E402
from modelgen.derivation.discretization import taylor_discretization, taylor_process_noise  # noqa: E402
from modelgen.derivation.symbolic import derive  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402


def naive_optimal_filter(models: PaperModels, scenario, budget) -> None:
    """Baseline: one system (the optimal filter) the straightforward way, discretizing every step."""
    values = {**budget.parameters, **operating_point(scenario)}
    P = budget.initial_covariance(models.truth.model)
    for _ in range(scenario.steps):
        m = models.truth.numeric(values)
        phi, gamma = taylor_discretization(m["F"], m["G"], scenario.step_s, scenario.taylor_order)
        P = reference.predict_covariance(P, phi, taylor_process_noise(gamma, m["Q"], scenario.step_s))
        _, P = reference.update(P[:, 0] * 0, P, m["H"][:, 0] * 0, m["H"], m["R"])


def main() -> None:
    scenario, budget = load_analysis_scenario(), load_error_budget()
    t0 = time.perf_counter()
    models = PaperModels.build(derive(load_model("ned_doppler18")))
    t1 = time.perf_counter()
    repeats = 5
    for _ in range(repeats):
        analyse_systems(models, scenario, budget)
    t2 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        run_covariance_analysis(out, models, sensitivity=True, figures=True)
    t3 = time.perf_counter()
    naive_optimal_filter(models, scenario, budget)
    t4 = time.perf_counter()
    print(f"derive 18-state, 16-state and reduced filter models (sympy + lambdify): {t1 - t0:6.2f} s")
    print(f"Table 2, six systems x {scenario.steps} steps (mean of {repeats}):            {(t2 - t1) / repeats:6.3f} s")
    print(f"whole report incl. inference, 11 sensitivity cases, 6 figures:  {t3 - t2:6.2f} s")
    print(f"baseline: optimal filter alone, discretized every step (reference.py): {t4 - t3:6.3f} s")
    print(f"ratio: all six systems / one system the straightforward way = {(t2 - t1) / repeats / (t4 - t3):.2f}")


if __name__ == "__main__":
    main()
