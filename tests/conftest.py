"""Shared fixtures (the paper's model, derived once per session), the suite's parallel schedule and its options.

The suite runs in parallel (pytest-xdist, ``-n auto`` in pyproject.toml): each
worker is a process with its own session fixtures.  Tests are handed out by
module (:func:`pytest_xdist_make_scheduler`), so that a module's fixtures are
made once, on one worker, except in the modules of :data:`SPREAD_MODULES`,
whose tests are independent and handed out one by one, and of the long
tests of :data:`SOLO_TESTS`, handed out on their own; tests marked
``xdist_group(name)`` all run on one worker, one after another, as do the
units of :data:`SHARED_WORKER_UNITS` that share a name.  The longest units are
handed out first (:data:`FIRST_MODULES`).
"""

import functools
import os
import sys
from pathlib import Path

import pytest

# pytest caches its assertion-rewritten test modules as .pyc files unless bytecode writing is off; an
# environment with PYTHONDONTWRITEBYTECODE=1 (this project's machines have it) then recompiles all ~230
# test modules on every run (about 8 s of a 12-s collection).  The cache lives in the gitignored __pycache__.
sys.dont_write_bytecode = False

REPO = Path(__file__).resolve().parents[1]

#: Modules whose tests are handed to the workers one by one (they share no costly module fixture).
SPREAD_MODULES = ("tests/test_corpus.py", "tests/embedded/test_cppcheck.py")

#: Tests handed out on their own, not with their module: each takes minutes and uses none of its module's
#: fixtures, so that the rest of the module runs on another worker meanwhile.
SOLO_TESTS = ("tests/test_cli.py::test_run_does_the_main_job_end_to_end",)

#: The modules whose tests fork a process (the figure process, the model process): a process forks only while no
#: other thread runs in it, so these tests skip once a test before them on their worker has left a thread behind
#: (dask's, a figure thread).  They form one unit, handed out first (FIRST_MODULES), so that they run on a
#: fresh worker, one after another, and never skip for the schedule (a full run had 6 such skips, CI none).
FORK_MODULES = ("tests/simulation/test_figure_process.py", "tests/simulation/test_flight_report.py",
                "tests/simulation/test_model_process.py")

#: Work units that run on one worker, one after another, so that the worker's per-process caches serve them all:
#: the main job and the Python Filter's conformance check of every built-in model derive the same built-in
#: models (derived_builtin) and load the same generated modules, whose numba predict kernels
#: (modelgen.codegen.build.load_python_module) are then compiled once instead of once on each worker.
SHARED_WORKER_UNITS = {SOLO_TESTS[0]: "builtin-models", "tests/codegen/test_python_filter_class.py": "builtin-models",
                       **{module: "fork-first" for module in FORK_MODULES}}

#: Units handed out first, in this order: a worker's first module runs before any other test has left a
#: thread behind (dask's, a figure thread), and the figure process forks only a process without threads;
#: then the longest units (CPU seconds with -n0, issue 29: the builtin-models group about 120 s, the others
#: 30-100 s), so that no long one is left for the end and the two workers end together.
FIRST_MODULES = ("fork-first", "builtin-models", "tests/test_cli.py",
                 "tests/codegen/test_lane_pairs.py", "tests/codegen/test_contract.py",
                 "tests/navigator/test_navigator_markov.py", "tests/navigator/test_navigator_smoother_generated.py",
                 "tests/codegen/test_options.py", "tests/navigator/test_navigator.py",
                 "tests/navigator/test_navigator_spec.py", "tests/codegen/test_large_models.py",
                 "tests/codegen/test_c_contract.py", "tests/test_cluster.py")


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """Under ``--dist loadgroup`` (the default here): one work unit per module, per xdist_group, per spread and per solo test,
    and one for each name of :data:`SHARED_WORKER_UNITS`."""
    if config.getoption("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadGroupScheduling

    class ModuleScheduling(LoadGroupScheduling):
        """LoadGroupScheduling with a module, not a test, as the unit of a test without a group."""

        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            if scope != nodeid:  # an xdist_group
                return scope
            module = nodeid.split("::", 1)[0]
            unit = nodeid if module in SPREAD_MODULES or nodeid in SOLO_TESTS else module
            return SHARED_WORKER_UNITS.get(unit, unit)

        def _assign_work_unit(self, node) -> None:
            for module in FIRST_MODULES:
                if module in self.workqueue:
                    self.workqueue.move_to_end(module, last=False)  # the next unit handed out
                    break
            super()._assign_work_unit(node)

    return ModuleScheduling(config, log)


def pytest_unconfigure(config):
    """The session is over: skip the interpreter's last garbage collection at exit (gc.freeze, as ``modelgen simulate``
    does), a walk over every object a worker made (sympy's, numba's, matplotlib's); the operating system frees the
    memory.  Run at the end of each worker, this is time of the run's tail."""
    import gc

    gc.freeze()


def pytest_addoption(parser):
    parser.addoption(
        "--regenerate-golden", action="store_true", default=False,
        help="write the golden files (generated/<model>/ of every built-in model and generated/options/) from the "
             "generator, then check them, instead of only checking them: "
             "python -m pytest tests/test_generated_up_to_date.py --regenerate-golden",
    )


@pytest.fixture(scope="session")
def regenerate_golden(request) -> bool:
    """True with --regenerate-golden: the freshness tests write the golden files before comparing them."""
    return bool(request.config.getoption("--regenerate-golden"))


@pytest.fixture(autouse=True)
def _signals_as_a_fresh_interpreter_has_them():
    """Each test starts with SIGINT, SIGTERM and SIGHUP deliverable and handled as in a fresh interpreter.

    A test process runs many tests: one that leaves SIGINT ignored or blocked
    (a library's child-process start-up, a handler not put back) would make
    the next test's interrupt tests pass or fail for the wrong reason, and its
    child processes inherit an ignored or blocked signal.
    """
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        held = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}
        signal.pthread_sigmask(signal.SIG_UNBLOCK, held)
        if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
            signal.signal(signal.SIGINT, signal.default_int_handler)
        for signum in (signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(signum) is signal.SIG_IGN:
                signal.signal(signum, signal.SIG_DFL)
    yield


def _run_folder(tmp_path_factory) -> Path:
    """The temporary folder of this run, shared by its xdist workers (each has a subfolder of it)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(scope="session", autouse=True)
def private_compile_cache(tmp_path_factory):
    """The suite's caches are its own, never the user's (child processes inherit them).

    ``$MODELGEN_CACHE_DIR`` (compiled libraries, trajectories),
    ``$XDG_CACHE_HOME`` (the compiled C navigators of modelgen.navigator.cnav)
    and ``$MODELGEN_KERNEL_CACHE_DIR`` (the generated Python modules' numba
    predict kernels, modelgen.codegen.kernel_cache, off for users) point into
    this run's temporary folder, so that a run compiles what it tests instead
    of taking it from an earlier run.  The workers of one run share them: a
    library or kernel one worker compiled is a hit for the others (entries are
    linked or renamed in whole, never replaced: modelgen.codegen.build; a
    kernel is keyed by its module's exact text).
    """
    from modelgen.codegen.build import CACHE_ENV
    from modelgen.codegen.kernel_cache import KERNEL_CACHE_ENV

    folders = {CACHE_ENV: "modelgen-cache", "XDG_CACHE_HOME": "xdg-cache", KERNEL_CACHE_ENV: "kernel-cache"}
    before = {name: os.environ.get(name) for name in folders}
    for name, folder in folders.items():
        path = _run_folder(tmp_path_factory) / folder
        path.mkdir(exist_ok=True)
        os.environ[name] = str(path)
    yield
    for name, value in before.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


@functools.lru_cache(maxsize=None)
def _loaded_builtin(name: str):
    """A built-in model by name, loaded once in this process (the suite's share of :func:`load_model`)."""
    from modelgen.model.loading import load_model

    return load_model(name)


@functools.lru_cache(maxsize=None)
def _derived_builtin(name: str):
    """A built-in model by name, derived once in this process from :func:`_loaded_builtin`'s model."""
    from modelgen.derivation.symbolic import derive

    return derive(_loaded_builtin(name))


@functools.lru_cache(maxsize=1)
def _mechanization_models():
    """modelgen.checks.mechanizations' (ecef, local-level twin, wander azimuth), derived once in this process."""
    from modelgen.checks.mechanizations import derive_mechanization_models

    return derive_mechanization_models()


@pytest.fixture(scope="session")
def loaded_builtin():
    """A built-in model by name, loaded once per session (a navigation-equation twin takes seconds).

    Models are frozen (ErrorModel, DerivedModel): every test of a worker that
    asks for a built-in model gets the same object, loaded by the same
    :func:`modelgen.model.loading.load_model` a test calling it would run.
    """
    return _loaded_builtin


@pytest.fixture(scope="session")
def derived_builtin():
    """A built-in model by name, loaded and derived once per session (``load_and_derive``: derive(load_model(name)))."""
    return _derived_builtin


@pytest.fixture(scope="session")
def mechanization_models():
    """The mechanization cross-checks' three models (ecef, local level, wander azimuth), derived once per session.

    Shared by tests/model/test_ecef_mechanization.py, test_wander_azimuth_mechanization.py and
    tests/checks/test_mechanizations.py (the wander model alone takes seconds to load).
    """
    return _mechanization_models()


@pytest.fixture(scope="session")
def paper_model():
    return _loaded_builtin("ned_doppler18")


@pytest.fixture(scope="session")
def paper_derived():
    return _derived_builtin("ned_doppler18")


@pytest.fixture(scope="session")
def level_flight():
    """The core paper's level-flight operating point (east at 30 N), with Table 1 statistics."""
    import numpy as np

    values = dict(
        latitude=np.radians(30.0),
        velocity_north=0.0,
        velocity_east=500 / 3.6,
        velocity_down=0.0,
        specific_force_north=0.0,
        specific_force_east=0.0,
        specific_force_down=-9.78,
        c11=0.0, c12=-1.0, c13=0.0, c21=1.0, c22=0.0, c23=0.0, c31=0.0, c32=0.0, c33=1.0,
    )
    for axis in "xyz":
        values[f"gyro_markov_rate_{axis}"] = 1 / 3600
        values[f"gyro_markov_sigma_{axis}"] = np.radians(0.1) / 3600
        values[f"accel_markov_rate_{axis}"] = 1 / 1800
        values[f"accel_markov_sigma_{axis}"] = 9.78e-4
    values["doppler_noise_sigma_north"] = 0.5
    values["doppler_noise_sigma_east"] = 0.5
    return values


@pytest.fixture(scope="session")
def paper_systems(paper_derived):
    """The core paper's six systems (pure inertial, optimal and suboptimal I-IV) made from the derived ned_doppler18.

    Shared by the covariance recursions' tests (tests/analysis) and Table 2's (tests/table2); nothing is derived again.
    """
    from modelgen.table2.systems import PaperModels

    return PaperModels.build(paper_derived)
