/* One state of a generated function with the checks of Robot's batch path (part of vgtarm).
 *
 * vgt_single_call serves Robot's single-state path (model/robot.py): the caller has copied one
 * state into s->x; the call checks it as the batch path would, runs the generated function and
 * checks its outputs, and says whether the result stands or the batch path must decide (which
 * then refuses the state with its own message, or gives the same numbers). Nothing here raises
 * or reports: any check that fails, or is not conclusive, only sends the call back.
 */
#include <math.h>
#include <stdint.h>

#include "vgtarm.h"

/* Whether x[0 .. n-1] are finite and each inside [low[i], high[i]] (a NaN is neither). */
static int inside(long n, const double *x, const double *low, const double *high)
{
    for (long i = 0; i < n; ++i) {
        if (!isfinite(x[i]) || !(x[i] >= low[i] && x[i] <= high[i])) return 0;
    }
    return 1;
}

/* Whether every row of the trusted margins, row . x[0 .. cols-1], is >= 0 (x[0] is 1, then q). */
static int trusted(long rows, long cols, const double *margins, const double *x)
{
    for (long i = 0; i < rows; ++i) {
        const double *row = margins + i * cols;
        double margin = 0.0;
        for (long j = 0; j < cols; ++j) margin += row[j] * x[j];
        if (!(margin >= 0.0)) return 0;
    }
    return 1;
}

int vgt_single_call(const vgt_single *s)
{
    if (!inside(s->n_x, s->x, s->low, s->high)) return VGT_SINGLE_OUTSIDE;
    if (!trusted(s->n_margins, s->n_columns, s->margins, s->x)) return VGT_SINGLE_MARGIN;
    if (s->f(s->arg, s->res, s->iw, s->w, 0)) return VGT_SINGLE_FAILED;
    for (long i = 0; i < s->n_y; ++i) {
        if (!isfinite(s->y[i])) return VGT_SINGLE_NOT_FINITE;
    }
    return VGT_SINGLE_DONE;
}
