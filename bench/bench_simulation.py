"""Benchmark of the navigation simulation (issue 5, item 7).

Measures, for the core paper's flight (profile_000) at 300 Hz:
  * truth + ideal IMU generation for the whole flight (4 h = 4.32 million samples),
  * the strapdown mechanization alone over all samples, compiled, against a
    baseline of the same loop run as plain Python on a slice in this process
    (extrapolated per sample) -- the ratio is the speed-up the compilation buys,
  * one complete closed-loop filtered run (sensors, mechanization, 18-state filter
    every 1 s, Doppler every 60 s),
  * a Monte Carlo ensemble on two worker processes;
  * memory: the peak resident size the flight adds to the process, against
    the size of the IMU increments themselves (the data any simulation of
    this flight must hold).

Usage: python bench/bench_simulation.py [--hours 4] [--rate 300] [--runs 8]
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from modelgen.derive.symbolic import derive
from modelgen.model.loading import load_model
from modelgen.simulation.filters import ReferenceFilter
from modelgen.simulation.flight import fly_profile, profile_layout, simulate_sensors
from modelgen.simulation.jit import HAVE_NUMBA
from modelgen.simulation.montecarlo import run_monte_carlo
from modelgen.simulation.scenario import load_profile
from modelgen.simulation.strapdown import ALGORITHMS, Strapdown, _mechanize
from modelgen.simulation.trajectory import generate_trajectory


def progress(label):
    state = {"next": 0.1, "t": time.perf_counter()}

    def report(done, total):
        if done / total >= state["next"] or done == total:
            print(f"    {label}: {100 * done / total:5.1f} % ({time.perf_counter() - state['t']:.1f} s)", flush=True)
            while state["next"] <= done / total:
                state["next"] += 0.1

    return report


def peak_rss_bytes() -> int:
    """Peak resident set size of this process so far (Linux reports kilobytes)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hours", type=float, default=4.0)
    parser.add_argument("--rate", type=float, default=300.0)
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--baseline-samples", type=int, default=30000)
    args = parser.parse_args()

    scenario = load_profile("profile_000").with_changes(hours=args.hours, imu_rate=args.rate)
    derived = derive(load_model(scenario.filter.model))
    print(f"numba: {HAVE_NUMBA}; {args.hours} h at {args.rate:g} Hz", flush=True)

    # warm-up (compilation or cache load) on a tiny flight, not timed
    tiny = generate_trajectory(scenario.path.truncated(10.0), args.rate, 1.0)
    Strapdown(tiny.initial_state(), args.rate, scenario.coning).run(tiny.delta_theta, tiny.delta_velocity, 0, tiny.n_samples)

    rss_before = peak_rss_bytes()
    t = time.perf_counter()
    trajectory = generate_trajectory(scenario.path, scenario.imu_rate, 1.0 / scenario.filter.period)
    t_trajectory = time.perf_counter() - t
    print(f"  trajectory: {trajectory.n_samples:,} IMU samples in {t_trajectory:.2f} s", flush=True)

    ins = Strapdown(trajectory.initial_state(), args.rate, scenario.coning)
    t = time.perf_counter()
    ins.run(trajectory.delta_theta, trajectory.delta_velocity, 0,
            trajectory.n_samples - trajectory.n_samples % ALGORITHMS[scenario.coning][1])
    t_mech = time.perf_counter() - t
    print(f"  mechanization alone: {t_mech:.2f} s ({t_mech / trajectory.n_samples * 1e9:.0f} ns/sample)", flush=True)

    # baseline: the same loop as plain Python, on a slice
    python_loop = getattr(_mechanize, "py_func", _mechanize)
    n = args.baseline_samples - args.baseline_samples % 2
    state = Strapdown(trajectory.initial_state(), args.rate, scenario.coning).state
    t = time.perf_counter()
    code, per = ALGORITHMS[scenario.coning]
    python_loop(state, trajectory.delta_theta, trajectory.delta_velocity, 0, n, 1.0 / args.rate, code, per,
                np.zeros(3), np.zeros(3), float("nan"), float("nan"), 0.0, 0.0, np.zeros(3))
    t_python = (time.perf_counter() - t) / n * trajectory.n_samples
    print(f"  baseline (plain Python, {n} samples, extrapolated): {t_python:.1f} s -> compiled is "
          f"{t_python / t_mech:.0f}x faster", flush=True)

    layout = profile_layout(scenario, derived, trajectory)
    rng = np.random.default_rng(0)
    t = time.perf_counter()
    sensors = simulate_sensors(scenario, trajectory, rng)
    t_sensors = time.perf_counter() - t
    t = time.perf_counter()
    result = fly_profile(scenario, derived, trajectory, rng, lambda x, P: ReferenceFilter(derived, x, P),
                         mode="closed_loop", sensors=sensors, layout=layout, progress=progress("filtered run"))
    t_run = time.perf_counter() - t
    print(f"  sensors: {t_sensors:.2f} s; closed-loop filtered run: {t_run:.2f} s "
          f"({result.updates} Doppler updates, {len(result.times) - 1} filter cycles)", flush=True)
    print(f"  whole 4-h flight (trajectory + sensors + run): {t_trajectory + t_sensors + t_run:.2f} s", flush=True)
    increments = trajectory.delta_theta.nbytes + trajectory.delta_velocity.nbytes
    added = peak_rss_bytes() - rss_before
    print(f"  memory: the flight added {added / 2**20:.0f} MiB to the peak resident size; the IMU increments are "
          f"{increments / 2**20:.0f} MiB -> ratio {added / increments:.2f}", flush=True)

    if args.runs:
        t = time.perf_counter()
        mc = run_monte_carlo(scenario, derived, args.runs, seed=1, workers=2, progress=progress("Monte Carlo"))
        t_mc = time.perf_counter() - t
        test = mc.nees_test(0.95, start_time=60.0)
        print(f"  Monte Carlo: {args.runs} runs on 2 workers in {t_mc:.1f} s ({t_mc / args.runs:.1f} s per run); "
              f"NEES inside the 95 % band at {100 * test.fraction_inside:.0f} % of times", flush=True)


if __name__ == "__main__":
    main()
