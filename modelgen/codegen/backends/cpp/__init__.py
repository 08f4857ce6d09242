"""The C++17 backend: a header-only class per model over the generated C (the proof of the backend seam).

``templates/cpp_class.hpp.j2`` renders ``<model>.hpp``: namespace
``modelgen::<model>``, the C's index constants and status codes as C++
names, and ``Filter``, which owns the C's structs (no heap) and calls the C
functions through the C header (includable from C++: ``extern "C"``, no
``restrict`` in C++), with ``Eigen::Map`` views of x and P where Eigen is
present and plain arrays otherwise.  Its arithmetic is the C's, bit for bit;
``run`` flies a check scenario through the class (``harness/``: a driver
compiled with the strict C++17 flags and loaded beside the C library).
"""

from __future__ import annotations

from pathlib import Path

from modelgen.codegen.backends.base import Backend
from modelgen.codegen.backends.cpp.context import cpp_context
from modelgen.codegen.backends.cpp.run import cpp_run

HERE = Path(__file__).resolve().parent

BACKEND = Backend(
    name="cpp",
    context=cpp_context,
    templates=HERE / "templates",
    harness=HERE / "harness",
    runner=cpp_run,
    files=(("{p}.hpp", "cpp_class.hpp.j2"),),
)
