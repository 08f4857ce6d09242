"""The language-neutral description of one generated filter, shared by every backend.

Everything a backend needs that does not depend on the output language is
decided here once: the structure (``structure``), the common-subexpression
block of the model matrices (``expressions``), the kernels (``kernels``), the
sizes and index tables of the sparse matrices (``layout``), the operation
counts and the parameters.  A backend (``backends/<lang>/``) only prints it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import sympy as sp

from modelgen.version import __version__
from modelgen.codegen.contract import contract_markdown, contract_text
from modelgen.codegen.expressions import Block, Pole, eliminate_common_subexpressions, poles
from modelgen.codegen.kernels import (
    CommitRow,
    OperationCount,
    compact_covariance_cost,
    compact_kernels,
    covariance_commit,
    covariance_predict,
    kept_pairs,
    kept_pairs_to_check,
    predict_commit,
    discretize_cost,
    doubling_cost,
    state_predict,
    ud_weights,
    ud_weights_cost,
    update_cost,
)
from modelgen.codegen.compact_discretize import CompactDiscretizeCost, CompactDiscretizeTables, compact_discretize_cost
from modelgen.codegen.discretize_kernels import (
    DiscretizeBlock,
    DiscretizePlan,
    doubling_block,
    noise_blocks,
    series_blocks,
    transition_check_block,
    unrolled_discretize_cost,
)
from modelgen.codegen.layout import ModelSizes
from modelgen.codegen.van_loan import van_loan_costs
from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.structure import FilterStructure, filter_structure
from modelgen.derivation.discretization import nominal_scaling
from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError

#: Name of the model-matrix evaluation in the operation counts (the C function's name).
EVALUATE = "matrices_evaluate"


def text_shaping_versions() -> str:
    """The releases of the packages that shape generated text, as generated files record them.

    sympy prints every expression and jinja2 lays out every file, so a generated file
    says which of their releases made it (the freshness test compares only under the
    releases pinned in constraints.txt).
    """
    import jinja2
    import sympy

    return f"sympy {sympy.__version__}, jinja2 {jinja2.__version__}"


@dataclass(frozen=True)
class MatrixTarget:
    """Where one evaluated entry goes: the k-th structural nonzero of ``matrix`` (F, G, H, q, r)."""

    matrix: str
    k: int


#: A backend's own operation counts of a description (``Backend.costs``): name -> count.
CostCounter = Callable[["FilterDescription"], dict[str, OperationCount]]


@dataclass(frozen=True)
class FilterDescription:
    """One model and one choice of options, with everything derived from them that backends share.

    ``backend_costs`` are the backends' own counters (``Backend.costs``, in
    the order of their names), whose lines every file header lists beside
    the language-neutral ones; ``codegen.generate.describe`` passes every
    registered backend's (this module sits below the backends).
    """

    derived: DerivedModel
    options: CodegenOptions
    structure: FilterStructure
    backend_costs: tuple[CostCounter, ...] = ()

    @property
    def model(self):
        return self.derived.model

    @cached_property
    def sizes(self) -> ModelSizes:
        return ModelSizes.of(self.derived)

    @cached_property
    def evaluation(self) -> tuple[list[MatrixTarget], list[sp.Expr], Block]:
        """Targets, expressions and CSE block of every nonzero model-matrix entry (F, G, H, diag Q, diag R)."""
        derived, structure = self.derived, self.structure
        targets: list[MatrixTarget] = []
        exprs: list[sp.Expr] = []
        for name, matrix in (("F", derived.F), ("G", derived.G), ("H", derived.H)):
            for k, (i, j) in enumerate(structure.entries(name)):
                targets.append(MatrixTarget(name, k))
                exprs.append(matrix[i, j])
        for name, matrix in (("q", derived.Q), ("r", derived.R)):
            for k in range(matrix.shape[0]):
                targets.append(MatrixTarget(name, k))
                exprs.append(matrix[k, k])
        return targets, exprs, eliminate_common_subexpressions(exprs)

    @cached_property
    def poles(self) -> list[Pole]:
        """Denominators of the evaluated expressions that vanish at some operating points."""
        return poles(self.evaluation[1])

    @property
    def packed(self) -> bool:
        """Whether P, Q_d and the workspace copies are packed (the UD form packs U, not P)."""
        return self.options.packed and not self.options.ud

    @cached_property
    def compact(self) -> bool:
        """Whether the C predicts by loops over Phi's pattern instead of unrolled code (large models)."""
        return compact_kernels(self.structure)

    @cached_property
    def predict_blocks(self):
        """The unrolled covariance (or UD weight) prediction, row by row, and its cost (no blocks when compact)."""
        if self.compact:
            return [], ud_weights_cost(self.structure) if self.options.ud else compact_covariance_cost(self.structure)
        if self.options.ud:
            return ud_weights(self.structure)
        return covariance_predict(self.structure, self.packed)

    @cached_property
    def discretize_unrolled(self) -> bool:
        """Whether the C discretizes by straight-line code over the structure (below the compact threshold)."""
        return not self.compact

    @cached_property
    def discretize_plan(self) -> DiscretizePlan:
        """The compressed patterns of the unrolled discretize (modelgen.codegen.discretize_kernels)."""
        return DiscretizePlan(self.structure, self.options.taylor_order)

    @cached_property
    def discretize_blocks(self) -> list[DiscretizeBlock]:
        """The unrolled discretize's functions: one per order with a nonzero power of F, doubling, check, and the noise (also for F = 0)."""
        plan = self.discretize_plan
        blocks = []
        if plan.active:  # F has a nonzero entry (otherwise Phi = I and S = I: no series)
            blocks += [b for b in series_blocks(plan) if b.block.statements]
            blocks += [doubling_block(plan), transition_check_block(plan)]
        if plan.gamma_entries and (self.options.ud or plan.qd_pairs):
            blocks += noise_blocks(plan, True, self.options.ud)  # the transition's Q_d is always packed (layout)
        return blocks

    @cached_property
    def covariance_commit(self) -> list[CommitRow]:
        """The unrolled commit of P from the packed Pn by predict and the updates (full storage, below the compact threshold)."""
        if self.options.ud or self.packed or self.compact:
            return []
        return covariance_commit(self.structure.n_states)

    @cached_property
    def kept_pairs(self) -> list[tuple[int, int]]:
        """The pairs the unrolled covariance prediction leaves in P as they are (``kernels.kept_pairs``)."""
        if self.options.ud or self.packed or self.compact:
            return []
        return kept_pairs(self.structure, self.packed)

    @cached_property
    def kept_pairs_to_check(self) -> list[tuple[int, int]]:
        """The :attr:`kept_pairs` that predict checks finite itself (``kernels.kept_pairs_to_check``)."""
        return kept_pairs_to_check(self.structure, self.kept_pairs)

    @cached_property
    def predict_commit(self) -> list[CommitRow]:
        """The prediction's commit in full storage: :attr:`covariance_commit` without the :attr:`kept_pairs`."""
        if not self.covariance_commit:
            return []
        return predict_commit(self.structure.n_states, self.kept_pairs)

    @cached_property
    def state_predict(self):
        """The unrolled x_n = Phi x: (assignments, commits, cost)."""
        return state_predict(self.structure)

    @cached_property
    def costs(self) -> dict[str, OperationCount]:
        """Operation counts per call of each generated function (written into the file headers).

        The language-neutral counts (evaluation, discretize, the dense
        prediction, update) and, between them, each backend's own.
        """
        structure, options = self.structure, self.options
        n = structure.n_states
        costs = {
            EVALUATE: OperationCount(self.evaluation[2].operation_count, 0),
            "discretize": discretize_cost(structure, options.taylor_order),
            "discretize, each doubling (long steps)": doubling_cost(structure),
            **self.unrolled_discretize_costs,
            **self.compact_discretize_costs,
            **self.van_loan_costs,
        }
        for counter in self.backend_costs:
            costs.update(counter(self))
        costs["predict (dense, for comparison)"] = OperationCount(2 * n**3 + n, 2 * n * n * (n - 1) + n * n)
        if self.derived.n_measurements:
            costs["update"] = update_cost(structure, options)
        return costs

    @cached_property
    def unrolled_discretize_costs(self) -> dict[str, OperationCount]:
        """The unrolled discretize's counts, replacing the loop version's (empty when it is not unrolled)."""
        if not self.discretize_unrolled or not self.discretize_plan.active:
            return {}
        first, doubling, _ = unrolled_discretize_cost(self.discretize_plan, self.options.ud, nominal_scaling(self.derived) is not None)
        return {
            "discretize": first,
            "discretize, each doubling (long steps)": doubling,
        }

    @cached_property
    def compact_discretize_cost(self) -> CompactDiscretizeCost | None:
        """The compact discretize's flops, counted from the tables its loops run over (None when unrolled or Van Loan's)."""
        if self.discretize_unrolled or self.options.van_loan:
            return None
        fixed = nominal_scaling(self.derived) is not None
        return compact_discretize_cost(CompactDiscretizeTables(self.structure), self.options.taylor_order, self.options.ud, fixed)

    @cached_property
    def compact_discretize_costs(self) -> dict[str, OperationCount]:
        """The compact discretize's counts, replacing the loop formula's (empty when it is unrolled)."""
        cost = self.compact_discretize_cost
        if cost is None:
            return {}
        return {
            "discretize": cost.first(self.options.taylor_order),
            "discretize, each doubling (long steps)": cost.doubling,
        }

    @cached_property
    def van_loan_costs(self) -> dict[str, OperationCount]:
        """Van Loan's discretize's counts (modelgen.codegen.van_loan), replacing the Taylor ones (empty without the option)."""
        if not self.options.van_loan:
            return {}
        series, doubling = van_loan_costs(self.structure, self.options.taylor_order)
        return {"discretize": series, "discretize, each doubling (long steps)": doubling}

    def cost_lines(self) -> list[str]:
        """The operation counts as the lines of a file header."""
        return [
            f"{name}: {cost}" if name != EVALUATE else f"{name}: {cost.multiplications} operations after CSE"
            for name, cost in self.costs.items()
        ]

    def shared_context(self) -> dict[str, object]:
        """Template variables every backend uses alike (computed once per description: the model hash prints every expression)."""
        return dict(self._shared_context)

    @cached_property
    def _shared_context(self) -> dict[str, object]:
        model, derived = self.model, self.derived
        return {
            "model": model,
            "version": __version__,
            "text_versions": text_shaping_versions(),
            "n_states": derived.n_states,
            "n_noises": derived.n_noises,
            "n_measurements": derived.n_measurements,
            "taylor_order": self.options.taylor_order,
            "state_names": model.state_names,
            "cost_lines": self.cost_lines(),
            "description": self.options.describe(),
            "contract_text": contract_text("  "),
            "contract_markdown": contract_markdown(),
            "model_hash": model_hash(model),
            "indices": index_names(model),
        }


def describe_filter(derived: DerivedModel, options: CodegenOptions, backend_costs: tuple[CostCounter, ...] = ()) -> FilterDescription:
    """The description of ``derived``'s filter under ``options`` (``backend_costs``: the backends' counters); refuses a model that is not linear."""
    if derived.nonlinear:
        raise ModelError(
            f"model {derived.model.name!r}: equations of {', '.join(derived.nonlinear)} are not linear in the "
            "error states and noises; a linear Kalman filter cannot be generated"
        )
    structure = filter_structure(
        derived.structure("F"), derived.structure("G"), derived.structure("H"), options.taylor_order
    )
    return FilterDescription(derived, options, structure, tuple(backend_costs))


def model_hash(model) -> str:
    """First 16 hex digits of the sha256 of the canonical model declaration (sorted JSON of every field).

    Written into the generated code so that a program can tell which model its
    filter was generated from; any change to the declaration changes it.
    """
    # the navigation problem (the equations the model was derived from, carried on it) is no part of the declaration
    declaration = dataclasses.asdict(dataclasses.replace(model, navigation=None) if getattr(model, "navigation", None) else model)
    declaration.pop("navigation", None)
    declaration.pop("neglected", None)  # what the derivation dropped, carried on the model: not part of the declaration
    declaration.pop("attitude_reset", None)  # derived from the declaration's error definition, like the neglected terms
    for kind in ("states", "noises", "parameters", "measurements"):
        for item in declaration.get(kind) or ():
            item.pop("places", None)  # where the file declared it: not the declaration
    if isinstance(declaration.get("check"), dict):
        declaration["check"].pop("where", None)  # where the file that declared it lies: not the declaration
    canonical = json.dumps(declaration, sort_keys=True, default=repr, ensure_ascii=True)
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()[:16]


def index_names(model) -> dict[str, list[dict[str, str]]]:
    """State, noise and measurement index names (upper case), with unit and description, by kind.

    Refuses (ModelError) two names of one kind that differ only in case: their
    index macros would be the same.
    """
    out = {}
    for kind, items in (("state", model.states), ("noise", model.noises), ("measurement", model.measurements)):
        upper = [q.name.upper() for q in items]
        if len(set(upper)) != len(upper):
            clash = sorted({u for u in upper if upper.count(u) > 1})
            second = next(q for j, q in enumerate(items) if upper[j] in upper[:j])  # the entry that repeats one before it
            at = f"{second.place()}: " if second.place() else ""
            raise ModelError(f"{at}model {model.name!r}: {kind} names differ only in case ({', '.join(clash)}); index names would clash")
        out[kind] = [{"name": q.name, "index": u, "unit": q.unit, "description": q.description} for q, u in zip(items, upper)]
    return out


def named(expr: sp.Expr, model) -> str:
    """``expr`` as text with parameters by name (``cos(latitude)``, not ``cos(phi)``), for messages."""
    return str(expr.subs({p.sym: sp.Symbol(p.name) for p in model.parameters}, simultaneous=True))
