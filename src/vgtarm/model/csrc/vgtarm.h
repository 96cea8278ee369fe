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
} vgt_model;

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
} vgt_run;

/* Evaluate one generated function over n samples (batch.c). */
int vgt_batch(vgt_fn f, vgt_int sz_arg, vgt_int sz_res, vgt_int sz_iw, vgt_int sz_w,
              int n_in, int n_out, long n,
              const double *const *in, const long *in_stride,
              double *const *out, const long *out_stride);

/* Run computed force control on the plant for samples k0 .. k1-1 (closed_loop.c). */
int vgt_simulate(const vgt_model *m, const vgt_settings *s, const vgt_run *r,
                 const double *Kp, const double *Kv, long k0, long k1, long *stop);

/* Predicted tip error of n_cand gain candidates over a horizon (closed_loop.c). */
int vgt_ga_fitness(const vgt_model *m, const vgt_settings *s, const double *p_ctrl, long horizon,
                   const double *q0, const double *qd0, const double *q_d, const double *qd_d,
                   const double *qdd_d, const double *tip_d, long n_cand, const double *Kp,
                   const double *Kv, double *fitness);

/* Size and field offsets of the interface's structures as this compiler lays them out,
 * written into out in the order interface.py asks (generated at build time: layout.c). */
void vgt_layout(long *out);
