"""The C++ template's context: names, sizes and storage of the C filter the class holds (no kernels: the class calls the C)."""

from __future__ import annotations

from modelgen.codegen.backends.c.context import BANNER
from modelgen.codegen.description import FilterDescription


def cpp_context(description: FilterDescription) -> dict[str, object]:
    """Everything the C++ templates read: the C's prefix and names, sizes, the options that shape the class."""
    model, options, sizes = description.model, description.options, description.sizes
    prefix = model.name.upper()
    return {
        **description.shared_context(),
        "banner_cpp": BANNER.replace("/*", "//").removesuffix(" */"),
        "p": model.name,
        "P": prefix,
        "guard": f"MODELGEN_{prefix}_HPP",
        "scalar": options.scalar,
        "parameters": [{"name": p.name, "unit": p.unit} for p in model.parameters],
        "ud": options.ud,
        "full_storage": not options.ud and not description.packed,  # P is an N x N row-major array: an Eigen::Map of it
        "dim_m": max(sizes.nm, 1),
    }
