"""Sums of products in two lanes (issue 14): the order of kernels.lane_split, printed as vector code.

The propagate rows, x_n = Phi x and the Q_d rows sum their products in two
lanes (``kernels.lane_split``); the C prints a pair of products as one SSE2
vector product under GCC with SSE2, and as two scalars otherwise (or with
``<MODEL>_SCALAR_LANE_PAIRS`` defined): the same operations in the same order.
"""

from __future__ import annotations

import platform
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from modelgen.codegen.backends.c.printer import c_lines
from modelgen.codegen.build import CompiledFilter, compile_shared_library
from modelgen.codegen.generate import generate_code
from modelgen.codegen.kernels import MIN_LANE_PAIRS, Assign, CheckedAssign, Ref, lane_split
from modelgen.codegen.layout import ModelSizes

from generated_support import write_files

OK = 0
GENERATED = Path(__file__).resolve().parents[2] / "generated"


def m(k: int) -> Ref:
    return Ref("scratch", "M", (k,))


def phi(k: int) -> Ref:
    return Ref("transition", "Phi", (k,))


QD = (Ref("transition", "Qd", (3,)),)


def test_products_pair_by_position_then_an_odd_product_and_the_rest_follow():
    """(t0, t1), (t2, t3) pair whatever their indices; t4 and the Q_d entry are added after the lanes."""
    terms = ((m(0), phi(15)), (m(1), phi(16)), (m(2), phi(17)), (m(4), phi(18)), (m(9), phi(30)), QD)
    assert lane_split(terms) == ((terms[0:2], terms[2:4]), terms[4:])


def test_fewer_products_than_the_minimum_keep_the_plain_order():
    """One product short of MIN_LANE_PAIRS pairs: summed left to right; one more product: in two lanes."""
    short = tuple((m(k), phi(k)) for k in range(2 * MIN_LANE_PAIRS - 1))
    assert lane_split(short + (QD,)) == ((), short + (QD,))
    enough = short + ((m(9), phi(9)),)
    assert len(lane_split(enough + (QD,))[0]) == MIN_LANE_PAIRS
    terms = ((m(0), phi(0)), (m(1), phi(1)), (m(5), phi(2)))
    statement = Assign(Ref("scratch", "xn", (0,)), terms)
    assert c_lines(statement, two_lanes=True) == ["w->xn[0] = w->M[0]*t->Phi[0] + w->M[1]*t->Phi[1] + w->M[5]*t->Phi[2];"]


def test_consecutive_factors_load_as_one_pair_and_others_are_gathered():
    """M[0], M[1] is one load; M[2], M[4] (not consecutive) is built from two values; the lanes come first."""
    statement = CheckedAssign((Ref("scratch", "Pn", (3,)),), ((m(0), phi(0)), (m(1), phi(1)), (m(2), phi(2)),
                                                              (m(4), phi(3)), (m(7), phi(4)), QD))
    assert c_lines(statement, two_lanes=True) == [
        "acc = lane_pair_product(lane_pair_load(&w->M[0]), lane_pair_load(&t->Phi[0]));",
        "acc = lane_pair_add_product(acc, lane_pair_of(w->M[2], w->M[4]), lane_pair_load(&t->Phi[2]));",
        "v = lane_pair_sum(acc) + w->M[7]*t->Phi[4] + t->Qd[3]; w->Pn[3] = v; check += v;",
    ]
    assert c_lines(statement) == ["v = w->M[0]*t->Phi[0] + w->M[1]*t->Phi[1] + w->M[2]*t->Phi[2] + w->M[4]*t->Phi[3] + "
                                  "w->M[7]*t->Phi[4] + t->Qd[3]; w->Pn[3] = v; check += v;"]


def test_factors_in_another_row_are_not_consecutive():
    """term[1][0] does not follow term[0][1] in memory (another row): the pair is gathered."""
    a, b = Ref("scratch", "term", (0, 1)), Ref("scratch", "term", (1, 0))
    statement = Assign(m(0), ((a, phi(0)), (b, phi(1)), (a, phi(2)), (b, phi(3))))
    assert c_lines(statement, two_lanes=True)[0] == (
        "acc = lane_pair_product(lane_pair_of(w->term[0][1], w->term[1][0]), lane_pair_load(&t->Phi[0]));")


def _run(folder, derived, flags: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Filter cycles at the model's check scenario (its step, then 60 times shorter), with updates, of the
    library compiled with ``flags``."""
    from modelgen.jobs import check_scenario

    model = derived.model
    scenario = check_scenario(derived)
    library = compile_shared_library([folder / f"{model.name}.c"], folder / f"lib{model.name}-{len(flags)}.so", flags)
    c = CompiledFilter(library, model.name, ModelSizes.of(derived), model.parameter_names)
    assert c.set_parameters(dict(scenario.parameters)) == OK
    rng = np.random.default_rng(5)
    assert c.set_state(0.1 * rng.standard_normal(c.n), scenario.initial_covariance) == OK
    out = {"library": np.frombuffer(library.read_bytes(), np.uint8)}
    for step, T in enumerate((scenario.step, scenario.step / 60, scenario.step)):
        assert c.discretize(T) == OK
        out[f"Phi{step}"], out[f"Qd{step}"] = c.Phi.copy(), c.Qd.copy()
        assert c.predict() == OK
        if c.nm:
            assert c.update(0.01 * rng.standard_normal(c.nm)) == OK
        out[f"x{step}"], out[f"P{step}"] = c.x.copy(), c.P.copy()
    return out


@pytest.mark.compile
@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="the vector lanes are SSE2 code (x86-64)")
@pytest.mark.parametrize("optimization", ["-O2", "-Os"])  # at -Os gcc does not inline the scalar helpers
@pytest.mark.parametrize("name", ["ned_doppler18", "ins_gnss21"])
def test_vector_and_scalar_lanes_give_the_same_bits(name, optimization, derived_builtin, tmp_path):
    """Discretize, predict and update of the SSE2 build equal the scalar-lane build bit for bit (-std=c99: no fused products)."""
    derived = derived_builtin(name)
    files = generate_code(derived).files
    source = files[f"{derived.model.name}.c"]
    assert "lane_pair_add_product(acc" in source and "__SSE2_MATH__" in files["modelgen_lane_pair.h"]  # two-lane sums
    folder = write_files(tmp_path, files)
    vector = _run(folder, derived, (optimization,))
    scalar = _run(folder, derived, (optimization, f"-D{derived.model.name.upper()}_SCALAR_LANE_PAIRS"))
    assert vector.pop("library").tobytes() != scalar.pop("library").tobytes()  # the SSE2 lanes were compiled in
    for key, value in vector.items():
        assert value.tobytes() == scalar[key].tobytes(), key


@pytest.mark.compile
@pytest.mark.skipif(shutil.which("clang") is None, reason="clang is not installed (.ci/run installs it)")
@pytest.mark.parametrize("lanes", ["vector", "scalar"])
def test_the_committed_c_passes_clangs_strict_checks(lanes):
    """clang -std=c99 -pedantic -Wall -Wextra -Werror on every committed C file, both lane paths (clang warns of an unused
    static inline helper, which gcc does not)."""
    sources = sorted(GENERATED.glob("**/*.c"))
    assert len(sources) >= 14
    for source in sources:
        define = [f"-D{source.stem.upper()}_SCALAR_LANE_PAIRS"] if lanes == "scalar" else []
        result = subprocess.run(["clang", "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-fsyntax-only", *define, str(source)],
                                capture_output=True, text=True)
        assert result.returncode == 0, f"{source}:\n{result.stderr[:2000]}"
