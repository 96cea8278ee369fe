/* Batch driver for CasADi-generated functions (part of vgtarm).
 *
 * vgt_batch evaluates one generated function over n samples in a single call: input i of
 * sample k starts at in[i] + k * in_stride[i] (a stride of 0 broadcasts one value to every
 * sample), output j of sample k at out[j] + k * out_stride[j]. Large batches are split over
 * OpenMP threads when the library was built with OpenMP; every sample is independent, so the
 * result does not depend on the number of threads.
 */
#include <stdint.h>
#include <stdlib.h>

#include "vgtarm.h"

int vgt_batch(vgt_fn f, vgt_int sz_arg, vgt_int sz_res, vgt_int sz_iw, vgt_int sz_w,
              int n_in, int n_out, long n,
              const double *const *in, const long *in_stride,
              double *const *out, const long *out_stride)
{
    int status = 0;
#ifdef _OPENMP
#pragma omp parallel if (n >= 4096) reduction(| : status)
#endif
    {
        const double **arg = malloc(sizeof(double *) * (size_t)(sz_arg > 0 ? sz_arg : 1));
        double **res = malloc(sizeof(double *) * (size_t)(sz_res > 0 ? sz_res : 1));
        vgt_int *iw = malloc(sizeof(vgt_int) * (size_t)(sz_iw > 0 ? sz_iw : 1));
        double *w = malloc(sizeof(double) * (size_t)(sz_w > 0 ? sz_w : 1));
        int ok = arg && res && iw && w;
        if (!ok) status |= 2;
        /* every thread reaches the loop (a worksharing construct must not be skipped) */
#ifdef _OPENMP
#pragma omp for schedule(static)
#endif
        for (long k = 0; k < n; ++k) {
            if (!ok) continue;
            for (int i = 0; i < n_in; ++i) arg[i] = in[i] + k * in_stride[i];
            for (int j = 0; j < n_out; ++j) res[j] = out[j] + k * out_stride[j];
            if (f(arg, res, iw, w, 0)) status |= 1;
        }
        free(arg);
        free(res);
        free(iw);
        free(w);
    }
    return status;
}
