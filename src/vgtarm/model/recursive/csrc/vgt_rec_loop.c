/* The functions the compiled closed loop (vgtarm.h, closed_loop.c, ga.c) calls, on the recursive
 * model. Each has the signature of a generated function (vgt_fn): inputs as the symbolic library's
 * cfc, fd, tip_state, tip, id and jac (codegen/control.py, codegen/model.py), the parameter vector
 * p last. The arm of p is the one registered for that address (vgt_rec_bind, from Python: the
 * recursive backend binds every parameter vector a run or a GA hands the drivers); an address not
 * registered makes the function fail (the drivers then stop with VGT_FUNCTION_FAILED). */

#include <stdlib.h>
#include <string.h>

#include "vgt_rec.h"

#define SLOTS 64

static const double *bound_p[SLOTS];
static const vgt_rec_arm *bound_arm[SLOTS];

int vgt_rec_bind(int slot, const double *p, const vgt_rec_arm *arm) {
    if (slot < 0 || slot >= SLOTS) return -1;
    bound_p[slot] = p, bound_arm[slot] = arm;
    vgt_rec_step_forget(); /* the arm a slot held may be freed, and its memory reused by another */
    return 0;
}

static _Thread_local int last_slot = 0; /* the slot found last: a loop step asks for the same ones */

static const vgt_rec_arm *arm_of(const double *p) {
    int last = last_slot;
    if (bound_p[last] == p && bound_arm[last]) return bound_arm[last];
    for (int i = 0; i < SLOTS; ++i)
        if (bound_p[i] == p && bound_arm[i]) {
            last_slot = i;
            return bound_arm[i];
        }
    return NULL;
}

/* cfc: q, qd, q_d, qd_d, qdd_d, Kp, Kv, p -> F = M (qdd_d + Kp e + Kv e_dot) + C: inverse dynamics
 * of the commanded acceleration (recursive Newton-Euler). */
int vgt_rec_fn_cfc(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[7]);
    if (!arm) return 1;
    int n = arm->nq;
    double *a = (double *)malloc(sizeof(double) * (size_t)(2 * n));
    if (!a) return 1;
    double *e = a + n;
    const double *q = arg[0], *qd = arg[1], *q_d = arg[2], *qd_d = arg[3], *qdd_d = arg[4], *Kp = arg[5], *Kv = arg[6];
    for (int j = 0; j < n; ++j) e[j] = qd_d[j] - qd[j];
    for (int i = 0; i < n; ++i) {
        double s = 0.0, t = 0.0;
        for (int j = 0; j < n; ++j) s += Kp[n * i + j] * (q_d[j] - q[j]);
        for (int j = 0; j < n; ++j) t += Kv[n * i + j] * e[j];
        a[i] = qdd_d[i] + s + t;
    }
    int status = vgt_rec_inverse(arm, 1, q, qd, a, NULL, res[0]);
    free(a);
    return status ? 1 : 0;
}

static void wrench_of(const double *f, double *out) {
    out[0] = f[0], out[1] = f[1], out[2] = f[2], out[3] = out[4] = out[5] = 0.0;
}

/* fd: q, qd, F, f, p -> qdd */
int vgt_rec_fn_fd(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[4]);
    if (!arm) return 1;
    double fext[6];
    wrench_of(arg[3], fext);
    return vgt_rec_forward(arm, 1, arg[0], arg[1], arg[2], fext, res[0]) ? 1 : 0;
}

/* id: q, qd, qdd, f, p -> F */
int vgt_rec_fn_id(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[4]);
    if (!arm) return 1;
    double fext[6];
    wrench_of(arg[3], fext);
    return vgt_rec_inverse(arm, 1, arg[0], arg[1], arg[2], fext, res[0]) ? 1 : 0;
}

/* tip_state: q, qd, p -> tip, velocity */
int vgt_rec_fn_tip_state(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[2]);
    if (!arm) return 1;
    double tip[3], vel[3];
    if (vgt_rec_tip_state(arm, 1, arg[0], arg[1], tip, vel)) return 1;
    if (res[0]) memcpy(res[0], tip, sizeof tip);
    if (res[1]) memcpy(res[1], vel, sizeof vel);
    return 0;
}

/* tip: q, p -> tip */
int vgt_rec_fn_tip(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[1]);
    if (!arm) return 1;
    double tip[3];
    if (vgt_rec_tip_state(arm, 1, arg[0], NULL, tip, NULL)) return 1;
    if (res[0]) memcpy(res[0], tip, sizeof tip);
    return 0;
}

/* jac: q, p -> J_P, J_W (3 x n each, row-major) */
int vgt_rec_fn_jac(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[1]);
    if (!arm) return 1;
    int n = arm->nq;
    double *scratch = (double *)malloc(sizeof(double) * (size_t)(6 * n));
    if (!scratch) return 1;
    int status = vgt_rec_jacobian(arm, 1, arg[0], scratch, scratch + 3 * n);
    if (!status) {
        if (res[0]) memcpy(res[0], scratch, sizeof(double) * (size_t)(3 * n));
        if (res[1]) memcpy(res[1], scratch + 3 * n, sizeof(double) * (size_t)(3 * n));
    }
    free(scratch);
    return status ? 1 : 0;
}

/* A function the recursive model does not provide in the loop (the tip Hessian of the GA's quadratic
 * prediction): it fails, and the driver stops with VGT_FUNCTION_FAILED. */
int vgt_rec_fn_unavailable(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)arg, (void)res, (void)iw, (void)w, (void)mem;
    return 1;
}

/* tip_hessian: q, p -> H (3, nq, nq), row-major: d^2 P_k / dq dq, k = 0, 1, 2 (the IK's terms at
 * the multipliers e_k) */
int vgt_rec_fn_tip_hessian(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[1]);
    if (!arm) return 1;
    int n = arm->nq;
    double *J = (double *)malloc(sizeof(double) * (size_t)(3 * n));
    if (!J) return 1;
    double c[3];
    int status = 0;
    for (int k = 0; k < 3 && !status; ++k) {
        double lam[3] = {0.0, 0.0, 0.0};
        lam[k] = 1.0;
        status = vgt_rec_ik_terms(arm, 1, arg[0], lam, NULL, NULL, c, J, res[0] + (size_t)k * n * n, NULL);
    }
    free(J);
    return status ? 1 : 0;
}

/* ---- The same functions on the step's shared kinematics (vgt_rec_step_*, vgt_rec.c) -------------
 * A loop step evaluates the plant's tip state, the CFC law and the plant's forward dynamics at the
 * same state (and the CFC law on the plant's arm when the controller's parameter vector equals the
 * plant's: the backend binds equal vectors to one arm): the joints are computed once. */

/* Per thread: the commanded acceleration and the errors of cfc (grown, never freed). */
static _Thread_local double *cfc_scratch = NULL;
static _Thread_local int cfc_capacity = 0;

/* a = qdd_d + Kp (q_d - q) + Kv (qd_d - qd): each entry summed in the order of vgt_rec_fn_cfc, four
 * rows at a time (independent sums, the same values). */
static void commanded(int n, const double *q, const double *qd, const double *q_d, const double *qd_d,
                      const double *qdd_d, const double *Kp, const double *Kv, double *e, double *ed, double *a) {
    for (int j = 0; j < n; ++j) e[j] = q_d[j] - q[j], ed[j] = qd_d[j] - qd[j];
    int i = 0;
    for (; i + 4 <= n; i += 4) {
        const double *p0 = Kp + (size_t)n * i, *p1 = p0 + n, *p2 = p1 + n, *p3 = p2 + n;
        const double *v0 = Kv + (size_t)n * i, *v1 = v0 + n, *v2 = v1 + n, *v3 = v2 + n;
        double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0, t0 = 0.0, t1 = 0.0, t2 = 0.0, t3 = 0.0;
        for (int j = 0; j < n; ++j) {
            const double x = e[j];
            s0 += p0[j] * x, s1 += p1[j] * x, s2 += p2[j] * x, s3 += p3[j] * x;
        }
        for (int j = 0; j < n; ++j) {
            const double x = ed[j];
            t0 += v0[j] * x, t1 += v1[j] * x, t2 += v2[j] * x, t3 += v3[j] * x;
        }
        a[i] = qdd_d[i] + s0 + t0, a[i + 1] = qdd_d[i + 1] + s1 + t1;
        a[i + 2] = qdd_d[i + 2] + s2 + t2, a[i + 3] = qdd_d[i + 3] + s3 + t3;
    }
    for (; i < n; ++i) {
        double s = 0.0, t = 0.0;
        for (int j = 0; j < n; ++j) s += Kp[(size_t)n * i + j] * e[j];
        for (int j = 0; j < n; ++j) t += Kv[(size_t)n * i + j] * ed[j];
        a[i] = qdd_d[i] + s + t;
    }
}

/* The gain matrices of a run, bound by the driver's caller for the run's call (vgt_rec_bind_run),
 * in the calling thread (the one the driver runs in): the columns of each row's nonzero entries,
 * Kp's rows then Kv's. */
static _Thread_local const double *gains_kp = NULL, *gains_kv = NULL;
static _Thread_local int gains_n = 0;
static _Thread_local int *gains_start = NULL, *gains_col = NULL; /* (2 n + 1), (nonzeros) */

/* The nonzero columns of each row of an n_rows x n matrix (row-major): start (n_rows + 1), col. */
static int nonzero_index(const double *A, int n_rows, int n, int **start, int **col) {
    size_t count = 0, all = (size_t)n_rows * (size_t)n;
    for (size_t e = 0; e < all; ++e) count += A[e] != 0.0;
    *start = (int *)malloc(sizeof(int) * (size_t)(n_rows + 1));
    *col = (int *)malloc(sizeof(int) * (count > 0 ? count : 1));
    if (!*start || !*col) return -1;
    int k = 0;
    for (int r = 0; r < n_rows; ++r) {
        (*start)[r] = k;
        for (int j = 0; j < n; ++j)
            if (A[(size_t)n * r + j] != 0.0) (*col)[k++] = j;
    }
    (*start)[n_rows] = k;
    return 0;
}

/* The margin rows G (n_margins x n) of the run bound with its gains (vgt_rec_bind_run). */
static _Thread_local const double *margins_G = NULL;
static _Thread_local int margins_n = 0, margins_rows = 0;
static _Thread_local int *margins_start = NULL, *margins_col = NULL;

static void unbind_run(void) {
    gains_kp = gains_kv = NULL, gains_n = 0;
    free(gains_start), free(gains_col);
    gains_start = gains_col = NULL;
    margins_G = NULL, margins_n = margins_rows = 0;
    free(margins_start), free(margins_col);
    margins_start = margins_col = NULL;
}

int vgt_rec_bind_run(const double *Kp, const double *Kv, int n, const double *G, int n_margins) {
    unbind_run();
    if (n <= 0) return 0;
    if (Kp && Kv) {
        int *start = NULL, *col = NULL, *start_v = NULL, *col_v = NULL;
        int failed = nonzero_index(Kp, n, n, &start, &col) || nonzero_index(Kv, n, n, &start_v, &col_v);
        int *merged_start = failed ? NULL : (int *)malloc(sizeof(int) * (size_t)(2 * n + 1));
        int total = failed ? 0 : start[n] + start_v[n];
        int *merged_col = failed ? NULL : (int *)malloc(sizeof(int) * (size_t)(total > 0 ? total : 1));
        if (!failed && merged_start && merged_col) {
            for (int r = 0; r <= n; ++r) merged_start[r] = start[r];
            for (int r = 1; r <= n; ++r) merged_start[n + r] = start[n] + start_v[r];
            memcpy(merged_col, col, sizeof(int) * (size_t)start[n]);
            memcpy(merged_col + start[n], col_v, sizeof(int) * (size_t)start_v[n]);
            gains_start = merged_start, gains_col = merged_col;
            gains_kp = Kp, gains_kv = Kv, gains_n = n;
        } else {
            free(merged_start), free(merged_col);
            failed = 1;
        }
        free(start), free(col), free(start_v), free(col_v);
        if (failed) return -1;
    }
    if (G && n_margins > 0) {
        if (nonzero_index(G, n_margins, n, &margins_start, &margins_col)) {
            free(margins_start), free(margins_col);
            margins_start = margins_col = NULL;
            return -1;
        }
        margins_G = G, margins_n = n, margins_rows = n_margins;
    }
    return 0;
}

/* The driver's margin row `row` of G (closed_loop.c's check_state, built with -DVGT_MARGIN_ROW):
 * margin + G[row] . q over the nonzero entries of bound rows, else over every entry. */
double vgt_rec_margin(const double *G, int nj, int row, double margin, const double *q) {
    const double *g = G + (size_t)nj * row;
    if (G == margins_G && nj == margins_n && row < margins_rows) {
        for (int k = margins_start[row]; k < margins_start[row + 1]; ++k) margin += g[margins_col[k]] * q[margins_col[k]];
        return margin;
    }
    for (int i = 0; i < nj; ++i) margin += g[i] * q[i];
    return margin;
}

/* commanded() over the nonzero entries of bound gains: the same sums (a zero entry adds a zero
 * product, which leaves a sum unchanged; the errors are finite: the loop checks its states). */
static void commanded_sparse(int n, const double *q, const double *qd, const double *q_d, const double *qd_d,
                             const double *qdd_d, const double *Kp, const double *Kv, double *e, double *ed, double *a) {
    for (int j = 0; j < n; ++j) e[j] = q_d[j] - q[j], ed[j] = qd_d[j] - qd[j];
    for (int i = 0; i < n; ++i) {
        const double *p = Kp + (size_t)n * i, *v = Kv + (size_t)n * i;
        double s = 0.0, t = 0.0;
        for (int k = gains_start[i]; k < gains_start[i + 1]; ++k) s += p[gains_col[k]] * e[gains_col[k]];
        for (int k = gains_start[n + i]; k < gains_start[n + i + 1]; ++k) t += v[gains_col[k]] * ed[gains_col[k]];
        a[i] = qdd_d[i] + s + t;
    }
}

/* cfc: q, qd, q_d, qd_d, qdd_d, Kp, Kv, p -> F */
int vgt_rec_fn_cfc_fused(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[7]);
    if (!arm) return 1;
    int n = arm->nq;
    if (cfc_capacity < n) {
        double *grown = (double *)realloc(cfc_scratch, sizeof(double) * (size_t)(3 * n));
        if (!grown) return 1;
        cfc_scratch = grown, cfc_capacity = n;
    }
    double *a = cfc_scratch, *e = a + n, *ed = e + n;
    if (arg[5] == gains_kp && arg[6] == gains_kv && n == gains_n)
        commanded_sparse(n, arg[0], arg[1], arg[2], arg[3], arg[4], arg[5], arg[6], e, ed, a);
    else
        commanded(n, arg[0], arg[1], arg[2], arg[3], arg[4], arg[5], arg[6], e, ed, a);
    return vgt_rec_step_inverse(arm, arg[0], arg[1], a, NULL, res[0]) ? 1 : 0;
}

/* fd: q, qd, F, f, p -> qdd */
int vgt_rec_fn_fd_fused(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[4]);
    if (!arm) return 1;
    double fext[6];
    wrench_of(arg[3], fext);
    return vgt_rec_step_forward(arm, arg[0], arg[1], arg[2], fext, res[0]) ? 1 : 0;
}

/* id: q, qd, qdd, f, p -> F */
int vgt_rec_fn_id_fused(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[4]);
    if (!arm) return 1;
    double fext[6];
    wrench_of(arg[3], fext);
    return vgt_rec_step_inverse(arm, arg[0], arg[1], arg[2], fext, res[0]) ? 1 : 0;
}

/* tip_state: q, qd, p -> tip, velocity */
int vgt_rec_fn_tip_state_fused(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[2]);
    if (!arm) return 1;
    double tip[3], vel[3];
    if (vgt_rec_step_tip_state(arm, arg[0], arg[1], tip, vel)) return 1;
    if (res[0]) memcpy(res[0], tip, sizeof tip);
    if (res[1]) memcpy(res[1], vel, sizeof vel);
    return 0;
}

/* tip: q, p -> tip */
int vgt_rec_fn_tip_fused(const double **arg, double **res, long long *iw, double *w, int mem) {
    (void)iw, (void)w, (void)mem;
    const vgt_rec_arm *arm = arm_of(arg[1]);
    if (!arm) return 1;
    double tip[3];
    if (vgt_rec_step_tip(arm, arg[0], tip)) return 1;
    if (res[0]) memcpy(res[0], tip, sizeof tip);
    return 0;
}
