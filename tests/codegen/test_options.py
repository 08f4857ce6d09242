"""Every supported option combination is the same filter as the numpy reference.

Each combination is generated, compiled (in parallel, -O1 to keep the suite
fast) and run through ctypes over the core paper's 4-hour scenario.  Double
precision must agree with the dense numpy reference to the conformance
tolerance; single precision must stay within modelgen.checks.embedded_check.FLOAT_TOLERANCE
of it (the justification is in that module's docstring).
"""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from modelgen.codegen.build import CompiledFilter, compile_shared_library
from modelgen.codegen.generate import generate_code, write_atomically
from modelgen.codegen.layout import ModelSizes, packed_index, upper_index
from modelgen.codegen.options import CodegenOptions, all_combinations
from modelgen.checks.code_check import compare, measurement_sequence, reference_run, scenario_tolerance
from modelgen.derivation.symbolic import parameter_vector
from modelgen.checks.embedded_check import float_tolerance, smallest_correlation_eigenvalue
from modelgen.errors import ModelError
from modelgen.jobs import paper_scenario
from tests.parallel_support import cores_per_worker

COMBINATIONS = all_combinations("double") + all_combinations("float")


@pytest.fixture(scope="module")
def scenario(paper_derived):
    return paper_scenario(paper_derived)


@pytest.fixture(scope="module")
def reference(paper_derived, scenario):
    return reference_run(paper_derived, scenario)


@pytest.fixture(scope="module")
def libraries(paper_derived, tmp_path_factory):
    """slug -> compiled shared library of that combination (through the run's compile cache: tests/codegen/generated_support.build)."""
    root = tmp_path_factory.mktemp("options")
    name = paper_derived.model.name

    def build(options):
        folder = write_atomically(root / options.slug(), generate_code(paper_derived, options).files)
        return options.slug(), compile_shared_library([folder / f"{name}.c"], folder / f"lib{name}.so", ("-O1",), cache=True)

    with ThreadPoolExecutor(max_workers=cores_per_worker()) as pool:
        return dict(pool.map(build, COMBINATIONS))


def run_filter(libraries, derived, scenario, options):
    """(x, P) after every step and the filter object, through the generated C."""
    filt = CompiledFilter(libraries[options.slug()], derived.model.name, ModelSizes.of(derived), derived.model.parameter_names, options=options)
    filt.set_parameters(dict(zip(derived.model.parameter_names, parameter_vector(derived.model, scenario.parameters))))
    assert filt.discretize(scenario.step) == 0
    assert filt.set_state(scenario.x0(), scenario.initial_covariance) == 0
    out, d_min = [], []
    for z in measurement_sequence(derived, scenario):
        assert filt.predict() == 0
        assert filt.update(z) == 0
        out.append((filt.x, filt.P))
        if options.ud:
            d_min.append(float(np.ctypeslib.as_array(filt.filter.D).min()))
    return out, d_min


@pytest.mark.compile
@pytest.mark.parametrize("options", all_combinations("double"), ids=lambda o: o.slug())
def test_double_combination_matches_numpy_reference(libraries, paper_derived, scenario, reference, options):
    run, _ = run_filter(libraries, paper_derived, scenario, options)
    result = compare(options.slug(), run, reference)
    assert result.steps == 240
    tolerance = scenario_tolerance(paper_derived, scenario)
    assert result.max_scaled_P < tolerance and result.max_scaled_x < tolerance, result
    assert result.symmetric
    assert all(smallest_correlation_eigenvalue(P) > 0 for _, P in run)


@pytest.mark.compile
@pytest.mark.parametrize("options", all_combinations("float"), ids=lambda o: o.slug())
def test_float_combination_stays_within_stated_tolerance_of_double_reference(libraries, paper_derived, scenario, reference, options):
    run, d_min = run_filter(libraries, paper_derived, scenario, options)
    result = compare(options.slug(), run, reference)
    tolerance = float_tolerance(paper_derived, scenario, options.taylor_order)
    assert result.max_scaled_P < tolerance and result.max_scaled_x < tolerance, result
    assert result.symmetric
    n = paper_derived.n_states
    for (_, P), (_, P_ref) in zip(run, reference):
        # float can only be asked to resolve a P whose correlation matrix is not closer to singular than its error
        if smallest_correlation_eigenvalue(P_ref) > n * result.max_scaled_P:
            assert smallest_correlation_eigenvalue(P) > 0
    if options.ud:
        assert min(d_min) > 0  # U D U^T is positive definite at every step, even the nearly singular first


@pytest.mark.compile
def test_packed_storage_keeps_only_the_upper_triangle(libraries, paper_derived):
    n = paper_derived.n_states
    full = CompiledFilter(libraries["double-full-vector-joseph"], paper_derived.model.name, ModelSizes.of(paper_derived), paper_derived.model.parameter_names, options=CodegenOptions())
    packed_options = CodegenOptions(storage="packed")
    packed = CompiledFilter(libraries[packed_options.slug()], paper_derived.model.name, ModelSizes.of(paper_derived), paper_derived.model.parameter_names, options=packed_options)
    import ctypes

    assert ctypes.sizeof(full.filter) == 8 * (n + n * n)
    assert ctypes.sizeof(packed.filter) == 8 * (n + n * (n + 1) // 2)
    rng = np.random.default_rng(3)
    A = rng.standard_normal((n, n))
    P = A @ A.T
    assert packed.set_state(np.zeros(n), P) == 0
    stored = np.ctypeslib.as_array(packed.filter.P)
    assert stored[packed_index(n, 2, 5)] == P[2, 5] and stored[packed_index(n, 5, 2)] == P[2, 5]
    assert np.array_equal(packed.P, P)


@pytest.mark.compile
def test_ud_factorization_round_trips_and_refuses_indefinite_covariance(libraries, paper_derived):
    options = CodegenOptions(form="ud")
    n = paper_derived.n_states
    filt = CompiledFilter(libraries[options.slug()], paper_derived.model.name, ModelSizes.of(paper_derived), paper_derived.model.parameter_names, options=options)
    rng = np.random.default_rng(5)
    A = rng.standard_normal((n, n))
    P = A @ A.T + 0.1 * np.eye(n)
    assert filt.set_state(np.zeros(n), P) == 0
    U = np.eye(n)
    for i in range(n):
        for j in range(i + 1, n):
            U[i, j] = np.ctypeslib.as_array(filt.filter.U)[upper_index(n, i, j)]
    D = np.ctypeslib.as_array(filt.filter.D).copy()
    assert np.allclose(U @ np.diag(D) @ U.T, P, rtol=1e-12, atol=1e-12)
    assert np.allclose(filt.P, P, rtol=1e-12, atol=1e-12)
    before = bytes(filt.filter)
    indefinite = P.copy()
    indefinite[n - 1, n - 1] = -1.0
    assert filt.set_state(np.zeros(n), indefinite) == 2
    assert bytes(filt.filter)[8 * n :] == before[8 * n :]  # U and D untouched (x is set by the caller first)


@pytest.mark.compile
@pytest.mark.parametrize("options", [o for o in COMBINATIONS if not o.ud], ids=lambda o: o.slug())
def test_covariance_form_refuses_a_covariance_that_is_not_positive_semidefinite(libraries, paper_derived, scenario,
                                                                                 options):
    """Every diagonal entry positive but a correlation beyond 1: only a factorization sees it."""
    n = paper_derived.n_states
    filt = CompiledFilter(libraries[options.slug()], paper_derived.model.name, ModelSizes.of(paper_derived),
                          paper_derived.model.parameter_names, options=options)
    P0 = scenario.initial_covariance  # semidefinite: the paper's zero initial velocity and position variances
    assert np.any(np.diag(P0) == 0) and filt.set_state(np.zeros(n), P0) == 0
    before = filt.P.copy()
    correlated = P0.copy()
    correlated[0, 1] = correlated[1, 0] = 1.01 * np.sqrt(P0[0, 0] * P0[1, 1])
    assert filt.set_state(np.zeros(n), correlated) == 2  # ERR_NOT_POSITIVE
    assert np.array_equal(filt.P, before)


@pytest.mark.parametrize("options", [o for o in COMBINATIONS if o.sequential], ids=lambda o: o.slug())
def test_sequential_and_ud_updates_need_no_square_root(paper_derived, options):
    source = generate_code(paper_derived, options).files["ned_doppler18.c"]
    update = source[source.index("int ned_doppler18_update(") :]
    assert "sqrt" not in update


def test_unknown_option_values_are_refused_with_their_name():
    with pytest.raises(ModelError, match="storage"):
        CodegenOptions(storage="diagonal")
    with pytest.raises(ModelError, match="update"):
        CodegenOptions(update="batch")
    with pytest.raises(ModelError, match="covariance update"):
        CodegenOptions(covariance_update="square-root")
    with pytest.raises(ModelError, match="form"):
        CodegenOptions(form="information")


def test_options_are_described_in_the_generated_header(paper_derived):
    header = generate_code(paper_derived, CodegenOptions(scalar="float", form="ud")).files["ned_doppler18.h"]
    assert "Thornton" in header and "Bierman" in header and "typedef float ned_doppler18_scalar;" in header


def test_every_combination_generates_byte_identical_output_across_processes(paper_derived, tmp_path):
    import os
    import subprocess
    import sys

    script = (
        "import sys; from modelgen.codegen.generate import generate_code; from modelgen.codegen.options import all_combinations; "
        "from modelgen.derivation.symbolic import derive; from modelgen.model.loading import load_model; import hashlib; "
        "d = derive(load_model('ned_doppler18')); "
        "print(hashlib.sha256(repr([sorted(generate_code(d, o).files.items()) for o in all_combinations('float')[::3]]).encode()).hexdigest())"
    )
    digests = {
        subprocess.run([sys.executable, "-c", script], check=True, capture_output=True, text=True, env={**os.environ, "PYTHONHASHSEED": seed}).stdout
        for seed in ("3", "4242")
    }
    assert len(digests) == 1


@pytest.mark.parametrize(
    "name,options",
    [
        ("ned_doppler32_augmented", CodegenOptions(form="ud")),
        ("ned_doppler32_augmented", CodegenOptions(storage="packed", update="sequential")),
        ("ned_inertial16", CodegenOptions(storage="packed", covariance_update="standard")),
    ],
    ids=lambda v: v if isinstance(v, str) else v.slug(),
)
@pytest.mark.compile
def test_other_models_match_the_reference_in_other_combinations(name, options, tmp_path, derived_builtin):
    from modelgen.jobs import synthetic_scenario

    derived = derived_builtin(name)
    scenario = synthetic_scenario(derived, steps=60)
    folder = write_atomically(tmp_path / "f", generate_code(derived, options).files)
    library = compile_shared_library([folder / f"{name}.c"], folder / f"lib{name}.so", ("-O1",))
    filt = CompiledFilter(library, name, ModelSizes.of(derived), derived.model.parameter_names, options=options)
    filt.set_parameters(dict(zip(derived.model.parameter_names, parameter_vector(derived.model, scenario.parameters))))
    assert filt.discretize(scenario.step) == 0
    assert filt.set_state(scenario.x0(), scenario.initial_covariance) == 0
    run = []
    for z in measurement_sequence(derived, scenario):
        assert filt.predict() == 0
        if derived.n_measurements:
            assert filt.update(z) == 0
        run.append((filt.x, filt.P))
    result = compare(name, run, reference_run(derived, scenario))
    tolerance = scenario_tolerance(derived, scenario)
    assert result.max_scaled_P < tolerance and result.max_scaled_x < tolerance, result
