"""Cost of the generated RTS backward pass (Python and C) on the built-in drive's recorded forward pass.

    PYTHONPATH=. python bench/bench_smoother.py     # writes bench/results/smoother.json and .md

For each drive configuration (the 15-state default and the 21-state one): the Python navigator's
forward pass flown with a ForwardRecord, then the backward pass alone (no output rows) by the
generated C (<model>_smooth in the compiled navigator library), the generated Python
(<model>.smooth) and the tests' numpy reference, best of three wall-clock runs each, and the largest
differences of the generated passes from the reference (covariance: relative to the largest
sqrt(P_ii P_jj); error: relative to the largest smoothed error).
"""

from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
sys.path.insert(0, str(HERE.parent))

from modelgen.fileio.datafiles import package_path  # noqa: E402
from modelgen.navigator.cnav import GeneratedC, cached_c_navigator, rest_capacity, window_capacity  # noqa: E402
from modelgen.navigator.config import load_config  # noqa: E402
from modelgen.navigator.errorstate import model_path  # noqa: E402
from modelgen.navigator.logs import read_gnss, read_imu  # noqa: E402
from modelgen.navigator.navigator import fly, prepare  # noqa: E402
from modelgen.navigator.smoother import ForwardRecord, GeneratedPython, record_arrays  # noqa: E402
from modelgen.navigator.spec import navigator_spec  # noqa: E402
from tests.navigator.rts_reference import NumpyReference  # noqa: E402

CONFIGS = ("replay_drive_0708.yaml", "replay_drive_0708_21.yaml")


def _best(function, repeat: int = 3) -> tuple[float, object]:
    best, result = float("inf"), None
    for _ in range(repeat):
        mark = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - mark)
    return best, result


def measure(name: str) -> dict:
    config = load_config(package_path("data", name))
    inputs = prepare(config, read_imu(config.imu_source, config.gap_factor, config.gap_action),
                     read_gnss(config.gnss_source))
    spec = navigator_spec(model_path(config.model, config.path))
    record = ForwardRecord()
    mark = time.perf_counter()
    fly(config, inputs, spec, record=record)
    forward_s = time.perf_counter() - mark
    arrays = record_arrays(record)
    navigator, _ = cached_c_navigator(spec, lambda _: None, rest_capacity(config, inputs.time),
                                      window_capacity(config, inputs.time))
    passes = {"generated C": GeneratedC(navigator), "generated Python": GeneratedPython(spec.module),
              "numpy reference": NumpyReference()}
    timings, results = {}, {}
    for label, backward in passes.items():
        timings[label], results[label] = _best(lambda: backward.smooth(arrays))
    s_ref, P_ref = results["numpy reference"]
    d = np.sqrt(np.einsum("kii->ki", P_ref))
    scale = (d[:, :, None] * d[:, None, :]).max()
    differences = {label: {"covariance_relative": float(np.abs(results[label][1] - P_ref).max() / scale),
                           "error_relative": float(np.abs(results[label][0] - s_ref).max() / np.abs(s_ref).max())}
                   for label in ("generated C", "generated Python")}
    return {"configuration": name, "model": spec.name, "states": spec.n_states, "steps": record.steps,
            "corrections": int(len(arrays.corrections)), "python_forward_pass_s": forward_s,
            "backward_pass_s": timings, "per_step_us": {k: 1e6 * v / record.steps for k, v in timings.items()},
            "difference_from_reference": differences}


def main() -> None:
    rows = [measure(name) for name in CONFIGS]
    RESULTS.mkdir(exist_ok=True)
    out = {"machine": platform.processor() or platform.machine(), "python": platform.python_version(), "runs": rows}
    (RESULTS / "smoother.json").write_text(json.dumps(out, indent=2) + "\n")
    lines = ["# RTS backward pass cost (bench/bench_smoother.py)", "",
             "| configuration | states | steps | C [s] | Python [s] | numpy ref [s] | C - ref (P, rel) | Python - ref (P, rel) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        t, dif = r["backward_pass_s"], r["difference_from_reference"]
        lines.append(f"| {r['configuration']} | {r['states']} | {r['steps']} | {t['generated C']:.3f} | "
                     f"{t['generated Python']:.3f} | {t['numpy reference']:.3f} | "
                     f"{dif['generated C']['covariance_relative']:.1e} | {dif['generated Python']['covariance_relative']:.1e} |")
    (RESULTS / "smoother.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
