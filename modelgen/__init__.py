"""modelgen: inertial-navigation error models to verified Kalman-filter code.

Data flows one way: model -> derivation -> (verification, discretization,
code generation, analysis, simulation).
"""

from modelgen.errors import ModelError

__all__ = ["ModelError"]
__version__ = "0.1.0"
