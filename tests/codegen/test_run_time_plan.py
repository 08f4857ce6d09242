"""The plan (doublings s, order m) is chosen at run time at the actual operating point (issue 31).

The generated code's norm uses a D balanced at generation time at the model's
check operating point; the 32-state model's check point has zero body rates,
so there its scale-factor states drive nothing and keep d = 1, and at a
manoeuvre (modelgen.jobs.synthetic_scenario) that D gives ||F||_D = 7.1 where
F's own balancing gives 0.89: 3 doublings where none are needed at
T = 0.148 s.  A plan on the fixed D that needs a doubling is retaken on F's
own balancing, swept from that D (modelgen.derivation.discretization.step_plan);
C, Python and the reference choose the same plan, and Phi and Q_d stay within
the stated bound against scipy's expm and Van Loan's exact Q_d at operating
points from 1 ms to a day.
"""

import numpy as np
import pytest

from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.discretization import (
    DEFAULT_TOLERANCE,
    balanced_norm,
    nominal_scaling,
    step_plan,
    taylor_discretization,
    taylor_plan,
    taylor_process_noise,
    van_loan_discretization,
)
from modelgen.derivation.symbolic import parameter_vector
from modelgen.jobs import synthetic_scenario
from tests.codegen.generated_support import build
from tests.derivation.test_discretization import bound, exact, relative_error

pytestmark = pytest.mark.compile

STEPS = [1e-3, 0.00247, 0.148, 1.0, 60.0, 600.0, 3600.0, 86400.0]


@pytest.fixture(scope="module")
def augmented(tmp_path_factory, derived_builtin):
    """The 32-state model, its manoeuvre operating point, and its generated C and Python (default options)."""
    derived = derived_builtin("ned_doppler32_augmented")
    values = synthetic_scenario(derived).parameters
    built = build(derived, tmp_path_factory.mktemp("augmented32"), CodegenOptions())
    return derived, values, built


def _c_at(derived, values, built):
    c = built.c_filter(CodegenOptions())
    assert c.set_parameters(dict(zip(derived.model.parameter_names, parameter_vector(derived.model, values)))) == 0
    return c


def test_the_fixed_scaling_is_far_off_at_the_manoeuvre_and_the_plan_is_not(augmented):
    """At T = 0.148 s the fixed D asks 3 doublings, F's own balancing none; step_plan takes F's own at every step."""
    derived, values, _ = augmented
    F = derived.numeric(values)["F"]
    scaling = nominal_scaling(derived)
    assert taylor_plan(balanced_norm(F, scaling), 0.148, 9)[0] == 3
    assert step_plan(F, 0.148, 9, DEFAULT_TOLERANCE, scaling) == (0, 9)
    for T in STEPS:
        fixed = taylor_plan(balanced_norm(F, scaling), T, 9)
        own = taylor_plan(balanced_norm(F), T, 9)
        plan = step_plan(F, T, 9, DEFAULT_TOLERANCE, scaling)
        assert plan[0] <= min(fixed[0], own[0]), T  # never more doublings than either norm asks
        if fixed[0] == 0:
            assert plan == fixed, T  # no doubling at stake: the one-pass norm, no sweeps
    assert step_plan(F, 86400.0, 9, DEFAULT_TOLERANCE, scaling)[0] < taylor_plan(balanced_norm(F, scaling), 86400.0, 9)[0]


def test_the_rebalancing_stops_at_the_first_sweep_that_takes_the_doublings_away(augmented):
    """At the manoeuvre and T = 0.148 s one sweep from the fixed D leaves no doubling: the rebalancing stops there, on the
    norm all eight sweeps reach; at T = 1 day a doubling stays at every sweep, and all of them run."""
    from modelgen.derivation.discretization import balancing_exponents, rebalanced_norm, scaled_norm

    derived, values, _ = augmented
    F = derived.numeric(values)["F"]
    scaling = nominal_scaling(derived)
    full = balancing_exponents(F, scaling)
    for T, sweeps in ((0.148, 1), (86400.0, 8)):
        seen = []

        def enough(exponents, T=T, seen=seen):
            seen.append(tuple(exponents))
            return taylor_plan(scaled_norm(F, exponents), T, 9)[0] == 0

        stopped = balancing_exponents(F, scaling, enough)
        assert len(seen) == sweeps, T
        assert (stopped != full) == (sweeps == 1), T  # the eight sweeps go on moving the exponents
        assert rebalanced_norm(F, scaling, T, 9) == scaled_norm(F, stopped) <= scaled_norm(F, full) * (1 + 1e-15), T
    assert step_plan(F, 0.148, 9, DEFAULT_TOLERANCE, scaling) == (0, 9)


def test_at_the_check_point_the_plan_is_the_fixed_scalings(augmented):
    """There the fixed D is F's own balancing: rebalancing from it changes nothing."""
    derived, _, _ = augmented
    F = derived.numeric(derived.model.check.parameter_values())["F"]
    scaling = nominal_scaling(derived)
    for T in STEPS:
        assert step_plan(F, T, 9, DEFAULT_TOLERANCE, scaling) == taylor_plan(balanced_norm(F, scaling), T, 9), T


@pytest.mark.parametrize("T", STEPS)
def test_python_chooses_the_reference_plan_and_c_its_transition(augmented, T, monkeypatch):
    """The generated Python's last plan is step_plan's; C and Python Phi, Q_d equal the reference's to rounding."""
    derived, values, built = augmented
    py = built.python
    m = derived.numeric(values)
    plans = []
    plan = py._taylor_plan
    monkeypatch.setattr(py, "_taylor_plan", lambda norm, step: plans.append(plan(norm, step)) or plans[-1])
    p = py.parameter_vector(values)
    phi_py, qd_py = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), T)
    scaling = nominal_scaling(derived)
    assert plans[-1] == step_plan(m["F"], T, 9, DEFAULT_TOLERANCE, scaling)
    phi_ref, gamma_ref = taylor_discretization(m["F"], m["G"], T, tolerance=DEFAULT_TOLERANCE, scaling=scaling)
    qd_ref = taylor_process_noise(gamma_ref, m["Q"], T)
    c = _c_at(derived, values, built)
    assert c.discretize(T) == 0
    for phi, qd in ((phi_py, qd_py), (c.Phi, c.Qd)):
        assert relative_error(phi, phi_ref) < 1e-13
        assert relative_error(qd, qd_ref) < 1e-12


@pytest.mark.parametrize("T", STEPS)
def test_phi_and_qd_meet_the_stated_bound_against_expm_at_the_manoeuvre(augmented, T):
    """Fewer doublings, the same accuracy, in C and Python: Phi against expm, Q_d against Gamma (Q/T) Gamma^T of
    the exact Gamma (the block exponential of [[F, G], [0, 0]] T), the bounds of tests/codegen/test_discretize_generated.py."""
    derived, values, built = augmented
    m = derived.numeric(values)
    phi_exact, gamma_exact = exact(m["F"], m["G"], T)
    qd_exact = taylor_process_noise(gamma_exact, m["Q"], T)
    py = built.python
    p = py.parameter_vector(values)
    phi_py, qd_py = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), T)
    c = _c_at(derived, values, built)
    assert c.discretize(T) == 0
    limit = bound(T, DEFAULT_TOLERANCE)
    for phi, qd in ((phi_py, qd_py), (c.Phi, c.Qd)):
        assert relative_error(phi, phi_exact) < limit
        assert relative_error(qd, qd_exact) < 10 * limit


def test_short_step_q_d_agrees_with_van_loan_at_the_manoeuvre(augmented):
    """At the filter's short step the paper's Gamma (Q/T) Gamma^T and Van Loan's exact integral of the noise agree
    to second order in T: here within 1e-5 (measured 7.2e-7), C and Python."""
    derived, values, built = augmented
    m = derived.numeric(values)
    T = 0.00247
    _, qd_exact = van_loan_discretization(m["F"], m["G"], m["Q"], T)
    py = built.python
    p = py.parameter_vector(values)
    _, qd_py = py.discretize(py.system_matrix(p), py.noise_input_matrix(p), py.noise_psd(p), T)
    c = _c_at(derived, values, built)
    assert c.discretize(T) == 0
    for qd in (qd_py, c.Qd):
        assert relative_error(qd, qd_exact) < 1e-5


def test_the_c_plans_single_step_thresholds_are_exactly_where_the_bound_crosses_the_tolerance():
    """theta_m (the generated C's fast path with no doubling): taylor_plan picks order m at theta_m and more just above it."""
    from modelgen.derivation.discretization import single_step_thresholds

    thresholds = single_step_thresholds(9, DEFAULT_TOLERANCE)
    assert list(thresholds) == sorted(thresholds) and thresholds[-1] < 9 + 1
    for m, theta in enumerate(thresholds, start=1):
        s, order = taylor_plan(theta, 1.0, 9)
        assert (s, order) == (0, m)
        above = taylor_plan(float(np.nextafter(theta, 10.0)), 1.0, 9)
        if m == 9:
            assert above[0] == 1  # past the highest order's reach: a doubling
        else:
            assert above == (0, m + 1)


def test_the_c_plan_is_the_reference_plan_on_both_sides_of_every_threshold(augmented, tmp_path):
    """The generated C's taylor_plan (its fast path below theta_order, its loops above) called directly, at each
    theta_m, the doubles either side of it and a spread of other norms: the same (s, m) as the reference."""
    import subprocess

    from modelgen.derivation.discretization import single_step_thresholds

    derived, _, built = augmented
    name = derived.model.name
    thetas = []
    for theta in single_step_thresholds(9, DEFAULT_TOLERANCE):
        thetas += [theta, float(np.nextafter(theta, 0.0)), float(np.nextafter(theta, 10.0))]
    thetas += [float(x) for x in np.geomspace(1e-15, 1e12, 200)]
    (tmp_path / "plan.c").write_text(
        f'#include "{name}.c"\n#include <stdio.h>\nint main(void)\n{{\n    static const double theta[] = {{ '
        + ", ".join(repr(t) for t in thetas)
        + " };\n    unsigned i;\n    for (i = 0; i < sizeof theta / sizeof theta[0]; ++i) {\n"
        "        int s = -1, m = -1, status = taylor_plan(theta[i], 1.0, &s, &m);\n"
        '        printf("%d %d %d\\n", status, s, m);\n    }\n    return 0;\n}\n'
    )
    subprocess.run(["gcc", "-std=c99", "-O2", f"-I{built.folder}", "plan.c", "-o", "plan", "-lm"], cwd=tmp_path, check=True)
    lines = subprocess.run(["./plan"], cwd=tmp_path, check=True, capture_output=True, text=True).stdout.split("\n")
    for theta, line in zip(thetas, lines):
        status, s, m = map(int, line.split())
        assert status == 0 and (s, m) == taylor_plan(theta, 1.0, 9), theta


def test_the_compact_loops_rebalance_as_the_unrolled_code_does(augmented, tmp_path, monkeypatch):
    """The compact discretize (large models' loops, forced here) at the manoeuvre: Phi and Q_d as the reference's."""
    from modelgen.codegen import kernels

    derived, values, _ = augmented
    monkeypatch.setattr(kernels, "COMPACT_ABOVE_FLOPS", 0)
    built = build(derived, tmp_path / "compact", CodegenOptions())
    assert "horner_series" in (built.folder / f"{derived.model.name}.c").read_text()  # the loops, not the unrolled blocks
    m = derived.numeric(values)
    scaling = nominal_scaling(derived)
    c = _c_at(derived, values, built)
    for T in (0.00247, 0.148, 1.0, 60.0, 86400.0):
        assert c.discretize(T) == 0
        phi_ref, gamma_ref = taylor_discretization(m["F"], m["G"], T, tolerance=DEFAULT_TOLERANCE, scaling=scaling)
        assert relative_error(c.Phi, phi_ref) < 1e-13
        assert relative_error(c.Qd, taylor_process_noise(gamma_ref, m["Q"], T)) < 1e-12


def _c_norms(built, name: str, matrices: list[np.ndarray], tmp_path, T: float) -> list[tuple[float, float]]:
    """(balanced_norm, rebalanced_norm at step T) of the generated C, its static functions called directly, for each F."""
    import subprocess

    entries = [(int(i), int(j)) for i, j in zip(*np.nonzero(built.derived.structure("F")))]
    sets = "\n".join(
        "    " + " ".join(f"m.F[{e}] = {float(F[i, j])!r};" for e, (i, j) in enumerate(entries))
        + f'\n    printf("%.17g %.17g\\n", balanced_norm(&m, &rows_sum), rebalanced_norm(&m, {T!r}, &ws.discretize));'
        for F in matrices
    )
    (tmp_path / "norms.c").write_text(
        f'#include "{name}.c"\n#include <stdio.h>\nstatic {name}_matrices m;\nstatic {name}_workspace ws;\n'
        f"static {name}_scalar rows_sum;\n"
        f"int main(void)\n{{\n{sets}\n    return 0;\n}}\n"
    )
    subprocess.run(["gcc", "-std=c99", "-O2", f"-I{built.folder}", "norms.c", "-o", "norms", "-lm"], cwd=tmp_path, check=True)
    out = subprocess.run(["./norms"], cwd=tmp_path, check=True, capture_output=True, text=True).stdout.split()
    return [(float(out[2 * k]), float(out[2 * k + 1])) for k in range(len(matrices))]


@pytest.mark.parametrize("compact", [False, True])
@pytest.mark.parametrize("T", [0.148, 86400.0])
def test_the_c_norms_are_the_references_bit_for_bit(augmented, compact, T, tmp_path, monkeypatch):
    """The fixed-D norm and the norm rebalanced from that D, in the unrolled and the compact C: the reference's exactly,
    at the manoeuvre, the check point and random operating points on the same structure (so C plans as step_plan),
    at a step where the rebalancing may stop early (0.148 s) and one where every sweep still leaves a doubling (1 day)."""
    from modelgen.codegen import kernels
    from modelgen.derivation.discretization import rebalanced_norm, scaled_norm

    derived, values, built = augmented
    if compact:
        monkeypatch.setattr(kernels, "COMPACT_ABOVE_FLOPS", 0)
        built = build(derived, tmp_path / "compact", CodegenOptions())
    scaling = nominal_scaling(derived)
    F = derived.numeric(values)["F"]
    rng = np.random.default_rng(3)
    matrices = [F, derived.numeric(derived.model.check.parameter_values())["F"]]
    matrices += [np.where(F != 0, rng.standard_normal(F.shape) * 10.0 ** rng.integers(-8, 8, F.shape), 0.0) for _ in range(4)]
    matrices = [np.where(derived.structure("F"), G, 0.0) for G in matrices]
    norms = _c_norms(built, derived.model.name, matrices, tmp_path, T)
    for G, (fixed, rebalanced) in zip(matrices, norms):
        assert fixed == scaled_norm(G, scaling)
        assert rebalanced == rebalanced_norm(G, scaling, T, 9)
    # the manoeuvre: 0.89 against 7.1.  The C program's first F is the manoeuvre's (it reads F's structural entries
    # only, which matrices[0] keeps), computed first, so from the same static state as in a program of its own
    assert norms[0][1] < 0.2 * scaled_norm(F, scaling)
