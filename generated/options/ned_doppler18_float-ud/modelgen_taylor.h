/* modelgen C runtime: Osborne's balancing step and the Taylor series' error bound, for the scaling
 * and squaring of discretize (modelgen.derivation.discretization: the Python module and the
 * reference compute the same numbers in the same order).
 * From modelgen/codegen/backends/c/runtime/modelgen_taylor.h (copied verbatim).
 */
#ifndef MODELGEN_TAYLOR_H
#define MODELGEN_TAYLOR_H

#include "modelgen_ieee.h"
#include "modelgen_scalar.h"

/* One state's step of Osborne's balancing (modelgen.derivation.discretization.sweep_exponent):
   2^k ~ sqrt(row / column) within [-8, 8], the exponent kept within [-40, 40]; 1 when it
   changed. */
static inline int modelgen_balance_step(const MODELGEN_SCALAR row, const MODELGEN_SCALAR column,
                                        signed char *exponent)
{
    int step = 0, next;
    if (row > 0 && column > 0) {
        /* log2(row / column) within 1 */
        step = modelgen_binary_exponent(row) - modelgen_binary_exponent(column);
        step = (step >= 0) ? step / 2 : -((1 - step) / 2); /* floor(step / 2) */
        step = step > 8 ? 8 : (step < -8 ? -8 : step);
    } else if (column > 0) {
        step = -8; /* drives others, driven by none */
    } else if (row > 0) {
        step = 8; /* driven, drives none */
    }
    next = *exponent + step;
    next = next > 40 ? 40 : (next < -40 ? -40 : next);
    if (next == *exponent) {
        return 0;
    }
    *exponent = (signed char)next;
    return 1;
}

/* 2^(s+1) e^theta rho_(m-1)(theta), rho_m(theta) = theta^(m+1) / (m+1)! (m+2) / (m+2-theta): the
   bound on the relative error of Phi of order m after s doublings (growth = e^theta), one order of
   margin for the entries that couple blocks of F, power = theta^m / m!; the same operations in the
   same order as modelgen.derivation.discretization.step_error_bound. */
static inline MODELGEN_SCALAR modelgen_series_bound(const MODELGEN_SCALAR growth,
                                                    const MODELGEN_SCALAR theta,
                                                    const MODELGEN_SCALAR power,
                                                    const int taylor_order, const int halvings)
{
    const int order = taylor_order - 1; /* power = theta^(order+1) / (order+1)! */
    if (!(theta < (MODELGEN_SCALAR)(order + 2))) {
        return MODELGEN_HUGE;
    }
    return growth
           * (power * (MODELGEN_SCALAR)(order + 2) / ((MODELGEN_SCALAR)(order + 2) - theta))
           * modelgen_power_of_two(halvings + 1);
}

/* modelgen_series_bound of order taylor_order, theta^m / m! built here. */
static inline MODELGEN_SCALAR modelgen_step_error_bound(const MODELGEN_SCALAR growth,
                                                        const MODELGEN_SCALAR theta,
                                                        const int taylor_order, const int halvings)
{
    MODELGEN_SCALAR power = 1;
    int k;
    for (k = 1; k <= taylor_order; ++k) {
        power = power * theta / (MODELGEN_SCALAR)k;
    }
    return modelgen_series_bound(growth, theta, power, taylor_order, halvings);
}

#endif /* MODELGEN_TAYLOR_H */
