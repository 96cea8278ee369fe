/* The genetic algorithm of switching control for a real-time target (written by `vgtarm export
 * controller --switching ...`).
 *
 * One call of vgtc_ga_activate runs a whole GA activation: the paper's binary-coded algorithm
 * (Appendix B) run by the simulation's own code (vgt_ga.h, which the simulation's compiled GA,
 * vgtarm/model/csrc/ga.c, includes too): the same operators, random stream (xoshiro256** seeded
 * through splitmix64) and arithmetic, so that the same activation (state, reference window, seed)
 * gives the simulation's gains bit for bit. Unlike the simulation it uses no heap, no threads and
 * no intrinsics: every buffer is a member of vgtc_ga, sized at compile time from VGTC_NJ and the
 * GA's sizes in vgtc_config.h (population, words per individual, horizon, mutation flips); the
 * candidates are predicted in blocks of VGTC_GA_LANES in single precision, vectors of GCC's and
 * Clang's extensions or plain loops over the block (VGTC_GA_NO_VECTORS, and other compilers) that
 * the compiler may vectorise (-O3 -march=native does), with fmaf exactly where the simulation's
 * kernel fuses (VGTC_GA_FMA: 1 when the exporting machine ran that kernel with FMA, as x86-64-v3
 * machines do).
 *
 * The fitness is the predicted tip error of a gain candidate over the horizon under the
 * controller's model (vgtarm/control/scm.py): the joint errors on the linear recursion of computed
 * force control (explicit Euler), mapped to the tip by the model's tip Jacobian and Hessian along
 * the reference (quadratic prediction), and steps whose joint error leaves the trust region
 * (exact_above) by the exact forward kinematics.
 *
 * Safe variant (safe = 1): each candidate's Kp is symmetrised and Kv set to kv I (kv held, or the
 * nearest point of a damping grid); a candidate is admitted iff the eigenvalues of its Kp lie in
 * the admitted interval (Cholesky tests), others are penalised; the result falls back to the fixed
 * gains (the first seeded individual) unless admitted and predicted better than them.
 */
#ifndef VGTC_GA_H
#define VGTC_GA_H

#include <stdint.h>

#include "vgtc_config.h"

#ifdef __cplusplus
extern "C" {
#endif

#define VGTC_GA_GENES (2 * VGTC_NJ * VGTC_NJ) /* Kp then Kv, row by row */
#define VGTC_GA_LANES 8 /* candidates predicted together (the inner loops run over them: vectorisable) */

/* What vgtc_ga_init and vgtc_ga_activate return (the controller's status codes). */
enum vgtc_ga_status {
    VGTC_GA_OK = 0,
    VGTC_GA_BAD_ARGUMENT = -1,   /* a NULL pointer, an uninitialised GA, a horizon out of range  */
    VGTC_GA_NOT_FINITE = -2,     /* an input is NaN or infinite                                  */
    VGTC_GA_FUNCTION_FAILED = -4,/* a generated model function failed                            */
    VGTC_GA_BAD_PARAMETER = -6   /* vgtc_ga_init: a parameter out of range or beyond the sizes    */
};

typedef struct {
    double dt;                           /* control period (s)                                   */
    double model[VGTC_NP];               /* the controller model's parameter vector              */
    int population;                      /* individuals per generation (<= VGTC_GA_POPULATION)   */
    int generations;                     /* generations after the first population               */
    int elite;                           /* individuals copied unchanged (< population)          */
    int n_seeded;                        /* seeded individuals (<= VGTC_GA_SEEDED)               */
    double p_crossover, p_mutation;      /* probabilities of crossing a pair, flipping a bit     */
    long horizon;                        /* prediction horizon (periods, <= VGTC_GA_HORIZON)      */
    double exact_above;                  /* joint-error norm beyond which a step is mapped by the */
                                         /* exact forward kinematics (0: never)                  */
    int quadratic;                       /* 1: second-order tip map (tip Hessian), 0: first-order */
    double lower[VGTC_GA_GENES], upper[VGTC_GA_GENES]; /* gene bounds (8-bit genes)              */
    uint64_t initial_bits[VGTC_GA_SEEDED * VGTC_GA_WORDS]; /* seeded individuals, packed bits    */
    int safe;                            /* 1: the safe variant                                  */
    double safe_kv, safe_lo, safe_hi;    /* held damping and its admitted eigenvalue interval     */
    int safe_nkv;                        /* > 0: the damping grid's points (<= VGTC_GA_NKV)       */
    double safe_kv_step;                 /* its step (1/s)                                       */
    double safe_lo_tab[VGTC_GA_NKV], safe_hi_tab[VGTC_GA_NKV]; /* admitted interval per point     */
    int saturation;                      /* 1: the prediction clips the effort to the actuators   */
    double force_limit[VGTC_NJ];         /* peak force of each joint (INFINITY: none; N, N m)     */
    double speed_limit[VGTC_NJ];         /* no-load speed (m/s, rad/s)                            */
    double force_speed[VGTC_NJ];         /* 1 where the force-speed line holds, else 0            */
} vgtc_ga_params;

/* What an activation reports. */
typedef struct {
    double best_cost;       /* predicted tip error of the gains returned (m)                       */
    double seeded_cost;     /* that of the first seeded individual (the fixed gains)               */
    long generations;       /* generations run                                                     */
    long evaluations;       /* candidates predicted                                                */
    long exact_steps;       /* steps mapped by the exact forward kinematics                        */
    int dropped;            /* safe variant: the fixed gains replaced the GA's best                */
} vgtc_ga_result;

/* The GA's state: its parameters and every work array (about sizeof(vgtc_ga) bytes; static or
 * caller-provided memory, one per controller). */
typedef struct {
    vgtc_ga_params p;
    int ready;
    long max_flips;
    uint64_t valid[VGTC_GA_WORDS];
    double weights[VGTC_GA_POPULATION];
    float lo[VGTC_GA_GENES], step[VGTC_GA_GENES], hi[VGTC_GA_GENES];
    /* the window: reference rows 0 .. horizon and the model's tip derivatives along it */
    long horizon;
    double q0[VGTC_NJ], qd0[VGTC_NJ];
    double q_d[(VGTC_GA_HORIZON + 1) * VGTC_NJ], qd_d[(VGTC_GA_HORIZON + 1) * VGTC_NJ];
    double qdd_d[(VGTC_GA_HORIZON + 1) * VGTC_NJ], tip_d[(VGTC_GA_HORIZON + 1) * 3];
    double tip_offset[(VGTC_GA_HORIZON + 1) * 3], J_d[(VGTC_GA_HORIZON + 1) * 3 * VGTC_NJ];
    double H_d[(VGTC_GA_HORIZON + 1) * 3 * VGTC_NJ * VGTC_NJ];
    float r[VGTC_GA_HORIZON * VGTC_NJ], s[VGTC_GA_HORIZON * VGTC_NJ];
    float jac_f[(VGTC_GA_HORIZON + 1) * 3 * VGTC_NJ], off_f[(VGTC_GA_HORIZON + 1) * 3];
    float coef[VGTC_GA_HORIZON * 3 * VGTC_NJ * VGTC_NJ];
    unsigned char row_used[3 * VGTC_NJ];
    int moves[VGTC_NJ];
    /* with saturation: the model's effort, mass matrix, its inverse and dID/dqd along the window */
    double F_d[(VGTC_GA_HORIZON + 1) * VGTC_NJ], M_d[(VGTC_GA_HORIZON + 1) * VGTC_NJ * VGTC_NJ];
    double Minv_d[(VGTC_GA_HORIZON + 1) * VGTC_NJ * VGTC_NJ], D_d[(VGTC_GA_HORIZON + 1) * VGTC_NJ * VGTC_NJ];
    float force_f[VGTC_GA_HORIZON * VGTC_NJ], mass_f[VGTC_GA_HORIZON * VGTC_NJ * VGTC_NJ];
    float minv_f[VGTC_GA_HORIZON * VGTC_NJ * VGTC_NJ], damp_f[VGTC_GA_HORIZON * VGTC_NJ * VGTC_NJ];
    float act_f[3 * VGTC_NJ];
    double dynamics_tmp[5 * VGTC_NJ + 3 + VGTC_NJ * VGTC_NJ];
    /* the population */
    uint64_t pop[VGTC_GA_POPULATION * VGTC_GA_WORDS], next[VGTC_GA_POPULATION * VGTC_GA_WORDS];
    uint64_t best_bits[VGTC_GA_WORDS];
    double cost[VGTC_GA_POPULATION], next_cost[VGTC_GA_POPULATION], new_cost[VGTC_GA_POPULATION];
    double expectation[VGTC_GA_POPULATION], work[2 * VGTC_GA_POPULATION + VGTC_GA_LANES];
    double parent_cost[VGTC_GA_POPULATION];
    long order[VGTC_GA_POPULATION], pool[VGTC_GA_POPULATION], fresh[VGTC_GA_POPULATION];
    long flips[VGTC_GA_MAX_FLIPS + 1];
    float K[VGTC_GA_GENES][VGTC_GA_LANES];                /* a block's gains, one lane each      */
    double sym[VGTC_NJ * VGTC_NJ][VGTC_GA_LANES];         /* safe variant: sym(Kp) of each lane,  */
    double shifted[VGTC_NJ * VGTC_NJ][VGTC_GA_LANES];     /* shifted by an edge and factorised   */
    float far[VGTC_GA_LANES * (VGTC_GA_HORIZON + 1) * VGTC_NJ]; /* joint errors outside the region */
    long far_at[VGTC_GA_LANES * (VGTC_GA_HORIZON + 1)];  /* their lane * horizon + step          */
    const uint64_t *rows[VGTC_GA_POPULATION];             /* the candidates of a prediction      */
    long exact_steps;
    /* work of the generated functions */
    const double *arg[VGTC_SZ_ARG];
    double *res[VGTC_SZ_RES];
    long long iw[VGTC_SZ_IW];
    double w[VGTC_SZ_W + 3 * VGTC_NJ];
} vgtc_ga;

/* The exported values of the GA (generated in vgtc_defaults.c). */
void vgtc_ga_default_params(vgtc_ga_params *params);

/* Check the parameters against the compiled sizes; VGTC_GA_OK or VGTC_GA_BAD_PARAMETER. */
int vgtc_ga_init(vgtc_ga *ga, const vgtc_ga_params *params);

/* One activation from the measured state (q0, qd0) over the reference window of `horizon` + 1
 * rows (1 <= horizon <= params.horizon; shorter near the end of a trajectory):
 *   ref:   (horizon + 1) rows of 3 VGTC_NJ values, q_d then qd_d then qdd_d (the rows the
 *          controller gets in vgtc_step, from the activation's period on);
 *   tip_d: (horizon + 1) rows of 3, the desired tip (m); NULL: the model's tip at q_d;
 *   seed:  the generator's seed (an activation is a pure function of its inputs and the seed);
 *   gains: out, VGTC_GA_GENES values: Kp then Kv (row-major) of the best individual;
 *   out:   the activation's record (may be NULL).
 * No allocation, no I/O; its time is bounded by population x generations predictions. */
int vgtc_ga_activate(vgtc_ga *ga, long horizon, const double *q0, const double *qd0, const double *ref,
                     const double *tip_d, uint64_t seed, double *gains, vgtc_ga_result *out);

#ifdef __cplusplus
}
#endif

#endif
