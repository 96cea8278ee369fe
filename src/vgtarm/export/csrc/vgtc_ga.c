/* The genetic algorithm of switching control for a real-time target (see vgtc_ga.h).
 *
 * Every operation follows vgtarm/model/csrc/ga.c (the simulation's compiled GA) in the same order
 * with the same arithmetic; the comments name the function of ga.c each part mirrors. ga.c keeps
 * eight candidates in a vector of the GCC extensions; so does this file's prediction with GCC or
 * Clang (VGTC_GA_VECTORS), and with any other C99 compiler it keeps them in arrays of
 * VGTC_GA_LANES values with the loops over the lanes innermost (the compiler may vectorise them).
 * The lanes never mix, so each candidate's numbers are those of its lane in ga.c. Build with
 * -ffp-contract=off (the Makefile and CMakeLists.txt do): the fused multiply-adds of ga.c's kernel
 * are written out as fmaf (VGTC_GA_FMA), and no other operation may be fused.
 */
#include <math.h>
#include <string.h>

#include "vgtc_ga.h"
#include "vgtc_model.h"

#if VGTC_GA_FMA
#define FMA(a, b, c) fmaf((a), (b), (c))
#else
#define FMA(a, b, c) ((a) * (b) + (c))
#endif

/* With GCC or Clang (and compilers that take their vector extensions), the block's lanes are one
 * vector per quantity in the prediction, as in ga.c, so that the recursion's values stay in
 * registers; gcc -O2 writes the plain code's arrays to memory at every step (its activation took
 * 1.9 times ga.c's, against about 1 now). Each lane is computed with the very operations, in the
 * same order, of the plain code (an FMA is written per lane, which both compilers turn into one
 * vector instruction), so the two give the same bits (tested). Define VGTC_GA_NO_VECTORS to build
 * the plain code with these compilers. */
#if defined(__GNUC__) && !defined(VGTC_GA_NO_VECTORS)
#define VGTC_GA_VECTORS 1
#else
#define VGTC_GA_VECTORS 0
#endif

typedef int (*vgtc_ga_fn)(const double **arg, double **res, long long *iw, double *w, int mem);

/* ---- generator (ga.c: splitmix64, rng_seed, rng_next, rng_uniform, rng_below) ---------------- */

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
    int i;
    for (i = 0; i < 4; ++i) r->s[i] = splitmix64(&seed);
}

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

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

static double rng_uniform(rng_t *r) { return (double)(rng_next(r) >> 11) * 0x1.0p-53; }

/* The 128-bit product a b as two words (C99 has no 128-bit integer). */
static void multiply_wide(uint64_t a, uint64_t b, uint64_t *high, uint64_t *low)
{
    const uint64_t a0 = a & 0xFFFFFFFFULL, a1 = a >> 32, b0 = b & 0xFFFFFFFFULL, b1 = b >> 32;
    const uint64_t p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
    const uint64_t middle = (p00 >> 32) + (p01 & 0xFFFFFFFFULL) + (p10 & 0xFFFFFFFFULL);
    *high = p11 + (p01 >> 32) + (p10 >> 32) + (middle >> 32);
    *low = a * b;
}

/* Uniform integer in [0, n): Lemire's multiply-shift with rejection, as ga.c. */
static long rng_below(rng_t *r, long n)
{
    const uint64_t bound = (uint64_t)n;
    uint64_t high, low;
    multiply_wide(rng_next(r), bound, &high, &low);
    if (low < bound) {
        const uint64_t threshold = (0 - bound) % bound;
        while (low < threshold) multiply_wide(rng_next(r), bound, &high, &low);
    }
    return (long)high;
}

/* ga.c: mutation_positions. */
static long mutation_positions(rng_t *r, long total, double p, long max_flips, long *positions)
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
        const double u = 1.0 - rng_uniform(r);
        const double gap = floor(log(u) / log_q);
        if (gap >= (double)(total - position - 1)) break;
        position += (long)gap + 1;
        positions[n++] = position;
    }
    return n;
}

/* ---- coding (ga.c: decode_with for 8-bit genes without a table, flip_bit) -------------------- */

static unsigned gene_byte(const uint64_t *bits, int gi) { return (unsigned)((bits[gi >> 3] >> (56 - 8 * (gi & 7))) & 0xFFu); }

static void decode(const vgtc_ga_params *p, const uint64_t *bits, double *genes)
{
    int i;
    for (i = 0; i < VGTC_GA_GENES; ++i) {
        const double fraction = (double)gene_byte(bits, i) / 255.0;
        double value = p->lower[i] + fraction * (p->upper[i] - p->lower[i]);
        if (!(value < p->upper[i])) value = p->upper[i];
        if (fraction == 1.0) value = p->upper[i];
        genes[i] = value;
    }
}

static void flip_bit(uint64_t *w, long bit) { w[bit >> 6] ^= 1ULL << (63 - (bit & 63)); }

static int same_bits(const uint64_t *a, const uint64_t *b)
{
    int w;
    for (w = 0; w < VGTC_GA_WORDS; ++w)
        if (a[w] != b[w]) return 0;
    return 1;
}

/* ---- selection (ga.c: pairwise_sum, clean_cost, stable_order, rank_expectations, sus) -------- */

static double pairwise_sum(const double *a, long n)
{
    if (n < 8) {
        double res = 0.0;
        long i;
        for (i = 0; i < n; ++i) res += a[i];
        return res;
    }
    if (n <= 128) {
        double r[8], res;
        long i;
        int j;
        for (j = 0; j < 8; ++j) r[j] = a[j];
        for (i = 8; i < n - (n % 8); i += 8)
            for (j = 0; j < 8; ++j) r[j] += a[i + j];
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; ++i) res += a[i];
        return res;
    }
    {
        long n2 = n / 2;
        n2 -= n2 % 8;
        return pairwise_sum(a, n2) + pairwise_sum(a + n2, n - n2);
    }
}

static double clean_cost(double c) { return isfinite(c) ? c : INFINITY; }

/* Indices in ascending cost, ties in index order (any stable sort's order): by counting ranks
 * (n <= VGTC_GA_POPULATION; the costs cleaned once, not at every comparison). */
static void stable_order(long n, const double *cost, long *order)
{
    double clean[VGTC_GA_POPULATION];
    long i, j;
    for (i = 0; i < n; ++i) clean[i] = clean_cost(cost[i]);
    for (i = 0; i < n; ++i) {
        const double ci = clean[i];
        long rank = 0;
        for (j = 0; j < i; ++j) rank += clean[j] <= ci;
        for (j = i + 1; j < n; ++j) rank += clean[j] < ci;
        order[rank] = i;
    }
}

static void rank_expectations(long n, const double *cost, long n_parents, double *expectation, long *order,
                              const double *weights, double *shared)
{
    long start = 0, r, i;
    double scale;
    stable_order(n, cost, order);
    while (start < n) {
        long end = start + 1;
        while (end < n && clean_cost(cost[order[end]]) == clean_cost(cost[order[start]])) ++end;
        if (end - start == 1) {
            shared[start] = weights[start];
        } else {
            const double mean = pairwise_sum(weights + start, end - start) / (double)(end - start);
            for (r = start; r < end; ++r) shared[r] = mean;
        }
        start = end;
    }
    for (r = 0; r < n; ++r) expectation[order[r]] = shared[r];
    scale = (double)n_parents / pairwise_sum(expectation, n);
    for (i = 0; i < n; ++i) expectation[i] *= scale;
}

static void sus(long n, const double *expectation, long n_select, double u, long *selected, double *edges)
{
    double total = 0.0, scale;
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

/* ---- the safe variant (ga.c: positive_definite, safe_admit) ---------------------------------- */

static int positive_definite(int nj, double *S)
{
    int i, j, k;
    for (j = 0; j < nj; ++j) {
        double d = S[j * nj + j];
        for (k = 0; k < j; ++k) d -= S[j * nj + k] * S[j * nj + k];
        if (!(d > 0.0)) return 0;
        d = sqrt(d);
        S[j * nj + j] = d;
        for (i = j + 1; i < nj; ++i) {
            double v = S[i * nj + j];
            for (k = 0; k < j; ++k) v -= S[i * nj + k] * S[j * nj + k];
            S[i * nj + j] = v / d;
        }
    }
    return 1;
}

static double safe_admit(const vgtc_ga_params *g, double *kp, double *kv)
{
    const int nj = VGTC_NJ;
    double below[VGTC_NJ * VGTC_NJ], above[VGTC_NJ * VGTC_NJ], gmin = INFINITY, gmax = -INFINITY;
    double lo = g->safe_lo, hi = g->safe_hi, kv0 = g->safe_kv, scale;
    int i, l;
    if (g->safe_nkv > 0) {
        double mean = 0.0;
        long j;
        for (i = 0; i < nj; ++i) mean += kv[i * nj + i];
        j = lround(mean / nj / g->safe_kv_step);
        j = j < 0 ? 0 : (j >= g->safe_nkv ? g->safe_nkv - 1 : j);
        kv0 = (double)j * g->safe_kv_step;
        lo = g->safe_lo_tab[j];
        hi = g->safe_hi_tab[j];
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
    if (positive_definite(nj, below) && positive_definite(nj, above)) return 0.0;
    scale = hi - lo;
    return 1.0 + fmin(1.0, fmax(0.0, lo - gmin) / scale) + fmin(1.0, fmax(0.0, gmax - hi) / scale) + 1e-9;
}

/* ---- prediction (ga.c: gains_from_bytes_scalar, safe_repair, block_kernel, predict_one_block) - */

enum { LANES = VGTC_GA_LANES };

#if !VGTC_GA_VECTORS
/* The gains of candidates rows[0 .. count), one lane each, in single precision
 * (gains_from_bytes_scalar: lanes past count get code 0). */
static void gains_from_bytes(vgtc_ga *x, int count, const uint64_t *const *rows)
{
    int gi, c;
    for (gi = 0; gi < VGTC_GA_GENES; ++gi)
        for (c = 0; c < LANES; ++c) {
            const unsigned code = c < count ? gene_byte(rows[c], gi) : 0u;
            float value = x->lo[gi] + (float)code * x->step[gi];
            value = value < x->hi[gi] ? value : x->hi[gi];
            x->K[gi][c] = code == 255u ? x->hi[gi] : value;
        }
}
#endif

/* ---- the safe variant on a block of candidates (ga.c: safe_repair) -------------------------- */

/* positive_definite on the LANES matrices A (VGTC_NJ x VGTC_NJ, one lane each) at once: ok[c]
 * stays 1 only if every pivot of lane c is positive. A lane's numbers are positive_definite's on
 * it, in the same order (so the same test, bit for bit); a lane that failed goes on with pivot 1
 * (its numbers are no longer used, and nothing divides by zero). Stops when no lane is left. */
static void lanes_cholesky(double (*A)[LANES], int *ok)
{
    const int nj = VGTC_NJ;
    int i, j, k, c, any;
    for (j = 0; j < nj; ++j) {
        double d[LANES];
        for (c = 0; c < LANES; ++c) d[c] = A[j * nj + j][c];
        for (k = 0; k < j; ++k)
            for (c = 0; c < LANES; ++c) d[c] -= A[j * nj + k][c] * A[j * nj + k][c];
        any = 0;
        for (c = 0; c < LANES; ++c) {
            ok[c] &= d[c] > 0.0;
            d[c] = sqrt(ok[c] ? d[c] : 1.0);
            A[j * nj + j][c] = d[c];
            any |= ok[c];
        }
        if (!any) return;
        for (i = j + 1; i < nj; ++i) {
            double v[LANES];
            for (c = 0; c < LANES; ++c) v[c] = A[i * nj + j][c];
            for (k = 0; k < j; ++k)
                for (c = 0; c < LANES; ++c) v[c] -= A[i * nj + k][c] * A[j * nj + k][c];
            for (c = 0; c < LANES; ++c) A[i * nj + j][c] = v[c] / d[c];
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

/* safe_admit on every lane of the block's gains x->K, the repaired gains written back (so the
 * prediction is that of the gains that would be applied), penalty[c] set. The same arithmetic as
 * safe_admit lane by lane (fmin and fmax of the Gershgorin bounds as comparisons: the running
 * bound is never NaN, and a NaN value leaves it, as fmin does), and the same answers with less
 * work: a shifted matrix with a diagonal entry <= 0 is not positive definite (its factorisation
 * fails at that pivot at the latest: a pivot is the entry minus squares), one well inside
 * Gershgorin's bound is (GERSHGORIN_MARGIN); only the lanes left between are factorised, side by
 * side, and a factorisation runs only while a lane needs it. */
static void safe_repair(vgtc_ga *x, double *penalty)
{
    const vgtc_ga_params *g = &x->p;
    const int nj = VGTC_NJ, nn = VGTC_NJ * VGTC_NJ;
    double kv0[LANES], lo[LANES], hi[LANES], gmin[LANES], gmax[LANES], radius[LANES];
    double below_min[LANES], below_max[LANES], above_min[LANES], above_max[LANES];
    int ok[LANES], diagonal[LANES], need[LANES], any, i, l, c;
    for (c = 0; c < LANES; ++c) {
        kv0[c] = g->safe_kv;
        lo[c] = g->safe_lo;
        hi[c] = g->safe_hi;
        gmin[c] = below_min[c] = above_min[c] = INFINITY;
        gmax[c] = below_max[c] = above_max[c] = -INFINITY;
        diagonal[c] = 1;
    }
    if (g->safe_nkv > 0)
        for (c = 0; c < LANES; ++c) {
            double mean = 0.0;
            long j;
            for (i = 0; i < nj; ++i) mean += (double)x->K[nn + i * nj + i][c];
            j = lround(mean / nj / g->safe_kv_step);
            j = j < 0 ? 0 : (j >= g->safe_nkv ? g->safe_nkv - 1 : j);
            kv0[c] = (double)j * g->safe_kv_step;
            lo[c] = g->safe_lo_tab[j];
            hi[c] = g->safe_hi_tab[j];
        }
    for (i = 0; i < nj; ++i)
        for (l = i; l < nj; ++l)
            for (c = 0; c < LANES; ++c) {
                const double v = 0.5 * ((double)x->K[i * nj + l][c] + (double)x->K[l * nj + i][c]);
                x->sym[i * nj + l][c] = v;
                x->sym[l * nj + i][c] = v;
            }
    for (i = 0; i < nj; ++i) {
        for (c = 0; c < LANES; ++c) radius[c] = 0.0;
        for (l = 0; l < nj; ++l) {
            for (c = 0; c < LANES; ++c) {
                x->K[i * nj + l][c] = (float)x->sym[i * nj + l][c];
                x->K[nn + i * nj + l][c] = (float)(i == l ? kv0[c] : 0.0);
                x->shifted[i * nj + l][c] = x->sym[i * nj + l][c] - (i == l ? lo[c] : 0.0);
            }
            if (l != i)
                for (c = 0; c < LANES; ++c) radius[c] += fabs(x->sym[i * nj + l][c]);
        }
        for (c = 0; c < LANES; ++c) {
            const double low = x->sym[i * nj + i][c] - radius[c], high = x->sym[i * nj + i][c] + radius[c];
            const double below = x->sym[i * nj + i][c] - lo[c], above = hi[c] - x->sym[i * nj + i][c];
            gmin[c] = low < gmin[c] ? low : gmin[c];
            gmax[c] = high > gmax[c] ? high : gmax[c];
            diagonal[c] &= below > 0.0 && above > 0.0;
            below_min[c] = below - radius[c] < below_min[c] ? below - radius[c] : below_min[c];
            below_max[c] = below > below_max[c] ? below : below_max[c];
            above_min[c] = above - radius[c] < above_min[c] ? above - radius[c] : above_min[c];
            above_max[c] = above > above_max[c] ? above : above_max[c];
        }
    }
    for (c = any = 0; c < LANES; ++c) { /* sym(Kp) - lo I */
        ok[c] = lo[c] < hi[c] && diagonal[c];
        need[c] = ok[c] && !(below_min[c] > GERSHGORIN_MARGIN * below_max[c]);
        any |= need[c];
    }
    if (any) {
        lanes_cholesky(x->shifted, need);
        for (c = 0; c < LANES; ++c) ok[c] &= (below_min[c] > GERSHGORIN_MARGIN * below_max[c]) || need[c];
    }
    for (c = any = 0; c < LANES; ++c) { /* hi I - sym(Kp) */
        need[c] = ok[c] && !(above_min[c] > GERSHGORIN_MARGIN * above_max[c]);
        any |= need[c];
    }
    if (any) {
        for (i = 0; i < nj; ++i)
            for (l = 0; l < nj; ++l)
                for (c = 0; c < LANES; ++c) x->shifted[i * nj + l][c] = (i == l ? hi[c] : 0.0) - x->sym[i * nj + l][c];
        lanes_cholesky(x->shifted, need);
        for (c = 0; c < LANES; ++c) ok[c] &= (above_min[c] > GERSHGORIN_MARGIN * above_max[c]) || need[c];
    }
    for (c = 0; c < LANES; ++c) {
        const double scale = hi[c] - lo[c];
        if (!(lo[c] < hi[c])) penalty[c] = 3.0;
        else if (ok[c]) penalty[c] = 0.0;
        else
            penalty[c] = 1.0 + fmin(1.0, fmax(0.0, lo[c] - gmin[c]) / scale)
                         + fmin(1.0, fmax(0.0, gmax[c] - hi[c]) / scale) + 1e-9;
    }
}

#if !VGTC_GA_VECTORS
/* Operations on the LANES values of a block, one loop each (the compiler vectorises them). */
static void lanes_mul(float *restrict r, const float *restrict a, const float *restrict b)
{
    int c;
    for (c = 0; c < LANES; ++c) r[c] = a[c] * b[c];
}

static void lanes_mul_s(float *restrict r, float a, const float *restrict b)
{
    int c;
    for (c = 0; c < LANES; ++c) r[c] = a * b[c];
}

/* r = a b + r, fused where ga.c's kernel fuses (FMA) */
static void lanes_fma(float *restrict r, const float *restrict a, const float *restrict b)
{
    int c;
    for (c = 0; c < LANES; ++c) r[c] = FMA(a[c], b[c], r[c]);
}

static void lanes_fma_s(float *restrict r, float a, const float *restrict b)
{
    int c;
    for (c = 0; c < LANES; ++c) r[c] = FMA(a, b[c], r[c]);
}

/* The predicted squared tip errors of the block's gains summed over the steps inside the trust
 * region (block_kernel, lane by lane); the steps outside are listed in x->far, x->far_at. */
static void kernel(vgtc_ga *x, int count, double *sum, long *n_far)
{
    const int nj = VGTC_NJ, nn = VGTC_NJ * VGTC_NJ;
    const float dt = (float)x->p.dt;
    const float limit2 = x->p.exact_above > 0.0 ? (float)(x->p.exact_above * x->p.exact_above) : INFINITY;
    float E[VGTC_NJ][LANES], Ed[VGTC_NJ][LANES], a[VGTC_NJ][LANES], total[LANES];
    long j;
    int i, l, m, k, c;
    for (i = 0; i < nj; ++i)
        for (c = 0; c < LANES; ++c) {
            E[i][c] = (float)(x->q_d[i] - x->q0[i]);
            Ed[i][c] = (float)(x->qd_d[i] - x->qd0[i]);
        }
    for (c = 0; c < LANES; ++c) total[c] = 0.0f;
    *n_far = 0;
    for (j = 0; j < x->horizon; ++j) {
        const float *r = x->r + j * nj, *s = x->s + j * nj;
        const float *J = x->jac_f + (j + 1) * 3 * nj, *off = x->off_f + (j + 1) * 3;
        float norm2[LANES], t[3][LANES], square[LANES];
        for (i = 0; i < nj; ++i) { /* a = Kp E + Kv Ed: each lane's sums in one loop body (in registers) */
            const int ip = i * nj, iv = nn + i * nj;
            for (c = 0; c < LANES; ++c) {
                float p0, v0;
                if (nj == 1) {
                    p0 = x->K[ip][c] * E[0][c];
                    v0 = x->K[iv][c] * Ed[0][c];
                } else { /* the first product is fused with the second (GCC contracts a*b + c*d so) */
                    p0 = x->K[ip + 1][c] * E[1][c];
                    p0 = FMA(x->K[ip][c], E[0][c], p0);
                    v0 = x->K[iv + 1][c] * Ed[1][c];
                    v0 = FMA(x->K[iv][c], Ed[0][c], v0);
                }
                for (l = 2; l < nj; ++l) {
                    p0 = FMA(x->K[ip + l][c], E[l][c], p0);
                    v0 = FMA(x->K[iv + l][c], Ed[l][c], v0);
                }
                a[i][c] = p0 + v0;
            }
        }
        for (c = 0; c < LANES; ++c) norm2[c] = 0.0f;
        for (i = 0; i < nj; ++i) {
            lanes_fma_s(E[i], dt, Ed[i]);
            for (c = 0; c < LANES; ++c) E[i][c] += r[i];
            lanes_fma_s(Ed[i], -dt, a[i]);
            for (c = 0; c < LANES; ++c) Ed[i][c] += s[i];
            if (x->moves[i])
                for (c = 0; c < LANES; ++c) norm2[c] += E[i][c] * E[i][c];
            else
                for (c = 0; c < LANES; ++c) norm2[c] += 0.0f;
        }
        for (k = 0; k < 3; ++k)
            for (c = 0; c < LANES; ++c) t[k][c] = off[k];
        for (l = 0; l < nj; ++l)
            for (k = 0; k < 3; ++k) lanes_fma_s(t[k], J[k * nj + l], E[l]);
        if (x->p.quadratic) {
            const float *coef = x->coef + j * 3 * nn;
            for (k = 0; k < 3; ++k)
                for (l = 0; l < nj; ++l) {
                    const float *cf = coef + k * nn + l * nj;
                    float u[LANES];
                    if (!x->row_used[k * nj + l]) continue;
                    if (l + 1 < nj) {
                        lanes_mul_s(u, cf[l + 1], E[l + 1]);
                        lanes_fma_s(u, cf[l], E[l]);
                    } else {
                        lanes_mul_s(u, cf[l], E[l]);
                    }
                    for (m = l + 2; m < nj; ++m) lanes_fma_s(u, cf[m], E[m]);
                    lanes_fma(t[k], u, E[l]);
                }
        }
        lanes_mul(square, t[1], t[1]);
        lanes_fma(square, t[0], t[0]);
        lanes_fma(square, t[2], t[2]);
        for (c = 0; c < LANES; ++c) total[c] += norm2[c] > limit2 ? 0.0f : square[c];
        for (c = 0; c < count; ++c)
            if (norm2[c] > limit2) {
                const long f = (*n_far)++;
                x->far_at[f] = (long)c * x->horizon + j;
                for (i = 0; i < nj; ++i) x->far[f * nj + i] = E[i][c];
            }
    }
    for (c = 0; c < LANES; ++c) sum[c] = (double)total[c];
}
#else

/* the loops over the joints unrolled, so that each joint's vector has a register (as in ga.c) */
#define UNROLL _Pragma("GCC unroll 16")

typedef float lanes_f __attribute__((vector_size(4 * VGTC_GA_LANES)));
typedef int32_t lanes_i __attribute__((vector_size(4 * VGTC_GA_LANES)));
typedef uint64_t lanes_u __attribute__((vector_size(8 * VGTC_GA_LANES)));

/* Macros rather than functions: a vector passed to or returned from a function is an ABI question
 * (GCC notes it in builds without AVX), and these are only arithmetic. */
#define SPLAT(v) ((float)(v) - (lanes_f){0.0f}) /* every lane v (v - 0 is v, -0 and NaN included) */
#define LOAD(dst, src) memcpy(&(dst), (src), sizeof(dst)) /* LANES floats, any alignment        */
/* r = a b + r lane by lane, fused where ga.c's kernel fuses (FMA), which both compilers turn into
 * one vector instruction when the target has one */
#define FMA_TO(r, a, b)                                                                            \
    do {                                                                                           \
        const lanes_f a_ = (a), b_ = (b);                                                          \
        lanes_f r_ = (r);                                                                          \
        int c_;                                                                                    \
        for (c_ = 0; c_ < LANES; ++c_) r_[c_] = FMA(a_[c_], b_[c_], r_[c_]);                       \
        (r) = r_;                                                                                  \
    } while (0)

/* gains_from_bytes: a word of each candidate is loaded once, its bytes shifted out side by side */
static void gains_from_bytes(vgtc_ga *x, int count, const uint64_t *const *rows)
{
    lanes_i top;
    int w, g, c;
    for (c = 0; c < LANES; ++c) top[c] = 255;
    for (w = 0; w < VGTC_GA_WORDS; ++w) {
        lanes_u word;
        for (c = 0; c < LANES; ++c) word[c] = c < count ? rows[c][w] : 0u;
        for (g = 0; g < 8 && 8 * w + g < VGTC_GA_GENES; ++g) {
            const int gi = 8 * w + g;
            const lanes_i code = __builtin_convertvector((word >> (uint64_t)(56 - 8 * g)) & 0xFFu, lanes_i);
            const lanes_f hi = SPLAT(x->hi[gi]);
            lanes_f value = SPLAT(x->lo[gi]) + __builtin_convertvector(code, lanes_f) * SPLAT(x->step[gi]);
            lanes_i pick = value < hi; /* -1 where value < hi */
            value = (lanes_f)(((lanes_i)value & pick) | ((lanes_i)hi & ~pick));
            pick = code == top;
            value = (lanes_f)(((lanes_i)hi & pick) | ((lanes_i)value & ~pick));
            memcpy(x->K[gi], &value, sizeof value);
        }
    }
}

/* kernel, one vector per quantity */
static void kernel(vgtc_ga *x, int count, double *sum, long *n_far)
{
    const int nj = VGTC_NJ, nn = VGTC_NJ * VGTC_NJ;
    const float dt = (float)x->p.dt;
    const float limit = x->p.exact_above > 0.0 ? (float)(x->p.exact_above * x->p.exact_above) : INFINITY;
    const lanes_f zero = SPLAT(0.0f), limit2 = SPLAT(limit), step = SPLAT(dt), back = SPLAT(-dt);
    lanes_f E[VGTC_NJ], Ed[VGTC_NJ], a[VGTC_NJ], total = zero;
    long j;
    int i, l, m, k, c;
    UNROLL for (i = 0; i < nj; ++i) {
        E[i] = SPLAT((float)(x->q_d[i] - x->q0[i]));
        Ed[i] = SPLAT((float)(x->qd_d[i] - x->qd0[i]));
    }
    *n_far = 0;
    for (j = 0; j < x->horizon; ++j) {
        const float *r = x->r + j * nj, *s = x->s + j * nj;
        const float *J = x->jac_f + (j + 1) * 3 * nj, *off = x->off_f + (j + 1) * 3;
        lanes_f norm2 = zero, t[3], square;
        lanes_i outside;
        int any = 0;
        UNROLL for (i = 0; i < nj; ++i) { /* a = Kp E + Kv Ed */
            const int ip = i * nj, iv = nn + i * nj;
            lanes_f p0, v0, kp, kv;
            if (nj == 1) {
                LOAD(kp, x->K[ip]);
                LOAD(kv, x->K[iv]);
                p0 = kp * E[0];
                v0 = kv * Ed[0];
            } else { /* the first product is fused with the second (GCC contracts a*b + c*d so) */
                LOAD(kp, x->K[ip + 1]);
                LOAD(kv, x->K[iv + 1]);
                p0 = kp * E[1];
                v0 = kv * Ed[1];
                LOAD(kp, x->K[ip]);
                LOAD(kv, x->K[iv]);
                FMA_TO(p0, kp, E[0]);
                FMA_TO(v0, kv, Ed[0]);
            }
            UNROLL for (l = 2; l < nj; ++l) {
                LOAD(kp, x->K[ip + l]);
                LOAD(kv, x->K[iv + l]);
                FMA_TO(p0, kp, E[l]);
                FMA_TO(v0, kv, Ed[l]);
            }
            a[i] = p0 + v0;
        }
        UNROLL for (i = 0; i < nj; ++i) {
            FMA_TO(E[i], step, Ed[i]);
            E[i] = E[i] + SPLAT(r[i]);
            FMA_TO(Ed[i], back, a[i]);
            Ed[i] = Ed[i] + SPLAT(s[i]);
            norm2 = norm2 + (x->moves[i] ? E[i] * E[i] : zero);
        }
        UNROLL for (k = 0; k < 3; ++k) t[k] = SPLAT(off[k]);
        UNROLL for (l = 0; l < nj; ++l)
            UNROLL for (k = 0; k < 3; ++k) FMA_TO(t[k], SPLAT(J[k * nj + l]), E[l]);
        if (x->p.quadratic) {
            const float *coef = x->coef + j * 3 * nn;
            UNROLL for (k = 0; k < 3; ++k)
                UNROLL for (l = 0; l < nj; ++l) {
                    const float *cf = coef + k * nn + l * nj;
                    lanes_f u;
                    if (!x->row_used[k * nj + l]) continue;
                    if (l + 1 < nj) {
                        u = SPLAT(cf[l + 1]) * E[l + 1];
                        FMA_TO(u, SPLAT(cf[l]), E[l]);
                    } else {
                        u = SPLAT(cf[l]) * E[l];
                    }
                    UNROLL for (m = l + 2; m < nj; ++m) FMA_TO(u, SPLAT(cf[m]), E[m]);
                    FMA_TO(t[k], u, E[l]);
                }
        }
        square = t[1] * t[1];
        FMA_TO(square, t[0], t[0]);
        FMA_TO(square, t[2], t[2]);
        outside = norm2 > limit2;
        total = total + (lanes_f)((lanes_i)square & ~outside);
        for (c = 0; c < LANES; ++c) any |= outside[c];
        if (any)
            for (c = 0; c < count; ++c)
                if (outside[c]) {
                    const long f = (*n_far)++;
                    x->far_at[f] = (long)c * x->horizon + j;
                    for (i = 0; i < nj; ++i) x->far[f * nj + i] = E[i][c];
                }
    }
    for (c = 0; c < LANES; ++c) sum[c] = (double)total[c];
}
#endif

/* The predicted tip errors of candidates rows[0 .. count), count <= LANES (predict_one_block). */
static int predict_block(vgtc_ga *x, int count, const uint64_t *const *rows, double *cost)
{
    const int nj = VGTC_NJ;
    double penalty[LANES], sum[LANES];
    long n_far, f;
    int i, c;
    gains_from_bytes(x, count, rows);
    for (c = 0; c < LANES; ++c) penalty[c] = 0.0;
    if (x->p.safe) safe_repair(x, penalty); /* every lane (those past count are not read) */
    kernel(x, count, sum, &n_far);
    for (f = 0; f < n_far; ++f) { /* the exact forward kinematics of the predicted joints */
        const long lane = x->far_at[f] / x->horizon, j = x->far_at[f] % x->horizon;
        const double *td = x->tip_d + 3 * (j + 1);
        double q[VGTC_NJ], tip[3], d0, d1, d2;
        for (i = 0; i < nj; ++i) q[i] = x->q_d[(j + 1) * nj + i] - (double)x->far[f * nj + i];
        x->arg[0] = q;
        x->arg[1] = x->p.model;
        x->res[0] = tip;
        if (vgt_tip(x->arg, x->res, x->iw, x->w, 0)) return VGTC_GA_FUNCTION_FAILED;
        d0 = td[0] - tip[0];
        d1 = td[1] - tip[1];
        d2 = td[2] - tip[2];
        sum[lane] += d0 * d0 + d1 * d1 + d2 * d2;
        x->exact_steps++;
    }
    for (c = 0; c < count; ++c) {
        cost[c] = isfinite(sum[c]) ? sqrt(sum[c]) : INFINITY;
        if (x->p.safe && penalty[c] > 0.0) cost[c] = penalty[c];
    }
    return VGTC_GA_OK;
}

/* The predicted tip errors of candidates rows[0 .. n) (predict: blocks of LANES). */
static int predict(vgtc_ga *x, long n, const uint64_t *const *rows, double *cost)
{
    long b;
    for (b = 0; b < n; b += LANES) {
        const int status = predict_block(x, n - b < LANES ? (int)(n - b) : LANES, rows + b, cost + b);
        if (status != VGTC_GA_OK) return status;
    }
    return VGTC_GA_OK;
}

/* ---- the window (ga.c: ensure_rows, predictor_init) ------------------------------------------ */

static int window(vgtc_ga *x, long horizon, const double *q0, const double *qd0, const double *ref,
                  const double *tip_d)
{
    const int nj = VGTC_NJ, nn = VGTC_NJ * VGTC_NJ;
    const long rows = horizon + 1;
    long j, i;
    int k, l, m;
    x->horizon = horizon;
    memcpy(x->q0, q0, sizeof x->q0);
    memcpy(x->qd0, qd0, sizeof x->qd0);
    for (j = 0; j < rows; ++j) {
        memcpy(x->q_d + j * nj, ref + j * 3 * nj, sizeof(double) * (size_t)nj);
        memcpy(x->qd_d + j * nj, ref + j * 3 * nj + nj, sizeof(double) * (size_t)nj);
        memcpy(x->qdd_d + j * nj, ref + j * 3 * nj + 2 * nj, sizeof(double) * (size_t)nj);
    }
    for (j = 0; j < rows; ++j) {
        double tip[3], *angular = x->w + VGTC_SZ_W;
        x->arg[0] = x->q_d + j * nj;
        x->arg[1] = x->p.model;
        x->res[0] = tip;
        if (vgt_tip(x->arg, x->res, x->iw, x->w, 0)) return VGTC_GA_FUNCTION_FAILED;
        x->res[0] = x->J_d + 3 * nj * j;
        x->res[1] = angular;
        if (vgt_jac(x->arg, x->res, x->iw, x->w, 0)) return VGTC_GA_FUNCTION_FAILED;
        if (x->p.quadratic) {
            x->res[0] = x->H_d + 3 * nn * j;
            if (vgt_tip_hessian(x->arg, x->res, x->iw, x->w, 0)) return VGTC_GA_FUNCTION_FAILED;
        }
        for (k = 0; k < 3; ++k) {
            x->tip_d[3 * j + k] = tip_d ? tip_d[3 * j + k] : tip[k];
            x->tip_offset[3 * j + k] = x->tip_d[3 * j + k] - tip[k];
        }
    }
    memset(x->row_used, 0, sizeof x->row_used);
    memset(x->moves, 0, sizeof x->moves);
    for (i = 0; i < rows * 3 * nj; ++i) x->jac_f[i] = (float)x->J_d[i];
    for (i = 0; i < rows * 3; ++i) x->off_f[i] = (float)x->tip_offset[i];
    if (x->p.quadratic) {
        memset(x->coef, 0, sizeof(float) * (size_t)(horizon * 3 * nn));
        for (j = 1; j <= horizon; ++j)
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
    for (j = 0; j < horizon; ++j)
        for (l = 0; l < nj; ++l) {
            const long now = j * nj + l, next = (j + 1) * nj + l;
            x->r[now] = (float)(x->q_d[next] - x->q_d[now] - x->p.dt * x->qd_d[now]);
            x->s[now] = (float)(x->qd_d[next] - x->qd_d[now] - x->p.dt * x->qdd_d[now]);
        }
    return VGTC_GA_OK;
}

/* ---- init and the activation (ga.c: vgt_ga_activation) -------------------------------------- */

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
    long C, bit, max_flips;
    int gi;
    if (!ga || !p) return VGTC_GA_BAD_ARGUMENT;
    C = (long)p->population - p->elite;
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
    max_flips = 64 + (long)(4.0 * p->p_mutation * (double)(C * L)) + 8 * (long)sqrt((double)C * L + 1.0);
    if (max_flips > C * L) max_flips = C * L;
    if (max_flips > VGTC_GA_MAX_FLIPS) return VGTC_GA_BAD_PARAMETER;
    memset(ga, 0, sizeof *ga);
    ga->p = *p;
    ga->max_flips = max_flips;
    for (bit = 0; bit < L; ++bit) ga->valid[bit >> 6] |= 1ULL << (63 - (bit & 63));
    for (gi = 0; gi < p->population; ++gi) ga->weights[gi] = 1.0 / sqrt((double)(gi + 1));
    for (gi = 0; gi < VGTC_GA_GENES; ++gi) { /* ga.c: gene_tables */
        ga->lo[gi] = (float)p->lower[gi];
        ga->step[gi] = (float)((p->upper[gi] - p->lower[gi]) / 255.0);
        ga->hi[gi] = (float)p->upper[gi];
    }
    ga->ready = 1;
    return VGTC_GA_OK;
}

static long argmin_first(long n, const double *cost)
{
    long best = 0, i;
    for (i = 1; i < n; ++i)
        if (clean_cost(cost[i]) < clean_cost(cost[best])) best = i;
    return best;
}

int vgtc_ga_activate(vgtc_ga *ga, long horizon, const double *q0, const double *qd0, const double *ref,
                     const double *tip_d, uint64_t seed, double *gains, vgtc_ga_result *out)
{
    const int W = VGTC_GA_WORDS, nn = VGTC_NJ * VGTC_NJ;
    const long L = (long)VGTC_GA_GENES * 8;
    int P, E, C, k, w, generation, status;
    long best, evaluations, i;
    double best_cost, seeded_cost;
    uint64_t *pop, *next;
    double *cost, *next_cost;
    rng_t rng;
    if (!ga || !ga->ready || !q0 || !qd0 || !ref || !gains || horizon < 1 || horizon > ga->p.horizon)
        return VGTC_GA_BAD_ARGUMENT;
    if (!finite_all(VGTC_NJ, q0) || !finite_all(VGTC_NJ, qd0) || !finite_all((horizon + 1) * 3 * VGTC_NJ, ref)
        || (tip_d && !finite_all((horizon + 1) * 3, tip_d)))
        return VGTC_GA_NOT_FINITE;
    P = ga->p.population;
    E = ga->p.elite;
    C = P - E;
    status = window(ga, horizon, q0, qd0, ref, tip_d);
    if (status != VGTC_GA_OK) return status;
    ga->exact_steps = 0;
    rng_seed(&rng, seed);
    pop = ga->pop;
    next = ga->next;
    cost = ga->cost;
    next_cost = ga->next_cost;

    /* first population: the seeded rows, then random bits */
    for (k = 0; k < P; ++k) {
        uint64_t *row = pop + (long)k * W;
        if (k < ga->p.n_seeded) {
            memcpy(row, ga->p.initial_bits + (long)k * W, sizeof(uint64_t) * (size_t)W);
            for (w = 0; w < W; ++w) row[w] &= ga->valid[w];
        } else {
            for (w = 0; w < W; ++w) row[w] = ga->valid[w] ? rng_next(&rng) & ga->valid[w] : 0;
        }
    }
    for (k = 0; k < P; ++k) ga->rows[k] = pop + (long)k * W;
    if ((status = predict(ga, P, ga->rows, cost)) != VGTC_GA_OK) return status;
    for (k = 0; k < P; ++k) cost[k] = clean_cost(cost[k]);
    evaluations = P;
    seeded_cost = ga->p.n_seeded > 0 ? cost[0] : NAN;
    best = argmin_first(P, cost);
    best_cost = cost[best];
    memcpy(ga->best_bits, pop + best * W, sizeof(uint64_t) * (size_t)W);

    for (generation = 1; generation <= ga->p.generations; ++generation) {
        uint64_t *children = next + (long)E * W, *swap_bits;
        double *swap_cost;
        long n_flips, f, child, child_start, n_fresh = 0, index;
        rank_expectations(P, cost, C, ga->expectation, ga->order, ga->weights, ga->work);
        sus(P, ga->expectation, C, rng_uniform(&rng), ga->pool, ga->work);
        for (i = C - 1; i > 0; --i) {
            const long j = rng_below(&rng, i + 1), tmp = ga->pool[i];
            ga->pool[i] = ga->pool[j];
            ga->pool[j] = tmp;
        }
        for (k = 0; k < C; ++k) {
            memcpy(children + (long)k * W, pop + ga->pool[k] * W, sizeof(uint64_t) * (size_t)W);
            ga->parent_cost[k] = cost[ga->pool[k]];
        }
        for (k = 0; k + 1 < C; k += 2) { /* uniform crossover of consecutive pairs */
            uint64_t *a = children + (long)k * W, *b = a + W;
            if (!(rng_uniform(&rng) < ga->p.p_crossover)) continue;
            for (w = 0; w < W; ++w) {
                const uint64_t swap = (a[w] ^ b[w]) & rng_next(&rng) & ga->valid[w];
                a[w] ^= swap;
                b[w] ^= swap;
            }
        }
        n_flips = mutation_positions(&rng, (long)C * L, ga->p.p_mutation, ga->max_flips, ga->flips);
        for (f = 0, child = 0, child_start = 0; f < n_flips; ++f) {
            while (ga->flips[f] >= child_start + L) {
                ++child;
                child_start += L;
            }
            flip_bit(children + child * W, ga->flips[f] - child_start);
        }
        for (k = 0; k < C; ++k) { /* children equal to a parent keep its cost */
            const int mate = (k ^ 1) < C ? (k ^ 1) : k;
            const uint64_t *row = children + (long)k * W;
            if (same_bits(row, pop + ga->pool[k] * W))
                ga->new_cost[k] = ga->parent_cost[k];
            else if (same_bits(row, pop + ga->pool[mate] * W))
                ga->new_cost[k] = ga->parent_cost[mate];
            else
                ga->fresh[n_fresh++] = k;
        }
        for (f = 0; f < n_fresh; ++f) ga->rows[f] = children + ga->fresh[f] * W;
        if ((status = predict(ga, n_fresh, ga->rows, ga->work)) != VGTC_GA_OK) return status;
        for (f = 0; f < n_fresh; ++f) ga->new_cost[ga->fresh[f]] = clean_cost(ga->work[f]);
        evaluations += n_fresh;
        for (k = 0; k < E; ++k) { /* elitism */
            memcpy(next + (long)k * W, pop + ga->order[k] * W, sizeof(uint64_t) * (size_t)W);
            next_cost[k] = cost[ga->order[k]];
        }
        for (k = 0; k < C; ++k) next_cost[E + k] = ga->new_cost[k];
        swap_bits = pop;
        pop = next;
        next = swap_bits;
        swap_cost = cost;
        cost = next_cost;
        next_cost = swap_cost;
        index = argmin_first(P, cost);
        if (cost[index] < best_cost) {
            best_cost = cost[index];
            memcpy(ga->best_bits, pop + index * W, sizeof(uint64_t) * (size_t)W);
        }
    }
    decode(&ga->p, ga->best_bits, gains);
    if (out) out->dropped = 0;
    if (ga->p.safe) {
        const int admitted = safe_admit(&ga->p, gains, gains + nn) == 0.0;
        if (!admitted || !(best_cost < seeded_cost)) {
            decode(&ga->p, ga->p.initial_bits, gains);
            best_cost = seeded_cost;
            if (out) out->dropped = 1;
        }
    }
    if (out) {
        out->best_cost = best_cost;
        out->seeded_cost = seeded_cost;
        out->generations = generation - 1;
        out->evaluations = evaluations;
        out->exact_steps = ga->exact_steps;
    }
    return VGTC_GA_OK;
}
