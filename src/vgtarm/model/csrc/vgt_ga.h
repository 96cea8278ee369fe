/* The genetic algorithm of the switching control method, shared by the simulation and the
 * exported controller (part of vgtarm).
 *
 * ga.c (the simulation's compiled GA) and the exported controller (vgtarm.export, whose vgtc_ga.c
 * includes a copy of this file) run every operation of a GA activation through these functions,
 * so the two compute the same numbers in the same order: the tests hold the exported GA to the
 * simulation's bit for bit. Only C99 and libm, no heap, no state, no I/O: the includer owns the
 * memory (ga.c allocates it and predicts blocks on threads; vgtc_ga.c holds it in a structure).
 *
 * One activation is the paper's binary-coded algorithm (Appendix B) with the same operators, in
 * the same order, as the readable NumPy reference vgtarm/ga.py:
 *
 *   rank scaling (MATLAB's fitscalingrank, ties share their mean weight) -> stochastic universal
 *   sampling -> shuffle -> uniform crossover of consecutive pairs -> bit-flip mutation -> children
 *   equal to a parent keep its cost, the others are predicted -> elitism.
 *
 * Individuals are bit strings packed most significant bit first into 64-bit words (one spare
 * word at the end, always zero, so a gene can be read with two shifts). Randomness comes from
 * xoshiro256** seeded through splitmix64: a seed gives the same activation bit for bit.
 *
 * The fitness is the predicted tip error of a gain candidate over H control periods under the
 * controller's model (see vgtarm/control/scm.py). Under its own model computed force control
 * leaves the joint errors E = q_d - q, Ed = qd_d - qd on a linear recursion in the gains
 * (explicit Euler, as the exact prediction):
 *
 *   E_{j+1}  = E_j + dt Ed_j + r_j,            r_j = q_d[j+1] - q_d[j] - dt qd_d[j]
 *   Ed_{j+1} = Ed_j - dt (Kp E_j + Kv Ed_j) + s_j,  s_j = qd_d[j+1] - qd_d[j] - dt qdd_d[j]
 *
 * and the tip error tip_d - P(q_d - E) = offset + J E - E^T H E / 2 + O(|E|^3) with J, H the tip
 * Jacobian and Hessian at the reference; a step whose joint error leaves the trust region
 * (exact_above) is mapped by the model's exact forward kinematics instead.
 *
 * The candidates are predicted in blocks of VGT_GA_LANES, one lane each, in single precision: the
 * errors are about 1e-4 m and the gains at most about 1e4, so rounding moves the fitness by about
 * 1e-7 relative (measured in docs/control.md), far below what the GA's ranking resolves; the sums
 * of squares are completed in double. The lanes never mix, so a candidate's numbers do not depend
 * on its block. With GCC or Clang a quantity of the block is one vector of their extensions
 * (VGT_GA_VECTORS: the recursion's values stay in registers); with any other C99 compiler, or with
 * VGT_GA_NO_VECTORS defined, an array of VGT_GA_LANES floats (the loops over the lanes innermost).
 * Each lane is computed with the very operations of the other form, so the two give the same
 * bits (tested).
 *
 * Fused multiply-adds: the prediction's kernel takes `fused`, a constant at each call. With 1 the
 * products the kernel names (LF_FMA) are fused (fmaf: one rounding), as on x86-64-v3 and later and
 * on the other 64-bit ISAs; with 0 they are multiplied, then added. No other operation may be
 * fused: build with -ffp-contract=off (the model build and the export's Makefile do).
 *
 * Macros the includer may define first: VGT_GA_NJ (the joint count, fixed at compile time: arrays
 * sized by it instead of variable-length arrays), VGT_GA_LANES (candidates per block, 8),
 * VGT_GA_NO_VECTORS (the arrays even with GCC or Clang).
 */
#ifndef VGT_GA_H
#define VGT_GA_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "vgt_control.h" /* vgt_cholesky */

#ifndef VGT_GA_LANES
#define VGT_GA_LANES 8
#endif

#if defined(__GNUC__) && !defined(VGT_GA_NO_VECTORS)
#define VGT_GA_VECTORS 1
#else
#define VGT_GA_VECTORS 0
#endif

/* The lane code is inlined into its caller, so that a caller compiled for a wider instruction set
 * (ga.c's x86-64-v3 and v4 versions) vectorises it, and a joint count known there unrolls it. */
#if defined(__GNUC__)
#define GA_INLINE static inline __attribute__((always_inline))
#define GA_UNROLL _Pragma("GCC unroll 16")
#else
#define GA_INLINE static inline
#define GA_UNROLL
#endif

#ifdef VGT_GA_NJ
#define GA_NJ(nj) VGT_GA_NJ
#else
#define GA_NJ(nj) (nj)
#endif

enum { GA_LANES = VGT_GA_LANES, GA_COUNTED = 64 };

/* A CasADi-generated function of the model: arguments, results, integer and real work, memory. */
typedef int (*ga_fn)(const double **arg, double **res, long long *iw, double *w, int mem);

/* Work arrays of the model's functions (w holds their real work, angular 3 nj values more). */
typedef struct {
    const double **arg;
    double **res;
    long long *iw;
    double *w, *angular;
} ga_work;

/* ---- generator ------------------------------------------------------------------------------ */

typedef struct {
    uint64_t s[4];
} ga_rng;

static inline uint64_t ga_splitmix64(uint64_t *x)
{
    uint64_t z = (*x += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

static inline void ga_rng_seed(ga_rng *r, uint64_t seed)
{
    int i;
    for (i = 0; i < 4; ++i) r->s[i] = ga_splitmix64(&seed);
}

static inline uint64_t ga_rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

static inline uint64_t ga_rng_next(ga_rng *r)
{
    uint64_t *s = r->s;
    const uint64_t result = ga_rotl(s[1] * 5, 7) * 9;
    const uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = ga_rotl(s[3], 45);
    return result;
}

/* Uniform on [0, 1) with 53 random bits. */
static inline double ga_rng_uniform(ga_rng *r) { return (double)(ga_rng_next(r) >> 11) * 0x1.0p-53; }

/* The 128-bit product a b as two words (C99 has no 128-bit integer). */
static inline void ga_multiply_wide(uint64_t a, uint64_t b, uint64_t *high, uint64_t *low)
{
    const uint64_t a0 = a & 0xFFFFFFFFULL, a1 = a >> 32, b0 = b & 0xFFFFFFFFULL, b1 = b >> 32;
    const uint64_t p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
    const uint64_t middle = (p00 >> 32) + (p01 & 0xFFFFFFFFULL) + (p10 & 0xFFFFFFFFULL);
    *high = p11 + (p01 >> 32) + (p10 >> 32) + (middle >> 32);
    *low = a * b;
}

/* Uniform integer in [0, n) (Lemire's multiply-shift with rejection: exactly uniform). */
static inline long ga_rng_below(ga_rng *r, long n)
{
    const uint64_t bound = (uint64_t)n;
    uint64_t high, low;
    ga_multiply_wide(ga_rng_next(r), bound, &high, &low);
    if (low < bound) {
        const uint64_t threshold = (0 - bound) % bound;
        while (low < threshold) ga_multiply_wide(ga_rng_next(r), bound, &high, &low);
    }
    return (long)high;
}

/* Positions of the flipped bits among `total` bits flipped independently with probability p:
 * geometric gaps between flips, the same distribution as a draw per bit at a cost per flip. */
static inline long ga_mutation_positions(ga_rng *r, long total, double p, long max_flips, long *positions)
{
    long n = 0, i, position = -1;
    double log_q;
    if (!(p > 0.0) || total <= 0) return 0;
    if (p >= 1.0) {
        for (i = 0; i < total && n < max_flips; ++i) positions[n++] = i;
        return n;
    }
    log_q = log1p(-p);
    while (n < max_flips) {
        const double u = 1.0 - ga_rng_uniform(r); /* (0, 1] */
        const double gap = floor(log(u) / log_q);
        if (gap >= (double)(total - position - 1)) break;
        position += (long)gap + 1;
        positions[n++] = position;
    }
    return n;
}

/* ---- coding --------------------------------------------------------------------------------- */

static inline uint64_t ga_gene_code(const uint64_t *w, long start, int n_bits)
{
    const long i = start >> 6;
    const int offset = (int)(start & 63);
    uint64_t x = w[i] << offset;
    if (offset) x |= w[i + 1] >> (64 - offset);
    return x >> (64 - n_bits);
}

/* Gene gi of a string of 8-bit genes: byte gi, most significant first within each word. */
static inline unsigned ga_gene_byte(const uint64_t *bits, int gi)
{
    return (unsigned)((bits[gi >> 3] >> (56 - 8 * (gi & 7))) & 0xFFu);
}

/* The same arithmetic as ga._decode: lower + code / (2^b - 1) * (upper - lower), capped. With
 * `fractions` (code / (2^b - 1) for every code, b <= 16) the division is a table look-up. */
static inline void ga_decode(int n_genes, int n_bits, const uint64_t *bits, const double *lower,
                             const double *upper, const double *fractions, double *genes)
{
    const double top = (double)((1ULL << n_bits) - 1ULL);
    int i;
    for (i = 0; i < n_genes; ++i) {
        const uint64_t code = ga_gene_code(bits, (long)i * n_bits, n_bits);
        const double fraction = fractions ? fractions[code] : (double)code / top;
        double value = lower[i] + fraction * (upper[i] - lower[i]);
        if (!(value < upper[i])) value = upper[i];
        if (fraction == 1.0) value = upper[i];
        genes[i] = value;
    }
}

static inline void ga_flip_bit(uint64_t *w, long bit) { w[bit >> 6] ^= 1ULL << (63 - (bit & 63)); }

static inline int ga_same_bits(int words, const uint64_t *a, const uint64_t *b)
{
    int w;
    for (w = 0; w < words; ++w)
        if (a[w] != b[w]) return 0;
    return 1;
}

/* valid (words, zeroed): the n_bits_total bits of an individual set. */
static inline void ga_valid_bits(long n_bits_total, uint64_t *valid)
{
    long bit;
    for (bit = 0; bit < n_bits_total; ++bit) valid[bit >> 6] |= 1ULL << (63 - (bit & 63));
}

/* The most bits one generation's mutation flips: the mean of the children's flips with a margin
 * of 64 plus eight standard deviations, at most all their bits (children x bits each). */
static inline long ga_max_flips(long children, long bits, double p_mutation)
{
    const long total = children * bits;
    const long most = 64 + (long)(4.0 * p_mutation * (double)total) + 8 * (long)sqrt((double)children * bits + 1.0);
    return most > total ? total : most;
}

/* ---- selection ------------------------------------------------------------------------------ */

/* NumPy's pairwise summation (numpy/core/src/umath/loops_utils.h), so sums agree bit for bit. */
static inline double ga_pairwise_sum(const double *a, long n)
{
    long i, n2;
    if (n < 8) {
        double res = 0.0;
        for (i = 0; i < n; ++i) res += a[i];
        return res;
    }
    if (n <= 128) {
        double r[8], res;
        int j;
        for (j = 0; j < 8; ++j) r[j] = a[j];
        for (i = 8; i < n - (n % 8); i += 8)
            for (j = 0; j < 8; ++j) r[j] += a[i + j];
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; ++i) res += a[i];
        return res;
    }
    n2 = n / 2;
    n2 -= n2 % 8;
    return ga_pairwise_sum(a, n2) + ga_pairwise_sum(a + n2, n - n2);
}

static inline double ga_clean_cost(double c) { return isfinite(c) ? c : INFINITY; }

/* A cost and its individual, for the merge sort of large populations. */
typedef struct {
    double cost;
    long index;
} ga_keyed;

/* Indices of cost in ascending order, ties in index order, so the order is the same as any stable
 * sort's. Up to GA_COUNTED individuals, or without `merge`, by counting ranks (branch-free: a
 * sort's comparisons of random costs mispredict half the time), the lanes of a block of costs at
 * once, with the costs cleaned into `clean` (n rounded up to GA_LANES, padded with NaN, which
 * compares false to everything):
 *   order[rank[i]] = i,  rank[i] = #{j : c_j < c_i} + #{j < i : c_j == c_i};
 * else by a bottom-up merge sort in `merge` (2 n). */
GA_INLINE void ga_stable_order(long n, const double *cost, long *order, double *clean, ga_keyed *merge)
{
    const long padded = (n + GA_LANES - 1) / GA_LANES * GA_LANES;
    long i, j, b, width, lo;
    int c;
    if (merge && n > GA_COUNTED) {
        ga_keyed *a = merge, *m = merge + n, *t;
        for (i = 0; i < n; ++i) a[i].cost = ga_clean_cost(cost[i]), a[i].index = i;
        for (width = 1; width < n; width *= 2) {
            for (lo = 0; lo < n; lo += 2 * width) {
                const long mid = lo + width < n ? lo + width : n, hi = lo + 2 * width < n ? lo + 2 * width : n;
                long k = lo;
                i = lo;
                j = mid;
                while (i < mid && j < hi) m[k++] = a[j].cost < a[i].cost ? a[j++] : a[i++];
                while (i < mid) m[k++] = a[i++];
                while (j < hi) m[k++] = a[j++];
            }
            t = a, a = m, m = t;
        }
        for (i = 0; i < n; ++i) order[i] = a[i].index;
        return;
    }
    for (i = 0; i < padded; ++i) clean[i] = i < n ? ga_clean_cost(cost[i]) : NAN;
    for (i = 0; i < n; ++i) {
        const double ci = clean[i];
        int64_t count[GA_LANES];
        long rank = 0;
        for (c = 0; c < GA_LANES; ++c) count[c] = 0;
        for (b = 0; b < padded; b += GA_LANES)
            for (c = 0; c < GA_LANES; ++c) {
                const double cj = clean[b + c];
                count[c] += (cj < ci) | ((cj == ci) & (b + c < i));
            }
        for (c = 0; c < GA_LANES; ++c) rank += (long)count[c];
        order[rank] = i;
    }
}

/* Rank weights 1/sqrt(r), r = 1..n. */
static inline void ga_rank_weights(long n, double *weights)
{
    long r;
    for (r = 0; r < n; ++r) weights[r] = 1.0 / sqrt((double)(r + 1));
}

/* The expectations of rank scaling (n_parents in all); order (n) gets the ascending order of the
 * costs, shared (n) is work; clean and merge as ga_stable_order's. */
GA_INLINE void ga_rank_expectations(long n, const double *cost, long n_parents, double *expectation, long *order,
                                    const double *weights, double *shared, double *clean, ga_keyed *merge)
{
    long start = 0, r;
    double scale;
    ga_stable_order(n, cost, order, clean, merge);
    while (start < n) {
        long end = start + 1;
        while (end < n && ga_clean_cost(cost[order[end]]) == ga_clean_cost(cost[order[start]])) ++end;
        if (end - start == 1) { /* a cost of its own: its weight (the mean of one, exactly) */
            shared[start] = weights[start];
        } else {
            const double mean = ga_pairwise_sum(weights + start, end - start) / (double)(end - start);
            for (r = start; r < end; ++r) shared[r] = mean;
        }
        start = end;
    }
    for (r = 0; r < n; ++r) expectation[order[r]] = shared[r];
    scale = (double)n_parents / ga_pairwise_sum(expectation, n);
    for (r = 0; r < n; ++r) expectation[r] *= scale;
}

/* Stochastic universal sampling with the pointer offset u in [0, 1): the same edges and
 * pointers as ga._sus (cumulative sum, rescaled, last edge pinned, searchsorted right). */
static inline void ga_sus(long n, const double *expectation, long n_select, double u, long *selected, double *edges)
{
    double total, scale;
    long i, k, index = 0;
    for (i = 0; i < n; ++i) {
        total = i ? edges[i - 1] + expectation[i] : expectation[i];
        edges[i] = total;
    }
    scale = (double)n_select / edges[n - 1];
    for (i = 0; i < n; ++i) edges[i] *= scale;
    edges[n - 1] = (double)n_select;
    for (k = 0; k < n_select; ++k) {
        const double pointer = u + (double)k;
        while (index < n && edges[index] <= pointer) ++index;
        selected[k] = index;
    }
}

/* ---- the safe variant's admission ----------------------------------------------------------- */

/* The safe variant's settings (control/safety.py): Kp symmetrised, Kv = kv I, kv held or, when
 * the damping is tuned (nkv > 0), the grid point j kv_step nearest to the mean of the candidate's
 * Kv diagonal; admitted iff the eigenvalues of Kp lie in [lo, hi] (per grid point when tuned). */
typedef struct {
    int on;
    double kv, lo, hi;
    int nkv;
    double kv_step;
    const double *lo_tab, *hi_tab; /* (nkv) */
} ga_safe;

/* The damping and admitted interval of the grid point nearest to the mean of a Kv diagonal whose
 * sum is `diagonal`. */
static inline void ga_safe_point(const ga_safe *g, int nj, double diagonal, double *kv0, double *lo, double *hi)
{
    long j = lround(diagonal / nj / g->kv_step);
    j = j < 0 ? 0 : (j >= g->nkv ? g->nkv - 1 : j);
    *kv0 = (double)j * g->kv_step;
    *lo = g->lo_tab[j];
    *hi = g->hi_tab[j];
}

/* Whether the symmetric nj x nj matrix S (row-major) is positive definite: a Cholesky
 * factorisation whose pivots stay positive (exact test, about nj^3 / 6 multiplications). */
static inline int ga_positive_definite(int nj, double *S) { return vgt_cholesky(nj, S); }

/* The safe variant's repair and admission of one candidate: kp (nj x nj, row-major) is replaced by
 * its symmetric part Ks and kv by kv0 I. With Kv a multiple of the identity, Ks and Kv share their
 * eigenvectors, so the discrete loop (hold, velocity filter, model error) splits into one scalar
 * loop per pair (eigenvalue of Ks, kv0); control/safety.py computes the interval [lo, hi] of the
 * eigenvalues whose scalar loops have every pole inside the margin circle for every model error in
 * the bound. Admitted iff Ks - lo I and hi I - Ks are positive definite. Returns 0 when admitted,
 * else a penalty in (1, 3] that grows with Gershgorin's estimate of the violation (3 for a damping
 * without interval), so the GA's ranking leads the population back into the admitted set. */
static inline double ga_safe_admit(int nj, const ga_safe *g, double *kp, double *kv)
{
    double below[GA_NJ(nj) * GA_NJ(nj)], above[GA_NJ(nj) * GA_NJ(nj)], gmin = INFINITY, gmax = -INFINITY;
    double lo = g->lo, hi = g->hi, kv0 = g->kv, scale;
    int i, l;
    if (g->nkv > 0) {
        double mean = 0.0;
        for (i = 0; i < nj; ++i) mean += kv[i * nj + i];
        ga_safe_point(g, nj, mean, &kv0, &lo, &hi);
    }
    for (i = 0; i < nj; ++i)
        for (l = i; l < nj; ++l) {
            const double v = 0.5 * (kp[i * nj + l] + kp[l * nj + i]);
            kp[i * nj + l] = kp[l * nj + i] = v;
        }
    for (i = 0; i < nj; ++i) {
        double radius = 0.0;
        for (l = 0; l < nj; ++l) {
            kv[i * nj + l] = i == l ? kv0 : 0.0;
            below[i * nj + l] = kp[i * nj + l] - (i == l ? lo : 0.0);
            above[i * nj + l] = (i == l ? hi : 0.0) - kp[i * nj + l];
            if (l != i) radius += fabs(kp[i * nj + l]);
        }
        gmin = fmin(gmin, kp[i * nj + i] - radius);
        gmax = fmax(gmax, kp[i * nj + i] + radius);
    }
    if (!(lo < hi)) return 3.0;
    if (ga_positive_definite(nj, below) && ga_positive_definite(nj, above)) return 0.0;
    scale = hi - lo;
    return 1.0 + fmin(1.0, fmax(0.0, lo - gmin) / scale) + fmin(1.0, fmax(0.0, gmax - hi) / scale) + 1e-9;
}

/* ---- the prediction's window ---------------------------------------------------------------- */

/* What the prediction of an activation reads: its window (the measured state, the reference rows
 * from the activation's sample and the model's tip terms along them) and its settings. */
typedef struct {
    int nj, n_genes;
    long horizon;
    double dt;
    int quadratic;       /* second-order tip map (the Hessian) */
    double exact_above2; /* squared joint-error norm above which a step is mapped exactly (0: never) */
    const double *q0, *qd0;                  /* (nj) the measured state                         */
    const double *q_d, *qd_d, *qdd_d;        /* (H+1, nj) the reference                          */
    const double *tip_d, *tip_offset;        /* (H+1, 3) desired tip, tip_d - P^(q_d)            */
    const double *J_d, *H_d;                 /* (H+1, 3, nj), (H+1, 3, nj, nj) tip derivatives   */
    const double *p;                         /* the controller model's parameters                */
    ga_fn tip;                               /* the model's tip (q, p -> tip)                    */
    float *r, *s;        /* (H, nj) reference residuals of the Euler steps                          */
    float *jac_f;        /* (H+1, 3, nj) tip Jacobian of the window                                 */
    float *off_f;        /* (H+1, 3) tip offsets of the window                                      */
    float *coef;         /* (H, 3, nj, nj) -H[k][l][m] for m > l, -H/2 for m = l (0 below), per step */
    unsigned char *row_used; /* (3, nj) row l of axis k has a nonzero coefficient in the window    */
    int *moves;          /* (nj) joint i moves the tip somewhere in the window (a nonzero in its    */
                         /*   column of J or its row of H): only these count for the region       */
    float *lo, *step, *hi; /* (n_genes) 8-bit genes in the prediction: lo + code step, at most hi */
    ga_safe safe;
    /* the actuators (force_limit not NULL; see ga_kernel_saturate): the peak force, the no-load
     * speed and the force-speed line of each joint (INFINITY, any, 0: none), and along the window
     * the controller model's effort F_d = ID(q_d, qd_d, qdd_d), M(q_d), M(q_d)^-1 and dID/dqd
     * (double rows from ga_dynamics_row) with their single-precision copies */
    const double *force_limit, *speed_limit, *force_speed;  /* (nj)                             */
    const double *F_d, *M_d, *Minv_d, *D_d; /* (H+1, nj), then (H+1, nj, nj) each; D = dID/dqd  */
    float *force_f, *mass_f, *minv_f, *damp_f; /* (H, nj), then (H, nj, nj) each (damp_f: -D)   */
    float *act_f;                       /* (3, nj): peak force, 1 / no-load speed, line (1 or 0) */
} ga_window;

/* lo, step, hi of 8-bit genes in single precision (see ga_gains_from_bytes). */
static inline void ga_gene_tables(int n_genes, const double *lower, const double *upper, float *lo, float *step,
                                  float *hi)
{
    int gi;
    for (gi = 0; gi < n_genes; ++gi) {
        lo[gi] = (float)lower[gi];
        step[gi] = (float)((upper[gi] - lower[gi]) / 255.0);
        hi[gi] = (float)upper[gi];
    }
}

/* The model's tip, tip Jacobian and (H not NULL) tip Hessian at q: nonzero when one fails. */
static inline int ga_tip_terms(ga_fn tip_f, ga_fn jac_f, ga_fn hessian_f, const ga_work *w, const double *q,
                               const double *p, double *tip, double *J, double *H)
{
    w->arg[0] = q;
    w->arg[1] = p;
    w->res[0] = tip;
    if (tip_f(w->arg, w->res, w->iw, w->w, 0)) return 1;
    w->res[0] = J;
    w->res[1] = w->angular;
    if (jac_f(w->arg, w->res, w->iw, w->w, 0)) return 1;
    if (!H) return 0;
    w->res[0] = H;
    return hessian_f(w->arg, w->res, w->iw, w->w, 0) != 0;
}

/* The controller model's effort F = ID(q, qd, qdd) of a reference row (no tool force), its mass
 * matrix M(q), column i = ID(q, 0, e_i) - ID(q, 0, 0) (gravity and friction cancel exactly: the
 * same terms of the same call), M^-1 by Cholesky and one solve per column, and the effort's
 * velocity Jacobian D = dID/dqd, column i = (ID(q, qd + e_i, qdd) - ID(q, qd - e_i, qdd)) / 2: exact
 * for any step, the effort being quadratic in qd (Coriolis) plus linear (viscous friction); all in
 * double. id: the model's inverse dynamics (q, qd, qdd, f, p -> F); tmp: GA_DYNAMICS_TMP(nj)
 * doubles. Nonzero when the function fails or M is not positive definite. */
#define GA_DYNAMICS_TMP(nj) (5 * (nj) + 3 + (nj) * (nj))
static inline int ga_dynamics_row(ga_fn id, const ga_work *w, int nj, const double *q, const double *qd,
                                  const double *qdd, const double *p, double *F, double *M, double *Minv,
                                  double *D, double *tmp)
{
    double *zero = tmp, *unit = tmp + nj, *base = tmp + 2 * nj, *f = tmp + 3 * nj, *L = tmp + 3 * nj + 3;
    double *plus = L + nj * nj, *minus = plus + nj;
    int i, l, k;
    for (i = 0; i < nj; ++i) zero[i] = unit[i] = 0.0;
    f[0] = f[1] = f[2] = 0.0;
    w->arg[0] = q, w->arg[1] = qd, w->arg[2] = qdd, w->arg[3] = f, w->arg[4] = p;
    w->res[0] = F;
    if (id(w->arg, w->res, w->iw, w->w, 0)) return 1;
    w->arg[1] = zero, w->arg[2] = zero;
    w->res[0] = base;
    if (id(w->arg, w->res, w->iw, w->w, 0)) return 1;
    w->arg[2] = unit;
    for (l = 0; l < nj; ++l) { /* column l into row l of Minv (M is symmetric), then M */
        unit[l] = 1.0;
        w->res[0] = Minv + l * nj;
        if (id(w->arg, w->res, w->iw, w->w, 0)) return 1;
        unit[l] = 0.0;
        for (i = 0; i < nj; ++i) M[i * nj + l] = Minv[l * nj + i] - base[i];
    }
    w->arg[1] = unit, w->arg[2] = qdd;
    for (l = 0; l < nj; ++l) { /* column l of D */
        for (i = 0; i < nj; ++i) unit[i] = qd[i];
        unit[l] = qd[l] + 1.0;
        w->res[0] = plus;
        if (id(w->arg, w->res, w->iw, w->w, 0)) return 1;
        unit[l] = qd[l] - 1.0;
        w->res[0] = minus;
        if (id(w->arg, w->res, w->iw, w->w, 0)) return 1;
        for (i = 0; i < nj; ++i) D[i * nj + l] = 0.5 * (plus[i] - minus[i]);
    }
    for (l = 0; l < nj; ++l) /* M = L L^T */
        for (i = l; i < nj; ++i) {
            double v = 0.5 * (M[i * nj + l] + M[l * nj + i]);
            for (k = 0; k < l; ++k) v -= L[i * nj + k] * L[l * nj + k];
            if (i == l) {
                if (!(v > 0.0)) return 1;
                L[l * nj + l] = sqrt(v);
            } else {
                L[i * nj + l] = v / L[l * nj + l];
            }
        }
    for (l = 0; l < nj; ++l) { /* column l of M^-1: L y = e_l, L^T x = y */
        double *x = base;
        for (i = 0; i < nj; ++i) {
            double v = i == l ? 1.0 : 0.0;
            for (k = 0; k < i; ++k) v -= L[i * nj + k] * x[k];
            x[i] = v / L[i * nj + i];
        }
        for (i = nj - 1; i >= 0; --i) {
            double v = x[i];
            for (k = i + 1; k < nj; ++k) v -= L[k * nj + i] * x[k];
            x[i] = v / L[i * nj + i];
        }
        for (i = 0; i < nj; ++i) Minv[i * nj + l] = x[i];
    }
    return 0;
}

/* The window's terms in single precision from its rows (J_d, tip_offset, H_d, the reference).
 * The tip map is exact in the joints that do not move the tip (the twist of the paper's robot,
 * whose axis holds the tip): their errors do not count for the trust region. */
static inline void ga_window_terms(ga_window *x)
{
    const int nj = x->nj, nn = nj * nj;
    const long rows = x->horizon + 1;
    long i, j;
    int k, l, m;
    memset(x->row_used, 0, (size_t)(3 * nj));
    for (k = 0; k < nj; ++k) x->moves[k] = 0;
    for (i = 0; i < rows * 3 * nj; ++i) x->jac_f[i] = (float)x->J_d[i];
    for (i = 0; i < rows * 3; ++i) x->off_f[i] = (float)x->tip_offset[i];
    if (x->quadratic) {
        memset(x->coef, 0, sizeof(float) * (size_t)(x->horizon * 3 * nn));
        for (j = 1; j <= x->horizon; ++j)
            for (k = 0; k < 3; ++k)
                for (l = 0; l < nj; ++l)
                    for (m = l; m < nj; ++m) {
                        const double h = x->H_d[(j * 3 + k) * nn + l * nj + m];
                        x->coef[((j - 1) * 3 + k) * nn + l * nj + m] = (float)((l == m ? -0.5 : -1.0) * h);
                        x->row_used[k * nj + l] |= h != 0.0;
                        if (h != 0.0) x->moves[l] = x->moves[m] = -1;
                    }
    }
    for (i = 0; i < rows * 3 * nj; ++i)
        if (x->J_d[i] != 0.0) x->moves[i % nj] = -1;
    for (j = 0; j < x->horizon; ++j)
        for (l = 0; l < nj; ++l) {
            const long now = j * nj + l, next = (j + 1) * nj + l;
            x->r[now] = (float)(x->q_d[next] - x->q_d[now] - x->dt * x->qd_d[now]);
            x->s[now] = (float)(x->qd_d[next] - x->qd_d[now] - x->dt * x->qdd_d[now]);
        }
    if (!x->force_limit) return;
    for (l = 0; l < nj; ++l) {
        x->act_f[l] = (float)x->force_limit[l];
        x->act_f[nj + l] = (float)(1.0 / x->speed_limit[l]);
        x->act_f[2 * nj + l] = x->force_speed[l] != 0.0 ? 1.0f : 0.0f;
    }
    for (i = 0; i < x->horizon * nj; ++i) x->force_f[i] = (float)x->F_d[i];
    for (i = 0; i < x->horizon * nn; ++i) {
        x->mass_f[i] = (float)x->M_d[i];
        x->minv_f[i] = (float)x->Minv_d[i];
        x->damp_f[i] = (float)-x->D_d[i];
    }
}

/* What the prediction of one block writes (one per thread). */
typedef struct {
    float (*K)[GA_LANES];        /* (2 nj^2) the block's gains, gene-major, one lane per candidate  */
    double (*sym)[GA_LANES];     /* (nj^2) the safe variant: sym(Kp) of each lane                   */
    double (*shifted)[GA_LANES]; /* (nj^2) it shifted by an edge of the admitted interval, factorised */
    float *far;                  /* (LANES (H+1), nj) predicted joint errors of steps outside the region */
    long *far_at;                /* (LANES (H+1)) their lane * H + step                             */
    ga_work work;                /* of the model's tip                                              */
    long exact_candidates, exact_steps; /* work of the trust region's exact steps                  */
} ga_lanes;

/* ---- a block's gains ------------------------------------------------------------------------ */

/* The gains of the candidates rows[0 .. count) of 8-bit genes into K, decoded in single precision
 * as min(lo + code * step, hi), and hi for the top code: within a few float units in the last
 * place of the larger bound from ga_decode's value (tested), far below what the single-precision
 * prediction resolves, and with no table look-ups. Lanes past count get code 0. */
static inline void ga_gains_from_bytes_lanes(const ga_window *x, int count, const uint64_t *const *rows,
                                             float (*K)[GA_LANES])
{
    int gi, c;
    for (gi = 0; gi < x->n_genes; ++gi)
        for (c = 0; c < GA_LANES; ++c) {
            const unsigned code = c < count ? ga_gene_byte(rows[c], gi) : 0u;
            float value = x->lo[gi] + (float)code * x->step[gi];
            value = value < x->hi[gi] ? value : x->hi[gi];
            K[gi][c] = code == 255u ? x->hi[gi] : value;
        }
}

#if VGT_GA_VECTORS
typedef float ga_lf __attribute__((vector_size(4 * GA_LANES)));    /* a quantity of the block */
typedef int32_t ga_li __attribute__((vector_size(4 * GA_LANES)));  /* a comparison of two     */
typedef uint64_t ga_lu __attribute__((vector_size(8 * GA_LANES))); /* a word of each candidate */

/* ga_gains_from_bytes_lanes with vectors: a word of each candidate is loaded once, its bytes
 * shifted out side by side (the same operations lane by lane). */
GA_INLINE void ga_gains_from_bytes(const ga_window *x, int count, const uint64_t *const *rows, float (*K)[GA_LANES])
{
    ga_li top;
    int w, g, c;
    for (c = 0; c < GA_LANES; ++c) top[c] = 255;
    for (w = 0; w * 8 < x->n_genes; ++w) {
        ga_lu word;
        for (c = 0; c < GA_LANES; ++c) word[c] = c < count ? rows[c][w] : 0u;
        for (g = 0; g < 8 && 8 * w + g < x->n_genes; ++g) {
            const int gi = 8 * w + g;
            const ga_li code = __builtin_convertvector((word >> (uint64_t)(56 - 8 * g)) & 0xFFu, ga_li);
            const ga_lf hi = x->hi[gi] - (ga_lf){0.0f};
            ga_lf value = (x->lo[gi] - (ga_lf){0.0f}) + __builtin_convertvector(code, ga_lf) * x->step[gi];
            ga_li pick = value < hi; /* -1 where value < hi */
            value = (ga_lf)(((ga_li)value & pick) | ((ga_li)hi & ~pick));
            pick = code == top;
            value = (ga_lf)(((ga_li)hi & pick) | ((ga_li)value & ~pick));
            memcpy(K[gi], &value, sizeof value);
        }
    }
}
#else
#define ga_gains_from_bytes ga_gains_from_bytes_lanes
#endif

/* ---- the safe variant on a block ------------------------------------------------------------ */

/* positive_definite on the LANES matrices A (nj x nj, one lane each) at once: ok[c] stays 1 only
 * if every pivot of lane c is positive. A lane's numbers are ga_positive_definite's on it, in the
 * same order (so the same test, bit for bit: no contraction, a correctly rounded sqrt and
 * division); a lane that failed goes on with pivot 1 (its numbers are no longer used, and nothing
 * divides by zero). Stops when no lane is left. */
GA_INLINE void ga_lanes_cholesky(int nj, double (*A)[GA_LANES], int *ok)
{
    int i, j, k, c, any;
    for (j = 0; j < nj; ++j) {
        double d[GA_LANES];
        for (c = 0; c < GA_LANES; ++c) d[c] = A[j * nj + j][c];
        for (k = 0; k < j; ++k)
            for (c = 0; c < GA_LANES; ++c) d[c] -= A[j * nj + k][c] * A[j * nj + k][c];
        any = 0;
        for (c = 0; c < GA_LANES; ++c) {
            ok[c] &= d[c] > 0.0;
            d[c] = sqrt(ok[c] ? d[c] : 1.0);
            A[j * nj + j][c] = d[c];
            any |= ok[c];
        }
        if (!any) return;
        for (i = j + 1; i < nj; ++i) {
            double v[GA_LANES];
            for (c = 0; c < GA_LANES; ++c) v[c] = A[i * nj + j][c];
            for (k = 0; k < j; ++k)
                for (c = 0; c < GA_LANES; ++c) v[c] -= A[i * nj + k][c] * A[j * nj + k][c];
            for (c = 0; c < GA_LANES; ++c) A[i * nj + j][c] = v[c] / d[c];
        }
    }
}

/* How far inside Gershgorin's bound a shifted matrix must be, relative to its largest diagonal
 * entry, for its factorisation to be skipped: its smallest eigenvalue relative to the largest
 * diagonal entry is then above 1e-8, and a Cholesky factorisation in double precision runs to the
 * end (its pivots stay positive) once that ratio exceeds n gamma_{n+1} / (1 - n gamma_{n+1}),
 * about n^2 1.1e-16 (Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed., Thm 10.7):
 * below 1e-8 for every n up to several thousand joints, with room for the rounding of the bound
 * itself. So the skip gives ga_positive_definite's answer exactly. */
#define GA_GERSHGORIN_MARGIN 1e-8

/* Each lane's damping, admitted interval and Gershgorin bounds during ga_safe_repair. */
typedef struct {
    double kv0[GA_LANES], lo[GA_LANES], hi[GA_LANES], gmin[GA_LANES], gmax[GA_LANES];
    double below_min[GA_LANES], below_max[GA_LANES], above_min[GA_LANES], above_max[GA_LANES];
    int ok[GA_LANES], diagonal[GA_LANES], need[GA_LANES];
} ga_safe_lanes;

/* Each lane's damping and admitted interval (its grid point when tuned), the bounds' start. */
GA_INLINE void ga_safe_lanes_start(const ga_safe *g, int nj, float (*K)[GA_LANES], ga_safe_lanes *s)
{
    const int nn = nj * nj;
    int i, c;
    for (c = 0; c < GA_LANES; ++c) {
        s->kv0[c] = g->kv;
        s->lo[c] = g->lo;
        s->hi[c] = g->hi;
        s->gmin[c] = s->below_min[c] = s->above_min[c] = INFINITY;
        s->gmax[c] = s->below_max[c] = s->above_max[c] = -INFINITY;
        s->diagonal[c] = 1;
    }
    if (g->nkv > 0)
        for (c = 0; c < GA_LANES; ++c) {
            double mean = 0.0;
            for (i = 0; i < nj; ++i) mean += (double)K[nn + i * nj + i][c];
            ga_safe_point(g, nj, mean, &s->kv0[c], &s->lo[c], &s->hi[c]);
        }
}

/* sym(Kp) of each lane, written back into K with Kv = kv0 I (the gains applied), sym(Kp) - lo I
 * into shifted, and the Gershgorin bounds of sym(Kp) and of both shifted matrices (fmin and fmax
 * as comparisons: the running bound is never NaN, and a NaN value leaves it, as fmin does). */
GA_INLINE void ga_safe_lanes_bounds(int nj, ga_lanes *sc, ga_safe_lanes *s)
{
    const int nn = nj * nj;
    float (*K)[GA_LANES] = sc->K;
    double(*sym)[GA_LANES] = sc->sym, (*shifted)[GA_LANES] = sc->shifted;
    double radius[GA_LANES];
    int i, l, c;
    for (i = 0; i < nj; ++i)
        for (l = i; l < nj; ++l)
            for (c = 0; c < GA_LANES; ++c) {
                const double v = 0.5 * ((double)K[i * nj + l][c] + (double)K[l * nj + i][c]);
                sym[i * nj + l][c] = v;
                sym[l * nj + i][c] = v;
            }
    for (i = 0; i < nj; ++i) {
        for (c = 0; c < GA_LANES; ++c) radius[c] = 0.0;
        for (l = 0; l < nj; ++l) {
            for (c = 0; c < GA_LANES; ++c) {
                K[i * nj + l][c] = (float)sym[i * nj + l][c];
                K[nn + i * nj + l][c] = (float)(i == l ? s->kv0[c] : 0.0);
                shifted[i * nj + l][c] = sym[i * nj + l][c] - (i == l ? s->lo[c] : 0.0);
            }
            if (l != i)
                for (c = 0; c < GA_LANES; ++c) radius[c] += fabs(sym[i * nj + l][c]);
        }
        for (c = 0; c < GA_LANES; ++c) {
            const double low = sym[i * nj + i][c] - radius[c], high = sym[i * nj + i][c] + radius[c];
            const double below = sym[i * nj + i][c] - s->lo[c], above = s->hi[c] - sym[i * nj + i][c];
            s->gmin[c] = low < s->gmin[c] ? low : s->gmin[c];
            s->gmax[c] = high > s->gmax[c] ? high : s->gmax[c];
            s->diagonal[c] &= below > 0.0 && above > 0.0;
            s->below_min[c] = below - radius[c] < s->below_min[c] ? below - radius[c] : s->below_min[c];
            s->below_max[c] = below > s->below_max[c] ? below : s->below_max[c];
            s->above_min[c] = above - radius[c] < s->above_min[c] ? above - radius[c] : s->above_min[c];
            s->above_max[c] = above > s->above_max[c] ? above : s->above_max[c];
        }
    }
}

/* ok[c]: sym(Kp) - lo I and hi I - sym(Kp) positive definite. A shifted matrix with a diagonal
 * entry <= 0 is not (its factorisation fails at that pivot at the latest: a pivot is the entry
 * minus squares), one well inside Gershgorin's bound is (GA_GERSHGORIN_MARGIN); only the lanes
 * left between are factorised, side by side, and a factorisation runs only while a lane needs it. */
GA_INLINE void ga_safe_lanes_admit(int nj, ga_lanes *sc, ga_safe_lanes *s)
{
    int i, l, c, any = 0;
    for (c = 0; c < GA_LANES; ++c) { /* sym(Kp) - lo I */
        s->ok[c] = s->lo[c] < s->hi[c] && s->diagonal[c];
        s->need[c] = s->ok[c] && !(s->below_min[c] > GA_GERSHGORIN_MARGIN * s->below_max[c]);
        any |= s->need[c];
    }
    if (any) {
        ga_lanes_cholesky(nj, sc->shifted, s->need);
        for (c = 0; c < GA_LANES; ++c)
            s->ok[c] &= (s->below_min[c] > GA_GERSHGORIN_MARGIN * s->below_max[c]) || s->need[c];
    }
    any = 0;
    for (c = 0; c < GA_LANES; ++c) { /* hi I - sym(Kp) */
        s->need[c] = s->ok[c] && !(s->above_min[c] > GA_GERSHGORIN_MARGIN * s->above_max[c]);
        any |= s->need[c];
    }
    if (any) {
        for (i = 0; i < nj; ++i)
            for (l = 0; l < nj; ++l)
                for (c = 0; c < GA_LANES; ++c)
                    sc->shifted[i * nj + l][c] = (i == l ? s->hi[c] : 0.0) - sc->sym[i * nj + l][c];
        ga_lanes_cholesky(nj, sc->shifted, s->need);
        for (c = 0; c < GA_LANES; ++c)
            s->ok[c] &= (s->above_min[c] > GA_GERSHGORIN_MARGIN * s->above_max[c]) || s->need[c];
    }
}

/* ga_safe_admit on every lane of the block's gains sc->K, the repaired gains written back (so the
 * prediction is that of the gains that would be applied), penalty[c] set (lanes past the block's
 * candidates too: they are not read); penalty 0 for every lane unless g->on. The same arithmetic
 * as ga_safe_admit lane by lane, and the same answers with less work (ga_safe_lanes_admit). */
GA_INLINE void ga_safe_repair(const ga_safe *g, int nj, ga_lanes *sc, double *penalty)
{
    ga_safe_lanes s;
    int c;
    if (!g->on) {
        for (c = 0; c < GA_LANES; ++c) penalty[c] = 0.0;
        return;
    }
    ga_safe_lanes_start(g, nj, sc->K, &s);
    ga_safe_lanes_bounds(nj, sc, &s);
    ga_safe_lanes_admit(nj, sc, &s);
    for (c = 0; c < GA_LANES; ++c) {
        const double scale = s.hi[c] - s.lo[c];
        if (!(s.lo[c] < s.hi[c])) penalty[c] = 3.0;
        else if (s.ok[c]) penalty[c] = 0.0;
        else
            penalty[c] = 1.0 + fmin(1.0, fmax(0.0, s.lo[c] - s.gmin[c]) / scale)
                         + fmin(1.0, fmax(0.0, s.gmax[c] - s.hi[c]) / scale) + 1e-9;
    }
}

/* ---- the prediction's kernel ---------------------------------------------------------------- */

/* Operations on the quantities of a block (ga_lf): one vector operation each, or a loop over the
 * lanes. Statements, not functions: a vector passed to or returned from a function is an ABI
 * question (GCC notes it in builds without AVX). */
#define GA_FMA(fused, a, b, c) ((fused) ? fmaf((a), (b), (c)) : (a) * (b) + (c))
#define LF_LANE(v, c) ((v)[c])
#if VGT_GA_VECTORS
/* every lane v, -0 as +0 (zero plus v: a vector GCC keeps, where it rebuilds the splat of a bare
 * scalar lane by lane at each use in a lane loop; only squares and sums are taken of the block's
 * values, so the sign of a zero never shows in a cost) */
#define GA_SPLAT(v) ((ga_lf){0.0f} + (float)(v))
#define LF_SET(r, v) ((r) = GA_SPLAT(v))
#define LF_LOAD(r, src) memcpy(&(r), (src), sizeof(r)) /* LANES floats, any alignment */
#define LF_MUL(r, a, b) ((r) = (a) * (b))
#define LF_MUL_S(r, v, b) ((r) = (float)(v) * (b))
#define LF_ADD(r, a, b) ((r) = (a) + (b))
#define LF_ADD_S(r, v) ((r) = (r) + (float)(v))
/* r = a b + r, fused lane by lane when `fused` (both compilers make that one vector instruction
 * when the target has one) */
#define LF_FMA(r, a, b, fused)                                                                      \
    do {                                                                                            \
        if (fused) {                                                                                \
            const ga_lf a_ = (a), b_ = (b);                                                         \
            ga_lf r_ = (r);                                                                         \
            int c_;                                                                                 \
            for (c_ = 0; c_ < GA_LANES; ++c_) r_[c_] = fmaf(a_[c_], b_[c_], r_[c_]);                \
            (r) = r_;                                                                               \
        } else {                                                                                    \
            (r) = (a) * (b) + (r);                                                                  \
        }                                                                                           \
    } while (0)
/* r = v b + r with a scalar v (from memory: a broadcast operand) */
#define LF_FMA_S(r, v, b, fused)                                                                    \
    do {                                                                                            \
        if (fused) {                                                                                \
            const float v_ = (v);                                                                   \
            const ga_lf b_ = (b);                                                                   \
            ga_lf r_ = (r);                                                                         \
            int c_;                                                                                 \
            for (c_ = 0; c_ < GA_LANES; ++c_) r_[c_] = fmaf(v_, b_[c_], r_[c_]);                    \
            (r) = r_;                                                                               \
        } else {                                                                                    \
            (r) = (float)(v) * (b) + (r);                                                           \
        }                                                                                           \
    } while (0)
#define LF_COPY(r, a) ((r) = (a))
typedef ga_li ga_lm; /* a lane mask */
/* outside: norm2 > limit lane by lane (a NaN error stays inside) */
#define LF_OUTSIDE(outside, norm2, limit) ((outside) = (norm2) > GA_SPLAT(limit))
/* total += square where not outside */
#define LF_ADD_INSIDE(total, square, outside) ((total) = (total) + (ga_lf)((ga_li)(square) & ~(outside)))
/* r += a in every lane where the scalar mask m is -1, r += 0 where it is 0: a bitwise and with the
 * mask, never a branch on it. GCC 12.2 at -O3 for x86-64-v4 compiled `if (m) { a = E * E; r += a; }`
 * in the loop over a joint count known at run time into a multiply under an AVX-512 mask register
 * loaded with the condition's 0/1, i.e. lane 0 only: the other lanes' steps all fell inside the
 * trust region, and the recursive model's library (built -O3) left the symbolic one's (-O2) runs. */
#define LF_ADD_MASKED(r, a, m) ((r) = (r) + (ga_lf)((ga_li)(a) & (int32_t)(m)))
#define LF_SUB(r, a, b) ((r) = (a) - (b))
/* r = b where a < b (LF_MAX) or b < a (LF_MIN), else a: a select, so a NaN in a stays */
#define LF_SELECT_(r, a, b, below)                                                                  \
    do {                                                                                            \
        const ga_li m_ = (ga_li)(below);                                                            \
        (r) = (ga_lf)(((ga_li)(a) & ~m_) | ((ga_li)(b) & m_));                                      \
    } while (0)
#define LF_MAX(r, a, b) LF_SELECT_(r, a, b, (a) < (b))
#define LF_MIN(r, a, b) LF_SELECT_(r, a, b, (b) < (a))
#else
typedef float ga_lf[GA_LANES];
#define GA_EACH(body)                                                                               \
    do {                                                                                            \
        int c_;                                                                                     \
        for (c_ = 0; c_ < GA_LANES; ++c_) body;                                                     \
    } while (0)
#define LF_SET(r, v) GA_EACH((r)[c_] = (float)(v))
#define LF_LOAD(r, src) memcpy((r), (src), sizeof(r))
#define LF_MUL(r, a, b) GA_EACH((r)[c_] = (a)[c_] * (b)[c_])
#define LF_MUL_S(r, v, b) GA_EACH((r)[c_] = (v) * (b)[c_])
#define LF_ADD(r, a, b) GA_EACH((r)[c_] = (a)[c_] + (b)[c_])
#define LF_ADD_S(r, v) GA_EACH((r)[c_] += (v))
#define LF_FMA(r, a, b, fused) GA_EACH((r)[c_] = GA_FMA(fused, (a)[c_], (b)[c_], (r)[c_]))
#define LF_FMA_S(r, v, b, fused) GA_EACH((r)[c_] = GA_FMA(fused, (v), (b)[c_], (r)[c_]))
#define LF_COPY(r, a) memcpy((r), (a), sizeof(r))
typedef int ga_lm[GA_LANES];
#define LF_OUTSIDE(outside, norm2, limit) GA_EACH((outside)[c_] = (norm2)[c_] > (limit))
#define LF_ADD_INSIDE(total, square, outside) GA_EACH((total)[c_] += (outside)[c_] ? 0.0f : (square)[c_])
#define LF_ADD_MASKED(r, a, m) GA_EACH((r)[c_] += (m) ? (a)[c_] : 0.0f)
#define LF_SUB(r, a, b) GA_EACH((r)[c_] = (a)[c_] - (b)[c_])
#define LF_MAX(r, a, b) GA_EACH((r)[c_] = (a)[c_] < (b)[c_] ? (b)[c_] : (a)[c_])
#define LF_MIN(r, a, b) GA_EACH((r)[c_] = (b)[c_] < (a)[c_] ? (b)[c_] : (a)[c_])
#endif
/* any |= a lane of v is not zero (a statement: see above) */
#define LF_ANY_NONZERO(any, v)                                                                      \
    do {                                                                                            \
        int c_;                                                                                     \
        for (c_ = 0; c_ < GA_LANES; ++c_) (any) |= (v)[c_] != 0.0f;                                 \
    } while (0)

/* a = Kp E + Kv Ed: each row's first product fused with its second (as GCC contracts a*b + c*d
 * into fma(a, b, c*d)), then one multiply-add per column. */
GA_INLINE void ga_kernel_accel(float (*K)[GA_LANES], const int nj, const int fused, ga_lf *E, ga_lf *Ed, ga_lf *a)
{
    const int nn = nj * nj;
    int i, l;
    GA_UNROLL for (i = 0; i < nj; ++i) {
        const int ip = i * nj, iv = nn + i * nj;
        ga_lf p0, v0, kp, kv;
        if (nj == 1) {
            LF_LOAD(kp, K[ip]);
            LF_LOAD(kv, K[iv]);
            LF_MUL(p0, kp, E[0]);
            LF_MUL(v0, kv, Ed[0]);
        } else {
            LF_LOAD(kp, K[ip + 1]);
            LF_LOAD(kv, K[iv + 1]);
            LF_MUL(p0, kp, E[1]);
            LF_MUL(v0, kv, Ed[1]);
            LF_LOAD(kp, K[ip]);
            LF_LOAD(kv, K[iv]);
            LF_FMA(p0, kp, E[0], fused);
            LF_FMA(v0, kv, Ed[0], fused);
        }
        GA_UNROLL for (l = 2; l < nj; ++l) {
            LF_LOAD(kp, K[ip + l]);
            LF_LOAD(kv, K[iv + l]);
            LF_FMA(p0, kp, E[l], fused);
            LF_FMA(v0, kv, Ed[l], fused);
        }
        LF_ADD(a[i], p0, v0);
    }
}

/* Step j of the recursion (E += dt Ed + r, Ed += -dt a + s) and the squared norm of the new
 * errors of the joints that move the tip (every square taken, then masked by moves[i]:
 * LF_ADD_MASKED says why not a branch). */
GA_INLINE void ga_kernel_step(const ga_window *x, long j, const int nj, const int fused, ga_lf *E, ga_lf *Ed,
                              ga_lf *a, ga_lf *norm2)
{
    const float dt = (float)x->dt;
    const float *r = x->r + j * nj, *s = x->s + j * nj;
    ga_lf square, step, back, sum;
    int i;
    LF_SET(step, dt);
    LF_SET(back, -dt);
    LF_SET(sum, 0.0f);
    GA_UNROLL for (i = 0; i < nj; ++i) {
        LF_FMA(E[i], step, Ed[i], fused);
        LF_ADD_S(E[i], r[i]);
        LF_FMA(Ed[i], back, a[i], fused);
        LF_ADD_S(Ed[i], s[i]);
        LF_MUL(square, E[i], E[i]);
        LF_ADD_MASKED(sum, square, x->moves[i]);
    }
    LF_COPY(*norm2, sum);
}

/* The tip error t of step j + 1: offset + J E (dense: with the joint count known at compile time
 * the errors stay in registers), then (quadratic) - E^T H E / 2 = sum_l E_l sum_{m >= l} coef[l][m]
 * E_m per axis, skipping the rows that are zero over the whole window. */
GA_INLINE void ga_kernel_tip(const ga_window *x, long j, const int nj, const int fused, ga_lf *E, ga_lf *t)
{
    const int nn = nj * nj;
    const float *J = x->jac_f + (j + 1) * 3 * nj, *off = x->off_f + (j + 1) * 3, *coef;
    int k, l, m;
    GA_UNROLL for (k = 0; k < 3; ++k) LF_SET(t[k], off[k]);
    GA_UNROLL for (l = 0; l < nj; ++l)
        GA_UNROLL for (k = 0; k < 3; ++k) LF_FMA_S(t[k], J[k * nj + l], E[l], fused);
    if (!x->quadratic) return;
    coef = x->coef + j * 3 * nn;
    GA_UNROLL for (k = 0; k < 3; ++k)
        GA_UNROLL for (l = 0; l < nj; ++l) {
            const float *cf = coef + k * nn + l * nj;
            ga_lf u;
            if (!x->row_used[k * nj + l]) continue;
            if (l + 1 < nj) {
                LF_MUL_S(u, cf[l + 1], E[l + 1]);
                LF_FMA_S(u, cf[l], E[l], fused);
            } else {
                LF_MUL_S(u, cf[l], E[l]);
            }
            GA_UNROLL for (m = l + 2; m < nj; ++m) LF_FMA_S(u, cf[m], E[m], fused);
            LF_FMA(t[k], u, E[l], fused);
        }
}

/* The actuators in the prediction (x->force_limit): the controller's effort for the acceleration
 * a, linearised about the reference, F = F_d + M_d a - D_d Ed (D = dID/dqd: friction and Coriolis
 * at the predicted velocity qd_d - Ed; without it a saturated prediction, which drifts from the
 * reference, is off by tens of per cent), clipped as the controller and the plant's motors would
 * clip it at that velocity (vgt_clip, then vgt_saturate's force-speed lines: together the bounds
 * of vgt_saturate, which lie within the peak forces), and the acceleration the clipped effort
 * gives, a + M_d^-1 (clip(F) - F): under computed force control the model's own effort cancels,
 * so only the clipped part changes the error dynamics. A block none of whose efforts is clipped
 * keeps a as it is (the prediction without actuators, bit for bit). */
GA_INLINE void ga_kernel_saturate(const ga_window *x, long j, const int nj, const int fused, ga_lf *Ed, ga_lf *a)
{
    const int nn = nj * nj;
    const float *M = x->mass_f + j * nn, *W = x->minv_f + j * nn, *Fd = x->force_f + j * nj;
    const float *B = x->damp_f + j * nn;
    const float *peak = x->act_f, *rate = x->act_f + nj, *line = x->act_f + 2 * nj;
    const double *qd_d = x->qd_d + j * nj;
    ga_lf delta[GA_NJ(nj)], F, v, lower, upper, t, one, clipped;
    int i, l, any = 0;
    LF_SET(one, 1.0f);
    for (i = 0; i < nj; ++i) {
        LF_SET(F, Fd[i]);
        for (l = 0; l < nj; ++l) LF_FMA_S(F, M[i * nj + l], a[l], fused);
        for (l = 0; l < nj; ++l) LF_FMA_S(F, B[i * nj + l], Ed[l], fused);
        LF_SET(lower, -peak[i]);
        LF_SET(upper, peak[i]);
        if (line[i] != 0.0f) { /* upper = max(F_s min(1, 1 - r), -F_s), lower = min(-F_s min(1, 1 + r), F_s) */
            LF_SET(v, (float)qd_d[i]);
            LF_SUB(v, v, Ed[i]);
            LF_MUL_S(v, rate[i], v);
            LF_SUB(t, one, v);
            LF_MIN(t, t, one);
            LF_MUL_S(t, peak[i], t);
            LF_MAX(upper, t, lower);
            LF_ADD(t, one, v);
            LF_MIN(t, t, one);
            LF_MUL_S(t, -peak[i], t);
            LF_SET(clipped, peak[i]);
            LF_MIN(lower, t, clipped);
        }
        LF_MAX(clipped, F, lower);
        LF_MIN(clipped, clipped, upper);
        LF_SUB(delta[i], clipped, F);
        LF_ANY_NONZERO(any, delta[i]);
    }
    if (!any) return;
    for (i = 0; i < nj; ++i)
        for (l = 0; l < nj; ++l) LF_FMA_S(a[i], W[i * nj + l], delta[l], fused);
}

/* The squared tip error of step j + 1 into total where the joint error is inside the trust region;
 * the steps outside are recorded for the exact forward kinematics (sc->far, sc->far_at). */
GA_INLINE void ga_kernel_sum(const ga_window *x, ga_lanes *sc, long j, const int nj, const int fused, int count,
                             ga_lf *E, ga_lf *t, ga_lf *norm2, float limit, ga_lf *total, long *n_far)
{
    ga_lf square;
    ga_lm outside;
    int c, i, any = 0;
    LF_MUL(square, t[1], t[1]);
    LF_FMA(square, t[0], t[0], fused);
    LF_FMA(square, t[2], t[2], fused);
    LF_OUTSIDE(outside, *norm2, limit);
    LF_ADD_INSIDE(*total, square, outside);
    for (c = 0; c < GA_LANES; ++c) any |= LF_LANE(outside, c) != 0;
    if (!any) return;
    for (c = 0; c < count; ++c)
        if (LF_LANE(outside, c)) {
            const long f = (*n_far)++;
            sc->far_at[f] = (long)c * x->horizon + j;
            for (i = 0; i < nj; ++i) sc->far[f * nj + i] = LF_LANE(E[i], c);
        }
}

/* The predicted squared tip errors of the block's gains sc->K (count candidates) summed over the
 * steps inside the trust region into sum (LANES); the *n_far steps outside in sc->far, far_at. */
GA_INLINE void ga_kernel(const ga_window *x, ga_lanes *sc, const int nj, const int fused, int count, double *sum,
                         long *n_far)
{
    const float limit = x->exact_above2 > 0.0 ? (float)x->exact_above2 : INFINITY; /* none: infinite */
    ga_lf E[GA_NJ(nj)], Ed[GA_NJ(nj)], a[GA_NJ(nj)], t[3], norm2, total;
    long j;
    int i, c;
    GA_UNROLL for (i = 0; i < nj; ++i) {
        LF_SET(E[i], (float)(x->q_d[i] - x->q0[i]));
        LF_SET(Ed[i], (float)(x->qd_d[i] - x->qd0[i]));
    }
    LF_SET(total, 0.0f);
    *n_far = 0;
    for (j = 0; j < x->horizon; ++j) {
        ga_kernel_accel(sc->K, nj, fused, E, Ed, a);
        if (x->force_limit) ga_kernel_saturate(x, j, nj, fused, Ed, a);
        ga_kernel_step(x, j, nj, fused, E, Ed, a, &norm2);
        ga_kernel_tip(x, j, nj, fused, E, t);
        ga_kernel_sum(x, sc, j, nj, fused, count, E, t, &norm2, limit, &total, n_far);
    }
    for (c = 0; c < GA_LANES; ++c) sum[c] = (double)LF_LANE(total, c);
}

/* The costs of the block's count candidates into cost: the steps outside the trust region (n_far)
 * mapped by the exact forward kinematics of the predicted joints and added to their lanes' sums,
 * the root of each sum, and the safe variant's penalties. Nonzero when the model's tip fails. */
static inline int ga_block_costs(const ga_window *x, ga_lanes *sc, int count, long n_far, double *sum,
                                 const double *penalty, double *cost)
{
    const int nj = x->nj;
    const ga_work *w = &sc->work;
    int seen[GA_LANES] = {0}, i, k;
    long f;
    for (f = 0; f < n_far; ++f) {
        const long lane = sc->far_at[f] / x->horizon, j = sc->far_at[f] % x->horizon;
        const double *td = x->tip_d + 3 * (j + 1);
        double q[GA_NJ(nj)], tip[3], d0, d1, d2;
        for (i = 0; i < nj; ++i) q[i] = x->q_d[(j + 1) * nj + i] - (double)sc->far[f * nj + i];
        w->arg[0] = q;
        w->arg[1] = x->p;
        w->res[0] = tip;
        if (x->tip(w->arg, w->res, w->iw, w->w, 0)) return 1;
        d0 = td[0] - tip[0];
        d1 = td[1] - tip[1];
        d2 = td[2] - tip[2];
        sum[lane] += d0 * d0 + d1 * d1 + d2 * d2;
        sc->exact_steps++;
        if (!seen[lane]) sc->exact_candidates++;
        seen[lane] = 1;
    }
    for (k = 0; k < count; ++k) {
        cost[k] = isfinite(sum[k]) ? sqrt(sum[k]) : INFINITY;
        if (x->safe.on && penalty[k] > 0.0) cost[k] = penalty[k];
    }
    return 0;
}

/* ---- the activation ------------------------------------------------------------------------- */

/* The costs of the n candidates rows[0 .. n) (bit strings) into cost; nonzero on a failure, which
 * ends the activation with that status. */
typedef int (*ga_predict_fn)(void *context, long n, const uint64_t *const *rows, double *cost);

/* One activation's settings, its population and work (P = population, W = words) and results. */
typedef struct {
    int n_genes, n_bits, words, population, generations, elite, n_seeded;
    double p_crossover, p_mutation;
    long max_flips;                    /* most flips of a generation (ga_max_flips)             */
    const double *lower, *upper;       /* (n_genes) gene bounds                                 */
    const uint64_t *initial_bits;      /* (n_seeded, W) seeded individuals                      */
    const uint64_t *valid;             /* (W) the bits of an individual (ga_valid_bits)         */
    const double *weights;             /* (P) rank weights (ga_rank_weights)                    */
    uint64_t *pop, *next, *best_bits;  /* (P, W), (P, W), (W)                                   */
    double *cost, *next_cost, *new_cost, *expectation, *parent_cost; /* (P) each              */
    double *work;                      /* (2 P + LANES)                                         */
    long *order, *pool, *fresh;        /* (P) each                                              */
    long *flips;                       /* (max_flips + 1)                                       */
    const uint64_t **rows;             /* (P) the candidates of a prediction                    */
    ga_keyed *merge;                   /* (2 P) or NULL: see ga_stable_order                    */
    ga_predict_fn predict;
    void *context;
    double best_cost, seeded_cost;     /* out: the best individual's cost (best_bits), the first */
    long evaluations;                  /* seeded one's (or NaN); the candidates predicted       */
} ga_population;

static inline long ga_argmin_first(long n, const double *cost)
{
    long best = 0, i;
    for (i = 1; i < n; ++i)
        if (ga_clean_cost(cost[i]) < ga_clean_cost(cost[best])) best = i;
    return best;
}

/* The first population, the seeded rows then random bits, and its costs. */
GA_INLINE int ga_first_generation(ga_population *p, ga_rng *rng)
{
    const int W = p->words, P = p->population;
    long best;
    int k, w, status;
    for (k = 0; k < P; ++k) {
        uint64_t *row = p->pop + (long)k * W;
        if (k < p->n_seeded) {
            memcpy(row, p->initial_bits + (long)k * W, sizeof(uint64_t) * (size_t)W);
            for (w = 0; w < W; ++w) row[w] &= p->valid[w];
        } else {
            for (w = 0; w < W; ++w) row[w] = p->valid[w] ? ga_rng_next(rng) & p->valid[w] : 0;
        }
    }
    for (k = 0; k < P; ++k) p->rows[k] = p->pop + (long)k * W;
    if ((status = p->predict(p->context, P, p->rows, p->cost)) != 0) return status;
    for (k = 0; k < P; ++k) p->cost[k] = ga_clean_cost(p->cost[k]);
    p->evaluations = P;
    p->seeded_cost = p->n_seeded > 0 ? p->cost[0] : NAN;
    best = ga_argmin_first(P, p->cost);
    p->best_cost = p->cost[best];
    memcpy(p->best_bits, p->pop + best * W, sizeof(uint64_t) * (size_t)W);
    return 0;
}

/* The children of a generation into next after its elite rows: rank scaling, SUS, shuffled pool,
 * uniform crossover of consecutive pairs, bit-flip mutation over every child's bits. */
GA_INLINE void ga_breed(ga_population *p, ga_rng *rng)
{
    const int W = p->words, P = p->population, C = P - p->elite;
    const long L = (long)p->n_genes * p->n_bits;
    uint64_t *children = p->next + (long)p->elite * W;
    long i, n_flips, f, child, child_start;
    int k, w;
    ga_rank_expectations(P, p->cost, C, p->expectation, p->order, p->weights, p->work, p->work + P, p->merge);
    ga_sus(P, p->expectation, C, ga_rng_uniform(rng), p->pool, p->work);
    for (i = C - 1; i > 0; --i) {
        const long j = ga_rng_below(rng, i + 1), tmp = p->pool[i];
        p->pool[i] = p->pool[j];
        p->pool[j] = tmp;
    }
    for (k = 0; k < C; ++k) {
        memcpy(children + (long)k * W, p->pop + p->pool[k] * W, sizeof(uint64_t) * (size_t)W);
        p->parent_cost[k] = p->cost[p->pool[k]];
    }
    for (k = 0; k + 1 < C; k += 2) {
        uint64_t *a = children + (long)k * W, *b = a + W;
        if (!(ga_rng_uniform(rng) < p->p_crossover)) continue;
        for (w = 0; w < W; ++w) {
            const uint64_t swap = (a[w] ^ b[w]) & ga_rng_next(rng) & p->valid[w];
            a[w] ^= swap;
            b[w] ^= swap;
        }
    }
    n_flips = ga_mutation_positions(rng, (long)C * L, p->p_mutation, p->max_flips, p->flips);
    /* the positions ascend: follow the child they fall in instead of dividing each by L */
    for (f = 0, child = 0, child_start = 0; f < n_flips; ++f) {
        while (p->flips[f] >= child_start + L) {
            ++child;
            child_start += L;
        }
        ga_flip_bit(children + child * W, p->flips[f] - child_start);
    }
}

/* The children's costs into new_cost: a child equal to a parent keeps its cost; the others are
 * predicted. */
GA_INLINE int ga_children_costs(ga_population *p)
{
    const int W = p->words, C = p->population - p->elite;
    const uint64_t *children = p->next + (long)p->elite * W;
    long n_fresh = 0, f;
    int k, status;
    for (k = 0; k < C; ++k) {
        const int mate = (k ^ 1) < C ? (k ^ 1) : k;
        const uint64_t *row = children + (long)k * W;
        if (ga_same_bits(W, row, p->pop + p->pool[k] * W))
            p->new_cost[k] = p->parent_cost[k];
        else if (ga_same_bits(W, row, p->pop + p->pool[mate] * W))
            p->new_cost[k] = p->parent_cost[mate];
        else
            p->fresh[n_fresh++] = k;
    }
    if (!n_fresh) return 0;
    for (f = 0; f < n_fresh; ++f) p->rows[f] = children + p->fresh[f] * W;
    if ((status = p->predict(p->context, n_fresh, p->rows, p->work)) != 0) return status;
    for (f = 0; f < n_fresh; ++f) p->new_cost[p->fresh[f]] = ga_clean_cost(p->work[f]);
    p->evaluations += n_fresh;
    return 0;
}

/* Elitism: the best of the old population (`order` still sorts the old costs), then the
 * children, become the population; the best individual seen is kept. */
GA_INLINE void ga_next_generation(ga_population *p)
{
    const int W = p->words, E = p->elite, C = p->population - E;
    uint64_t *swap_bits;
    double *swap_cost;
    long index;
    int k;
    for (k = 0; k < E; ++k) {
        memcpy(p->next + (long)k * W, p->pop + p->order[k] * W, sizeof(uint64_t) * (size_t)W);
        p->next_cost[k] = p->cost[p->order[k]];
    }
    for (k = 0; k < C; ++k) p->next_cost[E + k] = p->new_cost[k];
    swap_bits = p->pop;
    p->pop = p->next;
    p->next = swap_bits;
    swap_cost = p->cost;
    p->cost = p->next_cost;
    p->next_cost = swap_cost;
    index = ga_argmin_first(p->population, p->cost);
    if (p->cost[index] < p->best_cost) {
        p->best_cost = p->cost[index];
        memcpy(p->best_bits, p->pop + index * W, sizeof(uint64_t) * (size_t)W);
    }
}

/* One activation from the generator's seed: the best individual in p->best_bits, its cost and the
 * work in p; 0, or the status of the prediction that failed. */
GA_INLINE int ga_evolve(ga_population *p, uint64_t seed)
{
    ga_rng rng;
    int generation, status;
    ga_rng_seed(&rng, seed);
    if ((status = ga_first_generation(p, &rng)) != 0) return status;
    for (generation = 1; generation <= p->generations; ++generation) {
        ga_breed(p, &rng);
        if ((status = ga_children_costs(p)) != 0) return status;
        ga_next_generation(p);
    }
    return 0;
}

/* The activation's gains (genes: Kp then Kv, row by row) from its best individual. The safe
 * variant applies the repaired gains, admitted again in double precision; a set that is not
 * admitted, or not predicted to lower the error below the fixed gains' from the same measured
 * state, is dropped for the fixed gains (the first seeded row), p->best_cost then theirs. Returns
 * whether it was dropped. */
static inline int ga_result(ga_population *p, int nj, const ga_safe *safe, double *genes)
{
    ga_decode(p->n_genes, p->n_bits, p->best_bits, p->lower, p->upper, NULL, genes);
    if (!safe->on) return 0;
    if (ga_safe_admit(nj, safe, genes, genes + nj * nj) == 0.0 && p->best_cost < p->seeded_cost) return 0;
    ga_decode(p->n_genes, p->n_bits, p->initial_bits, p->lower, p->upper, NULL, genes);
    p->best_cost = p->seeded_cost;
    return 1;
}

#endif
