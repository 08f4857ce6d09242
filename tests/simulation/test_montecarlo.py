"""Monte Carlo consistency: the optimal filter passes the NEES test, a mis-modelled one fails.

The runs go to one local dask cluster of two workers, shared by the module's tests.
"""

import dataclasses

import numpy as np
import pytest

from modelgen.cluster import dask_client
from modelgen.errors import ModelError
from modelgen.simulation.montecarlo import run_monte_carlo
from modelgen.simulation.scenario import load_profile

pytestmark = pytest.mark.flight

CHECK_TIMES = (400.0, 800.0, 1200.0)  # s; the Doppler updates every 60 s


@pytest.fixture(scope="module")
def scenario():
    # 20 min of the paper's flight (the climb), 50 Hz IMU, Doppler every 60 s.
    return load_profile("profile_000").with_changes(hours=1 / 3, imu_rate=50.0)


@pytest.fixture(scope="module")
def client():
    with dask_client(workers=2) as c:
        yield c


def mean_nees_at(result, times, confidence=0.99):
    test = result.nees_test(confidence=confidence, start_time=60.0)
    rows = [int(np.argmin(np.abs(test.times - t))) for t in times]
    return test.mean_nees[rows], test


def test_optimal_filter_passes_the_nees_test_on_both_cores(scenario, paper_derived, client):
    # 16 runs on two worker processes.  At each check time N * mean NEES is
    # chi-square with 16 x 18 degrees of freedom for a consistent filter; the
    # two-sided 99 % band is [14.4, 22.1] for the mean.  (Checked at a few
    # separated times: the random-constant states make the NEES of one
    # ensemble strongly correlated in time, so "fraction of all times inside"
    # is a weak statistic for 16 runs.)
    result = run_monte_carlo(scenario, paper_derived, runs=16, seed=1, client=client)
    values, test = mean_nees_at(result, CHECK_TIMES)
    assert result.runs == 16 and test.dimension == 18
    assert np.all((values > test.lower) & (values < test.upper)), (values, test.lower, test.upper)
    # ensemble rms of the actual errors against the filter sigma: same size
    ratio = result.ensemble_rms()[1:] / result.mean_sigma()[1:]
    assert 0.7 < np.median(ratio) < 1.3


def test_filter_with_understated_doppler_noise_fails_the_nees_test(scenario, paper_derived, client):
    # The sensors are drawn with a Doppler 4x noisier than the filter believes:
    # the filter is over-confident and the ensemble NEES leaves its band.
    short = scenario.with_changes(hours=1 / 6)
    doppler = short.sensors["doppler"]
    noisy = dataclasses.replace(doppler, white_noise=4 * doppler.white_noise)
    result = run_monte_carlo(short, paper_derived, runs=8, seed=1, client=client, truth_profile=short.with_sensor("doppler", noisy))
    values, test = mean_nees_at(result, (300.0, 600.0))
    assert np.all(values > test.upper), (values, test.upper)


def test_runs_do_not_depend_on_where_they_run(scenario, paper_derived, client):
    short = scenario.with_changes(hours=0.05)
    here = run_monte_carlo(short, paper_derived, runs=3, seed=9)
    there = run_monte_carlo(short, paper_derived, runs=3, seed=9, client=client)
    assert here.where == "this process" and there.where == "local cluster, 2 workers"
    assert np.array_equal(here.errors, there.errors) and np.array_equal(here.sigma, there.sigma)
    # run i's generator is spawned from the study seed: the first runs of a larger study are the same runs
    more = run_monte_carlo(short, paper_derived, runs=4, seed=9)
    assert np.array_equal(more.errors[:3], here.errors)


def test_a_run_reaches_the_caller_as_it_completes(scenario, paper_derived, client):
    short = scenario.with_changes(hours=0.05)
    arrived, progress = [], []
    result = run_monte_carlo(short, paper_derived, runs=3, seed=2, client=client,
                             on_run=lambda i, run: arrived.append((i, run.errors.copy())),
                             progress=lambda done, total: progress.append((done, total)))
    assert sorted(i for i, _ in arrived) == [0, 1, 2] and progress == [(1, 3), (2, 3), (3, 3)]
    for i, errors in arrived:
        assert np.array_equal(errors, result.errors[i])


def test_a_bad_number_of_runs_or_filter_is_refused(scenario, paper_derived):
    with pytest.raises(ModelError, match="at least one run"):
        run_monte_carlo(scenario, paper_derived, runs=0)
    with pytest.raises(ModelError, match="unknown filter implementation 'fortran'"):
        run_monte_carlo(scenario, paper_derived, runs=1, implementation="fortran")


def _same_runs(a, b) -> bool:
    return all(np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True)
               for name in ("times", "errors", "sigma", "nees", "rejected", "updates"))


def test_a_journal_keeps_completed_runs_and_a_rerun_flies_only_the_missing_ones(scenario, paper_derived, client,
                                                                                tmp_path):
    short = scenario.with_changes(hours=0.05)
    journal = tmp_path / "runs.jsonl"
    whole = run_monte_carlo(short, paper_derived, runs=4, seed=5, client=client, journal=journal)
    lines = journal.read_text().splitlines()
    assert len(lines) == 5  # the study's header, then one line per run as it completed
    kept = [lines[0]] + [line for line in lines[1:] if '"index":1,' in line or '"index":3,' in line]
    journal.write_text("\n".join(kept) + "\n")  # the study stopped after runs 1 and 3
    flown = []
    resumed = run_monte_carlo(short, paper_derived, runs=4, seed=5, client=client, journal=journal,
                              on_run=lambda i, run: flown.append(i))
    assert sorted(flown) == [0, 2]
    assert _same_runs(resumed, whole)  # the kept runs come back from the journal bit for bit (NaN NEES included)
    flown.clear()
    again = run_monte_carlo(short, paper_derived, runs=4, seed=5, journal=journal, on_run=lambda i, run: flown.append(i))
    assert flown == [] and _same_runs(again, whole)  # complete: nothing flown, here or on the cluster


@pytest.mark.parametrize("change", ["seed", "runs", "profile", "filter"])
def test_a_journal_of_another_monte_carlo_study_is_refused(scenario, paper_derived, tmp_path, change):
    short = scenario.with_changes(hours=0.02)
    journal = tmp_path / "runs.jsonl"
    run_monte_carlo(short, paper_derived, runs=2, seed=5, journal=journal)
    other = {"seed": dict(seed=6), "runs": dict(runs=3), "profile": dict(profile=short.with_changes(hours=0.03)),
             "filter": dict(implementation="python")}[change]
    arguments = {"profile": short, "runs": 2, "seed": 5, **other}
    with pytest.raises(ModelError, match=r"runs.jsonl:1: journal of another study or task split \(it holds study "
                                         r"'montecarlo-[0-9a-f]{16}-seed-5' of 2 tasks; this is study"):
        run_monte_carlo(derived=paper_derived, journal=journal, **arguments)


def test_a_worker_killed_in_the_middle_of_a_monte_carlo_study_does_not_lose_it(scenario, paper_derived):
    import os
    import signal

    short = scenario.with_changes(hours=1 / 6)
    here = run_monte_carlo(short, paper_derived, runs=6, seed=3)
    killed = []

    with dask_client(workers=2) as own:
        def kill_a_busy_worker(i, run):
            # at the first completed run: kill (SIGKILL, as a crash or a lost machine) a worker flying another run
            if killed:
                return
            busy = [address for address, keys in own.processing().items()
                    if any(str(key).startswith("modelgen-montecarlo-") and "-setup-" not in str(key) for key in keys)]
            assert busy, "no run in flight to lose"
            pid = own.run(os.getpid, workers=busy[:1])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

        there = run_monte_carlo(short, paper_derived, runs=6, seed=3, client=own, on_run=kill_a_busy_worker)
    assert len(killed) == 1
    assert _same_runs(there, here)


@pytest.mark.compile
def test_fresh_workers_take_the_filter_the_caller_compiled_from_the_compile_cache(scenario, paper_derived, tmp_path,
                                                                                  monkeypatch):
    from modelgen.codegen.build import CACHE_ENV
    from tests.codegen.compile_cache_support import counting_compiler

    script, compiles = counting_compiler(tmp_path)
    monkeypatch.setenv("CC", str(script))  # the workers started below inherit both
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    short = scenario.with_changes(hours=0.02)
    here = run_monte_carlo(short, paper_derived, runs=2, seed=8, implementation="c")  # compiles once, here
    assert compiles() == 1
    with dask_client(workers=2) as fresh:
        there = run_monte_carlo(short, paper_derived, runs=4, seed=8, implementation="c", client=fresh)
        workers_with_a_filter = sum(fresh.run(_montecarlo_set_ups).values())
    # every new worker that flew a run (short runs: one or both) built its filter from the cache, not the compiler
    assert workers_with_a_filter >= 1 and compiles() == 1
    assert np.array_equal(there.errors[:2], here.errors) and np.array_equal(there.sigma[:2], here.sigma)


def _montecarlo_set_ups() -> int:
    """On a worker: how many Monte Carlo set-ups it holds."""
    from modelgen.cluster import _CACHE

    return sum(str(key).startswith("montecarlo-") for key in _CACHE)


def test_the_filter_code_is_generated_once_per_model_in_the_calling_process(paper_derived, monkeypatch):
    import modelgen.codegen.generate as generate
    from modelgen.simulation.filters import generated_filter_files

    calls = []
    real = generate.generate_code
    monkeypatch.setattr(generate, "generate_code", lambda derived: calls.append(1) or real(derived))
    first = generated_filter_files(paper_derived)
    first["ned_doppler18.c"] = "changed by the caller"  # a copy: the kept files stay as generated
    again = generated_filter_files(paper_derived)
    assert len(calls) <= 1 and again["ned_doppler18.c"].startswith("/*")
    assert again == real(paper_derived).files
