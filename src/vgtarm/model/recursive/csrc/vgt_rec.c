/* Recursive kinematics and dynamics of a stack of VGT modules (Featherstone's algorithms over a
 * serial chain whose joints have one or three degrees of freedom).
 *
 * Conventions: body i hangs on joint i below it (its parent is body i - 1, or the base). The
 * joint gives R (the body's axes in parent components, row-major) and r (the body origin in the
 * parent frame): x_parent = R x_body + r. Spatial vectors are (angular, linear) in body
 * coordinates, about the body origin. S (6 x nd, row-major, nd <= 3) is the motion subspace and
 * c_J = Sdot qd its bias, both in body coordinates. */

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "vgt_rec.h"
#include "vgt_rec_generated.h"

typedef struct {
    double R[9], r[3];    /* pose in the parent frame */
    double R0[9], p0[3];  /* pose in the base frame */
    double S[18], cj[6];  /* motion subspace (6 x 3, row-major) and its bias */
    double v[6], a[6], f[6], c[6], vf[6]; /* vf = v x* (I v) */
    double IA[36], pA[6], U[18], Dinv[9], u[3];
} body_t;

typedef struct {
    body_t *body;
    const casadi_real **arg;
    casadi_real **res;
    casadi_int *iw;
    casadi_real *w;
    int owned; /* 1: the memory at body was allocated for this call */
} work_t;

/* The scratch of one call: the bodies and the generated functions' work arrays (with those of the
 * module's derivatives up to order 3 when taylor is set: they are large). The common case reuses a
 * buffer of the calling thread (zeroed, as calloc would give it), so a closed-loop step allocates
 * nothing; the large one is allocated per call. */
typedef struct {
    void *memory;
    size_t size;
} scratch_t;

static _Thread_local scratch_t thread_scratch = {NULL, 0};

static int work_open_sized(work_t *k, const vgt_rec_arm *arm, int taylor) {
    casadi_int sz_arg = 0, sz_res = 0, sz_iw = 0, sz_w = 0, a, r, i, w;
    vgt_rec_module_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
    vgt_rec_module_kin_work(&a, &r, &i, &w);
    if (a > sz_arg) sz_arg = a;
    if (r > sz_res) sz_res = r;
    if (i > sz_iw) sz_iw = i;
    if (w > sz_w) sz_w = w;
    if (taylor) {
        vgt_rec_module_taylor_work(&a, &r, &i, &w);
        if (a > sz_arg) sz_arg = a;
        if (r > sz_res) sz_res = r;
        if (i > sz_iw) sz_iw = i;
        if (w > sz_w) sz_w = w;
    }
    size_t nb = (size_t)(arm->nb > 0 ? arm->nb : 1);
    size_t bodies = nb * sizeof(body_t), args = ((size_t)sz_arg + 1) * sizeof(casadi_real *);
    size_t ress = ((size_t)sz_res + 1) * sizeof(casadi_real *), iws = ((size_t)sz_iw + 1) * sizeof(casadi_int);
    size_t ws = ((size_t)sz_w + 1) * sizeof(casadi_real);
    size_t total = bodies + args + ress + iws + ws + 64;
    char *memory;
    if (taylor) {
        memory = (char *)calloc(total, 1);
        if (!memory) return -1;
    } else {
        if (thread_scratch.size < total) {
            void *grown = realloc(thread_scratch.memory, total);
            if (!grown) return -1;
            thread_scratch.memory = grown, thread_scratch.size = total;
        }
        memory = (char *)thread_scratch.memory;
        memset(memory, 0, total);
    }
    k->body = (body_t *)memory;
    k->arg = (const casadi_real **)(memory + bodies);
    k->res = (casadi_real **)(memory + bodies + args);
    k->iw = (casadi_int *)(memory + bodies + args + ress);
    k->w = (casadi_real *)(memory + bodies + args + ress + iws);
    k->owned = taylor;
    return 0;
}

static int work_open(work_t *k, const vgt_rec_arm *arm) { return work_open_sized(k, arm, 0); }

static void work_close(work_t *k) {
    if (k->owned) free(k->body);
}

/* ---- small 3-vector and spatial helpers ------------------------------------------------------ */

static void cross3(const double *a, const double *b, double *out) {
    double x = a[1] * b[2] - a[2] * b[1], y = a[2] * b[0] - a[0] * b[2], z = a[0] * b[1] - a[1] * b[0];
    out[0] = x, out[1] = y, out[2] = z;
}

static void mul3(const double *R, const double *x, double *out) { /* R x */
    double a = R[0] * x[0] + R[1] * x[1] + R[2] * x[2];
    double b = R[3] * x[0] + R[4] * x[1] + R[5] * x[2];
    double c = R[6] * x[0] + R[7] * x[1] + R[8] * x[2];
    out[0] = a, out[1] = b, out[2] = c;
}

static void mul3t(const double *R, const double *x, double *out) { /* R^T x */
    double a = R[0] * x[0] + R[3] * x[1] + R[6] * x[2];
    double b = R[1] * x[0] + R[4] * x[1] + R[7] * x[2];
    double c = R[2] * x[0] + R[5] * x[1] + R[8] * x[2];
    out[0] = a, out[1] = b, out[2] = c;
}

static void matmul3(const double *A, const double *B, double *out) { /* A B */
    double t[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) t[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
    memcpy(out, t, sizeof t);
}

/* motion vector from the parent to the body: w' = R^T w, v' = R^T (v - r x w) */
static void motion_in(const body_t *b, const double *m, double *out) {
    double t[3], w[3];
    cross3(b->r, m, t);
    t[0] = m[3] - t[0], t[1] = m[4] - t[1], t[2] = m[5] - t[2];
    mul3t(b->R, m, w);
    mul3t(b->R, t, out + 3);
    out[0] = w[0], out[1] = w[1], out[2] = w[2];
}

/* force from the body to the parent: f' = R f, n' = R n + r x f' */
static void force_out(const body_t *b, const double *f, double *out) {
    double n[3], t[3];
    mul3(b->R, f + 3, out + 3);
    mul3(b->R, f, n);
    cross3(b->r, out + 3, t);
    out[0] = n[0] + t[0], out[1] = n[1] + t[1], out[2] = n[2] + t[2];
}

/* v x m (motion) */
static void cross_motion(const double *v, const double *m, double *out) {
    double a[3], b[3], c[3];
    cross3(v, m, a);
    cross3(v, m + 3, b);
    cross3(v + 3, m, c);
    out[0] = a[0], out[1] = a[1], out[2] = a[2];
    out[3] = b[0] + c[0], out[4] = b[1] + c[1], out[5] = b[2] + c[2];
}

/* v x* f (force) */
static void cross_force(const double *v, const double *f, double *out) {
    double a[3], b[3], c[3];
    cross3(v, f, a);
    cross3(v + 3, f + 3, b);
    cross3(v, f + 3, c);
    out[0] = a[0] + b[0], out[1] = a[1] + b[1], out[2] = a[2] + b[2];
    out[3] = c[0], out[4] = c[1], out[5] = c[2];
}

static void mul6(const double *I, const double *x, double *out) {
    for (int i = 0; i < 6; ++i) {
        const double *row = I + 6 * i;
        out[i] = row[0] * x[0] + row[1] * x[1] + row[2] * x[2] + row[3] * x[3] + row[4] * x[4] + row[5] * x[5];
    }
}

/* P += X^T I X: an inertia of the body (body coordinates) added to its parent's. With I =
 * [A B; B^T C] turned into parent axes (A' = R A R^T, ...) and shifted by r (rx its cross-product
 * matrix): [A' - B' rx + rx B'^T - rx C' rx, B' + rx C'; B'^T - C' rx, C']. */
static void rotate_block(const double *R, const double *I, int row, int col, double *out) {
    double t[9];
    for (int i = 0; i < 3; ++i) /* t = R X, X the 3x3 block */
        for (int j = 0; j < 3; ++j)
            t[3 * i + j] = R[3 * i] * I[6 * row + col + j] + R[3 * i + 1] * I[6 * (row + 1) + col + j] +
                           R[3 * i + 2] * I[6 * (row + 2) + col + j];
    for (int i = 0; i < 3; ++i) /* out = t R^T */
        for (int j = 0; j < 3; ++j) out[3 * i + j] = t[3 * i] * R[3 * j] + t[3 * i + 1] * R[3 * j + 1] + t[3 * i + 2] * R[3 * j + 2];
}

static void inertia_out(const body_t *b, const double *I, double *P) {
    double A[9], B[9], C[9], BX[9], XC[9], XCX[9];
    const double *r = b->r;
    rotate_block(b->R, I, 0, 0, A);
    rotate_block(b->R, I, 0, 3, B);
    rotate_block(b->R, I, 3, 3, C);
    /* BX = B rx, XC = rx C (rx = [0 -z y; z 0 -x; -y x 0]) */
    for (int i = 0; i < 3; ++i) {
        const double *Bi = B + 3 * i;
        BX[3 * i + 0] = Bi[1] * r[2] - Bi[2] * r[1];
        BX[3 * i + 1] = Bi[2] * r[0] - Bi[0] * r[2];
        BX[3 * i + 2] = Bi[0] * r[1] - Bi[1] * r[0];
    }
    for (int j = 0; j < 3; ++j) {
        XC[0 + j] = -r[2] * C[3 + j] + r[1] * C[6 + j];
        XC[3 + j] = r[2] * C[0 + j] - r[0] * C[6 + j];
        XC[6 + j] = -r[1] * C[0 + j] + r[0] * C[3 + j];
    }
    for (int i = 0; i < 3; ++i) { /* XCX = XC rx */
        const double *Xi = XC + 3 * i;
        XCX[3 * i + 0] = Xi[1] * r[2] - Xi[2] * r[1];
        XCX[3 * i + 1] = Xi[2] * r[0] - Xi[0] * r[2];
        XCX[3 * i + 2] = Xi[0] * r[1] - Xi[1] * r[0];
    }
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            /* rx B^T = -(B rx)^T: its (i, j) entry is -BX[j][i] */
            P[6 * i + j] += A[3 * i + j] - BX[3 * i + j] - BX[3 * j + i] - XCX[3 * i + j];
            double off = B[3 * i + j] + XC[3 * i + j];
            P[6 * i + 3 + j] += off;
            P[6 * (3 + j) + i] += off;
            P[6 * (3 + i) + 3 + j] += C[3 * i + j];
        }
}

/* ---- the joints ------------------------------------------------------------------------------ */

static int dofs(const vgt_rec_arm *arm, int i) { return arm->type[i] == 3 ? 3 : 1; }

/* Pose, motion subspace and (when qd is given) bias of every joint, and the poses in the base
 * frame. passive (4 per module) is written when given (and qd is NULL). */
static void joints(const vgt_rec_arm *arm, work_t *k, const double *q, const double *qd, double *passive) {
    int module = 0;
    for (int i = 0; i < arm->nb; ++i) {
        body_t *b = k->body + i;
        const double *qi = q + arm->qi[i];
        if (arm->type[i] == 3) {
            double pose[12];
            const double *g = arm->geom + 4 * i;
            if (qd) {
                k->arg[0] = qi, k->arg[1] = qd + arm->qi[i], k->arg[2] = g;
                k->res[0] = pose, k->res[1] = b->S, k->res[2] = b->cj;
                vgt_rec_module(k->arg, k->res, k->iw, k->w, 0);
            } else {
                double scratch[4];
                k->arg[0] = qi, k->arg[1] = g;
                k->res[0] = pose, k->res[1] = b->S, k->res[2] = passive ? passive + 4 * module : scratch;
                vgt_rec_module_kin(k->arg, k->res, k->iw, k->w, 0);
                memset(b->cj, 0, sizeof b->cj);
            }
            memcpy(b->R, pose, 9 * sizeof(double));
            b->r[0] = pose[9], b->r[1] = pose[10], b->r[2] = pose[11] + arm->tz[i];
            ++module;
        } else {
            double c = cos(qi[0]), s = sin(qi[0]);
            double R[9] = {c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0};
            memcpy(b->R, R, sizeof R);
            b->r[0] = 0.0, b->r[1] = 0.0, b->r[2] = arm->tz[i];
            memset(b->S, 0, sizeof b->S);
            b->S[2 * 3] = 1.0; /* row 2 (omega_z), column 0 */
            memset(b->cj, 0, sizeof b->cj);
        }
        if (i == 0) {
            memcpy(b->R0, b->R, sizeof b->R);
            memcpy(b->p0, b->r, sizeof b->r);
        } else {
            const body_t *p = b - 1;
            double t[3];
            matmul3(p->R0, b->R, b->R0);
            mul3(p->R0, b->r, t);
            b->p0[0] = p->p0[0] + t[0], b->p0[1] = p->p0[1] + t[1], b->p0[2] = p->p0[2] + t[2];
        }
    }
}

/* S column j as a spatial vector */
static void column(const body_t *b, int j, double *out) {
    for (int i = 0; i < 6; ++i) out[i] = b->S[3 * i + j];
}

/* S qd of the body's joint */
static void joint_velocity(const vgt_rec_arm *arm, const body_t *b, int i, const double *qd, double *out) {
    int nd = dofs(arm, i);
    const double *x = qd + arm->qi[i];
    for (int r = 0; r < 6; ++r) {
        double s = 0.0;
        for (int j = 0; j < nd; ++j) s += b->S[3 * r + j] * x[j];
        out[r] = s;
    }
}

/* The tip wrench as a force on the last body, in its coordinates. */
static void tip_force(const vgt_rec_arm *arm, const body_t *last, const double *fext, double *out) {
    double t[3];
    mul3t(last->R0, fext, out + 3);
    mul3t(last->R0, fext + 3, out);
    cross3(arm->tip, out + 3, t);
    out[0] += t[0], out[1] += t[1], out[2] += t[2];
}

/* Velocities of every body; the velocity-product accelerations c = c_J + v x v_J. */
static void velocities(const vgt_rec_arm *arm, work_t *k, const double *qd) {
    for (int i = 0; i < arm->nb; ++i) {
        body_t *b = k->body + i;
        double vj[6], x[6];
        joint_velocity(arm, b, i, qd, vj);
        if (i == 0)
            memset(x, 0, sizeof x);
        else
            motion_in(b, k->body[i - 1].v, x);
        for (int r = 0; r < 6; ++r) b->v[r] = x[r] + vj[r];
        cross_motion(b->v, vj, x);
        for (int r = 0; r < 6; ++r) b->c[r] = b->cj[r] + x[r];
    }
}

/* ---- the exported functions ------------------------------------------------------------------ */

long vgt_rec_unassembled(const vgt_rec_arm *arm, long n, const double *q, const double *rows, const double *h,
                         int *where) {
    for (long s = 0; s < n; ++s) {
        const double *x = q + s * arm->nq;
        int module = 0;
        for (int i = 0; i < arm->nb; ++i) {
            if (arm->type[i] != 3) continue;
            const double *legs = x + arm->qi[i];
            for (int r = 0; r < 6; ++r) {
                double margin = rows[3 * r] * legs[0] + rows[3 * r + 1] * legs[1] + rows[3 * r + 2] * legs[2] + h[6 * module + r];
                if (!(margin > 0.0)) {
                    where[0] = module, where[1] = r;
                    return s;
                }
            }
            ++module;
        }
    }
    return -1;
}

int vgt_rec_fk(const vgt_rec_arm *arm, long n, const double *q, double *tip, double *rot, double *body_pos,
               double *body_rot, double *passive) {
    work_t k;
    if (work_open(&k, arm)) return -1;
    int nb = arm->nb;
    for (long s = 0; s < n; ++s) {
        joints(arm, &k, q + s * arm->nq, NULL, passive + s * 4 * arm->nm);
        const body_t *last = k.body + nb - 1;
        double t[3];
        mul3(last->R0, arm->tip, t);
        for (int r = 0; r < 3; ++r) tip[3 * s + r] = last->p0[r] + t[r];
        memcpy(rot + 9 * s, last->R0, 9 * sizeof(double));
        for (int i = 0; i < nb; ++i) {
            memcpy(body_pos + 3 * (s * nb + i), k.body[i].p0, 3 * sizeof(double));
            memcpy(body_rot + 9 * (s * nb + i), k.body[i].R0, 9 * sizeof(double));
        }
    }
    work_close(&k);
    return 0;
}

int vgt_rec_jacobian(const vgt_rec_arm *arm, long n, const double *q, double *jp, double *jw) {
    work_t k;
    if (work_open(&k, arm)) return -1;
    int nb = arm->nb, nq = arm->nq;
    for (long s = 0; s < n; ++s) {
        joints(arm, &k, q + s * nq, NULL, NULL);
        const body_t *last = k.body + nb - 1;
        double p[3], t[3];
        mul3(last->R0, arm->tip, t);
        for (int r = 0; r < 3; ++r) p[r] = last->p0[r] + t[r];
        double *JP = jp + 3 * nq * s, *JW = jw + 3 * nq * s;
        for (int i = 0; i < nb; ++i) {
            const body_t *b = k.body + i;
            double arm_[3] = {p[0] - b->p0[0], p[1] - b->p0[1], p[2] - b->p0[2]};
            for (int j = 0; j < dofs(arm, i); ++j) {
                double col[6], w[3], v[3], x[3];
                column(b, j, col);
                mul3(b->R0, col, w);
                mul3(b->R0, col + 3, v);
                cross3(w, arm_, x);
                int c = arm->qi[i] + j;
                for (int r = 0; r < 3; ++r) {
                    JW[r * nq + c] = w[r];
                    JP[r * nq + c] = v[r] + x[r];
                }
            }
        }
    }
    work_close(&k);
    return 0;
}

#include "vgt_rec_lanes.h"

int vgt_rec_mass(const vgt_rec_arm *arm, long n, const double *q, double *m) {
    work_t k;
    if (work_open(&k, arm)) return -1;
    int nb = arm->nb, nq = arm->nq;
    for (long s = run_lanes(arm, &k, n, q, NULL, NULL, NULL, m, 2); s < n; ++s) { /* the rest one by one */
        joints(arm, &k, q + s * nq, NULL, NULL);
        double *M = m + (long)nq * nq * s;
        for (int i = 0; i < nb; ++i) memcpy(k.body[i].IA, arm->inertia + 36 * i, 36 * sizeof(double));
        for (int i = nb - 1; i > 0; --i) inertia_out(k.body + i, k.body[i].IA, k.body[i - 1].IA);
        for (int i = 0; i < nb; ++i) {
            const body_t *b = k.body + i;
            int nd = dofs(arm, i);
            double F[3][6];
            for (int j = 0; j < nd; ++j) {
                double col[6];
                column(b, j, col);
                mul6(b->IA, col, F[j]);
            }
            for (int jb = i; jb >= 0; --jb) {
                const body_t *o = k.body + jb;
                if (jb < i)
                    for (int j = 0; j < nd; ++j) force_out(k.body + jb + 1, F[j], F[j]);
                for (int r = 0; r < dofs(arm, jb); ++r)
                    for (int j = 0; j < nd; ++j) {
                        double sum = 0.0;
                        for (int e = 0; e < 6; ++e) sum += o->S[3 * e + r] * F[j][e];
                        int row = arm->qi[jb] + r, col = arm->qi[i] + j;
                        M[row * nq + col] = sum;
                        M[col * nq + row] = sum;
                    }
            }
        }
    }
    work_close(&k);
    return 0;
}

/* The velocity-product forces v x* (I v) of every body (after velocities). */
static void velocity_forces(const vgt_rec_arm *arm, body_t *body) {
    for (int i = 0; i < arm->nb; ++i) {
        body_t *b = body + i;
        double Iv[6];
        mul6(arm->inertia + 36 * i, b->v, Iv);
        cross_force(b->v, Iv, b->vf);
    }
}

/* Recursive Newton-Euler of one sample on bodies whose joints, velocities and velocity-product
 * forces are computed: the efforts T at accelerations xdd under the tip wrench fext (or NULL).
 * Writes the bodies' a and f only. */
static void rnea_pass(const vgt_rec_arm *arm, body_t *body, const double *xd, const double *xdd,
                      const double *fext, double *T) {
    int nb = arm->nb;
    double a0[6] = {0.0, 0.0, 0.0, -arm->gravity[0], -arm->gravity[1], -arm->gravity[2]};
    for (int i = 0; i < nb; ++i) {
        body_t *b = body + i;
        double t[6];
        motion_in(b, i == 0 ? a0 : body[i - 1].a, t);
        joint_velocity(arm, b, i, xdd, b->a);
        for (int r = 0; r < 6; ++r) b->a[r] += t[r] + b->c[r];
        mul6(arm->inertia + 36 * i, b->a, b->f);
        for (int r = 0; r < 6; ++r) b->f[r] += b->vf[r];
    }
    if (fext) {
        double fb[6];
        tip_force(arm, body + nb - 1, fext, fb);
        for (int r = 0; r < 6; ++r) body[nb - 1].f[r] -= fb[r];
    }
    for (int i = nb - 1; i >= 0; --i) {
        body_t *b = body + i;
        for (int j = 0; j < dofs(arm, i); ++j) {
            double sum = 0.0;
            for (int e = 0; e < 6; ++e) sum += b->S[3 * e + j] * b->f[e];
            int c = arm->qi[i] + j;
            T[c] = sum + arm->viscous[c] * xd[c];
        }
        if (i > 0) {
            double g[6];
            force_out(b, b->f, g);
            for (int r = 0; r < 6; ++r) body[i - 1].f[r] += g[r];
        }
    }
}

int vgt_rec_inverse(const vgt_rec_arm *arm, long n, const double *q, const double *qd, const double *qdd,
                    const double *fext, double *tau) {
    work_t k;
    if (work_open(&k, arm)) return -1;
    int nq = arm->nq;
    for (long s = run_lanes(arm, &k, n, q, qd, qdd, fext, tau, 1); s < n; ++s) { /* the rest one by one */
        const double *x = q + s * nq, *xd = qd + s * nq, *xdd = qdd + s * nq;
        joints(arm, &k, x, xd, NULL);
        velocities(arm, &k, xd);
        velocity_forces(arm, k.body);
        rnea_pass(arm, k.body, xd, xdd, fext ? fext + 6 * s : NULL, tau + s * nq);
    }
    work_close(&k);
    return 0;
}

/* inverse of a symmetric positive definite nd x nd matrix (nd = 1 or 3), row-major 3x3 storage */
static void inverse_spd(const double *D, int nd, double *out) {
    if (nd == 1) {
        out[0] = 1.0 / D[0];
        return;
    }
    double a = D[0], b = D[1], c = D[2], d = D[4], e = D[5], f = D[8];
    double A = d * f - e * e, B = c * e - b * f, C = b * e - c * d;
    double det = a * A + b * B + c * C, inv = 1.0 / det;
    out[0] = A * inv, out[1] = B * inv, out[2] = C * inv;
    out[3] = B * inv, out[4] = (a * f - c * c) * inv, out[5] = (b * c - a * e) * inv;
    out[6] = C * inv, out[7] = (b * c - a * e) * inv, out[8] = (a * d - b * b) * inv;
}

/* The articulated-body algorithm of one sample on bodies whose joints, velocities and
 * velocity-product forces are computed: the accelerations A under the efforts F and the tip wrench
 * fext (or NULL). Writes the bodies' IA, pA, U, Dinv, u and a only. */
static void aba_pass(const vgt_rec_arm *arm, body_t *body, const double *xd, const double *F, const double *fext,
                     double *A) {
    int nb = arm->nb;
    for (int i = 0; i < nb; ++i) {
        body_t *b = body + i;
        memcpy(b->IA, arm->inertia + 36 * i, 36 * sizeof(double));
        memcpy(b->pA, b->vf, sizeof b->pA);
    }
    if (fext) {
        double fb[6];
        tip_force(arm, body + nb - 1, fext, fb);
        for (int r = 0; r < 6; ++r) body[nb - 1].pA[r] -= fb[r];
    }
    for (int i = nb - 1; i >= 0; --i) {
        body_t *b = body + i;
        int nd = dofs(arm, i);
        double D[9];
        for (int j = 0; j < nd; ++j) { /* U = IA S */
            double col[6], u[6];
            column(b, j, col);
            mul6(b->IA, col, u);
            for (int r = 0; r < 6; ++r) b->U[3 * r + j] = u[r];
        }
        for (int r = 0; r < nd; ++r) {
            int c = arm->qi[i] + r;
            double sum = 0.0;
            for (int e = 0; e < 6; ++e) sum += b->S[3 * e + r] * b->pA[e];
            b->u[r] = F[c] - arm->viscous[c] * xd[c] - sum;
            for (int j = 0; j < nd; ++j) {
                double d = 0.0;
                for (int e = 0; e < 6; ++e) d += b->S[3 * e + r] * b->U[3 * e + j];
                D[3 * r + j] = d;
            }
        }
        inverse_spd(D, nd, b->Dinv);
        if (i == 0) continue;
        double Ia[36], pa[6], UD[18], du[3];
        for (int r = 0; r < 6; ++r) /* UD = U Dinv */
            for (int j = 0; j < nd; ++j) {
                double sum = 0.0;
                for (int e = 0; e < nd; ++e) sum += b->U[3 * r + e] * b->Dinv[3 * e + j];
                UD[3 * r + j] = sum;
            }
        for (int r = 0; r < 6; ++r)
            for (int c = 0; c < 6; ++c) {
                double sum = 0.0;
                for (int e = 0; e < nd; ++e) sum += UD[3 * r + e] * b->U[3 * c + e];
                Ia[6 * r + c] = b->IA[6 * r + c] - sum;
            }
        for (int e = 0; e < nd; ++e) du[e] = b->u[e];
        mul6(Ia, b->c, pa);
        for (int r = 0; r < 6; ++r) {
            double sum = 0.0;
            for (int e = 0; e < nd; ++e) sum += UD[3 * r + e] * du[e];
            pa[r] += b->pA[r] + sum;
        }
        body_t *p = b - 1;
        inertia_out(b, Ia, p->IA);
        double g[6];
        force_out(b, pa, g);
        for (int r = 0; r < 6; ++r) p->pA[r] += g[r];
    }
    double a0[6] = {0.0, 0.0, 0.0, -arm->gravity[0], -arm->gravity[1], -arm->gravity[2]};
    for (int i = 0; i < nb; ++i) {
        body_t *b = body + i;
        int nd = dofs(arm, i);
        double ap[6], t[3];
        motion_in(b, i == 0 ? a0 : body[i - 1].a, ap);
        for (int r = 0; r < 6; ++r) ap[r] += b->c[r];
        for (int r = 0; r < nd; ++r) {
            double sum = 0.0;
            for (int e = 0; e < 6; ++e) sum += b->U[3 * e + r] * ap[e];
            t[r] = b->u[r] - sum;
        }
        for (int r = 0; r < nd; ++r) {
            double sum = 0.0;
            for (int e = 0; e < nd; ++e) sum += b->Dinv[3 * r + e] * t[e];
            A[arm->qi[i] + r] = sum;
        }
        for (int r = 0; r < 6; ++r) {
            double sum = ap[r];
            for (int e = 0; e < nd; ++e) sum += b->S[3 * r + e] * A[arm->qi[i] + e];
            b->a[r] = sum;
        }
    }
}

int vgt_rec_forward(const vgt_rec_arm *arm, long n, const double *q, const double *qd, const double *tau,
                    const double *fext, double *qdd) {
    work_t k;
    if (work_open(&k, arm)) return -1;
    int nq = arm->nq;
    for (long s = run_lanes(arm, &k, n, q, qd, tau, fext, qdd, 0); s < n; ++s) { /* the rest one by one */
        const double *x = q + s * nq, *xd = qd + s * nq;
        joints(arm, &k, x, xd, NULL);
        velocities(arm, &k, xd);
        velocity_forces(arm, k.body);
        aba_pass(arm, k.body, xd, tau + s * nq, fext ? fext + 6 * s : NULL, qdd + s * nq);
    }
    work_close(&k);
    return 0;
}

int vgt_rec_taylor(const vgt_rec_arm *arm, long n, const double *q, double *out) {
    work_t k;
    if (work_open_sized(&k, arm, 1)) return -1;
    for (long s = 0; s < n; ++s) {
        int module = 0;
        for (int i = 0; i < arm->nb; ++i) {
            if (arm->type[i] != 3) continue;
            double *o = out + 480 * (s * arm->nm + module);
            k.arg[0] = q + s * arm->nq + arm->qi[i], k.arg[1] = arm->geom + 4 * i;
            k.res[0] = o, k.res[1] = o + 12, k.res[2] = o + 48, k.res[3] = o + 156;
            vgt_rec_module_taylor(k.arg, k.res, k.iw, k.w, 0);
            ++module;
        }
    }
    work_close(&k);
    return 0;
}

/* The tip point alone: each joint's pose (vgt_rec_module_pose: no motion subspace) chained from
 * the tip back to the base (the same products as the poses in the base frame of joints()). */
int vgt_rec_tip(const vgt_rec_arm *arm, long n, const double *q, double *tip) {
    casadi_int sz_arg, sz_res, sz_iw, sz_w;
    vgt_rec_module_pose_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
    const casadi_real *arg[8];
    casadi_real *res[8];
    casadi_int iw[64];
    casadi_real w[512];
    if (sz_arg > 8 || sz_res > 8 || sz_iw > 64 || sz_w > 512) return vgt_rec_tip_state(arm, n, q, NULL, tip, NULL);
    int nb = arm->nb;
    for (long s = 0; s < n; ++s) {
        const double *x = q + s * arm->nq;
        double R0[9], p0[3];
        for (int i = 0; i < nb; ++i) {
            const double *qi = x + arm->qi[i];
            double R[9], r[3], pose[12];
            if (arm->type[i] == 3) {
                arg[0] = qi, arg[1] = arm->geom + 4 * i, res[0] = pose;
                vgt_rec_module_pose(arg, res, iw, w, 0);
                memcpy(R, pose, 9 * sizeof(double));
                r[0] = pose[9], r[1] = pose[10], r[2] = pose[11] + arm->tz[i];
            } else {
                double c = cos(qi[0]), sn = sin(qi[0]);
                double Rz[9] = {c, -sn, 0.0, sn, c, 0.0, 0.0, 0.0, 1.0};
                memcpy(R, Rz, sizeof Rz);
                r[0] = 0.0, r[1] = 0.0, r[2] = arm->tz[i];
            }
            if (i == 0) {
                memcpy(R0, R, sizeof R);
                memcpy(p0, r, sizeof r);
            } else {
                double t[3];
                mul3(R0, r, t);
                matmul3(R0, R, R0);
                p0[0] += t[0], p0[1] += t[1], p0[2] += t[2];
            }
        }
        double t[3];
        mul3(R0, arm->tip, t);
        for (int r = 0; r < 3; ++r) tip[3 * s + r] = p0[r] + t[r];
    }
    return 0;
}

int vgt_rec_tip_state(const vgt_rec_arm *arm, long n, const double *q, const double *qd, double *tip, double *vel) {
    work_t k;
    if (work_open(&k, arm)) return -1;
    int nb = arm->nb, nq = arm->nq;
    for (long s = 0; s < n; ++s) {
        joints(arm, &k, q + s * nq, NULL, NULL);
        const body_t *last = k.body + nb - 1;
        double t[3];
        mul3(last->R0, arm->tip, t);
        for (int r = 0; r < 3; ++r) tip[3 * s + r] = last->p0[r] + t[r];
        if (vel) { /* the last body's velocity at the tip point, in base components */
            velocities(arm, &k, qd + s * nq);
            double w[3], u[3];
            cross3(last->v, arm->tip, w);
            for (int r = 0; r < 3; ++r) u[r] = last->v[3 + r] + w[r];
            mul3(last->R0, u, vel + 3 * s);
        }
    }
    work_close(&k);
    return 0;
}

/* ---- exact second- and third-order tip terms for the inverse kinematics ------------------------
 * (the algebra of second_order.py, per sample in C): P = T_1 ... T_b p with 4x4 homogeneous T_a of
 * each joint; a partial derivative in a coordinate of joint a falls on T_a alone. Jets in t of
 * P(q + t qd) hold derivatives of orders 0, 1, 2 (not Taylor coefficients). */

static void mm4(const double *A, const double *B, double *out) { /* out = A B (4x4), out may not alias */
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            out[4 * i + j] = A[4 * i] * B[j] + A[4 * i + 1] * B[4 + j] + A[4 * i + 2] * B[8 + j] + A[4 * i + 3] * B[12 + j];
}

static void mv4(const double *A, const double *x, double *out) {
    for (int i = 0; i < 4; ++i) out[i] = A[4 * i] * x[0] + A[4 * i + 1] * x[1] + A[4 * i + 2] * x[2] + A[4 * i + 3] * x[3];
}

/* the homogeneous matrix (bottom row one = 1 for a value, 0 for a derivative) of 12 values E, r */
static void homogeneous(const double *v, double tz, int value, double *out) {
    for (int i = 0; i < 3; ++i) {
        out[4 * i] = v[3 * i], out[4 * i + 1] = v[3 * i + 1], out[4 * i + 2] = v[3 * i + 2];
        out[4 * i + 3] = v[9 + i];
    }
    out[12] = out[13] = out[14] = 0.0;
    out[15] = value ? 1.0 : 0.0;
    if (value) out[11] += tz;
}

/* derivative k (0..3) of Trans(0, 0, tz) Rz(theta) in theta */
static void twist_derivative(double theta, double tz, int k, double *out) {
    const double quarter = 1.57079632679489661923; /* pi / 2 */
    double c = cos(theta + k * quarter), s = sin(theta + k * quarter);
    memset(out, 0, 16 * sizeof(double));
    out[0] = c, out[1] = -s, out[4] = s, out[5] = c;
    if (k == 0) out[10] = out[15] = 1.0, out[11] = tz;
}

/* jets of L D R (L: 3 matrices, D: 3 matrices, R: 3 vectors; order 1 or 3), first three rows */
static void triple_jet(int order, const double *L, const double *D, const double *R, double *out) {
    double t[4], u[4], x[4];
    /* order 0 */
    mv4(D, R, t);
    mv4(L, t, x);
    out[0] = x[0], out[1] = x[1], out[2] = x[2];
    if (order < 3) return;
    /* order 1: L1 D0 R0 + L0 D1 R0 + L0 D0 R1 */
    double y[4] = {0, 0, 0, 0};
    mv4(L + 16, t, x);
    for (int i = 0; i < 4; ++i) y[i] += x[i];
    mv4(D + 16, R, u);
    mv4(L, u, x);
    for (int i = 0; i < 4; ++i) y[i] += x[i];
    double w[4];
    mv4(D, R + 4, w);
    mv4(L, w, x);
    for (int i = 0; i < 4; ++i) y[i] += x[i];
    out[3] = y[0], out[4] = y[1], out[5] = y[2];
    /* order 2: L2 D0 R0 + L0 D2 R0 + L0 D0 R2 + 2 (L1 D1 R0 + L1 D0 R1 + L0 D1 R1) */
    double z[4] = {0, 0, 0, 0}, a[4], b[4];
    mv4(L + 32, t, x);
    for (int i = 0; i < 4; ++i) z[i] += x[i];
    mv4(D + 32, R, a);
    mv4(L, a, x);
    for (int i = 0; i < 4; ++i) z[i] += x[i];
    mv4(D, R + 8, a);
    mv4(L, a, x);
    for (int i = 0; i < 4; ++i) z[i] += x[i];
    mv4(L + 16, u, x); /* L1 D1 R0 */
    for (int i = 0; i < 4; ++i) z[i] += 2 * x[i];
    mv4(L + 16, w, x); /* L1 D0 R1 */
    for (int i = 0; i < 4; ++i) z[i] += 2 * x[i];
    mv4(D + 16, R + 4, b); /* L0 D1 R1 */
    mv4(L, b, x);
    for (int i = 0; i < 4; ++i) z[i] += 2 * x[i];
    out[6] = z[0], out[7] = z[1], out[8] = z[2];
}

int vgt_rec_ik_terms(const vgt_rec_arm *arm, long n, const double *q, const double *lam, const double *qd,
                     const double *lam_d, double *c, double *J, double *H, double *d2) {
    work_t k;
    if (work_open_sized(&k, arm, 1)) return -1;
    int nb = arm->nb, nq = arm->nq, order = qd ? 3 : 1;
    /* per body: T (3 jets), the partials D (3 coordinates x 3 jets), the second partials (3 x 3) */
    double *T = (double *)malloc(sizeof(double) * (size_t)nb * 48);
    double *D = (double *)malloc(sizeof(double) * (size_t)nb * 144);
    double *D2 = (double *)malloc(sizeof(double) * (size_t)nb * 144);
    double *L = (double *)malloc(sizeof(double) * (size_t)(nb + 1) * 48);
    double *R = (double *)malloc(sizeof(double) * (size_t)nb * 12);
    double *omega = (double *)malloc(sizeof(double) * (size_t)nq * 3);
    double *y = (double *)malloc(sizeof(double) * (size_t)nq * 3);
    double *cols = (double *)malloc(sizeof(double) * (size_t)nq * 9);
    int *joint = (int *)malloc(sizeof(int) * (size_t)nq);
    double *taylor = (double *)malloc(sizeof(double) * 480);
    if (!T || !D || !D2 || !L || !R || !omega || !y || !cols || !joint || !taylor) {
        free(T), free(D), free(D2), free(L), free(R), free(omega), free(y), free(cols), free(joint), free(taylor);
        work_close(&k);
        return -1;
    }
    for (int a = 0; a < nb; ++a)
        for (int j = 0; j < dofs(arm, a); ++j) joint[arm->qi[a] + j] = a;
    for (long s = 0; s < n; ++s) {
        const double *x = q + s * nq, *v = qd ? qd + s * nq : NULL, *l = lam + 3 * s;
        memset(T, 0, sizeof(double) * (size_t)nb * 48);
        memset(D, 0, sizeof(double) * (size_t)nb * 144);
        for (int a = 0; a < nb; ++a) {
            int nd = dofs(arm, a), qa = arm->qi[a];
            double tz = arm->tz[a];
            double d0[16], d1[3][16], dd[3][3][16], d3[3][3][3][16];
            if (arm->type[a] == 3) {
                k.arg[0] = x + qa, k.arg[1] = arm->geom + 4 * a;
                k.res[0] = taylor, k.res[1] = taylor + 12, k.res[2] = taylor + 48, k.res[3] = taylor + 156;
                vgt_rec_module_taylor(k.arg, k.res, k.iw, k.w, 0);
                homogeneous(taylor, tz, 1, d0);
                for (int i = 0; i < 3; ++i) {
                    homogeneous(taylor + 12 + 12 * i, 0.0, 0, d1[i]);
                    for (int j = 0; j < 3; ++j) {
                        homogeneous(taylor + 48 + 12 * (3 * i + j), 0.0, 0, dd[i][j]);
                        if (order == 3)
                            for (int m = 0; m < 3; ++m) homogeneous(taylor + 156 + 12 * (9 * i + 3 * j + m), 0.0, 0, d3[i][j][m]);
                    }
                }
            } else {
                twist_derivative(x[qa], tz, 0, d0);
                twist_derivative(x[qa], tz, 1, d1[0]);
                twist_derivative(x[qa], tz, 2, dd[0][0]);
                twist_derivative(x[qa], tz, 3, d3[0][0][0]);
            }
            double *Ta = T + 48 * a, *Da = D + 144 * a, *D2a = D2 + 144 * a;
            memcpy(Ta, d0, sizeof d0);
            for (int i = 0; i < nd; ++i) {
                memcpy(Da + 48 * i, d1[i], sizeof d0);
                for (int j = 0; j < nd; ++j) memcpy(D2a + 48 * i + 16 * j, dd[i][j], sizeof d0);
            }
            if (order == 3) {
                const double *va = v + qa;
                for (int e = 0; e < 16; ++e) {
                    double t1 = 0.0, t2 = 0.0;
                    for (int i = 0; i < nd; ++i) {
                        t1 += va[i] * d1[i][e];
                        for (int j = 0; j < nd; ++j) t2 += va[i] * va[j] * dd[i][j][e];
                    }
                    Ta[16 + e] = t1, Ta[32 + e] = t2;
                    for (int i = 0; i < nd; ++i) {
                        double p1 = 0.0, p2 = 0.0;
                        for (int j = 0; j < nd; ++j) {
                            p1 += va[j] * dd[i][j][e];
                            for (int m = 0; m < nd; ++m) p2 += va[j] * va[m] * d3[i][j][m][e];
                        }
                        Da[48 * i + 16 + e] = p1, Da[48 * i + 32 + e] = p2;
                    }
                }
            }
        }
        /* prefix jets L[a] = T_1 ... T_(a-1) */
        memset(L, 0, sizeof(double) * 48);
        L[0] = L[5] = L[10] = L[15] = 1.0;
        for (int a = 0; a < nb; ++a) {
            const double *P = L + 48 * a, *Ta = T + 48 * a;
            double *N = L + 48 * (a + 1), tmp[16];
            mm4(P, Ta, N);
            if (order == 3) {
                mm4(P + 16, Ta, N + 16);
                mm4(P, Ta + 16, tmp);
                for (int e = 0; e < 16; ++e) N[16 + e] += tmp[e];
                mm4(P + 32, Ta, N + 32);
                mm4(P + 16, Ta + 16, tmp);
                for (int e = 0; e < 16; ++e) N[32 + e] += 2 * tmp[e];
                mm4(P, Ta + 32, tmp);
                for (int e = 0; e < 16; ++e) N[32 + e] += tmp[e];
            }
        }
        /* suffix jets R[a] = T_(a+1) ... T_b p */
        double *Rl = R + 12 * (nb - 1);
        memset(Rl, 0, sizeof(double) * 12);
        Rl[0] = arm->tip[0], Rl[1] = arm->tip[1], Rl[2] = arm->tip[2], Rl[3] = 1.0;
        for (int a = nb - 1; a > 0; --a) {
            const double *Ta = T + 48 * a, *X = R + 12 * a;
            double *Y = R + 12 * (a - 1), t[4];
            mv4(Ta, X, Y);
            if (order == 3) {
                mv4(Ta + 16, X, Y + 4);
                mv4(Ta, X + 4, t);
                for (int e = 0; e < 4; ++e) Y[4 + e] += t[e];
                mv4(Ta + 32, X, Y + 8);
                mv4(Ta + 16, X + 4, t);
                for (int e = 0; e < 4; ++e) Y[8 + e] += 2 * t[e];
                mv4(Ta, X + 8, t);
                for (int e = 0; e < 4; ++e) Y[8 + e] += t[e];
            }
        }
        /* the columns: dP/dq_i and its jets; omega_i; the diagonal blocks of H */
        double *Hs = H + (size_t)s * nq * nq;
        memset(Hs, 0, sizeof(double) * (size_t)nq * nq);
        for (int a = 0; a < nb; ++a) {
            int nd = dofs(arm, a), qa = arm->qi[a];
            const double *La = L + 48 * a, *Ra = R + 12 * a, *Ta = T + 48 * a;
            for (int i = 0; i < nd; ++i) {
                const double *Di = D + 144 * a + 48 * i;
                triple_jet(order, La, Di, Ra, cols + 9 * (qa + i));
                /* omega_i = R_L vee(dR R^T) */
                double W[9], loc[3];
                for (int r = 0; r < 3; ++r)
                    for (int cc = 0; cc < 3; ++cc)
                        W[3 * r + cc] = Di[4 * r] * Ta[4 * cc] + Di[4 * r + 1] * Ta[4 * cc + 1] + Di[4 * r + 2] * Ta[4 * cc + 2];
                loc[0] = W[7], loc[1] = W[2], loc[2] = W[3];
                for (int r = 0; r < 3; ++r)
                    omega[3 * (qa + i) + r] = La[4 * r] * loc[0] + La[4 * r + 1] * loc[1] + La[4 * r + 2] * loc[2];
                for (int j = 0; j < nd; ++j) {
                    double t[4], u[4];
                    mv4(D2 + 144 * a + 48 * i + 16 * j, Ra, t);
                    mv4(La, t, u);
                    Hs[(size_t)(qa + i) * nq + qa + j] = l[0] * u[0] + l[1] * u[1] + l[2] * u[2];
                }
            }
        }
        /* blocks off the diagonal: lam . (omega_i x u_j) = omega_i . (u_j x lam), joint(i) < joint(j) */
        for (int j = 0; j < nq; ++j) cross3(cols + 9 * j, l, y + 3 * j);
        for (int i = 0; i < nq; ++i) {
            const double *w = omega + 3 * i;
            for (int j = i + 1; j < nq; ++j) {
                if (joint[j] == joint[i]) continue;
                double h = w[0] * y[3 * j] + w[1] * y[3 * j + 1] + w[2] * y[3 * j + 2];
                Hs[(size_t)i * nq + j] = h, Hs[(size_t)j * nq + i] = h;
            }
        }
        const double *Lb = L + 48 * nb, *pt = R + 12 * (nb - 1);
        double tip[4];
        mv4(Lb, pt, tip);
        memcpy(c + 3 * s, tip, 3 * sizeof(double));
        double *Js = J + (size_t)s * 3 * nq;
        for (int i = 0; i < nq; ++i)
            for (int r = 0; r < 3; ++r) Js[r * nq + i] = cols[9 * i + r];
        if (order == 3 && d2) {
            const double *ld = lam_d + 3 * s;
            double *o = d2 + (size_t)s * (nq + 3);
            for (int i = 0; i < nq; ++i) {
                const double *col = cols + 9 * i;
                o[i] = l[0] * col[6] + l[1] * col[7] + l[2] * col[8] + 2 * (ld[0] * col[3] + ld[1] * col[4] + ld[2] * col[5]);
            }
            mv4(Lb + 32, pt, tip);
            o[nq] = tip[0], o[nq + 1] = tip[1], o[nq + 2] = tip[2];
        }
    }
    free(T), free(D), free(D2), free(L), free(R), free(omega), free(y), free(cols), free(joint), free(taylor);
    work_close(&k);
    return 0;
}

/* ---- the closed loop's step on shared kinematics ----------------------------------------------
 * In one step of the compiled loop the plant's tip state, the CFC law (inverse dynamics of the
 * commanded acceleration) and the plant's forward dynamics are evaluated at the same joints and
 * velocities (without sensing; with it, the plant's two at least). Each calling thread keeps the
 * joints' poses, motion subspaces and biases, the bodies' velocities and their velocity-product
 * forces v x* (I v) of the last (arm, q, qd) it was given; a function given the same arm and
 * bitwise the same q and qd reuses them and runs only its own pass. The arithmetic is that of
 * the batch functions, so the results are the same bit for bit. vgt_rec_step_forget (called on
 * every binding of a parameter vector: an arm's memory may be reused by another) drops them. */

typedef struct {
    const vgt_rec_arm *arm; /* the arm of the kept state (NULL: none) */
    unsigned long epoch;
    double *key;            /* q, qd (2 nq) */
    work_t work;            /* bodies and the module function's work arrays */
    void *memory;
    size_t size;
} shared_t;

static _Thread_local shared_t shared = {NULL, 0, NULL, {NULL, NULL, NULL, NULL, NULL, 0}, NULL, 0};
static volatile unsigned long shared_epoch = 1;

void vgt_rec_step_forget(void) { ++shared_epoch; }

/* The bodies of (arm, q, qd), kept or computed; NULL when memory fails. */
static body_t *shared_state(const vgt_rec_arm *arm, const double *q, const double *qd) {
    shared_t *c = &shared;
    size_t nq = (size_t)arm->nq, bytes = nq * sizeof(double);
    if (c->arm == arm && c->epoch == shared_epoch && !memcmp(c->key, q, bytes) && !memcmp(c->key + nq, qd, bytes))
        return c->work.body;
    c->arm = NULL;
    casadi_int sz_arg, sz_res, sz_iw, sz_w;
    vgt_rec_module_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
    size_t nb = (size_t)(arm->nb > 0 ? arm->nb : 1);
    size_t bodies = nb * sizeof(body_t), key = 2 * bytes, args = ((size_t)sz_arg + 1) * sizeof(casadi_real *);
    size_t ress = ((size_t)sz_res + 1) * sizeof(casadi_real *), iws = ((size_t)sz_iw + 1) * sizeof(casadi_int);
    size_t ws = ((size_t)sz_w + 1) * sizeof(casadi_real);
    size_t total = bodies + key + args + ress + iws + ws + 64;
    if (c->size < total) {
        void *grown = realloc(c->memory, total);
        if (!grown) return NULL;
        memset(grown, 0, total);
        c->memory = grown, c->size = total;
    }
    char *memory = (char *)c->memory;
    c->work.body = (body_t *)memory;
    c->key = (double *)(memory + bodies);
    c->work.arg = (const casadi_real **)(memory + bodies + key);
    c->work.res = (casadi_real **)(memory + bodies + key + args);
    c->work.iw = (casadi_int *)(memory + bodies + key + args + ress);
    c->work.w = (casadi_real *)(memory + bodies + key + args + ress + iws);
    c->work.owned = 0;
    joints(arm, &c->work, q, qd, NULL);
    velocities(arm, &c->work, qd);
    velocity_forces(arm, c->work.body);
    memcpy(c->key, q, bytes);
    memcpy(c->key + nq, qd, bytes);
    c->arm = arm, c->epoch = shared_epoch;
    return c->work.body;
}

int vgt_rec_step_inverse(const vgt_rec_arm *arm, const double *q, const double *qd, const double *qdd,
                         const double *fext, double *tau) {
    body_t *body = shared_state(arm, q, qd);
    if (!body) return -1;
    rnea_pass(arm, body, qd, qdd, fext, tau);
    return 0;
}

int vgt_rec_step_forward(const vgt_rec_arm *arm, const double *q, const double *qd, const double *tau,
                         const double *fext, double *qdd) {
    body_t *body = shared_state(arm, q, qd);
    if (!body) return -1;
    aba_pass(arm, body, qd, tau, fext, qdd);
    return 0;
}

int vgt_rec_step_tip_state(const vgt_rec_arm *arm, const double *q, const double *qd, double *tip, double *vel) {
    body_t *body = shared_state(arm, q, qd);
    if (!body) return -1;
    const body_t *last = body + arm->nb - 1;
    double t[3], w[3], u[3];
    mul3(last->R0, arm->tip, t);
    for (int r = 0; r < 3; ++r) tip[r] = last->p0[r] + t[r];
    cross3(last->v, arm->tip, w);
    for (int r = 0; r < 3; ++r) u[r] = last->v[3 + r] + w[r];
    mul3(last->R0, u, vel);
    return 0;
}

int vgt_rec_step_tip(const vgt_rec_arm *arm, const double *q, double *tip) {
    shared_t *c = &shared;
    if (c->arm == arm && c->epoch == shared_epoch && !memcmp(c->key, q, (size_t)arm->nq * sizeof(double))) {
        const body_t *last = c->work.body + arm->nb - 1;
        double t[3];
        mul3(last->R0, arm->tip, t);
        for (int r = 0; r < 3; ++r) tip[r] = last->p0[r] + t[r];
        return 0;
    }
    return vgt_rec_tip(arm, 1, q, tip);
}
