/* modelgen C runtime: the factorizations, U D U^T of a covariance, L L^T of an innovation's.
 *
 * Status codes as the generated filters': 0 OK, 1 ERR_NONFINITE, 2 ERR_NOT_POSITIVE.
 * From modelgen/codegen/backends/c/runtime/modelgen_factor.h (copied verbatim).
 */
#ifndef MODELGEN_FACTOR_H
#define MODELGEN_FACTOR_H

#include "modelgen_scalar.h"

/* Index of U(i, j), i < j, of an n x n unit upper triangular U stored as its packed strictly upper
   triangle, row by row. */
#define MODELGEN_STRICT_UPPER(n, i, j) ((i) * (2 * (n) - (i) - 3) / 2 + (j) - 1)

/* P = U D U^T of the n x n row-major P, column by column from the last one, into the packed
   strictly upper u (MODELGEN_STRICT_UPPER) and the pivots d: the contract's test that P is
   positive semidefinite (README, "Generated code"), tol = 16 n eps: P_ii >= 0,
   |P_ij - P_ji| <= tol sqrt(P_ii P_jj) and |P_ij| <= sqrt(P_ii P_jj) (1 + tol), so that a zero
   variance carries no correlation; a pivot that rounding made slightly negative (within tol of the
   diagonal) is zero, and then what is left of its column must be zero too (within the same
   tolerance), else P is indefinite.  Returns 2 for a P that is not, 1 when the factors overflowed,
   else 0.  P's entries must be finite (the caller tests them first). */
static inline int modelgen_udu_factor(const int n, const MODELGEN_SCALAR *P, MODELGEN_SCALAR *u,
                                      MODELGEN_SCALAR *d)
{
    const MODELGEN_SCALAR tol = 16 * n * MODELGEN_EPSILON;
    MODELGEN_SCALAR check = 0;
    int i, j, k;
    for (i = 0; i < n; ++i) {
        if (!(P[i * n + i] >= 0)) {
            return 2;
        }
    }
    for (i = 0; i < n; ++i) {
        for (j = i + 1; j < n; ++j) {
            const MODELGEN_SCALAR bound = MODELGEN_SQRT(P[i * n + i] * P[j * n + j]);
            if (MODELGEN_FABS(P[i * n + j] - P[j * n + i]) > tol * bound
                || MODELGEN_FABS(P[i * n + j]) > bound * (1 + tol)) {
                return 2;
            }
        }
    }
    for (j = n - 1; j >= 0; --j) {
        MODELGEN_SCALAR pivot = P[j * n + j];
        for (k = j + 1; k < n; ++k) {
            pivot -= d[k] * u[MODELGEN_STRICT_UPPER(n, j, k)] * u[MODELGEN_STRICT_UPPER(n, j, k)];
        }
        if (pivot < 0) {
            if (pivot < -tol * P[j * n + j] || !(P[j * n + j] > 0)) {
                return 2;
            }
            pivot = 0;
        }
        d[j] = pivot;
        for (i = 0; i < j; ++i) {
            MODELGEN_SCALAR s = P[i * n + j];
            for (k = j + 1; k < n; ++k) {
                s -= d[k] * u[MODELGEN_STRICT_UPPER(n, i, k)] * u[MODELGEN_STRICT_UPPER(n, j, k)];
            }
            if (!(pivot > 0)
                && MODELGEN_FABS(s) > tol * MODELGEN_SQRT(P[i * n + i] * P[j * n + j])) {
                return 2;
            }
            u[MODELGEN_STRICT_UPPER(n, i, j)] = (pivot > 0) ? s / pivot : 0;
            check += u[MODELGEN_STRICT_UPPER(n, i, j)] - u[MODELGEN_STRICT_UPPER(n, i, j)];
        }
        check += pivot - pivot;
    }
    return (check != 0) ? 1 : 0;
}

/* S = L L^T in place (Cholesky), S symmetric positive definite m x m, its lower triangle given in L
   (row a at L[a * stride]); the strictly upper part of L is not read.  Returns 1 for a pivot that
   is not finite, 2 for one that is not positive, else 0. */
static inline int modelgen_cholesky(const int m, const int stride, MODELGEN_SCALAR *L)
{
    int a, b, e;
    for (b = 0; b < m; ++b) {
        MODELGEN_SCALAR d = L[b * stride + b];
        for (e = 0; e < b; ++e) {
            d -= L[b * stride + e] * L[b * stride + e];
        }
        if (!isfinite(d)) {
            return 1;
        }
        if (!(d > 0)) {
            return 2;
        }
        L[b * stride + b] = MODELGEN_SQRT(d);
        for (a = b + 1; a < m; ++a) {
            MODELGEN_SCALAR s = L[a * stride + b];
            for (e = 0; e < b; ++e) {
                s -= L[a * stride + e] * L[b * stride + e];
            }
            L[a * stride + b] = s / L[b * stride + b];
        }
    }
    return 0;
}

#endif /* MODELGEN_FACTOR_H */
