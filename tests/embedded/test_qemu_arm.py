"""The generated filter, cross-built for ARM and run under qemu-arm, tracks the double reference."""

import pytest

from embedded_support import in_parallel, require_tools
from modelgen.codegen import toolchain
from modelgen.codegen.options import CodegenOptions
from modelgen.checks.embedded_check import EMBEDDED_OPTIONS, qemu_run, report_markdown
from modelgen.jobs import paper_scenario

pytestmark = [require_tools(toolchain.ARM_LINUX_CC, toolchain.QEMU_ARM), pytest.mark.embedded, pytest.mark.compile]

DOUBLE = CodegenOptions()


@pytest.fixture(scope="module")
def runs(paper_derived, tmp_path_factory):
    root = tmp_path_factory.mktemp("qemu")
    scenario = paper_scenario(paper_derived)
    assert scenario.steps == 240 and scenario.step == 60.0
    options = [*EMBEDDED_OPTIONS, DOUBLE]
    return dict(zip((o.slug() for o in options), in_parallel(lambda o: qemu_run(paper_derived, scenario, o, root), options)))


@pytest.mark.parametrize("options", EMBEDDED_OPTIONS, ids=lambda o: o.slug())
def test_float_filter_on_arm_stays_within_tolerance_of_double_reference(runs, options):
    run = runs[options.slug()]
    assert run.steps == 240 and run.statuses_ok
    assert run.max_scaled_P < run.tolerance and run.max_scaled_x < run.tolerance, (run.max_scaled_P, run.max_scaled_x, run.tolerance)
    assert run.symmetric


def test_float_covariance_is_positive_definite_wherever_float_can_resolve_it(runs):
    run = runs[EMBEDDED_OPTIONS[0].slug()]
    assert len(run.resolvable_steps) >= 230  # all but the first, nearly singular steps
    assert run.positive_definite_where_resolvable, run.not_positive_definite


def test_float_ud_filter_stays_positive_definite_at_every_step(runs):
    run = runs[EMBEDDED_OPTIONS[1].slug()]
    assert run.min_D is not None and run.min_D > 0
    assert run.not_positive_definite == []


def test_double_filter_on_arm_matches_reference_to_conformance_tolerance(runs):
    run = runs[DOUBLE.slug()]
    assert run.statuses_ok and run.symmetric
    assert run.tolerance < 1e-10  # the double bound, not the float one
    assert run.max_scaled_P < run.tolerance and run.max_scaled_x < run.tolerance
    assert run.not_positive_definite == []


def test_report_gives_measured_error_and_verdict(runs):
    text = report_markdown("ned_doppler18", {}, list(runs.values()))
    assert "qemu-arm" in text and f"{runs[EMBEDDED_OPTIONS[0].slug()].max_scaled_P:.2e}" in text
    assert "FAILED" not in text


@pytest.fixture(scope="module")
def gnss21_runs(tmp_path_factory):
    """The 21-state INS/GNSS filter in float (covariance and U-D) at the IMU step 5 ms and the GNSS step 1 s."""
    import dataclasses

    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model
    from modelgen.jobs import check_scenario

    derived = derive(load_model("ins_gnss21"))
    declared = check_scenario(derived)
    assert declared.step == 1.0
    root = tmp_path_factory.mktemp("gnss21")
    steps = (0.005, 1.0)

    def run(options):
        """Both steps of one build, one after the other: the second takes the first's build from the compile cache."""
        return [qemu_run(derived, dataclasses.replace(declared, step=step, steps=100), options, root / f"{step:g}")
                for step in steps]

    for step in steps:
        (root / f"{step:g}").mkdir()
    flown = in_parallel(run, EMBEDDED_OPTIONS)
    return {(step, o.slug()): r for o, runs in zip(EMBEDDED_OPTIONS, flown) for step, r in zip(steps, runs)}


@pytest.mark.parametrize("step", [0.005, 1.0], ids=["5ms", "1s"])
@pytest.mark.parametrize("options", EMBEDDED_OPTIONS, ids=lambda o: o.slug())
def test_21_state_ins_gnss_float_filter_meets_its_stated_tolerance(gnss21_runs, step, options):
    run = gnss21_runs[(step, options.slug())]
    assert run.steps == 100 and run.statuses_ok and run.symmetric
    assert run.tolerance < 1e-2  # (2n + 1) u_float sum rho over 100 steps: a bound, stated in the report
    assert run.within(), (run.max_scaled_P, run.max_scaled_x, run.tolerance)
    assert run.positive_definite_where_resolvable


def test_report_names_the_single_precision_form_to_use(gnss21_runs):
    from modelgen.checks.embedded_check import recommended_form

    runs = [r for (step, _), r in gnss21_runs.items() if step == 1.0]
    text = recommended_form(runs)
    error = {r.options.form: max(r.max_scaled_P, r.max_scaled_x) for r in runs}
    expected = "ud" if error["ud"] <= 2 * min(error.values()) else "covariance"
    assert f"--form {expected}" in text
    failing = [dataclass_replace_within(r) for r in runs]
    assert "No single-precision form" in recommended_form(failing)


def dataclass_replace_within(run):
    """The same run judged against a tolerance it cannot meet (to see the report say so)."""
    import dataclasses

    return dataclasses.replace(run, tolerance=run.max_scaled_P / 2)
