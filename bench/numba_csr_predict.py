#!/usr/bin/env python
"""Exploration (issue 31, item 2; not wired into the generated module): a numba CSR predict kernel beside dense numpy.

One compiled call computes x' = Phi x and the upper triangle of Phi P Phi^T + Q_d (mirrored), over
the structural pattern of Phi (its off-pattern entries checked to be zero, else Phi's own nonzeros),
with a NaN flag for a non-finite result.  Inner loops run over contiguous 1-D slices (2-D row views
did not vectorize: 52 us against 15 us for the upper triangle at 100 states).  Measured beside the
bench's bare dense numpy predict in the same process (CPU time, BLAS on one thread).

usage: python bench/numba_csr_predict.py [18 32 100]
"""
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy as np  # noqa: E402
import numba  # noqa: E402

def make(structure):
    n = structure.shape[0]
    STRUCT = structure.copy()
    SCOLS = np.array([j for i in range(n) for j in range(n) if structure[i, j]], np.int64)
    SSTARTS = np.concatenate([[0], np.cumsum(structure.sum(1))]).astype(np.int64)

    @numba.njit(nogil=True)
    def _predict_kernel(Phi, x, P, Qd, x_out, P_out, check):
        n = x.shape[0]
        outside = False
        for i in range(n):
            row = Phi[i]
            mask = STRUCT[i]
            for j in range(n):
                outside |= (row[j] != 0.0) & (not mask[j])
        if not outside:
            starts = SSTARTS
            cols = SCOLS
            vals = np.empty(SSTARTS[n])
            for i in range(n):
                row = Phi[i]
                for q in range(SSTARTS[i], SSTARTS[i + 1]):
                    vals[q] = row[SCOLS[q]]
        else:
            starts = np.empty(n + 1, np.int64)
            cols = np.empty(n * n, np.int64)
            vals = np.empty(n * n)
            nnz = 0
            for i in range(n):
                starts[i] = nnz
                row = Phi[i]
                for j in range(n):
                    v = row[j]
                    cols[nnz] = j
                    vals[nnz] = v
                    nnz += v != 0.0
            starts[n] = nnz
        nonfinite = 0.0
        for i in range(n):
            s = 0.0
            for q in range(starts[i], starts[i + 1]):
                s += vals[q] * x[cols[q]]
            x_out[i] = s
            nonfinite += 0.0 * s
        if check:
            for i in range(n):
                nonfinite += 0.0 * x[i]
        M = np.empty((n, n))
        for i in range(n):
            row = P_out[i, :]
            row[:] = 0.0
            for q in range(starts[i], starts[i + 1]):
                v = vals[q]
                src = P[cols[q], :]
                for k in range(n):
                    row[k] += v * src[k]
        for i in range(n):
            row = P_out[i]
            for k in range(n):
                M[k, i] = row[k]
        acc = np.zeros(n)
        for i in range(n):
            row = P_out[i, i:]
            row[:] = Qd[i, i:]
            m = n - i
            for q in range(starts[i], starts[i + 1]):
                v = vals[q]
                src = M[cols[q], i:]
                for j in range(m):
                    row[j] += v * src[j]
            q_low = Qd[i, :i]
            for j in range(i):
                acc[j] += 0.0 * q_low[j]
            a_up = acc[i:]
            for j in range(m):
                a_up[j] += 0.0 * row[j]
        for i in range(n):
            nonfinite += acc[i]
            for j in range(i):
                P_out[i, j] = P_out[j, i]
        return nonfinite
    return _predict_kernel


def main() -> None:
    import warnings

    from bench_python_module import BUILTIN, dense_predict, inputs, per_call_us
    from modelgen.codegen.generate import describe
    from modelgen.derivation.symbolic import derive
    from modelgen.jobs import paper_scenario, synthetic_scenario
    from modelgen.model.loading import load_model
    from tests.codegen.large_model_support import large_model

    warnings.simplefilter("ignore")
    print("load average", os.getloadavg())
    for n in map(int, sys.argv[1:] or ["18", "32", "100"]):
        d = derive(load_model(BUILTIN[n]) if n in BUILTIN else large_model(n))
        a = inputs(d, paper_scenario(d) if n == 18 else synthetic_scenario(d))
        kernel = make(describe(d).structure.Phi)
        x, P, Phi, Qd = a["x"], a["P"], a["Phi"], a["Qd"]
        dense = dense_predict(np.tril(np.ones((n, n), dtype=bool), -1))
        xo, Po = np.empty(n), np.empty((n, n))
        kernel(Phi, x, P, Qd, xo, Po, False)
        xw, Pw = dense(x, P, Phi, Qd)
        assert np.array_equal(Po, Po.T) and np.allclose(Po, Pw, rtol=1e-9, atol=1e-12 * abs(Pw).max())

        def call():
            return kernel(Phi, x, P, Qd, np.empty(n), np.empty((n, n)), False)

        td, tk = per_call_us(lambda: dense(x, P, Phi, Qd)), per_call_us(call)
        print(f"{n} states: dense numpy {td:.2f} us, numba CSR kernel {tk:.2f} us, ratio {td / tk:.2f}")


if __name__ == "__main__":
    main()
