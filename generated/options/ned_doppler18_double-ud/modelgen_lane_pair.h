/* modelgen C runtime: sums of products in two lanes (modelgen/codegen/kernels.py, lane_split).
 *
 * The products pair up by position, the first of each pair is added in one lane and the second in
 * the other, then the two lanes are added.  In double, under GCC or Clang with SSE2 arithmetic
 * (unless MODELGEN_SCALAR_LANE_PAIRS is defined), a lane pair is an SSE2 vector, otherwise two
 * scalars: the same operations in the same order, so the same result bit for bit, as long as the
 * compiler does not fuse a product and a sum (-ffp-contract=off, which gcc's -std=c99 implies).
 * From modelgen/codegen/backends/c/runtime/modelgen_lane_pair.h (copied verbatim).
 */
#ifndef MODELGEN_LANE_PAIR_H
#define MODELGEN_LANE_PAIR_H

#include <stdint.h>
#include <string.h>

#include "modelgen_scalar.h"

#if !MODELGEN_SCALAR_FLOAT && defined(__GNUC__) && defined(__SSE2_MATH__) \
    && !defined(MODELGEN_SCALAR_LANE_PAIRS)
typedef double lane_pair __attribute__((vector_size(2 * sizeof(double))));

static inline lane_pair lane_pair_load(const double *a) /* a[0], a[1] */
{
    lane_pair lanes;
    memcpy(&lanes, a, sizeof lanes);
    return lanes;
}

/* the two lanes stored at a, 16-byte aligned: one aligned load (a value stored twice, as the
   unrolled discretize's F h, is then broadcast without a shuffle; may_alias: read through a
   double array) */
typedef double lane_pair_stored
    __attribute__((vector_size(2 * sizeof(double)), __may_alias__));

static inline lane_pair lane_pair_load_aligned(const double *a) /* a[0], a[1], a 16-byte aligned */
{
    return *(const lane_pair_stored *)a;
}

/* 0 or 1: a + lane_pair_offset(a) is 16-byte aligned (a is a double's address) */
static inline size_t lane_pair_offset(const double *a)
{
    return (size_t)(((uintptr_t)a / sizeof(double)) & 1u);
}

static inline lane_pair lane_pair_of(const double a, const double b)
{
    lane_pair lanes;
    const double values[2] = { a, b };
    memcpy(&lanes, values, sizeof lanes);
    return lanes;
}

static inline lane_pair lane_pair_product(const lane_pair a, const lane_pair b)
{
    return a * b;
}

static inline lane_pair lane_pair_add_product(const lane_pair acc, const lane_pair a,
                                              const lane_pair b)
{
    return acc + a * b;
}

static inline lane_pair lane_pair_add(const lane_pair acc, const lane_pair a)
{
    return acc + a;
}

static inline double lane_pair_sum(const lane_pair acc)
{
    double lanes[2];
    memcpy(lanes, &acc, sizeof lanes);
    return lanes[0] + lanes[1];
}

/* the larger of norm and each lane, the first lane first (norm = v > norm ? v : norm, lane by
   lane) */
static inline double lane_pair_max(const lane_pair acc, double norm)
{
    double lanes[2];
    memcpy(lanes, &acc, sizeof lanes);
    norm = lanes[0] > norm ? lanes[0] : norm;
    return lanes[1] > norm ? lanes[1] : norm;
}

static inline void lane_pair_store(double *a, const lane_pair acc) /* a[0], a[1] */
{
    memcpy(a, &acc, sizeof acc);
}
#else
typedef struct {
    MODELGEN_SCALAR lane[2];
} lane_pair;

static inline lane_pair lane_pair_load(const MODELGEN_SCALAR *a) /* a[0], a[1] */
{
    lane_pair lanes;
    lanes.lane[0] = a[0];
    lanes.lane[1] = a[1];
    return lanes;
}

static inline lane_pair lane_pair_load_aligned(const MODELGEN_SCALAR *a) /* a[0], a[1] */
{
    return lane_pair_load(a);
}

static inline size_t lane_pair_offset(const MODELGEN_SCALAR *a) /* no alignment needed: 0 */
{
    (void)a;
    return 0;
}

static inline lane_pair lane_pair_of(const MODELGEN_SCALAR a, const MODELGEN_SCALAR b)
{
    lane_pair lanes;
    lanes.lane[0] = a;
    lanes.lane[1] = b;
    return lanes;
}

static inline lane_pair lane_pair_product(const lane_pair a, const lane_pair b)
{
    lane_pair lanes;
    lanes.lane[0] = a.lane[0] * b.lane[0];
    lanes.lane[1] = a.lane[1] * b.lane[1];
    return lanes;
}

static inline lane_pair lane_pair_add_product(const lane_pair acc, const lane_pair a,
                                              const lane_pair b)
{
    lane_pair lanes;
    lanes.lane[0] = acc.lane[0] + a.lane[0] * b.lane[0];
    lanes.lane[1] = acc.lane[1] + a.lane[1] * b.lane[1];
    return lanes;
}

static inline lane_pair lane_pair_add(const lane_pair acc, const lane_pair a)
{
    lane_pair lanes;
    lanes.lane[0] = acc.lane[0] + a.lane[0];
    lanes.lane[1] = acc.lane[1] + a.lane[1];
    return lanes;
}

static inline MODELGEN_SCALAR lane_pair_sum(const lane_pair acc)
{
    return acc.lane[0] + acc.lane[1];
}

static inline MODELGEN_SCALAR lane_pair_max(const lane_pair acc, MODELGEN_SCALAR norm)
{
    norm = acc.lane[0] > norm ? acc.lane[0] : norm;
    return acc.lane[1] > norm ? acc.lane[1] : norm;
}

static inline void lane_pair_store(MODELGEN_SCALAR *a, const lane_pair acc) /* a[0], a[1] */
{
    a[0] = acc.lane[0];
    a[1] = acc.lane[1];
}
#endif

#endif /* MODELGEN_LANE_PAIR_H */
