"""The generated filter builds for a Cortex-M4F with no heap, and its size and stack are known."""

import pytest

from embedded_support import in_parallel, require_tools
from modelgen.codegen import toolchain
from modelgen.checks.embedded_check import EMBEDDED_OPTIONS, firmware, report_markdown

pytestmark = [require_tools(toolchain.ARM_EMBEDDED_CC, toolchain.ARM_EMBEDDED_SIZE), pytest.mark.embedded, pytest.mark.compile]

#: Stack the filter may use on the target: a 2 KiB main stack is a common small-MCU budget.
STACK_BUDGET = 2048


@pytest.fixture(scope="module")
def builds(paper_derived, tmp_path_factory):
    root = tmp_path_factory.mktemp("m4")
    return dict(zip((o.slug() for o in EMBEDDED_OPTIONS), in_parallel(lambda o: firmware(paper_derived, o, root), EMBEDDED_OPTIONS)))


def test_image_links_without_heap_or_stdio(builds):
    for slug, build in builds.items():
        linked = build.map_file.read_text().split("Linker script and memory map", 1)[1]
        assert "ned_doppler18_predict" in linked and "ned_doppler18_update" in linked, slug
        assert build.forbidden_symbols == [], f"{slug}: {build.forbidden_symbols}"


def test_heap_check_sees_an_allocator_when_one_is_linked(tmp_path):
    source = tmp_path / "leak.c"
    source.write_text(
        "#include <stdlib.h>\nchar *volatile kept;\n"
        "void Reset_Handler(void) { kept = malloc(8); free(kept); for (;;) {} }\n"
    )
    elf, map_file = tmp_path / "leak.elf", tmp_path / "leak.map"
    toolchain.run(
        [toolchain.ARM_EMBEDDED_CC, *toolchain.CORTEX_M4F_FLAGS, "-O2", "-nostartfiles", "--specs=nosys.specs", "-Wl,-e,Reset_Handler", f"-Wl,-Map={map_file}", "-o", str(elf), str(source)],
        "leak build",
    )
    found = toolchain.forbidden_symbols_in_map(map_file)
    assert "malloc" in found and "free" in found


def test_sections_and_worst_case_stack_are_measured_and_within_budget(builds):
    for slug, build in builds.items():
        assert build.filter_object.text > 1000 and build.filter_object.data == 0 and build.filter_object.bss == 0, slug
        assert build.image.bss > 0  # the caller's static structs
        assert build.unbounded == [], f"{slug}: dynamic stack frames in {build.unbounded}"
        for fn in ("predict", "update", "discretize", "set_covariance"):
            stack = build.worst_case_stack[f"ned_doppler18_{fn}"]
            assert 0 < stack <= STACK_BUDGET, f"{slug} {fn}: {stack} bytes"
        assert build.worst_case_stack["main"] <= STACK_BUDGET + 64


def test_report_lists_sizes_and_stack_per_function(builds):
    text = report_markdown("ned_doppler18", builds, [])
    for slug, build in builds.items():
        assert f"| {slug} | {build.filter_object.text} |" in text
        assert str(build.worst_case_stack["ned_doppler18_predict"]) in text
    assert "heap/stdio symbols" in text
