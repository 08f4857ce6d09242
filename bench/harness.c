/* Benchmark harness: one implementation's glue (BENCH_GLUE) around a common loop.
 *
 *   harness INPUT callgrind predict|update ITERATIONS   (valgrind --toggle-collect=bench_*_once)
 *   harness INPUT time predict|update ITERATIONS        (prints ns per call)
 *   harness INPUT memory predict|update 1               (prints peak stack bytes of one call, storage bytes)
 *
 * INPUT holds Phi, Q_d, P (N x N each), x (N), H (M x N), r (M), z (M) as
 * doubles.  Before every call the filter state is restored from a saved copy
 * (outside the measured function), so each call sees the same numbers.
 *
 * Peak stack is measured by stack painting, as on a microcontroller: a
 * noinline function fills a block below the caller's frame with a pattern,
 * the measured call runs from the same frame, and a second noinline function
 * with the identical frame layout counts how much of the pattern was
 * overwritten.  The measured call is the second one, so the dynamic
 * linker's lazy binding on a first call is not counted.  Storage is what the glue's storage_bytes() counts: the filter
 * state and scratch memory each implementation needs beyond the model inputs
 * (Phi, Q_d, H, r, z) that every harness holds alike.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double in_Phi[BENCH_N][BENCH_N], in_Qd[BENCH_N][BENCH_N], in_P[BENCH_N][BENCH_N], in_x[BENCH_N], in_H[BENCH_M][BENCH_N], in_r[BENCH_M], in_z[BENCH_M];

#include BENCH_GLUE

#define STACK_PAINT_BYTES 262144
#define STACK_PATTERN 0xA5

static __attribute__((noinline)) void paint_stack(void)
{
    volatile unsigned char block[STACK_PAINT_BYTES];
    size_t i;
    for (i = 0; i < STACK_PAINT_BYTES; ++i) block[i] = STACK_PATTERN;
}

static __attribute__((noinline)) size_t painted_stack_used(void)
{
    volatile unsigned char block[STACK_PAINT_BYTES];
    size_t i;
    for (i = 0; i < STACK_PAINT_BYTES && block[i] == STACK_PATTERN; ++i) {
    }
    return STACK_PAINT_BYTES - i;
}

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

int main(int argc, char **argv)
{
    FILE *f;
    long it, iterations;
    int predict;
    double start, restore_only, total;
    if (argc < 5) return 2;
    f = fopen(argv[1], "rb");
    if (!f) return 2;
    if (fread(in_Phi, sizeof in_Phi, 1, f) != 1 || fread(in_Qd, sizeof in_Qd, 1, f) != 1 || fread(in_P, sizeof in_P, 1, f) != 1
        || fread(in_x, sizeof in_x, 1, f) != 1 || fread(in_H, sizeof in_H, 1, f) != 1 || fread(in_r, sizeof in_r, 1, f) != 1
        || fread(in_z, sizeof in_z, 1, f) != 1) return 2;
    fclose(f);
    setup();
    predict = strcmp(argv[3], "predict") == 0;
    iterations = atol(argv[4]);
    if (strcmp(argv[2], "callgrind") == 0) {
        for (it = 0; it < iterations; ++it) {
            restore();
            if (predict) bench_predict_once(); else bench_update_once();
        }
        printf("%g\n", checksum());
        return 0;
    }
    if (strcmp(argv[2], "memory") == 0) {
        /* one call first: the dynamic linker binds libm's functions (sincos, tan) lazily on their first
           call, with about 2.5 kB of its own stack; a statically linked microcontroller build has none */
        restore();
        if (predict) bench_predict_once(); else bench_update_once();
        restore();
        paint_stack();
        if (predict) bench_predict_once(); else bench_update_once();
        printf("%lu %lu %g\n", (unsigned long)painted_stack_used(), storage_bytes(), checksum());
        return 0;
    }
    start = now();
    for (it = 0; it < iterations; ++it) restore();
    restore_only = now() - start;
    start = now();
    for (it = 0; it < iterations; ++it) {
        restore();
        if (predict) bench_predict_once(); else bench_update_once();
    }
    total = now() - start;
    printf("%.3f %g\n", 1e9 * (total - restore_only) / (double)iterations, checksum());
    return 0;
}
