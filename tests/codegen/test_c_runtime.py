"""The fixed C runtime (modelgen/codegen/backends/c/runtime) is code: compiled strictly, linted, tested, and copied verbatim.

Every runtime header compiles with gcc and clang at -std=c99 -Wall -Wextra
-Werror -pedantic in double and in float (and with the scalar lane pairs),
passes cppcheck, and its functions compute what they promise (a driver of
checks compiled through the compile cache and called with ctypes); every
generated folder carries the runtime files byte for byte and its C includes
them.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import pytest

from modelgen.codegen import toolchain
from modelgen.codegen.backends.c.context import RUNTIME, RUNTIME_FILES, RUNTIME_HEADERS
from modelgen.codegen.build import STRICT_FLAGS, compile_shared_library

pytestmark = pytest.mark.compile

GENERATED = Path(__file__).resolve().parents[2] / "generated"

#: The runtime's functions on inputs whose answers are known exactly; returns 0, else the number of the failed check.
CHECKS = r"""
#include "modelgen_factor.h"
#include "modelgen_ieee.h"
#include "modelgen_lane_pair.h"
#include "modelgen_taylor.h"

int modelgen_runtime_checks(void);

int modelgen_runtime_checks(void)
{
    typedef MODELGEN_SCALAR S;
    S L[4] = { 4, 0, 2, 3 }; /* S = [[4, 2], [2, 3]]: L = [[2, 0], [1, sqrt(2)]] */
    S not_positive[4] = { 1, 0, 2, 1 };
    const S P[9] = { 4, 2, 0, 2, 3, 1, 0, 1, 2 };
    const S indefinite[9] = { 1, 0.9, 0, 0.9, 1, 0.9, 0, 0.9, 1 };
    const S correlated_zero[4] = { 0, 0.5, 0.5, 1 };
    S u[3], d[3], rebuilt;
    signed char exponent = 0;
    lane_pair acc;
    const S a[4] = { 1, 2, 3, 4 };
    int i, j, k;
    if (modelgen_cholesky(2, 2, L) != 0 || L[0] != 2 || L[2] != 1 || L[3] != MODELGEN_SQRT((S)2)) {
        return 1;
    }
    if (modelgen_cholesky(2, 2, not_positive) != 2) {
        return 2;
    }
    if (modelgen_udu_factor(3, P, u, d) != 0) {
        return 3;
    }
    for (i = 0; i < 3; ++i) { /* P = U D U^T, U unit upper */
        for (j = i; j < 3; ++j) {
            rebuilt = d[j];
            if (i < j) {
                rebuilt *= u[MODELGEN_STRICT_UPPER(3, i, j)];
            }
            for (k = j + 1; k < 3; ++k) {
                rebuilt += u[MODELGEN_STRICT_UPPER(3, i, k)] * d[k] * u[MODELGEN_STRICT_UPPER(3, j, k)];
            }
            if (MODELGEN_FABS(rebuilt - P[i * 3 + j]) > 8 * MODELGEN_EPSILON * 4) {
                return 4;
            }
        }
    }
    if (modelgen_udu_factor(3, indefinite, u, d) != 2 || modelgen_udu_factor(2, correlated_zero, u, d) != 2) {
        return 5;
    }
    if (modelgen_power_of_two(-3) != (S)0.125 || modelgen_power_of_two(40) != (S)1099511627776.0
        || modelgen_binary_exponent(1) != 1 || modelgen_binary_exponent((S)0.75) != 0) {
        return 6;
    }
    if (!(modelgen_bits_of((S)-1) & MODELGEN_SIGN_BIT) || (modelgen_bits_of((S)2) & MODELGEN_SIGN_BIT)) {
        return 7;
    }
    if (modelgen_balance_step(64, 1, &exponent) != 1 || exponent != 3 || modelgen_balance_step(0, 0, &exponent) != 0) {
        return 8;
    }
    acc = lane_pair_product(lane_pair_load(&a[0]), lane_pair_of(5, 6));
    acc = lane_pair_add_product(acc, lane_pair_load(&a[2]), lane_pair_of(7, 8));
    if (lane_pair_sum(acc) != (1 * 5 + 3 * 7) + (2 * 6 + 4 * 8)) {
        return 9;
    }
    /* the bound of order 1, no halving, theta = 1: 2 e rho_0(1) = 2 e (1 * 2 / (2 - 1)) = 4 e */
    if (MODELGEN_FABS(modelgen_step_error_bound(MODELGEN_EXP((S)1), 1, 1, 0) - 4 * MODELGEN_EXP((S)1)) > 16 * MODELGEN_EPSILON
        || modelgen_step_error_bound(1, 5, 2, 0) != MODELGEN_HUGE) {
        return 10;
    }
    return 0;
}
"""

CONFIGURATIONS = {
    "double": "#define MODELGEN_SCALAR double\n#define MODELGEN_SCALAR_FLOAT 0\n",
    "double-scalar-lanes": "#define MODELGEN_SCALAR double\n#define MODELGEN_SCALAR_FLOAT 0\n#define MODELGEN_SCALAR_LANE_PAIRS\n",
    "float": "#define MODELGEN_SCALAR float\n#define MODELGEN_SCALAR_FLOAT 1\n",
}


def checks_source(folder: Path, configuration: str) -> Path:
    source = folder / f"runtime_checks_{configuration}.c"
    source.write_text(CONFIGURATIONS[configuration] + CHECKS)
    return source


def test_the_runtime_is_the_headers_the_generated_c_includes():
    assert [p.name for p in RUNTIME_FILES] == ["modelgen_factor.h", "modelgen_ieee.h", "modelgen_lane_pair.h", "modelgen_scalar.h",
                                               "modelgen_taylor.h"]
    for path in RUNTIME_FILES:
        assert max(len(line) for line in path.read_text().splitlines()) <= 100, path


@pytest.mark.parametrize("configuration", list(CONFIGURATIONS))
@pytest.mark.parametrize("cc", ["gcc", "clang"])
def test_the_runtime_compiles_strictly_and_computes_what_it_promises(cc, configuration, tmp_path):
    if shutil.which(cc) is None:
        pytest.skip(f"{cc} is not installed (.ci/run installs it)")
    source = checks_source(tmp_path, configuration)
    for optimization in ("-O0", "-O2"):
        result = subprocess.run([cc, *STRICT_FLAGS, optimization, f"-I{RUNTIME}", "-fsyntax-only", str(source)],
                                capture_output=True, text=True)
        assert result.returncode == 0, result.stderr[:3000]
    if cc == "gcc":
        library = compile_shared_library([source], tmp_path / f"libruntime_{configuration}.so", ("-O2", f"-I{RUNTIME}"), cache=True)
        assert ctypes.CDLL(str(library)).modelgen_runtime_checks() == 0


@pytest.mark.skipif(not shutil.which(toolchain.CPPCHECK), reason="cppcheck is not installed (.ci/run installs it)")
def test_the_runtime_passes_cppcheck(tmp_path):
    sources = [checks_source(tmp_path, configuration) for configuration in CONFIGURATIONS]
    toolchain.run_cppcheck(sources, RUNTIME)


def test_every_generated_folder_carries_the_runtime_byte_for_byte_and_includes_it():
    folders = [p.parent for p in GENERATED.glob("**/*.c")]
    assert len(folders) >= 20
    for folder in folders:
        source = next(folder.glob("*.c")).read_text()
        for path in RUNTIME_FILES:
            assert (folder / path.name).read_bytes() == path.read_bytes(), folder / path.name
        for path in RUNTIME_HEADERS:
            assert f'#include "{path.name}"' in source, (folder, path.name)
