"""What a fresh Monte Carlo worker does before its first run: imports side by side, the trajectory mapped from the cache."""

import gc
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from modelgen.cluster import dask_client, import_on_workers

pytestmark = pytest.mark.flight

# Only modelgen.cluster at the top: the workers import this file to run its functions, and must not get the
# Monte Carlo module from it.


def _has_module(name: str) -> bool:
    return name in sys.modules


def _set_up_trajectories() -> list[bool]:
    """On a worker: for each Monte Carlo set-up it holds, whether its trajectory is streamed (truth rows only, no increments held)."""
    from modelgen.cluster import _CACHE

    return [context["trajectory"].streamed and context["trajectory"].delta_theta is None
            for key, context in _CACHE.items() if str(key).startswith("montecarlo-")]


def test_fresh_workers_import_the_study_code_when_asked_without_a_task():
    module = "modelgen.simulation.montecarlo"
    with dask_client(workers=2) as client:
        client.wait_for_workers(2)
        assert not any(client.run(_has_module, module).values())  # spawned workers start without it
        import_on_workers(client, module)  # returns at once; the workers import side by side
        deadline = time.monotonic() + 60
        while not all(client.run(_has_module, module).values()):
            assert time.monotonic() < deadline, "the workers did not import the module"
            time.sleep(0.1)


def test_fresh_workers_warm_up_after_the_import_what_their_first_run_would_pay_for():
    module = "modelgen.simulation.montecarlo"
    with dask_client(workers=2) as client:
        client.wait_for_workers(2)
        assert not any(client.run(_has_module, "scipy.special").values())  # the study code alone does not load it
        import_on_workers(client, module, warm_up="warm_worker")
        deadline = time.monotonic() + 60
        while not all(client.run(_has_module, "scipy.special").values()):
            assert time.monotonic() < deadline, "the workers did not warm up"
            time.sleep(0.1)


def test_a_module_imported_long_lived_is_warmed_up_once(tmp_path, monkeypatch):
    from modelgen.cluster import import_long_lived

    (tmp_path / "modelgen_warm_up_probe.py").write_text("CALLS = []\n\ndef warm():\n    CALLS.append(1)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "modelgen_warm_up_probe", raising=False)
    try:
        import_long_lived("modelgen_warm_up_probe", "warm")
        import_long_lived("modelgen_warm_up_probe", "warm")  # already imported: neither imported nor warmed again
    finally:
        gc.unfreeze()  # import_long_lived froze this test session's objects, as a worker's
    assert sys.modules["modelgen_warm_up_probe"].CALLS == [1]


def test_fresh_workers_fly_a_streamed_trajectory_and_give_the_callers_results(paper_derived):
    """No array of the flight's length is held by a worker (issue 31: memory flat in the flight's duration)."""
    from modelgen.simulation.montecarlo import run_monte_carlo
    from modelgen.simulation.scenario import load_profile

    short = load_profile("profile_000").with_changes(hours=0.02, imu_rate=50.0)
    here = run_monte_carlo(short, paper_derived, runs=3, seed=4)
    with dask_client(workers=2) as fresh:
        there = run_monte_carlo(short, paper_derived, runs=3, seed=4, client=fresh)
        streamed = [s for flags in fresh.run(_set_up_trajectories).values() for s in flags]
    assert streamed and all(streamed)  # every worker that flew a run streamed its trajectory
    assert np.array_equal(there.errors, here.errors) and np.array_equal(there.sigma, here.sigma)


def test_the_collector_is_paused_for_a_set_up_and_restored_after_it():
    import gc

    from modelgen.cluster import collector_paused, forget_cached, worker_cached

    seen = []
    assert gc.isenabled()
    worker_cached("test-collector", lambda: seen.append(gc.isenabled()))
    forget_cached("test-collector")
    assert seen == [False] and gc.isenabled()
    try:
        with collector_paused():
            raise RuntimeError("a failed set-up")
    except RuntimeError:
        pass
    assert gc.isenabled()
    gc.disable()
    try:
        with collector_paused():
            pass
        assert not gc.isenabled()  # a collector the caller had turned off stays off
    finally:
        gc.enable()


def test_pauses_of_the_collector_overlapping_in_two_threads_end_with_the_last_one():
    import gc
    import threading

    from modelgen.cluster import collector_paused

    assert gc.isenabled()
    entered, leave = threading.Event(), threading.Event()

    def import_thread():  # as a worker's import (import_on_workers) beside a task's set-up
        with collector_paused():
            entered.set()
            leave.wait(10)

    thread = threading.Thread(target=import_thread)
    thread.start()
    assert entered.wait(10)
    with collector_paused():
        leave.set()
        thread.join(10)
        assert not gc.isenabled()  # the other thread's pause is over, this one is not
    assert gc.isenabled()


def test_a_task_of_modelgen_travels_by_name_and_a_worker_imports_its_module_only_to_run_it():
    from modelgen.cluster import _named, call_by_name
    from modelgen.simulation import montecarlo

    assert _named(montecarlo.fly_one_run) == (call_by_name, ("modelgen.simulation.montecarlo", "fly_one_run"))
    assert call_by_name("modelgen.cluster", "held", 42) == 42
    local = lambda x: x  # noqa: E731  (not a module-level function of modelgen: pickled as it is)
    assert _named(local) == (local, ())
    assert _named(np.sum) == (np.sum, ())


def test_a_worker_flying_the_reference_takes_the_callers_derived_model_instead_of_deriving_it(paper_derived,
                                                                                              monkeypatch):
    import pickle

    import modelgen.derivation.symbolic as symbolic
    from modelgen.simulation import montecarlo

    paper_derived._numeric  # the caller's model has made its lambdified matrices: code, which cannot travel
    with pytest.raises(Exception):
        pickle.dumps(paper_derived)
    short = load_short_profile()
    setup = montecarlo.worker_setup(short, None, paper_derived, short.filter.mode, 60, "reference", "test-key")
    received = pickle.loads(pickle.dumps(setup))  # as a worker receives it

    def refuse(model):
        raise AssertionError("the worker derived the model again")

    monkeypatch.setattr(symbolic, "derive", refuse)
    context = montecarlo._prepare(received)
    model = context["derived"]
    assert isinstance(model, symbolic.DerivedModel)  # the reference filter evaluates its symbolic matrices
    assert all(getattr(model, name) == getattr(paper_derived, name) for name in ("model", "F", "G", "H", "Q", "R"))
    context["code_dir"].cleanup()


def test_a_worker_takes_the_callers_error_layout_instead_of_making_it(paper_derived, monkeypatch):
    import pickle

    from modelgen.simulation import montecarlo

    short = load_short_profile()
    setup = montecarlo.worker_setup(short, None, paper_derived, short.filter.mode, 60, "reference", "test-key")
    received = pickle.loads(pickle.dumps(setup))  # as a worker receives it: the layout holds the received outline
    assert received.layout.derived is received.outline

    def refuse(*args):
        raise AssertionError("the worker made the error layout again")

    monkeypatch.setattr(montecarlo, "profile_layout", refuse)
    context = montecarlo._prepare(received)
    assert context["layout"] is received.layout
    context["code_dir"].cleanup()


def test_a_set_up_whose_runs_need_the_derived_model_and_carry_none_is_refused_by_name(paper_derived):
    import dataclasses

    from modelgen.errors import ModelError
    from modelgen.simulation import montecarlo

    short = load_short_profile()
    setup = montecarlo.worker_setup(short, None, paper_derived, short.filter.mode, 60, "reference", "test-key")
    with pytest.raises(ModelError, match="test-key: its runs \\(filter 'reference', sensor 'doppler'\\) need the "
                                         "derived model, and the set-up carries none"):
        montecarlo._prepare(dataclasses.replace(setup, derived=None))


def test_the_models_outline_has_the_names_and_sizes_the_compiled_loop_reads(paper_derived):
    import pickle

    from modelgen.codegen.layout import ModelSizes
    from modelgen.simulation.model_outline import ModelOutline

    outline = pickle.loads(pickle.dumps(ModelOutline.of(paper_derived)))
    model = paper_derived.model
    assert (outline.model.name, outline.model.frame) == (model.name, model.frame)
    for names in ("state_names", "noise_names", "parameter_names", "measurement_names"):
        assert list(getattr(outline.model, names)) == list(getattr(model, names))
    assert ModelSizes.of(outline) == ModelSizes.of(paper_derived)
    assert np.array_equal(outline.structure("H"), paper_derived.structure("H"))
    with pytest.raises(Exception, match="keeps the structure of F, G, H only"):
        outline.structure("Q")


_WORKER_RUN = """
import pickle, sys
import numpy as np
from modelgen import cluster
cluster.import_long_lived("modelgen.simulation.montecarlo", "warm_worker")  # what a worker is asked first
from modelgen.simulation import montecarlo
sent = open(sys.argv[1], "rb").read()
output = montecarlo.fly_one_run(sys.argv[2], sent, np.random.SeedSequence(5).spawn(2)[1])
np.save(sys.argv[3], np.concatenate([output.errors.ravel(), output.sigma.ravel(), output.nees.ravel()]))
print(sorted(name for name in sys.modules if name == "sympy" or name.startswith("sympy.")))
"""


@pytest.mark.compile
def test_a_worker_flying_the_generated_c_in_the_compiled_loop_never_imports_sympy(paper_derived, tmp_path):
    import os
    import pickle
    import subprocess

    from modelgen.simulation import montecarlo

    short = load_short_profile()
    here = montecarlo.run_monte_carlo(short, paper_derived, runs=2, seed=5, implementation="c", store_every=60)
    key = montecarlo.setup_key(short, None, paper_derived.model, short.filter.mode, 60, "c")
    setup = montecarlo.worker_setup(short, None, paper_derived, short.filter.mode, 60, "c", key)
    (tmp_path / "setup.pickle").write_bytes(pickle.dumps(setup, protocol=pickle.HIGHEST_PROTOCOL))
    repo = str(Path(__file__).resolve().parents[2])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([repo, os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", _WORKER_RUN, str(tmp_path / "setup.pickle"), key,
                           str(tmp_path / "run.npy")], capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"  # the set-up, the filter and the run: not one sympy module
    run = here.runs - 1  # the same run (seed 5, run 2 of 2) flown in this process
    expected = np.concatenate([here.errors[run].ravel(), here.sigma[run].ravel(), here.nees[run].ravel()])
    assert np.array_equal(np.load(tmp_path / "run.npy"), expected, equal_nan=True)


@pytest.mark.parametrize("name", ["profile_000", "profile_001", "profile_003"])
def test_the_callers_layout_from_the_first_filter_cycle_is_the_layout_of_the_whole_flight(name):
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model
    from modelgen.simulation import montecarlo
    from modelgen.simulation.flight import profile_layout
    from modelgen.simulation.scenario import load_profile
    from modelgen.simulation.trajectory import generate_trajectory

    profile = load_profile(name).with_changes(hours=0.02)
    derived = derive(load_model(profile.filter.model))
    whole = generate_trajectory(profile.path, profile.imu_rate, 1.0 / profile.filter.period)
    start = montecarlo.flight_start(profile)
    assert start.n_samples < whole.n_samples and np.array_equal(start.initial_state(), whole.initial_state())
    made = profile_layout(profile, derived, whole)
    shipped = montecarlo.symbolic_only(derived)
    sent = montecarlo.caller_layout(profile, derived, shipped)
    assert sent.derived is shipped and (sent.groups, sent.conventions) == (made.groups, made.conventions)


def load_short_profile():
    from modelgen.simulation.scenario import load_profile

    return load_profile("profile_000").with_changes(hours=0.01, imu_rate=50.0)


def test_only_a_first_import_freezes_what_the_collector_sees(tmp_path, monkeypatch):
    import gc

    from modelgen.cluster import import_long_lived

    (tmp_path / "modelgen_test_task_code.py").write_text("VALUE = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "modelgen_test_task_code", raising=False)
    frozen = gc.get_freeze_count()
    try:
        import_long_lived("modelgen_test_task_code")
        assert sys.modules["modelgen_test_task_code"].VALUE == 1 and gc.get_freeze_count() > frozen
        now = gc.get_freeze_count()
        import_long_lived("modelgen_test_task_code")  # imported already (a later study): nothing frozen
        assert gc.get_freeze_count() == now
    finally:
        gc.unfreeze()
        sys.modules.pop("modelgen_test_task_code", None)


_KEY_OF_A_FRESH_LOAD = """
import sys
from modelgen.model.loading import load_model
from modelgen.simulation.montecarlo import setup_key
from modelgen.simulation.scenario import load_profile
if sys.argv[1] == "derived first":
    from modelgen.jobs import load_and_derive
    load_and_derive("ned_doppler18")
print(setup_key(load_profile("profile_000"), None, load_model("ned_doppler18"), "closed_loop", 1, "reference"))
"""


def test_the_set_up_key_of_a_study_does_not_depend_on_what_the_process_loaded_before():
    """The same study has the same key in a fresh process and in one that has loaded and derived its model before
    (a suite worker, an API user's second study): before, the key hashed the model's pickle, which derivation
    changes, so a --journal resume was refused as another study's depending on the process's history."""
    import os
    import subprocess

    repo = str(Path(__file__).resolve().parents[2])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([repo, os.environ.get("PYTHONPATH", "")])}
    keys = [subprocess.run([sys.executable, "-c", _KEY_OF_A_FRESH_LOAD, history], capture_output=True, text=True,
                           env=env, timeout=300, check=True).stdout.strip() for history in ("fresh", "derived first")]
    assert keys[0].startswith("montecarlo-") and keys[0] == keys[1], keys
