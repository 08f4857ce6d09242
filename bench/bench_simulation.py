"""Benchmark of the navigation simulation: the single run's time, the compiled filter cycle, streaming memory.

For the core paper's flight (profile_000, 300 Hz IMU, 18-state Doppler filter
every 1 s, Doppler every 60 s), the generated C filter, one seed:

  * one correction mode (closed loop):
      old  -- held trajectory and sensors (every IMU increment in memory), the
              Python filter loop calling the C through ctypes once per call;
      new  -- streamed trajectory and sensors (30-s pieces; the truth positions
              integrated by the pieces, once, as ``modelgen simulate`` does for
              the Doppler radar), the compiled loop
              (modelgen/simulation/native_loop.py) running mechanization, glue
              and the C filter with no Python per cycle;
    their closed-loop histories are compared bit for bit.  The new mode is
    given two ways: the filter alone (mechanization, glue, C filter: a one-mode
    pass minus a pass over the data with no mode) and with its data (truth,
    sensor errors, the pass that makes the IMU increments piece by piece and
    flies the mode), CPU and wall.  Beside it: the mechanization alone, the C
    filter alone, and the rest per filter cycle (the glue), old and new;
  * the three modes with their data in one pass (what ``modelgen simulate`` flies);
  * the whole single-run ``modelgen simulate --runs 0`` (three modes, figures,
    summary) as a fresh process: Python start, imports, derivation, code
    generation and compile included -- once with an empty cache folder (cold:
    the filter's code generated, gcc runs) and then ``--warm-runs`` times (3)
    with the code and the library in it (warm): the fastest of those runs
    (the one the other sessions of a shared machine delayed least) is the
    figure, their median and every wall time recorded beside it;
  * memory: the peak resident size of a fresh process that flies the closed-loop
    flight (derive, build the C, fly) -- old for 4 h, new for 4 h and 24 h.  Peak
    RSS only grows, so each figure comes from its own child process (this script
    with --memory-child).

Wall time and CPU time are both printed: on a shared machine the CPU time is the
figure to compare with the one-core targets; the load averages at start and end
are recorded.  numba's compiled loops come from its on-disk cache (a short
flight first fills it), as for an installed modelgen.

Usage: python bench/bench_simulation.py [--hours 4] [--long-hours 24] [--warm-runs 3] [--skip-memory] [--memory-only]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from modelgen.derivation.symbolic import derive
from modelgen.model.loading import load_model
from modelgen.simulation.filter_loop import MODES
from modelgen.simulation.filters import filter_factory
from modelgen.simulation.flight import profile_layout, simulate_sensors
from modelgen.simulation.scenario import load_profile
from modelgen.simulation.streaming import PIECE_SECONDS, cycles_per_piece, fly_modes, history_every
from modelgen.simulation.strapdown import Strapdown
from modelgen.simulation.trajectory import generate_trajectory

TARGETS = {"peak RSS [MiB]": 250.0, "one mode [s]": 1.0, "simulate [s]": 4.0}


class Clock:
    """Wall and CPU seconds of a block."""

    def __enter__(self):
        self.wall, self.cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall, self.cpu = time.perf_counter() - self.wall, time.process_time() - self.cpu


def peak_rss_mib() -> float:
    """Peak resident set size of this process so far [MiB].

    Linux's VmHWM (/proc/self/status) where there is one: ru_maxrss survives
    exec, so a child started by a big parent would report the parent's peak.
    """
    status = Path("/proc/self/status")
    if status.is_file():
        for line in status.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def progress(label: str):
    state = {"next": 0.25, "t": time.perf_counter()}

    def report(done: int, total: int) -> None:
        if done / total >= state["next"] or done == total:
            print(f"    {label}: {100 * done / total:5.1f} % ({time.perf_counter() - state['t']:.1f} s)", flush=True)
            while state["next"] <= done / total:
                state["next"] += 0.25

    return report


def fly(scenario, derived, make, streamed: bool, glue: str, modes=("closed_loop",), label: str = "",
        record_every: int = 1):
    """Trajectory, sensors and the flight; (results, timings)."""
    # streamed: the truth positions integrated by the pieces where the aiding sensor does not read them (Doppler)
    positions_in_pieces = streamed and not getattr(scenario.aiding_sensor, "reads_truth_position", True)
    with Clock() as c_trajectory:
        trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0 / scenario.filter.period, streamed=streamed,
                                         positions_in_pieces=positions_in_pieces)
    layout = profile_layout(scenario, derived, trajectory)
    with Clock() as c_sensors:
        sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(0))
    with Clock() as c_fly:
        results = fly_modes(scenario, derived, trajectory, sensors, layout, make, modes, glue=glue,
                            progress=(lambda mode: progress(f"{label} {mode}")) if label else None,
                            record_every=record_every)
    return results, trajectory, {"trajectory": c_trajectory, "sensors": c_sensors, "fly": c_fly}


def increments_clock(scenario) -> "Clock":
    """The ideal IMU increments of the whole flight alone (trajectory._increments), in the pieces the new mode's pass
    makes them (PIECE_SECONDS of IMU data, the truth positions integrated by the pieces), one after the other."""
    trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0 / scenario.filter.period, streamed=True,
                                     positions_in_pieces=True)
    step = cycles_per_piece(trajectory, PIECE_SECONDS) * trajectory.record_every
    with Clock() as clock:
        for start in range(0, trajectory.n_samples, step):
            trajectory.increments(start, start + step)
    clock.samples = trajectory.n_samples
    return clock


def c_filter_seconds(make, cycles: int) -> float:
    """CPU seconds of the C filter's own work over ``cycles`` cycles: evaluate, discretize, predict (via ctypes)."""
    native = make.native(np.zeros(make.sizes.n), np.eye(make.sizes.n) * 1e-6)
    evaluate, discretize, predict = native.functions[:3]
    params, matrices, transition, filt, workspace = (int(a) for a in native.addresses)
    evaluate(params, matrices)
    count = min(cycles, 3000)
    with Clock() as clock:
        for _ in range(count):
            evaluate(params, matrices)
            discretize(matrices, 1.0, transition, workspace)
            predict(filt, transition, workspace)
    return clock.cpu / count * cycles


def memory_child(hours: float, way: str) -> None:
    """Fly the closed loop once in this fresh process and print its peak RSS as JSON (--memory-child)."""
    scenario = load_profile("profile_000").with_changes(hours=hours)
    derived = derive(load_model(scenario.filter.model))
    with tempfile.TemporaryDirectory() as folder:
        make = filter_factory(derived, "c", folder)
        before = peak_rss_mib()
        # the histories at the rate `modelgen simulate` keeps them (at most MAX_HISTORY_ROWS rows: every 5 s at 24 h)
        cycles = round(scenario.path.duration / scenario.filter.period)
        record_every = history_every(cycles) if way == "new" else 1
        results, trajectory, clocks = fly(scenario, derived, make, way == "new", "compiled" if way == "new" else "python",
                                          record_every=record_every)
    print(json.dumps({"hours": hours, "way": way, "peak_rss_mib": peak_rss_mib(), "before_flight_mib": before,
                      "record_every": record_every,
                      "cycles": len(trajectory.truth) - 1, "updates": results["closed_loop"].updates,
                      "cpu_s": clocks["fly"].cpu + clocks["trajectory"].cpu + clocks["sensors"].cpu}))


def measure_memory(hours: float, way: str) -> dict:
    print(f"  memory: {way} way, {hours:g} h in a fresh process ...", flush=True)
    out = subprocess.run([sys.executable, __file__, "--memory-child", way, "--hours", str(hours)], check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure_time(scenario, derived, report: dict) -> None:
    """One mode (filter only, and with its data), the three-mode pass, old vs new, in this process (module docstring)."""
    with tempfile.TemporaryDirectory() as folder:
        make = filter_factory(derived, "c", folder)
        warm = scenario.with_changes(hours=30 / 3600)  # numba compilation or cache load, not timed
        for streamed, glue in ((False, "python"), (True, "compiled")):
            fly(warm, derived, make, streamed, glue)

        # -- old: held data, Python loop ----------------------------------------------------------
        old, trajectory, t_old = fly(scenario, derived, make, False, "python", label="old")
        cycles = len(trajectory.truth) - 1
        with Clock() as c_mech:  # the mechanization alone over the same samples (held data, ideal increments)
            ins = Strapdown(trajectory.initial_state(), scenario.imu_rate, scenario.coning)
            ins.run(trajectory.delta_theta, trajectory.delta_velocity, 0, cycles * trajectory.record_every)
        del trajectory
        # -- new: streamed, compiled loop: the data alone, one mode, three modes ------------------
        _, _, t_data = fly(scenario, derived, make, True, "compiled", modes=())
        c_increments = increments_clock(scenario)
        new, _, t_one = fly(scenario, derived, make, True, "compiled", label="new")
        _, _, t_three = fly(scenario, derived, make, True, "compiled", modes=MODES)
        c_filter = c_filter_seconds(make, cycles)
        a, b = old["closed_loop"], new["closed_loop"]
        same = all(np.array_equal(getattr(a, f), getattr(b, f)) for f in ("outputs", "estimation_error", "sigma"))

        def data_cpu(t):  # truth, sensors (IMU errors, aiding) and the pieces' IMU increments
            return t["trajectory"].cpu + t["sensors"].cpu

        filter_only = t_one["fly"].cpu - t_data["fly"].cpu  # what the mode adds to a pass over the data
        one_cpu = data_cpu(t_one) + t_one["fly"].cpu
        one_wall = t_one["trajectory"].wall + t_one["sensors"].wall + t_one["fly"].wall
        three_cpu = data_cpu(t_three) + t_three["fly"].cpu
        three_wall = t_three["trajectory"].wall + t_three["sensors"].wall + t_three["fly"].wall
        old_mode, old_data = t_old["fly"].cpu, data_cpu(t_old)
        glue_old = (old_mode - c_mech.cpu - c_filter) / cycles * 1e6
        glue_new = (filter_only - c_mech.cpu - c_filter) / cycles * 1e6
        target = TARGETS["one mode [s]"]
        print(f"  one mode (closed loop), {cycles} filter cycles, {b.updates} Doppler updates; histories old vs new "
              f"{'bit for bit equal' if same else 'DIFFERENT'}", flush=True)
        print(f"    old (held data, Python loop): data {old_data:.2f} s CPU (truth, every increment, sensors: once), "
              f"the mode {old_mode:.2f} s CPU (wall {t_old['fly'].wall:.2f} s)", flush=True)
        print(f"    new, the filter alone (mechanization, glue, C filter: a one-mode pass minus a pass over the data "
              f"alone): {filter_only:.2f} s CPU -> {old_mode / filter_only:.1f}x the old mode; target <= {target} s", flush=True)
        print(f"    new, one mode with its data (truth {t_one['trajectory'].cpu:.2f} + sensors {t_one['sensors'].cpu:.2f} "
              f"+ pass {t_one['fly'].cpu:.2f}, the pass: increments, IMU errors, the mode): {one_cpu:.2f} s CPU, "
              f"wall {one_wall:.2f} s; the data alone {data_cpu(t_data) + t_data['fly'].cpu:.2f} s CPU; target <= {target} s",
              flush=True)
        print(f"    of the data: the ideal IMU increments alone ({c_increments.samples:,} samples, delta theta and delta v "
              f"by Gauss-Legendre over each sample, latitude by RK4, in {PIECE_SECONDS:g}-s pieces): "
              f"{c_increments.cpu:.2f} s CPU ({c_increments.cpu / c_increments.samples * 1e9:.0f} ns per sample), "
              f"wall {c_increments.wall:.2f} s", flush=True)
        print(f"    new, three modes with their data (one pass): {three_cpu:.2f} s CPU, wall {three_wall:.2f} s "
              f"(the pass {t_three['fly'].cpu:.2f} s CPU)", flush=True)
        print(f"    of the mode: mechanization {c_mech.cpu:.2f} s, C filter (evaluate + discretize + predict, "
              f"through ctypes) {c_filter:.2f} s; the rest per filter cycle (glue): old {glue_old:.1f} us, "
              f"new {glue_new:.1f} us", flush=True)
        report["one_mode"] = {
            "cycles": cycles, "bit_for_bit": same, "mechanization_cpu_s": c_mech.cpu, "c_filter_cpu_s": c_filter,
            "old": {"data_cpu_s": old_data, "mode_cpu_s": old_mode, "mode_wall_s": t_old["fly"].wall,
                    "glue_us_per_cycle": glue_old},
            "new": {"filter_only_cpu_s": filter_only, "glue_us_per_cycle": glue_new,
                    "with_data_cpu_s": one_cpu, "with_data_wall_s": one_wall,
                    "truth_cpu_s": t_one["trajectory"].cpu, "sensors_cpu_s": t_one["sensors"].cpu,
                    "one_mode_pass_cpu_s": t_one["fly"].cpu, "data_only_pass_cpu_s": t_data["fly"].cpu,
                    "data_only_cpu_s": data_cpu(t_data) + t_data["fly"].cpu,
                    "increments_cpu_s": c_increments.cpu, "increments_wall_s": c_increments.wall,
                    "increments_samples": c_increments.samples}}
        report["three_modes"] = {"with_data_cpu_s": three_cpu, "with_data_wall_s": three_wall,
                                 "pass_cpu_s": t_three["fly"].cpu, "pass_wall_s": t_three["fly"].wall}

        # -- simulate() itself, in this warm process (imports, numba loading and derivation done) ----------
        from modelgen.simulation.flight_report import simulate

        with tempfile.TemporaryDirectory() as out:
            children = resource.getrusage(resource.RUSAGE_CHILDREN)
            with Clock() as c_sim:
                simulate(scenario, derived, Path(out), runs=0, echo=lambda line: None)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)  # the forked figure process and its copy
            forked = (after.ru_utime - children.ru_utime) + (after.ru_stime - children.ru_stime)
        print(f"  simulate() in this process (three modes, figures, summary; the filter code generated and its "
              f"library taken from the compile cache): CPU {c_sim.cpu + forked:.2f} s (of which the forked figure "
              f"processes {forked:.2f} s), wall {c_sim.wall:.2f} s", flush=True)
        report["simulate_in_process"] = {"cpu_s": c_sim.cpu + forked, "forked_figure_cpu_s": forked, "wall_s": c_sim.wall}


def measure_simulate_runs(hours: float, cache: Path, label: str, runs: int) -> dict:
    """:func:`measure_simulate` ``runs`` times: the fastest run's figures, with the median wall and every run's."""
    measured = [measure_simulate(hours, cache, f"{label}, run {k + 1} of {runs}") for k in range(runs)]
    walls = [r["wall_s"] for r in measured]
    best = dict(min(measured, key=lambda r: r["wall_s"]))
    best.update(runs=runs, median_wall_s=float(np.median(walls)), every_wall_s=walls)
    print(f"  fastest of {runs}: wall {best['wall_s']:.2f} s (median {best['median_wall_s']:.2f} s)", flush=True)
    return best


def measure_simulate(hours: float, cache: Path, label: str) -> dict:
    """The whole ``modelgen simulate --runs 0`` (three modes, figures, summary) as a fresh process; its wall time
    and CPU time (its own and its children's: the C compiler), the filter build time it reports."""
    env = {**os.environ, "MODELGEN_CACHE_DIR": str(cache)}
    with tempfile.TemporaryDirectory() as out:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "modelgen", "simulate", "--hours", str(hours), "--runs", "0",
                        "--out", str(Path(out) / "simulation")], check=True, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        summary = (Path(out) / "simulation" / "summary.md").read_text(encoding="utf-8")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    steps = {}
    for line in summary.split("## Timings", 1)[1].split("## Figures", 1)[0].strip().splitlines()[2:]:
        step, seconds = line.strip("|").rsplit("|", 1)
        steps[step.strip()] = float(seconds)
    print(f"  whole `modelgen simulate --runs 0` ({label}): wall {wall:.2f} s, CPU {cpu:.2f} s (this process and the "
          f"compiler; Python start, imports, derivation included); target <= {TARGETS['simulate [s]']} s", flush=True)
    for step, seconds in steps.items():
        print(f"      {step}: {seconds:.2f} s wall", flush=True)
    return {"wall_s": wall, "cpu_s": cpu, "steps_wall_s": steps}


def _glue_text(us: float) -> str:
    """The new glue per cycle: a difference of CPU times, so below about 1 us it is within their noise."""
    if us < 1.0:
        return f"{us:.1f} us, that is within the noise of zero (a difference of three CPU times)"
    return f"{us:.1f} us"


def markdown(report: dict) -> str:
    """The results as a short Markdown table against the targets (bench/results/simulation.md)."""
    lines = [f"# Simulation benchmark (bench/bench_simulation.py): profile_000, {report['hours']:g} h at "
             f"{report['imu_rate_hz']:g} Hz, generated C filter", "",
             f"Machine: {report['cpu_count']} cores, shared; load average (1, 5, 15 min) "
             f"{', '.join(f'{x:.1f}' for x in report['load_average_at_start'])} at start, "
             f"{', '.join(f'{x:.1f}' for x in report['load_average_at_end'])} at end.  CPU seconds are the "
             "figures for the one-core targets; wall times include waiting for the other sessions.", "",
             "| figure | what it computes | CPU [s] | wall [s] | target |", "|---|---|---|---|---|"]
    if "one_mode" in report:
        one, three = report["one_mode"], report["three_modes"]
        new, old = one["new"], one["old"]
        lines += [
            f"| one mode, filter alone | mechanization, glue and C filter of the closed loop over {one['cycles']} cycles "
            f"(a one-mode pass minus a data-only pass) | {new['filter_only_cpu_s']:.2f} | - | <= 1.0 s |",
            f"| one mode with its data | truth, sensor errors, IMU increments piece by piece, the closed loop | "
            f"{new['with_data_cpu_s']:.2f} | {new['with_data_wall_s']:.2f} | <= 1.0 s |",
            f"| the data alone | truth {new['truth_cpu_s']:.2f} + sensors {new['sensors_cpu_s']:.2f} + a pass integrating the "
            f"truth positions, making and corrupting the increments {new['data_only_pass_cpu_s']:.2f} | {new['data_only_cpu_s']:.2f} | - | - |",
            f"| of the data: the ideal IMU increments alone | delta theta, delta v of the {new['increments_samples']:,} "
            f"samples (Gauss-Legendre nodes, RK4 latitude) in the pass's {PIECE_SECONDS:g}-s pieces, one after the other "
            f"| {new['increments_cpu_s']:.2f} | {new['increments_wall_s']:.2f} | - |",
            f"| three modes with their data | the same data, open loop, closed loop, accumulated in one pass | "
            f"{three['with_data_cpu_s']:.2f} | {three['with_data_wall_s']:.2f} | - |",
            f"| old: one mode | held data, Python loop through ctypes (its data {old['data_cpu_s']:.2f} s CPU not counted) "
            f"| {old['mode_cpu_s']:.2f} | {old['mode_wall_s']:.2f} | - |",
        ]
    if "simulate_in_process" in report:
        r = report["simulate_in_process"]
        lines.append(f"| `simulate()` in a warm process | the same run without Python start, imports, numba loading, "
                     f"derivation (the C from the cache) | {r['cpu_s']:.2f} | {r['wall_s']:.2f} | - |")
    for key, label in (("cold_compile", "cold: the filter's code generated, gcc compiles it"),
                       ("warm_compile", "warm: the filter's code and library from the caches")):
        if key in report.get("simulate", {}):
            r = report["simulate"][key]
            runs = (f"; the fastest of {r['runs']} runs, median wall {r['median_wall_s']:.2f} s" if r.get("runs", 1) > 1
                    else "")
            lines.append(f"| `modelgen simulate --runs 0`, {label} | a fresh process: imports, derivation, code, truth, "
                         f"sensors, three modes, figures, summary (CPU: with the compiler{runs}) | {r['cpu_s']:.2f} | "
                         f"{r['wall_s']:.2f} | <= 4 s |")
    for row in report.get("memory", []):
        lines.append(f"| peak RSS, {row['way']} way, {row['hours']:g} h | a fresh process: derive, build the C, "
                     f"fly the closed loop | - | - | {row['peak_rss_mib']:.0f} MiB (<= 250) |")
    if "one_mode" in report:
        lines += ["", f"Old and new closed-loop histories bit for bit equal: {report['one_mode']['bit_for_bit']}.  "
                  f"Glue per filter cycle (a one-mode pass's CPU minus the mechanization's and the C filter's, each "
                  f"timed on its own): old {report['one_mode']['old']['glue_us_per_cycle']:.1f} us, new "
                  f"{_glue_text(report['one_mode']['new']['glue_us_per_cycle'])}."]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hours", type=float, default=4.0)
    parser.add_argument("--long-hours", type=float, default=24.0)
    parser.add_argument("--skip-memory", action="store_true")
    parser.add_argument("--warm-runs", type=int, default=3, help="fresh warm `modelgen simulate` runs (the fastest is the figure)")
    parser.add_argument("--memory-only", action="store_true", help="only the peak-RSS figures")
    parser.add_argument("--memory-child", choices=("old", "new"), help=argparse.SUPPRESS)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "simulation.json"))
    args = parser.parse_args()
    if args.memory_child:
        memory_child(args.hours, args.memory_child)
        return

    scenario = load_profile("profile_000").with_changes(hours=args.hours)
    derived = derive(load_model(scenario.filter.model))
    report: dict = {"hours": args.hours, "imu_rate_hz": scenario.imu_rate, "cpu_count": os.cpu_count()}
    print(f"profile_000, {args.hours:g} h at {scenario.imu_rate:g} Hz, filter {derived.model.name} (generated C)", flush=True)
    report["load_average_at_start"] = os.getloadavg()
    # the compile cache of this run: a folder of its own (the user's cache is left alone)
    cache_home = tempfile.TemporaryDirectory(prefix="bench-simulation-cache-")
    os.environ["MODELGEN_CACHE_DIR"] = cache_home.name
    if not args.memory_only:
        measure_time(scenario, derived, report)
        # the caches of a fresh folder (modelgen/codegen/build.py's libraries, modelgen/simulation/filters.py's
        # generated files): generated and compiled once (cold), then found (warm)
        with tempfile.TemporaryDirectory() as cache:
            report["simulate"] = {"cold_compile": measure_simulate(args.hours, Path(cache), "cold: the C compiled"),
                                  "warm_compile": measure_simulate_runs(args.hours, Path(cache), "warm: the C from the cache",
                                                                        max(1, args.warm_runs))}

    # -- memory ---------------------------------------------------------------------------------
    if not args.skip_memory:
        # a first short flight fills numba's on-disk cache (compiling the loops takes ~100 MB in the compiler), so
        # that each measured process loads compiled code as an installed modelgen does
        measure_memory(1 / 60, "new")
        rows = [measure_memory(args.hours, "old"), measure_memory(args.hours, "new"), measure_memory(args.long_hours, "new")]
        for row in rows:
            print(f"    {row['way']}: {row['hours']:g} h, peak RSS {row['peak_rss_mib']:.0f} MiB "
                  f"({row['before_flight_mib']:.0f} MiB before the flight: interpreter, numpy, sympy, numba, the model); "
                  f"target <= {TARGETS['peak RSS [MiB]']:.0f} MiB", flush=True)
        print(f"    ratio old / new at {args.hours:g} h: {rows[0]['peak_rss_mib'] / rows[1]['peak_rss_mib']:.1f}x", flush=True)
        report["memory"] = rows
    report["load_average_at_end"] = os.getloadavg()
    report["note"] = ("shared 2-core machine; load averages (1, 5, 15 min) at start and end recorded: CPU seconds "
                      "are the figures to compare with the one-core targets, wall times are inflated by the load")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    Path(args.out).with_suffix(".md").write_text(markdown(report), encoding="utf-8")
    print(f"  wrote {args.out} and {Path(args.out).with_suffix('.md')}")


if __name__ == "__main__":
    main()
