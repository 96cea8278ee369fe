/* The genetic algorithm of the switching control method in the simulation (part of vgtarm).
 *
 * Every operation of a GA activation is in vgt_ga.h (the generator, the operators, the prediction
 * of a block of candidates, the safe variant, the activation's loop), which the exported
 * controller includes too: the tests hold the two to the same activations bit for bit. This file
 * gives the GA what the simulation needs around it: the heap (any population, horizon and joint
 * count), genes of any width and the exact prediction, threads predicting the blocks of a
 * generation (OpenMP) watched so that a busy machine drops them, the block's lane code compiled
 * for x86-64-v4, x86-64-v3 and the baseline (chosen by the CPU), the lazily computed tip terms of a
 * run, the entry points Python calls (vgtarm.h) and switching control in the closed loop.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "vgtarm.h"
#include "vgt_ga.h"
#ifdef _OPENMP
#include <omp.h>
#endif

/* ---- the generator and the operators, for the tests ----------------------------------------- */

void vgt_rng_uniform(uint64_t seed, long n, double *out)
{
    ga_rng r;
    ga_rng_seed(&r, seed);
    for (long i = 0; i < n; ++i) out[i] = ga_rng_uniform(&r);
}

void vgt_rng_mutation_positions(uint64_t seed, long total, double p, long max_flips, long *positions,
                                long *n_flips)
{
    ga_rng r;
    ga_rng_seed(&r, seed);
    *n_flips = ga_mutation_positions(&r, total, p, max_flips, positions);
}

void vgt_ga_decode(const vgt_ga_settings *g, long rows, const uint64_t *bits, const double *lower,
                   const double *upper, double *genes)
{
    for (long k = 0; k < rows; ++k)
        ga_decode(g->n_genes, g->n_bits, bits + k * g->words, lower, upper, NULL, genes + k * g->n_genes);
}

void vgt_ga_flip(int words, uint64_t *bits, long n_flips, const long *positions)
{
    (void)words;
    for (long i = 0; i < n_flips; ++i) ga_flip_bit(bits, positions[i]);
}

void vgt_ga_rank_expectations(long n, const double *cost, long n_parents, double *expectation)
{
    long *order = malloc(sizeof(long) * (size_t)n);
    double *work = malloc(sizeof(double) * (3 * (size_t)n + GA_LANES)); /* weights, shared, clean */
    ga_keyed *merge = n > GA_COUNTED ? malloc(sizeof(ga_keyed) * 2 * (size_t)n) : NULL;
    if (order && work && (merge || n <= GA_COUNTED)) {
        ga_rank_weights(n, work);
        ga_rank_expectations(n, cost, n_parents, expectation, order, work, work + n, work + 2 * n, merge);
    }
    free(order);
    free(work);
    free(merge);
}

void vgt_ga_sus(long n, const double *expectation, long n_select, double u, long *selected)
{
    double *edges = malloc(sizeof(double) * (size_t)n);
    if (edges) ga_sus(n, expectation, n_select, u, selected, edges);
    free(edges);
}

void vgt_ga_crossover(int words, long rows, uint64_t *bits, const unsigned char *crossed, const uint64_t *masks)
{
    long pairs = rows / 2, used = 0;
    for (long k = 0; k < pairs; ++k) {
        if (!crossed[k]) continue;
        uint64_t *a = bits + 2 * k * words, *b = a + words;
        const uint64_t *mask = masks + used * words;
        for (int w = 0; w < words; ++w) {
            uint64_t swap = (a[w] ^ b[w]) & mask[w];
            a[w] ^= swap;
            b[w] ^= swap;
        }
        ++used;
    }
}

/* ---- the block's lanes, compiled for the CPU ------------------------------------------------ */

/* The lanes' part of predicting a block of candidates: its gains (from the bit strings rows, or
 * already in sc->K when rows is NULL), the safe variant's repair, and the kernel with the joint
 * count known at compile time for the common sizes (the loops unroll and the gains stay in
 * registers), and for any other count at run time. */
#define LANES_ARGS                                                                                   \
    const ga_window *x, ga_lanes *sc, int count, const uint64_t *const *rows, double *sum, double *penalty, \
        long *n_far
#define LANES_CALL x, sc, count, rows, sum, penalty, n_far
typedef void (*lanes_fn)(LANES_ARGS);

GA_INLINE void block_lanes(LANES_ARGS, const int fused)
{
    if (rows) ga_gains_from_bytes(x, count, rows, sc->K);
    ga_safe_repair(&x->safe, x->nj, sc, penalty);
    switch (x->nj) {
    case 3: ga_kernel(x, sc, 3, fused, count, sum, n_far); break;
    case 6: ga_kernel(x, sc, 6, fused, count, sum, n_far); break;
    case 7: ga_kernel(x, sc, 7, fused, count, sum, n_far); break;
    default: ga_kernel(x, sc, x->nj, fused, count, sum, n_far); break;
    }
}

/* No errno for sqrt, so that the safe variant's lane loops vectorise; no contraction, so that only
 * the kernel's named products are fused. */
#if defined(__GNUC__) && !defined(__clang__)
#define LANE_OPTIONS __attribute__((optimize("no-math-errno", "fp-contract=off")))
#else
#define LANE_OPTIONS
#endif

#if defined(__x86_64__) && defined(__GNUC__)
/* x86-64-v4 (AVX-512: 32 vector registers instead of 16, so fewer of the joints' vectors spill,
 * and a lane loop of the safe variant is one instruction on eight doubles: 7 % off the paper
 * variant's activation and 11 % off the safe variant's on an AMD EPYC, docs/benchmarks.md) and
 * x86-64-v3 (AVX2 and FMA): the same operations lane by lane, the kernel's products fused in both,
 * so the same bits (tested against the export, and the paper's runs). The baseline has no FMA. */
LANE_OPTIONS __attribute__((target("arch=x86-64-v4"))) static void lanes_v4(LANES_ARGS)
{
    block_lanes(LANES_CALL, 1);
}
LANE_OPTIONS __attribute__((target("arch=x86-64-v3"))) static void lanes_v3(LANES_ARGS)
{
    block_lanes(LANES_CALL, 1);
}
#define BASELINE_FUSES 0
#else
#define BASELINE_FUSES 1 /* the other 64-bit ISAs fuse in their baseline */
#endif
LANE_OPTIONS static void lanes_baseline(LANES_ARGS) { block_lanes(LANES_CALL, BASELINE_FUSES); }

/* The lanes' code this CPU runs (vgtarm.export.switching.simulator_fuses tells which fuses). */
static lanes_fn chosen_lanes(void)
{
#if defined(__x86_64__) && defined(__GNUC__)
    __builtin_cpu_init();
#if !defined(__clang__) && __GNUC__ >= 12
    if (__builtin_cpu_supports("x86-64-v4")) return lanes_v4;
    if (__builtin_cpu_supports("x86-64-v3")) return lanes_v3;
#else
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512bw")
        && __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512cd"))
        return lanes_v4;
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi")
        && __builtin_cpu_supports("bmi2"))
        return lanes_v3;
#endif
#endif
    return lanes_baseline;
}

/* ---- prediction ----------------------------------------------------------------------------- */

typedef struct {
    ga_window w;                /* the window and the settings of the prediction                 */
    const vgt_model *m;
    const vgt_settings *s;
    const vgt_ga_settings *g;
    const vgt_ga_problem *pb;
    lanes_fn lanes;             /* chosen_lanes()                                                  */
    int threads;                /* threads that predict blocks of candidates (OpenMP), each with a  */
    int n_scratch;              /*   scratch; scratches allocated (`threads` may drop to 1)       */
    ga_lanes *sc;               /* (n_scratch)                                                     */
} predictor;

/* The gains of up to LANES candidates from decoded genes (row by row), rounded to float. */
static void gains_from_genes(int n_genes, int count, const double *genes, float (*K)[GA_LANES])
{
    for (int gi = 0; gi < n_genes; ++gi)
        for (int c = 0; c < GA_LANES; ++c) K[gi][c] = 0.0f;
    for (int c = 0; c < count; ++c)
        for (int gi = 0; gi < n_genes; ++gi) K[gi][c] = (float)genes[(long)c * n_genes + gi];
}

/* Exact prediction of the candidates listed in `which` (all when which is NULL). */
static int predict_exact(const predictor *x, long n, const long *which, const double *genes, double *cost)
{
    const int nn = x->w.nj * x->w.nj;
    const vgt_ga_problem *pb = x->pb;
    double *kp = malloc(sizeof(double) * (size_t)(n * nn + 1)), *kv = malloc(sizeof(double) * (size_t)(n * nn + 1));
    double *out = malloc(sizeof(double) * (size_t)(n + 1));
    int status = VGT_NO_MEMORY;
    if (kp && kv && out) {
        for (long c = 0; c < n; ++c) {
            long row = which ? which[c] : c;
            memcpy(kp + c * nn, genes + row * 2 * nn, sizeof(double) * (size_t)nn);
            memcpy(kv + c * nn, genes + row * 2 * nn + nn, sizeof(double) * (size_t)nn);
        }
        status = vgt_ga_fitness_limited(x->m, x->s, pb->p_ctrl, x->w.horizon, pb->q0, pb->qd0, pb->q_d, pb->qd_d,
                                        pb->qdd_d, pb->tip_d, pb->force_limit, pb->speed_limit, pb->force_speed, n,
                                        kp, kv, out);
        for (long c = 0; c < n && status == VGT_DONE; ++c) cost[which ? which[c] : c] = out[c];
    }
    free(kp);
    free(kv);
    free(out);
    return status;
}

/* Costs of candidates c .. c + LANES (those below n) with one thread's scratch. */
static int predict_one_block(const predictor *x, ga_lanes *sc, long c, long n, const double *genes,
                             const uint64_t *const *rows, double *cost)
{
    const int count = n - c < GA_LANES ? (int)(n - c) : GA_LANES;
    double sum[GA_LANES], penalty[GA_LANES];
    long n_far;
    if (genes) gains_from_genes(x->w.n_genes, count, genes + c * x->w.n_genes, sc->K);
    x->lanes(&x->w, sc, count, genes ? NULL : rows + c, sum, penalty, &n_far);
    return ga_block_costs(&x->w, sc, count, n_far, sum, penalty, cost + c) ? VGT_FUNCTION_FAILED : VGT_DONE;
}

/* Predicted tip error of n candidates given as decoded genes (row by row), or, with genes NULL, as
 * the bit strings rows[0..n) of 8-bit genes. */
static int predict(const predictor *x, long n, const double *genes, const uint64_t *const *rows, double *cost)
{
    if (x->g->prediction == VGT_PREDICT_EXACT) return predict_exact(x, n, NULL, genes, cost);
    const long n_blocks = (n + GA_LANES - 1) / GA_LANES;
    const int threads = x->threads < n_blocks ? x->threads : (int)n_blocks;
    int failed = 0;
    /* the blocks are independent (each candidate's cost depends on its own lane only), so any
     * split between threads gives the same costs bit for bit; they are handed out one at a time,
     * so that a thread the system holds back delays only the block it has (and blocks with many
     * exact steps even out) */
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) if (threads > 1) reduction(| : failed)
    for (long b = 0; b < n_blocks; ++b) {
#ifdef _OPENMP
        ga_lanes *sc = x->sc + omp_get_thread_num();
#else
        ga_lanes *sc = x->sc;
#endif
        if (predict_one_block(x, sc, b * GA_LANES, n, genes, rows, cost)) failed = 1;
    }
    return failed ? VGT_FUNCTION_FAILED : VGT_DONE;
}

/* The tip derivatives of the window's rows that are not ready yet (pb->ready), from the model's
 * generated functions at q_d with the controller's parameters: each row of a run is computed the
 * first time a window needs it, so a run with few activations computes few rows. */
static int ensure_rows(const vgt_model *m, const vgt_ga_problem *pb, int nj, long rows, int quadratic)
{
    if (!pb->ready) return VGT_DONE;
    const vgt_call *calls[4] = {&m->tip, &m->jac, &m->tip_hessian, &m->id};
    vgt_int sz_arg = 5, sz_res = 2, sz_iw = 1, sz_w = 1;
    for (int f = 0; f < 4; ++f) {
        if (calls[f]->sz_arg > sz_arg) sz_arg = calls[f]->sz_arg;
        if (calls[f]->sz_res > sz_res) sz_res = calls[f]->sz_res;
        if (calls[f]->sz_iw > sz_iw) sz_iw = calls[f]->sz_iw;
        if (calls[f]->sz_w > sz_w) sz_w = calls[f]->sz_w;
    }
    const double **arg = malloc(sizeof(double *) * (size_t)sz_arg);
    double **res = malloc(sizeof(double *) * (size_t)sz_res);
    vgt_int *iw = malloc(sizeof(vgt_int) * (size_t)sz_iw);
    double *w = malloc(sizeof(double) * (size_t)(sz_w + 3 * nj));
    double *tmp = malloc(sizeof(double) * (size_t)GA_DYNAMICS_TMP(nj));
    const ga_work work = {arg, res, iw, w, w + sz_w};
    int status = arg && res && iw && w && tmp ? VGT_DONE : VGT_NO_MEMORY;
    for (long j = 0; j < rows && status == VGT_DONE; ++j) {
        if (pb->ready[j]) continue;
        double tip[3];
        if (ga_tip_terms(m->tip.f, m->jac.f, m->tip_hessian.f, &work, pb->q_d + (long)nj * j, pb->p_ctrl, tip,
                         pb->J_d + 3L * nj * j, quadratic ? pb->H_d + 3L * nj * nj * j : NULL)) {
            status = VGT_FUNCTION_FAILED;
            break;
        }
        for (int k = 0; k < 3; ++k) pb->tip_offset[3 * j + k] = pb->tip_d[3 * j + k] - tip[k];
        if (pb->force_limit) {
            const long at = (long)nj * j, at2 = (long)nj * nj * j;
            if (ga_dynamics_row(m->id.f, &work, nj, pb->q_d + at, pb->qd_d + at, pb->qdd_d + at, pb->p_ctrl,
                                pb->F_d + at, pb->M_d + at2, pb->Minv_d + at2, pb->D_d + at2, tmp)) {
                status = VGT_FUNCTION_FAILED;
                break;
            }
        }
        pb->ready[j] = 1;
    }
    free(tmp);
    free((void *)arg);
    free(res);
    free(iw);
    free(w);
    return status;
}

/* The window's arrays (single precision, per activation) and the gene tables of 8-bit genes. */
static int window_alloc(ga_window *w, const vgt_ga_settings *g, const vgt_ga_problem *pb)
{
    const int nj = w->nj;
    const long H = g->horizon;
    w->r = malloc(sizeof(float) * (size_t)(H * nj + 1));
    w->s = malloc(sizeof(float) * (size_t)(H * nj + 1));
    w->jac_f = malloc(sizeof(float) * (size_t)((H + 1) * 3 * nj));
    w->off_f = malloc(sizeof(float) * (size_t)((H + 1) * 3));
    w->row_used = calloc((size_t)(3 * nj), 1);
    w->moves = calloc((size_t)nj, sizeof(int));
    if (w->quadratic) w->coef = calloc((size_t)(H * 3 * nj * nj + 1), sizeof(float));
    if (!w->r || !w->s || !w->jac_f || !w->off_f || !w->row_used || !w->moves || (w->quadratic && !w->coef))
        return VGT_NO_MEMORY;
    if (w->force_limit) {
        w->force_f = malloc(sizeof(float) * (size_t)(H * nj + 1));
        w->mass_f = malloc(sizeof(float) * (size_t)(H * nj * nj + 1));
        w->minv_f = malloc(sizeof(float) * (size_t)(H * nj * nj + 1));
        w->damp_f = malloc(sizeof(float) * (size_t)(H * nj * nj + 1));
        w->act_f = malloc(sizeof(float) * (size_t)(3 * nj));
        if (!w->force_f || !w->mass_f || !w->minv_f || !w->damp_f || !w->act_f) return VGT_NO_MEMORY;
    }
    if (g->n_bits == 8 && g->prediction != VGT_PREDICT_EXACT) {
        w->lo = malloc(sizeof(float) * (size_t)g->n_genes);
        w->step = malloc(sizeof(float) * (size_t)g->n_genes);
        w->hi = malloc(sizeof(float) * (size_t)g->n_genes);
        if (!w->lo || !w->step || !w->hi) return VGT_NO_MEMORY;
        ga_gene_tables(g->n_genes, pb->lower, pb->upper, w->lo, w->step, w->hi);
    }
    return VGT_DONE;
}

/* One thread's scratch of the prediction. */
static int scratch_alloc(ga_lanes *sc, const vgt_model *m, const vgt_ga_settings *g, int nj)
{
    sc->K = aligned_alloc(sizeof(float[GA_LANES]), sizeof(float[GA_LANES]) * (size_t)(2 * nj * nj));
    if (g->safe) {
        sc->sym = malloc(sizeof(double[GA_LANES]) * (size_t)(nj * nj));
        sc->shifted = malloc(sizeof(double[GA_LANES]) * (size_t)(nj * nj));
        if (!sc->sym || !sc->shifted) return VGT_NO_MEMORY;
    }
    sc->far = malloc(sizeof(float) * (size_t)(GA_LANES * (g->horizon + 1) * nj));
    sc->far_at = malloc(sizeof(long) * (size_t)(GA_LANES * (g->horizon + 1)));
    sc->work.arg = malloc(sizeof(double *) * (size_t)(m->tip.sz_arg > 2 ? m->tip.sz_arg : 2));
    sc->work.res = malloc(sizeof(double *) * (size_t)(m->tip.sz_res > 1 ? m->tip.sz_res : 1));
    sc->work.iw = malloc(sizeof(vgt_int) * (size_t)(m->tip.sz_iw + 1));
    sc->work.w = malloc(sizeof(double) * (size_t)(m->tip.sz_w + 1));
    if (!sc->K || !sc->far || !sc->far_at || !sc->work.arg || !sc->work.res || !sc->work.iw || !sc->work.w)
        return VGT_NO_MEMORY;
    return VGT_DONE;
}

static int predictor_init(predictor *x, const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g,
                          const vgt_ga_problem *pb)
{
    ga_window *w = &x->w;
    memset(x, 0, sizeof *x); /* every pointer NULL, so predictor_free is safe after any failure */
    x->m = m, x->s = s, x->g = g, x->pb = pb;
    x->lanes = chosen_lanes();
    x->threads = g->threads > 0 ? g->threads : 1;
    w->nj = s->n_joints, w->n_genes = g->n_genes, w->horizon = g->horizon, w->dt = s->dt;
    w->quadratic = g->prediction == VGT_PREDICT_QUADRATIC;
    w->exact_above2 = g->exact_above * g->exact_above;
    w->q0 = pb->q0, w->qd0 = pb->qd0, w->q_d = pb->q_d, w->qd_d = pb->qd_d, w->qdd_d = pb->qdd_d;
    w->tip_d = pb->tip_d, w->tip_offset = pb->tip_offset, w->J_d = pb->J_d, w->H_d = pb->H_d;
    w->p = pb->p_ctrl, w->tip = m->tip.f;
    w->force_limit = pb->force_limit, w->speed_limit = pb->speed_limit, w->force_speed = pb->force_speed;
    w->F_d = pb->F_d, w->M_d = pb->M_d, w->Minv_d = pb->Minv_d, w->D_d = pb->D_d;
    w->safe = (ga_safe){g->safe, g->safe_kv, g->safe_lo, g->safe_hi, g->safe_nkv, g->safe_kv_step, g->safe_lo_tab,
                        g->safe_hi_tab};
    int status = window_alloc(w, g, pb);
    if (status != VGT_DONE) return status;
    x->sc = calloc((size_t)x->threads, sizeof(ga_lanes));
    if (!x->sc) return VGT_NO_MEMORY;
    x->n_scratch = x->threads;
    for (int t = 0; t < x->n_scratch; ++t)
        if ((status = scratch_alloc(x->sc + t, m, g, w->nj)) != VGT_DONE) return status;
    if (g->prediction == VGT_PREDICT_EXACT) return VGT_DONE;
    status = ensure_rows(m, pb, w->nj, g->horizon + 1, w->quadratic);
    if (status == VGT_DONE) ga_window_terms(w);
    return status;
}

static void predictor_free(predictor *x)
{
    ga_window *w = &x->w;
    free(w->r);
    free(w->s);
    free(w->jac_f);
    free(w->off_f);
    free(w->lo);
    free(w->step);
    free(w->hi);
    free(w->row_used);
    free(w->moves);
    free(w->coef);
    free(w->force_f);
    free(w->mass_f);
    free(w->minv_f);
    free(w->damp_f);
    free(w->act_f);
    for (int t = 0; x->sc && t < x->n_scratch; ++t) {
        ga_lanes *sc = x->sc + t;
        free(sc->K);
        free(sc->sym);
        free(sc->shifted);
        free(sc->far);
        free(sc->far_at);
        free((void *)sc->work.arg);
        free(sc->work.res);
        free(sc->work.iw);
        free(sc->work.w);
    }
    free(x->sc);
}

int vgt_ga_predict(const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g, const vgt_ga_problem *pb,
                   long n_cand, const double *genes, double *cost)
{
    predictor x;
    int status = predictor_init(&x, m, s, g, pb);
    if (status == VGT_DONE) status = predict(&x, n_cand, genes, NULL, cost);
    predictor_free(&x);
    return status;
}

int vgt_ga_decode_single(const vgt_ga_settings *g, long rows, const uint64_t *bits, const double *lower,
                         const double *upper, int vector, float *genes)
{
    if (g->n_bits != 8) return VGT_FUNCTION_FAILED;
    const int n = g->n_genes;
    ga_window w;
    memset(&w, 0, sizeof w);
    w.n_genes = n;
    w.lo = malloc(sizeof(float) * (size_t)n);
    w.step = malloc(sizeof(float) * (size_t)n);
    w.hi = malloc(sizeof(float) * (size_t)n);
    float(*K)[GA_LANES] = malloc(sizeof(float[GA_LANES]) * (size_t)n);
    int status = w.lo && w.step && w.hi && K ? VGT_DONE : VGT_NO_MEMORY;
    if (status == VGT_DONE) {
        ga_gene_tables(n, lower, upper, w.lo, w.step, w.hi);
        for (long c = 0; c < rows; c += GA_LANES) {
            const uint64_t *block[GA_LANES];
            int count = rows - c < GA_LANES ? (int)(rows - c) : GA_LANES;
            for (int k = 0; k < count; ++k) block[k] = bits + (c + k) * g->words;
            if (vector)
                ga_gains_from_bytes(&w, count, block, K);
            else
                ga_gains_from_bytes_lanes(&w, count, block, K);
            for (int k = 0; k < count; ++k)
                for (int gi = 0; gi < n; ++gi) genes[(c + k) * n + gi] = K[gi][k];
        }
    }
    free(w.lo);
    free(w.step);
    free(w.hi);
    free(K);
    return status;
}

/* ---- the activation ------------------------------------------------------------------------- */

static double seconds(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* predict() with several threads, watched: threads only pay when the CPUs are free. When another
 * process holds them, a thread of the team may not run for a whole time slice, and every
 * generation would wait for it; a prediction that takes far longer than the fastest one per
 * block seen so far (and over half a millisecond) drops the rest of the activation to one thread.
 * The costs are the same with any count. */
static int predict_watched(predictor *x, long n, const double *genes, const uint64_t *const *rows, double *cost,
                           double *fastest_per_block)
{
    if (x->threads <= 1) return predict(x, n, genes, rows, cost);
    const double blocks = (double)((n + GA_LANES - 1) / GA_LANES), start = seconds();
    int status = predict(x, n, genes, rows, cost);
    double elapsed = seconds() - start;
    if (elapsed / blocks < *fastest_per_block) *fastest_per_block = elapsed / blocks;
    if (elapsed > 5e-4 && elapsed > 20.0 * blocks * *fastest_per_block) x->threads = 1;
    return status;
}

/* The activation's predictions (ga_predict_fn): straight from the bit strings for 8-bit genes and
 * a cheaper prediction, else from the decoded genes. */
typedef struct {
    predictor *x;
    int from_bytes;
    const double *lower, *upper;
    double *fractions; /* code / (2^b - 1) for every code (b <= 16), or NULL */
    double *genes;     /* (P, n_genes) */
    double fastest_per_block;
} activation;

static int predict_rows(void *context, long n, const uint64_t *const *rows, double *cost)
{
    activation *a = context;
    const vgt_ga_settings *g = a->x->g;
    if (a->from_bytes) return predict_watched(a->x, n, NULL, rows, cost, &a->fastest_per_block);
    for (long f = 0; f < n; ++f)
        ga_decode(g->n_genes, g->n_bits, rows[f], a->lower, a->upper, a->fractions, a->genes + f * g->n_genes);
    return predict_watched(a->x, n, a->genes, NULL, cost, &a->fastest_per_block);
}

/* The activation's population on the heap, and what its predictions need (a). */
static int population_alloc(ga_population *p, activation *a, const vgt_ga_settings *g, const vgt_ga_problem *pb)
{
    const int W = g->words, P = g->population;
    const long L = (long)g->n_genes * g->n_bits;
    uint64_t *valid = calloc((size_t)W, sizeof(uint64_t));
    double *weights = malloc(sizeof(double) * (size_t)P);
    memset(p, 0, sizeof *p);
    p->n_genes = g->n_genes, p->n_bits = g->n_bits, p->words = W, p->population = P;
    p->generations = g->generations, p->elite = g->elite, p->n_seeded = g->n_seeded;
    p->p_crossover = g->p_crossover, p->p_mutation = g->p_mutation;
    p->max_flips = ga_max_flips(P - g->elite, L, g->p_mutation);
    p->lower = pb->lower, p->upper = pb->upper, p->initial_bits = pb->initial_bits;
    p->valid = valid, p->weights = weights;
    p->pop = calloc((size_t)P * W, sizeof(uint64_t)), p->next = calloc((size_t)P * W, sizeof(uint64_t));
    p->best_bits = calloc((size_t)W, sizeof(uint64_t));
    p->cost = malloc(sizeof(double) * (size_t)P), p->next_cost = malloc(sizeof(double) * (size_t)P);
    p->new_cost = malloc(sizeof(double) * (size_t)P), p->expectation = malloc(sizeof(double) * (size_t)P);
    p->parent_cost = malloc(sizeof(double) * (size_t)P), p->work = malloc(sizeof(double) * (2 * (size_t)P + GA_LANES));
    p->order = malloc(sizeof(long) * (size_t)P), p->pool = malloc(sizeof(long) * (size_t)P);
    p->fresh = malloc(sizeof(long) * (size_t)P), p->flips = malloc(sizeof(long) * (size_t)(p->max_flips + 1));
    p->rows = malloc(sizeof(uint64_t *) * (size_t)P);
    p->merge = P > GA_COUNTED ? malloc(sizeof(ga_keyed) * 2 * (size_t)P) : NULL;
    p->predict = predict_rows;
    p->context = a;
    a->genes = malloc(sizeof(double) * (size_t)P * g->n_genes);
    if (g->n_bits <= 16 && (a->fractions = malloc(sizeof(double) * ((size_t)1 << g->n_bits))))
        for (long c = 0, top = (1L << g->n_bits) - 1; c <= top; ++c) a->fractions[c] = (double)c / (double)top;
    if (!(valid && weights && p->pop && p->next && p->best_bits && p->cost && p->next_cost && p->new_cost
          && p->expectation && p->parent_cost && p->work && p->order && p->pool && p->fresh && p->flips && p->rows
          && (p->merge || P <= GA_COUNTED) && a->genes))
        return VGT_NO_MEMORY;
    ga_valid_bits(L, valid);
    ga_rank_weights(P, weights);
    return VGT_DONE;
}

static void population_free(ga_population *p, activation *a)
{
    free((void *)p->valid);
    free((void *)p->weights);
    free(p->pop);
    free(p->next);
    free(p->best_bits);
    free(p->cost);
    free(p->next_cost);
    free(p->new_cost);
    free(p->expectation);
    free(p->parent_cost);
    free(p->work);
    free(p->order);
    free(p->pool);
    free(p->fresh);
    free(p->flips);
    free((void *)p->rows);
    free(p->merge);
    free(a->genes);
    free(a->fractions);
}

/* ga_evolve, its ranking's lane loops vectorised where the CPU has AVX2 (the same numbers: they
 * count comparisons) */
#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target_clones("arch=x86-64-v3", "default")))
#endif
static int evolve(ga_population *p, uint64_t seed)
{
    return ga_evolve(p, seed);
}

int vgt_ga_activation(const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g,
                      const vgt_ga_problem *pb, uint64_t seed, vgt_ga_result *out)
{
    predictor x;
    ga_population p;
    activation a = {&x, g->n_bits == 8 && g->prediction != VGT_PREDICT_EXACT, pb->lower, pb->upper, NULL, NULL,
                    INFINITY};
    int status = predictor_init(&x, m, s, g, pb);
    int allocated = population_alloc(&p, &a, g, pb);
    if (status == VGT_DONE) status = allocated;
    if (status == VGT_DONE) status = evolve(&p, seed);
    if (status == VGT_DONE) {
        out->dropped = ga_result(&p, x.w.nj, &x.w.safe, out->best);
        out->best_cost = p.best_cost;
        out->seeded_cost = p.seeded_cost;
        out->generations = p.generations;
        out->evaluations = p.evaluations;
        out->exact_candidates = out->exact_steps = 0;
        for (int t = 0; t < x.n_scratch; ++t) {
            out->exact_candidates += x.sc[t].exact_candidates;
            out->exact_steps += x.sc[t].exact_steps;
        }
        out->threads = x.threads;
    }
    predictor_free(&x);
    population_free(&p, &a);
    return status;
}

/* ---- switching control in the loop ---------------------------------------------------------- */

int vgt_simulate_switching(const vgt_model *m, const vgt_settings *s, const vgt_settings *unswitched,
                           const vgt_run *r, const double *Kp, const double *Kv, vgt_switching *sw, long k0,
                           long k1, long *stop)
{
    const int nj = s->n_joints, nn = nj * nj;
    vgt_ga_settings g = *sw->g;
    const vgt_ga_problem *base = sw->pb;
    vgt_slice *slice = sw->slice;
    long k = k0;
    int status;
    if (sw->pending == 3) { /* finish the sample of a dropped held set where the last call paused */
        status = vgt_simulate_slice(m, unswitched, r, Kp, Kv, k, k + 1, stop, slice);
        if (status == VGT_PAUSED) return status;
        sw->pending = 0;
        if (status != VGT_DONE) return status;
        k += 1;
    } else if (sw->pending) { /* finish the activation's sample where the last call paused */
        const long record = sw->count;
        const double start = seconds();
        const double *kp = sw->pending == 1 ? sw->best : Kp, *kv = sw->pending == 1 ? sw->best + nn : Kv;
        status = vgt_simulate_slice(m, unswitched, r, kp, kv, k, k + 1, stop, slice);
        sw->wall_time[record] += seconds() - start;
        if (status == VGT_PAUSED) return status;
        sw->pending = 0;
        sw->count = record + 1;
        if (status != VGT_DONE) return status;
        k += 1;
    }
    while (k < k1) {
        if (sw->hold_left > 0) { /* an admitted set held over the periods it was certified frozen for */
            /* while the error seen at each held sample stays at or below the one seen at the
             * activation (the threshold of `watch`, tested before the sample is controlled) */
            vgt_settings watch = *unswitched;
            watch.threshold = sw->hold_above;
            watch.threshold_measured = s->threshold_measured;
            long end = k + sw->hold_left < k1 ? k + sw->hold_left : k1;
            const long period = sw->hold - sw->hold_left; /* of sample k, counted from the activation's */
            if (period < sw->watch_from) { /* before the gains can act on the error: not watched */
                watch.threshold = 0.0;
                if (k + sw->watch_from - period < end) end = k + sw->watch_from - period;
            }
            status = vgt_simulate_slice(m, &watch, r, sw->best, sw->best + nn, k, end, stop, slice);
            /* paused: *stop is not finished yet; above: *stop was not controlled */
            const long done = status == VGT_DONE ? end : *stop;
            if (sw->held)
                for (long i = k; i < done && i < end; ++i) sw->held[i] = 1;
            sw->hold_left -= (done < end ? done : end) - k;
            if (status == VGT_ABOVE_THRESHOLD) { /* the set did not lower the error: dropped at once */
                k = *stop;
                sw->hold_left = 0;
                if (sw->held) sw->held[k] = 2;
                status = vgt_simulate_slice(m, unswitched, r, Kp, Kv, k, k + 1, stop, slice);
                if (status == VGT_PAUSED) {
                    sw->pending = 3;
                    return status;
                }
                if (status != VGT_DONE) return status;
                k += 1;
                continue;
            }
            if (status != VGT_DONE) return status; /* failed or paused (the next call resumes it) */
            k = end;
            continue;
        }
        status = vgt_simulate_slice(m, s, r, Kp, Kv, k, k1, stop, slice);
        if (status != VGT_ABOVE_THRESHOLD) return status; /* done, failed or paused */
        k = *stop;
        if (sw->count >= sw->max_activations) return VGT_ABOVE_THRESHOLD;
        const long record = sw->count;
        const double start = seconds();
        const double *kp = Kp, *kv = Kv;
        long horizon = sw->g->horizon < r->n - 1 - k ? sw->g->horizon : r->n - 1 - k;
        sw->sample[record] = k;
        sw->generations[record] = sw->evaluations[record] = 0;
        sw->best_cost[record] = sw->seeded_cost[record] = 0.0;
        sw->threads[record] = 1;
        if (horizon > 0) { /* the last sample has nothing left to predict: it keeps the fixed gains */
            if (sw->seeds_used >= sw->max_activations) return VGT_ABOVE_THRESHOLD;
            vgt_ga_problem pb = *base;
            memcpy(sw->q0, r->q_meas + (long)nj * k, sizeof(double) * (size_t)nj);
            memcpy(sw->qd0, r->qd_meas + (long)nj * k, sizeof(double) * (size_t)nj);
            pb.q0 = sw->q0;
            pb.qd0 = sw->qd0;
            pb.q_d = base->q_d + (long)nj * k;
            pb.qd_d = base->qd_d + (long)nj * k;
            pb.qdd_d = base->qdd_d + (long)nj * k;
            pb.tip_d = base->tip_d + 3 * k;
            pb.tip_offset = base->tip_offset + 3 * k;
            pb.J_d = base->J_d + 3L * nj * k;
            if (base->force_limit) {
                pb.F_d = base->F_d + (long)nj * k;
                pb.M_d = base->M_d + (long)nn * k;
                pb.Minv_d = base->Minv_d + (long)nn * k;
                pb.D_d = base->D_d + (long)nn * k;
            }
            if (g.prediction == VGT_PREDICT_QUADRATIC) pb.H_d = base->H_d + 3L * nn * k;
            if (base->ready) pb.ready = base->ready + k;
            g.horizon = horizon;
            /* after a stall (a busy machine, see predict_watched) a spell of activations on one
             * thread, doubling while stalls repeat: a rare hiccup costs a few activations' threads,
             * a busy machine a dozen stalls a run */
            g.threads = sw->skip > 0 ? 1 : sw->g->threads;
            if (sw->skip > 0) --sw->skip;
            vgt_ga_result out = {.best = sw->best};
            status = vgt_ga_activation(m, s, &g, &pb, sw->seeds[sw->seeds_used++], &out);
            if (status != VGT_DONE) {
                *stop = k;
                return status;
            }
            if (g.threads > 1 && out.threads < g.threads) {
                sw->skip = sw->backoff;
                sw->backoff = sw->backoff < 1024 ? 2 * sw->backoff : 1024;
            } else if (g.threads > 1) {
                sw->backoff = 1;
            }
            sw->generations[record] = out.generations;
            sw->evaluations[record] = out.evaluations;
            sw->best_cost[record] = out.best_cost;
            sw->seeded_cost[record] = out.seeded_cost;
            sw->threads[record] = out.threads;
            kp = sw->best;
            kv = sw->best + nn;
            if (sw->hold > 1 && !out.dropped) {
                sw->hold_left = sw->hold - 1;
                sw->hold_above = r->seen ? r->seen[k] : INFINITY;
            }
        }
        status = vgt_simulate_slice(m, unswitched, r, kp, kv, k, k + 1, stop, slice);
        sw->wall_time[record] = seconds() - start;
        if (status == VGT_PAUSED) { /* inside the sample's integration: the next call finishes it */
            sw->pending = horizon > 0 ? 1 : 2;
            return status;
        }
        sw->count = record + 1;
        if (status != VGT_DONE) return status;
        k += 1;
    }
    *stop = k1;
    return VGT_DONE;
}
