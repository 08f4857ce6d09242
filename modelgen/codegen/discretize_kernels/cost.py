"""Operation counts of the unrolled discretize, from the emitted statements, and the structural floor they approach."""

from __future__ import annotations

import numpy as np

from modelgen.codegen.discretize_kernels.doubling import doubling_block
from modelgen.codegen.discretize_kernels.noise import noise_blocks
from modelgen.codegen.discretize_kernels.plan import DiscretizeBlock, DiscretizePlan, scalar_statements
from modelgen.codegen.discretize_kernels.series import HORNER_UNIT_COLUMNS, f_row_entries, horner_schedule, series_blocks
from modelgen.codegen.kernels import OperationCount

def block_cost(blocks: list[DiscretizeBlock]) -> OperationCount:
    """Multiplications and additions of the emitted statements, segments entry by entry (a zero fill costs nothing)."""
    mul = add = 0
    for b in blocks:
        for s in scalar_statements(b.block.statements):
            mul += sum(len(t) - 1 for t in s.terms)
            add += max(len(s.terms) - 1, 0)
    return OperationCount(mul, add)


def series_block_costs(plan: DiscretizePlan) -> dict[str, OperationCount]:
    """Flops of each function of the Horner chain, by name (built once, then summed per order)."""
    return {b.block.name: block_cost([b]) for b in series_blocks(plan)}


def series_cost(plan: DiscretizePlan, order: int, costs: dict[str, OperationCount] | None = None, doubling: bool = False) -> OperationCount:
    """Flops of Phi and S by the Horner chain of ``order`` (A = F h, the levels it calls, Phi = I + A S).

    ``costs``: :func:`series_block_costs` of ``plan``, when the caller counts several orders;
    ``doubling``: the levels of a step that is then doubled (:func:`horner_schedule`).
    """
    costs = series_block_costs(plan) if costs is None else costs
    called = [costs[name] for name in ("horner_input", *horner_schedule(plan, order, doubling), "horner_transition")]
    return OperationCount(sum(c.multiplications for c in called), sum(c.additions for c in called))


def unrolled_discretize_cost(plan: DiscretizePlan, ud: bool, fixed_scaling: bool = False) -> tuple[OperationCount, OperationCount, list[int]]:
    """(flops at the highest order without doubling, flops of one doubling, flops of the series at each order 1..N).

    Counted from the emitted statements, so that the header states what the
    code does (the norm and the plan's bound are included in the first count:
    with D fixed at generation time, ``fixed_scaling``, one product and sum
    per nonzero of F; otherwise also the balancing's sweeps, at most 8 over
    the off-diagonal entries of F).
    """
    costs = series_block_costs(plan)
    per_order = [series_cost(plan, m, costs).total for m in range(1, plan.order + 1)]
    series = series_cost(plan, plan.order, costs)
    noise = block_cost(noise_blocks(plan, packed=False, ud=ud))
    structure = plan.structure
    nnz_f = int(structure.F.sum())
    off = nnz_f - int(np.trace(structure.F.astype(int)))
    sweeps = 0 if fixed_scaling else 8 * 2 * off
    balancing = OperationCount(sweeps + nnz_f, sweeps + nnz_f) if nnz_f else OperationCount(0, 0)
    bound = OperationCount(3 * plan.order + 6, plan.order + 2)
    parts = (series, noise, balancing, bound)
    first = OperationCount(sum(c.multiplications for c in parts), sum(c.additions for c in parts))
    doubling = block_cost([doubling_block(plan)])
    if plan.unit_columns_deferred:  # a halved step also sums S's unit columns (once): counted in each doubling, a bound
        extra = series_cost(plan, plan.order, costs, doubling=True)
        extra = OperationCount(extra.multiplications - series.multiplications + costs[HORNER_UNIT_COLUMNS].multiplications,
                               extra.additions - series.additions + costs[HORNER_UNIT_COLUMNS].additions)
        doubling = OperationCount(doubling.multiplications + extra.multiplications, doubling.additions + extra.additions)
    return first, doubling, per_order


def structural_series_cost(plan: DiscretizePlan, order: int) -> OperationCount:
    """Flops of Phi and S by Horner's rule of ``order`` over the structural nonzeros of each level alone.

    The floor the dense segments approach (the benchmark's flop floor): R_k
    over the pattern of I + F + ... + F^(m-k) (the closure once it stops
    growing), each entry a product only where F(i, c) and R_(k+1)(c, j) can
    both be nonzero, plus A = F h and E = A S over the active entries.  A
    unit column j (a row of random constants) is summed where it is needed
    only, as the emitted chain does: E(:, j) = S A(:, j), and S(:, j) = R_1
    A(:, j) at k = 0 (below the top level) where S G reads it (a step that is
    not halved needs it nowhere else); a row that no row of F reads at k = 0
    only.
    """
    unit = set(plan.structure.unit_rows)
    f_rows = f_row_entries(plan)
    f_columns: dict[int, list[int]] = {}
    for c, j in plan.f_entries:
        f_columns.setdefault(j, []).append(c)
    patterns = plan.horner_patterns
    mul, add = len(plan.f_entries), 0

    def count(entries, inputs: set | None, constant: bool) -> None:
        """R_k (``constant``: plus c_out I) or E over ``entries``; ``inputs`` the pattern of R_(k+1) (None: R_m = c_in I)."""
        nonlocal mul, add
        for i, j in entries:
            terms = int(constant and i == j)
            for c, _ in f_rows.get(i, []):
                if c in unit or inputs is None:  # R_(k+1)(c, j) = c_in delta_cj (times c_in; E: S(c, c) = 1)
                    products = int(c == j)
                    mul += products if constant else 0
                else:
                    products = int((c, j) in inputs)
                    mul += products
                terms += products
            add += max(terms - 1, 0)

    def count_unit_columns(entries, left: set) -> None:
        """X(i, j) = sum_c left(i, c) A(c, j) over the entries in unit columns."""
        nonlocal mul, add
        for i, j in entries:
            products = sum(1 for c in f_columns.get(j, []) if (i, c) in left)
            mul += products
            add += max(products - 1, 0)

    leaves = set(plan.leaf_rows)
    first_needed = plan.needs_first_level and not plan.unit_columns_deferred  # R_1 of the leaf rows: S's unit columns read it
    for level in range(1, order + 1):
        inputs = None if level == 1 else set(patterns[min(level - 1, len(patterns)) - 1])
        entries = patterns[min(level, len(patterns)) - 1]
        if level < order and not (level == order - 1 and first_needed):  # a row no row reads: needed at k = 0 only
            entries = [(i, j) for i, j in entries if i not in leaves]
        if inputs is None:
            count(entries, inputs, True)
        else:
            count([(i, j) for i, j in entries if j not in unit], inputs, True)
            if level == order and not plan.unit_columns_deferred:  # k = 0: S(:, j) = R_1 A(:, j), where S G reads it
                count_unit_columns([(i, j) for i, j in entries if j in unit], inputs)
    active = set(plan.active)
    count([(i, j) for i, j in plan.active if j not in unit], active, False)
    count_unit_columns([(i, j) for i, j in plan.active if j in unit], active)
    return OperationCount(mul, add)
