"""Time to load the 21-state INS/GNSS model written as navigation equations and derive its error model.

Run: python bench/bench_derivation.py [--repeat N].  Not a test: timings depend on the machine.

Two sides, in one process, each from a cleared sympy cache, best of N runs:

* baseline: ``ins_gnss21`` (the hand-written scalar error equations): read the YAML,
  validate, and derive F, G, H, Q, R (``modelgen.derive.symbolic.derive``);
* navigation: ``ins_gnss21_nav`` (the same 21-state filter as navigation equations):
  read the YAML, perturb the mechanization and derive the error model with every
  declared approximation and its dropped terms (``modelgen.model.perturbation``),
  then derive F, G, H, Q, R from it as for any model.

CPU time of this process (``time.process_time``: one core, whatever else the machine
runs) and wall time.  Issue 12's target: the navigation side under 5 s on one core.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from sympy.core.cache import clear_cache  # noqa: E402

from modelgen.derive.symbolic import derive  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402

TARGET_S = 5.0


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per side (best is kept)")
    args = parser.parse_args()
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


if __name__ == "__main__":
    main()
