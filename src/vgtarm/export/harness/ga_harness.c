/* Activations of the exported GA, timed (vgtarm.export.galoop; not exported).
 *
 * vgtc_ga_harness_run runs n activations of the exported GA (vgtc_ga.c) one after the other, the
 * i-th from the state q0[i], qd0[i] over the reference window starting at row start[i] of `ref`
 * (rows of 3 VGTC_NJ values) and `tip_d` (rows of 3), with seed seeds[i]; it writes each one's
 * gains, record and wall time (CLOCK_MONOTONIC around the call only). The GA's memory is the
 * caller's: nothing is allocated.
 */
#define _POSIX_C_SOURCE 200809L
#include <time.h>

#include "vgtc_ga.h"

size_t vgtc_ga_size(void) { return sizeof(vgtc_ga); }
size_t vgtc_ga_params_size(void) { return sizeof(vgtc_ga_params); }

int vgtc_ga_harness_run(vgtc_ga *ga, long n, const long *start, const long *horizon, const double *q0,
                        const double *qd0, const double *ref, const double *tip_d, const uint64_t *seeds,
                        double *gains, double *costs, long *counts, double *seconds)
{
    for (long i = 0; i < n; ++i) {
        vgtc_ga_result out;
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        int status = vgtc_ga_activate(ga, horizon[i], q0 + VGTC_NJ * i, qd0 + VGTC_NJ * i,
                                      ref + 3L * VGTC_NJ * start[i], tip_d ? tip_d + 3 * start[i] : NULL, seeds[i],
                                      gains + (long)VGTC_GA_GENES * i, &out);
        clock_gettime(CLOCK_MONOTONIC, &t1);
        if (status != VGTC_GA_OK) return status;
        seconds[i] = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
        costs[2 * i] = out.best_cost;
        costs[2 * i + 1] = out.seeded_cost;
        counts[4 * i] = out.generations;
        counts[4 * i + 1] = out.evaluations;
        counts[4 * i + 2] = out.exact_steps;
        counts[4 * i + 3] = out.dropped;
    }
    return VGTC_GA_OK;
}
