"""Under AddressSanitizer and UndefinedBehaviorSanitizer the generated C keeps its contract.

The test driver (modelgen/codegen/backends/c/harness/c_test_driver.c.j2) checks
in C that every refused call returns its code and leaves the filter byte-for-byte unchanged, and that
every accepted call leaves it finite; the fuzz mode feeds seeded random and
hostile values (NaN, +-Inf, huge, tiny, zero, negative variances).
"""

import numpy as np
import pytest

from embedded_support import IN_CI, in_parallel, sanitizers_available
from modelgen.codegen import toolchain
from modelgen.codegen.options import CodegenOptions
from modelgen.checks.code_check import reference_run, scenario_tolerance
from modelgen.checks.embedded_check import compare_run, scenario_inputs
from modelgen.jobs import paper_scenario

pytestmark = [pytest.mark.embedded, pytest.mark.compile]


@pytest.fixture(scope="module", autouse=True)
def _skip_without_sanitizers():
    """Probed when the module runs, not at collection (a probe compiles and links an ASan program)."""
    if not IN_CI and not sanitizers_available():
        pytest.skip("the host compiler cannot build ASan/UBSan programs (libasan/libubsan absent)")


#: Together these reach every template branch: full/packed, vector/sequential, Joseph/standard, UD; double and float.
VARIANTS = (
    CodegenOptions(),
    CodegenOptions(scalar="float", storage="packed", update="sequential", covariance_update="standard"),
    CodegenOptions(storage="packed", covariance_update="standard"),
    CodegenOptions(update="sequential"),
    CodegenOptions(scalar="float", form="ud"),
)
FUZZ_CALLS = 20000


@pytest.fixture(scope="module")
def drivers(paper_derived, tmp_path_factory):
    root = tmp_path_factory.mktemp("sanitize")

    def build(options):
        folder = toolchain.write_filter(paper_derived, options, root / options.slug())
        return toolchain.build_host_driver(folder, paper_derived.model.name, folder / "driver")

    return dict(zip((o.slug() for o in VARIANTS), in_parallel(build, VARIANTS)))


@pytest.mark.parametrize("options", VARIANTS, ids=lambda o: o.slug())
def test_hostile_inputs_return_codes_and_leave_the_filter_unchanged(drivers, options):
    result = toolchain.run_driver(drivers[options.slug()], ["hostile"])
    assert b"hostile: 0 failure(s)" in result.stdout


@pytest.mark.parametrize("options", VARIANTS, ids=lambda o: o.slug())
def test_seeded_fuzz_finds_no_contract_violation_or_sanitizer_report(drivers, options):
    result = toolchain.run_driver(drivers[options.slug()], ["fuzz", str(FUZZ_CALLS), "20240601"])
    text = result.stdout.decode()
    assert f"fuzz: {FUZZ_CALLS} calls" in text and "0 failure(s)" in text
    ok, nonfinite, notpositive = (int(v) for v in __import__("re").findall(r"(\d+) ok, (\d+) non-finite refused, (\d+) not-positive refused", text)[0])
    assert ok > 0 and nonfinite > 0 and notpositive > 0  # all three outcomes were exercised


def test_paper_scenario_under_sanitizers_matches_reference(drivers, paper_derived):
    options = VARIANTS[0]
    scenario = paper_scenario(paper_derived)
    params, z = scenario_inputs(paper_derived, scenario)
    data = toolchain.encode_scenario(scenario.steps, params, scenario.step, scenario.x0(), scenario.initial_covariance, z, options.scalar)
    out = toolchain.run_driver(drivers[options.slug()], ["run"], stdin=data).stdout
    steps = toolchain.decode_run(out, paper_derived.n_states, options.scalar, options.ud)
    run = compare_run(steps, reference_run(paper_derived, scenario), options)
    assert run.steps == 240 and run.statuses_ok
    assert run.max_scaled_P < scenario_tolerance(paper_derived, scenario) and np.isfinite(run.max_scaled_x)
