"""cppcheck finds nothing in the generated C (and does find a planted bug, in every configuration it checks)."""

import pytest

from embedded_support import require_tools
from modelgen.codegen import toolchain
from modelgen.codegen.generate import generate_code, write_atomically
from modelgen.codegen.options import CodegenOptions
from modelgen.errors import ModelError
from tests.parallel_support import cores_per_worker

pytestmark = [require_tools(toolchain.CPPCHECK), pytest.mark.embedded, pytest.mark.compile]

#: Every template branch: full/packed, vector/sequential, Joseph/standard, UD; double and float.
VARIANTS = (
    CodegenOptions(),
    CodegenOptions(scalar="float", storage="packed", update="sequential", covariance_update="standard"),
    CodegenOptions(storage="packed", covariance_update="standard"),
    CodegenOptions(scalar="float", update="sequential"),
    CodegenOptions(form="ud"),
)


@pytest.mark.parametrize("options", VARIANTS, ids=lambda o: o.slug())
def test_generated_c_passes_cppcheck(paper_derived, tmp_path, options):
    """One variant a test, so that the suite's workers share them (conftest.SPREAD_MODULES)."""
    folder = write_atomically(tmp_path / options.slug(), generate_code(paper_derived, options).files)
    toolchain.run_cppcheck([folder / "ned_doppler18.c", folder / "ned_doppler18.h"], folder, workers=cores_per_worker())


def test_cppcheck_configuration_reports_an_out_of_bounds_write(tmp_path):
    bad = tmp_path / "bad.c"
    bad.write_text("void f(void);\nvoid f(void)\n{\n    int a[4];\n    a[4] = 1;\n    (void)a;\n}\n")
    with pytest.raises(ModelError, match="arrayIndexOutOfBounds|out of bounds"):
        toolchain.run_cppcheck([bad], tmp_path)


PLANTED_HEADER = """\
#ifndef PLANTED_H
#define PLANTED_H
#if !PLANTED_FLOAT && defined(PLANTED_WIDE) \\
    && defined(PLANTED_SSE)
static void planted_wide(void) { int w[2]; w[2] = 1; (void)w; }
#endif
#endif
"""

PLANTED_SOURCE = """\
#define PLANTED_FLOAT 0
#include "planted.h"
/* a comment line that looks like a directive:
#if defined(NOT_A_CONFIGURATION)
*/
void f(void);
void f(void)
{
#if defined(PLANTED_GNU)
    int a[4];
    a[4] = 1;
    (void)a;
#endif
#ifdef PLANTED_UNUSED
#endif
}
"""


def test_every_configuration_cppcheck_lists_is_checked_and_identical_texts_once(tmp_path):
    """A bug that only one configuration compiles is found, in the file or in a header of the include folder."""
    include = tmp_path / "include"
    include.mkdir()
    header = include / "planted.h"
    header.write_text(PLANTED_HEADER.replace("w[2] = 1;", "w[1] = 1;"))
    source = tmp_path / "src" / "planted.c"
    source.parent.mkdir()
    source.write_text(PLANTED_SOURCE)
    configurations = toolchain.cppcheck_configurations(source, include)
    assert configurations[0] == "" and {"PLANTED_GNU", "PLANTED_UNUSED"} <= set(configurations), configurations
    assert any("PLANTED_WIDE" in c for c in configurations), configurations
    # the directive in the comment is no configuration
    assert not any("NOT_A_CONFIGURATION" in c for c in configurations), configurations
    with pytest.raises(ModelError, match=r"(?s)PLANTED_GNU.*a\[4\]"):
        toolchain.run_cppcheck([source], include)
    source.write_text(PLANTED_SOURCE.replace("a[4] = 1;", "a[3] = 1;"))
    checks = toolchain.run_cppcheck([source], include)
    # "" and PLANTED_UNUSED preprocess to one text: it is checked once
    texts = {toolchain.cppcheck_preprocessed(source, include, c) for c in configurations}
    assert len(checks) == len(texts) == len(configurations) - 1
    header.write_text(PLANTED_HEADER)
    with pytest.raises(ModelError, match=r"(?s)PLANTED_WIDE.*w\[2\]"):
        toolchain.run_cppcheck([source], include)
