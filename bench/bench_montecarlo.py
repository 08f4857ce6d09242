"""Benchmark of the dask runs (issue 15, targets of items 3 and 4).

1. Scaling of Monte Carlo: the same 16 runs of 1 h of the paper's flight
   (profile_000, 300 Hz IMU, 18-state filter every 1 s, Doppler every 60 s,
   the generated C filter by default) on a local dask cluster of 1 worker,
   then of 2 workers, in this one bench run.  Each side is timed from
   submitting the first run to receiving the last, on a cluster already
   started: it includes each worker's own set-up (derive the model, generate
   the trajectory, generate and compile the filter), because a study pays it.
   Also shown: the same study again on the warm clusters (set-up cached).
   Speed-up = t(1 worker) / t(2 workers); efficiency = speed-up / 2 (target >= 0.8).
   Both sides give identical results (checked).
2. The 1,000 covariance cases of modelgen/data/studies/paper_gyro_doppler_1000.yaml
   (200 points x 5 filters, 240 steps of 60 s each) on a local cluster of 2
   workers (target <= 60 s), against the same cases run one after another in
   this process (baseline; same results, checked).

On a shared machine the other processes take cores from the workers: the
numbers printed are what this run measured, and the load average is shown.

Usage: nice -n 10 python bench/bench_montecarlo.py [--runs 16] [--hours 1] [--filter c] [--skip-trade]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

import numpy as np

from modelgen.cluster import dask_client
from modelgen.derive.symbolic import derive
from modelgen.model.loading import load_model
from modelgen.simulation.montecarlo import run_monte_carlo
from modelgen.simulation.scenario import load_profile
from modelgen.study.outputs import csv_text
from modelgen.study.studyfile import load_study
from modelgen.study.trade import run_trade


def monte_carlo_on(workers: int, profile, derived, runs: int, implementation: str) -> tuple[float, float, object]:
    """Seconds for the study on a fresh local cluster of ``workers`` (cold), then again (warm); the result."""
    with dask_client(workers=workers) as client:
        client.wait_for_workers(workers)
        start = time.perf_counter()
        cold = run_monte_carlo(profile, derived, runs, seed=1, client=client, implementation=implementation)
        cold_s = time.perf_counter() - start
        start = time.perf_counter()
        run_monte_carlo(profile, derived, runs, seed=1, client=client, implementation=implementation)
        warm_s = time.perf_counter() - start
    return cold_s, warm_s, cold


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=16)
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--rate", type=float, default=300.0)
    parser.add_argument("--filter", dest="implementation", default="c", choices=("c", "python", "reference"))
    parser.add_argument("--skip-trade", action="store_true")
    parser.add_argument("--skip-monte-carlo", action="store_true")
    args = parser.parse_args()
    print(f"cores: {os.cpu_count()}, load average before: {os.getloadavg()[0]:.2f}")

    if not args.skip_monte_carlo:
        profile = load_profile("profile_000").with_changes(hours=args.hours, imu_rate=args.rate)
        derived = derive(load_model(profile.filter.model))
        print(f"Monte Carlo: {args.runs} runs of {args.hours:g} h at {args.rate:g} Hz, filter {args.implementation}")
        one_cold, one_warm, one = monte_carlo_on(1, profile, derived, args.runs, args.implementation)
        print(f"  1 worker : {one_cold:7.1f} s  (warm: {one_warm:.1f} s)", flush=True)
        two_cold, two_warm, two = monte_carlo_on(2, profile, derived, args.runs, args.implementation)
        print(f"  2 workers: {two_cold:7.1f} s  (warm: {two_warm:.1f} s)", flush=True)
        same = np.array_equal(one.errors, two.errors) and np.array_equal(one.sigma, two.sigma)
        print(f"  identical results on 1 and 2 workers: {same}")
        speed_up, warm_speed_up = one_cold / two_cold, one_warm / two_warm
        print(f"  speed-up {speed_up:.2f}, efficiency {speed_up / 2:.2f} (target >= 0.8: "
              f"{'met' if speed_up / 2 >= 0.8 else 'MISSED'}); warm: speed-up {warm_speed_up:.2f}, "
              f"efficiency {warm_speed_up / 2:.2f}")
        print(f"  load average: {os.getloadavg()[0]:.2f}")

    if not args.skip_trade:
        study = load_study("paper_gyro_doppler_1000")
        study = dataclasses.replace(study, monte_carlo=None)
        print(f"Trade study {study.name}: {study.case_count} covariance cases "
              f"({len(study.points)} points x {len(study.filters)} filters)")
        with dask_client(workers=2) as client:
            client.wait_for_workers(2)
            on_two = run_trade(study, client)
        print(f"  2 workers     : {on_two.covariance_seconds:6.1f} s (target <= 60 s: "
              f"{'met' if on_two.covariance_seconds <= 60 else 'MISSED'})", flush=True)
        here = run_trade(study)
        print(f"  this process  : {here.covariance_seconds:6.1f} s (baseline, one core)")
        print(f"  speed-up {here.covariance_seconds / on_two.covariance_seconds:.2f}; identical tables: "
              f"{csv_text(here) == csv_text(on_two)}")
        print(f"  load average: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
