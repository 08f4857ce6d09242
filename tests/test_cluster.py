"""Runs on a real dask cluster: a scheduler and a worker started as separate processes, as a user would.

The scheduler and the worker are ``python -m distributed.cli.dask_scheduler``
and ``python -m distributed.cli.dask_worker`` (what ``dask scheduler`` and
``dask worker`` run), on the loopback address; each test submits through
their address and compares with the same work done in this process.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO
from modelgen.cluster import Journal, dask_client, describe_client, run_tasks
from modelgen.errors import ModelError
from modelgen.simulation.montecarlo import run_monte_carlo
from modelgen.simulation.scenario import load_profile

pytestmark = pytest.mark.flight

START_TIMEOUT_S = 90

SMALL_STUDY = """\
study: cluster_grid
parameters:
  gyro_drift: {unit: deg/h, values: [0.03, 0.3], sets: [gyro_markov_sigma_x, gyro_markov_sigma_y, gyro_markov_sigma_z]}
  doppler_noise: {unit: m/s, values: [0.1, 0.3], sets: [doppler_noise_sigma_north, doppler_noise_sigma_east]}
filters: [optimal, suboptimal_4]
"""


def _wait_for(predicate, what: str, process: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while not predicate():
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"{what} did not start:\n{log.read_text(errors='replace')[-3000:]}")
        time.sleep(0.2)


@pytest.fixture(scope="module")
def scheduler_address(tmp_path_factory):
    """The address of a scheduler with one single-threaded worker, both separate processes."""
    folder = tmp_path_factory.mktemp("dask")
    scheduler_file = folder / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    processes = []
    try:
        log = folder / "scheduler.log"
        scheduler = subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
             "--no-dashboard", "--scheduler-file", str(scheduler_file)],
            stdout=log.open("w"), stderr=subprocess.STDOUT, env=env, cwd=folder)
        processes.append(scheduler)
        _wait_for(lambda: scheduler_file.is_file() and scheduler_file.stat().st_size > 0, "dask scheduler", scheduler, log)
        address = json.loads(scheduler_file.read_text())["address"]
        worker_log = folder / "worker.log"
        worker = subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--nworkers", "1",
             "--no-dashboard", "--local-directory", str(folder)],
            stdout=worker_log.open("w"), stderr=subprocess.STDOUT, env=env, cwd=folder)
        processes.append(worker)
        with dask_client(address) as client:
            client.wait_for_workers(1, timeout=START_TIMEOUT_S)
        yield address
    finally:
        for process in reversed(processes):
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
                try:
                    process.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()


@pytest.fixture(scope="module")
def short_flight():
    # 3 minutes of the paper's climb at 20 Hz, Doppler every 60 s
    return load_profile("profile_000").with_changes(hours=0.05, imu_rate=20.0)


def test_monte_carlo_on_a_separate_scheduler_and_worker_equals_the_run_in_this_process(
        scheduler_address, short_flight, paper_derived):
    here = run_monte_carlo(short_flight, paper_derived, runs=3, seed=11)
    with dask_client(scheduler_address) as client:
        assert describe_client(client) == f"{scheduler_address}, 1 worker"
        done = []
        there = run_monte_carlo(short_flight, paper_derived, runs=3, seed=11, client=client,
                                progress=lambda d, t: done.append((d, t)))
    assert done == [(1, 3), (2, 3), (3, 3)]
    assert there.where.startswith(scheduler_address) and here.where == "this process"
    for name in ("times", "errors", "sigma", "nees", "rejected", "updates"):
        assert np.array_equal(getattr(here, name), getattr(there, name), equal_nan=True), name  # NEES is NaN at t = 0
    assert not np.array_equal(here.errors[0], here.errors[1])  # each run its own seed


@pytest.mark.compile
def test_the_generated_c_filter_is_built_once_on_the_worker_and_flies_the_same_runs(
        scheduler_address, short_flight, paper_derived):
    def cached_filter_libraries() -> list[str]:
        """On a worker (a nested function travels by value): the compiled filters its cached set-ups hold."""
        from modelgen.cluster import _CACHE

        return [str(path) for key, context in _CACHE.items() if str(key).startswith("montecarlo-")
                for path in Path(context["code_dir"].name).rglob("*.so")]

    here = run_monte_carlo(short_flight, paper_derived, runs=2, seed=4, implementation="c")
    with dask_client(scheduler_address) as client:
        there = run_monte_carlo(short_flight, paper_derived, runs=2, seed=4, implementation="c", client=client)
        run_monte_carlo(short_flight, paper_derived, runs=2, seed=4, implementation="c", client=client)
        cached = client.run(cached_filter_libraries)
    assert np.array_equal(here.errors, there.errors) and np.array_equal(here.sigma, there.sigma)
    # one set-up, one compiled library on the worker, for both studies' four runs
    assert [len(libraries) for libraries in cached.values()] == [1]
    reference = run_monte_carlo(short_flight, paper_derived, runs=2, seed=4)
    assert np.allclose(here.sigma, reference.sigma, rtol=1e-8, atol=0)


def test_modelgen_trade_through_scheduler_writes_the_table_of_the_run_in_this_process(scheduler_address, tmp_path):
    from modelgen.study.outputs import csv_text
    from modelgen.study.studyfile import load_study
    from modelgen.study.trade import run_trade

    study_file = tmp_path / "grid.yaml"
    study_file.write_text(SMALL_STUDY, encoding="utf-8")
    out = tmp_path / "out"
    completed = subprocess.run([sys.executable, "-m", "modelgen", "trade", str(study_file), "--scheduler",
                                scheduler_address, "--out", str(out)],
                               capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert completed.returncode == 0, completed.stderr
    assert f"on {scheduler_address}, 1 worker" in completed.stderr
    assert "covariance: 4/4 tasks" in completed.stderr
    local = run_trade(load_study(study_file))
    assert (out / "trade.csv").read_text(encoding="utf-8") == csv_text(local)
    assert (out / "position_cep_vs_gyro_drift.png").is_file()


def test_modelgen_simulate_sends_its_monte_carlo_to_the_scheduler(scheduler_address, tmp_path):
    out = tmp_path / "sim"
    completed = subprocess.run([sys.executable, "-m", "modelgen", "simulate", "--hours", "0.05", "--imu-rate", "20",
                                "--runs", "2", "--filter", "reference", "--scheduler", scheduler_address,
                                "--out", str(out)], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert completed.returncode == 0, completed.stderr
    assert f"Monte Carlo on {scheduler_address}, 1 worker" in completed.stderr
    assert f"Monte Carlo (2 runs, {scheduler_address}, 1 worker)" in (out / "summary.md").read_text(encoding="utf-8")


def test_a_task_that_fails_once_is_retried_and_the_study_completes(scheduler_address, tmp_path):
    marker = tmp_path / "failed-once"

    def flaky(i: int) -> int:
        # the first call of task 2 fails (as a lost worker or a crash would); its retry succeeds
        if i == 2 and not marker.exists():
            marker.write_text("failed")
            raise RuntimeError("worker lost")
        return i * i

    with dask_client(scheduler_address) as client:
        assert run_tasks(flaky, [(i,) for i in range(5)], client, retries=1) == [0, 1, 4, 9, 16]
        assert marker.exists()
        marker.unlink()
        kept = []
        with pytest.raises(RuntimeError, match="worker lost"):
            run_tasks(flaky, [(i,) for i in range(5)], client, retries=0, on_result=lambda i, r: kept.append(i))
    assert 2 not in kept


def test_a_worker_lost_in_the_middle_of_a_task_does_not_lose_the_study(tmp_path):
    marker = tmp_path / "died-once"

    def dies_once(i: int) -> int:
        # the first worker to run task 1 dies with it (its process exits, as on a crash or a lost machine)
        if i == 1 and not marker.exists():
            marker.write_text("died")
            os._exit(1)
        return 10 * i

    with dask_client(workers=2) as client:
        assert run_tasks(dies_once, [(i,) for i in range(4)], client) == [0, 10, 20, 30]
    assert marker.exists()


def test_the_local_cluster_keeps_its_diagnostics_out_of_the_runs_way_and_the_callers_settings_as_they_were():
    import dask
    import distributed  # noqa: F401  (registers the distributed settings)

    from modelgen.cluster import LOCAL_CLUSTER_CONFIG

    names = list(LOCAL_CLUSTER_CONFIG)
    before = [dask.config.get(name) for name in names]
    assert before != list(LOCAL_CLUSTER_CONFIG.values())  # dask's defaults differ: the test can see the setting
    with dask_client(workers=1) as client:
        client.wait_for_workers(1)
        on_worker = [next(iter(client.run(dask.config.get, name).values())) for name in names]
        assert on_worker == list(LOCAL_CLUSTER_CONFIG.values())
        client.submit(time.sleep, 0.5, pure=False).result()  # a task: a sampling profiler would have counted it
        assert list(client.run(lambda dask_worker: dask_worker.profile_recent["count"]).values()) == [0]
    assert [dask.config.get(name) for name in names] == before


def test_an_unreachable_scheduler_is_a_clear_error_within_the_timeout():
    start = time.monotonic()
    with pytest.raises(ModelError, match=r"--scheduler tcp://127.0.0.1:9: no dask scheduler answered within 2 s"):
        with dask_client("tcp://127.0.0.1:9", timeout_s=2):
            pass
    assert time.monotonic() - start < 15
    with pytest.raises(ModelError, match="not a dask scheduler address"):
        with dask_client("bogus://127.0.0.1:9", timeout_s=2):
            pass


@pytest.mark.parametrize("address", ["ucx://127.0.0.1:9", "tls://127.0.0.1:9", "UCX://127.0.0.1:9"])
def test_a_scheduler_protocol_other_than_tcp_is_refused_naming_it(address):
    """ucx:// and tls:// ended in a TypeError from distributed, exit 3 (issue 28)."""
    with pytest.raises(ModelError, match=rf"--scheduler {address}: not a dask scheduler address.*protocol {address[:3].lower()}://"):
        with dask_client(address, timeout_s=2):
            pass


def test_a_service_that_is_not_dask_is_a_clear_error_within_the_timeout():
    """A listener that accepts and never answers as dask does held the client over 90 s (issue 28)."""
    import socket

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    port = listener.getsockname()[1]
    start = time.monotonic()
    try:
        with pytest.raises(ModelError, match=rf"--scheduler tcp://127.0.0.1:{port}: no dask scheduler answered within 2 s"):
            with dask_client(f"tcp://127.0.0.1:{port}", timeout_s=2):
                pass
    finally:
        listener.close()
    assert time.monotonic() - start < 10


def test_a_service_that_answers_but_not_as_dask_is_a_clear_error_not_out_of_memory():
    """A web server's reply read as a dask frame length asked for exabytes: "out of memory", exit 2, misleading."""
    import socket
    import threading

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    port = listener.getsockname()[1]

    def answer_as_a_web_server() -> None:
        try:
            while True:
                connection, _ = listener.accept()
                connection.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\n\r\nhello")
        except OSError:  # the listener closed
            pass

    threading.Thread(target=answer_as_a_web_server, daemon=True).start()
    start = time.monotonic()
    try:
        with pytest.raises(ModelError, match=rf"--scheduler tcp://127.0.0.1:{port}: the address answered, but not as a dask scheduler"):
            with dask_client(f"tcp://127.0.0.1:{port}", timeout_s=5):
                pass
    finally:
        listener.close()
    assert time.monotonic() - start < 10


def test_a_journal_keeps_results_as_they_complete_and_a_stopped_study_resumes_from_it(tmp_path):
    path = tmp_path / "study.jsonl"
    calls = []

    def square(i: int) -> dict:
        calls.append(i)
        return {"i": i, "square": i * i, "nothing": float("nan")}

    first = run_tasks(square, [(i,) for i in range(5)], journal=Journal(path, "study-a", 5))
    assert calls == [0, 1, 2, 3, 4] and len(path.read_text().splitlines()) == 6
    # the study stops after two results, the third cut short as it was written
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:3] + [lines[3][:9]]) + "\n")
    calls.clear()
    progress = []
    again = run_tasks(square, [(i,) for i in range(5)], journal=Journal(path, "study-a", 5),
                      progress=lambda d, t: progress.append(d))
    assert calls == [2, 3, 4] and progress == [3, 4, 5]
    assert [(r["i"], r["square"]) for r in again] == [(r["i"], r["square"]) for r in first]
    calls.clear()
    run_tasks(square, [(i,) for i in range(5)], journal=Journal(path, "study-a", 5))
    assert calls == []  # all five recorded now


def test_a_journal_of_another_study_is_refused(tmp_path):
    path = tmp_path / "study.jsonl"
    run_tasks(abs, [(-1,), (-2,)], journal=Journal(path, "study-a", 2))
    with pytest.raises(ModelError, match="study.jsonl:1: journal of another study"):
        run_tasks(abs, [(-1,), (-2,)], journal=Journal(path, "study-b", 2))
    path.write_text('{"study": "study-a", "tasks": 2}\nnot json\n{"index": 1, "result": 2}\n')
    with pytest.raises(ModelError, match="study.jsonl:2: not a journal entry"):
        run_tasks(abs, [(-1,), (-2,)], journal=Journal(path, "study-a", 2))
    path.write_text('{"study": "study-a", "tasks": 2}\n{"index": 7, "result": 2}\n')
    with pytest.raises(ModelError, match="task index 7 out of range"):
        run_tasks(abs, [(-1,), (-2,)], journal=Journal(path, "study-a", 2))


def test_a_journal_is_checked_before_any_work_without_writing_to_it(tmp_path):
    path = tmp_path / "study.jsonl"
    Journal(path, "study-a", 2).check()  # absent: passes, and is not started
    assert not path.exists()
    run_tasks(abs, [(-1,), (-2,)], journal=Journal(path, "study-a", 2))
    kept = path.read_text()
    Journal(path, "study-a", 2).check()
    with pytest.raises(ModelError, match="study.jsonl:1: journal of another study"):
        Journal(path, "study-b", 2).check()
    with path.open("a") as handle:
        handle.write('{"index": 1, "res')  # a last line cut short: left for completed() to drop
    Journal(path, "study-a", 2).check()
    assert path.read_text() == kept + '{"index": 1, "res'
    path.write_text('{"study": "study-a", "tasks": 2}\n{"index": 7, "result": 2}\n')
    with pytest.raises(ModelError, match="task index 7 out of range"):
        Journal(path, "study-a", 2).check()


def test_modelgen_simulate_journal_keeps_the_runs_and_refuses_another_study(tmp_path):
    """The first run is a process of its own (``python -m modelgen``, with a local cluster of worker processes);
    the two that start no cluster run in this process (tests/cli_in_process.py: as the process would, exit
    code and outputs; it saves two interpreters' start-up and imports)."""
    from cli_in_process import run_modelgen

    journal = tmp_path / "runs.jsonl"

    def simulate(*extra: str, in_process: bool = True) -> subprocess.CompletedProcess:
        argv = ["simulate", "--hours", "0.02", "--imu-rate", "20", "--runs", "2", "--workers", "1", "--filter",
                "reference", "--journal", str(journal), "--out", str(tmp_path / "sim"), "--force", *extra]
        if in_process:
            result = run_modelgen(argv, cwd=tmp_path, timeout=300)
            assert result is not None, "modelgen simulate ran longer than 300 s"
            return result
        return subprocess.run([sys.executable, "-m", "modelgen", *argv], capture_output=True, text=True, cwd=tmp_path,
                              timeout=300)

    first = simulate(in_process=False)
    assert first.returncode == 0, first.stderr
    kept = journal.read_text()
    assert len(kept.splitlines()) == 3  # the study's header and both runs
    assert "Monte Carlo on local cluster" in first.stderr  # the progress lines
    again = simulate()
    assert again.returncode == 0, again.stderr
    assert journal.read_text() == kept  # nothing flown again, nothing appended
    assert "Monte Carlo on" not in again.stderr  # every run held: no cluster started for none to fly
    other = simulate("--seed", "1")
    assert other.returncode == 2
    assert "runs.jsonl:1: journal of another study or task split" in other.stderr
    assert "modelgen simulate:" not in other.stderr and "Monte Carlo on" not in other.stderr  # refused before anything was flown or a cluster opened
    assert journal.read_text() == kept


def test_more_local_workers_than_four_per_core_are_refused_naming_the_limit():
    """Issue 28: --workers 100000 tried to start them all."""
    from modelgen.cluster import check_worker_count, local_worker_count, max_local_workers

    limit = max_local_workers()
    assert limit == max(8, 4 * (os.cpu_count() or 1))
    assert local_worker_count(limit) == limit
    with pytest.raises(ModelError, match=rf"^--workers 100000: at most {limit} worker processes on this machine"):
        local_worker_count(100000)
    with pytest.raises(ModelError, match="at least one worker"):
        check_worker_count(0)


_INTERRUPTED_CLIENT = r'''
import sys, time
from modelgen.cluster import dask_client
try:
    with dask_client(workers=2) as client:
        assert client.submit(sum, [1, 2]).result() == 3
        print("ready", flush=True)
        time.sleep(60)
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr, flush=True)
    sys.exit(130)
'''


def test_ctrl_c_reaching_the_local_clusters_workers_prints_no_traceback_of_theirs():
    """Ctrl-C goes to the terminal's whole process group: each worker printed its KeyboardInterrupt traceback
    (issue 28: SIGINT during a Monte Carlo); the workers ignore it, and this process ends them."""
    child = subprocess.Popen([sys.executable, "-c", _INTERRUPTED_CLIENT], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, start_new_session=True, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        assert child.stdout.readline().strip() == "ready"
        time.sleep(1.0)  # the workers idle, as they do between runs
        os.killpg(child.pid, signal.SIGINT)
        _, err = child.communicate(timeout=START_TIMEOUT_S)
    finally:
        if child.poll() is None:
            os.killpg(child.pid, signal.SIGKILL)
            child.wait()
    assert child.returncode == 130 and err.strip() == "interrupted", err
