"""Van Loan's exact Q_d as a code-generation option (modelgen.codegen.van_loan).

The generated C (block Taylor series with scaling and squaring) and Python
(scipy expm) must give the Phi and Q_d of the numpy reference
modelgen.derivation.discretization.van_loan_discretization on the paper's model,
the option must change only the discretize, the UD form must be refused with
it, and the C must compile strictly in float and for a compact (large) model.
"""

from __future__ import annotations

import difflib
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner

from modelgen.checks.code_check import check_generated, compare, reference_run, scenario_tolerance
from modelgen.codegen.backends.registry import backend
from modelgen.checks.embedded_check import float_tolerance
from modelgen.cli import main
from modelgen.codegen import toolchain
from modelgen.codegen.build import CompiledFilter, compile_shared_library, compiler, load_python_module
from modelgen.codegen.generate import generate_code, write_atomically
from modelgen.codegen.layout import ModelSizes
from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.van_loan import QD_MARGIN, van_loan_plan, van_loan_series
from modelgen.derivation.discretization import van_loan_discretization
from modelgen.derivation.symbolic import derive, parameter_vector
from modelgen.errors import ModelError
from modelgen.jobs import paper_parameters, paper_scenario
from tests.parallel_support import cores_per_worker
from modelgen.model.loading import load_model_text
from tests.codegen.large_model_support import large_model
from tests.codegen.test_degenerate_models import MODELS as DEGENERATE
from tests.embedded.embedded_support import require_tools

VAN_LOAN = CodegenOptions(process_noise="van-loan")
PACKED_FIXED_ORDER = CodegenOptions(process_noise="van-loan", storage="packed", taylor_tolerance=None)
STRICT = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")


def largest_relative(value: np.ndarray, reference: np.ndarray) -> float:
    """max |value - reference| over the largest |reference|: the accuracy rule's measure."""
    return float(np.abs(value - reference).max() / np.abs(reference).max())


@pytest.fixture(scope="module")
def paper_matrices(paper_derived):
    m = paper_derived.numeric(paper_parameters())
    return m["F"], m["G"], m["Q"]


@pytest.fixture(scope="module")
def folders(paper_derived, tmp_path_factory):
    """slug -> folder with the generated code and its compiled library."""
    root = tmp_path_factory.mktemp("van_loan")
    name = paper_derived.model.name
    out = {}
    for options in (VAN_LOAN, PACKED_FIXED_ORDER):
        folder = write_atomically(root / options.slug(), generate_code(paper_derived, options).files)
        compile_shared_library([folder / f"{name}.c"], folder / f"lib{name}.so", ("-O1",))
        out[options.slug()] = folder
    return out


def compiled(folders, derived, options) -> CompiledFilter:
    name = derived.model.name
    filt = CompiledFilter(
        folders[options.slug()] / f"lib{name}.so", name, ModelSizes.of(derived), derived.model.parameter_names, options=options
    )
    filt.set_parameters(dict(zip(derived.model.parameter_names, parameter_vector(derived.model, paper_parameters()))))
    return filt


@pytest.mark.compile
@pytest.mark.parametrize("options", [VAN_LOAN, PACKED_FIXED_ORDER], ids=lambda o: o.slug())
@pytest.mark.parametrize("T", [1.0, 60.0])
def test_van_loan_c_and_python_equal_the_exact_reference(folders, paper_derived, paper_matrices, options, T):
    F, G, Q = paper_matrices
    phi_ref, qd_ref = van_loan_discretization(F, G, Q, T)
    filt = compiled(folders, paper_derived, options)
    assert filt.discretize(T) == 0
    module = load_python_module(folders[options.slug()] / f"{paper_derived.model.name}.py")
    phi_py, qd_py = module.discretize(F, G, np.diag(Q), T)
    for phi, qd in ((filt.Phi, filt.Qd), (phi_py, qd_py)):
        assert largest_relative(phi, phi_ref) < 1e-12
        assert largest_relative(qd, qd_ref) < 1e-12
        assert np.array_equal(qd, qd.T)


@pytest.mark.compile
@pytest.mark.parametrize("T", [1.0, 60.0])
def test_van_loan_qd_is_not_the_taylor_qd(folders, paper_derived, paper_matrices, T):
    """The option changes Q_d by far more than rounding (so the checks below can tell the two apart)."""
    F, G, Q = paper_matrices
    taylor = generate_code(paper_derived, CodegenOptions()).files[f"{paper_derived.model.name}.py"]
    path = folders[VAN_LOAN.slug()] / "taylor_module.py"
    path.write_text(taylor)
    _, qd_taylor = load_python_module(path).discretize(F, G, np.diag(Q), T)
    _, qd_exact = van_loan_discretization(F, G, Q, T)
    assert largest_relative(qd_taylor, qd_exact) > 1e-9


def test_van_loan_numpy_model_needs_the_qd_margin(paper_matrices):
    """At T = 1 s the accuracy rule alone picks order 5, 5e-12 off; QD_MARGIN more orders meet 1e-12."""
    F, G, Q = paper_matrices
    q = np.diag(Q)
    _, qd_ref = van_loan_discretization(F, G, Q, 1.0)
    s, m = van_loan_plan(F, G, q, 1.0, 9, 1e-12)
    assert (s, m) == (0, 5 + QD_MARGIN)
    assert largest_relative(van_loan_series(F, G, q, 1.0, 9, 1e-12)[1], qd_ref) < 1e-12
    _, qd_rule_only = van_loan_series(F, G, q, 1.0, m - QD_MARGIN, None)
    assert largest_relative(qd_rule_only, qd_ref) > 1e-12


@pytest.mark.compile
def test_van_loan_combination_passes_the_conformance_check(folders, paper_derived, monkeypatch):
    """check_generated's reference follows the option; the Taylor reference would fail the same run.

    The run compared with the Taylor reference is the check's own Python run (kept as the backend returns it),
    not a second flight of the same files."""
    import dataclasses

    from modelgen.codegen.backends import python

    scenario = paper_scenario(paper_derived)
    runs, checked = [], python.BACKEND

    def kept_run(*args):
        runs.append(checked.runner(*args))
        return runs[-1]

    monkeypatch.setattr(python, "BACKEND", dataclasses.replace(checked, runner=kept_run))
    results = check_generated(folders[VAN_LOAN.slug()], paper_derived, scenario, options=VAN_LOAN)
    assert {"python", "c"} <= {r.implementation for r in results}
    assert all(r.passed() for r in results), results
    (run,) = runs
    taylor = compare("python", run, reference_run(paper_derived, scenario), scenario_tolerance(paper_derived, scenario))
    assert not taylor.passed()


@pytest.mark.compile
def test_van_loan_c_refuses_bad_inputs_as_the_taylor_discretize(folders, paper_derived):
    filt = compiled(folders, paper_derived, VAN_LOAN)
    assert filt.discretize(float("nan")) == 1
    assert filt.discretize(float("inf")) == 1
    assert filt.discretize(0.0) == 2
    assert filt.discretize(-1.0) == 2
    assert filt.discretize(1e300) == 1  # e^{M T} not representable within 64 doublings
    filt.matrices.q[0] = -1.0
    assert filt.discretize(1.0) == 2
    filt.matrices.q[0] = 1.0
    filt.matrices.F[0] = float("nan")
    assert filt.discretize(1.0) == 1


@pytest.mark.compile
def test_van_loan_python_refuses_bad_inputs_naming_them(folders, paper_derived, paper_matrices):
    F, G, Q = paper_matrices
    module = load_python_module(folders[VAN_LOAN.slug()] / f"{paper_derived.model.name}.py")
    q = np.diag(Q)
    with pytest.raises(ValueError, match="discretize: T must be positive"):
        module.discretize(F, G, q, 0.0)
    with pytest.raises(ValueError, match="discretize: q has a negative"):
        module.discretize(F, G, -q, 1.0)
    bad = F.copy()
    bad[0, 1] = np.nan
    with pytest.raises(ValueError, match="discretize: F has a non-finite entry"):
        module.discretize(bad, G, q, 1.0)
    with pytest.raises(ValueError, match="non-finite"):
        module.discretize(F, G, q, 1e300)


def test_ud_form_with_van_loan_is_refused_naming_both_options(tmp_path):
    with pytest.raises(ModelError, match="process noise 'van-loan' needs form 'covariance', not form 'ud'"):
        CodegenOptions(form="ud", process_noise="van-loan")
    with pytest.raises(ModelError, match="process noise must be one of 'taylor', 'van-loan', not 'exact'"):
        CodegenOptions(process_noise="exact")
    result = CliRunner().invoke(main, ["generate", "--out", str(tmp_path), "--form", "ud", "--process-noise", "van-loan"])
    assert result.exit_code != 0
    assert "process noise 'van-loan' needs form 'covariance'" in result.output
    assert not list(tmp_path.iterdir())


def _changed_lines(old: str, new: str) -> list[str]:
    """Lines removed from or added to ``old`` to make ``new``."""
    return [
        line[1:]
        for line in difflib.unified_diff(old.splitlines(), new.splitlines(), lineterm="", n=0)
        if line[:1] in "+-" and not line.startswith(("+++", "---"))
    ]


def _without(text: str, start: str, end: str) -> str:
    """``text`` with the span from the line starting ``start`` up to (not including) ``end`` cut out."""
    i = text.index(start)
    return text[:i] + text[text.index(end, i):]


def test_cli_flag_changes_only_the_discretize_and_what_describes_it(tmp_path, paper_derived):
    """generate --process-noise van-loan against the default: the discretize, its docs and counts, nothing else.

    The file header comments (filter description, operation counts) may differ;
    past them, the Python module differs only in the discretize and its scipy
    import, the C source only in the discretize, the C header only in the
    discretize's comment, the Q_d member's comment and the discretize scratch.
    """
    runner = CliRunner()
    for label, extra in (("taylor", []), ("van-loan", ["--process-noise", "van-loan"])):
        result = runner.invoke(main, ["generate", "--out", str(tmp_path / label), *extra])
        assert result.exit_code == 0, result.output
    assert "Van Loan's exact Q_d" in result.output  # the filter line the command prints
    name = paper_derived.model.name
    read = {k: {f: (tmp_path / k / name / f).read_text() for f in (f"{name}.py", f"{name}.c", f"{name}.h")} for k in ("taylor", "van-loan")}
    assert "Van Loan's exact Q_d" in read["van-loan"][f"{name}.c"].split("#include")[0]

    def body(text: str, first: str) -> str:
        return text[text.index(first):]

    # everything from the end of matrices_evaluate to the prediction is the discretize and its helpers
    py = [_without(body(read[k][f"{name}.py"], "import math"), "    return system_matrix(p)", "# The prediction's kernel") for k in read]
    assert _changed_lines(*py) == ["from scipy.linalg import blas, lapack", "from scipy.linalg import blas, lapack, expm"]

    def without_discretize(source: str) -> str:
        """The C source without what lies between matrices_evaluate and get_state (the discretize)."""
        start = source.index("\n}\n", source.index(f"int {name}_matrices_evaluate(")) + 3
        return source[:start] + source[source.index(f"void {name}_get_state"):]

    c = [without_discretize(body(read[k][f"{name}.c"], "#include")) for k in read]
    assert _changed_lines(*c) == []

    header = [body(read[k][f"{name}.h"], "#ifndef") for k in read]
    words = " ".join(header[1].split())  # comments are wrapped at 100 columns
    assert "Qd[NED_DOPPLER18_N_PACKED]; /* int_0^T e^{F s} G Q G^T e^{F^T s} ds (Van Loan), packed upper triangle" in words
    assert "the exact process noise Q_d = int_0^T e^{F s} G Q G^T e^{F^T s} ds by Van Loan's block exponential" in words
    for start, end in (
        ("/* The transition over one step T", "/* The filter state"),
        ("/* Scratch memory of discretize. */", "/* Scratch memory of predict"),
        ("/* The transition over a step T", f"int {name}_discretize("),
    ):
        header = [_without(h, start, end) for h in header]
    assert _changed_lines(*header) == []


@pytest.mark.compile
def test_float_and_compact_van_loan_builds_compile_strictly(tmp_path, paper_derived):
    """Float with packed storage, sequential update and recompute threshold; and a 64-state model (compact kernels)."""
    cases = [
        (paper_derived, CodegenOptions(process_noise="van-loan", scalar="float", storage="packed", update="sequential", recompute_threshold=1e-6)),
        (derive(large_model(64)), CodegenOptions(process_noise="van-loan")),
    ]
    for derived, options in cases:
        folder = write_atomically(tmp_path / f"{derived.model.name}-{options.slug()}", generate_code(derived, options).files)
        result = subprocess.run(
            [compiler(), *STRICT, "-O1", "-c", str(folder / f"{derived.model.name}.c"), "-o", str(folder / "filter.o")],
            capture_output=True,
            text=True,
        )
        assert result.returncode == 0, result.stderr


@pytest.mark.compile
def test_recompute_threshold_keeps_the_van_loan_transition(paper_derived, tmp_path):
    options = CodegenOptions(process_noise="van-loan", recompute_threshold=1e-6)
    name = paper_derived.model.name
    folder = write_atomically(tmp_path / "code", generate_code(paper_derived, options).files)
    compile_shared_library([folder / f"{name}.c"], folder / f"lib{name}.so", ("-O1",))
    filt = compiled({options.slug(): folder}, paper_derived, options)
    assert filt.discretize(60.0) == 0
    first = filt.Qd.copy()
    filt.transition.Qd[0] = 123.0  # a kept transition is returned untouched (Q_d(0, 0): packed index 0)
    assert filt.discretize(60.0) == 0 and filt.Qd[0, 0] == 123.0
    assert filt.discretize(1.0) == 0 and filt.Qd[0, 0] != 123.0
    assert filt.discretize(60.0) == 0 and np.array_equal(filt.Qd, first)


@pytest.mark.compile
@pytest.mark.parametrize("name", list(DEGENERATE))
def test_degenerate_models_compile_strictly_and_discretize_as_the_python(name, tmp_path):
    """No noises, no measurements, F = 0, one state: the Van Loan C compiles (double and float) and agrees with the Python."""
    derived = derive(load_model_text(DEGENERATE[name], filename=f"{name}.yaml"))
    model = derived.model.name
    for scalar in ("double", "float"):
        options = CodegenOptions(process_noise="van-loan", scalar=scalar)
        folder = write_atomically(tmp_path / scalar, generate_code(derived, options).files)
        result = subprocess.run(
            [compiler(), *STRICT, "-O0", "-c", str(folder / f"{model}.c"), "-o", str(folder / "filter.o")], capture_output=True, text=True
        )
        assert result.returncode == 0, result.stderr
    compile_shared_library([folder.parent / "double" / f"{model}.c"], tmp_path / f"lib{model}.so", ("-O0",))
    filt = CompiledFilter(tmp_path / f"lib{model}.so", model, ModelSizes.of(derived), derived.model.parameter_names, options=VAN_LOAN)
    assert filt.set_parameters({}) == 0
    assert filt.discretize(2.0) == 0
    module = load_python_module(folder.parent / "double" / f"{model}.py")
    p = module.parameter_vector({})
    phi, qd = module.discretize(module.system_matrix(p), module.noise_input_matrix(p), module.noise_psd(p), 2.0)
    # two algorithms (the C's block Taylor series, scipy's Pade): entry by entry to 1e-14, and an entry that
    # is structurally zero (the clock's Phi(1, 0)) to the unit roundoff of the matrix's scale
    np.testing.assert_allclose(filt.Phi, phi, rtol=1e-14, atol=np.finfo(float).eps * np.abs(phi).max())
    np.testing.assert_allclose(filt.Qd, qd, rtol=1e-14, atol=max(1e-300, np.finfo(float).eps * np.abs(qd).max()))
    if not derived.structure("F").any():
        assert np.array_equal(phi, np.eye(derived.n_states)) and np.array_equal(filt.Phi, phi)


@pytest.mark.compile
def test_float_van_loan_filter_stays_within_the_float_tolerance_of_the_exact_reference(paper_derived, tmp_path):
    """Single precision: the paper's 240 steps within embedded_check's float tolerance, and far closer to the exact Q_d than to eq. (9)'s."""
    options = CodegenOptions(process_noise="van-loan", scalar="float")
    scenario = paper_scenario(paper_derived)
    folder = write_atomically(tmp_path / "code", generate_code(paper_derived, options).files)
    (tmp_path / "build").mkdir()
    run = backend("c").run(folder, paper_derived, scenario, options, tmp_path / "build")
    exact = compare("c", run, reference_run(paper_derived, scenario, process_noise="van-loan"))
    taylor = compare("c", run, reference_run(paper_derived, scenario))
    tolerance = float_tolerance(paper_derived, scenario, options.taylor_order)
    assert exact.max_scaled_P < tolerance and exact.max_scaled_x < tolerance, exact
    assert exact.max_scaled_P < taylor.max_scaled_P / 100


@pytest.mark.compile
@require_tools(toolchain.CPPCHECK)
def test_van_loan_c_passes_cppcheck(paper_derived, tmp_path):
    """The Van Loan discretize's branches (double full with the accuracy rule; float packed, fixed order, recompute threshold)."""
    for options in (
        VAN_LOAN,
        CodegenOptions(process_noise="van-loan", scalar="float", storage="packed", taylor_tolerance=None, recompute_threshold=1e-6),
    ):
        folder = write_atomically(tmp_path / options.slug(), generate_code(paper_derived, options).files)
        toolchain.run_cppcheck([folder / "ned_doppler18.c", folder / "ned_doppler18.h"], folder, workers=cores_per_worker())
