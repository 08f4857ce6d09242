"""The unrolled discretize follows the structure: products only where they can be nonzero, compressed scratch.

modelgen.codegen.discretize_kernels builds the series order by order over the
structural nonzeros of (F h)^k; these tests read its statements (no compiler)
and check what the issue asks of them: no product with a structural zero, no
work on rows of random constants, fewer products than a dense-row loop, and a
scratch of at most two N x N arrays.
"""

import numpy as np
import pytest

from modelgen.codegen.discretize_kernels import DiscretizePlan, doubling_block, noise_blocks, series_blocks
from modelgen.codegen.structure import filter_structure
from modelgen.derive.symbolic import derive
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


def test_each_order_computes_exactly_the_structural_nonzeros_of_the_power_of_F(plan):
    F = plan.structure.F
    for k, block in enumerate(series_blocks(plan)[1:], start=2):
        targets = [s.target.index for s in block.block.statements if s.target.array == "term"]
        assert len(targets) == int(power_pattern(F, k).sum()), k
        assert len(set(targets)) == len(targets)


def test_no_product_of_the_series_reads_a_structural_zero(plan):
    """Every term of B_k(i, j) is (F h)(i, c) times B_(k-1)(c, j) with both structurally nonzero."""
    F = plan.structure.F
    f_entries = plan.f_entries
    for k, block in enumerate(series_blocks(plan)[1:], start=2):
        previous = plan.powers[k - 2]
        current = plan.powers[k - 1]
        for s in block.block.statements:
            if s.target.array != "term":
                continue
            i, j = current[s.target.index[1]]
            for fh, term in s.terms:
                r, c = f_entries[fh.index[0]]
                assert r == i and F[r, c]
                assert previous[term.index[-1]] == (c, j)


def test_rows_of_random_constants_are_never_written(plan):
    """A row of F that is empty gives a row e_i of Phi: no series, doubling or noise statement writes it."""
    unit = set(plan.structure.unit_rows)
    blocks = series_blocks(plan) + [doubling_block(plan)]
    for b in blocks:
        for s in b.block.statements:
            if s.target.array == "Phi":
                assert s.target.index[0] not in unit


def test_the_series_does_fewer_products_than_a_loop_over_dense_rows(plan):
    """The loop version multiplied each active entry by its whole row of F; the unrolled one skips zero terms."""
    F = plan.structure.F
    rows = F.sum(axis=1)
    loop = sum(int(rows[i]) for i, _ in plan.active)  # products per order of the loop version
    for block in series_blocks(plan)[1:]:
        products = sum(len(s.terms) for s in block.block.statements if s.target.array == "term")
        assert products < loop


def compressed_scratch(plan: DiscretizePlan) -> int:
    """Scalars of the unrolled discretize's scratch: two term arrays, S, F h and the balancing's two sums."""
    n = plan.structure.n_states
    return 2 * plan.term_size + plan.active_size + max(int(plan.structure.F.sum()), 1) + 2 * n


def test_discretize_scratch_is_below_the_dense_arrays_of_the_loop_version(plan):
    """Three N x N arrays, three balancing vectors and Gamma before; the compressed patterns now."""
    n, nw = plan.structure.n_states, plan.structure.G.shape[1]
    assert compressed_scratch(plan) < 3 * n * n + 3 * n + n * nw


@pytest.mark.parametrize("name", ["ned_doppler18", "ned_inertial16", "ned_doppler32_augmented"])
def test_discretize_scratch_of_the_papers_models_is_within_two_n_by_n_arrays(name):
    """Issue 14, item 6: two N x N arrays or fewer where Phi has structure (the paper's models: 426 of 648 at 18 states).

    Where Phi fills more than half of its entries (ins_gps15: 127 of 225) the
    compressed scratch is 3 active entries + F h, a little above 2 N^2.
    """
    plan = plan_of(name)
    n = plan.structure.n_states
    assert compressed_scratch(plan) <= 2 * n * n


def test_process_noise_pairs_are_the_structural_pairs_of_q_d():
    plan = plan_of("ned_doppler18")
    blocks = noise_blocks(plan, packed=False, ud=False)
    pairs = [s.targets[0].index for s in blocks[-1].block.statements if hasattr(s, "targets")]
    assert pairs == plan.qd_pairs
