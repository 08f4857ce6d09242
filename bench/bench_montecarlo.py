"""Benchmark of the dask runs (issue 15, targets of items 3 and 4); writes bench/results/montecarlo.{json,md}.

Every Monte Carlo figure is the same function on every side:
``run_monte_carlo(profile_000 cut to --hours, --rate Hz IMU, --runs runs, seed 1,
the generated C filter)`` -- the paper's 18-state filter every 1 s, Doppler
every 60 s -- on a local dask cluster of 1 worker and of 2 workers (one
single-threaded process each), timed from the call to the last result on a
cluster already started.  Both sides give identical results (checked).

1. Worker set-up.  What a fresh worker process does before its first run,
   in a fresh process of its own, step by step (wall and CPU, the compiler's
   CPU included): import (no sympy: the generated C flies in the compiled
   loop, which reads only the model's outline), receive the set-up (the
   model's outline, the error layout the caller made, the code), take the
   trajectory (made and kept in the trajectory cache when it is empty, mapped
   from it when filled), write the shipped code and compile it (compile
   cache empty) or take it from the cache (filled), take the model's outline,
   numba's registries (what the first compiled call loads; numba imports
   scipy.linalg there), then two runs.  A worker of the clusters below does
   the import and the registries in its import thread, while the caller
   makes the set-up.
2. Scaling, in three states of the workers:
   * ``cold, caches empty``: new worker processes, nothing compiled and no
     trajectory kept (the first study of a new model and flight on a new
     machine);
   * ``cold, caches filled``: new worker processes, the library in the
     compile cache and the flight in the trajectory cache (any later study
     of the flight, on a new cluster) -- the target's "cold efficiency";
   * ``warm``: the same workers again (set-up kept in each worker).
   Speed-up = t(1 worker) / t(2 workers); efficiency = speed-up / 2 (target
   >= 0.8).  Each state is measured ``--repeat`` times on each side, the
   sides taking turns (1 worker, 2 workers, 1 worker, ...) so that other
   processes of a shared machine disturb both alike; the efficiency is that
   of the best (least disturbed) time of each side, and of the medians
   beside it.  Beside wall time, a CPU-time estimate of each study, immune to
   other processes on a shared machine: the caller's CPU plus the CPU of the
   busiest worker (its set-up and runs), i.e. the study's length on otherwise
   idle cores; its speed-up and efficiency are shown too.
   Before timing, numba's on-disk cache of the simulation's kernels is filled
   by a 30-s flight in this process (a one-time cost per installed version,
   paid outside every side alike) with a compile cache of its own.
3. The 1,000 covariance cases of modelgen/data/studies/paper_gyro_doppler_1000.yaml
   (200 points x 5 filters, 240 steps of 60 s each) on a local cluster of 2
   workers (target <= 60 s), against the same cases one after another in
   this process (same table, checked).

The compile and trajectory caches used are temporary folders of this run
($MODELGEN_CACHE_DIR is set for the clusters), never the user's.  The load average before and
after (``uptime``) is recorded with the results: on a shared machine the other
processes take cores from the workers and the wall times with them.

Usage: nice -n 10 python bench/bench_montecarlo.py [--runs 16] [--hours 1] [--filter c] [--repeat 3] [--skip-trade]
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import pickle
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
#: Not measured by this script: a fresh worker's set-up at commit 0293297 (before the compile cache, the shipped
#: code and the lazy scipy imports), the same steps in a fresh process, numba's cache filled, load average ~7 on 2
#: cores; CPU seconds.  Kept beside this run's figures for comparison.
BEFORE = {"commit": "0293297", "import_cpu_s": 1.22, "prepare_cpu_s": 7.12, "first_run_cpu_s": 0.39,
          "note": "prepare = derive + trajectory + layout + generate the code (~0.5 s) + gcc -O2 (~5 s)"}
#: Not measured by this script: the scaling at commit cc6efa0 (workers warmed up in their import thread, but
#: importing sympy and unpickling the caller's derived model: before the model's outline), best of 3 per side,
#: quiet machine (load 0.9-1.6 on 2 cores, this benchmark included).  Kept beside this run's figures for comparison.
PREVIOUS = {"commit": "cc6efa0", "efficiency": {"cold, caches empty": 0.62, "cold, caches filled": 0.80, "warm": 0.92},
            "cpu_efficiency": {"cold, caches empty": 0.64, "cold, caches filled": 0.84, "warm": 0.97}}
STATES = ("cold, caches empty", "cold, caches filled", "warm")


def process_cpu() -> float:
    """CPU seconds of this process and of its finished children (the compiler)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return f"load average {os.getloadavg()}"


# -- 1. one worker's set-up, in a fresh process ---------------------------------------------------


def setup_child(setup_file: str) -> None:
    """--setup-child: a fresh worker's first task, step by step; one JSON line of (step, wall s, CPU s)."""
    steps, last = [], (time.perf_counter(), process_cpu())

    def mark(step: str) -> None:
        nonlocal last
        now = (time.perf_counter(), process_cpu())
        steps.append((step, now[0] - last[0], now[1] - last[1]))
        last = now

    from modelgen import cluster

    cluster.import_long_lived("modelgen.simulation.montecarlo")  # what run_monte_carlo has each worker do first
    from modelgen.simulation import montecarlo

    mark("import modelgen's Monte Carlo (numpy, numba, modelgen)")
    setup = pickle.loads(Path(setup_file).read_bytes())
    mark("receive the set-up (unpickle the profile, the model's outline, the layout and the code)")
    context = cluster.worker_cached(setup.key, lambda: montecarlo._prepare(setup, mark=mark))  # as fly_one_run
    from modelgen.simulation import jit

    if jit.HAVE_NUMBA:  # what a worker's first compiled call does first (shown apart from run 1's own work)
        from numba.core.registry import cpu_target

        cpu_target.target_context.refresh()
        mark("numba's registries of compiled code (at the first compiled call; numba imports scipy.linalg for BLAS)")
    for run in (0, 1):
        seed = np.random.SeedSequence(1).spawn(2)[run]
        montecarlo.fly_profile(setup.profile, context["derived"], context["trajectory"], np.random.default_rng(seed),
                               context["make_filter"], mode=setup.mode, layout=context["layout"])
        mark(f"run {run + 1} (1 flight)")
    if "sympy" in sys.modules and context["derived"] is setup.outline:  # the compiled loop needs none of it
        raise SystemExit("the worker's set-up and runs of the compiled loop imported sympy")
    print(json.dumps(steps))


def measure_setup(setup, cache: Path) -> list[dict]:
    """The set-up of a fresh worker process with the caches in ``cache`` (their state as it is).

    The child gets the environment a dask nanny gives the worker processes it
    spawns (``distributed.nanny.pre-spawn-environ``: one BLAS / OpenMP thread).
    """
    import dask
    import distributed  # noqa: F401  (registers the distributed configuration read below)

    spawned = {name: str(value) for name, value in dask.config.get("distributed.nanny.pre-spawn-environ").items()}
    with tempfile.NamedTemporaryFile(suffix=".pickle") as handle:
        handle.write(pickle.dumps(setup))
        handle.flush()
        out = subprocess.run([sys.executable, __file__, "--setup-child", handle.name], check=True, capture_output=True,
                             text=True, env={**os.environ, **spawned, "MODELGEN_CACHE_DIR": str(cache)})
    return [{"step": step, "wall_s": wall, "cpu_s": cpu} for step, wall, cpu in json.loads(out.stdout.splitlines()[-1])]


# -- 2. scaling -------------------------------------------------------------------------------------


@contextlib.contextmanager
def cache_folder(path: str):
    """$MODELGEN_CACHE_DIR set to ``path`` for the block (processes started in it inherit it), then as it was."""
    before = os.environ.get("MODELGEN_CACHE_DIR")
    os.environ["MODELGEN_CACHE_DIR"] = path
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("MODELGEN_CACHE_DIR", None)
        else:
            os.environ["MODELGEN_CACHE_DIR"] = before


def timed_study(client, profile, derived, runs: int, implementation: str) -> tuple[dict, object]:
    """One study on ``client``: wall, the caller's CPU, each worker's CPU (set-up and runs), the machine's
    1-minute load average as it starts (other processes included), and the result."""
    from modelgen.simulation.montecarlo import run_monte_carlo

    before = client.run(process_cpu)
    load = os.getloadavg()[0]
    cpu, start = process_cpu(), time.perf_counter()
    result = run_monte_carlo(profile, derived, runs, seed=1, client=client, implementation=implementation)
    wall, caller = time.perf_counter() - start, process_cpu() - cpu
    after = client.run(process_cpu)
    workers = sorted(after[w] - before.get(w, 0.0) for w in after)
    return {"wall_s": wall, "caller_cpu_s": caller, "worker_cpu_s": workers,
            "cpu_estimate_s": caller + max(workers), "load_average": load}, result


def scaling(workers: int, profile, derived, runs: int, implementation: str) -> tuple[dict, object]:
    """The three states of module docstring item 2 on clusters of ``workers`` processes, with empty caches at first."""
    from modelgen.cluster import dask_client

    measured = {}
    with tempfile.TemporaryDirectory(prefix="modelgen-bench-cache-") as cache, cache_folder(cache):
        with dask_client(workers=workers) as client:
            client.wait_for_workers(workers)
            measured[STATES[0]], result = timed_study(client, profile, derived, runs, implementation)
            measured[STATES[2]], _ = timed_study(client, profile, derived, runs, implementation)
        with dask_client(workers=workers) as client:
            client.wait_for_workers(workers)
            measured[STATES[1]], again = timed_study(client, profile, derived, runs, implementation)
    print(f"  {workers} worker(s): " + "; ".join(f"{state} {measured[state]['wall_s']:.2f} s" for state in STATES),
          flush=True)
    assert np.array_equal(result.errors, again.errors) and np.array_equal(result.sigma, again.sigma)
    return measured, result


def summary(samples: list[dict]) -> dict:
    """The repetitions of one side and state: every sample, the best and the median wall time and CPU estimate."""
    walls = [m["wall_s"] for m in samples]
    cpus = [m["cpu_estimate_s"] for m in samples]
    return {"samples": samples, "best_wall_s": min(walls), "median_wall_s": float(np.median(walls)),
            "best_cpu_estimate_s": min(cpus), "median_cpu_estimate_s": float(np.median(cpus))}


def efficiency_of(one: dict, two: dict) -> dict:
    """Speed-up and efficiency (speed-up / 2) from the best and the median times of 1 and of 2 workers."""
    figures = {}
    for name, field in (("", "best_wall_s"), ("median_", "median_wall_s"), ("cpu_", "best_cpu_estimate_s")):
        speed_up = one[field] / two[field]
        figures[f"{name}speed_up"], figures[f"{name}efficiency"] = speed_up, speed_up / 2
    return figures


def monte_carlo_part(args) -> dict:
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model
    from modelgen.simulation.montecarlo import run_monte_carlo, setup_key, worker_setup
    from modelgen.simulation.scenario import load_profile

    profile = load_profile("profile_000").with_changes(hours=args.hours, imu_rate=args.rate)
    derived = derive(load_model(profile.filter.model))
    print(f"Monte Carlo: {args.runs} runs of {args.hours:g} h at {args.rate:g} Hz, filter {args.implementation}")
    with tempfile.TemporaryDirectory(prefix="modelgen-bench-warmup-") as cache, cache_folder(cache):
        print("  filling numba's cache (a 30-s flight here, with a compile cache of its own) ...", flush=True)
        run_monte_carlo(profile.with_changes(hours=30 / 3600), derived, 1, implementation=args.implementation)

    mode, store_every = profile.filter.mode, max(1, int(round(profile.aiding_period / profile.filter.period)))
    key = setup_key(profile, None, derived.model, mode, store_every, args.implementation)
    setup = worker_setup(profile, None, derived, mode, store_every, args.implementation, key)  # what run_monte_carlo sends
    set_up = {}
    with tempfile.TemporaryDirectory(prefix="modelgen-bench-cache-") as cache:
        for state in ("caches empty", "caches filled"):
            print(f"  one worker's set-up, {state} ...", flush=True)
            set_up[state] = measure_setup(setup, Path(cache))

    samples: dict[int, dict[str, list]] = {1: {state: [] for state in STATES}, 2: {state: [] for state in STATES}}
    results = []
    for repetition in range(args.repeat):
        print(f"  repetition {repetition + 1} of {args.repeat}", flush=True)
        for workers in (1, 2) if repetition % 2 == 0 else (2, 1):  # the sides take turns going first
            measured, result = scaling(workers, profile, derived, args.runs, args.implementation)
            results.append(result)
            for state in STATES:
                samples[workers][state].append(measured[state])
    identical = all(np.array_equal(r.errors, results[0].errors) and np.array_equal(r.sigma, results[0].sigma)
                    for r in results[1:])
    one = {state: summary(samples[1][state]) for state in STATES}
    two = {state: summary(samples[2][state]) for state in STATES}
    efficiency = {state: efficiency_of(one[state], two[state]) for state in STATES}
    for state in STATES:
        e = efficiency[state]
        print(f"  {state}: best of {args.repeat}: speed-up {e['speed_up']:.2f}, efficiency {e['efficiency']:.2f}; "
              f"medians: efficiency {e['median_efficiency']:.2f}; CPU estimate: efficiency {e['cpu_efficiency']:.2f}",
              flush=True)
    return {"runs": args.runs, "hours": args.hours, "imu_rate_hz": args.rate, "filter": args.implementation,
            "repeat": args.repeat, "worker_set_up": set_up, "one_worker": one, "two_workers": two, "efficiency": efficiency,
            "identical_results": identical}


# -- 3. the 1,000 covariance cases ----------------------------------------------------------------


def trade_part() -> dict:
    from modelgen.cluster import dask_client
    from modelgen.study.outputs import csv_text
    from modelgen.study.studyfile import load_study
    from modelgen.study.trade import run_trade

    study = dataclasses.replace(load_study("paper_gyro_doppler_1000"), monte_carlo=None)
    print(f"Trade study {study.name}: {study.case_count} covariance cases "
          f"({len(study.points)} points x {len(study.filters)} filters)", flush=True)
    with dask_client(workers=2) as client:
        client.wait_for_workers(2)
        cpu = process_cpu()
        on_two = run_trade(study, client)
        caller_cpu = process_cpu() - cpu
    print(f"  2 workers: {on_two.covariance_seconds:.1f} s (target <= 60 s)", flush=True)
    cpu = process_cpu()
    here = run_trade(study)
    here_cpu = process_cpu() - cpu
    print(f"  this process: {here.covariance_seconds:.1f} s", flush=True)
    return {"cases": study.case_count, "two_workers_s": on_two.covariance_seconds, "two_workers_caller_cpu_s": caller_cpu,
            "this_process_s": here.covariance_seconds, "this_process_cpu_s": here_cpu,
            "identical_tables": csv_text(here) == csv_text(on_two)}


# -- results ------------------------------------------------------------------------------------------


def markdown(report: dict) -> str:
    """bench/results/montecarlo.md: the tables of report, each figure with what it computes."""
    lines = ["# Monte Carlo and trade study on dask (bench/bench_montecarlo.py)", "",
             f"Machine: {report['cores']} cores.  Load before: `{report['uptime_before']}`; "
             f"after: `{report['uptime_after']}`.", ""]
    mc = report.get("monte_carlo")
    if mc:
        lines += [f"Every side computes `run_monte_carlo`: {mc['runs']} runs of {mc['hours']:g} h of profile_000 at "
                  f"{mc['imu_rate_hz']:g} Hz, the generated {mc['filter']} filter, seed 1, on a local dask cluster; "
                  f"identical results on 1 and 2 workers: {mc['identical_results']}.", "",
                  "## One worker's set-up (fresh process)", "",
                  "| step | caches empty: wall s | CPU s | caches filled: wall s | CPU s |", "|---|---:|---:|---:|---:|"]
        empty, filled = mc["worker_set_up"]["caches empty"], mc["worker_set_up"]["caches filled"]
        for a, b in zip(empty, filled):
            lines.append(f"| {a['step']} | {a['wall_s']:.2f} | {a['cpu_s']:.2f} | {b['wall_s']:.2f} | {b['cpu_s']:.2f} |")
        for label, rows in (("set-up before the first run", lambda r: r[:-2]),
                            ("set-up and the first run's extra over the second", lambda r: r[:-2] + [
                                {"wall_s": r[-2]["wall_s"] - r[-1]["wall_s"], "cpu_s": r[-2]["cpu_s"] - r[-1]["cpu_s"]}])):
            lines.append(f"| **{label}** | {sum(s['wall_s'] for s in rows(empty)):.2f} | "
                         f"{sum(s['cpu_s'] for s in rows(empty)):.2f} | {sum(s['wall_s'] for s in rows(filled)):.2f} | "
                         f"{sum(s['cpu_s'] for s in rows(filled)):.2f} |")
        lines += ["", f"Before (commit {BEFORE['commit']}, measured once, not by this run): import "
                  f"{BEFORE['import_cpu_s']:.2f} s CPU, set-up {BEFORE['prepare_cpu_s']:.2f} s CPU ({BEFORE['note']}), "
                  f"{BEFORE['import_cpu_s'] + 0.03 + BEFORE['prepare_cpu_s']:.2f} s CPU before the first run."]
        loads = [m["load_average"] for side in ("one_worker", "two_workers") for state in STATES
                 for m in mc[side][state]["samples"]]
        lines += ["", "## Scaling: 1 worker against 2 workers", "",
                  f"Each state measured {mc['repeat']} times on each side, the sides taking turns; efficiency from the "
                  "best time of each side (the least disturbed by other processes), and from the medians.  CPU "
                  "estimate = the caller's CPU + the busiest worker's CPU (the study on otherwise idle cores), best "
                  "of the repetitions.  1-minute load average as each study started: "
                  f"{min(loads):.1f} to {max(loads):.1f} (this benchmark's own processes count about 1-2 while a study runs).", "",
                  "| workers' state | 1 worker: wall s (each) | best | 2 workers: wall s (each) | best | "
                  "efficiency (best) | (medians) | (CPU est.) |", "|---|---|---:|---|---:|---:|---:|---:|"]
        for state in STATES:
            one, two, eff = mc["one_worker"][state], mc["two_workers"][state], mc["efficiency"][state]
            each = lambda side: ", ".join(f"{m['wall_s']:.2f}" for m in side["samples"])
            lines.append(f"| {state} | {each(one)} | {one['best_wall_s']:.2f} | {each(two)} | {two['best_wall_s']:.2f} | "
                         f"**{eff['efficiency']:.2f}** | {eff['median_efficiency']:.2f} | {eff['cpu_efficiency']:.2f} |")
        before = ", ".join(f"{state} {value:.2f} (CPU est. {PREVIOUS['cpu_efficiency'][state]:.2f})"
                           for state, value in PREVIOUS["efficiency"].items())
        lines += ["", f"Before (commit {PREVIOUS['commit']}, measured by this script then, not by this run): "
                  f"efficiency {before}.",
                  "", "Target: efficiency (speed-up / workers) >= 0.8, cold."]
    trade = report.get("trade")
    if trade:
        lines += ["", "## 1,000 covariance cases (paper_gyro_doppler_1000)", "",
                  "| where | wall s | caller CPU s |", "|---|---:|---:|",
                  f"| local cluster, 2 workers | {trade['two_workers_s']:.1f} | {trade['two_workers_caller_cpu_s']:.1f} |",
                  f"| this process, one after another | {trade['this_process_s']:.1f} | {trade['this_process_cpu_s']:.1f} |",
                  "", f"Target: <= 60 s on 2 workers.  Identical tables: {trade['identical_tables']}."]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=16)
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--rate", type=float, default=300.0)
    parser.add_argument("--filter", dest="implementation", default="c", choices=("c", "python", "reference"))
    parser.add_argument("--repeat", type=int, default=3, help="measurements of each state on each side (default 3)")
    parser.add_argument("--skip-trade", action="store_true")
    parser.add_argument("--skip-monte-carlo", action="store_true")
    parser.add_argument("--out", type=Path, default=RESULTS / "montecarlo", help="results: OUT.json and OUT.md")
    parser.add_argument("--setup-child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.setup_child:
        setup_child(args.setup_child)
        return
    report: dict = {"cores": os.cpu_count(), "uptime_before": uptime(), "before": BEFORE, "previous": PREVIOUS}
    print(f"cores: {os.cpu_count()}; {report['uptime_before']}", flush=True)
    if not args.skip_monte_carlo:
        report["monte_carlo"] = monte_carlo_part(args)
    if not args.skip_trade:
        report["trade"] = trade_part()
    report["uptime_after"] = uptime()
    print(report["uptime_after"])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    args.out.with_suffix(".md").write_text(markdown(report), encoding="utf-8")
    print(f"wrote {args.out.with_suffix('.json')} and {args.out.with_suffix('.md')}")


if __name__ == "__main__":
    main()
