/* modelgen C runtime: the scalar's IEEE-754 bits: exponents and powers of two without a call, and
 * sign bits (the cheap first test of a vector's signs).
 * From modelgen/codegen/backends/c/runtime/modelgen_ieee.h (copied verbatim).
 */
#ifndef MODELGEN_IEEE_H
#define MODELGEN_IEEE_H

#include <stdint.h>
#include <string.h>

#include "modelgen_scalar.h"

#if MODELGEN_SCALAR_FLOAT
typedef uint32_t modelgen_bits;
#define MODELGEN_SIGN_BIT 0x80000000u
#define MODELGEN_MANTISSA_BITS 23
#define MODELGEN_EXPONENT_MASK 0xFFu
#define MODELGEN_EXPONENT_BIAS 127
#else
typedef uint64_t modelgen_bits;
#define MODELGEN_SIGN_BIT 0x8000000000000000u
#define MODELGEN_MANTISSA_BITS 52
#define MODELGEN_EXPONENT_MASK 0x7FFu
#define MODELGEN_EXPONENT_BIAS 1023
#endif

/* frexp's exponent of a positive finite x (x = f 2^e, f in [0.5, 1)), read from its IEEE-754 bits
   without a call; a subnormal x goes through frexp. */
static inline int modelgen_binary_exponent(const MODELGEN_SCALAR x)
{
    modelgen_bits bits;
    int e;
    memcpy(&bits, &x, sizeof bits);
    e = (int)((bits >> MODELGEN_MANTISSA_BITS) & MODELGEN_EXPONENT_MASK);
    if (e == 0) {
        (void)MODELGEN_FREXP(x, &e);
        return e;
    }
    return e - (MODELGEN_EXPONENT_BIAS - 1);
}

/* 2^e for -80 <= e <= 80, built from its IEEE-754 bits (exact, no call). */
static inline MODELGEN_SCALAR modelgen_power_of_two(const int e)
{
    const modelgen_bits bits = (modelgen_bits)(e + MODELGEN_EXPONENT_BIAS)
                               << MODELGEN_MANTISSA_BITS;
    MODELGEN_SCALAR x;
    memcpy(&x, &bits, sizeof x);
    return x;
}

/* The bits of x: OR'ed over a vector, their MODELGEN_SIGN_BIT is clear when no entry is negative
   (one load and one OR per entry); set, it may be a -0 or a NaN too, so the caller then compares
   entry by entry. */
static inline modelgen_bits modelgen_bits_of(const MODELGEN_SCALAR x)
{
    modelgen_bits bits;
    memcpy(&bits, &x, sizeof bits);
    return bits;
}

#endif /* MODELGEN_IEEE_H */
