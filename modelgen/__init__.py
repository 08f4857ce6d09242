"""modelgen: inertial-navigation error models to verified Kalman-filter code.

Data flows one way through layers (README "Architecture"; enforced by
tests/test_architecture.py): ``fileio`` and ``errors`` at the bottom, then
``model`` (what a model is), ``derive`` (its matrices), then ``codegen``,
``checks``, ``analysis``, ``simulation`` and ``navigator``, composed by
``jobs`` and called from ``cli``.
"""

from modelgen.errors import ModelError

__all__ = ["ModelError"]
__version__ = "0.1.0"
