#!/usr/bin/env python
"""Benchmark: the optimization presets of the generated Makefile (issue 14, item 5), on the paper's model.

The generated Makefile is run as a user runs it (``make PRESET=...``), and the
library it builds is linked into the benchmark harness (bench/harness.c) with
bench_cycle.py's glue of the full cycle (b): evaluate, discretize and predict
from the parameters, at the paper's step T = 60 s and at T = 1 s.

* ``portable`` (-O2) against ``host`` (-O3 -march=native): wall time per cycle,
  the best of ROUNDS runs of each, interleaved so that both see the same load
  of a shared machine; callgrind instructions where valgrind decodes the code
  (-march=native may use instructions it cannot, e.g. AVX-512), and of -O3
  without -march=native, to tell the two flags apart;
* the float filter for the Cortex-M4F: ``.text`` of the library that
  ``PRESET=cortex-m4f`` (-O2) and ``PRESET=cortex-m4f-size`` (-Os) build
  (arm-none-eabi-size; skipped without arm-none-eabi-gcc).

Writes bench/results/presets.json and .md.  usage: python bench/bench_presets.py
"""

from __future__ import annotations

import json
import platform
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import bench_codegen as bc  # noqa: E402
import bench_cycle as cycle  # noqa: E402

from modelgen.codegen.generate import generate_code, write_atomically  # noqa: E402
from modelgen.codegen.options import CodegenOptions  # noqa: E402

RESULTS = HERE / "results"
ROUNDS = 15
ITERATIONS = 20000
MODEL = "ned_doppler18"


def make_library(source: Path, folder: Path, preset: str, cflags: str | None = None) -> Path:
    """``make PRESET=preset`` (and CFLAGS, when given) in a copy of the generated folder; the archive it builds."""
    shutil.copytree(source, folder)
    command = ["make", "-s", f"PRESET={preset}"] + ([f"CFLAGS={cflags}"] if cflags else [])
    bc.run(command, cwd=folder)
    return folder / f"lib{MODEL}.a"


def wall_ns(exes: dict[str, Path], data: Path) -> dict[str, float]:
    """Best time per cycle of each build over ROUNDS interleaved runs."""
    best = {name: float("inf") for name in exes}
    for k in range(ROUNDS):
        bc.progress(f"wall time, round {k + 1} of {ROUNDS}")
        for name, exe in exes.items():
            out = bc.run([str(exe), str(data), "time", "predict", str(ITERATIONS)]).stdout
            best[name] = min(best[name], float(out.split()[0]))
    return best


def instructions(exe: Path, data: Path) -> float | None:
    """Callgrind instructions per cycle, None when valgrind cannot run the code."""
    try:
        return bc.callgrind_instructions(exe, data, "predict")
    except RuntimeError as error:
        if "unhandled instruction" in str(error) or "SIGILL" in str(error):  # an instruction valgrind cannot decode
            return None
        raise


def text_bytes(library: Path) -> int:
    """.text of an archive (the sum over its objects)."""
    out = bc.run(["arm-none-eabi-size", "-t", str(library)]).stdout.splitlines()
    return int(out[-1].split()[0])


def main() -> int:
    p = cycle.problem(MODEL)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-presets-") as tmp:
        root = Path(tmp)
        data = bc.input_file(p, root)
        gen = root / "double"
        write_atomically(gen, generate_code(p["derived"]).files)
        libraries = {
            "portable (-O2)": make_library(gen, root / "portable", "portable"),
            "host (-O3 -march=native)": make_library(gen, root / "host", "host"),
            "-O3 alone": make_library(gen, root / "o3", "portable", "-std=c99 -O3 -Wall -Wextra"),
        }
        for T, label in p["steps"]:
            bc.progress(f"building the cycle at T = {T:g} s")
            exes = {}
            for k, (name, library) in enumerate(libraries.items()):
                folder = root / f"cycle-{k}-{T}"
                folder.mkdir()
                exes[name] = bc.build_harness(folder, cycle.glue_generated_cycle(p, T), [], p, includes=(gen,), libraries=(library,))
            walls = wall_ns(exes, data)
            for name, exe in exes.items():
                bc.progress(f"T = {T:g} s: instructions of {name}")
                rows.append({"kind": "cycle", "T": T, "step": label, "build": name, "wall_ns": walls[name],
                             "instructions": instructions(exe, data)})
        if shutil.which("arm-none-eabi-gcc"):
            floats = root / "float"
            write_atomically(floats, generate_code(p["derived"], CodegenOptions(scalar="float")).files)
            for preset in ("cortex-m4f", "cortex-m4f-size"):
                bc.progress(f"Cortex-M4F: make PRESET={preset}")
                rows.append({"kind": "text", "build": preset, "text_bytes": text_bytes(make_library(floats, root / preset, preset))})
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "presets.json").write_text(json.dumps(rows, indent=2))
    (RESULTS / "presets.md").write_text(markdown(rows))
    print(markdown(rows))
    return 0


def markdown(rows: list[dict]) -> str:
    """The results as the Markdown table of bench/results/presets.md."""
    lines = [
        f"# Build presets of the generated Makefile (bench/bench_presets.py), {MODEL}",
        "",
        f"{platform.machine()}; the full cycle (b) of bench_cycle.py (evaluate, discretize, predict from the parameters),"
        f" double; wall time: best of {ROUNDS} interleaved runs of {ITERATIONS} cycles; instructions: callgrind per cycle"
        " (n/a: valgrind cannot decode the code that -march=native made).",
        "",
        "| T [s] | build | wall [ns] | vs portable | instructions |",
        "|---|---|---:|---:|---:|",
    ]
    for row in rows:
        if row["kind"] != "cycle":
            continue
        base = next(r["wall_ns"] for r in rows if r["kind"] == "cycle" and r["T"] == row["T"] and r["build"].startswith("portable"))
        count = f"{row['instructions']:.0f}" if row["instructions"] is not None else "n/a"
        lines.append(f"| {row['T']:g} | {row['build']} | {row['wall_ns']:.0f} | {row['wall_ns'] / base:.3f} | {count} |")
    texts = [r for r in rows if r["kind"] == "text"]
    if texts:
        lines += ["", "Float filter for the Cortex-M4F (`--scalar float`), `.text` of the library `make PRESET=...` builds:", "",
                  "| preset | .text [B] |", "|---|---:|"]
        lines += [f"| {r['build']} | {r['text_bytes']} |" for r in texts]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
