"""The C99 backend: header, source, CMakeLists.txt, Makefile and README of a drop-in filter.

``printer`` prints sympy expressions and the language-neutral kernels as C,
``literals`` knows the scalar type's spellings (``1.0F``, ``sqrtf``,
``FLT_EPSILON``), ``context`` builds the templates' variables, ``templates/``
holds the product templates and ``harness/`` the test driver, the firmware
main of the embedded tests and the navigator's driver.
"""

from __future__ import annotations

from pathlib import Path

from modelgen.codegen.backends import Backend
from modelgen.codegen.backends.c.context import c_context

HERE = Path(__file__).resolve().parent

BACKEND = Backend(
    name="c",
    context=c_context,
    templates=HERE / "templates",
    harness=HERE / "harness",
    files=(
        ("{p}.h", "c_header.h.j2"),
        ("{p}.c", "c_source.c.j2"),
        ("CMakeLists.txt", "c_cmakelists.txt.j2"),
        ("Makefile", "c_makefile.j2"),
        ("README.md", "c_readme.md.j2"),
    ),
)
