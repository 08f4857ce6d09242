"""The C++17 backend: a header-only class per model over the C, and the C header includable from C++ (issue 29, item 3).

The committed class of every model and option golden compiles with g++ and
clang++ at -std=c++17 -Wall -Wextra -Werror -pedantic, with Eigen and
without; a C++ translation unit that includes the C header alone calls the
C filter; and the class flies the check scenario through ``Backend.run``
(``modelgen.checks.code_check.check_generated``) to the same bits as the C.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from modelgen.codegen.backends.cpp.run import eigen_flags
from modelgen.codegen.backends.registry import backend
from modelgen.codegen.build import CXX_STRICT_FLAGS, STRICT_FLAGS, compiler
from modelgen.codegen.generate import generate_code
from modelgen.checks.code_check import check_generated

from generated_support import write_files

pytestmark = pytest.mark.compile

GENERATED = Path(__file__).resolve().parents[2] / "generated"
COMPILERS = [c for c in ("g++", "clang++") if shutil.which(c)]

#: Calls every member of the class (the ones a model without measurements lacks are left out by the macro).
USE_THE_CLASS = """#include "{name}.hpp"

int use_{name}_class(void);

int use_{name}_class(void)
{{
    using namespace modelgen::{name};
    static Filter filter; // the C's structs: static, not on the stack
    Scalar x[N_STATES] = {{}}, P[N_STATES * N_STATES] = {{}}, Phi[N_STATES * N_STATES];
    for (int i = 0; i < N_STATES; ++i) {{
        P[i * N_STATES + i] = 1;
    }}
    if (filter.evaluate() != Status::ok || filter.discretize(1) != Status::ok || filter.set_state(x) != Status::ok
        || filter.set_covariance(P) != Status::ok || filter.predict() != Status::ok) {{
        return 1;
    }}
    filter.get_state(x);
    filter.get_covariance(P);
    filter.get_transition_matrix(Phi);
    filter.reset_error_state();
#if {P}_N_MEASUREMENTS
    Scalar z[N_MEASUREMENTS] = {{}}, innovation[N_MEASUREMENTS], nis = 0;
    if (filter.update(z) != Status::ok || filter.update_masked(z, nullptr, innovation, &nis) != Status::ok) {{
        return 2;
    }}
#endif
#ifdef {P}_HAS_EIGEN
    const Filter::Covariance covariance = filter.covariance();
    if (filter.state().data() != filter.x() || filter.set_covariance(covariance) != Status::ok) {{
        return 3; // the state view is the filter's own memory
    }}
#endif
    return static_cast<int>(filter.set_transition_matrix(Phi)) + 0 * STATE_{state} + 0 * N_NOISES;
}}
"""


def committed_classes() -> list[Path]:
    return sorted(GENERATED.glob("**/*.hpp"))


def test_every_committed_folder_has_its_class():
    headers = sorted(h for h in GENERATED.glob("**/*.h") if not h.name.startswith("modelgen_"))  # not the C runtime
    assert len(headers) >= 20
    for header in headers:
        assert header.with_suffix(".hpp").is_file(), header


def translation_units() -> list[list[Path]]:
    """The committed classes in as few C++ files as can hold them: every model's once, then each option variant of the paper's."""
    by_model: dict[str, list[Path]] = {}
    for hpp in committed_classes():
        by_model.setdefault(hpp.stem, []).append(hpp)
    units = []
    while any(by_model.values()):
        units.append([paths.pop(0) for paths in by_model.values() if paths])
    return units


def _syntax_check(cxx: str, classes: list[Path], tmp_path: Path, eigen: bool, unit: int) -> None:
    """One C++17 file using every class in ``classes`` (distinct models), checked strictly."""
    text = ""
    for hpp in classes:
        name = hpp.stem
        state = next(line.split()[2] for line in hpp.read_text().splitlines() if line.startswith("constexpr int STATE_"))
        text += USE_THE_CLASS.format(name=name, P=name.upper(), state=state.removeprefix("STATE_"))
    source = tmp_path / f"unit{unit}.cpp"
    source.write_text(text)
    flags = [*eigen_flags()] if eigen else [f"-D{hpp.stem.upper()}_NO_EIGEN" for hpp in classes]
    includes = [f"-I{hpp.parent}" for hpp in classes]
    result = subprocess.run([cxx, *CXX_STRICT_FLAGS, *flags, *includes, "-fsyntax-only", str(source)], capture_output=True, text=True)
    assert result.returncode == 0, f"{[str(c) for c in classes]}:\n{result.stderr[:3000]}"


@pytest.mark.skipif(not COMPILERS, reason="no C++ compiler (.ci/run installs g++ and clang++)")
@pytest.mark.parametrize("cxx", COMPILERS)
def test_every_committed_class_compiles_strictly_as_cpp17(cxx, tmp_path):
    """Every model's class and every option variant with plain arrays (<MODEL>_NO_EIGEN), and with Eigen's views the
    default classes and the variants whose P is not an N x N array (UD, packed: P a copy); Eigen is slow to parse."""
    units = translation_units()
    assert sum(len(u) for u in units) == len(committed_classes())
    for k, classes in enumerate(units):
        _syntax_check(cxx, classes, tmp_path, False, k)
    if not eigen_flags():
        pytest.skip("Eigen is not installed (.ci/run installs libeigen3-dev): the Eigen views were not compiled")
    for k, classes in enumerate(units):
        if k == 0 or any(kind in classes[0].parent.name for kind in ("-ud", "-packed")):
            _syntax_check(cxx, classes, tmp_path, True, k)


@pytest.mark.skipif(not COMPILERS, reason="no C++ compiler (.ci/run installs g++ and clang++)")
@pytest.mark.parametrize("cxx", COMPILERS)
def test_the_c_header_included_from_cpp_calls_the_c_filter(cxx, derived_builtin, tmp_path):
    """extern "C" and no restrict in C++: a C++ program that includes only the C header links the C filter and runs it."""
    derived = derived_builtin("gps_pseudorange11")
    name = derived.model.name
    folder = write_files(tmp_path / "gen", generate_code(derived).files)
    program = tmp_path / "main.cpp"
    program.write_text(f"""#include "{name}.h"

int main()
{{
    static {name}_params params;
    static {name}_matrices m;
    static {name}_transition t;
    static {name}_filter f;
    static {name}_workspace work;
    {name}_scalar P[{name.upper()}_N_STATES * {name.upper()}_N_STATES] = {{}};
    const {name}_scalar z[{name.upper()}_N_MEASUREMENTS] = {{}};
    for (int i = 0; i < {name.upper()}_N_STATES; ++i) {{
        P[i * {name.upper()}_N_STATES + i] = 1.0;
    }}
    {name}_default_params(&params);
    params.{derived.model.parameters[0].name} = 0.5;
    int status = {name}_matrices_evaluate(&params, &m);
    status = status ? status : {name}_discretize(&m, 1.0, &t, &work);
    status = status ? status : {name}_set_covariance(&f, P, &work);
    status = status ? status : {name}_predict(&f, &t, &work);
    status = status ? status : {name}_update(&f, z, &m, &work);
    return status;
}}
""")
    c_object = tmp_path / f"{name}.o"
    built = subprocess.run([compiler(), *STRICT_FLAGS, "-O0", "-c", str(folder / f"{name}.c"), "-o", str(c_object)], capture_output=True, text=True)
    assert built.returncode == 0, built.stderr[:2000]
    exe = tmp_path / "main"
    linked = subprocess.run([cxx, *CXX_STRICT_FLAGS, "-I", str(folder), str(program), str(c_object), "-o", str(exe), "-lm"],
                            capture_output=True, text=True)
    assert linked.returncode == 0, linked.stderr[:2000]
    assert subprocess.run([str(exe)]).returncode == 0  # OK from every call: the C filter ran, called from C++


@pytest.mark.skipif(not COMPILERS, reason="no C++ compiler (.ci/run installs g++ and clang++)")
def test_the_class_flies_the_check_scenario_to_the_bits_of_the_c(derived_builtin, tmp_path):
    """Backend.run of the C++ backend, through check_generated as Python and C: within the tolerance, and the C's numbers exactly."""
    from modelgen.jobs import check_scenario

    derived = derived_builtin("ins_gps15")
    folder = write_files(tmp_path / "gen", generate_code(derived).files)
    scenario = check_scenario(derived)
    results = {r.implementation: r for r in check_generated(folder, derived, scenario, tmp_path / "build")}
    assert set(results) == {"python", "c", "cpp"}
    assert results["cpp"].passed()
    cpp = backend("cpp").run(folder, derived, scenario, build_dir=tmp_path / "again")
    c = backend("c").run(folder, derived, scenario, build_dir=tmp_path / "c")
    for (xc, Pc), (xk, Pk) in zip(c, cpp):
        assert np.array_equal(xc, xk) and np.array_equal(Pc, Pk)
