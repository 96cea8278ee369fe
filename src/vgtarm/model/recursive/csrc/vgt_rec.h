/* The recursive model of a stack of VGT modules: the one C interface (read by cffi too).
 *
 * An arm is a serial chain of bodies, base first. Each body hangs on a joint: a module (three
 * legs; its platform pose, motion subspace and bias come from the generated module functions)
 * or a twist (a revolute joint about the z axis of the frame before it). Everything about the arm
 * is data in vgt_rec_arm, so one compiled library serves every arm. Spatial vectors are
 * (angular, linear) in body coordinates; matrices are row-major. */

typedef struct {
    int nb;                 /* bodies (one per joint), base first */
    int nq;                 /* degrees of freedom */
    int nm;                 /* modules (bodies of type 3) */
    const int *type;        /* per body: 3 = module, 1 = twist */
    const int *qi;          /* per body: index in q of its first coordinate */
    const double *tz;       /* per body: offset along the parent frame's z axis before the joint (m) */
    const double *geom;     /* per body: b, d, cos(phi), sin(phi) (used by modules) */
    const double *inertia;  /* per body: 6x6 spatial inertia about the body origin, body coordinates */
    const double *viscous;  /* per degree of freedom: viscous friction */
    const double *gravity;  /* 3: gravity in the base frame (m/s^2) */
    const double *tip;      /* 3: the tip point in the last body's frame (m) */
} vgt_rec_arm;

/* Every function evaluates n samples (row-major arrays, one row per sample) and returns 0, or -1
 * when its scratch memory could not be allocated. A tip wrench fext is (f, m) in base
 * components: f acts at the tip point, m on the last body; NULL means none. */
/* The first sample (or -1) with a module that cannot be assembled: some margin rows[6x3] legs + h
 * <= 0 (h: 6 per module, legs the module's s, v, p), or not a number; where gets (module, row). */
long vgt_rec_unassembled(const vgt_rec_arm *arm, long n, const double *q, const double *rows, const double *h,
                         int *where);
int vgt_rec_fk(const vgt_rec_arm *arm, long n, const double *q, double *tip, double *rot, double *body_pos,
               double *body_rot, double *passive);
int vgt_rec_jacobian(const vgt_rec_arm *arm, long n, const double *q, double *jp, double *jw);
int vgt_rec_mass(const vgt_rec_arm *arm, long n, const double *q, double *m);
int vgt_rec_inverse(const vgt_rec_arm *arm, long n, const double *q, const double *qd, const double *qdd,
                    const double *fext, double *tau);
int vgt_rec_forward(const vgt_rec_arm *arm, long n, const double *q, const double *qd, const double *tau,
                    const double *fext, double *qdd);
/* Forward and inverse dynamics and the mass matrix run blocks of samples side by side in the lanes
 * of vectors where the compiler and the CPU have them (the same numbers, bit for bit, as one sample
 * at a time; vgt_rec_lanes.h). vgt_rec_lanes chooses their instruction set for the whole process:
 * 0 none (one sample at a time), 1 the baseline (not on x86-64), 2 x86-64-v3 (AVX2), 3 x86-64-v4
 * (AVX-512), -1 the best of this CPU (the default). Returns the samples per block, 0 for none (-1:
 * none on this CPU), or -1 when this CPU or library lacks the set asked for (nothing changed). */
int vgt_rec_lanes(int level);
/* The pose of every module joint (E row-major, r; without the offset tz) and its partial derivatives
 * of orders 1 to 3 in the module's three legs: 12 + 36 + 108 + 324 = 480 values per module, modules in
 * order, per sample (the generated vgt_rec_module_taylor). */
int vgt_rec_taylor(const vgt_rec_arm *arm, long n, const double *q, double *out);
/* The tip point alone (base components), from the joints' poses only. */
int vgt_rec_tip(const vgt_rec_arm *arm, long n, const double *q, double *tip);
/* The tip point and (vel not NULL) its velocity J_P qd, both in base components. */
int vgt_rec_tip_state(const vgt_rec_arm *arm, long n, const double *q, const double *qd, double *tip, double *vel);

/* One sample of the closed loop's step on shared kinematics (vgt_rec.c): the calling thread keeps
 * the joints, velocities and velocity-product forces of the last (arm, q, qd) it was given, and a
 * call with the same arm and bitwise the same q, qd reuses them (the same results, bit for bit, as
 * the batch functions); vgt_rec_step_tip reuses them when q is the same. vgt_rec_step_forget drops
 * what every thread keeps (vgt_rec_bind calls it). */
int vgt_rec_step_inverse(const vgt_rec_arm *arm, const double *q, const double *qd, const double *qdd,
                         const double *fext, double *tau);
int vgt_rec_step_forward(const vgt_rec_arm *arm, const double *q, const double *qd, const double *tau,
                         const double *fext, double *qdd);
int vgt_rec_step_tip_state(const vgt_rec_arm *arm, const double *q, const double *qd, double *tip, double *vel);
int vgt_rec_step_tip(const vgt_rec_arm *arm, const double *q, double *tip);
void vgt_rec_step_forget(void);

/* ---- The closed loop on the recursive model (vgt_rec_loop.c) ------------------------------------
 * The drivers of vgtarm.h call generated functions of the signature vgt_fn, whose last argument is
 * the parameter vector p. These adapters give the same functions from the recursive loops: the arm
 * of a parameter vector is found by its address, registered beforehand (vgt_rec_bind; slot < 64). */
int vgt_rec_bind(int slot, const double *p, const vgt_rec_arm *arm);
int vgt_rec_fn_cfc(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_fd(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_tip_state(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_tip(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_id(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_jac(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_tip_hessian(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_unavailable(const double **arg, double **res, long long *iw, double *w, int mem);
/* The same functions on the step's shared kinematics (vgt_rec_step_*): cfc, fd, id, tip_state and tip
 * (jac and tip_hessian are the adapters above). */
/* The gains Kp, Kv (n x n, row-major) and the margin rows G (n_margins x n) the next driver calls pass
 * (by address; their contents must not change until unbound), in the calling thread: cfc_fused sums
 * over the gains' nonzero entries only, and the driver's assembly check over G's (the same values).
 * n = 0 unbinds; a NULL array is not bound. */
int vgt_rec_bind_run(const double *Kp, const double *Kv, int n, const double *G, int n_margins);
double vgt_rec_margin(const double *G, int nj, int row, double margin, const double *q);
int vgt_rec_fn_cfc_fused(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_fd_fused(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_id_fused(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_tip_state_fused(const double **arg, double **res, long long *iw, double *w, int mem);
int vgt_rec_fn_tip_fused(const double **arg, double **res, long long *iw, double *w, int mem);
/* The inverse kinematics' position terms, exact: the tip c (3), its Jacobian J (3 x nq, row-major),
 * H = d^2 (lam . P) / dq^2 (nq x nq) at multipliers lam (3); with qd and lam_d (else NULL) also d2
 * (nq + 3): the second derivative of [J^T lam; P] along (qd, lam_d). */
int vgt_rec_ik_terms(const vgt_rec_arm *arm, long n, const double *q, const double *lam, const double *qd,
                     const double *lam_d, double *c, double *J, double *H, double *d2);
