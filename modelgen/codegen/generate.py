"""Code generation: derived model -> Python module and C99 header/source.

The pipeline is expression (``expressions``), structure and kernels
(``structure``, ``kernels``), memory layout (``layout``), all gathered in
the language-neutral ``description``, then one backend per output language
(``backends/c``, ``backends/python``: printer, literals, context, templates);
``options`` says which filter variant is wanted.  Besides the code, the C
folder gets a CMakeLists.txt, a Makefile and a README with a usage example,
so that it can be dropped into another build as it is.  The files are
written atomically (``modelgen.fileio.output.write_atomically``): the output folder
is built next to its destination and renamed into place, so a failure never
leaves a half-written ``generated/<model>/``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

from modelgen.codegen.backends.registry import backend, backends
from modelgen.codegen.description import FilterDescription, describe_filter
from modelgen.codegen.kernels import OperationCount, estimated_code_bytes
from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.structure import FilterStructure
from modelgen.derivation.symbolic import DerivedModel
from modelgen.fileio.output import write_atomically  # noqa: F401  (re-exported: the one atomic writer lives in modelgen.fileio.output)

__all__ = [
    "CodegenOptions", "GeneratedCode", "generate_code", "render_c_template", "write_atomically", "template_folder",
    "harness_folder",
]


@dataclass(frozen=True)
class GeneratedCode:
    """File name -> text, plus the operation counts written into the files."""

    model: str
    files: dict[str, str]
    costs: dict[str, OperationCount] = field(default_factory=dict)


def template_folder() -> Path:
    """The C backend's product templates (the filter's and the navigator's header and source)."""
    return backend("c").templates


def harness_folder() -> Path:
    """The C backend's harness templates (test driver, firmware main, navigator driver)."""
    return backend("c").harness


class GeneratedSizeWarning(UserWarning):
    """The model's generated code will be unusually large (see :data:`LARGE_CODE_BYTES`)."""


#: Above this estimated size of the generated files a model gets a warning: 2 MB is about
#: 13 times the paper's 18-state model (160 kB), or roughly 110,000 unrolled flops in
#: predict; straight-line C of that size takes gcc -O2 minutes and hundreds of MB, and its
#: object code no longer fits the flash of a typical Cortex-M4 (1 MB).
LARGE_CODE_BYTES = 2_000_000


def warn_if_large(name: str, structure: FilterStructure) -> None:
    """``warnings.warn`` a :class:`GeneratedSizeWarning` with the expected size when above the threshold."""
    expected = estimated_code_bytes(structure)
    if expected > LARGE_CODE_BYTES:
        warnings.warn(
            f"model {name!r} is large: its generated code will be about {expected / 1e6:.1f} MB "
            f"({structure.n_states} states, {int(structure.Phi.sum())} structural nonzeros in Phi), "
            f"above the {LARGE_CODE_BYTES / 1e6:.0f} MB at which compiling it gets slow and it outgrows "
            "a microcontroller's flash; a reduced model (keep_states, markov_to_white) is smaller",
            GeneratedSizeWarning,
            stacklevel=3,
        )


def describe(derived: DerivedModel, options: CodegenOptions | None = None) -> FilterDescription:
    """The language-neutral description of ``derived``'s filter, warning first when it will be large."""
    counters = tuple(b.costs for b in sorted(backends(), key=lambda b: b.name))  # their lines in the order of their names
    description = describe_filter(derived, options or CodegenOptions(), counters)
    warn_if_large(derived.model.name, description.structure)
    return description


def generate_code(derived: DerivedModel, options: CodegenOptions | None = None) -> GeneratedCode:
    """Render every backend's files (the Python module, the C header/source and build files) for ``derived``."""
    description = describe(derived, options)
    files: dict[str, str] = {}
    for b in backends():
        files.update(b.render(description))
    return GeneratedCode(model=derived.model.name, files=files, costs=description.costs)


def render_c_template(derived: DerivedModel, options: CodegenOptions, template: str, **extra: object) -> str:
    """Render another C template (test driver, firmware main) with the filter's context.

    Used for files that go with a generated filter but are not part of it,
    so that they always agree with its names, sizes and scalar type.
    """
    return backend("c").render_template(describe(derived, options), template, **extra)
