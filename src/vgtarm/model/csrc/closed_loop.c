/* Closed-loop drivers for the CasADi-generated model (part of vgtarm).
 *
 * vgt_simulate runs computed force control on the plant for a range of samples in one call
 * (vgt_simulate_slice the same in slices of bounded work, so the caller can stop between them);
 * vgt_ga_fitness predicts, for a batch of gain candidates, the tip tracking error over a horizon
 * under the controller's model. Both call the generated functions through pointers filled in by
 * vgtarm/model/closedloop.py (the structures are declared once, in vgtarm.h); the Python reference loop in vgtarm/simulation/python_loop.py does the
 * same computation and the tests hold the two to each other.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "vgtarm.h"
#include "vgt_control.h" /* the controller's per-period arithmetic, shared with the exported controller */
#include "vgt_work.h"    /* the generated functions' work arrays */

#ifdef VGT_MARGIN_ROW
/* A library may sum the margin rows of the assembly check (check_state) with a function of its
 * own, named by this macro: margin + G[row] . q. The recursive model's library is compiled with
 * -DVGT_MARGIN_ROW=vgt_rec_margin (model/recursive/library.py), which sums the rows a run bound over
 * their nonzero entries; the symbolic libraries define no such macro and sum every entry here. */
double VGT_MARGIN_ROW(const double *G, int nj, int row, double margin, const double *q);
#endif

static int work_alloc(vgt_work *wk, const vgt_model *m)
{
    const vgt_call *calls[6] = {&m->cfc, &m->fd, &m->tip_state, &m->tip, &m->id, &m->jac};
    return vgt_work_alloc(wk, calls, 6);
}

/* Tool force of one sample: cutting force opposing the tip velocity V plus the disturbance. */
static void tool_force(const vgt_settings *s, const double *V, const double *dist, double *f)
{
    double speed = sqrt(V[0] * V[0] + V[1] * V[1] + V[2] * V[2]);
    for (int i = 0; i < 3; ++i) {
        f[i] = dist[i];
        if (s->cutting && speed > s->cutting_speed) f[i] -= s->cutting_force * V[i] / speed;
    }
}

/* Joint acceleration of the plant at (q, qd) under effort F, as its actuators deliver it at this
 * state (settings.saturation: the force-speed line at this velocity); the cutting force is
 * evaluated at this state (so RK4 stages see both change), the disturbance is held over the sample. */
static int acceleration(const vgt_model *m, const vgt_settings *s, const vgt_run *r, vgt_work *wk,
                        const double *q, const double *qd, const double *F, const double *dist,
                        double *qdd, double *f_used)
{
    double tip[3], V[3], f[3];
    const double *in_ts[3] = {q, qd, r->p_plant};
    double *out_ts[2] = {tip, V};
    if (vgt_work_call(&m->tip_state, wk, 3, in_ts, 2, out_ts)) return VGT_FUNCTION_FAILED;
    tool_force(s, V, dist, f);
    if (f_used) memcpy(f_used, f, sizeof f);
    double applied[s->n_joints];
    if (s->saturation) { /* what the actuators deliver at this state: the force-speed line acts */
        memcpy(applied, F, sizeof applied); /* continuously, at every stage's velocity          */
        vgt_saturate(s->n_joints, r->force_limit, r->speed_limit, r->force_speed, qd, applied);
        F = applied;
    }
    const double *in_fd[5] = {q, qd, F, f, r->p_plant};
    double *out_fd[1] = {qdd};
    if (vgt_work_call(&m->fd, wk, 5, in_fd, 1, out_fd)) return VGT_FUNCTION_FAILED;
    return VGT_DONE;
}

/* Integrate the plant over one control period with the effort F and the disturbance held, from
 * sub-step *substep (state q, qd, advanced in place) to s->substeps, one work unit per sub-step;
 * stops early, with 0 < *substep < s->substeps, once *used reaches budget (budget <= 0: no
 * limit); a period's first sub-step is always made, so a pause never falls before it. */
static int integrate(const vgt_model *m, const vgt_settings *s, const vgt_run *r, vgt_work *wk,
                     const double *F, const double *dist, double *q, double *qd, long *substep,
                     long *used, long budget)
{
    int steps = s->substeps > 0 ? s->substeps : 1;
    double h = s->dt / steps;
    const int nj = s->n_joints;
    double a[nj];
    for (; *substep < steps; ++*substep) {
        if (*substep > 0 && budget > 0 && *used >= budget) return VGT_PAUSED;
        int status;
        if (s->integrator == VGT_RK4) {
            double kq[4][nj], kv[4][nj], qs[nj], vs[nj];
            const double c[4] = {0.0, 0.5, 0.5, 1.0};
            for (int stage = 0; stage < 4; ++stage) {
                for (int i = 0; i < nj; ++i) {
                    qs[i] = stage ? q[i] + c[stage] * h * kq[stage - 1][i] : q[i];
                    vs[i] = stage ? qd[i] + c[stage] * h * kv[stage - 1][i] : qd[i];
                }
                status = acceleration(m, s, r, wk, qs, vs, F, dist, kv[stage], NULL);
                if (status) return status;
                memcpy(kq[stage], vs, sizeof vs);
            }
            for (int i = 0; i < nj; ++i) {
                q[i] += h / 6.0 * (kq[0][i] + 2.0 * kq[1][i] + 2.0 * kq[2][i] + kq[3][i]);
                qd[i] += h / 6.0 * (kv[0][i] + 2.0 * kv[1][i] + 2.0 * kv[2][i] + kv[3][i]);
            }
        } else {
            status = acceleration(m, s, r, wk, q, qd, F, dist, a, NULL);
            if (status) return status;
            for (int i = 0; i < nj; ++i) {
                if (s->integrator == VGT_SEMI_IMPLICIT_EULER) {
                    qd[i] += h * a[i];
                    q[i] += h * qd[i];
                } else {
                    q[i] += h * qd[i];
                    qd[i] += h * a[i];
                }
            }
        }
        ++*used;
    }
    return VGT_DONE;
}

static int check_state(const vgt_settings *s, const vgt_run *r, const double *q, const double *qd)
{
    const int nj = s->n_joints;
    for (int i = 0; i < nj; ++i)
        if (!isfinite(q[i]) || !isfinite(qd[i])) return VGT_NOT_FINITE;
    for (int row = 0; row < s->n_margins; ++row) {
        double margin = r->h[row];
#ifdef VGT_MARGIN_ROW
        margin = VGT_MARGIN_ROW(r->G, nj, row, margin, q);
#else
        for (int i = 0; i < nj; ++i) margin += r->G[nj * row + i] * q[i];
#endif
        if (!(margin > 0.0)) return VGT_NOT_ASSEMBLABLE;
    }
    for (int i = 0; i < nj; ++i)
        if (q[i] < r->q_min[i] - s->limit_tolerance || q[i] > r->q_max[i] + s->limit_tolerance)
            return VGT_OUTSIDE_LIMITS;
    return VGT_DONE;
}

/* What the controller sees at sample k: encoder-quantised joints, and velocities from their
 * differences (plus noise) through a first-order filter; the true state without sensing. */
static void measure(const vgt_settings *s, const vgt_run *r, long k)
{
    const int nj = s->n_joints;
    const double *q = r->q + nj * k, *qd = r->qd + nj * k;
    double *qm = r->q_meas + nj * k, *vm = r->qd_meas + nj * k;
    if (!s->sensing) {
        memcpy(qm, q, sizeof(double) * (size_t)nj);
        memcpy(vm, qd, sizeof(double) * (size_t)nj);
        return;
    }
    for (int i = 0; i < nj; ++i) qm[i] = vgt_quantise(q[i], r->resolution[i]);
    if (k == 0) { /* the run starts from a known state */
        memcpy(vm, qd, sizeof(double) * (size_t)nj);
        return;
    }
    if (s->estimator == VGT_ESTIMATOR_KALMAN) return; /* the velocity is the estimator's */
    const double *qm0 = qm - nj, *vm0 = vm - nj, *noise = r->velocity_noise + nj * k;
    vgt_filtered_velocity(nj, s->velocity_filter, s->dt, qm, qm0, vm0, noise, vm);
}

/* The Kalman estimator at sample k (VGT_ESTIMATOR_KALMAN, with sensing; after measure): each joint's
 * position, velocity and acceleration disturbance from the encoder reading q_meas_k, predicted over
 * the last period by the controller model's forward dynamics at the estimate of sample k-1 under
 * the effort applied, F_{k-1} (no tool force: that is in the disturbance; with tool_feedforward the
 * expected tool force f_exp_{k-1}, so the disturbance is the rest), then corrected with the
 * steady-state gains. The controller sees the encoder reading and the estimated velocity. The run
 * starts from a known state (the encoder reading, the true velocity, no disturbance). */
static int estimate(const vgt_model *m, const vgt_settings *s, const vgt_run *r, vgt_work *wk, long k)
{
    const int nj = s->n_joints;
    double *x = r->x_hat + 4 * nj * k;
    double *q = x, *v = x + nj, *d = x + 2 * nj, *a = x + 3 * nj;
    const double *z = r->q_meas + nj * k;
    if (k == 0) {
        memcpy(q, z, sizeof(double) * (size_t)nj);
        memcpy(v, r->qd, sizeof(double) * (size_t)nj);
        for (int i = 0; i < nj; ++i) d[i] = a[i] = 0.0;
    } else {
        const double *x0 = x - 4 * nj, zero[3] = {0.0, 0.0, 0.0};
        const double *f = s->tool_feedforward ? r->tool_force_expected + 3 * (k - 1) : zero;
        const double *in_fd[5] = {x0, x0 + nj, r->F + nj * (k - 1), f, r->p_ctrl};
        double *out_fd[1] = {a};
        if (vgt_work_call(&m->fd, wk, 5, in_fd, 1, out_fd)) return VGT_FUNCTION_FAILED;
        vgt_kalman_step(nj, s->dt, s->kalman_gain, x0, x0 + nj, x0 + 2 * nj, a, z, q, v, d);
    }
    memcpy(r->qd_meas + nj * k, v, sizeof(double) * (size_t)nj);
    return VGT_DONE;
}

/* The velocity of sample j >= 1 differenced from the encoder readings, (q_meas_j - q_meas_{j-1})
 * / dt plus that sample's noise, before the controller's filter; the known start at j = 0. */
static void differenced(const vgt_settings *s, const vgt_run *r, long j, double *v)
{
    const int nj = s->n_joints;
    if (j == 0) {
        memcpy(v, r->qd, sizeof(double) * (size_t)nj);
        return;
    }
    const double *qm = r->q_meas + nj * j, *qm0 = qm - nj, *noise = r->velocity_noise + nj * j;
    vgt_differenced_velocity(nj, s->dt, qm, qm0, noise, v);
}

/* Estimated external joint efforts at sample k (enum vgt_observer), from what the controller saw
 * and applied. The momentum observer is the generalised-momentum residual in discrete form, the
 * mass matrix held over the window of the velocity change: the raw estimate is the controller
 * model's inverse dynamics M^ (v_b - v_a) / dt + C^ minus the effort applied meanwhile (no
 * acceleration sensor), filtered by the exact discretisation of d tau/dt = K_O (tau_ext - tau),
 * so its step response is 1 - exp(-K_O t) at the samples. With measured velocities the window is
 * the last period: (q_{k-1}, v_{k-1}) -> v_k under F_{k-1}. With velocities differenced from
 * encoders, v_j is the mean velocity over period j-1, so the change v_k - v_{k-1} spans the two
 * last periods: M^ and C^ at q_{k-2} and v_{k-1}, the mean of F_{k-2} and F_{k-1}, unfiltered
 * differences (the estimate starts at k = 2). With tool_feedforward the inverse dynamics take the
 * expected tool force of the window (f_exp_{k-1}; with differences the mean of f_exp_{k-2} and
 * f_exp_{k-1}) as known, so the observer estimates only the rest of the external efforts. The force
 * sensor feeds the tool force of the previous period forward through J_P^T. */
static int observe(const vgt_model *m, const vgt_settings *s, const vgt_run *r, vgt_work *wk, long k)
{
    const int nj = s->n_joints;
    double *tau = r->tau_hat + nj * k;
    if (s->observer == VGT_OBSERVER_NONE || k == 0 || (s->observer == VGT_OBSERVER_MOMENTUM && s->sensing && k < 2)) {
        for (int i = 0; i < nj; ++i) tau[i] = 0.0;
        return VGT_DONE;
    }
    if (s->observer == VGT_OBSERVER_FORCE) {
        double J[3 * nj], Jw[3 * nj];
        const double *in_j[2] = {r->q_meas + nj * k, r->p_ctrl};
        double *out_j[2] = {J, Jw};
        if (vgt_work_call(&m->jac, wk, 2, in_j, 2, out_j)) return VGT_FUNCTION_FAILED;
        const double *f = r->f_ext + 3 * (k - 1);
        vgt_force_feedforward(nj, J, f, tau);
        return VGT_DONE;
    }
    double acc[nj], raw[nj], applied[nj], va[nj], vb[nj], zero[3] = {0.0, 0.0, 0.0}, f[3] = {0.0, 0.0, 0.0};
    const double *qa, *F1 = r->F + nj * (k - 1);
    const double *f1 = s->tool_feedforward ? r->tool_force_expected + 3 * (k - 1) : zero;
    if (s->sensing && s->estimator == VGT_ESTIMATOR_KALMAN) {
        /* the Kalman estimate of the last period: the model's acceleration plus the disturbance,
         * at the estimate of sample k-1, under F_{k-1} (and the expected tool force f_exp_{k-1}
         * with tool_feedforward); raw = M^ d^ (to round-off) */
        const double *x0 = r->x_hat + 4 * nj * (k - 1), *x = x0 + 4 * nj;
        for (int i = 0; i < nj; ++i) acc[i] = x[3 * nj + i] + x[2 * nj + i];
        const double *in_k[5] = {x0, x0 + nj, acc, f1, r->p_ctrl};
        double *out_k[1] = {raw};
        if (vgt_work_call(&m->id, wk, 5, in_k, 1, out_k)) return VGT_FUNCTION_FAILED;
        const double keep = exp(-s->observer_gain * s->dt), *tau0 = tau - nj;
        vgt_observer_filter(nj, keep, tau0, raw, F1, tau);
        return VGT_DONE;
    }
    if (s->sensing) {
        const double *F2 = F1 - nj;
        differenced(s, r, k - 1, va);
        differenced(s, r, k, vb);
        qa = r->q_meas + nj * (k - 2);
        vgt_mean_effort(nj, F2, F1, applied);
        if (s->tool_feedforward) vgt_mean_effort(3, f1 - 3, f1, f);
    } else {
        memcpy(va, r->qd_meas + nj * (k - 1), sizeof(double) * (size_t)nj);
        memcpy(vb, r->qd_meas + nj * k, sizeof(double) * (size_t)nj);
        qa = r->q_meas + nj * (k - 1);
        memcpy(applied, F1, sizeof(double) * (size_t)nj);
        memcpy(f, f1, sizeof f);
    }
    vgt_window_acceleration(nj, s->dt, va, vb, acc);
    const double *in_id[5] = {qa, va, acc, f, r->p_ctrl};
    double *out_id[1] = {raw};
    if (vgt_work_call(&m->id, wk, 5, in_id, 1, out_id)) return VGT_FUNCTION_FAILED;
    const double keep = exp(-s->observer_gain * s->dt), *tau0 = tau - nj;
    vgt_observer_filter(nj, keep, tau0, raw, applied, tau);
    return VGT_DONE;
}

/* The expected tool force of sample k fed forward (tool_feedforward): F -= J_P(q_meas_k)^T f_exp_k,
 * the controller model's tip Jacobian at what the controller sees. */
static int feed_forward(const vgt_model *m, const vgt_settings *s, const vgt_run *r, vgt_work *wk, long k, double *F)
{
    const int nj = s->n_joints;
    double J[3 * nj], Jw[3 * nj], tau[nj];
    const double *in_j[2] = {r->q_meas + nj * k, r->p_ctrl};
    double *out_j[2] = {J, Jw};
    if (vgt_work_call(&m->jac, wk, 2, in_j, 2, out_j)) return VGT_FUNCTION_FAILED;
    vgt_force_feedforward(nj, J, r->tool_force_expected + 3 * k, tau);
    vgt_subtract_estimate(nj, tau, F);
    return VGT_DONE;
}

/* Run samples k0 .. k1-1 with the gains Kp, Kv (row-major nj x nj). Sample k: measure the tip and
 * its error and what the controller sees, stop if the error exceeds the threshold (*stop = k,
 * before any control), estimate the external efforts, compute the effort (computed force control
 * minus the estimate and, with tool_feedforward, minus the expected tool force through J_P^T) and
 * the tool force, clip the effort to the actuators' peak forces (settings.saturation; the plant
 * applies their force-speed lines at each stage), and integrate to sample k+1 (unless k is the last). On any other stop, *stop is the sample whose state failed. */
int vgt_simulate(const vgt_model *m, const vgt_settings *s, const vgt_run *r,
                 const double *Kp, const double *Kv, long k0, long k1, long *stop)
{
    return vgt_simulate_slice(m, s, r, Kp, Kv, k0, k1, stop, NULL);
}

/* vgt_simulate in slices (see vgtarm.h): the same steps; a pause saves the sub-step count and the
 * plant state of the sample being integrated in the slice, and the next call resumes there
 * without controlling that sample again (its effort and tool force are already in the run). */
int vgt_simulate_slice(const vgt_model *m, const vgt_settings *s, const vgt_run *r,
                       const double *Kp, const double *Kv, long k0, long k1, long *stop, vgt_slice *slice)
{
    const int nj = s->n_joints;
    const long budget = slice ? slice->budget : 0;
    long used = 0, substep = slice ? slice->substep : 0;
    double q_own[nj], qd_own[nj];
    double *qi = slice ? slice->q : q_own, *vi = slice ? slice->qd : qd_own; /* state being integrated */
    vgt_work wk;
    int status = VGT_DONE;
    *stop = k1;
    if (!work_alloc(&wk, m)) {
        vgt_work_free(&wk);
        return VGT_NO_MEMORY;
    }
    for (long k = k0; k < k1; ++k) {
        const double *q = r->q + nj * k, *qd = r->qd + nj * k;
        double *F = r->F + nj * k;
        const double *dist = r->disturbance + 3 * k;
        if (substep == 0) { /* control sample k */
            if (budget > 0 && used >= budget) { status = VGT_PAUSED; *stop = k; break; }
            double V[3];
            double *tip = r->tip + 3 * k;
            const double *in_ts[3] = {q, qd, r->p_plant};
            double *out_ts[2] = {tip, V};
            if (vgt_work_call(&m->tip_state, &wk, 3, in_ts, 2, out_ts)) { status = VGT_FUNCTION_FAILED; *stop = k; break; }
            const double *td = r->tip_d + 3 * k;
            double e0 = td[0] - tip[0], e1 = td[1] - tip[1], e2 = td[2] - tip[2];
            r->error[k] = sqrt(e0 * e0 + e1 * e1 + e2 * e2);
            measure(s, r, k);
            if (s->sensing && s->estimator == VGT_ESTIMATOR_KALMAN && estimate(m, s, r, &wk, k)) {
                status = VGT_FUNCTION_FAILED; *stop = k; break;
            }
            if (s->threshold > 0.0) {
                double seen = r->error[k];
                if (s->threshold_measured) { /* what the controller sees: its model's tip at q_meas */
                    double tip_m[3];
                    const double *in_m[2] = {r->q_meas + nj * k, r->p_ctrl};
                    double *out_m[1] = {tip_m};
                    if (vgt_work_call(&m->tip, &wk, 2, in_m, 1, out_m)) { status = VGT_FUNCTION_FAILED; *stop = k; break; }
                    double m0 = td[0] - tip_m[0], m1 = td[1] - tip_m[1], m2 = td[2] - tip_m[2];
                    seen = sqrt(m0 * m0 + m1 * m1 + m2 * m2);
                }
                if (r->seen) r->seen[k] = seen;
                if (seen > s->threshold) { status = VGT_ABOVE_THRESHOLD; *stop = k; break; }
            }
            if (observe(m, s, r, &wk, k)) { status = VGT_FUNCTION_FAILED; *stop = k; break; }
            const double *qm = r->q_meas + nj * k, *vm = r->qd_meas + nj * k, *tau = r->tau_hat + nj * k;
            const double *in_c[8] = {qm, vm, r->q_d + nj * k, r->qd_d + nj * k, r->qdd_d + nj * k, Kp, Kv, r->p_ctrl};
            double *out_c[1] = {F};
            if (vgt_work_call(&m->cfc, &wk, 8, in_c, 1, out_c)) { status = VGT_FUNCTION_FAILED; *stop = k; break; }
            vgt_subtract_estimate(nj, tau, F);
            if (s->tool_feedforward && feed_forward(m, s, r, &wk, k, F)) {
                status = VGT_FUNCTION_FAILED; *stop = k; break;
            }
            if (s->saturation) vgt_clip(nj, r->force_limit, F); /* the controller's own clip */
            tool_force(s, V, dist, r->f_ext + 3 * k);
            ++used;
            if (k + 1 >= r->n) continue;
            memcpy(qi, q, sizeof(double) * (size_t)nj);
            memcpy(vi, qd, sizeof(double) * (size_t)nj);
        }
        status = integrate(m, s, r, &wk, F, dist, qi, vi, &substep, &used, budget);
        if (status == VGT_PAUSED) { *stop = k; break; }
        substep = 0;
        double *q1 = r->q + nj * (k + 1), *qd1 = r->qd + nj * (k + 1);
        if (status == VGT_DONE) {
            memcpy(q1, qi, sizeof(double) * (size_t)nj);
            memcpy(qd1, vi, sizeof(double) * (size_t)nj);
            status = check_state(s, r, q1, qd1);
        }
        if (status != VGT_DONE) { *stop = k + 1; break; }
    }
    if (slice) {
        slice->used = used;
        slice->substep = substep;
    }
    vgt_work_free(&wk);
    return status;
}

/* The actuators of a prediction (vgt_ga_fitness_limited): peak force, no-load speed, line flag. */
typedef struct {
    const double *force, *speed, *line;
} limits;

/* With actuators, the acceleration of the controller's model under computed force control whose
 * effort is clipped as the controller and the plant's motors clip it: F = CFC(q, qd, row j),
 * vgt_saturate(F) at qd (within the peak forces: vgt_clip changes nothing after it), a = FD(q, qd,
 * F). Nonzero when a function fails. */
static int limited_acceleration(const vgt_model *m, vgt_work *wk, const double *p_ctrl, const limits *act, int nj,
                                const double *q, const double *qd, const double *q_d, const double *qd_d,
                                const double *qdd_d, const double *kp, const double *kv, double *a)
{
    double F[nj];
    const double zero[3] = {0.0, 0.0, 0.0};
    const double *in_c[8] = {q, qd, q_d, qd_d, qdd_d, kp, kv, p_ctrl};
    double *out_c[1] = {F};
    if (vgt_work_call(&m->cfc, wk, 8, in_c, 1, out_c)) return 1;
    vgt_saturate(nj, act->force, act->speed, act->line, qd, F);
    const double *in_f[5] = {q, qd, F, zero, p_ctrl};
    double *out_f[1] = {a};
    return vgt_work_call(&m->fd, wk, 5, in_f, 1, out_f) != 0;
}

/* Predicted tip-error norm of one candidate (see vgt_ga_fitness_limited). */
static double predict_one(const vgt_model *m, const vgt_settings *s, vgt_work *wk, const double *p_ctrl, long horizon,
                          const double *q0, const double *qd0, const double *q_d, const double *qd_d,
                          const double *qdd_d, const double *tip_d, const limits *act, const double *kp,
                          const double *kv)
{
    const int nj = s->n_joints;
    const double dt = s->dt;
    double q[nj], qd[nj], a[nj], tip[3], sum = 0.0;
    memcpy(q, q0, sizeof q);
    memcpy(qd, qd0, sizeof qd);
    for (long j = 0; j < horizon; ++j) {
        double e[nj], ed[nj];
        for (int i = 0; i < nj; ++i) {
            e[i] = q_d[nj * j + i] - q[i];
            ed[i] = qd_d[nj * j + i] - qd[i];
        }
        if (act) {
            const long at = (long)nj * j;
            if (limited_acceleration(m, wk, p_ctrl, act, nj, q, qd, q_d + at, qd_d + at, qdd_d + at, kp, kv, a))
                return INFINITY;
        } else {
            for (int i = 0; i < nj; ++i) {
                double acc = qdd_d[nj * j + i];
                for (int l = 0; l < nj; ++l) acc += kp[nj * i + l] * e[l] + kv[nj * i + l] * ed[l];
                a[i] = acc;
            }
        }
        for (int i = 0; i < nj; ++i) {
            q[i] += dt * qd[i];
            qd[i] += dt * a[i];
        }
        const double *in_t[2] = {q, p_ctrl};
        double *out_t[1] = {tip};
        if (vgt_work_call(&m->tip, wk, 2, in_t, 1, out_t)) return INFINITY;
        const double *td = tip_d + 3 * (j + 1);
        double d0 = td[0] - tip[0], d1 = td[1] - tip[1], d2 = td[2] - tip[2];
        sum += d0 * d0 + d1 * d1 + d2 * d2;
        if (!isfinite(sum)) return INFINITY;
    }
    return sqrt(sum);
}

/* Predicted tip error of n_cand gain candidates over `horizon` control periods from the state
 * (q0, qd0) at the reference rows 0..horizon. Under the controller's own model, computed force
 * control cancels M^ and C^ exactly, so the predicted joints obey qdd = qdd_d + Kp e + Kv e_dot;
 * they are advanced by explicit Euler (the paper's integrator) and mapped to the tip with the
 * forward kinematics. fitness = sqrt(sum_j |tip_d[j] - P(q_j)|^2), j = 1..horizon; a candidate
 * whose prediction leaves the assemblable set gets +inf. */
int vgt_ga_fitness(const vgt_model *m, const vgt_settings *s, const double *p_ctrl, long horizon,
                   const double *q0, const double *qd0, const double *q_d, const double *qd_d,
                   const double *qdd_d, const double *tip_d, long n_cand, const double *Kp,
                   const double *Kv, double *fitness)
{
    return vgt_ga_fitness_limited(m, s, p_ctrl, horizon, q0, qd0, q_d, qd_d, qdd_d, tip_d, NULL, NULL, NULL, n_cand,
                                  Kp, Kv, fitness);
}

/* vgt_ga_fitness with actuators (force_limit not NULL): the controller's effort is clipped to the
 * peak forces and the force-speed lines at the predicted velocity, and the joints follow the
 * model's forward dynamics under it (limited_acceleration) instead of qdd_d + Kp e + Kv e_dot. */
int vgt_ga_fitness_limited(const vgt_model *m, const vgt_settings *s, const double *p_ctrl, long horizon,
                           const double *q0, const double *qd0, const double *q_d, const double *qd_d,
                           const double *qdd_d, const double *tip_d, const double *force_limit,
                           const double *speed_limit, const double *force_speed, long n_cand, const double *Kp,
                           const double *Kv, double *fitness)
{
    const limits act = {force_limit, speed_limit, force_speed};
    /* Serial on purpose: a candidate costs a few microseconds, and threads that spin-wait for
     * the next generation lose far more than they gain when the other core is busy. */
    const int nj = s->n_joints;
    vgt_work wk;
    int ok = work_alloc(&wk, m);
    for (long c = 0; c < n_cand; ++c)
        fitness[c] = ok ? predict_one(m, s, &wk, p_ctrl, horizon, q0, qd0, q_d, qd_d, qdd_d, tip_d,
                                      force_limit ? &act : NULL, Kp + (long)nj * nj * c, Kv + (long)nj * nj * c)
                        : INFINITY;
    vgt_work_free(&wk);
    return ok ? VGT_DONE : VGT_NO_MEMORY;
}
