/* The one interface between Python and the compiled drivers of vgtarm.
 *
 * The C sources include this file, and vgtarm/model/interface.py hands the same text to cffi's
 * cdef, so every structure, code and signature is written once. It therefore holds only what
 * cffi's parser accepts: plain typedefs, structures, enums and prototypes, and no preprocessor
 * directive (each C file includes it exactly once).
 */

typedef long long vgt_int;

/* A CasADi-generated function: arguments, results, integer and real work arrays, memory id. */
typedef int (*vgt_fn)(const double **arg, double **res, vgt_int *iw, double *w, int mem);

/* A generated function with the sizes of its work arrays. */
typedef struct {
    vgt_fn f;
    vgt_int sz_arg, sz_res, sz_iw, sz_w;
} vgt_call;

/* The generated functions the closed loop calls. */
typedef struct {
    vgt_call cfc;       /* q, qd, q_d, qd_d, qdd_d, Kp, Kv, p -> F          */
    vgt_call fd;        /* q, qd, F, f, p -> qdd                            */
    vgt_call tip_state; /* q, qd, p -> tip, tip velocity                    */
    vgt_call tip;       /* q, p -> tip                                      */
    vgt_call id;        /* q, qd, qdd, f, p -> F (inverse dynamics)         */
    vgt_call jac;       /* q, p -> J_P, J_W                                 */
    vgt_call tip_hessian; /* q, p -> H (3, nj, nj), row-major: tip Hessian  */
} vgt_model;

/* What the controller adds to computed force control to cancel external efforts. */
enum vgt_observer {
    VGT_OBSERVER_NONE = 0,     /* plain computed force control                                  */
    VGT_OBSERVER_MOMENTUM = 1, /* generalised-momentum disturbance observer, first order         */
    VGT_OBSERVER_FORCE = 2     /* tip force sensor, one period late, through J_P^T              */
};

/* How the controller estimates joint velocities (with sensing). */
enum vgt_estimator {
    VGT_ESTIMATOR_DIFFERENCE = 0, /* encoder differences through a first-order filter (the default) */
    VGT_ESTIMATOR_KALMAN = 1      /* steady-state Kalman filter on the encoder positions, process      */
                                  /* model the controller model's forward dynamics under the applied */
                                  /* effort plus an estimated acceleration disturbance (a state)     */
};

/* Integrators of the plant. */
enum vgt_integrator {
    VGT_EULER = 0,               /* explicit Euler                                 */
    VGT_SEMI_IMPLICIT_EULER = 1, /* velocity first, then position (symplectic)     */
    VGT_RK4 = 2                  /* classical Runge-Kutta                          */
};

/* What a driver call returns. */
enum vgt_status {
    VGT_DONE = 0,            /* every requested sample was run                       */
    VGT_ABOVE_THRESHOLD = 1, /* stopped before a sample whose tip error is too large */
    VGT_PAUSED = 2,          /* vgt_simulate_slice: the slice's budget is used up     */
    VGT_NOT_FINITE = -1,     /* the state is no longer finite                        */
    VGT_NOT_ASSEMBLABLE = -2,/* a leg set can no longer be assembled                 */
    VGT_OUTSIDE_LIMITS = -3, /* a joint is far outside its limits                    */
    VGT_FUNCTION_FAILED = -4,/* a generated function returned an error               */
    VGT_NO_MEMORY = -5       /* a work array could not be allocated                  */
};

typedef struct {
    int n_joints;           /* joints of the model (sizes every joint-space array)        */
    int n_margins;          /* rows of the assembly margins G q + h                       */
    double dt;              /* control period (s)                                         */
    int integrator;         /* an enum vgt_integrator                                     */
    int substeps;           /* integration steps per control period                       */
    int cutting;            /* 1: cutting force -F0 V/|V| on the tool                      */
    double cutting_force;   /* F0 (N)                                                     */
    double cutting_speed;   /* |V| below which the cutting force is zero (m/s)            */
    double threshold;       /* stop before controlling a sample whose tip error exceeds it */
    double limit_tolerance; /* distance outside a joint limit that counts as divergence   */
    int observer;           /* an enum vgt_observer                                       */
    double observer_gain;   /* K_O (1/s) of the momentum observer                         */
    int sensing;            /* 1: the controller sees encoder-quantised, differenced state */
    double velocity_filter; /* sensing: weight of the previous velocity estimate, [0, 1)   */
    int estimator;          /* sensing: an enum vgt_estimator                              */
    double kalman_gain[3];  /* VGT_ESTIMATOR_KALMAN: gains of position, velocity and       */
                            /* disturbance on the position innovation (per joint, the same) */
    int threshold_measured; /* 1: the threshold is on the tip error the controller sees: the  */
                            /* model's tip at q_meas against tip_d; 0: the true tip error     */
    int tool_feedforward;   /* 1: the expected tool force (vgt_run.tool_force_expected) is fed */
                            /* forward, F -= J_P(q_meas)^T f_exp_k, and the observer and the   */
                            /* Kalman process model take it as known (they estimate the rest)  */
    int saturation;         /* 1: the controller clips its effort to the actuators' peak forces */
                            /* (vgt_clip, vgt_control.h: F, the observer and the estimator get */
                            /* it), and the plant delivers it as the actuators can at each      */
                            /* stage's velocity (vgt_saturate: the force-speed lines)           */
} vgt_settings;

/* One run: n samples of an n_joints robot (nj below). */
typedef struct {
    long n;                                 /* number of samples                          */
    const double *q_d, *qd_d, *qdd_d;       /* (n, nj) joint reference                     */
    const double *tip_d;                    /* (n, 3) desired tip P(q_d)                    */
    const double *disturbance;              /* (n, 3) random tool force, held per sample   */
    const double *p_plant, *p_ctrl;         /* parameter vectors                           */
    const double *G, *h;                    /* (n_margins, nj), (n_margins) margins G q + h */
    const double *q_min, *q_max;            /* (nj) joint limits                           */
    double *q, *qd;                         /* (n, nj) state; row 0 is the initial state   */
    double *F, *f_ext, *tip, *error;        /* (n, nj), (n, 3), (n, 3), (n)                */
    const double *resolution;               /* (nj) encoder step of each joint (0: exact)   */
    const double *velocity_noise;           /* (n, nj) noise on the differenced velocity    */
    double *q_meas, *qd_meas;               /* (n, nj) what the controller sees              */
    double *tau_hat;                        /* (n, nj) estimated external joint efforts      */
    double *x_hat;                          /* (n, 4 nj) Kalman estimator: q^, v^, d^ and the */
                                            /* model's acceleration over the period before   */
    double *seen;                           /* (n) the tip error the threshold was tested on, */
                                            /* at each sample where it was (NULL: not kept)  */
    const double *tool_force_expected;      /* (n, 3) expected tool force on the tip (N), fed */
                                            /* forward with settings.tool_feedforward        */
    const double *force_limit;              /* (nj) actuators' peak force (inf: none), with   */
    const double *speed_limit;              /* (nj) their no-load speed and                   */
    const double *force_speed;              /* (nj) 1 where the force-speed line holds        */
                                            /* (settings.saturation)                          */
} vgt_run;

/* Evaluate one generated function over n samples (batch.c). */
int vgt_batch(vgt_fn f, vgt_int sz_arg, vgt_int sz_res, vgt_int sz_iw, vgt_int sz_w,
              int n_in, int n_out, long n,
              const double *const *in, const long *in_stride,
              double *const *out, const long *out_stride);

/* One state of a generated function with the checks of Robot's batch path (single.c): the caller
 * copies the state into x and sets the argument pointers into it (and the parameters) and the
 * result pointers into y; the call keeps every pointer. */
typedef struct {
    vgt_fn f;                 /* the generated function                                       */
    const double **arg;       /* its arguments: into x, then the parameters                    */
    double **res;             /* its results: into y                                          */
    vgt_int *iw;              /* its work arrays, of the sizes it reports                     */
    double *w;
    long n_x;                 /* x: a 1, then the inputs one after the other (q first)        */
    const double *x;          /* (n_x) the state                                              */
    const double *low, *high; /* (n_x) accepted bounds, inclusive ([1, 1] for the 1)          */
    long n_margins;           /* rows of the trusted triangle margins                         */
    long n_columns;           /* 1 + joints                                                   */
    const double *margins;    /* (n_margins, n_columns) row by row: the margin less its trust */
                              /* is the row's product with x[0 .. n_columns - 1], [1, q]      */
    long n_y;                 /* y: every output one after the other                          */
    const double *y;          /* (n_y)                                                        */
} vgt_single;

/* What vgt_single_call returns: DONE, else why the batch path must decide. */
enum vgt_single_status {
    VGT_SINGLE_DONE = 0,       /* every check passed: y holds the result                       */
    VGT_SINGLE_OUTSIDE = 1,    /* an input is not finite or outside its bounds (y untouched)   */
    VGT_SINGLE_MARGIN = 2,     /* a triangle margin is below its trust (y untouched)           */
    VGT_SINGLE_FAILED = 3,     /* the generated function returned an error                     */
    VGT_SINGLE_NOT_FINITE = 4  /* an output is not finite                                      */
};

/* Check the state, evaluate the function once, check its outputs (single.c). */
int vgt_single_call(const vgt_single *s);

/* Run computed force control on the plant for samples k0 .. k1-1 (closed_loop.c). */
int vgt_simulate(const vgt_model *m, const vgt_settings *s, const vgt_run *r,
                 const double *Kp, const double *Kv, long k0, long k1, long *stop);

/* A run in slices of bounded work, so that the caller regains control (Ctrl-C) between them. */
typedef struct {
    long budget;   /* in: work units this call may do: one per sub-step integrated and one per   */
                   /* sample controlled (<= 0: no limit); at least one is done                    */
    long used;     /* out: work units done                                                        */
    long substep;  /* in/out: sub-steps of sample k0's integration already done (0: none; then    */
                   /* sample k0 is controlled first), where the last call paused                  */
    double *q, *qd;/* (nj) in/out: the plant state after `substep` sub-steps of that sample        */
} vgt_slice;

/* vgt_simulate that stops when slice->budget is used up: returns VGT_PAUSED with *stop = the
 * sample to continue from (call again with k0 = *stop and the same slice); every result is the
 * same, bit for bit, as one uninterrupted call. slice NULL: no limit (vgt_simulate). */
int vgt_simulate_slice(const vgt_model *m, const vgt_settings *s, const vgt_run *r,
                       const double *Kp, const double *Kv, long k0, long k1, long *stop, vgt_slice *slice);

/* Predicted tip error of n_cand gain candidates over a horizon (closed_loop.c). */
int vgt_ga_fitness(const vgt_model *m, const vgt_settings *s, const double *p_ctrl, long horizon,
                   const double *q0, const double *qd0, const double *q_d, const double *qd_d,
                   const double *qdd_d, const double *tip_d, long n_cand, const double *Kp,
                   const double *Kv, double *fitness);

int vgt_ga_fitness_limited(const vgt_model *m, const vgt_settings *s, const double *p_ctrl, long horizon,
                           const double *q0, const double *qd0, const double *q_d, const double *qd_d,
                           const double *qdd_d, const double *tip_d, const double *force_limit,
                           const double *speed_limit, const double *force_speed, long n_cand, const double *Kp,
                           const double *Kv, double *fitness);

/* Size and field offsets of the interface's structures as this compiler lays them out,
 * written into out in the order interface.py asks (generated at build time: layout.c). */
void vgt_layout(long *out);

/* ---- The compiled genetic algorithm of the switching control method (ga.c) ---------------- */

/* How the GA predicts the tip error of a gain candidate over the horizon. */
enum vgt_prediction {
    VGT_PREDICT_EXACT = 0,    /* Euler steps of the joints, exact forward kinematics of each step */
    VGT_PREDICT_LINEAR = 1,   /* the same joint errors by their linear recursion, mapped to the   */
                              /* tip through the tip Jacobian at the reference                    */
    VGT_PREDICT_QUADRATIC = 2 /* as LINEAR plus the second-order term of the forward kinematics   */
};

typedef struct {
    int n_genes;            /* genes per individual (2 nj^2: Kp then Kv, row by row)           */
    int n_bits;             /* bits per gene, 1..32, most significant first                    */
    int words;              /* 64-bit words per individual (>= ceil(n_genes n_bits / 64) + 1)  */
    int population;         /* individuals per generation                                      */
    int generations;        /* generations after the initial population                        */
    int elite;              /* best individuals copied unchanged into the next generation      */
    int n_seeded;           /* rows of initial_bits that start the first population            */
    int prediction;         /* an enum vgt_prediction                                          */
    double p_crossover;     /* probability that a pair of parents is crossed                    */
    double p_mutation;      /* probability that a child's bit flips                             */
    long horizon;           /* prediction horizon H in control periods                          */
    double exact_above;     /* LINEAR/QUADRATIC: a candidate whose predicted joint error norm  */
                            /* exceeds this (m, rad) is predicted exactly instead (0: never)    */
    int threads;            /* threads that predict a generation's candidates (OpenMP; 1: none) */
                            /* any count gives the same activation bit for bit; a generation    */
                            /* whose prediction stalls (another thread not scheduled: a busy     */
                            /* machine) makes the rest of the activation use one                 */
    int safe;               /* 1: the safe variant (control/safety.py): Kp symmetrised, Kv = safe_kv */
                            /* times the identity, a candidate admitted only when the eigenvalues */
                            /* of its Kp lie in [safe_lo, safe_hi], others penalised (cost > 1);  */
                            /* the result falls back to the seeded (fixed) gains unless admitted  */
                            /* and predicted better than them. 0: the paper's GA, unchanged       */
    double safe_kv;         /* the damping of the safe variant (1/s)                              */
    double safe_lo, safe_hi;/* the admitted interval of the eigenvalues of Kp (1/s^2)             */
    int safe_nkv;           /* > 0: the damping is tuned too: Kv = kv_j I with kv_j = j safe_kv_step */
                            /* (j = 0 .. safe_nkv - 1) the grid point nearest to the mean of the   */
                            /* candidate's Kv diagonal, admitted iff the eigenvalues of Kp lie in  */
                            /* [safe_lo_tab[j], safe_hi_tab[j]] (NaN: none); safe_kv, safe_lo and  */
                            /* safe_hi are then unused. 0: Kv = safe_kv I held                     */
    double safe_kv_step;    /* the grid's step (1/s)                                               */
    const double *safe_lo_tab, *safe_hi_tab; /* (safe_nkv) the admitted intervals per grid point  */
} vgt_ga_settings;

/* One activation: the state at sample k and the reference rows k .. k+H. */
typedef struct {
    const double *lower, *upper;            /* (n_genes) gene bounds                           */
    const uint64_t *initial_bits;           /* (n_seeded, words) seeded individuals            */
    const double *p_ctrl;                   /* controller's parameter vector                   */
    const double *q0, *qd0;                 /* (nj) state at sample k                          */
    const double *q_d, *qd_d, *qdd_d;       /* (H+1, nj) reference                             */
    const double *tip_d;                    /* (H+1, 3) desired tip                            */
    double *tip_offset;                     /* (H+1, 3) tip_d - P^(q_d) (zero for exact kinematics) */
    double *J_d;                            /* (H+1, 3, nj) tip Jacobian of the model at q_d   */
    double *H_d;                            /* (H+1, 3, nj, nj) tip Hessian at q_d (QUADRATIC) */
    unsigned char *ready;                   /* (H+1) 1 where the three rows above are computed: */
                                            /* the GA computes the others when it needs them   */
                                            /* and sets the flag (NULL: all given)              */
    const double *force_limit;              /* (nj) actuators the prediction clips to: peak   */
    const double *speed_limit;              /*   force, no-load speed, 1 where the force-speed */
    const double *force_speed;              /*   line holds (force_limit NULL: no actuators)  */
    double *F_d, *M_d, *Minv_d, *D_d;       /* with force_limit: (H+1, nj), (H+1, nj, nj) x3: */
                                            /* the model's effort ID(q_d, qd_d, qdd_d), M(q_d),*/
                                            /* M(q_d)^-1 and dID/dqd, rows computed with the   */
                                            /* rows above                                      */
} vgt_ga_problem;

typedef struct {
    double *best;           /* (n_genes) decoded genes of the best individual                    */
    double best_cost;       /* its predicted tip error                                           */
    double seeded_cost;     /* predicted tip error of the first seeded individual (or NaN)       */
    long generations;       /* generations run                                                   */
    long evaluations;       /* candidates whose prediction was computed                          */
    long exact_candidates;  /* of those, recomputed for leaving the trust region                  */
    long exact_steps;       /* steps of those mapped by the exact forward kinematics              */
    int threads;            /* threads predicting at the end (fewer than asked after a stall)    */
    int dropped;            /* safe variant: the GA's best was not admitted or not better than the */
                            /* fixed gains, which `best` then holds                               */
} vgt_ga_result;

/* One GA activation: evolve the gains from a seeded first population, all in C. */
int vgt_ga_activation(const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g,
                      const vgt_ga_problem *pb, uint64_t seed, vgt_ga_result *out);

/* Switching control in the loop (ga.c): the run's GA and where its activations are recorded. */
typedef struct {
    const vgt_ga_settings *g;     /* the GA (its horizon is the full one; shortened near the end)  */
    const vgt_ga_problem *pb;     /* the reference and its tip derivatives from sample 0 (q0, qd0  */
                                  /* are taken from the measured state of each activation)         */
    const uint64_t *seeds;        /* (max_activations) generator seed of each GA activation, in order */
    long max_activations;         /* capacity of the records below                                 */
    long count;                   /* activations recorded so far (the next one is record `count`)  */
    long seeds_used;              /* seeds taken so far (the last sample activates without a GA)   */
    long *sample;                 /* (max) sample of each activation                               */
    long *generations, *evaluations; /* (max) GA work                                              */
    double *best_cost;            /* (max) predicted tip error of the gains applied                */
    double *seeded_cost;          /* (max) predicted tip error of the fixed gains                  */
    double *wall_time;            /* (max) seconds spent in the GA                                 */
    long *threads;                /* (max) threads predicting at the end of the activation         */
    double *q0, *qd0;             /* (nj) work: the measured state handed to the GA                */
    double *best;                 /* (n_genes) work: the GA's best genes (Kp then Kv, row by row)  */
    vgt_slice *slice;             /* bounded work per call (NULL: none); see vgt_simulate_slice     */
    long skip;                    /* activations left to run on one thread after a stall            */
    long backoff;                 /* length of the next such spell (doubles while stalls repeat,    */
                                  /* back to 1 after an activation on threads without one; init 1) */
    int pending;                  /* a call paused inside an activation's sample: 1 under the GA's */
                                  /* gains (best), 2 under the fixed ones (the last sample); 3 in  */
                                  /* the sample of a dropped held set (fixed gains, no record); 0 none */
    long hold;                    /* periods an admitted (not dropped) gain set controls, counting  */
                                  /* its activation's sample (0 or 1: that sample only, the paper)  */
    long hold_left;               /* samples the current set still controls after its activation's */
    unsigned char *held;          /* (n) 1 at each sample controlled by a held set, 2 at the sample */
                                  /* where one was dropped (the fixed gains) (NULL: hold <= 1)      */
    double hold_above;            /* the error seen at the held set's activation: the set is dropped */
                                  /* at the first held sample whose seen error exceeds it           */
    long watch_from;              /* the first held period (the activation's sample is 0) watched  */
} vgt_switching;

/* Samples k0 .. k1-1 under the switching control method: the fixed gains Kp, Kv while the tip
 * error stays within s->threshold; at a sample above it, one GA activation from the measured
 * state, whose gains control that sample (with `unswitched`, s without the threshold) and, when
 * sw->hold > 1 and the set was not dropped, the next sw->hold - 1 samples too (held), unless the
 * error seen at one of them (the threshold's, r->seen) exceeds the one seen at the activation:
 * the set is then dropped and that sample runs with the fixed gains (`unswitched`). Returns
 * VGT_DONE, a failure status (with *stop), VGT_ABOVE_THRESHOLD with *stop = the sample when
 * the records are full, or VGT_PAUSED with *stop = the sample to continue from when sw->slice's
 * budget ran out (call again with k0 = *stop; the results are the same bit for bit). */
int vgt_simulate_switching(const vgt_model *m, const vgt_settings *s, const vgt_settings *unswitched,
                           const vgt_run *r, const double *Kp, const double *Kv, vgt_switching *sw, long k0,
                           long k1, long *stop);

/* Predicted tip error of n_cand decoded candidates (genes, row by row), as the GA computes it. */
int vgt_ga_predict(const vgt_model *m, const vgt_settings *s, const vgt_ga_settings *g,
                   const vgt_ga_problem *pb, long n_cand, const double *genes, double *cost);

/* The GA's operators, exported for the tests (each given its random draws explicitly). */
void vgt_ga_decode(const vgt_ga_settings *g, long rows, const uint64_t *bits, const double *lower,
                   const double *upper, double *genes);
void vgt_ga_rank_expectations(long n, const double *cost, long n_parents, double *expectation);
void vgt_ga_sus(long n, const double *expectation, long n_select, double u, long *selected);
void vgt_ga_crossover(int words, long rows, uint64_t *bits, const unsigned char *crossed,
                      const uint64_t *masks);
void vgt_ga_flip(int words, uint64_t *bits, long n_flips, const long *positions);
/* 8-bit genes decoded as the prediction decodes them (single precision, into `genes`, rows x
 * g->n_genes), with the vector path when `vector` is nonzero and the CPU has AVX2;
 * VGT_FUNCTION_FAILED unless the genes have 8 bits. */
int vgt_ga_decode_single(const vgt_ga_settings *g, long rows, const uint64_t *bits, const double *lower,
                         const double *upper, int vector, float *genes);

/* The GA's generator (xoshiro256**, seeded through splitmix64), exported for the tests. */
void vgt_rng_uniform(uint64_t seed, long n, double *out);
void vgt_rng_mutation_positions(uint64_t seed, long total, double p, long max_flips, long *positions,
                                long *n_flips);

/* ---- Force-controlled drilling (drill_loop.c, vgt_drill_control.h; docs/drilling_control.md) ---- */

/* The generated functions the drilling loop calls (the symbolic library's names, Robot's methods). */
typedef struct {
    vgt_call tip;         /* q, p -> tip                                           */
    vgt_call velocity;    /* q, qd, p -> tip velocity, angular velocity            */
    vgt_call jac;         /* q, p -> J_P, J_W (row-major)                          */
    vgt_call fk;          /* q, p -> ..., C03 (its last output, row-major)          */
    vgt_call bias_acc;    /* q, qd, p -> Jdot qd of the tip, angular, bodies ...    */
    vgt_call mass;        /* q, p -> M (row-major)                                 */
    vgt_call bias_forces; /* q, qd, p -> C                                         */
    vgt_call id;          /* q, qd, qdd, f, p -> F                                 */
    int n_fk_outputs;     /* outputs of fk (C03 is the last)                       */
    int n_bias_outputs;   /* outputs of bias_acc (the tip's and the angular first) */
} vgt_drill_model;

/* A layered bone (vgtarm.drilling.Bone) as vgt_drill_forces takes it. */
typedef struct {
    int n_layers;
    const double *boundaries;   /* (n_layers + 1) interface depths (m)                    */
    const double *coefficients; /* (n_layers, VGT_DRILL_COEFFICIENTS) the law's rows       */
    double point_length, chisel_length, chisel_share, feed_ref, speed_ref, feed_floor;
    double cap_strength;        /* (Pa) the cap ahead of the apex breaks out once thinner than */
    double cap_factor;          /* sqrt(cap_factor thrust / cap_strength); 0: never          */
} vgt_drill_bone;

/* A drilling run's settings (vgtarm.drilling.control.DrillingSettings, SI units) and what the
 * controller is told of the bone (its layer count and the law's feed exponent and feed scales). */
typedef struct {
    int n_joints;
    double dt;                  /* control period (s)                                        */
    int substeps;               /* plant steps per period                                    */
    double set_point;           /* thrust (N)                                                */
    double feed_limit;          /* (m/s)                                                     */
    double spindle_speed;       /* (rad/s)                                                   */
    int mode;                   /* 0 explicit force control, 1 admittance                     */
    int feedback;               /* 0 the observer's estimate, 1 a tip force sensor            */
    double tare_time;           /* (s)                                                       */
    double velocity_keep;       /* the velocity filter's weight of its previous value        */
    double observer_keep;       /* exp(-K_O dt)                                              */
    double hold_frequency, axial_frequency, null_frequency; /* (Hz)                          */
    double force_gain, force_rate, feed_lead;
    double admittance_mass, admittance_time, admittance_share;
    double estimate_time, feed_time, layer_change;
    int layer_samples;
    double breakthrough_fraction;
    int breakthrough_samples;
    double settle_time, retract_distance, retract_speed;
    double stop_hold, end_hold; /* hold after the stop and after the retract (s)             */
    long max_samples;           /* the run's longest length (samples)                        */
    int tool_torque;            /* 1: the cutting torque acts on the end-effector             */
    double exponent;            /* the told bone's thrust feed exponent                       */
    int told_layers;            /* the told bone's layer count                                */
    double told_feed_ref, told_feed_floor;
    double gap;                 /* the tip's start before the entry surface (m)              */
    double arm_depth;           /* depths (m) past which the breakthrough is armed with the   */
    double arm_depth_late;      /* layer count behind by two or more, and by one             */
    const double *force_limit;  /* (nj) the actuators' peak forces the controller clips its   */
                                /* efforts to (vgt_clip), NULL: no actuators                 */
} vgt_drill_settings;

/* One drilling run of an n_joints robot (nj): inputs, then what the run writes. */
typedef struct {
    const double *q0;              /* (nj) start, at rest                                     */
    const double *p_plant, *p_ctrl;/* parameter vectors                                      */
    const double *steps;           /* (nj) encoder steps (0: exact)                          */
    const double *entry;           /* (3) entry point (m, F0)                                */
    const double *frame;           /* (3, 3) row-major: columns e1, e2, the drilling axis      */
    const double *tool_axis;       /* (3) the tool's axis in the end-effector frame            */
    double *series;                /* (max_samples, 13) vgtarm.drilling.loop.SERIES             */
    double *efforts;               /* (max_samples, nj)                                       */
    double *q_meas;                /* (max_samples, nj) the encoder readings (NULL: not kept)   */
    const double *speed_limit;     /* (nj) with settings.force_limit: the plant delivers the    */
    const double *force_speed;     /* efforts through the force-speed lines (vgt_saturate)     */
    double *events;                /* (max_events, 3): t, kind (enum vgt_drill_event), layer   */
    long max_events;
    long n_samples, n_events;      /* out                                                     */
    double fracture_time;          /* out: when the cap broke out (s), NaN if it did not       */
} vgt_drill_run;

/* The phases of a drilling run and the detector's events (vgtarm.drilling.control.PHASES). */
enum vgt_drill_phase {
    VGT_DRILL_TARE = 0,       /* holding still while the observer's offset is measured */
    VGT_DRILL_DRILLING = 1,   /* the thrust regulated, the detector watching            */
    VGT_DRILL_STOPPING = 2,   /* the feed stopped at the breakthrough                   */
    VGT_DRILL_RETRACTING = 3, /* moving back along the axis                              */
    VGT_DRILL_DONE = 4
};
enum vgt_drill_event {
    VGT_DRILL_CONTACT = 0,
    VGT_DRILL_SOFTER = 1,
    VGT_DRILL_HARDER = 2,
    VGT_DRILL_BREAKTHROUGH = 3,
    VGT_DRILL_ARMED = 4 /* the breakthrough armed by depth, a transition having been missed */
};

/* The drilling controller's state between periods (vgt_drill_control.h; its joint-space arrays
 * point into memory the caller gives: 10 nj doubles). */
typedef struct {
    int n_meas, n_efforts, n_raw;  /* readings (<= 3), efforts (<= 2), raw velocities (<= 2) kept */
    double *q_meas, *efforts, *v_filtered, *v_raw, *tau_hat, *q_centre;
    int phase;                     /* an enum vgt_drill_phase                                     */
    double offset, tare;           /* the tare's offset (N) and its running sum                    */
    long tare_n;
    double stopped_at, retracted_at, previous_thrust;
    double depth_ref, feed_ref, integral, stop_depth, feed_f; /* the axial loop                    */
    int limited;                   /* explicit mode: on the position loop at the feed limit         */
    double thrust_f, det_feed_f, specific, level, quiet_until; /* the detector                     */
    int count, layer, softer, started;
    double *events;                /* (max_events, 3): t, an enum vgt_drill_event, layer           */
    long max_events, n_events;
} vgt_drill_state;

/* What one period of the drilling controller gives besides the efforts. */
typedef struct {
    double estimate;  /* the thrust fed back (N)                         */
    double observed;  /* the observer's thrust, tared (N)                */
    double push;      /* the explicit mode's axial force (N)             */
    double depth;     /* the measured depth (m) and feed (m/s)           */
    double feed;
} vgt_drill_output;

/* Run the drilling loop: VGT_DONE when the run ended after its retract, VGT_ABOVE_THRESHOLD when
 * max_samples passed without a breakthrough, or a failure status (the samples so far kept). */
int vgt_drill_simulate(const vgt_drill_model *m, const vgt_drill_settings *s, const vgt_drill_bone *bone,
                       vgt_drill_run *r);
