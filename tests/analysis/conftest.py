"""Fixtures of the covariance-analysis tests: the paper's systems, built once per session."""

import pytest


@pytest.fixture(scope="session")
def paper_systems(paper_derived):
    """Pure inertial, optimal and suboptimal I-IV made from the derived ned_doppler18 (the analysis derives nothing)."""
    from modelgen.analysis.systems import PaperModels

    return PaperModels.build(paper_derived)
