"""Generated Python and C agree with the numpy reference over each model's check scenario.

The pass criterion is computed per run from its conditioning
(``modelgen.checks.code_check.conformance_tolerance``): correct code passes it, and
a coefficient perturbed by 1e-9 (relative) fails it, on a well-conditioned
scenario (ins_gps15: correlation matrix of P never worse than cond 35) and on
an ill-conditioned one (the paper's: cond 1e8 after the first update, from
exactly zero initial position and velocity variances).
"""

import re

import numpy as np
import pytest

from modelgen.codegen.generate import generate_code, write_atomically
from modelgen.checks.code_check import (
    DOUBLE_UNIT_ROUNDOFF,
    check_generated,
    conformance_tolerance,
    is_positive_definite,
    reference_run,
    relative_difference,
    step_conditioning,
)
from modelgen.derivation.symbolic import derive
from modelgen.model.loading import load_model
from modelgen.jobs import check_scenario, declared_scenario, paper_scenario


def correlation_condition(P: np.ndarray) -> float:
    d = np.sqrt(np.diag(P))
    eig = np.linalg.eigvalsh(P / np.outer(d, d))
    return float(eig.max() / eig.min())


@pytest.fixture(scope="module")
def gps15_derived(derived_builtin):
    return derived_builtin("ins_gps15")


def generated_folder(derived, root):
    folder = root / derived.model.name
    write_atomically(folder, generate_code(derived).files)
    return folder


@pytest.fixture(scope="module")
def paper_folder(paper_derived, tmp_path_factory):
    return generated_folder(paper_derived, tmp_path_factory.mktemp("gen"))


@pytest.fixture(scope="module")
def gps15_folder(gps15_derived, tmp_path_factory):
    return generated_folder(gps15_derived, tmp_path_factory.mktemp("gen15"))


def test_paper_model_declares_the_paper_scenario(paper_derived):
    """ned_doppler18's check: section is the core paper's scenario: 240 steps of 60 s, Table 1, level flight."""
    declared, paper = declared_scenario(paper_derived), paper_scenario(paper_derived)
    assert declared.steps == paper.steps == 240 and declared.step == paper.step == 60.0
    np.testing.assert_allclose(declared.initial_covariance, paper.initial_covariance, rtol=1e-15, atol=0)
    for name, value in declared.parameters.items():
        assert value == pytest.approx(paper.parameters[name], rel=1e-15, abs=0), name


def test_every_builtin_model_declares_its_check_scenario(loaded_builtin):
    from modelgen.model.loading import builtin_models

    for name in builtin_models():
        spec = loaded_builtin(name).check  # load_model(name), once per session (tests/conftest.py)
        assert spec is not None and spec.steps >= 100 and spec.step_s > 0, name


def test_a_model_without_a_check_section_falls_back_to_the_labelled_synthetic_scenario():
    from modelgen.model.loading import load_model_text

    text = (
        "model: tilt\nparameters:\n  - {name: g, value: 9.8}\n  - {name: R}\nstates:\n  - {name: phi}\n  - {name: dv}\n"
        "dynamics:\n  phi: -dv/R\n  dv: g*phi\nmeasurements:\n  - {name: z, expression: dv, variance: '0.01'}\n"
    )
    derived = derive(load_model_text(text, "m.yaml"))
    scenario = check_scenario(derived)
    assert declared_scenario(derived) is None
    assert scenario.label.startswith("synthetic operating point") and "no check: section" in scenario.label
    assert set(scenario.parameters) == {"R"}


def test_tolerance_is_the_stated_bound_of_the_run():
    """2 (2n + 1) u sum_k rho_k, no hidden constant."""
    rho = np.array([3.0, 5.0, 7.0])
    assert conformance_tolerance(rho, 18, DOUBLE_UNIT_ROUNDOFF, 2) == 2 * 37 * 2.0**-53 * 15.0
    assert conformance_tolerance(rho, 18, 2.0**-24, 1) == 37 * 2.0**-24 * 15.0


def test_conditioning_grows_where_the_update_cancels(paper_derived):
    """The paper's first update cuts exactly-zero-started variances: rho there exceeds the steady steps'."""
    rho = step_conditioning(paper_derived, paper_scenario(paper_derived))
    assert len(rho) == 240 and np.all(rho >= 1.0)
    assert rho[:5].max() > np.median(rho)


@pytest.fixture(scope="module")
def paper_results(paper_derived, paper_folder, tmp_path_factory):
    build = tmp_path_factory.mktemp("build")
    return {r.implementation: r for r in check_generated(paper_folder, paper_derived, paper_scenario(paper_derived), build)}


@pytest.mark.compile
@pytest.mark.parametrize("implementation", ["python", "c"])
def test_generated_filter_matches_reference_over_240_steps(paper_results, implementation):
    r = paper_results[implementation]
    assert r.steps == 240
    assert 1e-12 < r.tolerance < 1e-10  # the paper's bound: 2 * 37 * u * sum rho ~ 1.2e-11
    assert r.passed()
    assert r.symmetric and r.positive_definite


def perturbed_copy(folder, name, tmp_path):
    """The generated folder with one Phi product of the C prediction scaled by 1 + 1e-9."""
    broken = tmp_path / name
    broken.mkdir()
    for f in folder.iterdir():
        if f.is_file():  # not the __pycache__ an earlier test's import of the module left
            (broken / f.name).write_text(f.read_text())
    source = (broken / f"{name}.c").read_text()
    source, count = re.subn(r"(w->Pn\[0\] =\s+)", r"\g<1>1.000000001*", source, count=1)  # P_n(0, 0), packed (its value may wrap)
    assert count == 1
    (broken / f"{name}.c").write_text(source)
    return broken


@pytest.mark.compile
@pytest.mark.parametrize("conditioning", ["ill", "well"])
def test_a_wrong_coefficient_in_the_c_is_caught(conditioning, paper_derived, paper_folder, gps15_derived, gps15_folder, tmp_path,
                                               request):
    """The check can fail: perturb one Phi product in the C prediction by 1e-9, on either kind of problem.

    The unperturbed run of the paper's code over the paper's scenario is the module's ``paper_results`` (the same
    folder, model and scenario), not checked a second time.
    """
    derived, folder = (paper_derived, paper_folder) if conditioning == "ill" else (gps15_derived, gps15_folder)
    scenario = paper_scenario(derived) if conditioning == "ill" else check_scenario(derived)
    worst = max(correlation_condition(P) for _, P in reference_run(derived, scenario))
    assert (worst > 1e7) if conditioning == "ill" else (worst < 1e2)
    broken = perturbed_copy(folder, derived.model.name, tmp_path)
    results = {r.implementation: r for r in check_generated(broken, derived, scenario, tmp_path)}
    assert not results["c"].passed(), results["c"]
    assert results["python"].passed(), results["python"]
    if conditioning == "ill":
        correct = request.getfixturevalue("paper_results")
    else:
        (tmp_path / "ok").mkdir()
        correct = {r.implementation: r for r in check_generated(folder, derived, scenario, tmp_path / "ok")}
    assert correct["c"].passed() and correct["python"].passed()


@pytest.mark.compile
@pytest.mark.parametrize("name", ["ned_inertial16", "gps_pseudorange11", "ned_doppler32_augmented", "ins_gnss21"])
def test_every_builtin_model_passes_its_declared_check(name, tmp_path, derived_builtin):
    """A correct model never fails: unaided, pseudo-range, augmented-transform and 21-state code over their own scenarios.

    (``modelgen run`` checks every built-in model the same way.)
    """
    from modelgen.jobs import check

    derived = derived_builtin(name)
    results = check(derived, generated_folder(derived, tmp_path))
    assert all("check scenario" in r.scenario for r in results)
    assert all(r.passed() for r in results), results


def test_relative_difference_flags_a_lost_zero():
    assert relative_difference(np.array([1e-30]), np.array([0.0])) == float("inf")
    assert relative_difference(np.array([2.0, 0.0]), np.array([1.0, 0.0])) == 1.0


def test_positive_definiteness_is_judged_on_the_correlation_matrix():
    P = np.diag([1e-14, 1e6])
    assert is_positive_definite(P)
    assert not is_positive_definite(np.array([[1.0, 2.0], [2.0, 1.0]]))


TOY_LOOP = """\
model: toy_loop
parameters:
  - {name: rate, symbol: k, value: 0.5}
  - {name: sigma, symbol: s, value: 0.1}
states:
  - {name: x_state, symbol: x}
noises:
  - {name: w_noise, symbol: w, psd: "s**2"}
dynamics:
  x: -k*x + w
measurements:
  - {name: z_meas, symbol: z, expression: x, variance: "s**2"}
"""


@pytest.mark.compile
def test_the_c_built_ahead_while_the_python_runs_is_compiled_once_and_a_failed_build_is_reported(tmp_path, monkeypatch):
    """check_generated compiles the C in another thread (Backend.prepare) while the Python runs; the C's run (and
    the C++ driver's link) take that library from the compile cache: one compile of the C, not two; a C that does
    not compile fails the check with the compiler's message, as without the build ahead."""
    from modelgen.codegen.build import CACHE_ENV
    from modelgen.errors import ModelError
    from modelgen.jobs import check
    from tests.codegen.compile_cache_support import counting_compiler

    script, compiles = counting_compiler(tmp_path)
    monkeypatch.setenv("CC", str(script))
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    (tmp_path / "toy.yaml").write_text(TOY_LOOP)
    derived = derive(load_model(tmp_path / "toy.yaml"))
    folder = tmp_path / "toy_loop"
    write_atomically(folder, generate_code(derived).files)
    results = check(derived, folder)
    assert {r.implementation for r in results} >= {"python", "c"} and all(r.passed() for r in results)
    assert compiles() == 1
    source = folder / "toy_loop.c"
    source.write_text(source.read_text() + "\nint toy_loop_unused(int x) { return 0; }\n")  # -Wextra -Werror: refused
    with pytest.raises(ModelError, match="compiling .*toy_loop.c failed"):
        check(derived, folder)
