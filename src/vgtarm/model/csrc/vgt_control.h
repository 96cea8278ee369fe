/* The controller's per-period arithmetic, shared by the simulation and the exported controller.
 *
 * closed_loop.c (the simulated closed loop) and the exported controller (vgtarm.export, whose
 * vgtarm_controller.c includes a copy of this file) run the controller side of a control period
 * through these functions, so the two compute the same numbers in the same order: the tests hold
 * the exported controller to the simulation bit for bit. Only C99 and libm; no state, no I/O.
 * Every array is n joint values unless said otherwise.
 */
#ifndef VGT_CONTROL_H
#define VGT_CONTROL_H

#include <math.h>

/* Encoder reading of joint value x with step `step` (0: exact): the nearest count. */
static inline double vgt_quantise(double x, double step) { return step > 0.0 ? step * floor(x / step + 0.5) : x; }

/* The velocity the controller sees from two encoder readings qm0 -> qm one period dt apart: their
 * difference plus `noise` through the first-order filter of weight a on the previous estimate vm0. */
static inline void vgt_filtered_velocity(int n, double a, double dt, const double *qm, const double *qm0,
                                         const double *vm0, const double *noise, double *vm)
{
    for (int i = 0; i < n; ++i) vm[i] = a * vm0[i] + (1.0 - a) * ((qm[i] - qm0[i]) / dt + noise[i]);
}

/* The unfiltered velocity differenced from two encoder readings, plus `noise`. */
static inline void vgt_differenced_velocity(int n, double dt, const double *qm, const double *qm0,
                                            const double *noise, double *v)
{
    for (int i = 0; i < n; ++i) v[i] = (qm[i] - qm0[i]) / dt + noise[i];
}

/* One period of the steady-state Kalman filter of each joint (state q, v, d: position, velocity and
 * acceleration disturbance), from the estimate q0, v0, d0 of the sample before: predicted with the
 * model's acceleration a plus d over dt, corrected by the gains L[0..2] on the innovation z - q^-
 * of the encoder reading z. */
static inline void vgt_kalman_step(int n, double dt, const double *L, const double *q0, const double *v0,
                                   const double *d0, const double *a, const double *z, double *q, double *v,
                                   double *d)
{
    for (int i = 0; i < n; ++i) {
        const double acc = a[i] + d0[i];
        const double qp = q0[i] + dt * v0[i] + 0.5 * dt * dt * acc;
        const double vp = v0[i] + dt * acc;
        const double innovation = z[i] - qp;
        q[i] = qp + L[0] * innovation;
        v[i] = vp + L[1] * innovation;
        d[i] = d0[i] + L[2] * innovation;
    }
}

/* The momentum observer's window: the mean acceleration (vb - va) / dt over it. */
static inline void vgt_window_acceleration(int n, double dt, const double *va, const double *vb, double *acc)
{
    for (int i = 0; i < n; ++i) acc[i] = (vb[i] - va[i]) / dt;
}

/* The effort applied over a window of two periods: the mean of F2 (older) and F1. */
static inline void vgt_mean_effort(int n, const double *F2, const double *F1, double *applied)
{
    for (int i = 0; i < n; ++i) applied[i] = 0.5 * (F2[i] + F1[i]);
}

/* The observer's first-order filter, exact at the samples: tau = keep tau0 + (1 - keep)(raw - applied),
 * keep = exp(-K_O dt). */
static inline void vgt_observer_filter(int n, double keep, const double *tau0, const double *raw,
                                       const double *applied, double *tau)
{
    for (int i = 0; i < n; ++i) tau[i] = keep * tau0[i] + (1.0 - keep) * (raw[i] - applied[i]);
}

/* The force sensor fed forward: tau = J_P^T f (J_P 3 x n, row-major; f 3 values). */
static inline void vgt_force_feedforward(int n, const double *J, const double *f, double *tau)
{
    for (int i = 0; i < n; ++i) tau[i] = J[i] * f[0] + J[n + i] * f[1] + J[2 * n + i] * f[2];
}

/* Computed force control minus the estimate of the external efforts: F -= tau. */
static inline void vgt_subtract_estimate(int n, const double *tau, double *F)
{
    for (int i = 0; i < n; ++i) F[i] -= tau[i];
}

/* The Cholesky factor of the symmetric n x n matrix A (row-major), in place in its lower triangle;
 * 0 as soon as a pivot is not positive (A is not positive definite), 1 otherwise (about n^3 / 6
 * multiplications). The GA's definiteness test and the drilling controller's solves share it. */
static inline int vgt_cholesky(int n, double *A)
{
    for (int j = 0; j < n; ++j) {
        double d = A[j * n + j];
        for (int k = 0; k < j; ++k) d -= A[j * n + k] * A[j * n + k];
        if (!(d > 0.0)) return 0;
        d = sqrt(d);
        A[j * n + j] = d;
        for (int i = j + 1; i < n; ++i) {
            double v = A[i * n + j];
            for (int k = 0; k < j; ++k) v -= A[i * n + k] * A[j * n + k];
            A[i * n + j] = v / d;
        }
    }
    return 1;
}

/* The controller's clip of its effort F to its actuators' peak forces: |F_i| <= force[i] (INFINITY:
 * no actuator), as NumPy's minimum(maximum(F, -force), force). The force-speed line is the plant's
 * (vgt_saturate): a back-EMF acts continuously, and a controller that clipped to it at its sampled
 * velocity would close a loop of gain dt F_s / (v_max m) that chatters once it passes 2. */
static inline void vgt_clip(int n, const double *force, double *F)
{
    for (int i = 0; i < n; ++i) {
        if (F[i] < -force[i]) F[i] = -force[i];
        if (F[i] > force[i]) F[i] = force[i];
    }
}

/* The force the actuators deliver for the effort F at the joint velocities v
 * (vgtarm/model/actuators.py): |F_i| <= force[i] (inf: no actuator) and, where line[i] != 0, the
 * force-speed line of a motor whose voltage is bounded, F_i sign(v_i) <= force[i] (1 - |v_i| /
 * speed[i]) in the direction of motion (braking keeps the full force; past twice the no-load speed
 * both ends are the full braking force). F is clipped in place, as NumPy's
 * minimum(maximum(F, lower), upper). */
static inline void vgt_saturate(int n, const double *force, const double *speed, const double *line,
                                const double *v, double *F)
{
    for (int i = 0; i < n; ++i) {
        double lower = -force[i], upper = force[i];
        if (line[i] != 0.0) {
            const double r = v[i] / speed[i];
            upper = fmax(force[i] * fmin(1.0, 1.0 - r), -force[i]);
            lower = fmin(-force[i] * fmin(1.0, 1.0 + r), force[i]);
        }
        if (F[i] < lower) F[i] = lower;
        if (F[i] > upper) F[i] = upper;
    }
}

#endif
