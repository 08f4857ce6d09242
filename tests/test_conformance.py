"""Generated Python and C agree with the numpy reference over the paper's 4 hours."""

import re

import numpy as np
import pytest

from modelgen.codegen.generate import generate_code, write_atomically
from modelgen.conformance import check_generated, is_positive_definite, relative_difference
from modelgen.pipeline import CONFORMANCE_TOLERANCE, paper_scenario


@pytest.fixture(scope="module")
def paper_folder(paper_derived, tmp_path_factory):
    folder = tmp_path_factory.mktemp("gen") / "ned_doppler18"
    write_atomically(folder, generate_code(paper_derived).files)
    return folder


def test_paper_scenario_is_four_hours_of_sixty_second_steps(paper_derived):
    scenario = paper_scenario(paper_derived)
    assert scenario.steps == 240 and scenario.step == 60.0


@pytest.fixture(scope="module")
def paper_results(paper_derived, paper_folder, tmp_path_factory):
    build = tmp_path_factory.mktemp("build")
    return {r.implementation: r for r in check_generated(paper_folder, paper_derived, paper_scenario(paper_derived), build)}


@pytest.mark.parametrize("implementation", ["python", "c"])
def test_generated_filter_matches_reference_over_240_steps(paper_results, implementation):
    r = paper_results[implementation]
    assert r.steps == 240
    assert r.max_scaled_P < CONFORMANCE_TOLERANCE
    assert r.max_scaled_x < CONFORMANCE_TOLERANCE
    assert r.symmetric and r.positive_definite


def test_a_wrong_coefficient_in_the_c_is_caught(paper_derived, paper_folder, tmp_path):
    """The check can fail: perturb one Phi product in the C prediction by 1e-9."""
    broken = tmp_path / "ned_doppler18"
    broken.mkdir()
    for f in paper_folder.iterdir():
        (broken / f.name).write_text(f.read_text())
    source = (broken / "ned_doppler18.c").read_text()
    source, count = re.subn(r"(w->Pn\[0\]\[0\] = )", r"\g<1>1.000000001*", source, count=1)
    assert count == 1
    (broken / "ned_doppler18.c").write_text(source)
    results = {r.implementation: r for r in check_generated(broken, paper_derived, paper_scenario(paper_derived), tmp_path)}
    assert not results["c"].passed(CONFORMANCE_TOLERANCE)
    assert results["python"].passed(CONFORMANCE_TOLERANCE)


def test_relative_difference_flags_a_lost_zero():
    assert relative_difference(np.array([1e-30]), np.array([0.0])) == float("inf")
    assert relative_difference(np.array([2.0, 0.0]), np.array([1.0, 0.0])) == 1.0


def test_positive_definiteness_is_judged_on_the_correlation_matrix():
    P = np.diag([1e-14, 1e6])
    assert is_positive_definite(P)
    assert not is_positive_definite(np.array([[1.0, 2.0], [2.0, 1.0]]))
