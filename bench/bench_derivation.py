"""Time to load the 21-state INS/GNSS model written as navigation equations and derive its error model.

Run: python bench/bench_derivation.py [--repeat N].  Not a test: timings depend on the machine.

Two sides, in one process, each from a cleared sympy cache, best of N runs:

* baseline: ``ins_gnss21`` (the hand-written scalar error equations): read the YAML,
  validate, and derive F, G, H, Q, R (``modelgen.derivation.symbolic.derive``);
* navigation: ``ins_gnss21_nav`` (the same 21-state filter as navigation equations):
  read the YAML, perturb the mechanization and derive the error model with every
  declared approximation and its dropped terms (``modelgen.model.perturbation``),
  then derive F, G, H, Q, R from it as for any model.

CPU time of this process (``time.process_time``: one core, whatever else the machine
runs) and wall time.  Issue 12's target: the navigation side under 5 s on one core.

Large models (issue 31): for each of ``--large`` (default 100 and 200 states, the
augmented models of ``tests/codegen/large_model_support``), from a cleared sympy
cache, best of N runs: CPU seconds to build the model, to derive F, G, H, Q, R and to
generate the code (``generate_code``: Python and C), and their total -- the figure the
codegen-time claims must include.  Targets: 100 states <= 2 s and 200 states <= 5 s of
CPU, derive included.  Writes bench/results/derivation.json and .md with the load.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing
RESULTS = REPO / "bench" / "results"

from sympy.core.cache import clear_cache  # noqa: E402

from modelgen.derivation.symbolic import derive  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402

from modelgen.codegen.generate import generate_code  # noqa: E402
from tests.codegen.large_model_support import large_model  # noqa: E402

TARGET_S = 5.0
LARGE_TARGETS_S = {100: 2.0, 200: 5.0}


def timed_load_and_derive(name: str) -> tuple[float, float, float]:
    """(CPU s to load, CPU s to derive, wall s of both) for one model, from a cleared cache."""
    clear_cache()
    wall, cpu = time.perf_counter(), time.process_time()
    model = load_model(name)
    loaded = time.process_time()
    derived = derive(model)
    assert derived.n_states == 21
    return loaded - cpu, time.process_time() - loaded, time.perf_counter() - wall


def best(name: str, repeat: int) -> tuple[float, float, float]:
    """The run with the least total CPU time."""
    return min((timed_load_and_derive(name) for _ in range(repeat)), key=lambda r: r[0] + r[1])


def timed_large(n: int) -> dict:
    """CPU s to build, derive and generate the code of the n-state augmented model, from a cleared cache."""
    clear_cache()
    wall, cpu = time.perf_counter(), time.process_time()
    model = large_model(n)
    built = time.process_time()
    derived = derive(model)
    derived_at = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        generate_code(derived)
    done = time.process_time()
    return {"states": n, "build_cpu_s": built - cpu, "derive_cpu_s": derived_at - built, "codegen_cpu_s": done - derived_at,
            "total_cpu_s": done - cpu, "wall_s": time.perf_counter() - wall}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per side (best is kept)")
    parser.add_argument("--large", type=int, nargs="*", default=[100, 200], help="sizes of augmented models to time")
    args = parser.parse_args()
    load_before = os.getloadavg()
    load_model("ins_gps15")  # import everything once so neither side pays for imports
    scalar = best("ins_gnss21", args.repeat)
    navigation = best("ins_gnss21_nav", args.repeat)
    print(f"{'model':<34}{'load CPU s':>11}{'derive CPU s':>14}{'total CPU s':>13}{'wall s':>9}")
    for label, (load, deriving, wall) in (
        ("ins_gnss21 (scalar error equations)", scalar),
        ("ins_gnss21_nav (navigation eqs.)", navigation),
    ):
        print(f"{label:<34}{load:>11.2f}{deriving:>14.2f}{load + deriving:>13.2f}{wall:>9.2f}")
    total = navigation[0] + navigation[1]
    print(f"ratio navigation / scalar (CPU): {total / (scalar[0] + scalar[1]):.2f}")
    print(f"target: navigation side < {TARGET_S:.0f} s on one core: {'met' if total < TARGET_S else 'missed'} ({total:.2f} s)")
    large = [min((timed_large(n) for _ in range(args.repeat)), key=lambda r: r["total_cpu_s"]) for n in args.large]
    load_after = os.getloadavg()
    lines = ["| states | build CPU s | derive CPU s | codegen CPU s | total CPU s | wall s | target | |",
             "|---|---|---|---|---|---|---|---|"]
    for r in large:
        target = LARGE_TARGETS_S.get(r["states"])
        verdict = "" if target is None else ("met" if r["total_cpu_s"] <= target else "missed")
        r["target_cpu_s"] = target
        lines.append(f"| {r['states']} | {r['build_cpu_s']:.2f} | {r['derive_cpu_s']:.2f} | {r['codegen_cpu_s']:.2f} "
                     f"| {r['total_cpu_s']:.2f} | {r['wall_s']:.2f} | {'' if target is None else f'<= {target:.0f} s'} | {verdict} |")
    table = "\n".join(lines) + "\n"
    print(table)
    load = (f"Load average (1, 5, 15 min) on {os.cpu_count()} cores: {' '.join(f'{v:.2f}' for v in load_before)} before, "
            f"{' '.join(f'{v:.2f}' for v in load_after)} after the run.")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "derivation.json").write_text(json.dumps({
        "load_before": load_before, "load_after": load_after, "cores": os.cpu_count(), "repeat": args.repeat,
        "navigation": {"model": "ins_gnss21_nav", "load_cpu_s": navigation[0], "derive_cpu_s": navigation[1], "wall_s": navigation[2]},
        "scalar": {"model": "ins_gnss21", "load_cpu_s": scalar[0], "derive_cpu_s": scalar[1], "wall_s": scalar[2]},
        "large": large}, indent=2) + "\n")
    (RESULTS / "derivation.md").write_text(
        "# Derivation and code generation time (bench/bench_derivation.py)\n\n"
        f"CPU time of one process (best of {args.repeat}, each from a cleared sympy cache).  {load}\n\n"
        f"ins_gnss21_nav (navigation equations): load {navigation[0]:.2f} s + derive {navigation[1]:.2f} s CPU; "
        f"ins_gnss21 (scalar error equations): {scalar[0]:.2f} s + {scalar[1]:.2f} s.\n\n"
        "Augmented models (tests/codegen/large_model_support): build the model, derive F, G, H, Q, R, generate the "
        "Python and C code (`generate_code`):\n\n" + table)
    print(load)


if __name__ == "__main__":
    main()
