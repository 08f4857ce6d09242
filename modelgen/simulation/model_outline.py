"""What a flight with the compiled loop needs of a derived model, as plain data (no sympy).

A Monte Carlo worker that flies the generated C filter in the compiled loop
(:mod:`modelgen.simulation.native_loop`) reads only names and sizes of the
model: its name, navigation frame and the names of its states, noises,
parameters and measurements (the error layout, the navigator's measurement
rows, the C filter's parameter struct) and the structure of F, G and H (the
sizes of the C structs, :class:`modelgen.codegen.layout.ModelSizes`).  The
symbolic matrices themselves are the caller's business: the generated code
already holds them.  A :class:`ModelOutline` stands in for the
:class:`~modelgen.derivation.symbolic.DerivedModel` there (the same attributes
under the same names), so that such a worker never imports sympy (0.2 s of
its start) nor unpickles sympy expressions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from modelgen.errors import ModelError

#: the matrices whose structure (nonzero pattern) the outline keeps: what ModelSizes counts
STRUCTURES = ("F", "G", "H")


@dataclass(frozen=True)
class ModelNames:
    """The names of an :class:`~modelgen.model.declaration.ErrorModel`, under its attribute names."""

    name: str
    frame: str
    state_names: tuple[str, ...]
    noise_names: tuple[str, ...]
    parameter_names: tuple[str, ...]
    measurement_names: tuple[str, ...]

    @classmethod
    def of(cls, model: Any) -> "ModelNames":
        """The names of ``model`` (an ErrorModel)."""
        return cls(model.name, model.frame, tuple(model.state_names), tuple(model.noise_names),
                   tuple(model.parameter_names), tuple(model.measurement_names))


@dataclass(frozen=True)
class ModelOutline:
    """A derived model's names and matrix structure: ``model`` (:class:`ModelNames`), sizes, :meth:`structure`."""

    model: ModelNames
    structures: tuple[np.ndarray, ...]  # boolean nonzero masks of F, G, H (STRUCTURES order)

    @classmethod
    def of(cls, derived: Any) -> "ModelOutline":
        """The outline of ``derived`` (a DerivedModel: its model's names, its F, G and H structure)."""
        return cls(ModelNames.of(derived.model), tuple(np.array(derived.structure(m), dtype=bool) for m in STRUCTURES))

    @property
    def n_states(self) -> int:
        return self.structures[0].shape[0]

    @property
    def n_noises(self) -> int:
        return self.structures[1].shape[1]

    @property
    def n_measurements(self) -> int:
        return self.structures[2].shape[0]

    def structure(self, matrix: str) -> np.ndarray:
        """Boolean mask of the structurally nonzero entries of F, G or H (as DerivedModel.structure)."""
        if matrix not in STRUCTURES:
            raise ModelError(f"model outline of {self.model.name!r}: keeps the structure of "
                             f"{', '.join(STRUCTURES)} only, not {matrix!r}")
        return self.structures[STRUCTURES.index(matrix)].copy()
