/* Forward and inverse dynamics and the mass matrix of blocks of REC_LANES samples at once, one
 * sample per lane of a vector (included by vgt_rec.c after the one-sample code it mirrors:
 * vgt_rec_forward, vgt_rec_inverse and vgt_rec_mass run their batches through it in blocks, the
 * last n % REC_LANES samples one by one).
 *
 * Every step runs on vectors of REC_LANES doubles (GCC's and Clang's vector extensions): the joints
 * (lane_module and lane_module_kin: the generated module functions' own statements on vectors,
 * written by vgtarm.model.recursive.library.module_lanes into vgt_rec_module_lanes.h; sin, cos,
 * acos, atan2 and sqrt from libm lane by lane), the velocities and velocity-product forces, and
 * the articulated-body algorithm, recursive Newton-Euler or composite rigid bodies. Every
 * operation is that of the one-sample code, in the same order, lane by lane; nothing is contracted
 * (-ffp-contract=off) and the lanes never mix, so each sample's numbers are bit for bit those of
 * the one-sample code, whichever instruction set runs them: on x86-64, x86-64-v4 (AVX-512: a
 * vector is one register) or x86-64-v3 (AVX2: two), chosen by the CPU at the first call (or by
 * vgt_rec_lanes), a CPU without AVX2 running the one-sample code; elsewhere the baseline. Without
 * that header the joints come from the one-sample code, sample after sample, laid out lane by lane.
 * Compilers without the vector extensions (or VGT_REC_NO_LANES defined) run every sample one by
 * one. */

#if defined(__GNUC__) && !defined(VGT_REC_NO_LANES)
#define REC_LANES 8
typedef double vd __attribute__((vector_size(8 * REC_LANES)));
#define LANE_INLINE static inline __attribute__((always_inline))
#define LANE_SPLAT(x) ((double)(x) - (vd){0}) /* every lane x (x - 0 keeps the sign of a zero) */

/* A body's numbers in lanes that the articulated-body algorithm keeps between its passes; its
 * articulated inertia and bias force are carried from body to parent instead. */
typedef struct {
    vd R[9], r[3], S[18], c[6], vf[6], U[18], Dinv[9], u[3], f[6];
} lane_body_t;

/* The memory of one block: the bodies, then q, qd, the input (efforts or accelerations) and the
 * output (nq each), the last body's R0 (9), the tip wrench (6) and the composite inertias (36 per
 * body, for the mass matrix), in lanes. */
typedef struct {
    lane_body_t *body;
    vd *q, *qd, *in, *out, *R0, *fext, *IA;
} lane_work_t;

static _Thread_local scratch_t lane_scratch = {NULL, 0};

static int lane_open(lane_work_t *w, const vgt_rec_arm *arm) {
    size_t nb = (size_t)(arm->nb > 0 ? arm->nb : 1), nq = (size_t)arm->nq;
    size_t bodies = nb * sizeof(lane_body_t), total = bodies + (4 * nq + 15 + 36 * nb) * sizeof(vd);
    if (lane_scratch.size < total) {
        free(lane_scratch.memory);
        lane_scratch.size = 0;
        lane_scratch.memory = aligned_alloc(sizeof(vd), total); /* total: a multiple of sizeof(vd) */
        if (!lane_scratch.memory) return -1;
        lane_scratch.size = total;
    }
    char *memory = (char *)lane_scratch.memory;
    w->body = (lane_body_t *)memory;
    w->q = (vd *)(memory + bodies), w->qd = w->q + nq, w->in = w->qd + nq, w->out = w->in + nq;
    w->R0 = w->out + nq, w->fext = w->R0 + 9, w->IA = w->fext + 6;
    return 0;
}

/* ---- the helpers of vgt_rec.c, lane by lane ------------------------------------------------- */

LANE_INLINE void l_cross3(const vd *a, const vd *b, vd *out) {
    vd x = a[1] * b[2] - a[2] * b[1], y = a[2] * b[0] - a[0] * b[2], z = a[0] * b[1] - a[1] * b[0];
    out[0] = x, out[1] = y, out[2] = z;
}

LANE_INLINE void l_cross3_s(const double *a, const vd *b, vd *out) { /* a the same in every lane */
    vd x = a[1] * b[2] - a[2] * b[1], y = a[2] * b[0] - a[0] * b[2], z = a[0] * b[1] - a[1] * b[0];
    out[0] = x, out[1] = y, out[2] = z;
}

LANE_INLINE void l_mul3(const vd *R, const vd *x, vd *out) {
    vd a = R[0] * x[0] + R[1] * x[1] + R[2] * x[2];
    vd b = R[3] * x[0] + R[4] * x[1] + R[5] * x[2];
    vd c = R[6] * x[0] + R[7] * x[1] + R[8] * x[2];
    out[0] = a, out[1] = b, out[2] = c;
}

LANE_INLINE void l_mul3t(const vd *R, const vd *x, vd *out) {
    vd a = R[0] * x[0] + R[3] * x[1] + R[6] * x[2];
    vd b = R[1] * x[0] + R[4] * x[1] + R[7] * x[2];
    vd c = R[2] * x[0] + R[5] * x[1] + R[8] * x[2];
    out[0] = a, out[1] = b, out[2] = c;
}

LANE_INLINE void l_matmul3(const vd *A, const vd *B, vd *out) { /* out may alias A or B */
    vd t[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) t[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
    for (int e = 0; e < 9; ++e) out[e] = t[e];
}

/* A function of libm on every lane, one after the other (the one-sample code's numbers); statement
 * expressions, not functions, so that no vector is passed by value. */
#define LANE_LIBM(f, x)                                                                             \
    __extension__({                                                                                 \
        vd x_ = (x), y_ = x_;                                                                       \
        for (int l_ = 0; l_ < REC_LANES; ++l_) y_[l_] = f(x_[l_]);                                  \
        y_;                                                                                         \
    })
#define lane_sin(x) LANE_LIBM(sin, x)
#define lane_cos(x) LANE_LIBM(cos, x)
#define lane_acos(x) LANE_LIBM(acos, x)
#define lane_sqrt(x) LANE_LIBM(sqrt, x)
#define lane_atan2(y, x)                                                                            \
    __extension__({                                                                                 \
        vd y_ = (y), x_ = (x), z_ = y_;                                                             \
        for (int l_ = 0; l_ < REC_LANES; ++l_) z_[l_] = atan2(y_[l_], x_[l_]);                      \
        z_;                                                                                         \
    })
#define lane_sq(x) ((x) * (x)) /* casadi_sq: its argument is always a variable */

#if defined(__has_include)
#if __has_include("vgt_rec_module_lanes.h")
#include "vgt_rec_module_lanes.h" /* lane_module: the generated module function on vectors */
#endif
#endif

LANE_INLINE void l_motion_in(const lane_body_t *b, const vd *m, vd *out) {
    vd t[3], w[3];
    l_cross3(b->r, m, t);
    t[0] = m[3] - t[0], t[1] = m[4] - t[1], t[2] = m[5] - t[2];
    l_mul3t(b->R, m, w);
    l_mul3t(b->R, t, out + 3);
    out[0] = w[0], out[1] = w[1], out[2] = w[2];
}

LANE_INLINE void l_force_out(const lane_body_t *b, const vd *f, vd *out) {
    vd n[3], t[3];
    l_mul3(b->R, f + 3, out + 3);
    l_mul3(b->R, f, n);
    l_cross3(b->r, out + 3, t);
    out[0] = n[0] + t[0], out[1] = n[1] + t[1], out[2] = n[2] + t[2];
}

LANE_INLINE void l_cross_motion(const vd *v, const vd *m, vd *out) {
    vd a[3], b[3], c[3];
    l_cross3(v, m, a);
    l_cross3(v, m + 3, b);
    l_cross3(v + 3, m, c);
    out[0] = a[0], out[1] = a[1], out[2] = a[2];
    out[3] = b[0] + c[0], out[4] = b[1] + c[1], out[5] = b[2] + c[2];
}

LANE_INLINE void l_cross_force(const vd *v, const vd *f, vd *out) {
    vd a[3], b[3], c[3];
    l_cross3(v, f, a);
    l_cross3(v + 3, f + 3, b);
    l_cross3(v, f + 3, c);
    out[0] = a[0] + b[0], out[1] = a[1] + b[1], out[2] = a[2] + b[2];
    out[3] = c[0], out[4] = c[1], out[5] = c[2];
}

LANE_INLINE void l_mul6_s(const double *I, const vd *x, vd *out) { /* I the same in every lane */
    for (int i = 0; i < 6; ++i) {
        const double *row = I + 6 * i;
        out[i] = row[0] * x[0] + row[1] * x[1] + row[2] * x[2] + row[3] * x[3] + row[4] * x[4] + row[5] * x[5];
    }
}

LANE_INLINE void l_mul6(const vd *I, const vd *x, vd *out) {
    for (int i = 0; i < 6; ++i) {
        const vd *row = I + 6 * i;
        out[i] = row[0] * x[0] + row[1] * x[1] + row[2] * x[2] + row[3] * x[3] + row[4] * x[4] + row[5] * x[5];
    }
}

LANE_INLINE void l_rotate_block(const vd *R, const vd *I, int row, int col, vd *out) {
    vd t[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            t[3 * i + j] = R[3 * i] * I[6 * row + col + j] + R[3 * i + 1] * I[6 * (row + 1) + col + j] +
                           R[3 * i + 2] * I[6 * (row + 2) + col + j];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) out[3 * i + j] = t[3 * i] * R[3 * j] + t[3 * i + 1] * R[3 * j + 1] + t[3 * i + 2] * R[3 * j + 2];
}

LANE_INLINE void l_inertia_out(const lane_body_t *b, const vd *I, vd *P) {
    vd A[9], B[9], C[9], BX[9], XC[9], XCX[9];
    const vd *r = b->r;
    l_rotate_block(b->R, I, 0, 0, A);
    l_rotate_block(b->R, I, 0, 3, B);
    l_rotate_block(b->R, I, 3, 3, C);
    for (int i = 0; i < 3; ++i) {
        const vd *Bi = B + 3 * i;
        BX[3 * i + 0] = Bi[1] * r[2] - Bi[2] * r[1];
        BX[3 * i + 1] = Bi[2] * r[0] - Bi[0] * r[2];
        BX[3 * i + 2] = Bi[0] * r[1] - Bi[1] * r[0];
    }
    for (int j = 0; j < 3; ++j) {
        XC[0 + j] = -r[2] * C[3 + j] + r[1] * C[6 + j];
        XC[3 + j] = r[2] * C[0 + j] - r[0] * C[6 + j];
        XC[6 + j] = -r[1] * C[0 + j] + r[0] * C[3 + j];
    }
    for (int i = 0; i < 3; ++i) {
        const vd *Xi = XC + 3 * i;
        XCX[3 * i + 0] = Xi[1] * r[2] - Xi[2] * r[1];
        XCX[3 * i + 1] = Xi[2] * r[0] - Xi[0] * r[2];
        XCX[3 * i + 2] = Xi[0] * r[1] - Xi[1] * r[0];
    }
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            P[6 * i + j] += A[3 * i + j] - BX[3 * i + j] - BX[3 * j + i] - XCX[3 * i + j];
            vd off = B[3 * i + j] + XC[3 * i + j];
            P[6 * i + 3 + j] += off;
            P[6 * (3 + j) + i] += off;
            P[6 * (3 + i) + 3 + j] += C[3 * i + j];
        }
}

LANE_INLINE void l_inverse_spd(const vd *D, int nd, vd *out) {
    if (nd == 1) {
        out[0] = 1.0 / D[0];
        return;
    }
    vd a = D[0], b = D[1], c = D[2], d = D[4], e = D[5], f = D[8];
    vd A = d * f - e * e, B = c * e - b * f, C = b * e - c * d;
    vd det = a * A + b * B + c * C, inv = 1.0 / det;
    out[0] = A * inv, out[1] = B * inv, out[2] = C * inv;
    out[3] = B * inv, out[4] = (a * f - c * c) * inv, out[5] = (b * c - a * e) * inv;
    out[6] = C * inv, out[7] = (b * c - a * e) * inv, out[8] = (a * d - b * b) * inv;
}

/* ---- the block ------------------------------------------------------------------------------- */

/* The inputs of the block's samples (row-major q, qd, in, fext from its first sample; all but q
 * may be NULL) in lanes. */
static void lane_inputs(const vgt_rec_arm *arm, lane_work_t *w, const double *q, const double *qd, const double *in,
                        const double *fext) {
    int nq = arm->nq;
    for (int l = 0; l < REC_LANES; ++l) {
        for (int j = 0; j < nq; ++j) {
            w->q[j][l] = q[(long)l * nq + j];
            if (qd) w->qd[j][l] = qd[(long)l * nq + j], w->in[j][l] = in[(long)l * nq + j];
        }
        if (fext)
            for (int e = 0; e < 6; ++e) w->fext[e][l] = fext[6 * l + e];
    }
}

#ifndef VGT_REC_MODULE_LANES
/* The joints of the block's samples (row-major q and qd from its first sample; qd NULL: for the
 * mass matrix), lane by lane: each sample's from joints(), the one-sample code. */
static void lane_joints(const vgt_rec_arm *arm, work_t *k, lane_work_t *w, const double *q, const double *qd) {
    int nb = arm->nb, nq = arm->nq;
    for (int l = 0; l < REC_LANES; ++l) {
        joints(arm, k, q + (long)l * nq, qd ? qd + (long)l * nq : NULL, NULL);
        for (int i = 0; i < nb; ++i) {
            const body_t *b = k->body + i;
            lane_body_t *o = w->body + i;
            for (int e = 0; e < 9; ++e) o->R[e][l] = b->R[e];
            for (int e = 0; e < 3; ++e) o->r[e][l] = b->r[e];
            for (int e = 0; e < 18; ++e) o->S[e][l] = b->S[e];
            for (int e = 0; e < 6; ++e) o->c[e][l] = b->cj[e]; /* c = cj + v x vj: lane_velocities */
        }
        for (int e = 0; e < 9; ++e) w->R0[e][l] = k->body[nb - 1].R0[e];
    }
}
#endif

#ifdef VGT_REC_MODULE_LANES
/* joints() lane by lane (the base frame's axes R0 of the last body only, and only for a tip wrench):
 * the modules' from lane_module, the generated function's operations on vectors, or from
 * lane_module_kin (no velocities, no bias c) when `kin` (for the mass matrix). */
LANE_INLINE void lane_module_joints(const vgt_rec_arm *arm, lane_work_t *w, int fext, int kin) {
    const vd zero = LANE_SPLAT(0.0), one = LANE_SPLAT(1.0);
    for (int i = 0; i < arm->nb; ++i) {
        lane_body_t *b = w->body + i;
        const vd *x = w->q + arm->qi[i];
        if (arm->type[i] == 3) {
            vd pose[12], g[4];
            for (int e = 0; e < 4; ++e) g[e] = LANE_SPLAT(arm->geom[4 * i + e]);
            if (kin) {
                vd passive[4];
                const vd *arg[2] = {x, g};
                vd *res[3] = {pose, b->S, passive};
                lane_module_kin(arg, res);
            } else {
                const vd *arg[3] = {x, w->qd + arm->qi[i], g};
                vd *res[3] = {pose, b->S, b->c}; /* c = cj + v x vj: lane_velocities */
                lane_module(arg, res);
            }
            for (int e = 0; e < 9; ++e) b->R[e] = pose[e];
            b->r[0] = pose[9], b->r[1] = pose[10], b->r[2] = pose[11] + arm->tz[i];
        } else {
            vd c = lane_cos(x[0]), s = lane_sin(x[0]);
            b->R[0] = c, b->R[1] = -s, b->R[2] = zero, b->R[3] = s, b->R[4] = c, b->R[5] = zero;
            b->R[6] = zero, b->R[7] = zero, b->R[8] = one;
            b->r[0] = zero, b->r[1] = zero, b->r[2] = LANE_SPLAT(arm->tz[i]);
            for (int e = 0; e < 18; ++e) b->S[e] = zero;
            b->S[2 * 3] = one;
            for (int e = 0; e < 6; ++e) b->c[e] = zero;
        }
        if (fext && i == 0)
            for (int e = 0; e < 9; ++e) w->R0[e] = b->R[e];
        else if (fext)
            l_matmul3(w->R0, b->R, w->R0);
    }
}
#define LANE_JOINTS(arm, w, fext, kin) lane_module_joints(arm, w, fext, kin)
#else
#define LANE_JOINTS(arm, w, fext, kin) ((void)0) /* lane_joints before */
#endif

/* velocities() and velocity_forces() lane by lane (the velocities are not kept) */
LANE_INLINE void lane_velocities(const vgt_rec_arm *arm, lane_work_t *w) {
    vd v[6];
    for (int i = 0; i < arm->nb; ++i) {
        lane_body_t *b = w->body + i;
        int nd = dofs(arm, i);
        const vd *x = w->qd + arm->qi[i];
        vd vj[6], t[6], Iv[6];
        for (int r = 0; r < 6; ++r) {
            vd s = LANE_SPLAT(0.0);
            for (int j = 0; j < nd; ++j) s += b->S[3 * r + j] * x[j];
            vj[r] = s;
        }
        if (i == 0)
            for (int r = 0; r < 6; ++r) t[r] = LANE_SPLAT(0.0);
        else
            l_motion_in(b, v, t);
        for (int r = 0; r < 6; ++r) v[r] = t[r] + vj[r];
        l_cross_motion(v, vj, t);
        for (int r = 0; r < 6; ++r) b->c[r] = b->c[r] + t[r];
        l_mul6_s(arm->inertia + 36 * i, v, Iv);
        l_cross_force(v, Iv, b->vf);
    }
}

/* The backward pass of aba_pass at body i: its U, u, Dinv from the articulated inertia IA and bias
 * pA carried from its children; then (i > 0) the parent's, into IP and pP (its own inertia and
 * velocity-product force already there). */
LANE_INLINE void lane_aba_body(const vgt_rec_arm *arm, lane_work_t *w, int i, const vd *IA, const vd *pA, vd *IP,
                               vd *pP) {
    lane_body_t *b = w->body + i;
    int nd = dofs(arm, i);
    vd D[9];
    for (int j = 0; j < nd; ++j) {
        vd col[6], u[6];
        for (int r = 0; r < 6; ++r) col[r] = b->S[3 * r + j];
        l_mul6(IA, col, u);
        for (int r = 0; r < 6; ++r) b->U[3 * r + j] = u[r];
    }
    for (int r = 0; r < nd; ++r) {
        int c = arm->qi[i] + r;
        vd sum = LANE_SPLAT(0.0);
        for (int e = 0; e < 6; ++e) sum += b->S[3 * e + r] * pA[e];
        b->u[r] = w->in[c] - arm->viscous[c] * w->qd[c] - sum;
        for (int j = 0; j < nd; ++j) {
            vd d = LANE_SPLAT(0.0);
            for (int e = 0; e < 6; ++e) d += b->S[3 * e + r] * b->U[3 * e + j];
            D[3 * r + j] = d;
        }
    }
    l_inverse_spd(D, nd, b->Dinv);
    if (i == 0) return;
    vd Ia[36], pa[6], UD[18], g[6];
    for (int r = 0; r < 6; ++r)
        for (int j = 0; j < nd; ++j) {
            vd sum = LANE_SPLAT(0.0);
            for (int e = 0; e < nd; ++e) sum += b->U[3 * r + e] * b->Dinv[3 * e + j];
            UD[3 * r + j] = sum;
        }
    for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) {
            vd sum = LANE_SPLAT(0.0);
            for (int e = 0; e < nd; ++e) sum += UD[3 * r + e] * b->U[3 * c + e];
            Ia[6 * r + c] = IA[6 * r + c] - sum;
        }
    l_mul6(Ia, b->c, pa);
    for (int r = 0; r < 6; ++r) {
        vd sum = LANE_SPLAT(0.0);
        for (int e = 0; e < nd; ++e) sum += UD[3 * r + e] * b->u[e];
        pa[r] += pA[r] + sum;
    }
    l_inertia_out(b, Ia, IP);
    l_force_out(b, pa, g);
    for (int r = 0; r < 6; ++r) pP[r] += g[r];
}

/* tip_force() lane by lane */
LANE_INLINE void lane_tip_force(const vgt_rec_arm *arm, const lane_work_t *w, vd *out) {
    vd t[3];
    l_mul3t(w->R0, w->fext, out + 3);
    l_mul3t(w->R0, w->fext + 3, out);
    l_cross3_s(arm->tip, out + 3, t);
    out[0] += t[0], out[1] += t[1], out[2] += t[2];
}

/* rnea_pass lane by lane: the efforts into w->out. */
LANE_INLINE void lane_rnea(const vgt_rec_arm *arm, lane_work_t *w, int fext) {
    int nb = arm->nb;
    vd a[6];
    for (int r = 0; r < 6; ++r) a[r] = LANE_SPLAT(r < 3 ? 0.0 : -arm->gravity[r - 3]);
    for (int i = 0; i < nb; ++i) {
        lane_body_t *b = w->body + i;
        int nd = dofs(arm, i);
        const vd *x = w->in + arm->qi[i];
        vd t[6];
        l_motion_in(b, a, t);
        for (int r = 0; r < 6; ++r) {
            vd s = LANE_SPLAT(0.0);
            for (int j = 0; j < nd; ++j) s += b->S[3 * r + j] * x[j];
            a[r] = s + (t[r] + b->c[r]);
        }
        l_mul6_s(arm->inertia + 36 * i, a, b->f);
        for (int r = 0; r < 6; ++r) b->f[r] += b->vf[r];
    }
    if (fext) {
        vd fb[6];
        lane_tip_force(arm, w, fb);
        for (int r = 0; r < 6; ++r) w->body[nb - 1].f[r] -= fb[r];
    }
    for (int i = nb - 1; i >= 0; --i) {
        lane_body_t *b = w->body + i;
        for (int j = 0; j < dofs(arm, i); ++j) {
            vd sum = LANE_SPLAT(0.0);
            for (int e = 0; e < 6; ++e) sum += b->S[3 * e + j] * b->f[e];
            int c = arm->qi[i] + j;
            w->out[c] = sum + arm->viscous[c] * w->qd[c];
        }
        if (i > 0) {
            vd g[6];
            l_force_out(b, b->f, g);
            for (int r = 0; r < 6; ++r) w->body[i - 1].f[r] += g[r];
        }
    }
}

/* aba_pass lane by lane: the accelerations into w->out. */
LANE_INLINE void lane_aba(const vgt_rec_arm *arm, lane_work_t *w, int fext) {
    int nb = arm->nb;
    vd IA[2][36], pA[2][6];
    for (int e = 0; e < 36; ++e) IA[(nb - 1) & 1][e] = LANE_SPLAT(arm->inertia[36 * (nb - 1) + e]);
    for (int r = 0; r < 6; ++r) pA[(nb - 1) & 1][r] = w->body[nb - 1].vf[r];
    if (fext) {
        vd fb[6];
        lane_tip_force(arm, w, fb);
        for (int r = 0; r < 6; ++r) pA[(nb - 1) & 1][r] -= fb[r];
    }
    for (int i = nb - 1; i >= 0; --i) {
        vd *IP = IA[(i + 1) & 1], *pP = pA[(i + 1) & 1];
        if (i > 0) {
            for (int e = 0; e < 36; ++e) IP[e] = LANE_SPLAT(arm->inertia[36 * (i - 1) + e]);
            for (int r = 0; r < 6; ++r) pP[r] = w->body[i - 1].vf[r];
        }
        lane_aba_body(arm, w, i, IA[i & 1], pA[i & 1], IP, pP);
    }
    vd a[6];
    for (int r = 0; r < 6; ++r) a[r] = LANE_SPLAT(r < 3 ? 0.0 : -arm->gravity[r - 3]);
    for (int i = 0; i < nb; ++i) {
        const lane_body_t *b = w->body + i;
        int nd = dofs(arm, i);
        vd ap[6], t[3], *A = w->out + arm->qi[i];
        l_motion_in(b, a, ap);
        for (int r = 0; r < 6; ++r) ap[r] += b->c[r];
        for (int r = 0; r < nd; ++r) {
            vd sum = LANE_SPLAT(0.0);
            for (int e = 0; e < 6; ++e) sum += b->U[3 * e + r] * ap[e];
            t[r] = b->u[r] - sum;
        }
        for (int r = 0; r < nd; ++r) {
            vd sum = LANE_SPLAT(0.0);
            for (int e = 0; e < nd; ++e) sum += b->Dinv[3 * r + e] * t[e];
            A[r] = sum;
        }
        for (int r = 0; r < 6; ++r) {
            vd sum = ap[r];
            for (int e = 0; e < nd; ++e) sum += b->S[3 * r + e] * A[e];
            a[r] = sum;
        }
    }
}

/* vgt_rec_mass lane by lane: each sample's M (nq x nq, row-major) at m + its lane * nq^2. */
LANE_INLINE void lane_mass(const vgt_rec_arm *arm, lane_work_t *w, double *m) {
    int nb = arm->nb, nq = arm->nq;
    long size = (long)nq * nq;
    for (int i = 0; i < nb; ++i)
        for (int e = 0; e < 36; ++e) w->IA[36 * i + e] = LANE_SPLAT(arm->inertia[36 * i + e]);
    for (int i = nb - 1; i > 0; --i) l_inertia_out(w->body + i, w->IA + 36 * i, w->IA + 36 * (i - 1));
    for (int i = 0; i < nb; ++i) {
        const lane_body_t *b = w->body + i;
        int nd = dofs(arm, i);
        vd F[3][6];
        for (int j = 0; j < nd; ++j) {
            vd col[6];
            for (int r = 0; r < 6; ++r) col[r] = b->S[3 * r + j];
            l_mul6(w->IA + 36 * i, col, F[j]);
        }
        for (int jb = i; jb >= 0; --jb) {
            const lane_body_t *o = w->body + jb;
            if (jb < i)
                for (int j = 0; j < nd; ++j) l_force_out(w->body + jb + 1, F[j], F[j]);
            for (int r = 0; r < dofs(arm, jb); ++r)
                for (int j = 0; j < nd; ++j) {
                    vd sum = LANE_SPLAT(0.0);
                    for (int e = 0; e < 6; ++e) sum += o->S[3 * e + r] * F[j][e];
                    long row = arm->qi[jb] + r, col = arm->qi[i] + j;
                    for (int l = 0; l < REC_LANES; ++l)
                        m[l * size + row * nq + col] = m[l * size + col * nq + row] = sum[l];
                }
        }
    }
}

/* The vector part of a block (its outputs in w->out from its joints in w): forward dynamics (kind
 * 0), inverse dynamics (1) or the mass matrix (2: into m), for each instruction set: on x86-64,
 * x86-64-v4 and x86-64-v3 (a CPU without AVX2 runs the one-sample code: vectors of eight doubles
 * in SSE2 registers took GCC 12 nine seconds more to compile); elsewhere the baseline. All but
 * x86-64-v4 at -O2, none contracted: with GCC 12, -O2 halved the compile time of the v4 and v3
 * code and made v4's forward dynamics 20 % slower, so v4 keeps -O3. */
#define LANE_OPTIONS __attribute__((noinline))
#if defined(__clang__)
#define LANE_OPTIONS_O2 LANE_OPTIONS
#else
#define LANE_OPTIONS_O2 __attribute__((noinline, optimize("O2", "fp-contract=off")))
#endif
#define LANE_BODY                                                                                   \
    {                                                                                               \
        LANE_JOINTS(arm, w, fext, kind == 2);                                                       \
        if (kind == 2) {                                                                            \
            lane_mass(arm, w, m);                                                                   \
            return;                                                                                 \
        }                                                                                           \
        lane_velocities(arm, w);                                                                    \
        if (kind == 1)                                                                              \
            lane_rnea(arm, w, fext);                                                                \
        else                                                                                        \
            lane_aba(arm, w, fext);                                                                 \
    }
typedef void (*lane_fn)(const vgt_rec_arm *arm, lane_work_t *w, int fext, int kind, double *m);
#if defined(__x86_64__)
LANE_OPTIONS __attribute__((target("arch=x86-64-v4"))) static void lane_forward_v4(const vgt_rec_arm *arm,
                                                                                   lane_work_t *w, int fext,
                                                                                   int kind, double *m)
LANE_BODY
LANE_OPTIONS_O2 __attribute__((target("arch=x86-64-v3"))) static void lane_forward_v3(const vgt_rec_arm *arm,
                                                                                   lane_work_t *w, int fext,
                                                                                   int kind, double *m)
LANE_BODY
#else
LANE_OPTIONS_O2 static void lane_forward_baseline(const vgt_rec_arm *arm, lane_work_t *w, int fext, int kind,
                                               double *m)
LANE_BODY
#endif

/* The lane code of instruction set `level` (1 the baseline, 2 x86-64-v3, 3 x86-64-v4; anything else
 * the best this CPU has), or NULL when the CPU or this library lacks it. */
static lane_fn lane_code(int level) {
    int best = 1;
#if defined(__x86_64__)
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi") &&
        __builtin_cpu_supports("bmi2"))
        best = 2;
    if (best == 2 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
        __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512cd"))
        best = 3;
#endif
    if (level < 1 || level > 3) level = best;
    if (level > best) return NULL;
#if defined(__x86_64__)
    if (level == 3) return lane_forward_v4;
    if (level == 2) return lane_forward_v3;
    return NULL;
#else
    return lane_forward_baseline;
#endif
}

static lane_fn lane_chosen = NULL;   /* NULL: not chosen yet */
static int lane_off = 0;             /* 1: every sample through the one-sample code */

int vgt_rec_lanes(int level) {
    if (level == 0) {
        __atomic_store_n(&lane_off, 1, __ATOMIC_RELAXED);
        return 0;
    }
    lane_fn code = lane_code(level);
    if (!code && level >= 1 && level <= 3) return -1;
    __atomic_store_n(&lane_chosen, code, __ATOMIC_RELAXED);
    __atomic_store_n(&lane_off, code ? 0 : 1, __ATOMIC_RELAXED); /* none on this CPU: one by one */
    return code ? REC_LANES : 0;
}

/* Forward dynamics (kind 0: in the efforts, out the accelerations, as vgt_rec_forward), inverse
 * dynamics (1: in the accelerations, out the efforts, as vgt_rec_inverse) or the mass matrix (2: q
 * alone, out the matrices, as vgt_rec_mass) of the first n - n % REC_LANES samples, in blocks;
 * returns how many it did (0 when its memory could not be had: the one-sample code does them). */
static long run_lanes(const vgt_rec_arm *arm, work_t *k, long n, const double *q, const double *qd,
                      const double *in, const double *fext, double *out, int kind) {
    lane_work_t w;
    int nq = arm->nq;
    if (n < REC_LANES || __atomic_load_n(&lane_off, __ATOMIC_RELAXED) || lane_open(&w, arm)) return 0;
    lane_fn run = __atomic_load_n(&lane_chosen, __ATOMIC_RELAXED);
    if (!run && !vgt_rec_lanes(-1)) return 0; /* the first call: the same answer in every thread */
    run = __atomic_load_n(&lane_chosen, __ATOMIC_RELAXED);
    long s = 0;
    for (; s + REC_LANES <= n; s += REC_LANES) {
        long at = s * nq;
        lane_inputs(arm, &w, q + at, qd ? qd + at : NULL, in ? in + at : NULL, fext ? fext + 6 * s : NULL);
#ifndef VGT_REC_MODULE_LANES
        lane_joints(arm, k, &w, q + at, qd ? qd + at : NULL);
#else
        (void)k;
#endif
        run(arm, &w, fext != NULL, kind, kind == 2 ? out + at * nq : NULL);
        if (kind < 2)
            for (int l = 0; l < REC_LANES; ++l)
                for (int j = 0; j < nq; ++j) out[at + (long)l * nq + j] = w.out[j][l];
    }
    return s;
}
#else
int vgt_rec_lanes(int level) { return level == 0 ? 0 : -1; }

static long run_lanes(const vgt_rec_arm *arm, work_t *k, long n, const double *q, const double *qd,
                      const double *in, const double *fext, double *out, int kind) {
    (void)arm, (void)k, (void)n, (void)q, (void)qd, (void)in, (void)fext, (void)out, (void)kind;
    return 0;
}
#endif
