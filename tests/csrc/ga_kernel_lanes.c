/* The prediction kernel of the GA's one C file (src/vgtarm/model/csrc/vgt_ga.h) in its vector form
 * against its plain C99 form, and its safe repair compiled for each x86-64 level against the
 * baseline's, lane for lane and bit for bit, on random windows and gains of every joint count from
 * 1 to 21 (3, 6 and 7 known at compile time, the others at run time, as ga.c dispatches them).
 * Built twice by tests/test_ga_compiled.py: with -DPLAIN_KERNEL (the plain arrays: plain_kernel,
 * plain_repair), and without (for each x86-64 level the CPU has: generic, AVX2 + FMA, AVX-512),
 * at -O2 and -O3. Prints each difference and their count; exits 1 when there is one. */
#ifdef PLAIN_KERNEL
#define VGT_GA_NO_VECTORS
#include "vgt_ga.h"
void plain_kernel(const ga_window *x, ga_lanes *sc, int count, double *sum, long *n_far);
void plain_kernel(const ga_window *x, ga_lanes *sc, int count, double *sum, long *n_far)
{
    ga_kernel(x, sc, x->nj, 1, count, sum, n_far);
}
void plain_repair(const ga_safe *g, int nj, ga_lanes *sc, double *penalty);
void plain_repair(const ga_safe *g, int nj, ga_lanes *sc, double *penalty) { ga_safe_repair(g, nj, sc, penalty); }
#else
#include <stdio.h>
#include <stdlib.h>
#include "vgt_ga.h"

void plain_kernel(const ga_window *x, ga_lanes *sc, int count, double *sum, long *n_far);
void plain_repair(const ga_safe *g, int nj, ga_lanes *sc, double *penalty);
typedef void (*kernel_fn)(const ga_window *x, ga_lanes *sc, int count, double *sum, long *n_far);
typedef void (*repair_fn)(const ga_safe *g, int nj, ga_lanes *sc, double *penalty);

#define KERNEL(name, attributes)                                                                     \
    attributes void name(const ga_window *x, ga_lanes *sc, int count, double *sum, long *n_far)      \
    {                                                                                               \
        switch (x->nj) {                                                                            \
        case 3: ga_kernel(x, sc, 3, 1, count, sum, n_far); break;                                   \
        case 6: ga_kernel(x, sc, 6, 1, count, sum, n_far); break;                                   \
        case 7: ga_kernel(x, sc, 7, 1, count, sum, n_far); break;                                   \
        default: ga_kernel(x, sc, x->nj, 1, count, sum, n_far); break;                              \
        }                                                                                           \
    }                                                                                               \
    attributes void name##_repair(const ga_safe *g, int nj, ga_lanes *sc, double *penalty)         \
    {                                                                                               \
        ga_safe_repair(g, nj, sc, penalty);                                                         \
    }
KERNEL(generic, )
#if defined(__x86_64__) && defined(__GNUC__)
KERNEL(avx2, __attribute__((target("avx2,fma"))))
KERNEL(avx512, __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq,avx2,fma"))))
#endif

static uint64_t state = 88172645463325252ULL;
static float draw(void) /* uniform in [-0.5, 0.5) */
{
    state ^= state << 13, state ^= state >> 7, state ^= state << 17;
    return (float)(state >> 40) * 0x1.0p-24f - 0.5f;
}

static int compare(kernel_fn f, const char *name, const ga_window *x, ga_lanes *sc, int count)
{
    double want[GA_LANES], got[GA_LANES];
    long n_want, n_got, i;
    const long n = GA_LANES * (x->horizon + 1);
    float *far = malloc(sizeof(float) * (size_t)(n * x->nj));
    long *far_at = malloc(sizeof(long) * (size_t)n);
    int same;
    plain_kernel(x, sc, count, want, &n_want);
    for (i = 0; i < n_want * x->nj; ++i) far[i] = sc->far[i];
    for (i = 0; i < n_want; ++i) far_at[i] = sc->far_at[i];
    f(x, sc, count, got, &n_got);
    same = n_got == n_want && !memcmp(got, want, sizeof want);
    for (i = 0; same && i < n_want * x->nj; ++i) same = far[i] == sc->far[i];
    for (i = 0; same && i < n_want; ++i) same = far_at[i] == sc->far_at[i];
    if (!same)
        printf("%s nj %d horizon %ld quadratic %d count %d: %ld steps outside (plain: %ld), lane 1 %.17g (plain: %.17g)\n",
               name, x->nj, x->horizon, x->quadratic, count, n_got, n_want, got[1], want[1]);
    free(far);
    free(far_at);
    return !same;
}

/* The safe variant's repair of the block's gains sc->K (nj joints) by f against plain_repair's:
 * the same penalties and the same repaired gains, bit for bit; sc->K is left as it was. */
static int compare_repair(repair_fn f, const char *name, const ga_safe *g, int nj, ga_lanes *sc)
{
    const size_t size = sizeof(float[GA_LANES]) * (size_t)(2 * nj * nj);
    float(*K)[GA_LANES] = malloc(size), (*repaired)[GA_LANES] = malloc(size);
    double want[GA_LANES], got[GA_LANES];
    int same;
    memcpy(K, sc->K, size);
    plain_repair(g, nj, sc, want);
    memcpy(repaired, sc->K, size);
    memcpy(sc->K, K, size);
    f(g, nj, sc, got);
    same = !memcmp(got, want, sizeof want) && !memcmp(repaired, sc->K, size);
    if (!same)
        printf("%s repair nj %d tuned %d: lane 1 penalty %.17g (plain: %.17g)\n", name, nj, g->nkv > 0, got[1], want[1]);
    memcpy(sc->K, K, size);
    free(K);
    free(repaired);
    return !same;
}

/* Both comparisons for every x86-64 level the CPU has. */
static int compare_levels(const ga_window *x, ga_lanes *sc, int count, const ga_safe *g)
{
    int bad = compare(generic, "generic", x, sc, count) + compare_repair(generic_repair, "generic", g, x->nj, sc);
#if defined(__x86_64__) && defined(__GNUC__)
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"))
        bad += compare(avx2, "avx2", x, sc, count) + compare_repair(avx2_repair, "avx2", g, x->nj, sc);
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512bw")
        && __builtin_cpu_supports("avx512dq"))
        bad += compare(avx512, "avx512", x, sc, count) + compare_repair(avx512_repair, "avx512", g, x->nj, sc);
#endif
    return bad;
}

int main(void)
{
    int bad = 0, trial, nj;
    for (trial = 0; trial < 24; ++trial)
        for (nj = 1; nj <= 21; ++nj) {
            const long H = 1 + trial % 20, n = GA_LANES * (H + 1);
            const int count = trial % 3 == 2 ? 1 + trial % GA_LANES : GA_LANES;
            ga_window x;
            ga_lanes sc;
            double *state0 = calloc((size_t)(4 * nj), sizeof(double)), *q_d = calloc((size_t)(2 * (H + 1) * nj), sizeof(double));
            long i;
            int g, c;
            memset(&x, 0, sizeof x), memset(&sc, 0, sizeof sc);
            x.nj = nj, x.n_genes = 2 * nj * nj, x.horizon = H, x.dt = 1e-3, x.quadratic = trial & 1;
            x.exact_above2 = trial % 4 == 3 ? 0.0 : 4e-6 * (1.0 + draw()) * nj;
            for (i = 0; i < nj; ++i) state0[i] = 2e-3 * draw(), state0[nj + i] = 1e-2 * draw();
            x.q0 = state0, x.qd0 = state0 + nj, x.q_d = q_d, x.qd_d = q_d + (H + 1) * nj;
            x.r = malloc(sizeof(float) * (size_t)(H * nj)), x.s = malloc(sizeof(float) * (size_t)(H * nj));
            x.jac_f = malloc(sizeof(float) * (size_t)((H + 1) * 3 * nj)), x.off_f = malloc(sizeof(float) * (size_t)((H + 1) * 3));
            x.coef = malloc(sizeof(float) * (size_t)(H * 3 * nj * nj)), x.row_used = malloc((size_t)(3 * nj));
            x.moves = malloc(sizeof(int) * (size_t)nj);
            for (i = 0; i < H * nj; ++i) x.r[i] = 1e-5f * draw(), x.s[i] = 1e-3f * draw();
            for (i = 0; i < (H + 1) * 3 * nj; ++i) x.jac_f[i] = draw();
            for (i = 0; i < (H + 1) * 3; ++i) x.off_f[i] = 1e-3f * draw();
            for (i = 0; i < H * 3 * nj * nj; ++i) x.coef[i] = draw();
            for (i = 0; i < 3 * nj; ++i) x.row_used[i] = draw() > -0.2f;
            for (i = 0; i < nj; ++i) x.moves[i] = draw() > -0.3f ? -1 : 0;
            sc.K = malloc(sizeof(float[GA_LANES]) * (size_t)(2 * nj * nj));
            for (g = 0; g < 2 * nj * nj; ++g)
                for (c = 0; c < GA_LANES; ++c)
                    sc.K[g][c] = (g % (nj + 1) ? 0.0f : g < nj * nj ? 5000.0f : 300.0f) * (1.0f + 0.3f * draw()) + 50.0f * draw();
            sc.far = malloc(sizeof(float) * (size_t)(n * nj)), sc.far_at = malloc(sizeof(long) * (size_t)n);
            {
                const double lo_tab[3] = {3000.0, 3500.0, 4000.0}, hi_tab[3] = {6000.0, 5500.0, 7000.0};
                const ga_safe g = {1, 300.0, 3500.0, 6500.0, trial % 2 ? 3 : 0, 150.0, lo_tab, hi_tab};
                sc.sym = malloc(sizeof(double[GA_LANES]) * (size_t)(nj * nj));
                sc.shifted = malloc(sizeof(double[GA_LANES]) * (size_t)(nj * nj));
                bad += compare_levels(&x, &sc, count, &g);
                free(sc.sym), free(sc.shifted);
            }
            free(state0), free(q_d), free(x.r), free(x.s), free(x.jac_f), free(x.off_f), free(x.coef);
            free(x.row_used), free(x.moves), free(sc.K), free(sc.far), free(sc.far_at);
        }
    printf("%d differences\n", bad);
    return bad != 0;
}
#endif
