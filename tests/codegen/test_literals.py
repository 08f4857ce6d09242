"""Number literals of the generated C compile strictly: an underflowing constant prints as 0, one beyond the type's range is refused.

The literal 1e-999 in a model made the generated C fail its own strict
compile ("floating constant truncated to zero", -Werror): the printer now
rounds every constant to the scalar type first (issue 28).
"""

from __future__ import annotations

import shutil
import subprocess

import pytest
import sympy as sp

from modelgen.codegen.backends.c.literals import c_number
from modelgen.codegen.backends.c.printer import CPrinter
from modelgen.codegen.backends.printing import scalar_value
from modelgen.codegen.build import compiler
from modelgen.errors import ModelError

X = sp.Symbol("x")

#: (constant, scalar type, its value in the type: 0 where it underflows)
CASES = (
    (sp.Float("1e-999"), "double", 0.0),
    (sp.Float("-1e-330"), "double", 0.0),
    (sp.Float("1e-320"), "double", 1e-320),  # subnormal: kept
    (sp.Float("1e-50"), "float", 0.0),
    (sp.Float("1e-40"), "float", 9.99994610111476e-41),  # a float subnormal: kept
    (sp.Float("2.5"), "float", 2.5),
)


@pytest.mark.parametrize("number, scalar, value", CASES, ids=lambda c: str(c))
def test_a_constant_is_rounded_to_the_scalar_type(number, scalar, value):
    assert scalar_value(number, scalar) == value


@pytest.mark.parametrize("number, scalar", [(sp.Float("1e50"), "float"), (sp.Float("-1e39"), "float"), (sp.Float("1e400"), "double")])
def test_a_constant_beyond_the_types_range_is_refused_with_a_message(number, scalar):
    with pytest.raises(ModelError, match=f"outside the range of the C {scalar} type"):
        CPrinter(scalar).doprint(number * X)
    with pytest.raises(ModelError, match=f"outside the range of the C {scalar} type"):
        c_number(float(number), scalar)


@pytest.mark.compile
@pytest.mark.parametrize("cc", ["gcc", "clang"])
def test_every_printed_constant_compiles_strictly(cc, tmp_path):
    """The printed expressions and parameter defaults pass -std=c99 -Wall -Wextra -Werror -pedantic (gcc refused 1e-999)."""
    if shutil.which(cc) is None:
        pytest.skip(f"{cc} is not installed (.ci/run installs it)")
    lines = []
    for k, (number, scalar, value) in enumerate(CASES):
        printed = CPrinter(scalar).doprint(number * X + 1)
        assert ("0.0" in printed) == (value == 0.0), printed
        lines += [f"{scalar} f{k}({scalar} x);", f"{scalar} f{k}({scalar} x) {{ return {printed}; }}",
                  f"{scalar} g{k}(void);", f"{scalar} g{k}(void) {{ return {c_number(float(number), scalar)}; }}"]
    source = tmp_path / "literals.c"
    source.write_text("\n".join(lines) + "\n")
    result = subprocess.run([cc if cc != "gcc" else compiler(), "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-c",
                             str(source), "-o", str(tmp_path / "literals.o")], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
