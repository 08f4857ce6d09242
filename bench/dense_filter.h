/* Dense reference filter of the benchmark (see dense_filter.c). */
#ifndef BENCH_DENSE_FILTER_H
#define BENCH_DENSE_FILTER_H
void dense_predict(double x[N], double P[N][N], const double Phi[N][N], const double Qd[N][N]);
int dense_update(double x[N], double P[N][N], const double z[M], const double H[M][N], const double r[M]);
unsigned long dense_scratch_bytes(void); /* the static temporaries above */
#endif
