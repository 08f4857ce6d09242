"""cppcheck finds nothing in the generated C (and does find a planted bug)."""

import pytest

from embedded_support import in_parallel, require_tools
from modelgen.codegen import toolchain
from modelgen.codegen.generate import generate_code, write_atomically
from modelgen.codegen.options import CodegenOptions
from modelgen.errors import ModelError

pytestmark = [require_tools(toolchain.CPPCHECK), pytest.mark.embedded, pytest.mark.compile]

#: Every template branch: full/packed, vector/sequential, Joseph/standard, UD; double and float.
VARIANTS = (
    CodegenOptions(),
    CodegenOptions(scalar="float", storage="packed", update="sequential", covariance_update="standard"),
    CodegenOptions(storage="packed", covariance_update="standard"),
    CodegenOptions(scalar="float", update="sequential"),
    CodegenOptions(form="ud"),
)


@pytest.mark.parametrize("chunk", [VARIANTS[:3], VARIANTS[3:]], ids=["covariance", "sequential-ud"])
def test_generated_c_passes_cppcheck(paper_derived, tmp_path, chunk):
    def check(options):
        folder = write_atomically(tmp_path / options.slug(), generate_code(paper_derived, options).files)
        toolchain.run_cppcheck([folder / "ned_doppler18.c", folder / "ned_doppler18.h"], folder)
        return options.slug()

    assert in_parallel(check, chunk) == [o.slug() for o in chunk]


def test_cppcheck_configuration_reports_an_out_of_bounds_write(tmp_path):
    bad = tmp_path / "bad.c"
    bad.write_text("void f(void);\nvoid f(void)\n{\n    int a[4];\n    a[4] = 1;\n    (void)a;\n}\n")
    with pytest.raises(ModelError, match="arrayIndexOutOfBounds|out of bounds"):
        toolchain.run_cppcheck([bad], tmp_path)
