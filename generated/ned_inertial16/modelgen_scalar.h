/* modelgen C runtime (modelgen/codegen/backends/c/runtime): the scalar type of every header.
 *
 * The fixed part of every generated filter (what does not depend on the model) is written once,
 * here, as real C99 that the tests compile with gcc and clang and lint with cppcheck; a generated
 * folder carries a verbatim copy of these files.  Each is a header of static inline functions that
 * only the generated <model>.c includes, after defining:
 *
 *   MODELGEN_SCALAR        the scalar type (double or float)
 *   MODELGEN_SCALAR_FLOAT  1 for float, 0 for double
 *
 * so each filter's translation unit gets its own copy, inlined with the model's sizes as constants
 * (no call, no cost per cycle against code written into the filter itself).  Compile without
 * -ffast-math: the finiteness tests rely on IEEE arithmetic.
 */
#ifndef MODELGEN_SCALAR_H
#define MODELGEN_SCALAR_H

#if !defined(MODELGEN_SCALAR) || !defined(MODELGEN_SCALAR_FLOAT)
#error "define MODELGEN_SCALAR and MODELGEN_SCALAR_FLOAT before including a modelgen runtime header"
#endif

#include <float.h>
#include <math.h>

#if MODELGEN_SCALAR_FLOAT
#define MODELGEN_SQRT sqrtf
#define MODELGEN_FABS fabsf
#define MODELGEN_EXP expf
#define MODELGEN_FREXP frexpf
#define MODELGEN_HUGE HUGE_VALF
#define MODELGEN_EPSILON FLT_EPSILON
#else
#define MODELGEN_SQRT sqrt
#define MODELGEN_FABS fabs
#define MODELGEN_EXP exp
#define MODELGEN_FREXP frexp
#define MODELGEN_HUGE HUGE_VAL
#define MODELGEN_EPSILON DBL_EPSILON
#endif

#endif /* MODELGEN_SCALAR_H */
