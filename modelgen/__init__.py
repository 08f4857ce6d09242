"""modelgen: inertial-navigation error models to verified Kalman-filter code.

Data flows one way through layers (README "Architecture"; enforced by
tests/test_architecture.py): ``version``, ``errors`` and ``fileio`` at the
bottom, then ``model`` (what a model is), ``derive`` (its matrices), then
``codegen``, ``checks``, ``export``, ``analysis``, ``simulation`` and
``navigator``, composed by ``jobs``, called from ``cli`` and from the Python
API (``modelgen.api``), which this package offers at its top::

    import modelgen
    derived = modelgen.derive("enu_doppler18")
    result = modelgen.verify("enu_doppler18", table="my_table.yaml")

The API functions are imported on first use, so ``import modelgen`` stays
cheap (no sympy, numpy or CasADi).  ``modelgen.derive`` is both the derive
subpackage and the API function: calling it derives a model, its attributes
are the subpackage's modules (``modelgen.derive.symbolic``).
"""

from __future__ import annotations

import types
from typing import Any

import modelgen.derive as _derive_package
from modelgen.errors import ModelError
from modelgen.version import __version__

__all__ = [
    "ModelError",
    "__version__",
    "load_model",
    "derive",
    "verify",
    "generate",
    "check",
    "observability",
    "covariance_analysis",
    "simulate",
]
_API = frozenset(__all__) - {"ModelError", "__version__", "derive"}


class _CallableDerivePackage(types.ModuleType):
    """The ``modelgen.derive`` subpackage, callable as the API's :func:`modelgen.api.derive`.

    ``modelgen.derive`` is a subpackage, and Python sets a subpackage as an
    attribute of its parent whenever it is imported, so a plain function of
    that name would be replaced by the module.  Making the module callable
    keeps both meanings working.
    """

    def __call__(self, model: Any):
        from modelgen.api import derive

        return derive(model)


_derive_package.__class__ = _CallableDerivePackage
derive = _derive_package


def __getattr__(name: str) -> Any:
    """The API functions, imported from :mod:`modelgen.api` on first use (importing it loads sympy and numpy)."""
    if name in _API:
        from modelgen import api

        value = getattr(api, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'modelgen' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
