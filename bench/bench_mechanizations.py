"""Time to load and derive the same 21-state INS/GNSS filter in each mechanization (issue 27: ECEF and wander azimuth <= 5 s CPU).

Run: python bench/bench_mechanizations.py [--repeat N].  Not a test: timings depend on the machine.

Each side from a cleared sympy cache, best of N runs, CPU time of this process
(``time.process_time``: one core) and wall time: read the YAML, perturb the
mechanization and derive the error model (``modelgen.model.perturbation``, with
its approximations and dropped terms), then F, G, H, Q, R
(``modelgen.derivation.symbolic.derive``).

* local_level: ``ins_gnss21_nav`` (NED, phi-angle, NED metres; built in);
* ecef: ``modelgen/data/mechanizations/ins_gnss21_ecef.yaml`` (e-frame r, v, C_b^e, phi-angle, J2 gravity);
* wander_azimuth: ``modelgen/data/mechanizations/ins_gnss21_wander.yaml`` (free wander azimuth, psi-angle, computed-frame
  velocity, metres; the same 5 s target).

Writes bench/results/mechanizations.json and .md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing
RESULTS = REPO / "bench" / "results"

from sympy.core.cache import clear_cache  # noqa: E402

from modelgen.derivation.symbolic import derive  # noqa: E402
from modelgen.model.loading import load_model  # noqa: E402

TARGET_S = 5.0
MODELS = {
    "local_level": "ins_gnss21_nav",
    "ecef": str(REPO / "modelgen" / "data" / "mechanizations" / "ins_gnss21_ecef.yaml"),
    "wander_azimuth": str(REPO / "modelgen" / "data" / "mechanizations" / "ins_gnss21_wander.yaml"),
}
TARGETED = ("ecef", "wander_azimuth")


def timed(name: str) -> dict:
    """CPU s to load, CPU s to derive and wall s of both, for one model from a cleared cache."""
    clear_cache()
    wall, cpu = time.perf_counter(), time.process_time()
    model = load_model(name)
    loaded = time.process_time()
    derived = derive(model)
    done = time.process_time()
    return {"load_cpu_s": loaded - cpu, "derive_cpu_s": done - loaded, "total_cpu_s": done - cpu,
            "wall_s": time.perf_counter() - wall, "states": derived.n_states}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per mechanization (best is kept)")
    args = parser.parse_args()
    load_before = os.getloadavg()
    load_model("ins_gps15")  # import everything once so no side pays for imports
    results = {}
    for mechanization, name in MODELS.items():
        results[mechanization] = min((timed(name) for _ in range(args.repeat)), key=lambda r: r["total_cpu_s"])
        results[mechanization]["model"] = Path(name).stem
    load_after = os.getloadavg()
    lines = ["| mechanization | model | states | load CPU s | derive CPU s | total CPU s | wall s | target |",
             "|---|---|---|---|---|---|---|---|"]
    for mechanization, r in results.items():
        verdict = f"<= {TARGET_S:.0f} s: {'met' if r['total_cpu_s'] <= TARGET_S else 'missed'}" if mechanization in TARGETED else ""
        lines.append(f"| {mechanization} | {r['model']} | {r['states']} | {r['load_cpu_s']:.2f} | {r['derive_cpu_s']:.2f} "
                     f"| {r['total_cpu_s']:.2f} | {r['wall_s']:.2f} | {verdict} |")
    table = "\n".join(lines) + "\n"
    load = (f"Load average (1, 5, 15 min) on {os.cpu_count()} cores: {' '.join(f'{v:.2f}' for v in load_before)} before, "
            f"{' '.join(f'{v:.2f}' for v in load_after)} after the run.")
    print(table)
    print(load)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "mechanizations.json").write_text(json.dumps(
        {"load_before": load_before, "load_after": load_after, "cores": os.cpu_count(), "repeat": args.repeat,
         "target_cpu_s": TARGET_S, "results": results}, indent=2) + "\n")
    (RESULTS / "mechanizations.md").write_text(
        "# Load and derive one 21-state INS/GNSS filter per mechanization (bench/bench_mechanizations.py)\n\n"
        f"CPU time of one process (best of {args.repeat}, each from a cleared sympy cache).  {load}\n\n" + table)


if __name__ == "__main__":
    main()
