/* The genetic algorithm of the switching control method, compiled (part of vgtarm).
 *
 * One call runs a whole GA activation: the paper's binary-coded algorithm (Appendix B) with the
 * same operators, in the same order, as the readable NumPy reference vgtarm/ga.py:
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
 * Jacobian and Hessian at the reference. The candidates are evaluated in blocks laid out
 * candidate-last, so the compiler vectorises across candidates.
 */
#include <math.h>
#include <stdint.h>
#include <time.h>
#include <stdlib.h>
#include <string.h>

#include "vgtarm.h"
#ifdef _OPENMP
#include <omp.h>
#endif

/* ---- generator ------------------------------------------------------------------------------ */

typedef struct {
    uint64_t s[4];
} rng_t;

static uint64_t splitmix64(uint64_t *x)
{
    uint64_t z = (*x += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

static void rng_seed(rng_t *r, uint64_t seed)
{
    for (int i = 0; i < 4; ++i) r->s[i] = splitmix64(&seed);
}

static inline uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

static uint64_t rng_next(rng_t *r)
{
    uint64_t *s = r->s;
    const uint64_t result = rotl(s[1] * 5, 7) * 9;
    const uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

/* Uniform on [0, 1) with 53 random bits. */
static double rng_uniform(rng_t *r) { return (double)(rng_next(r) >> 11) * 0x1.0p-53; }

/* Uniform integer in [0, n) (Lemire's multiply-shift with rejection: exactly uniform). */
static long rng_below(rng_t *r, long n)
{
    uint64_t bound = (uint64_t)n;
    __uint128_t product = (__uint128_t)rng_next(r) * bound;
    uint64_t low = (uint64_t)product;
    if (low < bound) {
        uint64_t threshold = -bound % bound;
        while (low < threshold) {
            product = (__uint128_t)rng_next(r) * bound;
            low = (uint64_t)product;
        }
    }
    return (long)(product >> 64);
}

/* Positions of the flipped bits among `total` bits flipped independently with probability p:
 * geometric gaps between flips, the same distribution as a draw per bit at a cost per flip. */
static long mutation_positions(rng_t *r, long total, double p, long max_flips, long *positions)
{
    long n = 0;
    if (!(p > 0.0) || total <= 0) return 0;
    if (p >= 1.0) {
        for (long i = 0; i < total && n < max_flips; ++i) positions[n++] = i;
        return n;
    }
    const double log_q = log1p(-p);
    long position = -1;
    while (n < max_flips) {
        double u = 1.0 - rng_uniform(r); /* (0, 1] */
        double gap = floor(log(u) / log_q);
        if (gap >= (double)(total - position - 1)) break;
        position += (long)gap + 1;
        positions[n++] = position;
    }
    return n;
}

void vgt_rng_uniform(uint64_t seed, long n, double *out)
{
    rng_t r;
    rng_seed(&r, seed);
    for (long i = 0; i < n; ++i) out[i] = rng_uniform(&r);
}

void vgt_rng_mutation_positions(uint64_t seed, long total, double p, long max_flips, long *positions,
                                long *n_flips)
{
    rng_t r;
    rng_seed(&r, seed);
    *n_flips = mutation_positions(&r, total, p, max_flips, positions);
}

/* ---- coding --------------------------------------------------------------------------------- */

static inline uint64_t gene_code(const uint64_t *w, long start, int n_bits)
{
    long i = start >> 6;
    int offset = (int)(start & 63);
    uint64_t x = w[i] << offset;
    if (offset) x |= w[i + 1] >> (64 - offset);
    return x >> (64 - n_bits);
}

/* decode_with for 8-bit genes, four genes per vector (the same arithmetic, element by element). */
typedef double v4 __attribute__((vector_size(32)));
typedef long long m4 __attribute__((vector_size(32)));

static inline __attribute__((always_inline)) v4 select4(m4 mask, v4 yes, v4 no) { return (v4)(((m4)yes & mask) | ((m4)no & ~mask)); }

__attribute__((target_clones("arch=x86-64-v3", "default"))) static void decode_bytes(int n_genes,
                                                                                   const uint64_t *restrict bits,
                                                                                   const double *restrict lower,
                                                                                   const double *restrict upper,
                                                                                   double *restrict genes)
{
    int i = 0;
    for (; i + 4 <= n_genes; i += 4) {
        uint64_t word = bits[i >> 3];
        int shift = 56 - 8 * (i & 7);
        v4 code = {(double)((word >> shift) & 0xFFu), (double)((word >> (shift - 8)) & 0xFFu),
                   (double)((word >> (shift - 16)) & 0xFFu), (double)((word >> (shift - 24)) & 0xFFu)};
        v4 lo, hi;
        memcpy(&lo, lower + i, sizeof lo);
        memcpy(&hi, upper + i, sizeof hi);
        v4 value = lo + code / 255.0 * (hi - lo);
        value = select4((m4)(value < hi), value, hi);
        value = select4((m4)(code == 255.0), hi, value);
        memcpy(genes + i, &value, sizeof value);
    }
    for (; i < n_genes; ++i) {
        double code = (double)((bits[i >> 3] >> (56 - 8 * (i & 7))) & 0xFFu);
        double value = lower[i] + code / 255.0 * (upper[i] - lower[i]);
        value = value < upper[i] ? value : upper[i];
        genes[i] = code == 255.0 ? upper[i] : value;
    }
}

/* The same arithmetic as ga._decode: lower + code / (2^b - 1) * (upper - lower), capped. With
 * `fractions` (code / (2^b - 1) for every code, b <= 16) the division is a table look-up. */
static void decode_with(const vgt_ga_settings *g, const uint64_t *bits, const double *lower, const double *upper,
                        const double *fractions, double *genes)
{
    const double top = (double)((1ULL << g->n_bits) - 1ULL);
    if (g->n_bits == 8 && fractions) { /* the paper's coding: one byte per gene, vectorised */
        decode_bytes(g->n_genes, bits, lower, upper, genes);
        return;
    }
    for (int i = 0; i < g->n_genes; ++i) {
        uint64_t code = gene_code(bits, (long)i * g->n_bits, g->n_bits);
        double fraction = fractions ? fractions[code] : (double)code / top;
        double value = lower[i] + fraction * (upper[i] - lower[i]);
        if (!(value < upper[i])) value = upper[i];
        if (fraction == 1.0) value = upper[i];
        genes[i] = value;
    }
}

static void decode_one(const vgt_ga_settings *g, const uint64_t *bits, const double *lower, const double *upper,
                       double *genes)
{
    decode_with(g, bits, lower, upper, NULL, genes);
}

void vgt_ga_decode(const vgt_ga_settings *g, long rows, const uint64_t *bits, const double *lower,
                   const double *upper, double *genes)
{
    for (long k = 0; k < rows; ++k) decode_one(g, bits + k * g->words, lower, upper, genes + k * g->n_genes);
}

static inline void flip_bit(uint64_t *w, long bit) { w[bit >> 6] ^= 1ULL << (63 - (bit & 63)); }

void vgt_ga_flip(int words, uint64_t *bits, long n_flips, const long *positions)
{
    (void)words;
    for (long i = 0; i < n_flips; ++i) flip_bit(bits, positions[i]);
}

/* ---- selection ------------------------------------------------------------------------------ */

/* NumPy's pairwise summation (numpy/core/src/umath/loops_utils.h), so sums agree bit for bit. */
static double pairwise_sum(const double *a, long n)
{
    if (n < 8) {
        double res = 0.0;
        for (long i = 0; i < n; ++i) res += a[i];
        return res;
    }
    if (n <= 128) {
        double r[8];
        for (int j = 0; j < 8; ++j) r[j] = a[j];
        long i;
        for (i = 8; i < n - (n % 8); i += 8)
            for (int j = 0; j < 8; ++j) r[j] += a[i + j];
        double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; ++i) res += a[i];
        return res;
    }
    long n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise_sum(a, n2) + pairwise_sum(a + n2, n - n2);
}

static inline double clean_cost(double c) { return isfinite(c) ? c : INFINITY; }

/* Indices of cost in ascending order, ties in index order, so the order is the same as any
 * stable sort's: ranks by counting for populations up to COUNTED (branch-free: a sort's
 * comparisons of random costs mispredict half the time), a bottom-up merge sort for larger ones. */
typedef struct {
    double cost;
    long index;
} keyed;

enum { COUNTED = 64 };

/* order[rank[i]] = i with rank[i] = #{j : c_j < c_i} + #{j < i : c_j == c_i}
 *                                  = #{j < i : c_j <= c_i} + #{j > i : c_j < c_i},
 * four costs per comparison (the block holding i compares index by index); the padding is NaN,
 * which compares false to everything. */
__attribute__((target_clones("arch=x86-64-v3", "default"))) static void order_by_counting(long n,
                                                                                        const double *cost,
                                                                                        long *order)
{
    v4 c[COUNTED / 4];
    double *flat = (double *)c;
    const long blocks = (n + 3) / 4;
    for (long i = 0; i < 4 * blocks; ++i) flat[i] = i < n ? clean_cost(cost[i]) : NAN;
    for (long i = 0; i < n; ++i) {
        const v4 ci = (v4){0.0} + flat[i];
        const m4 ii = (m4){0} + i;
        const long own = i / 4;
        const m4 j = (m4){0, 1, 2, 3} + 4 * own;
        m4 count = (c[own] < ci) | ((c[own] == ci) & (j < ii));
        for (long b = 0; b < own; ++b) count += c[b] <= ci;
        for (long b = own + 1; b < blocks; ++b) count += c[b] < ci;
        order[-(count[0] + count[1] + count[2] + count[3])] = i;
    }
}

static void stable_order(long n, const double *cost, long *order)
{
    if (n <= COUNTED) {
        order_by_counting(n, cost, order);
        return;
    }
    keyed *a = malloc(sizeof(keyed) * 2 * (size_t)n);
    if (!a) { /* no memory for the merge: an insertion sort in place */
        for (long i = 0; i < n; ++i) {
            long j = i;
            while (j > 0 && clean_cost(cost[order[j - 1]]) > clean_cost(cost[i])) {
                order[j] = order[j - 1];
                --j;
            }
            order[j] = i;
        }
        return;
    }
    keyed *b = a + n;
    for (long i = 0; i < n; ++i) a[i] = (keyed){clean_cost(cost[i]), i};
    for (long width = 1; width < n; width *= 2) {
        for (long lo = 0; lo < n; lo += 2 * width) {
            long mid = lo + width < n ? lo + width : n, hi = lo + 2 * width < n ? lo + 2 * width : n;
            long i = lo, j = mid, k = lo;
            while (i < mid && j < hi) b[k++] = a[j].cost < a[i].cost ? a[j++] : a[i++];
            while (i < mid) b[k++] = a[i++];
            while (j < hi) b[k++] = a[j++];
        }
        keyed *t = a;
        a = b;
        b = t;
    }
    for (long i = 0; i < n; ++i) order[i] = a[i].index;
    free(a < b ? a : b);
}

/* Rank weights 1/sqrt(r), r = 1..n. */
static void rank_weights(long n, double *weights)
{
    for (long r = 0; r < n; ++r) weights[r] = 1.0 / sqrt((double)(r + 1));
}

static void rank_expectations(long n, const double *cost, long n_parents, double *expectation, long *order,
                              const double *weights, double *shared)
{
    stable_order(n, cost, order);
    long start = 0;
    while (start < n) {
        long end = start + 1;
        while (end < n && clean_cost(cost[order[end]]) == clean_cost(cost[order[start]])) ++end;
        if (end - start == 1) { /* a cost of its own: its weight (the mean of one, exactly) */
            shared[start] = weights[start];
        } else {
            double mean = pairwise_sum(weights + start, end - start) / (double)(end - start);
            for (long r = start; r < end; ++r) shared[r] = mean;
        }
        start = end;
    }
    for (long r = 0; r < n; ++r) expectation[order[r]] = shared[r];
    double scale = (double)n_parents / pairwise_sum(expectation, n);
    for (long i = 0; i < n; ++i) expectation[i] *= scale;
}

void vgt_ga_rank_expectations(long n, const double *cost, long n_parents, double *expectation)
{
    long *order = malloc(sizeof(long) * (size_t)n);
    double *work = malloc(sizeof(double) * 2 * (size_t)n);
    if (order && work) {
        rank_weights(n, work);
        rank_expectations(n, cost, n_parents, expectation, order, work, work + n);
    }
    free(order);
    free(work);
}

/* Stochastic universal sampling with the pointer offset u in [0, 1): the same edges and
 * pointers as ga._sus (cumulative sum, rescaled, last edge pinned, searchsorted right). */
static void sus(long n, const double *expectation, long n_select, double u, long *selected, double *edges)
{
    double total = 0.0;
    for (long i = 0; i < n; ++i) {
        total = i ? edges[i - 1] + expectation[i] : expectation[i];
        edges[i] = total;
    }
    double scale = (double)n_select / edges[n - 1];
    for (long i = 0; i < n; ++i) edges[i] *= scale;
    edges[n - 1] = (double)n_select;
    long index = 0;
    for (long k = 0; k < n_select; ++k) {
        double pointer = u + (double)k;
        while (index < n && edges[index] <= pointer) ++index;
        selected[k] = index;
    }
}

void vgt_ga_sus(long n, const double *expectation, long n_select, double u, long *selected)
{
    double *edges = malloc(sizeof(double) * (size_t)n);
    if (edges) sus(n, expectation, n_select, u, selected, edges);
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

/* ---- prediction ----------------------------------------------------------------------------- */

enum { BLOCK = 8 }; /* candidates per vectorised block */
typedef float vf __attribute__((vector_size(32))); /* the BLOCK candidates of one quantity */
typedef int vi __attribute__((vector_size(32)));   /* a comparison of two vf */

typedef struct {
    int nj;
    long horizon;
    double dt;
    int quadratic;
    double exact_above2;   /* squared joint-error norm above which the exact prediction is used */
    const vgt_ga_problem *pb;
    float *r, *s;        /* (H, nj) reference residuals of the Euler steps                        */
    float *jac_f;        /* (H+1, 3, nj) tip Jacobian of the window                               */
    float *off_f;        /* (H+1, 3) tip offsets of the window                                    */
    float *coef;         /* (H, 3, nj, nj) -H[k][l][m] for m > l, -H/2 for m = l (0 below), per step  */
    unsigned char *row_used; /* (3, nj) row l of axis k has a nonzero coefficient somewhere in the window */
    int *moves;          /* (nj) -1 if joint i moves the tip somewhere in the window (a nonzero in its  */
                         /*   column of J or its row of H), else 0: only these count for the region   */
    float *lo, *step, *hi; /* 8-bit genes in the prediction: lo + code * step in single precision, at */
                           /*   most hi, hi for the top code (see gains_from_bytes)                    */
    int avx2;            /* the CPU has AVX2 (gains_from_bytes_avx2)                                 */
    int safe;            /* the safe variant (see safe_repair)                                       */
    double safe_kv, safe_lo, safe_hi;
    const vgt_ga_settings *g; /* the safe variant's damping grid (safe_nkv, safe_kv_step, tables)      */
    int threads;         /* threads that predict blocks of candidates (OpenMP), each with a scratch */
    int n_scratch;       /* scratches allocated (the threads asked for; `threads` may drop to 1)     */
    struct scratch *sc;  /* (n_scratch) */
} predictor;

/* What one thread of the prediction writes. */
typedef struct scratch {
    vf *K;               /* (2 nj^2) gains of the block, one lane per candidate                     */
    double (*sym)[BLOCK];     /* (nj^2) the safe variant: sym(Kp) of each lane (safe_repair)          */
    double (*shifted)[BLOCK]; /* (nj^2) it shifted by an edge of the admitted interval, factorised   */
    float *far;          /* (BLOCK H, nj) predicted joint errors of the steps outside the region     */
    long *far_at;        /* (BLOCK H) their lane * H + step                                         */
    const double **arg;  /* work arrays of the generated tip function                               */
    double **res;
    vgt_int *iw;
    double *w;
    long exact_candidates, exact_steps; /* work counters of the trust-region fallback              */
} scratch;

/* Predicted tip error of up to BLOCK candidates by the linear recursion (see the top). Every
 * quantity is a vector across the block's candidates (GCC/Clang vector extensions, so the
 * accumulators live in registers). The recursion runs in single precision, 8 candidates per
 * AVX2 register: the errors are about 1e-4 m and the gains at most about 1e4, so rounding moves
 * the fitness by about 1e-7 relative (measured in docs/control.md), far below what the GA's
 * ranking resolves; the sums of squares are completed in double. */

static inline __attribute__((always_inline)) void block_kernel(const predictor *restrict x, const int nj, int count,
                                                               const vf *restrict K, double *restrict sum,
                                                               float *restrict far, long *restrict far_at,
                                                               long *restrict n_far)
{
    const int nn = nj * nj;
    const float dt = (float)x->dt;
    const vgt_ga_problem *pb = x->pb;
    vf E[nj], Ed[nj], a[nj];
    const vf zero = {0.0f};
    /* no trust region: an infinite radius */
    const vf limit2 = zero + (x->exact_above2 > 0.0 ? (float)x->exact_above2 : INFINITY);
    vf total = zero;
    _Pragma("GCC unroll 16") for (int i = 0; i < nj; ++i) {
        E[i] = zero + (float)(pb->q_d[i] - pb->q0[i]);
        Ed[i] = zero + (float)(pb->qd_d[i] - pb->qd0[i]);
    }
    for (long j = 0; j < x->horizon; ++j) {
        /* a = Kp E + Kv Ed, two rows at a time with four independent sums (FMA latency) */
        int i = 0;
        _Pragma("GCC unroll 16") for (; i + 1 < nj; i += 2) {
            const vf *kp0 = K + i * nj, *kv0 = K + nn + i * nj, *kp1 = kp0 + nj, *kv1 = kv0 + nj;
            vf p0 = kp0[0] * E[0], v0 = kv0[0] * Ed[0], p1 = kp1[0] * E[0], v1 = kv1[0] * Ed[0];
            _Pragma("GCC unroll 16") for (int l = 1; l < nj; ++l) {
                p0 += kp0[l] * E[l];
                v0 += kv0[l] * Ed[l];
                p1 += kp1[l] * E[l];
                v1 += kv1[l] * Ed[l];
            }
            a[i] = p0 + v0;
            a[i + 1] = p1 + v1;
        }
        _Pragma("GCC unroll 16") for (; i < nj; ++i) {
            const vf *kp = K + i * nj, *kv = K + nn + i * nj;
            vf p0 = kp[0] * E[0], v0 = kv[0] * Ed[0];
            _Pragma("GCC unroll 16") for (int l = 1; l < nj; ++l) {
                p0 += kp[l] * E[l];
                v0 += kv[l] * Ed[l];
            }
            a[i] = p0 + v0;
        }
        const float *r = x->r + j * nj, *s = x->s + j * nj;
        vf norm2 = zero;
        _Pragma("GCC unroll 16") for (int i = 0; i < nj; ++i) {
            E[i] = E[i] + dt * Ed[i] + r[i];
            Ed[i] = Ed[i] - dt * a[i] + s[i];
            norm2 += (vf)((vi)(E[i] * E[i]) & x->moves[i]);
        }
        const float *J = x->jac_f + (j + 1) * 3 * nj, *off = x->off_f + (j + 1) * 3;
        vf t[3];
        _Pragma("GCC unroll 3") for (int k = 0; k < 3; ++k) t[k] = zero + off[k];
        /* first order: t_k += J[k][l] E_l (dense: with the joint count known at compile time the
         * errors stay in registers, which beats skipping the structural zeros through index lists) */
        _Pragma("GCC unroll 16") for (int l = 0; l < nj; ++l)
            _Pragma("GCC unroll 3") for (int k = 0; k < 3; ++k) t[k] += J[k * nj + l] * E[l];
        if (x->quadratic) {
            /* second order: t_k -= E^T H_k E / 2 = sum_l E_l sum_{m >= l} coef[k][l][m] E_m, skipping
             * the rows that are zero over the whole window (the same rows at every step) */
            const float *coef = x->coef + j * 3 * nn;
            _Pragma("GCC unroll 3") for (int k = 0; k < 3; ++k)
                _Pragma("GCC unroll 16") for (int l = 0; l < nj; ++l) {
                    if (!x->row_used[k * nj + l]) continue;
                    const float *c = coef + k * nn + l * nj;
                    vf u = c[l] * E[l];
                    _Pragma("GCC unroll 16") for (int m = l + 1; m < nj; ++m) u += c[m] * E[m];
                    t[k] += u * E[l];
                }
        }
        /* steps inside the trust region add their squared tip error; the others are recorded for
         * the exact forward kinematics (a NaN error stays inside and makes the cost infinite) */
        const vi outside = norm2 > limit2;
        total += (vf)((vi)(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]) & ~outside);
        int any = 0;
        _Pragma("GCC unroll 16") for (int c = 0; c < BLOCK; ++c) any |= outside[c];
        if (any)
            _Pragma("GCC unroll 16") for (int c = 0; c < count; ++c)
                if (outside[c]) {
                    long f = (*n_far)++;
                    far_at[f] = (long)c * x->horizon + j;
                    _Pragma("GCC unroll 16") for (int i = 0; i < nj; ++i) far[f * nj + i] = E[i][c];
                }
    }
    _Pragma("GCC unroll 16") for (int c = 0; c < BLOCK; ++c) sum[c] = (double)total[c];
}

/* The kernel with the joint count known at compile time for the common sizes (the loops unroll
 * and the gains stay in registers), and for any other count at run time. A clone for AVX-512
 * (x86-64-v4: 32 vector registers instead of 16, so fewer of the joints' vectors spill): 7 % off
 * the paper variant's activation on an AMD EPYC (docs/benchmarks.md); the same operations lane by
 * lane as the AVX2 clone (both fuse the same products), so the same bits (tested against the
 * export, and the paper's runs). */
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default"), optimize("fp-contract=fast"))) static void
predict_block(
    const predictor *restrict x, int count, const vf *restrict K, double *restrict sum, float *restrict far,
    long *restrict far_at, long *restrict n_far)
{
    switch (x->nj) {
    case 3: block_kernel(x, 3, count, K, sum, far, far_at, n_far); break;
    case 6: block_kernel(x, 6, count, K, sum, far, far_at, n_far); break;
    case 7: block_kernel(x, 7, count, K, sum, far, far_at, n_far); break;
    default: block_kernel(x, x->nj, count, K, sum, far, far_at, n_far); break;
    }
}

/* The gains of up to BLOCK candidates, as the kernel wants them: gene-major, one float per lane,
 * from decoded genes (row by row, rounded to float). */
static void gains_from_genes(int n_genes, int count, const double *genes, vf *K)
{
    const vf zero = {0.0f};
    for (int gi = 0; gi < n_genes; ++gi) K[gi] = zero;
    for (int c = 0; c < count; ++c)
        for (int gi = 0; gi < n_genes; ++gi) K[gi][c] = (float)genes[(long)c * n_genes + gi];
}

/* The same from the bit strings rows[0..count) of 8-bit genes (gene gi is byte gi of a string,
 * most significant first within each 64-bit word), decoded in single precision as
 * min(lo + code * step, hi), and hi for the top code: within a few float units in the last place
 * of the larger bound from ga._decode's value (tested), far below what the single-precision
 * prediction resolves, and with no table look-ups (gathering the values from tables cost as much
 * as the kernel). Lanes past count get code 0. */
static void gains_from_bytes_scalar(const predictor *x, int n_genes, int count, const uint64_t *const *rows, vf *K)
{
    for (int gi = 0; gi < n_genes; ++gi)
        for (int c = 0; c < BLOCK; ++c) {
            unsigned code = c < count ? (unsigned)((rows[c][gi >> 3] >> (56 - 8 * (gi & 7))) & 0xFFu) : 0u;
            float value = x->lo[gi] + (float)code * x->step[gi];
            value = value < x->hi[gi] ? value : x->hi[gi];
            K[gi][c] = code == 255u ? x->hi[gi] : value;
        }
}

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
/* gains_from_bytes_scalar's arithmetic (multiply, then add: no contraction), eight lanes at a
 * time: a word of every candidate is loaded once, and a byte shuffle spreads gene b's byte of the
 * eight words into eight 32-bit lanes. */
__attribute__((target("avx2"))) static void gains_from_bytes_avx2(const predictor *x, int n_genes, int count,
                                                                  const uint64_t *const *rows, vf *K)
{
    /* in each 128-bit half, byte k of its two words into the low bytes of 32-bit lanes 0, 1 (from
     * a) or 2, 3 (from b); -128 + k keeps the top bit set, which zeroes the byte */
    const __m256i pick_a = _mm256_setr_epi8(0, -128, -128, -128, 8, -128, -128, -128, -128, -128, -128, -128, -128,
                                            -128, -128, -128, 0, -128, -128, -128, 8, -128, -128, -128, -128, -128,
                                            -128, -128, -128, -128, -128, -128);
    const __m256i pick_b = _mm256_setr_epi8(-128, -128, -128, -128, -128, -128, -128, -128, 0, -128, -128, -128, 8,
                                            -128, -128, -128, -128, -128, -128, -128, -128, -128, -128, -128, 0,
                                            -128, -128, -128, 8, -128, -128, -128);
    const __m256i top = _mm256_set1_epi32(255);
    for (int w = 0; w * 8 < n_genes; ++w) {
        long long q[BLOCK];
        for (int c = 0; c < BLOCK; ++c) q[c] = c < count ? (long long)rows[c][w] : 0;
        /* lanes 0..7 of the result are candidates 0..7: the halves hold candidates 0, 1 | 4, 5 of
         * a and 2, 3 | 6, 7 of b */
        const __m256i a = _mm256_setr_epi64x(q[0], q[1], q[4], q[5]), b = _mm256_setr_epi64x(q[2], q[3], q[6], q[7]);
        const int genes = n_genes - 8 * w < 8 ? n_genes - 8 * w : 8;
        for (int g = 0; g < genes; ++g) {
            const int gi = 8 * w + g;
            const __m256i k = _mm256_set1_epi8((char)(7 - g)); /* gene g is the word's byte 7 - g */
            const __m256i code = _mm256_or_si256(_mm256_shuffle_epi8(a, _mm256_add_epi8(pick_a, k)),
                                                 _mm256_shuffle_epi8(b, _mm256_add_epi8(pick_b, k)));
            const __m256 hi = _mm256_set1_ps(x->hi[gi]);
            __m256 value = _mm256_add_ps(_mm256_set1_ps(x->lo[gi]),
                                         _mm256_mul_ps(_mm256_cvtepi32_ps(code), _mm256_set1_ps(x->step[gi])));
            value = _mm256_min_ps(value, hi);
            value = _mm256_blendv_ps(value, hi, _mm256_castsi256_ps(_mm256_cmpeq_epi32(code, top)));
            _mm256_store_ps((float *)&K[gi], value);
        }
    }
}
#endif

static void gene_tables(predictor *x, int n_genes, const double *lower, const double *upper)
{
    for (int gi = 0; gi < n_genes; ++gi) {
        x->lo[gi] = (float)lower[gi];
        x->step[gi] = (float)((upper[gi] - lower[gi]) / 255.0);
        x->hi[gi] = (float)upper[gi];
    }
}

static void gains_from_bytes(const predictor *x, int n_genes, int count, const uint64_t *const *rows, vf *K)
{
#if defined(__x86_64__) && defined(__GNUC__)
    if (x->avx2) {
        gains_from_bytes_avx2(x, n_genes, count, rows, K);
        return;
    }
#endif
    gains_from_bytes_scalar(x, n_genes, count, rows, K);
}

/* ---- the safe variant's admission --------------------------------------------------------- */

/* Whether the symmetric nj x nj matrix S (row-major) is positive definite: a Cholesky
 * factorisation whose pivots stay positive (exact test, about nj^3 / 6 multiplications). */
static int positive_definite(int nj, double *S)
{
    for (int j = 0; j < nj; ++j) {
        double d = S[j * nj + j];
        for (int k = 0; k < j; ++k) d -= S[j * nj + k] * S[j * nj + k];
        if (!(d > 0.0)) return 0;
        d = sqrt(d);
        S[j * nj + j] = d;
        for (int i = j + 1; i < nj; ++i) {
            double v = S[i * nj + j];
            for (int k = 0; k < j; ++k) v -= S[i * nj + k] * S[j * nj + k];
            S[i * nj + j] = v / d;
        }
    }
    return 1;
}

/* The safe variant's repair and admission of one candidate: kp (nj x nj, row-major) is replaced by
 * its symmetric part Ks and kv by kv0 I, kv0 the held damping g->safe_kv or, when the damping is
 * tuned (g->safe_nkv > 0), the grid point j nearest to the mean of the candidate's Kv diagonal.
 * With Kv a multiple of the identity, Ks and Kv share their eigenvectors, so the discrete loop
 * (hold, velocity filter, model error) splits into one scalar loop per pair (eigenvalue of Ks,
 * kv0); control/safety.py computes the interval [lo, hi] of the eigenvalues whose scalar loops
 * have every pole inside the margin circle for every model error in the bound (per grid point
 * when tuned). Admitted iff Ks - lo I and hi I - Ks are positive definite. Returns 0 when
 * admitted, else a penalty in (1, 3] that grows with Gershgorin's estimate of the violation (3
 * for a damping without interval), so the GA's ranking leads the population back into the
 * admitted set. */
static double safe_admit(int nj, const vgt_ga_settings *g, double *kp, double *kv)
{
    double below[nj * nj], above[nj * nj], gmin = INFINITY, gmax = -INFINITY;
    double lo = g->safe_lo, hi = g->safe_hi, kv0 = g->safe_kv;
    if (g->safe_nkv > 0) {
        double mean = 0.0;
        for (int i = 0; i < nj; ++i) mean += kv[i * nj + i];
        long j = lround(mean / nj / g->safe_kv_step);
        j = j < 0 ? 0 : (j >= g->safe_nkv ? g->safe_nkv - 1 : j);
        kv0 = (double)j * g->safe_kv_step;
        lo = g->safe_lo_tab[j];
        hi = g->safe_hi_tab[j];
    }
    for (int i = 0; i < nj; ++i)
        for (int l = i; l < nj; ++l) {
            double v = 0.5 * (kp[i * nj + l] + kp[l * nj + i]);
            kp[i * nj + l] = kp[l * nj + i] = v;
        }
    for (int i = 0; i < nj; ++i) {
        double radius = 0.0;
        for (int l = 0; l < nj; ++l) {
            kv[i * nj + l] = i == l ? kv0 : 0.0;
            below[i * nj + l] = kp[i * nj + l] - (i == l ? lo : 0.0);
            above[i * nj + l] = (i == l ? hi : 0.0) - kp[i * nj + l];
            if (l != i) radius += fabs(kp[i * nj + l]);
        }
        gmin = fmin(gmin, kp[i * nj + i] - radius);
        gmax = fmax(gmax, kp[i * nj + i] + radius);
    }
    if (!(lo < hi)) return 3.0;
    if (positive_definite(nj, below) && positive_definite(nj, above)) return 0.0;
    const double scale = hi - lo;
    return 1.0 + fmin(1.0, fmax(0.0, lo - gmin) / scale) + fmin(1.0, fmax(0.0, gmax - hi) / scale) + 1e-9;
}

/* positive_definite on the BLOCK matrices A (nj x nj, one lane each) at once: ok[c] stays 1 only
 * if every pivot of lane c is positive. A lane's numbers are positive_definite's on it, in the
 * same order (so the same test, bit for bit: no contraction, a correctly rounded sqrt and
 * division); a lane that failed goes on with pivot 1 (its numbers are no longer used, and nothing
 * divides by zero). Stops when no lane is left. */
static inline __attribute__((always_inline)) void lanes_cholesky(int nj, double (*restrict A)[BLOCK], int *ok)
{
    for (int j = 0; j < nj; ++j) {
        double d[BLOCK];
        for (int c = 0; c < BLOCK; ++c) d[c] = A[j * nj + j][c];
        for (int k = 0; k < j; ++k)
            for (int c = 0; c < BLOCK; ++c) d[c] -= A[j * nj + k][c] * A[j * nj + k][c];
        int any = 0;
        for (int c = 0; c < BLOCK; ++c) {
            ok[c] &= d[c] > 0.0;
            d[c] = sqrt(ok[c] ? d[c] : 1.0);
            A[j * nj + j][c] = d[c];
            any |= ok[c];
        }
        if (!any) return;
        for (int i = j + 1; i < nj; ++i) {
            double v[BLOCK];
            for (int c = 0; c < BLOCK; ++c) v[c] = A[i * nj + j][c];
            for (int k = 0; k < j; ++k)
                for (int c = 0; c < BLOCK; ++c) v[c] -= A[i * nj + k][c] * A[j * nj + k][c];
            for (int c = 0; c < BLOCK; ++c) A[i * nj + j][c] = v[c] / d[c];
        }
    }
}

/* How far inside Gershgorin's bound a shifted matrix must be, relative to its largest diagonal
 * entry, for its factorisation to be skipped: its smallest eigenvalue relative to the largest
 * diagonal entry is then above 1e-8, and a Cholesky factorisation in double precision runs to the
 * end (its pivots stay positive) once that ratio exceeds n gamma_{n+1} / (1 - n gamma_{n+1}),
 * about n^2 1.1e-16 (Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed., Thm 10.7):
 * below 1e-8 for every n up to several thousand joints, with room for the rounding of the bound
 * itself. So the skip gives positive_definite's answer exactly. */
#define GERSHGORIN_MARGIN 1e-8

/* safe_admit on the BLOCK lanes of K (gene-major, one float per lane): the repaired gains are
 * written back (so the prediction is that of the gains that would be applied), penalty[c] set
 * (lanes past count too: they are not read). The same arithmetic as safe_admit lane by lane (fmin
 * and fmax of the Gershgorin bounds as comparisons: the running bound is never NaN, and a NaN
 * value leaves it, as fmin does), and the same answers with less work: a shifted matrix with a
 * diagonal entry <= 0 is not positive definite (its factorisation fails at that pivot at the
 * latest: a pivot is the entry minus squares), one well inside Gershgorin's bound is
 * (GERSHGORIN_MARGIN); only the lanes left between are factorised, side by side, and a
 * factorisation runs only while a lane needs it. The loops run over the lanes (vectorised; no
 * errno for sqrt, so that it vectorises, and no contraction, so that each lane rounds as
 * positive_definite does). With AVX-512 (the x86-64-v4 clone) a lane loop is one instruction on
 * eight doubles: 11 % off the safe variant's activation (docs/benchmarks.md). */
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default"), optimize("no-math-errno", "fp-contract=off"))) static void
safe_repair(const predictor *x, scratch *sc, vf *K, double *penalty)
{
    const vgt_ga_settings *g = x->g;
    const int nj = x->nj, nn = nj * nj;
    double (*restrict sym)[BLOCK] = sc->sym, (*restrict shifted)[BLOCK] = sc->shifted;
    double kv0[BLOCK], lo[BLOCK], hi[BLOCK], gmin[BLOCK], gmax[BLOCK], radius[BLOCK];
    double below_min[BLOCK], below_max[BLOCK], above_min[BLOCK], above_max[BLOCK];
    int ok[BLOCK], diagonal[BLOCK], need[BLOCK], any;
    for (int c = 0; c < BLOCK; ++c) {
        kv0[c] = g->safe_kv;
        lo[c] = g->safe_lo;
        hi[c] = g->safe_hi;
        gmin[c] = below_min[c] = above_min[c] = INFINITY;
        gmax[c] = below_max[c] = above_max[c] = -INFINITY;
        diagonal[c] = 1;
    }
    if (g->safe_nkv > 0)
        for (int c = 0; c < BLOCK; ++c) {
            double mean = 0.0;
            for (int i = 0; i < nj; ++i) mean += (double)K[nn + i * nj + i][c];
            long j = lround(mean / nj / g->safe_kv_step);
            j = j < 0 ? 0 : (j >= g->safe_nkv ? g->safe_nkv - 1 : j);
            kv0[c] = (double)j * g->safe_kv_step;
            lo[c] = g->safe_lo_tab[j];
            hi[c] = g->safe_hi_tab[j];
        }
    for (int i = 0; i < nj; ++i)
        for (int l = i; l < nj; ++l)
            for (int c = 0; c < BLOCK; ++c) {
                const double v = 0.5 * ((double)K[i * nj + l][c] + (double)K[l * nj + i][c]);
                sym[i * nj + l][c] = v;
                sym[l * nj + i][c] = v;
            }
    for (int i = 0; i < nj; ++i) {
        for (int c = 0; c < BLOCK; ++c) radius[c] = 0.0;
        for (int l = 0; l < nj; ++l) {
            for (int c = 0; c < BLOCK; ++c) {
                K[i * nj + l][c] = (float)sym[i * nj + l][c];
                K[nn + i * nj + l][c] = (float)(i == l ? kv0[c] : 0.0);
                shifted[i * nj + l][c] = sym[i * nj + l][c] - (i == l ? lo[c] : 0.0);
            }
            if (l != i)
                for (int c = 0; c < BLOCK; ++c) radius[c] += fabs(sym[i * nj + l][c]);
        }
        for (int c = 0; c < BLOCK; ++c) {
            const double low = sym[i * nj + i][c] - radius[c], high = sym[i * nj + i][c] + radius[c];
            const double below = sym[i * nj + i][c] - lo[c], above = hi[c] - sym[i * nj + i][c];
            gmin[c] = low < gmin[c] ? low : gmin[c];
            gmax[c] = high > gmax[c] ? high : gmax[c];
            diagonal[c] &= below > 0.0 && above > 0.0;
            below_min[c] = below - radius[c] < below_min[c] ? below - radius[c] : below_min[c];
            below_max[c] = below > below_max[c] ? below : below_max[c];
            above_min[c] = above - radius[c] < above_min[c] ? above - radius[c] : above_min[c];
            above_max[c] = above > above_max[c] ? above : above_max[c];
        }
    }
    any = 0;
    for (int c = 0; c < BLOCK; ++c) { /* sym(Kp) - lo I */
        ok[c] = lo[c] < hi[c] && diagonal[c];
        need[c] = ok[c] && !(below_min[c] > GERSHGORIN_MARGIN * below_max[c]);
        any |= need[c];
    }
    if (any) {
        lanes_cholesky(nj, shifted, need);
        for (int c = 0; c < BLOCK; ++c) ok[c] &= (below_min[c] > GERSHGORIN_MARGIN * below_max[c]) || need[c];
    }
    any = 0;
    for (int c = 0; c < BLOCK; ++c) { /* hi I - sym(Kp) */
        need[c] = ok[c] && !(above_min[c] > GERSHGORIN_MARGIN * above_max[c]);
        any |= need[c];
    }
    if (any) {
        for (int i = 0; i < nj; ++i)
            for (int l = 0; l < nj; ++l)
                for (int c = 0; c < BLOCK; ++c) shifted[i * nj + l][c] = (i == l ? hi[c] : 0.0) - sym[i * nj + l][c];
        lanes_cholesky(nj, shifted, need);
        for (int c = 0; c < BLOCK; ++c) ok[c] &= (above_min[c] > GERSHGORIN_MARGIN * above_max[c]) || need[c];
    }
    for (int c = 0; c < BLOCK; ++c) {
        const double scale = hi[c] - lo[c];
        if (!(lo[c] < hi[c])) penalty[c] = 3.0;
        else if (ok[c]) penalty[c] = 0.0;
        else
            penalty[c] = 1.0 + fmin(1.0, fmax(0.0, lo[c] - gmin[c]) / scale)
                         + fmin(1.0, fmax(0.0, gmax[c] - hi[c]) / scale) + 1e-9;
    }
}

/* Exact prediction of the candidates listed in `which` (all when which is NULL). */
static int predict_exact(const vgt_model *m, const vgt_settings *s, const predictor *x, long n, const long *which,
                         const double *genes, double *cost)
{
    const int nn = x->nj * x->nj;
    double *kp = malloc(sizeof(double) * (size_t)(n * nn + 1)), *kv = malloc(sizeof(double) * (size_t)(n * nn + 1));
    double *out = malloc(sizeof(double) * (size_t)(n + 1));
    int status = VGT_NO_MEMORY;
    if (kp && kv && out) {
        for (long c = 0; c < n; ++c) {
            long row = which ? which[c] : c;
            memcpy(kp + c * nn, genes + row * 2 * nn, sizeof(double) * (size_t)nn);
            memcpy(kv + c * nn, genes + row * 2 * nn + nn, sizeof(double) * (size_t)nn);
        }
        const vgt_ga_problem *pb = x->pb;
        status = vgt_ga_fitness(m, s, pb->p_ctrl, x->horizon, pb->q0, pb->qd0, pb->q_d, pb->qd_d, pb->qdd_d,
                                pb->tip_d, n, kp, kv, out);
        for (long c = 0; c < n && status == VGT_DONE; ++c) cost[which ? which[c] : c] = out[c];
    }
    free(kp);
    free(kv);
    free(out);
    return status;
}

/* Costs of candidates c .. c + BLOCK (those below n) with one thread's scratch. */
static int predict_one_block(const vgt_ga_settings *g, const vgt_model *m, const predictor *x, scratch *sc, long c,
                             long n, const double *genes, const uint64_t *const *rows, double *cost)
{
    const int nj = x->nj;
    const vgt_ga_problem *pb = x->pb;
    int count = n - c < BLOCK ? (int)(n - c) : BLOCK;
    double sum[BLOCK];
    long n_far = 0;
    int seen[BLOCK] = {0};
    if (genes)
        gains_from_genes(g->n_genes, count, genes + c * g->n_genes, sc->K);
    else
        gains_from_bytes(x, g->n_genes, count, rows + c, sc->K);
    double penalty[BLOCK];
    if (x->safe) safe_repair(x, sc, sc->K, penalty);
    predict_block(x, count, sc->K, sum, sc->far, sc->far_at, &n_far);
    /* the steps outside the trust region: the exact forward kinematics of the predicted joints */
    for (long f = 0; f < n_far; ++f) {
        long lane = sc->far_at[f] / x->horizon, j = sc->far_at[f] % x->horizon;
        double q[nj], tip[3];
        for (int i = 0; i < nj; ++i) q[i] = pb->q_d[(j + 1) * nj + i] - (double)sc->far[f * nj + i];
        sc->arg[0] = q;
        sc->arg[1] = pb->p_ctrl;
        sc->res[0] = tip;
        if (m->tip.f(sc->arg, sc->res, sc->iw, sc->w, 0)) return VGT_FUNCTION_FAILED;
        const double *td = pb->tip_d + 3 * (j + 1);
        double d0 = td[0] - tip[0], d1 = td[1] - tip[1], d2 = td[2] - tip[2];
        sum[lane] += d0 * d0 + d1 * d1 + d2 * d2;
        sc->exact_steps++;
        if (!seen[lane]) sc->exact_candidates++;
        seen[lane] = 1;
    }
    for (int k = 0; k < count; ++k) cost[c + k] = isfinite(sum[k]) ? sqrt(sum[k]) : INFINITY;
    if (x->safe)
        for (int k = 0; k < count; ++k)
            if (penalty[k] > 0.0) cost[c + k] = penalty[k];
    return VGT_DONE;
}

/* Predicted tip error of n candidates given as decoded genes (row by row), or, with genes NULL, as
 * the bit strings rows[0..n) of 8-bit genes. */
static int predict(const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g, predictor *x, long n,
                   const double *genes, const uint64_t *const *rows, double *cost)
{
    if (g->prediction == VGT_PREDICT_EXACT) return predict_exact(m, s, x, n, NULL, genes, cost);
    const long n_blocks = (n + BLOCK - 1) / BLOCK;
    const int threads = x->threads < n_blocks ? x->threads : (int)n_blocks;
    int failed = 0;
    /* the blocks are independent (each candidate's cost depends on its own lane only), so any
     * split between threads gives the same costs bit for bit; they are handed out one at a time,
     * so that a thread the system holds back delays only the block it has (and blocks with many
     * exact steps even out) */
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) if (threads > 1) reduction(| : failed)
    for (long b = 0; b < n_blocks; ++b) {
#ifdef _OPENMP
        scratch *sc = x->sc + omp_get_thread_num();
#else
        scratch *sc = x->sc;
#endif
        if (predict_one_block(g, m, x, sc, b * BLOCK, n, genes, rows, cost)) failed = 1;
    }
    return failed ? VGT_FUNCTION_FAILED : VGT_DONE;
}

/* The tip derivatives of the window's rows that are not ready yet (pb->ready), from the model's
 * generated functions at q_d with the controller's parameters: each row of a run is computed the
 * first time a window needs it, so a run with few activations computes few rows. */
static int ensure_rows(const vgt_model *m, const vgt_ga_problem *pb, int nj, long rows, int quadratic)
{
    if (!pb->ready) return VGT_DONE;
    const vgt_call *calls[3] = {&m->tip, &m->jac, &m->tip_hessian};
    vgt_int sz_arg = 2, sz_res = 2, sz_iw = 1, sz_w = 1;
    for (int f = 0; f < 3; ++f) {
        if (calls[f]->sz_arg > sz_arg) sz_arg = calls[f]->sz_arg;
        if (calls[f]->sz_res > sz_res) sz_res = calls[f]->sz_res;
        if (calls[f]->sz_iw > sz_iw) sz_iw = calls[f]->sz_iw;
        if (calls[f]->sz_w > sz_w) sz_w = calls[f]->sz_w;
    }
    const double **arg = malloc(sizeof(double *) * (size_t)sz_arg);
    double **res = malloc(sizeof(double *) * (size_t)sz_res);
    vgt_int *iw = malloc(sizeof(vgt_int) * (size_t)sz_iw);
    double *w = malloc(sizeof(double) * (size_t)(sz_w + 3 * nj));
    int status = arg && res && iw && w ? VGT_DONE : VGT_NO_MEMORY;
    for (long j = 0; j < rows && status == VGT_DONE; ++j) {
        if (pb->ready[j]) continue;
        double tip[3], *angular = w + sz_w;
        arg[0] = pb->q_d + (long)nj * j;
        arg[1] = pb->p_ctrl;
        res[0] = tip;
        if (m->tip.f(arg, res, iw, w, 0)) status = VGT_FUNCTION_FAILED;
        res[0] = pb->J_d + 3L * nj * j;
        res[1] = angular;
        if (status == VGT_DONE && m->jac.f(arg, res, iw, w, 0)) status = VGT_FUNCTION_FAILED;
        if (status == VGT_DONE && quadratic) {
            res[0] = pb->H_d + 3L * nj * nj * j;
            if (m->tip_hessian.f(arg, res, iw, w, 0)) status = VGT_FUNCTION_FAILED;
        }
        if (status != VGT_DONE) break;
        for (int k = 0; k < 3; ++k) pb->tip_offset[3 * j + k] = pb->tip_d[3 * j + k] - tip[k];
        pb->ready[j] = 1;
    }
    free((void *)arg);
    free(res);
    free(iw);
    free(w);
    return status;
}

static int predictor_init(predictor *x, const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g,
                          const vgt_ga_problem *pb)
{
    memset(x, 0, sizeof *x); /* every pointer NULL, so predictor_free is safe after any failure */
    x->nj = s->n_joints;
    x->horizon = g->horizon;
    x->dt = s->dt;
    x->quadratic = g->prediction == VGT_PREDICT_QUADRATIC;
    x->exact_above2 = g->exact_above * g->exact_above;
    x->pb = pb;
    x->threads = g->threads > 0 ? g->threads : 1;
    x->safe = g->safe;
    x->safe_kv = g->safe_kv;
    x->safe_lo = g->safe_lo;
    x->safe_hi = g->safe_hi;
    x->g = g;
    const int nj = x->nj;
    x->r = malloc(sizeof(float) * (size_t)(g->horizon * nj + 1));
    x->s = malloc(sizeof(float) * (size_t)(g->horizon * nj + 1));
    x->jac_f = malloc(sizeof(float) * (size_t)((g->horizon + 1) * 3 * nj));
    x->off_f = malloc(sizeof(float) * (size_t)((g->horizon + 1) * 3));
    x->row_used = calloc((size_t)(3 * nj), 1);
    x->moves = calloc((size_t)nj, sizeof(int));
    x->coef = NULL;
    if (g->n_bits == 8 && g->prediction != VGT_PREDICT_EXACT) {
        x->lo = malloc(sizeof(float) * (size_t)g->n_genes);
        x->step = malloc(sizeof(float) * (size_t)g->n_genes);
        x->hi = malloc(sizeof(float) * (size_t)g->n_genes);
        if (!x->lo || !x->step || !x->hi) return VGT_NO_MEMORY;
        gene_tables(x, g->n_genes, pb->lower, pb->upper);
#if defined(__x86_64__) && defined(__GNUC__)
        x->avx2 = __builtin_cpu_supports("avx2");
#endif
    }
    if (!x->r || !x->s || !x->jac_f || !x->off_f || !x->row_used || !x->moves) return VGT_NO_MEMORY;
    x->sc = calloc((size_t)x->threads, sizeof(scratch));
    if (!x->sc) return VGT_NO_MEMORY;
    x->n_scratch = x->threads;
    for (int t = 0; t < x->n_scratch; ++t) {
        scratch *sc = x->sc + t;
        sc->K = aligned_alloc(sizeof(vf), sizeof(vf) * (size_t)(2 * nj * nj));
        if (g->safe) {
            sc->sym = malloc(sizeof(double[BLOCK]) * (size_t)(nj * nj));
            sc->shifted = malloc(sizeof(double[BLOCK]) * (size_t)(nj * nj));
            if (!sc->sym || !sc->shifted) return VGT_NO_MEMORY;
        }
        sc->far = malloc(sizeof(float) * (size_t)(BLOCK * (g->horizon + 1) * nj));
        sc->far_at = malloc(sizeof(long) * (size_t)(BLOCK * (g->horizon + 1)));
        sc->arg = malloc(sizeof(double *) * (size_t)(m->tip.sz_arg > 2 ? m->tip.sz_arg : 2));
        sc->res = malloc(sizeof(double *) * (size_t)(m->tip.sz_res > 1 ? m->tip.sz_res : 1));
        sc->iw = malloc(sizeof(vgt_int) * (size_t)(m->tip.sz_iw + 1));
        sc->w = malloc(sizeof(double) * (size_t)(m->tip.sz_w + 1));
        if (!sc->K || !sc->far || !sc->far_at || !sc->arg || !sc->res || !sc->iw || !sc->w)
            return VGT_NO_MEMORY;
    }
    if (g->prediction != VGT_PREDICT_EXACT) {
        int status = ensure_rows(m, pb, nj, g->horizon + 1, x->quadratic);
        if (status != VGT_DONE) return status;
        for (long i = 0; i < (g->horizon + 1) * 3 * nj; ++i) x->jac_f[i] = (float)pb->J_d[i];
        for (long i = 0; i < (g->horizon + 1) * 3; ++i) x->off_f[i] = (float)pb->tip_offset[i];
        if (x->quadratic) {
            const int nn = nj * nj;
            x->coef = calloc((size_t)(g->horizon * 3 * nn + 1), sizeof(float));
            if (!x->coef) return VGT_NO_MEMORY;
            for (long j = 1; j <= g->horizon; ++j)
                for (int k = 0; k < 3; ++k)
                    for (int l = 0; l < nj; ++l)
                        for (int m = l; m < nj; ++m) {
                            double h = pb->H_d[(j * 3 + k) * nn + l * nj + m];
                            x->coef[((j - 1) * 3 + k) * nn + l * nj + m] = (float)((l == m ? -0.5 : -1.0) * h);
                            x->row_used[k * nj + l] |= h != 0.0;
                            if (h != 0.0) x->moves[l] = x->moves[m] = -1;
                        }
        }
        /* the tip map is exact in the joints that do not move the tip (the twist of the paper's
         * robot, whose axis holds the tip): their errors do not count for the trust region */
        for (long i = 0; i < (g->horizon + 1) * 3 * nj; ++i)
            if (pb->J_d[i] != 0.0) x->moves[i % nj] = -1;
    }
    for (long j = 0; j < g->horizon; ++j)
        for (int i = 0; i < nj; ++i) {
            long now = j * nj + i, next = (j + 1) * nj + i;
            x->r[now] = (float)(pb->q_d[next] - pb->q_d[now] - s->dt * pb->qd_d[now]);
            x->s[now] = (float)(pb->qd_d[next] - pb->qd_d[now] - s->dt * pb->qdd_d[now]);
        }
    return VGT_DONE;
}

static void predictor_free(predictor *x)
{
    free(x->r);
    free(x->s);
    free(x->jac_f);
    free(x->off_f);
    free(x->lo);
    free(x->step);
    free(x->hi);
    for (int t = 0; x->sc && t < x->n_scratch; ++t) {
        scratch *sc = x->sc + t;
        free(sc->K);
        free(sc->sym);
        free(sc->shifted);
        free(sc->far);
        free(sc->far_at);
        free(sc->arg);
        free(sc->res);
        free(sc->iw);
        free(sc->w);
    }
    free(x->sc);
    free(x->row_used);
    free(x->moves);
    free(x->coef);
}

int vgt_ga_predict(const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g, const vgt_ga_problem *pb,
                   long n_cand, const double *genes, double *cost)
{
    predictor x;
    int status = predictor_init(&x, m, s, g, pb);
    if (status == VGT_DONE) status = predict(m, s, g, &x, n_cand, genes, NULL, cost);
    predictor_free(&x);
    return status;
}

int vgt_ga_decode_single(const vgt_ga_settings *g, long rows, const uint64_t *bits, const double *lower,
                         const double *upper, int vector, float *genes)
{
    if (g->n_bits != 8) return VGT_FUNCTION_FAILED;
    const int n = g->n_genes;
    predictor x;
    memset(&x, 0, sizeof x);
    x.lo = malloc(sizeof(float) * (size_t)n);
    x.step = malloc(sizeof(float) * (size_t)n);
    x.hi = malloc(sizeof(float) * (size_t)n);
    vf *K = aligned_alloc(sizeof(vf), sizeof(vf) * (size_t)n);
    int status = x.lo && x.step && x.hi && K ? VGT_DONE : VGT_NO_MEMORY;
    if (status == VGT_DONE) {
        gene_tables(&x, n, lower, upper);
#if defined(__x86_64__) && defined(__GNUC__)
        x.avx2 = vector && __builtin_cpu_supports("avx2");
#endif
        for (long c = 0; c < rows; c += BLOCK) {
            const uint64_t *block[BLOCK];
            int count = rows - c < BLOCK ? (int)(rows - c) : BLOCK;
            for (int k = 0; k < count; ++k) block[k] = bits + (c + k) * g->words;
            gains_from_bytes(&x, n, count, block, K);
            for (int k = 0; k < count; ++k)
                for (int gi = 0; gi < n; ++gi) genes[(c + k) * n + gi] = K[gi][k];
        }
    }
    free(x.lo);
    free(x.step);
    free(x.hi);
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
static int predict_watched(const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g, predictor *x,
                           long n, const double *genes, const uint64_t *const *rows, double *cost,
                           double *fastest_per_block)
{
    if (x->threads <= 1) return predict(m, s, g, x, n, genes, rows, cost);
    const double blocks = (double)((n + BLOCK - 1) / BLOCK), start = seconds();
    int status = predict(m, s, g, x, n, genes, rows, cost);
    double elapsed = seconds() - start;
    if (elapsed / blocks < *fastest_per_block) *fastest_per_block = elapsed / blocks;
    if (elapsed > 5e-4 && elapsed > 20.0 * blocks * *fastest_per_block) x->threads = 1;
    return status;
}

static int same_bits(int words, const uint64_t *a, const uint64_t *b)
{
    for (int w = 0; w < words; ++w)
        if (a[w] != b[w]) return 0;
    return 1;
}

static long argmin_first(long n, const double *cost)
{
    long best = 0;
    for (long i = 1; i < n; ++i)
        if (clean_cost(cost[i]) < clean_cost(cost[best])) best = i;
    return best;
}

int vgt_ga_activation(const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g,
                      const vgt_ga_problem *pb, uint64_t seed, vgt_ga_result *out)
{
    const int W = g->words, P = g->population, E = g->elite, C = P - E;
    const long L = (long)g->n_genes * g->n_bits;
    rng_t rng;
    rng_seed(&rng, seed);
    predictor x;
    int status = predictor_init(&x, m, s, g, pb);

    uint64_t *pop = calloc((size_t)P * W, sizeof(uint64_t)), *next = calloc((size_t)P * W, sizeof(uint64_t));
    uint64_t *best_bits = calloc((size_t)W, sizeof(uint64_t)), *valid = calloc((size_t)W, sizeof(uint64_t));
    double *cost = malloc(sizeof(double) * (size_t)P), *next_cost = malloc(sizeof(double) * (size_t)P);
    double *genes = malloc(sizeof(double) * (size_t)P * g->n_genes), *new_cost = malloc(sizeof(double) * (size_t)P);
    double *expectation = malloc(sizeof(double) * (size_t)P), *work = malloc(sizeof(double) * 2 * (size_t)P);
    double *parent_cost = malloc(sizeof(double) * (size_t)P), *weights = malloc(sizeof(double) * (size_t)P);
    long *order = malloc(sizeof(long) * (size_t)P), *pool = malloc(sizeof(long) * (size_t)P);
    long *fresh = malloc(sizeof(long) * (size_t)P);
    const uint64_t **fresh_rows = malloc(sizeof(uint64_t *) * (size_t)P);
    const int from_bytes = g->n_bits == 8 && g->prediction != VGT_PREDICT_EXACT;
    long max_flips = 64 + (long)(4.0 * g->p_mutation * (double)(C * L)) + 8 * (long)sqrt((double)C * L + 1.0);
    if (max_flips > C * L) max_flips = C * L;
    long *flips = malloc(sizeof(long) * (size_t)(max_flips + 1));
    double *fractions = NULL;
    if (g->n_bits <= 16) {
        const long codes = 1L << g->n_bits;
        const double top = (double)(codes - 1);
        fractions = malloc(sizeof(double) * (size_t)codes);
        if (fractions)
            for (long c = 0; c < codes; ++c) fractions[c] = (double)c / top;
    }
    if (status == VGT_DONE && !(pop && next && best_bits && valid && cost && next_cost && genes && new_cost &&
                                expectation && work && parent_cost && weights && order && pool && fresh && fresh_rows && flips))
        status = VGT_NO_MEMORY;
    if (status != VGT_DONE) goto done;

    for (long bit = 0; bit < L; ++bit) valid[bit >> 6] |= 1ULL << (63 - (bit & 63));
    rank_weights(P, weights);

    /* first population: the seeded rows, then random bits */
    for (int k = 0; k < P; ++k) {
        uint64_t *row = pop + (long)k * W;
        if (k < g->n_seeded) {
            memcpy(row, pb->initial_bits + (long)k * W, sizeof(uint64_t) * (size_t)W);
            for (int w = 0; w < W; ++w) row[w] &= valid[w];
        } else {
            for (int w = 0; w < W; ++w) row[w] = valid[w] ? rng_next(&rng) & valid[w] : 0;
        }
    }
    double fastest_per_block = INFINITY;
    if (from_bytes) { /* every prediction decodes the same way, straight from the bits */
        for (int k = 0; k < P; ++k) fresh_rows[k] = pop + (long)k * W;
        status = predict_watched(m, s, g, &x, P, NULL, fresh_rows, cost, &fastest_per_block);
    } else {
        vgt_ga_decode(g, P, pop, pb->lower, pb->upper, genes);
        status = predict_watched(m, s, g, &x, P, genes, NULL, cost, &fastest_per_block);
    }
    if (status != VGT_DONE) goto done;
    for (int k = 0; k < P; ++k) cost[k] = clean_cost(cost[k]);
    out->evaluations = P;
    out->seeded_cost = g->n_seeded > 0 ? cost[0] : NAN;
    long best = argmin_first(P, cost);
    double best_cost = cost[best];
    memcpy(best_bits, pop + best * W, sizeof(uint64_t) * (size_t)W);

    int generation = 0;
    for (generation = 1; generation <= g->generations; ++generation) {
        /* selection: rank scaling, SUS, shuffled pool */
        rank_expectations(P, cost, C, expectation, order, weights, work);
        sus(P, expectation, C, rng_uniform(&rng), pool, work);
        for (long i = C - 1; i > 0; --i) {
            long j = rng_below(&rng, i + 1);
            long tmp = pool[i];
            pool[i] = pool[j];
            pool[j] = tmp;
        }
        uint64_t *children = next + (long)E * W;
        for (int i = 0; i < C; ++i) {
            memcpy(children + (long)i * W, pop + pool[i] * W, sizeof(uint64_t) * (size_t)W);
            parent_cost[i] = cost[pool[i]];
        }
        /* uniform crossover of consecutive pairs */
        for (int k = 0; k + 1 < C; k += 2) {
            if (!(rng_uniform(&rng) < g->p_crossover)) continue;
            uint64_t *a = children + (long)k * W, *b = a + W;
            for (int w = 0; w < W; ++w) {
                uint64_t swap = (a[w] ^ b[w]) & rng_next(&rng) & valid[w];
                a[w] ^= swap;
                b[w] ^= swap;
            }
        }
        /* bit-flip mutation over every child's bits */
        long n_flips = mutation_positions(&rng, (long)C * L, g->p_mutation, max_flips, flips);
        /* the positions ascend: follow the child they fall in instead of dividing each by L */
        for (long f = 0, child = 0, child_start = 0; f < n_flips; ++f) {
            while (flips[f] >= child_start + L) {
                ++child;
                child_start += L;
            }
            flip_bit(children + child * W, flips[f] - child_start);
        }
        /* children equal to a parent keep its cost; the others are predicted */
        long n_fresh = 0;
        for (int i = 0; i < C; ++i) {
            int mate = (i ^ 1) < C ? (i ^ 1) : i;
            const uint64_t *child = children + (long)i * W;
            if (same_bits(W, child, pop + pool[i] * W))
                new_cost[i] = parent_cost[i];
            else if (same_bits(W, child, pop + pool[mate] * W))
                new_cost[i] = parent_cost[mate];
            else
                fresh[n_fresh++] = i;
        }
        for (long f = 0; f < n_fresh; ++f) {
            fresh_rows[f] = children + fresh[f] * W;
            if (!from_bytes)
                decode_with(g, children + fresh[f] * W, pb->lower, pb->upper, fractions, genes + f * g->n_genes);
        }
        if (n_fresh) {
            status = predict_watched(m, s, g, &x, n_fresh, from_bytes ? NULL : genes, fresh_rows, work,
                                     &fastest_per_block);
            if (status != VGT_DONE) goto done;
            for (long f = 0; f < n_fresh; ++f) new_cost[fresh[f]] = clean_cost(work[f]);
            out->evaluations += n_fresh;
        }
        /* elitism: the best of the old population (`order` still sorts the old costs), then the
         * children */
        for (int e = 0; e < E; ++e) {
            memcpy(next + (long)e * W, pop + order[e] * W, sizeof(uint64_t) * (size_t)W);
            next_cost[e] = cost[order[e]];
        }
        for (int i = 0; i < C; ++i) next_cost[E + i] = new_cost[i];
        uint64_t *swap_bits = pop;
        pop = next;
        next = swap_bits;
        double *swap_cost = cost;
        cost = next_cost;
        next_cost = swap_cost;
        long index = argmin_first(P, cost);
        if (cost[index] < best_cost) {
            best_cost = cost[index];
            memcpy(best_bits, pop + index * W, sizeof(uint64_t) * (size_t)W);
        }
    }
    out->generations = generation - 1;
    out->exact_candidates = out->exact_steps = 0;
    out->threads = x.threads;
    for (int t = 0; t < x.n_scratch; ++t) {
        out->exact_candidates += x.sc[t].exact_candidates;
        out->exact_steps += x.sc[t].exact_steps;
    }
    out->best_cost = best_cost;
    decode_one(g, best_bits, pb->lower, pb->upper, out->best);
    out->dropped = 0;
    if (g->safe) {
        /* the gains applied are the repaired ones, admitted again in double precision; a set that
         * is not admitted, or not predicted to lower the error below the fixed gains' from the
         * same measured state, is dropped for the fixed gains (the first seeded row) */
        const int nn = x.nj * x.nj;
        int admitted = safe_admit(x.nj, g, out->best, out->best + nn) == 0.0;
        if (!admitted || !(best_cost < out->seeded_cost)) {
            decode_one(g, pb->initial_bits, pb->lower, pb->upper, out->best);
            out->best_cost = out->seeded_cost;
            out->dropped = 1;
        }
    }

done:
    predictor_free(&x);
    free(pop);
    free(next);
    free(best_bits);
    free(valid);
    free(cost);
    free(next_cost);
    free(genes);
    free(new_cost);
    free(expectation);
    free(work);
    free(parent_cost);
    free(weights);
    free(order);
    free(pool);
    free(fresh);
    free((void *)fresh_rows);
    free(flips);
    free(fractions);
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
