/* The work arrays of the CasADi-generated functions (part of vgtarm), for the drivers that call
 * them in a loop (closed_loop.c, drill_loop.c): sized once for the largest of the functions a
 * driver calls, allocated once, and one call that points the arrays at its inputs and outputs.
 * Include after vgtarm.h (vgt_call, vgt_int).
 */
#ifndef VGT_WORK_H
#define VGT_WORK_H

#include <stdlib.h>

typedef struct {
    const double **arg;
    double **res;
    vgt_int *iw;
    double *w;
} vgt_work;

/* The largest of the calls' sizes (which: 0 arguments, 1 results, 2 integer work, 3 real work), plus one. */
static vgt_int vgt_work_size(const vgt_call *const *calls, int count, int which)
{
    vgt_int best = 0;
    for (int i = 0; i < count; ++i) {
        const vgt_call *c = calls[i];
        vgt_int v = which == 0 ? c->sz_arg : which == 1 ? c->sz_res : which == 2 ? c->sz_iw : c->sz_w;
        best = v > best ? v : best;
    }
    return best + 1;
}

/* Work arrays for every one of the calls; 0 when memory ran out (free with vgt_work_free all the same). */
static int vgt_work_alloc(vgt_work *wk, const vgt_call *const *calls, int count)
{
    wk->arg = malloc(sizeof(double *) * (size_t)vgt_work_size(calls, count, 0));
    wk->res = malloc(sizeof(double *) * (size_t)vgt_work_size(calls, count, 1));
    wk->iw = malloc(sizeof(vgt_int) * (size_t)vgt_work_size(calls, count, 2));
    wk->w = malloc(sizeof(double) * (size_t)vgt_work_size(calls, count, 3));
    return wk->arg && wk->res && wk->iw && wk->w;
}

static void vgt_work_free(vgt_work *wk)
{
    free(wk->arg);
    free(wk->res);
    free(wk->iw);
    free(wk->w);
}

/* One generated function on its inputs and outputs, in the work arrays; its status (0: done). */
static int vgt_work_call(const vgt_call *c, vgt_work *wk, int n_in, const double **in, int n_out, double **out)
{
    for (int i = 0; i < n_in; ++i) wk->arg[i] = in[i];
    for (int j = 0; j < n_out; ++j) wk->res[j] = out[j];
    return c->f(wk->arg, wk->res, wk->iw, wk->w, 0);
}

#endif
