"""The registered backends: every output language ``generate_code`` renders, in order."""

from __future__ import annotations

from modelgen.codegen.backends import c, cpp, python
from modelgen.codegen.backends.base import Backend


def backends() -> tuple[Backend, ...]:
    """The registered backends, in the order their files are rendered."""
    return (python.BACKEND, c.BACKEND, cpp.BACKEND)


def backend(name: str) -> Backend:
    """The backend called ``name`` (``python``, ``c``, ``cpp``)."""
    for b in backends():
        if b.name == name:
            return b
    raise KeyError(f"no backend {name!r}; there are {', '.join(b.name for b in backends())}")
