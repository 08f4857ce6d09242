"""Shared fixtures: the paper's model, derived once per session."""

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session", autouse=True)
def private_compile_cache(tmp_path_factory):
    """The suite's compiled libraries and trajectories go to a cache of its own, never the user's (child processes inherit it)."""
    import os

    from modelgen.codegen.build import CACHE_ENV

    before = os.environ.get(CACHE_ENV)
    os.environ[CACHE_ENV] = str(tmp_path_factory.mktemp("modelgen-cache"))
    yield
    if before is None:
        os.environ.pop(CACHE_ENV, None)
    else:
        os.environ[CACHE_ENV] = before


@pytest.fixture(scope="session")
def paper_model():
    from modelgen.model.loading import load_model

    return load_model("ned_doppler18")


@pytest.fixture(scope="session")
def derived_builtin():
    """A built-in model by name, loaded and derived once per session (a navigation-equation twin takes seconds)."""
    from functools import lru_cache

    from modelgen.jobs import load_and_derive

    return lru_cache(maxsize=None)(load_and_derive)


@pytest.fixture(scope="session")
def paper_derived(paper_model):
    from modelgen.derive.symbolic import derive

    return derive(paper_model)


@pytest.fixture(scope="session")
def level_flight():
    """Seed 000's level-flight operating point (east at 30 N), with Table 1 statistics."""
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
