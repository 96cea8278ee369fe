/* The genetic algorithm of switching control for a real-time target (see vgtc_ga.h).
 *
 * Every operation of an activation is the simulation's own: vgt_ga.h, which the simulation's
 * compiled GA (vgtarm/model/csrc/ga.c) includes too, holds the generator, the operators, the
 * prediction and the safe variant; this file gives them static memory (the members of vgtc_ga),
 * the window of the activation and the model's generated functions. With GCC or Clang a block's
 * lanes are vectors of their extensions, with any other C99 compiler (or VGTC_GA_NO_VECTORS
 * defined) arrays: the same bits (see vgt_ga.h). Build with -ffp-contract=off (the Makefile and
 * CMakeLists.txt do): the fused multiply-adds of the simulation's kernel are written out as fmaf
 * (VGTC_GA_FMA), and no other operation may be fused.
 */
#include <math.h>
#include <string.h>

#include "vgtc_ga.h"
#include "vgtc_model.h"

#define VGT_GA_NJ VGTC_NJ
#define VGT_GA_LANES VGTC_GA_LANES
#ifdef VGTC_GA_NO_VECTORS
#define VGT_GA_NO_VECTORS
#endif
#include "vgt_ga.h"

/* ---- the prediction ------------------------------------------------------------------------- */

/* The model's generated functions as the GA calls them (local: their addresses need no GOT). */
static int model_tip(const double **arg, double **res, long long *iw, double *w, int mem)
{
    return vgt_tip(arg, res, iw, w, mem);
}

static int model_jac(const double **arg, double **res, long long *iw, double *w, int mem)
{
    return vgt_jac(arg, res, iw, w, mem);
}

static int model_tip_hessian(const double **arg, double **res, long long *iw, double *w, int mem)
{
    return vgt_tip_hessian(arg, res, iw, w, mem);
}

static int model_id(const double **arg, double **res, long long *iw, double *w, int mem)
{
    return vgt_id(arg, res, iw, w, mem);
}

/* What the prediction of an activation reads and writes. */
typedef struct {
    ga_window window;
    ga_lanes lanes;
} predictor;

/* The predicted tip errors of candidates rows[0 .. n) into cost, in blocks of VGTC_GA_LANES
 * (ga_predict_fn). */
static int predict(void *context, long n, const uint64_t *const *rows, double *cost)
{
    predictor *x = (predictor *)context;
    long b, n_far;
    for (b = 0; b < n; b += VGTC_GA_LANES) {
        const int count = n - b < VGTC_GA_LANES ? (int)(n - b) : VGTC_GA_LANES;
        double penalty[VGTC_GA_LANES], sum[VGTC_GA_LANES];
        ga_gains_from_bytes(&x->window, count, rows + b, x->lanes.K);
        ga_safe_repair(&x->window.safe, VGTC_NJ, &x->lanes, penalty);
        ga_kernel(&x->window, &x->lanes, VGTC_NJ, VGTC_GA_FMA, count, sum, &n_far);
        if (ga_block_costs(&x->window, &x->lanes, count, n_far, sum, penalty, cost + b))
            return VGTC_GA_FUNCTION_FAILED;
    }
    return VGTC_GA_OK;
}

/* The predictor of an activation on the members of ga (its window's terms not computed yet). */
static void predictor_on(vgtc_ga *ga, predictor *x, long horizon)
{
    ga_window *w = &x->window;
    ga_safe *safe = &w->safe;
    memset(x, 0, sizeof *x);
    w->nj = VGTC_NJ;
    w->n_genes = VGTC_GA_GENES;
    w->horizon = horizon;
    w->dt = ga->p.dt;
    w->quadratic = ga->p.quadratic;
    w->exact_above2 = ga->p.exact_above * ga->p.exact_above;
    w->q0 = ga->q0, w->qd0 = ga->qd0;
    w->q_d = ga->q_d, w->qd_d = ga->qd_d, w->qdd_d = ga->qdd_d;
    w->tip_d = ga->tip_d, w->tip_offset = ga->tip_offset;
    w->J_d = ga->J_d, w->H_d = ga->H_d;
    w->p = ga->p.model;
    w->tip = model_tip;
    w->r = ga->r, w->s = ga->s, w->jac_f = ga->jac_f, w->off_f = ga->off_f, w->coef = ga->coef;
    w->row_used = ga->row_used, w->moves = ga->moves;
    w->lo = ga->lo, w->step = ga->step, w->hi = ga->hi;
    if (ga->p.saturation) {
        w->force_limit = ga->p.force_limit, w->speed_limit = ga->p.speed_limit, w->force_speed = ga->p.force_speed;
        w->F_d = ga->F_d, w->M_d = ga->M_d, w->Minv_d = ga->Minv_d, w->D_d = ga->D_d;
        w->force_f = ga->force_f, w->mass_f = ga->mass_f, w->minv_f = ga->minv_f, w->damp_f = ga->damp_f;
        w->act_f = ga->act_f;
    }
    safe->on = ga->p.safe;
    safe->kv = ga->p.safe_kv, safe->lo = ga->p.safe_lo, safe->hi = ga->p.safe_hi;
    safe->nkv = ga->p.safe_nkv, safe->kv_step = ga->p.safe_kv_step;
    safe->lo_tab = ga->p.safe_lo_tab, safe->hi_tab = ga->p.safe_hi_tab;
    x->lanes.K = ga->K;
    x->lanes.sym = ga->sym;
    x->lanes.shifted = ga->shifted;
    x->lanes.far = ga->far;
    x->lanes.far_at = ga->far_at;
    x->lanes.work.arg = ga->arg;
    x->lanes.work.res = ga->res;
    x->lanes.work.iw = ga->iw;
    x->lanes.work.w = ga->w;
    x->lanes.work.angular = ga->w + VGTC_SZ_W;
}

/* The activation's window: the reference rows, the model's tip, its Jacobian and (quadratic)
 * Hessian along them, the desired tip (the model's when tip_d is NULL), and the terms of the
 * prediction. */
static int window(vgtc_ga *ga, predictor *x, long horizon, const double *q0, const double *qd0, const double *ref,
                  const double *tip_d)
{
    const int nj = VGTC_NJ, nn = VGTC_NJ * VGTC_NJ;
    long j;
    int k;
    predictor_on(ga, x, horizon);
    memcpy(ga->q0, q0, sizeof ga->q0);
    memcpy(ga->qd0, qd0, sizeof ga->qd0);
    for (j = 0; j <= horizon; ++j) {
        double tip[3];
        memcpy(ga->q_d + j * nj, ref + j * 3 * nj, sizeof(double) * (size_t)nj);
        memcpy(ga->qd_d + j * nj, ref + j * 3 * nj + nj, sizeof(double) * (size_t)nj);
        memcpy(ga->qdd_d + j * nj, ref + j * 3 * nj + 2 * nj, sizeof(double) * (size_t)nj);
        if (ga_tip_terms(model_tip, model_jac, model_tip_hessian, &x->lanes.work, ga->q_d + j * nj, ga->p.model, tip,
                         ga->J_d + 3 * nj * j, ga->p.quadratic ? ga->H_d + 3 * nn * j : NULL))
            return VGTC_GA_FUNCTION_FAILED;
        for (k = 0; k < 3; ++k) {
            ga->tip_d[3 * j + k] = tip_d ? tip_d[3 * j + k] : tip[k];
            ga->tip_offset[3 * j + k] = ga->tip_d[3 * j + k] - tip[k];
        }
        if (ga->p.saturation
            && ga_dynamics_row(model_id, &x->lanes.work, nj, ga->q_d + j * nj, ga->qd_d + j * nj,
                               ga->qdd_d + j * nj, ga->p.model, ga->F_d + j * nj, ga->M_d + j * nn,
                               ga->Minv_d + j * nn, ga->D_d + j * nn, ga->dynamics_tmp))
            return VGTC_GA_FUNCTION_FAILED;
    }
    ga_window_terms(&x->window);
    return VGTC_GA_OK;
}

/* ---- init and the activation ---------------------------------------------------------------- */

static int finite_all(long n, const double *v)
{
    long i;
    for (i = 0; i < n; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

int vgtc_ga_init(vgtc_ga *ga, const vgtc_ga_params *p)
{
    const long L = (long)VGTC_GA_GENES * 8;
    long max_flips;
    int gi;
    if (!ga || !p) return VGTC_GA_BAD_ARGUMENT;
    if (!(p->population >= 2 && p->population <= VGTC_GA_POPULATION) || !(p->elite >= 0 && p->elite < p->population)
        || !(p->generations >= 0) || !(p->n_seeded >= 0 && p->n_seeded <= VGTC_GA_SEEDED && p->n_seeded <= p->population)
        || !(p->horizon >= 1 && p->horizon <= VGTC_GA_HORIZON) || !(isfinite(p->dt) && p->dt > 0.0)
        || !(p->p_crossover >= 0.0 && p->p_crossover <= 1.0) || !(p->p_mutation >= 0.0 && p->p_mutation <= 1.0)
        || !(isfinite(p->exact_above) && p->exact_above >= 0.0) || !finite_all(VGTC_NP, p->model)
        || !finite_all(VGTC_GA_GENES, p->lower) || !finite_all(VGTC_GA_GENES, p->upper)
        || !(p->safe_nkv >= 0 && p->safe_nkv <= VGTC_GA_NKV) || (p->safe && p->n_seeded < 1))
        return VGTC_GA_BAD_PARAMETER;
    for (gi = 0; gi < VGTC_GA_GENES; ++gi)
        if (!(p->lower[gi] <= p->upper[gi])) return VGTC_GA_BAD_PARAMETER;
    for (gi = 0; p->saturation && gi < VGTC_NJ; ++gi) /* limits > 0 (INFINITY: none), lines 0 or 1 */
        if (!(p->force_limit[gi] > 0.0) || !(p->speed_limit[gi] > 0.0)
            || !(p->force_speed[gi] == 0.0 || p->force_speed[gi] == 1.0))
            return VGTC_GA_BAD_PARAMETER;
    max_flips = ga_max_flips((long)p->population - p->elite, L, p->p_mutation);
    if (max_flips > VGTC_GA_MAX_FLIPS) return VGTC_GA_BAD_PARAMETER;
    memset(ga, 0, sizeof *ga);
    ga->p = *p;
    ga->max_flips = max_flips;
    ga_valid_bits(L, ga->valid);
    ga_rank_weights(p->population, ga->weights);
    ga_gene_tables(VGTC_GA_GENES, p->lower, p->upper, ga->lo, ga->step, ga->hi);
    ga->ready = 1;
    return VGTC_GA_OK;
}

/* The population of an activation on the members of ga. */
static void population(vgtc_ga *ga, predictor *x, ga_population *p)
{
    memset(p, 0, sizeof *p);
    p->n_genes = VGTC_GA_GENES;
    p->n_bits = 8;
    p->words = VGTC_GA_WORDS;
    p->population = ga->p.population;
    p->generations = ga->p.generations;
    p->elite = ga->p.elite;
    p->n_seeded = ga->p.n_seeded;
    p->p_crossover = ga->p.p_crossover;
    p->p_mutation = ga->p.p_mutation;
    p->max_flips = ga->max_flips;
    p->lower = ga->p.lower;
    p->upper = ga->p.upper;
    p->initial_bits = ga->p.initial_bits;
    p->valid = ga->valid;
    p->weights = ga->weights;
    p->pop = ga->pop;
    p->next = ga->next;
    p->best_bits = ga->best_bits;
    p->cost = ga->cost;
    p->next_cost = ga->next_cost;
    p->new_cost = ga->new_cost;
    p->expectation = ga->expectation;
    p->parent_cost = ga->parent_cost;
    p->work = ga->work;
    p->order = ga->order;
    p->pool = ga->pool;
    p->fresh = ga->fresh;
    p->flips = ga->flips;
    p->rows = ga->rows;
    p->predict = predict;
    p->context = x;
}

int vgtc_ga_activate(vgtc_ga *ga, long horizon, const double *q0, const double *qd0, const double *ref,
                     const double *tip_d, uint64_t seed, double *gains, vgtc_ga_result *out)
{
    predictor x;
    ga_population p;
    int status, dropped;
    if (!ga || !ga->ready || !q0 || !qd0 || !ref || !gains || horizon < 1 || horizon > ga->p.horizon)
        return VGTC_GA_BAD_ARGUMENT;
    if (!finite_all(VGTC_NJ, q0) || !finite_all(VGTC_NJ, qd0) || !finite_all((horizon + 1) * 3 * VGTC_NJ, ref)
        || (tip_d && !finite_all((horizon + 1) * 3, tip_d)))
        return VGTC_GA_NOT_FINITE;
    if ((status = window(ga, &x, horizon, q0, qd0, ref, tip_d)) != VGTC_GA_OK) return status;
    population(ga, &x, &p);
    if ((status = ga_evolve(&p, seed)) != VGTC_GA_OK) return status;
    dropped = ga_result(&p, VGTC_NJ, &x.window.safe, gains);
    ga->exact_steps = x.lanes.exact_steps;
    if (out) {
        out->best_cost = p.best_cost;
        out->seeded_cost = p.seeded_cost;
        out->generations = p.generations;
        out->evaluations = p.evaluations;
        out->exact_steps = x.lanes.exact_steps;
        out->dropped = dropped;
    }
    return VGTC_GA_OK;
}
