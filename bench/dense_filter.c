/* A straightforward dense Kalman filter in C, for the benchmark only.
 *
 * What an engineer would write by hand for the same equations: full N x N
 * matrices, triple loops, no knowledge of the structure.  N and M are set by
 * the compiler command line (-DN=18 -DM=2).  Predict: x = Phi x,
 * P = Phi P Phi^T + Q_d.  Update: S = H P H^T + R, K = P H^T S^-1 (Cholesky),
 * x += K (z - H x), Joseph form P = (I - K H) P (I - K H)^T + K R K^T.
 */
#include <math.h>
#include <string.h>

#include "dense_filter.h"

static double T1[N][N], T2[N][N], PHt[N][M], S[M][M], L[M][M], K[N][M], A[N][N], xn[N];

unsigned long dense_scratch_bytes(void)
{
    return (unsigned long)(sizeof T1 + sizeof T2 + sizeof PHt + sizeof S + sizeof L + sizeof K + sizeof A + sizeof xn);
}

void dense_predict(double x[N], double P[N][N], const double Phi[N][N], const double Qd[N][N])
{
    int i, j, k;
    for (i = 0; i < N; ++i) {
        xn[i] = 0.0;
        for (k = 0; k < N; ++k) xn[i] += Phi[i][k] * x[k];
    }
    memcpy(x, xn, sizeof xn);
    for (i = 0; i < N; ++i)
        for (j = 0; j < N; ++j) {
            double s = 0.0;
            for (k = 0; k < N; ++k) s += Phi[i][k] * P[k][j];
            T1[i][j] = s;
        }
    for (i = 0; i < N; ++i)
        for (j = 0; j < N; ++j) {
            double s = Qd[i][j];
            for (k = 0; k < N; ++k) s += T1[i][k] * Phi[j][k];
            P[i][j] = s;
        }
}

int dense_update(double x[N], double P[N][N], const double z[M], const double H[M][N], const double r[M])
{
    int i, j, k, a, b;
    double nu[M];
    for (i = 0; i < N; ++i)
        for (a = 0; a < M; ++a) {
            double s = 0.0;
            for (k = 0; k < N; ++k) s += P[i][k] * H[a][k];
            PHt[i][a] = s;
        }
    for (a = 0; a < M; ++a)
        for (b = 0; b < M; ++b) {
            double s = (a == b) ? r[a] : 0.0;
            for (k = 0; k < N; ++k) s += H[a][k] * PHt[k][b];
            S[a][b] = s;
        }
    for (b = 0; b < M; ++b) { /* Cholesky S = L L^T */
        double d = S[b][b];
        for (k = 0; k < b; ++k) d -= L[b][k] * L[b][k];
        if (!(d > 0.0)) return 2;
        L[b][b] = sqrt(d);
        for (a = b + 1; a < M; ++a) {
            double s = S[a][b];
            for (k = 0; k < b; ++k) s -= L[a][k] * L[b][k];
            L[a][b] = s / L[b][b];
        }
    }
    for (i = 0; i < N; ++i) { /* K = PHt S^-1 row by row */
        double y[M];
        for (a = 0; a < M; ++a) {
            double s = PHt[i][a];
            for (b = 0; b < a; ++b) s -= L[a][b] * y[b];
            y[a] = s / L[a][a];
        }
        for (a = M - 1; a >= 0; --a) {
            double s = y[a];
            for (b = a + 1; b < M; ++b) s -= L[b][a] * K[i][b];
            K[i][a] = s / L[a][a];
        }
    }
    for (a = 0; a < M; ++a) {
        nu[a] = z[a];
        for (k = 0; k < N; ++k) nu[a] -= H[a][k] * x[k];
    }
    for (i = 0; i < N; ++i)
        for (a = 0; a < M; ++a) x[i] += K[i][a] * nu[a];
    for (i = 0; i < N; ++i) /* A = I - K H */
        for (j = 0; j < N; ++j) {
            double s = (i == j) ? 1.0 : 0.0;
            for (a = 0; a < M; ++a) s -= K[i][a] * H[a][j];
            A[i][j] = s;
        }
    for (i = 0; i < N; ++i)
        for (j = 0; j < N; ++j) {
            double s = 0.0;
            for (k = 0; k < N; ++k) s += A[i][k] * P[k][j];
            T1[i][j] = s;
        }
    for (i = 0; i < N; ++i)
        for (j = 0; j < N; ++j) {
            double s = 0.0;
            for (k = 0; k < N; ++k) s += T1[i][k] * A[j][k];
            for (a = 0; a < M; ++a) s += K[i][a] * r[a] * K[j][a];
            T2[i][j] = s;
        }
    memcpy(P, T2, sizeof T2);
    (void)xn;
    return 0;
}
