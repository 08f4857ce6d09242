"""The unrolled discretize follows the structure: products only where they can be nonzero, compressed scratch.

modelgen.codegen.discretize_kernels sums the series by Horner's rule over the
structural nonzeros of each level; these tests read its statements (no
compiler), run them in Python against the reference, and check what the issue
asks of them: no product with a structural zero, no work on rows of random
constants, fewer products than a dense-row loop, and a scratch of at most two
N x N arrays.
"""

import math

import numpy as np
import pytest

from modelgen.codegen.kernels import Ref

from modelgen.codegen.discretize_kernels import (
    HORNER_FIRST,
    HORNER_UNIT_COLUMNS,
    HORNER_LAST,
    DiscretizePlan,
    SegmentAssign,
    doubling_block,
    horner_schedule,
    noise_blocks,
    scalar_statements,
    series_blocks,
    series_cost,
    structural_series_cost,
    transition_check_block,
)
from modelgen.derivation.discretization import _taylor_terms
from modelgen.codegen.structure import filter_structure
from modelgen.derivation.symbolic import derive
from modelgen.model.loading import load_model

MODELS = ["ned_doppler18", "ned_inertial16", "enu_doppler18", "ins_gps15", "gps_pseudorange11", "ned_doppler32_augmented"]


def plan_of(name: str, order: int = 9) -> DiscretizePlan:
    derived = derive(load_model(name))
    structure = filter_structure(derived.structure("F"), derived.structure("G"), derived.structure("H"), order)
    return DiscretizePlan(structure, order)


@pytest.fixture(scope="module", params=MODELS)
def plan(request):
    return plan_of(request.param)


def power_pattern(F: np.ndarray, k: int) -> np.ndarray:
    step = F.astype(np.int64)
    power = np.eye(F.shape[0], dtype=np.int64)
    for _ in range(k):
        power = ((power @ step) > 0).astype(np.int64)
    return power > 0


def level_pattern(F: np.ndarray, level: int) -> np.ndarray:
    """Structural nonzeros of R_(m-level) = sum_(i<=level) (F h)^i / (m-level+i+1)!: those of I + F + ... + F^level."""
    return np.logical_or.reduce([power_pattern(F, i) for i in range(level + 1)])


def level_blocks(plan: DiscretizePlan):
    """(1, block) for the top level, then (None, block) for the dense levels below it (k = 0 too)."""
    for b in series_blocks(plan):
        name = b.block.name
        if name.startswith("horner_level_"):
            yield int(name.split("_")[2]), b
        elif name.startswith(("horner_saturated_", HORNER_LAST, HORNER_FIRST)):
            yield None, b


def stored_entry(plan: DiscretizePlan) -> dict[int, tuple[int, int]]:
    """(i, j) of each stored position of S and of the levels."""
    return {index: entry for entry, index in plan.s_position.items()}


def written(block, plan: DiscretizePlan) -> list[tuple[int, int]]:
    """The entries a level block computes with a product or constant (not the zero fill), in storage order."""
    entry = stored_entry(plan)
    return sorted({entry[s.target.index[-1]] for s in scalar_statements(block.block.statements) if s.terms}, key=plan.s_position.get)


def test_the_top_level_computes_exactly_the_structural_nonzeros_of_its_term(plan):
    """R_(m-1) = c_out I + F h c_in: its pattern is that of I + F, every other stored entry is set to zero."""
    F = plan.structure.F
    unit = set(plan.structure.unit_rows)
    expected = sorted(((int(i), int(j)) for i, j in zip(*np.nonzero(level_pattern(F, 1))) if i not in unit), key=plan.s_position.get)
    for level, block in level_blocks(plan):
        if level == 1:
            assert written(block, plan) == expected, block.block.name
            assert {s.target.index[-1] for s in block.block.statements} == set(range(plan.segment_size))


def test_the_dense_levels_compute_every_active_entry_that_is_read(plan):
    """The levels below the top cover the closure but the unit columns (summed at k = 0 only); the rows that no row of F reads at k = 0 (and k = 1) only."""
    leaves = set(plan.leaf_rows)
    units = set(plan.unit_entries)
    read = [(i, j) for i, j in plan.active if i not in leaves and (i, j) not in units]
    for level, block in level_blocks(plan):
        if level is None:
            computed = set(written(block, plan))
            name = block.block.name
            everything = [(i, j) for i, j in plan.active if (i, j) not in units]
            last = everything if plan.unit_columns_deferred else plan.active
            expected = last if name == HORNER_LAST else everything if name == HORNER_FIRST else read
            assert set(expected) <= computed, name
            assert name in (HORNER_LAST, HORNER_FIRST) or not computed & {(i, j) for i, j in plan.active if i in leaves}
            assert name == HORNER_LAST or not computed & units, name


def test_the_segments_leave_out_the_unit_and_leaf_columns_of_the_papers_model():
    """Columns 7-9 (random constants) and 6 (read by no row) need no product above k = 0: the segments are 12 wide, no padding.

    S(:, j) = R_1 A(:, j) for a unit column j is summed at k = 0 only, which
    reads R_1 of every row: row 6 is summed at k = 1 too.
    """
    plan = plan_of("ned_doppler18")
    assert plan.segment_columns == [0, 1, 2, 3, 4, 5, 10, 11, 12, 13, 14, 15]
    assert set(plan.spans.values()) == {(0, 12)}
    assert plan.needs_first_level and plan.needs_last_level
    assert plan.unit_columns_deferred  # G reads columns 10-15 only: S's unit columns are for the doublings
    schedule = horner_schedule(plan, 9, doubling=True)
    assert schedule[-2:] == [HORNER_FIRST, HORNER_LAST] and HORNER_FIRST not in schedule[:-2]
    assert HORNER_FIRST not in horner_schedule(plan, 9)
    assert horner_schedule(plan, 2) == ["horner_level_1_into_term", HORNER_LAST]


def test_only_the_last_level_computes_the_rows_no_row_of_f_reads():
    """The paper's model: row 6 (the longitude error) is read by no row of F, so it is summed at k = 0 only."""
    plan = plan_of("ned_doppler18")
    assert plan.leaf_rows == [6]
    F = plan.structure.F
    assert not F[:, 6].any()
    schedule = horner_schedule(plan, 9)
    assert schedule[-1] == HORNER_LAST and HORNER_LAST not in schedule[:-1]
    assert horner_schedule(plan, 1) == ["horner_level_1_into_S"]


def test_products_outside_the_closure_are_only_the_padding_of_the_dense_segments(plan):
    """A scalar term multiplies structural nonzeros only; a segment may read zeros of its span, at most as many as it reads nonzeros."""
    F = plan.structure.F
    closure = set(plan.active) | {(c, c) for c in plan.structure.unit_rows}
    entry = stored_entry(plan)
    f_entries = plan.f_entries
    for level, block in level_blocks(plan):
        padding = inside = 0
        for s in block.block.statements:
            segment = isinstance(s, SegmentAssign)
            for t in scalar_statements((s,)):
                for term in t.terms:
                    if term == (t.target,):  # a sparse term added after a segment's sum
                        continue
                    if len(term) == 1:  # the diagonal constant 1/(k+1)!
                        assert term[0].array == "c_out" and entry[t.target.index[-1]] in {(i, i) for i, _ in plan.active}
                        continue
                    fh, r = term
                    if fh.array != "fh":  # a unit column at k = 0: R_1(i, c) A(c, j)
                        r, fh = term
                        c, j = f_entries[fh.index[0]]
                        assert F[c, j] and entry[r.index[-1]][1] == c
                        c, j = entry[r.index[-1]]
                        assert (c, j) in closure
                        inside += 1
                        continue
                    i, c = f_entries[fh.index[0]]
                    assert F[i, c]
                    j = c if r.owner == "local" else entry[r.index[-1]][1]
                    if r.owner != "local":
                        assert entry[r.index[-1]][0] == c
                    if (c, j) in closure:
                        inside += 1
                    else:
                        assert segment, (block.block.name, t)
                        padding += 1
        assert padding <= inside, block.block.name


def run_chain(plan: DiscretizePlan, F: np.ndarray, h: float, order: int, doubling: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Execute the emitted statements of an order-``order`` chain on F (Phi, S as N x N), as C does before doublings (``doubling``) or without."""
    n = F.shape[0]
    blocks = {b.block.name: b for b in series_blocks(plan) + [transition_check_block(plan)]}
    arrays = {
        ("matrices", "F"): np.array([F[i, j] for i, j in plan.f_entries]),
        ("scratch", "fh"): np.full(len(plan.f_entries), np.nan),
        ("scratch", "S"): np.full(plan.active_size, np.nan),
        ("scratch", "term"): np.full((2, plan.term_size), np.nan),
        ("transition", "Phi"): np.full(len(plan.phi_position), np.nan),  # compressed; E = Phi - I until the doublings are done
    }

    def run(name: str, local: dict[str, float]) -> None:
        for s in scalar_statements(blocks[name].block.statements):
            value = 0.0
            for term in s.terms:
                product = 1.0
                for r in term:
                    product *= local[r.array] if r.owner == "local" else arrays[(r.owner, r.array)][r.index]
                value += product
            for target in s.targets if hasattr(s, "targets") else (s.target,):
                arrays[(target.owner, target.array)][target.index] = value

    run("horner_input", {"h": h})
    for k, name in zip(range(order - 1, -1, -1), horner_schedule(plan, order, doubling)):
        run(name, {"c_out": 1.0 / math.factorial(k + 1), "c_in": 1.0 / math.factorial(k + 2)})
    run("horner_transition", {"one": 1.0})
    if doubling and order > 1 and HORNER_UNIT_COLUMNS in blocks:
        run(HORNER_UNIT_COLUMNS, {})
    run("transition_check", {"one": 1.0})  # Phi = I + E
    S = np.eye(n)
    for i, j in plan.active:
        S[i, j] = arrays[("scratch", "S")][plan.s_position[(i, j)]]
    phi = np.zeros((n, n))  # the stored entries expanded: every other entry of Phi is a structural zero
    for (i, j), k in plan.phi_position.items():
        phi[i, j] = arrays[("transition", "Phi")][k]
    return phi, S


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 9])
def test_the_emitted_chain_is_the_reference_series_at_every_order(plan, order):
    """Phi and S of the statements (run in Python) equal modelgen.derivation.discretization's Horner sums to rounding."""
    F = np.where(plan.structure.F, np.random.default_rng(order).standard_normal(plan.structure.F.shape), 0.0)
    h = 0.4 / max(np.abs(F).sum(axis=1).max(), 1.0)
    phi, S = run_chain(plan, F, h, order)
    phi_ref, s_ref = _taylor_terms(F, h, order)
    assert np.abs(S - s_ref).max() <= 8 * np.finfo(float).eps
    assert np.abs(phi - phi_ref).max() <= 8 * np.finfo(float).eps
    assert not np.isnan(phi).any()


@pytest.mark.parametrize("order", [1, 2, 3, 9])
def test_without_doublings_phi_and_the_columns_of_s_that_g_reads_are_the_reference_series(plan, order):
    """A step that is not halved skips S's unit columns where only the doublings read them: Phi and S G stay the reference's."""
    F = np.where(plan.structure.F, np.random.default_rng(order).standard_normal(plan.structure.F.shape), 0.0)
    h = 0.4 / max(np.abs(F).sum(axis=1).max(), 1.0)
    phi, S = run_chain(plan, F, h, order, doubling=False)
    phi_ref, s_ref = _taylor_terms(F, h, order)
    read = sorted({c for c, _ in plan.structure.entries("G")})
    assert np.abs(phi - phi_ref).max() <= 8 * np.finfo(float).eps
    assert np.abs(S[:, read] - s_ref[:, read]).max(initial=0.0) <= 8 * np.finfo(float).eps


def test_rows_of_random_constants_are_only_set_to_e_i(plan):
    """A row of F that is empty gives a row e_i of Phi: the series, doubling and check write no value into it, only e_i's constants."""
    unit = set(plan.structure.unit_rows)
    blocks = series_blocks(plan) + [doubling_block(plan), transition_check_block(plan)]
    for b in blocks:
        for s in scalar_statements(b.block.statements):
            for target in s.targets if hasattr(s, "targets") else (s.target,):
                entry = {k: e for e, k in plan.phi_position.items()}
                if target.array == "Phi" and entry[target.index[0]][0] in unit:
                    i, j = entry[target.index[0]]
                    assert b.block.name == "horner_transition"
                    assert s.terms == ((Ref("local", "one", ()),),) if i == j else not s.terms


def test_the_transition_and_process_noise_set_every_entry_once(plan):
    """discretize does not clear Phi and Q_d first: the blocks write each stored entry exactly once (E = A S or zero; Q_d or zero).

    Phi is stored compressed to its structural nonzeros: every one of them is written, and nothing else."""
    n = plan.structure.n_states
    (transition,) = [b for b in series_blocks(plan) if b.block.name == "horner_transition"]
    stores, added = [], set()
    for s in scalar_statements(transition.block.statements):
        if (s.target,) in s.terms:  # a sparse term added to a segment's entry
            added.add(s.target.index)
        else:
            stores.append(s.target.index)
    assert sorted(stores) == [(k,) for k in range(len(plan.phi_position))]
    assert len(plan.phi_position) == int(plan.structure.Phi.sum())
    assert added <= set(stores)
    for packed in (False, True):
        noise = [s for b in noise_blocks(plan, packed=packed, ud=False) if b.block.name.startswith("process_noise") for s in b.block.statements]
        written = [t.index for s in noise for t in (s.targets if hasattr(s, "targets") else (s.target,)) if t.array == "Qd"]
        every = [(k,) for k in range(n * (n + 1) // 2)] if packed else [(i, j) for i in range(n) for j in range(n)]
        assert sorted(written) == every


def test_each_level_does_fewer_products_than_a_loop_over_dense_rows(plan):
    """The loop version multiplied each active entry by its whole row of F; the unrolled one skips zero terms."""
    F = plan.structure.F
    rows = F.sum(axis=1)
    loop = sum(int(rows[i]) for i, _ in plan.active)  # products per order of the loop version
    for _, block in level_blocks(plan):
        products = sum(len(t) - 1 for s in scalar_statements(block.block.statements) for t in s.terms)
        assert products < loop


def test_the_chain_of_order_9_on_the_papers_model_costs_what_the_header_states():
    """Horner's rule over the structure: 4557 flops for Phi and S at order 9 on the paper's model (the power series took 8446).

    The unit columns 7-9 are summed in E only (E(:, j) = S A(:, j); S's own
    are for the doublings), row 6, which no row reads, at k = 0 only: in the
    floor as in the emitted chain.  The emitted chain does 4817 (its dense
    segments also multiply the zeros of the levels that have not yet
    saturated): within 6 % of the structural count.
    """
    plan = plan_of("ned_doppler18")
    assert structural_series_cost(plan, 9).total == 4557
    assert [structural_series_cost(plan, m).total for m in (1, 5)] == [749, 2541]
    assert [series_cost(plan, m).total for m in (1, 5, 9)] == [749, 2801, 4817]


def test_the_structural_count_is_a_floor_of_the_emitted_chain(plan):
    """At every order the emitted chain does at least the flops of Horner's rule over the exact patterns (the benchmark's floor)."""
    for order in range(1, 10):
        assert structural_series_cost(plan, order).total <= series_cost(plan, order).total, order


def compressed_scratch(plan: DiscretizePlan) -> int:
    """Scalars of the unrolled discretize's scratch: two term arrays (F h in the first during the chain), S and the balancing's two sums."""
    n = plan.structure.n_states
    return 2 * plan.term_size + plan.active_size + 2 * n


def test_discretize_scratch_is_below_the_dense_arrays_of_the_loop_version(plan):
    """Three N x N arrays, three balancing vectors and Gamma before; the compressed patterns now."""
    n, nw = plan.structure.n_states, plan.structure.G.shape[1]
    assert compressed_scratch(plan) < 3 * n * n + 3 * n + n * nw


@pytest.mark.parametrize("name", ["ned_doppler18", "ned_inertial16", "ned_doppler32_augmented"])
def test_discretize_scratch_of_the_papers_models_is_within_two_n_by_n_arrays(name):
    """Issue 14, item 6: two N x N arrays or fewer where Phi has structure (the paper's models: 372 of 648 at 18 states).

    Where Phi fills more than half of its entries (ins_gps15: 127 of 225) the
    compressed scratch is 3 active entries and the balancing's sums, 411 of 450
    (F h shares term[0]).
    """
    plan = plan_of(name)
    n = plan.structure.n_states
    assert compressed_scratch(plan) <= 2 * n * n


def test_process_noise_pairs_are_the_structural_pairs_of_q_d_one_checked_block_per_row():
    """The checked blocks set exactly Q_d's structural pairs, row i's in ``process_noise_row_i`` (summed after its stores)."""
    plan = plan_of("ned_doppler18")
    blocks = noise_blocks(plan, packed=False, ud=False)
    rows = [b.block for b in blocks if b.block.name.startswith("process_noise_row_")]
    pairs = [s.targets[0].index for b in rows for s in b.statements]
    assert pairs == plan.qd_pairs
    assert all(b.checked and b.read_back for b in rows)
    assert all({i for i, _ in (s.targets[0].index for s in b.statements)} == {int(b.name.rsplit("_", 1)[1])} for b in rows)
