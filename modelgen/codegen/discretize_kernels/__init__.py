"""discretize as straight-line code that follows the structure of F, Phi, Gamma and Q_d.

The Taylor series of modelgen.derivation.discretization is summed by Horner's
rule over compressed storage, A = F h:

    R_m = I / (m+1)!,   R_k = I / (k+1)! + A R_(k+1),   S = R_0,   E = Phi - I = A S,

so each order is one sparse product A R_(k+1) and the constants 1/(k+1)!
land on the diagonal only (no per-entry scaling, no Phi += / S += sums).
The rows that are not e_i are of two kinds: block rows, whose closure (the
fill-in of Phi; R_k's pattern grows from I + F to it and then stays) has
more than the diagonal, and diagonal rows (a Markov state: F's row is F_ii).
A block row is stored as one dense segment over its closure's columns,
padded to an even length; its structural zeros are stored zeros.  The
segments leave out the lone columns (``DiscretizePlan.lone_columns``): a
unit column j (F's row j empty) has R_k(:, j) = e_j / (k+1)! + R_(k+1) A(:, j)
and no level reads it, so it is summed at k = 0 only, S(:, j) = R_1 A(:, j),
and E(:, j) = S A(:, j); a leaf column (read by no row of F) holds its
diagonal constant alone.  On the paper's model that takes the segments from
16 columns to 12 (columns 6-9 out).  Then
every level below the top is the same function: for each block row i,
R_k(i, span) = sum over the block rows c of A(i, c) R_(k+1)(c, span), one
fixed-trip loop over k for all rows that gcc -O2 vectorizes (even length,
contiguous rows: two doubles per instruction; 1.1 instructions per flop on
the paper's model against 1.9 for scalar statements over the exact
patterns, bench/bench_cycle.py), then
the sparse terms: c_out on the diagonal, A(i, c) c_in for a row c of
random constants (R_(k+1) = c_in e_c there), A(i, c) R_(k+1)(c, c) for a
diagonal row c.  A row that no row of F reads (``leaf_rows``) is summed at
k = 0 only.  The padding and the not yet saturated levels cost 10 % more
flops than the exact patterns on the paper's model at order 5, 6 % at
order 9 (:func:`structural_series_cost`, the benchmark's floor).  The top level R_(m-1) = c_out I + A c_in is scalar
(its pattern, I + F, is sparse) and sets the rest of the segments to zero.
Each function comes in two copies (R_k into S for even k, into the second
term array for odd k, so that S = R_0 lands in S).  The order m is chosen
at run time by the accuracy rule (``taylor_plan``): the chain reads the
coefficients 1/(k+1)! from a static table, so one generated file serves
every step T.  Rows of F that are empty (random constants) give rows e_i of
Phi and S and appear in no sum.

The doublings E(2h) = 2 E + E^2 and S(2h) = S + E S / 2 run over the active
entries of Phi (rows that are not e_i) with the same structure; working on
E = Phi - I keeps the small part of Phi(h) that adding I would round away
(in float, s times over).  The identity is added at the end.  Then S G (the
pattern of Gamma), and Q_d = T (S G) diag(q) (S G)^T over the upper-triangle
pairs that can be nonzero, which is the paper's Gamma (Q/T) Gamma^T with
Gamma = T S G.

The scratch is compressed too: two arrays of the stored entries (S and the
odd levels; the doubling's new values; S G), F h, and the balancing's two
vectors, far below the two N x N arrays of the filter's own scratch (the
workspace union keeps the larger).

The package, by job (each module one step of the generated discretize):

* ``plan``: the compressed patterns and where each entry is stored (:class:`DiscretizePlan`);
* ``series``: the Horner chain, A = F h down to E = A S (:func:`series_blocks`, :func:`horner_schedule`);
* ``doubling``: the doublings and the check of Phi (:func:`doubling_block`, :func:`transition_check_block`);
* ``noise``: S G and Q_d (:func:`noise_blocks`);
* ``cost``: the operation counts and the structural floor (:func:`unrolled_discretize_cost`, :func:`structural_series_cost`).
"""

from __future__ import annotations

from modelgen.codegen.discretize_kernels.cost import (
    block_cost,
    series_block_costs,
    series_cost,
    structural_series_cost,
    unrolled_discretize_cost,
)
from modelgen.codegen.discretize_kernels.doubling import doubling_block, transition_check_block
from modelgen.codegen.discretize_kernels.noise import noise_blocks
from modelgen.codegen.discretize_kernels.plan import LOCAL, DiscretizeBlock, DiscretizePlan, SegmentAssign, scalar_statements
from modelgen.codegen.discretize_kernels.series import (
    HORNER_FIRST,
    HORNER_LAST,
    HORNER_UNIT_COLUMNS,
    horner_input_block,
    horner_level_block,
    horner_level_name,
    horner_schedule,
    horner_top_block,
    horner_transition_block,
    series_blocks,
    unit_column_terms,
    unit_columns_block,
)

__all__ = [
    "HORNER_FIRST", "HORNER_LAST", "HORNER_UNIT_COLUMNS", "LOCAL", "DiscretizeBlock", "DiscretizePlan", "SegmentAssign",
    "block_cost", "doubling_block", "horner_input_block", "horner_level_block", "horner_level_name", "horner_schedule",
    "horner_top_block", "horner_transition_block", "noise_blocks", "scalar_statements", "series_block_costs", "series_cost",
    "series_blocks", "structural_series_cost", "transition_check_block", "unit_column_terms", "unit_columns_block",
    "unrolled_discretize_cost",
]
