"""The C99 backend: header, source, CMakeLists.txt, Makefile and README of a drop-in filter.

``printer`` prints sympy expressions and the language-neutral kernels as C,
``literals`` knows the scalar type's spellings (``1.0F``, ``sqrtf``,
``FLT_EPSILON``), ``context`` builds the templates' variables, ``templates/``
holds the product templates and ``harness/`` the test driver, the firmware
main of the embedded tests and the navigator's driver; ``runtime/`` is the
fixed C runtime (factorizations, IEEE bits, two-lane sums, the Taylor
bound): real C headers copied verbatim into every generated folder.
"""

from __future__ import annotations

from pathlib import Path

from modelgen.codegen.backends.base import Backend
from modelgen.codegen.backends.c.context import RUNTIME_FILES, c_context
from modelgen.codegen.backends.c.printer import wrap_c
from modelgen.codegen.backends.c.run import c_prepare, c_run
from modelgen.codegen.description import FilterDescription
from modelgen.codegen.kernels import OperationCount, thornton_cost

HERE = Path(__file__).resolve().parent


def finish(name: str, text: str) -> str:
    """C sources and headers wrapped to 100 columns; the build files and README as rendered."""
    return wrap_c(text) if name.endswith((".c", ".h")) else text


def c_costs(description: FilterDescription) -> dict[str, OperationCount]:
    """The C's prediction: x_n = Phi x, the unrolled (or compact) covariance or Phi U kernel, Thornton's sweep in the UD form."""
    state_cost = description.state_predict[2]
    kernel_cost = description.predict_blocks[1]
    extra = thornton_cost(description.structure) if description.options.ud else OperationCount(0, 0)
    return {"predict (C)": OperationCount(
        state_cost.multiplications + kernel_cost.multiplications + extra.multiplications,
        state_cost.additions + kernel_cost.additions + extra.additions,
    )}


BACKEND = Backend(
    name="c",
    context=c_context,
    templates=HERE / "templates",
    harness=HERE / "harness",
    finish=finish,
    verbatim=RUNTIME_FILES,
    runner=c_run,
    preparer=c_prepare,
    counter=c_costs,
    files=(
        ("{p}.h", "c_header.h.j2"),
        ("{p}.c", "c_source.c.j2"),
        ("CMakeLists.txt", "c_cmakelists.txt.j2"),
        ("Makefile", "c_makefile.j2"),
        ("README.md", "c_readme.md.j2"),
    ),
)
