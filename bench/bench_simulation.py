"""Benchmark of the navigation simulation: streaming memory, the compiled filter cycle, whole `simulate`.

For the core paper's flight (profile_000, 300 Hz IMU, 18-state Doppler filter
every 1 s, Doppler every 60 s), in one process unless said otherwise:

  * one correction mode with the generated C filter, two ways:
      old  -- held trajectory and sensors (every IMU increment in memory), the
              Python filter loop calling the C through ctypes once per call;
      new  -- streamed trajectory and sensors (10-s pieces), the compiled loop
              (modelgen/simulation/native_loop.py) running mechanization, glue and
              the C filter with no Python per cycle;
    both on the same seed (their closed-loop histories are compared).  The old
    way holds its data (made once for all modes); the new way makes its IMU
    pieces once per pass and flies every mode in that pass, so a mode costs
    what a second and third mode add to a one-mode pass.  Beside it: the
    mechanization alone, the C filter alone, and the rest per filter cycle
    (the glue), old and new;
  * the whole single-run `modelgen simulate` (three modes, no Monte Carlo,
    figures and summary) against the old recipe (held data, three Python-loop
    runs, same figures) -- in process, same seed;
  * memory: the peak resident size of a fresh process that flies the closed-loop
    flight (derive, build the C, fly) -- old for 4 h, new for 4 h and 24 h.  Peak
    RSS only grows, so each figure comes from its own child process (this script
    with --memory-child).

Wall time and CPU time of this process are both printed: on a shared machine the
CPU time is the figure to compare with the targets (one core).

Usage: python bench/bench_simulation.py [--hours 4] [--long-hours 24] [--skip-memory]
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

from modelgen.derive.symbolic import derive
from modelgen.model.loading import load_model
from modelgen.simulation.filters import filter_factory
from modelgen.simulation.flight import profile_layout, simulate_sensors
from modelgen.simulation.scenario import load_profile
from modelgen.simulation.streaming import fly_modes, history_every
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
    with Clock() as c_trajectory:
        trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0 / scenario.filter.period, streamed=streamed)
    layout = profile_layout(scenario, derived, trajectory)
    with Clock() as c_sensors:
        sensors = simulate_sensors(scenario, trajectory, np.random.default_rng(0))
    with Clock() as c_fly:
        results = fly_modes(scenario, derived, trajectory, sensors, layout, make, modes, glue=glue,
                            progress=(lambda mode: progress(f"{label} {mode}")) if label else None,
                            record_every=record_every)
    return results, trajectory, {"trajectory": c_trajectory, "sensors": c_sensors, "fly": c_fly}


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
    """One mode old vs new, and the whole `simulate`, in this process (module docstring)."""
    with tempfile.TemporaryDirectory() as folder:
        make = filter_factory(derived, "c", folder)
        warm = scenario.with_changes(hours=30 / 3600)  # numba compilation or cache load, not timed
        for streamed, glue in ((False, "python"), (True, "compiled")):
            fly(warm, derived, make, streamed, glue)

        # -- one correction mode ------------------------------------------------------------
        old, trajectory, t_old = fly(scenario, derived, make, False, "python", label="old")
        cycles = len(trajectory.truth) - 1
        with Clock() as c_mech:  # the mechanization alone over the same samples (held data, ideal increments)
            ins = Strapdown(trajectory.initial_state(), scenario.imu_rate, scenario.coning)
            ins.run(trajectory.delta_theta, trajectory.delta_velocity, 0, cycles * trajectory.record_every)
        del trajectory
        new, _, t_new = fly(scenario, derived, make, True, "compiled", label="new")
        _, _, t_new3 = fly(scenario, derived, make, True, "compiled", modes=("open_loop", "closed_loop", "accumulated"))
        per_mode = (t_new3["fly"].cpu - t_new["fly"].cpu) / 2  # what one more mode adds to the pass
        stream_data = t_new["fly"].cpu - per_mode  # IMU pieces generated and corrupted, once per pass
        c_filter = c_filter_seconds(make, cycles)
        a, b = old["closed_loop"], new["closed_loop"]
        same = all(np.array_equal(getattr(a, f), getattr(b, f)) for f in ("outputs", "estimation_error", "sigma"))
        old_mode = t_old["fly"].cpu
        old_data = t_old["trajectory"].cpu + t_old["sensors"].cpu
        glue_old = (old_mode - c_mech.cpu - c_filter) / cycles * 1e6
        glue_new = (per_mode - c_mech.cpu - c_filter) / cycles * 1e6
        print(f"  one mode (closed loop), {cycles} filter cycles, {b.updates} Doppler updates; histories old vs new "
              f"{'bit for bit equal' if same else 'DIFFERENT'}", flush=True)
        print(f"    old (held data, Python loop): data {old_data:.2f} s CPU (trajectory + sensors, once), "
              f"each mode {old_mode:.2f} s CPU (wall {t_old['fly'].wall:.2f} s)", flush=True)
        print(f"    new (streamed, compiled loop): data {stream_data + t_new['trajectory'].cpu + t_new['sensors'].cpu:.2f} s CPU "
              f"(truth, sensors, IMU pieces: once per pass), each mode {per_mode:.2f} s CPU "
              f"(one-mode pass {t_new['fly'].cpu:.2f} s, three-mode pass {t_new3['fly'].cpu:.2f} s) -> "
              f"{old_mode / per_mode:.1f}x; target <= {TARGETS['one mode [s]']} s", flush=True)
        print(f"    of each mode: mechanization {c_mech.cpu:.2f} s, C filter (evaluate + discretize + predict, "
              f"through ctypes) {c_filter:.2f} s; the rest per filter cycle (glue): old {glue_old:.1f} us, "
              f"new {glue_new:.1f} us", flush=True)
        report["one_mode"] = {"cycles": cycles, "bit_for_bit": same, "mechanization_cpu_s": c_mech.cpu,
                              "c_filter_cpu_s": c_filter,
                              "old": {"data_cpu_s": old_data, "mode_cpu_s": old_mode, "mode_wall_s": t_old["fly"].wall,
                                      "glue_us_per_cycle": glue_old},
                              "new": {"data_cpu_s": stream_data + t_new["trajectory"].cpu + t_new["sensors"].cpu,
                                      "mode_cpu_s": per_mode, "one_mode_pass_cpu_s": t_new["fly"].cpu,
                                      "three_mode_pass_cpu_s": t_new3["fly"].cpu, "glue_us_per_cycle": glue_new}}

        # -- whole simulate, three modes --------------------------------------------------------
        from modelgen.simulation.flight_report import simulate

        with tempfile.TemporaryDirectory() as out:
            with Clock() as c_sim:
                summary = simulate(scenario, derived, Path(out), runs=0, echo=lambda line: None)
            steps = summary.read_text(encoding="utf-8").split("## Timings", 1)[1].split("## Figures", 1)[0]
        print("    simulate's own timings (wall):\n" + "\n".join(f"      {line}" for line in steps.strip().splitlines()[2:]))
        with Clock() as c_three_old:
            fly(scenario, derived, make, False, "python", modes=("open_loop", "closed_loop", "accumulated"))
        print(f"  whole `modelgen simulate` (three modes, figures, no Monte Carlo): wall {c_sim.wall:.2f} s, "
              f"CPU {c_sim.cpu:.2f} s; the old recipe's data and three runs alone (no figures): CPU {c_three_old.cpu:.2f} s "
              f"-> {c_three_old.cpu / c_sim.cpu:.1f}x; target <= {TARGETS['simulate [s]']} s", flush=True)
        report["simulate"] = {"wall_s": c_sim.wall, "cpu_s": c_sim.cpu, "old_three_modes_cpu_s": c_three_old.cpu}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hours", type=float, default=4.0)
    parser.add_argument("--long-hours", type=float, default=24.0)
    parser.add_argument("--skip-memory", action="store_true")
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
    if not args.memory_only:
        measure_time(scenario, derived, report)

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
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    print(f"  wrote {args.out}")


if __name__ == "__main__":
    main()
