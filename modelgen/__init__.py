"""modelgen: inertial-navigation error models to verified Kalman-filter code.

Data flows one way through layers (README "Architecture"; enforced by
tests/test_architecture.py): ``version``, ``errors`` and ``fileio`` at the
bottom, then ``model`` (what a model is), ``derivation`` (its matrices), then
``codegen``, ``checks``, ``export``, ``analysis``, ``simulation`` and
``navigator``, composed by ``jobs``, called from ``cli`` and from the Python
API (``modelgen.api``), which this package offers at its top::

    import modelgen
    derived = modelgen.derive("enu_doppler18")
    result = modelgen.verify("enu_doppler18", table="my_table.yaml")

The API functions are imported on first use, so ``import modelgen`` stays
cheap (no sympy, numpy or CasADi).  ``modelgen.derive`` is the API function
(:func:`modelgen.api.derive`); the subpackage that derives the matrices is
``modelgen.derivation``.
"""

from __future__ import annotations

from typing import Any

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
_API = frozenset(__all__) - {"ModelError", "__version__"}


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
