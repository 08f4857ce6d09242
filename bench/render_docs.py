#!/usr/bin/env python
"""The performance figures of README.md and docs/*.md, filled in from bench/results/*.json (one source).

Every figure a page quotes from a benchmark sits in a marked block,

    <!-- bench:NAME -->text with the figures<!-- /bench:NAME -->

and the block's text is what :data:`BLOCKS` [NAME] renders from the committed
results.  Run after a benchmark has written new results:

    python bench/render_docs.py          # rewrite the blocks
    python bench/render_docs.py --check  # exit 1, naming each block that differs

tests/test_bench_figures.py runs the check on the committed pages and results,
so a page cannot drift from bench/results.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results"
PAGES = ("README.md", "docs/*.md")
BLOCK = re.compile(r"<!-- bench:(?P<name>[a-z0-9_]+) -->(?P<text>.*?)<!-- /bench:(?P=name) -->", re.S)


class Results:
    """bench/results/NAME.json, each read once; :attr:`used` names the files read."""

    def __init__(self, folder: Path = RESULTS):
        self.folder, self.used, self._cache = folder, set(), {}

    def __call__(self, name: str):
        if name not in self._cache:
            path = self.folder / f"{name}.json"
            self._cache[name] = json.loads(path.read_text(encoding="utf-8"))
            self.used.add(path)
        return self._cache[name]


def _kb(n_bytes: float) -> str:
    return f"{n_bytes / 1000:.0f} kB"


def _row(rows: list[dict], **match) -> dict:
    found = [r for r in rows if all(r.get(k) == v for k, v in match.items())]
    if len(found) != 1:
        raise KeyError(f"{len(found)} rows match {match}")
    return found[0]


def large_models_threshold(results: Results) -> str:
    rows = results("large_models")
    r32, r48 = _row(rows, states=32), _row(rows, states=48)
    unrolled, compact = r48["unrolled"], r48["compact"]
    return (f"between the 32-state augmented model, {r32['unrolled_flops']:,}, and a 48-state one, "
            f"{r48['unrolled_flops']:,}, whose unrolled code took {unrolled['compile_s']:.1f} s to compile and "
            f"{_kb(unrolled['text_bytes'])} of `.text` against {compact['compile_s']:.2f} s and "
            f"{_kb(compact['text_bytes'])}, for a prediction {compact['predict_ns'] / unrolled['predict_ns']:.2f} "
            f"times faster")


def large_models_sizes(results: Results) -> str:
    rows = results("large_models")
    r100, r200 = _row(rows, states=100), _row(rows, states=200)
    k100 = r100[r100["default"]]
    return (f"at 100 states codegen takes {r100['codegen_s']:.2f} s, the compile {k100['compile_s']:.2f} s, "
            f"`.text` is {_kb(k100['text_bytes'])} and a prediction {k100['ratio_to_dense']:.3f} times the dense "
            f"C's wall time ({k100['instruction_ratio_to_dense']:.3f} times its instructions); at 200 states "
            f"codegen takes {r200['codegen_s']:.2f} s and the largest file is {_kb(r200['largest_file_bytes'])}")


def _three(rows: list[dict], part: str, key: str = "ratio") -> str:
    values = [f"{r[part][key]:.2f}" for r in rows]
    return ", ".join(values[:-1]) + " and " + values[-1]


def python_module(results: Results) -> str:
    data = results("python_module")
    rows = sorted(data["rows"], key=lambda r: r["states"])
    states = ", ".join(str(r["states"]) for r in rows[:-1]) + " and " + str(rows[-1]["states"])
    checked = [r[part]["checked_ratio"] for r in rows
               for part in ("predict", "predict_filter", "update", "update_filter")]
    tests = ", ".join(f"{r['predict']['p_test_us']:.1f}" for r in rows[:-1]) + f" and {rows[-1]['predict']['p_test_us']:.1f}"
    return (f"Against bare numpy (load average {data['load_before'][0]:.1f} at the start, on {data['cores']} "
            f"cores), the `Filter` predicts {_three(rows, 'predict_filter')} times as fast at {states} states and "
            f"updates {_three(rows, 'update_filter')} times as fast; discretize (one function for both) is "
            f"{_three(rows, 'discretize')} times as fast. The functional API predicts {_three(rows, 'predict')} and "
            f"updates {_three(rows, 'update')} times as fast: its test of P costs {tests} µs a call, which bare "
            f"numpy skips; against checked numpy (the same contract in plain numpy) every ratio of both APIs is "
            f"{min(checked):.1f} to {max(checked):.1f}")


def _signed(value: float) -> str:
    return f"−{-value:.0f}" if value < 0 else f"+{value:.0f}"


def presets(results: Results) -> str:
    rows = results("presets")

    def cycle(T: float, build: str) -> dict:
        return _row(rows, kind="cycle", T=T, build=build)

    portable60, host60 = cycle(60.0, "portable (-O2)"), cycle(60.0, "host (-O3 -march=native)")
    portable1, host1 = cycle(1.0, "portable (-O2)"), cycle(1.0, "host (-O3 -march=native)")
    o3_60, o3_1 = cycle(60.0, "-O3 alone"), cycle(1.0, "-O3 alone")
    gains = sorted(100 * (1 - o3["wall_ns"] / portable["wall_ns"]) for o3, portable in ((o3_60, portable60), (o3_1, portable1)))
    text = {r["build"]: r["text_bytes"] for r in rows if r["kind"] == "text"}
    return (f"`host` takes {host60['wall_ns']:,.0f} ns per cycle against {portable60['wall_ns']:,.0f} ns for `-O2` "
            f"at T = 60 s ({_signed(100 * (host60['wall_ns'] / portable60['wall_ns'] - 1))} %) and "
            f"{host1['wall_ns']:,.0f} ns against {portable1['wall_ns']:,.0f} ns at T = 1 s; `-O3` alone gains "
            f"{gains[0]:.1f}–{gains[1]:.1f} % ({o3_60['instructions']:,.0f} instructions against "
            f"{portable60['instructions']:,.0f}); the rest of `host`'s gain is `-march=native`'s (callgrind cannot count its "
            f"AVX-512 code). `.text` of the float filter for the Cortex-M4F: {text['cortex-m4f'] / 1000:.1f} kB at "
            f"`-O2`, {text['cortex-m4f-size'] / 1000:.1f} kB at `-Os`")


def derivation(results: Results) -> str:
    data = results("derivation")
    navigation, scalar = data["navigation"], data["scalar"]
    total = navigation["load_cpu_s"] + navigation["derive_cpu_s"]
    return (f"CPU time of one core: {total:.2f} s against {scalar['load_cpu_s'] + scalar['derive_cpu_s']:.2f} s on "
            f"the shared development machine; target < 5 s")


def discretize_100(results: Results) -> str:
    rows = [r for r in results("cycle") if r["n"] == 100 and r["impl"] == "modelgen"]
    predict = _row(rows, part="a")["instructions"]
    check, small = _row(rows, part="b", step="check step"), _row(rows, part="b", step="step / 60")
    return (f"discretize costs {(check['instructions'] - predict) / 1e6:.2f}M instructions at T = {check['T']:.3f} s "
            f"(order {check['order']}) and {(small['instructions'] - predict) / 1e6:.2f}M at order {small['order']}")


def cycle(results: Results) -> str:
    """Part (b) of bench_cycle.py, modelgen (full P) against CasADi at each model and step, with instructions per floor flop."""
    rows = [r for r in results("cycle") if r["part"] == "b"]
    steps = sorted({(r["n"], r["T"]) for r in rows}, key=lambda k: (k[0], -k[1]))
    figures = []
    for n, T in steps:
        ours, casadi = _row(rows, n=n, T=T, impl="modelgen"), _row(rows, n=n, T=T, impl="casadi")
        figures.append(f"{ours['instructions']:,.0f} against {casadi['instructions']:,.0f} at {n} states and T = {T:.3g} s "
                       f"({ours['instructions'] / casadi['instructions']:.2f} times; "
                       f"{ours['instructions'] / ours['floor_flops']:.2f} per flop of the floor)")
    return "part (b), modelgen's C against CasADi's in instructions per call: " + "; ".join(figures)


def van_loan(results: Results) -> str:
    rows = results("van_loan")
    ratios = sorted(_row(rows, side="van-loan", T=T)["instructions"] / _row(rows, side="taylor", T=T)["instructions"]
                    for T in (1.0, 60.0))
    more = _row(rows, side="van-loan", T=1.0)["workspace_bytes"] - _row(rows, side="taylor", T=1.0)["workspace_bytes"]
    return (f"The exact form costs {ratios[0]:.0f}-{ratios[1]:.0f} times the instructions of the Taylor `discretize` "
            f"and {more / 1000:.1f} kB more workspace")


def montecarlo_worker(results: Results) -> str:
    data = results("montecarlo")
    before = data["before"]["import_cpu_s"] + data["before"]["prepare_cpu_s"]
    filled = sum(step["cpu_s"] for step in data["monte_carlo"]["worker_set_up"]["caches filled"]
                 if not step["step"].startswith("run "))
    return f"a fresh worker's set-up goes from about {before:.0f} s to {filled:.1f} s of CPU"


def simulate_memory(results: Results) -> str:
    data = results("simulate_memory")

    def peak(runs: int, hours: float) -> float:
        return _row(data["rows"], runs=runs, hours=hours)["peak_rss_mib"]

    return (f"Peak resident memory of `modelgen simulate` (the largest of its processes, caches warm, "
            f"`bench/bench_simulate_memory.py`): {peak(2, 1.0):.0f} MiB for 1 h and {peak(2, 4.0):.0f} MiB for 4 h "
            f"with `--runs 2` ({data['ratio_4h_to_1h']:.2f} times), {peak(0, 24.0):.0f} MiB for 24 h with `--runs 0`")


BLOCKS: dict[str, Callable[[Results], str]] = {
    "large_models_threshold": large_models_threshold,
    "large_models_sizes": large_models_sizes,
    "python_module": python_module,
    "presets": presets,
    "derivation": derivation,
    "discretize_100": discretize_100,
    "cycle": cycle,
    "van_loan": van_loan,
    "montecarlo_worker": montecarlo_worker,
    "simulate_memory": simulate_memory,
}


def pages(root: Path = ROOT) -> list[Path]:
    return sorted({path for pattern in PAGES for path in root.glob(pattern)})


def render(text: str, results: Results, where: str = "") -> tuple[str, list[str]]:
    """``text`` with every block rendered; the names of the blocks whose text changed."""
    changed: list[str] = []

    def fill(match: re.Match) -> str:
        name = match["name"]
        if name not in BLOCKS:
            raise KeyError(f"{where}: unknown bench block {name!r} (known: {', '.join(BLOCKS)})")
        new = BLOCKS[name](results)
        if new != match["text"]:
            changed.append(name)
        return f"<!-- bench:{name} -->{new}<!-- /bench:{name} -->"

    return BLOCK.sub(fill, text), changed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="change nothing; exit 1 if a block differs")
    args = parser.parse_args(argv)
    results, stale = Results(), []
    for path in pages():
        text = path.read_text(encoding="utf-8")
        new, changed = render(text, results, str(path.relative_to(ROOT)))
        stale += [f"{path.relative_to(ROOT)}: {name}" for name in changed]
        if changed and not args.check:
            path.write_text(new, encoding="utf-8")
    for line in stale:
        print(("differs from bench/results: " if args.check else "rewritten: ") + line)
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
