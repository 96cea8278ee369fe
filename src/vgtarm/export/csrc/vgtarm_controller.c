/* vgtarm's controller for a real-time target (see vgtarm_controller.h).
 *
 * The per-period arithmetic is the simulation's (vgtarm/model/csrc/closed_loop.c: measure, observe
 * and the control of a sample), through the same shared functions (vgt_control.h) and the same
 * CasADi-generated model functions (vgtc_model.c), in the same order, so that a run closed through
 * this file gives the simulation's efforts bit for bit. Build with -ffp-contract=off (the Makefile
 * and CMakeLists.txt do): a fused multiply-add rounds differently.
 */
#include <math.h>
#include <string.h>

#include "vgt_control.h"
#include "vgtarm_controller.h"
#include "vgtc_model.h"

typedef int (*vgtc_fn)(const double **arg, double **res, long long *iw, double *w, int mem);

/* Call a generated function with the context's work arrays. */
static int call(vgtc_context *c, vgtc_fn f, int n_in, const double **in, int n_out, double **out)
{
    for (int i = 0; i < n_in; ++i) c->arg[i] = in[i];
    for (int j = 0; j < n_out; ++j) c->res[j] = out[j];
    return f(c->arg, c->res, c->iw, c->w, 0);
}

static int finite_all(int n, const double *x)
{
    for (int i = 0; i < n; ++i)
        if (!isfinite(x[i])) return 0;
    return 1;
}

int vgtc_check_params(const vgtc_params *p, const char **field)
{
    const char *bad = NULL;
    const int n = VGTC_NJ;
    if (!p) bad = "params";
    else if (!(isfinite(p->dt) && p->dt > 0.0)) bad = "dt";
    else if (!finite_all(n * n, p->Kp)) bad = "Kp";
    else if (!finite_all(n * n, p->Kv)) bad = "Kv";
    else if (!finite_all(VGTC_NP, p->model)) bad = "model";
    else if (p->observer != VGTC_OBSERVER_NONE && p->observer != VGTC_OBSERVER_MOMENTUM
             && p->observer != VGTC_OBSERVER_FORCE) bad = "observer";
    else if (p->observer == VGTC_OBSERVER_MOMENTUM
             && !(isfinite(p->observer_gain) && p->observer_gain > 0.0 && p->observer_gain * p->dt <= 1.0))
        bad = "observer_gain";
    else if (p->velocity != VGTC_VELOCITY_MEASURED && p->velocity != VGTC_VELOCITY_DIFFERENCED) bad = "velocity";
    else if (!(p->velocity_filter >= 0.0 && p->velocity_filter < 1.0)) bad = "velocity_filter";
    else if (p->estimator != VGTC_ESTIMATOR_DIFFERENCE
             && !(VGTC_KALMAN && p->estimator == VGTC_ESTIMATOR_KALMAN && p->velocity == VGTC_VELOCITY_DIFFERENCED))
        bad = "estimator"; /* the Kalman filter needs the readings, and the forward dynamics (VGTC_KALMAN) */
    else if (p->estimator == VGTC_ESTIMATOR_KALMAN && !finite_all(3, p->kalman_gain)) bad = "kalman_gain";
    else if (!(isfinite(p->limit_tolerance) && p->limit_tolerance >= 0.0)) bad = "limit_tolerance";
    else {
        for (int i = 0; i < n && !bad; ++i) {
            if (!(isfinite(p->resolution[i]) && p->resolution[i] >= 0.0)) bad = "resolution";
            else if (!(isfinite(p->q_min[i]) && isfinite(p->q_max[i]) && p->q_min[i] <= p->q_max[i])) bad = "q_min/q_max";
            else if (!(p->effort_max[i] > 0.0)) bad = "effort_max";
        }
    }
    if (field) *field = bad;
    return bad ? VGTC_BAD_PARAMETER : VGTC_OK;
}

int vgtc_init(vgtc_context *ctx, const vgtc_params *params)
{
    if (!ctx || !params) return VGTC_BAD_ARGUMENT;
    if (vgtc_check_params(params, NULL) != VGTC_OK) return VGTC_BAD_PARAMETER;
    memset(ctx, 0, sizeof *ctx);
    ctx->p = *params;
    ctx->keep = exp(-params->observer_gain * params->dt);
    ctx->ready = 1;
    return VGTC_OK;
}

/* The estimate of the external efforts at period k into tau (observe in closed_loop.c): qm, vd are
 * this period's reading and differenced velocity, vm the controller's velocity, x the Kalman
 * estimate of this period (VGTC_ESTIMATOR_KALMAN). */
static int observe(vgtc_context *c, long k, const double *qm, const double *vm, const double *vd,
                   const double *x, const double *f_meas, double *tau)
{
    const int n = VGTC_NJ;
    const vgtc_params *p = &c->p;
    const int sensing = p->velocity == VGTC_VELOCITY_DIFFERENCED;
    if (p->observer == VGTC_OBSERVER_NONE || k == 0 || (p->observer == VGTC_OBSERVER_MOMENTUM && sensing && k < 2)
        || (p->observer == VGTC_OBSERVER_FORCE && !f_meas)) {
        for (int i = 0; i < n; ++i) tau[i] = 0.0;
        return VGTC_OK;
    }
    if (p->observer == VGTC_OBSERVER_FORCE) {
        double J[3 * VGTC_NJ], Jw[3 * VGTC_NJ];
        const double *in_j[2] = {qm, p->model};
        double *out_j[2] = {J, Jw};
        if (call(c, vgt_jac, 2, in_j, 2, out_j)) return VGTC_FUNCTION_FAILED;
        vgt_force_feedforward(n, J, f_meas, tau);
        return VGTC_OK;
    }
    double acc[VGTC_NJ], raw[VGTC_NJ], applied[VGTC_NJ], f[3];
    const double *va, *vb, *qa;
    if (sensing && p->estimator == VGTC_ESTIMATOR_KALMAN) {
        /* the Kalman estimate of the last period: the model's acceleration plus the disturbance, at
         * the estimate of period k-1, under F_{k-1} (and the expected tool force of period k-1);
         * raw = M^ d^ (to round-off) */
        for (int i = 0; i < n; ++i) acc[i] = x[3 * n + i] + x[2 * n + i];
        const double *in_k[5] = {c->x1, c->x1 + n, acc, c->fe1, p->model};
        double *out_k[1] = {raw};
        if (call(c, vgt_id, 5, in_k, 1, out_k)) return VGTC_FUNCTION_FAILED;
        vgt_observer_filter(n, c->keep, c->tau, raw, c->F1, tau);
        return VGTC_OK;
    }
    if (sensing) {
        va = c->vd1;
        vb = vd;
        qa = c->qm2;
        vgt_mean_effort(n, c->F2, c->F1, applied);
        vgt_mean_effort(3, c->fe2, c->fe1, f); /* the expected tool force over the same window */
    } else {
        va = c->vm1;
        vb = vm;
        qa = c->qm1;
        memcpy(applied, c->F1, sizeof applied);
        memcpy(f, c->fe1, sizeof f);
    }
    vgt_window_acceleration(n, p->dt, va, vb, acc);
    const double *in_id[5] = {qa, va, acc, f, p->model};
    double *out_id[1] = {raw};
    if (call(c, vgt_id, 5, in_id, 1, out_id)) return VGTC_FUNCTION_FAILED;
    vgt_observer_filter(n, c->keep, c->tau, raw, applied, tau);
    return VGTC_OK;
}

static int fail(double *efforts, int status)
{
    if (efforts)
        for (int i = 0; i < VGTC_NJ; ++i) efforts[i] = 0.0;
    return status;
}

/* The Kalman estimate x (q^, v^, d^ and the model's acceleration a, VGTC_NJ each) of this period
 * (estimate in closed_loop.c): from the last period's, predicted by the controller model's forward
 * dynamics under the effort applied, F_{k-1} (and the expected tool force of period k-1, zero
 * without the feedforward: the rest of the tool force is in the disturbance), then
 * corrected by the reading qm with the steady-state gains. The first period starts from a known
 * state: the reading, the velocity `start`, no disturbance. Uses the context's work arrays only. */
static int kalman(vgtc_context *c, const double *qm, const double *start, double *x)
{
    const int n = VGTC_NJ;
    double *q = x, *v = x + n, *d = x + 2 * n, *a = x + 3 * n;
    if (c->k == 0) {
        memcpy(q, qm, sizeof(double) * VGTC_NJ);
        memcpy(v, start, sizeof(double) * VGTC_NJ);
        for (int i = 0; i < n; ++i) d[i] = a[i] = 0.0;
        return VGTC_OK;
    }
#if VGTC_KALMAN
    const double *x0 = c->x1;
    const double *in_fd[5] = {x0, x0 + n, c->F1, c->fe1, c->p.model};
    double *out_fd[1] = {a};
    if (call(c, vgt_fd, 5, in_fd, 1, out_fd)) return VGTC_FUNCTION_FAILED;
    vgt_kalman_step(n, c->p.dt, c->p.kalman_gain, x0, x0 + n, x0 + 2 * n, a, qm, q, v, d);
    return VGTC_OK;
#else /* exported without the forward dynamics: vgtc_check_params refuses the estimator */
    return VGTC_FUNCTION_FAILED;
#endif
}

/* The readings the controller sees at its next period (measure and estimate in closed_loop.c):
 * joints rounded to the encoder steps (qm), its velocity (vm), the unfiltered differenced one (vd)
 * and, with the Kalman filter, its estimate x (4 VGTC_NJ). Uses the context's work arrays only. */
static int measure(vgtc_context *ctx, const double *q_meas, const double *qd_meas, double *qm, double *vm,
                   double *vd, double *x)
{
    const int n = VGTC_NJ;
    const vgtc_params *p = &ctx->p;
    const double *start = qd_meas ? qd_meas : ctx->zero;
    for (int i = 0; i < n; ++i) qm[i] = vgt_quantise(q_meas[i], p->resolution[i]);
    if (p->velocity != VGTC_VELOCITY_DIFFERENCED) {
        memcpy(vm, qd_meas, sizeof(double) * VGTC_NJ);
        memcpy(vd, qd_meas, sizeof(double) * VGTC_NJ);
    } else if (p->estimator == VGTC_ESTIMATOR_KALMAN) {
        if (kalman(ctx, qm, start, x)) return VGTC_FUNCTION_FAILED;
        memcpy(vm, x + n, sizeof(double) * VGTC_NJ);
        if (ctx->k == 0) memcpy(vd, start, sizeof(double) * VGTC_NJ);
        else vgt_differenced_velocity(n, p->dt, qm, ctx->qm1, ctx->zero, vd);
    } else if (ctx->k == 0) {
        memcpy(vm, start, sizeof(double) * VGTC_NJ);
        memcpy(vd, start, sizeof(double) * VGTC_NJ);
    } else {
        vgt_filtered_velocity(n, p->velocity_filter, p->dt, qm, ctx->qm1, ctx->vm1, ctx->zero, vm);
        vgt_differenced_velocity(n, p->dt, qm, ctx->qm1, ctx->zero, vd);
    }
    return VGTC_OK;
}

int vgtc_readings(vgtc_context *ctx, const double *q_meas, const double *qd_meas, double *qm, double *vm)
{
    double vd[VGTC_NJ], x[4 * VGTC_NJ];
    if (!ctx || !ctx->ready || !q_meas || !qm || !vm) return VGTC_BAD_ARGUMENT;
    if (ctx->p.velocity != VGTC_VELOCITY_DIFFERENCED && !qd_meas) return VGTC_BAD_ARGUMENT;
    return measure(ctx, q_meas, qd_meas, qm, vm, vd, x);
}

int vgtc_step(vgtc_context *ctx, double t, const double *q_meas, const double *qd_meas, const double *ref_row,
              const double *f_meas, double *efforts)
{
    if (!ctx) return fail(efforts, VGTC_BAD_ARGUMENT);
    return vgtc_step_gains(ctx, t, q_meas, qd_meas, ref_row, f_meas, ctx->p.Kp, ctx->p.Kv, efforts);
}

int vgtc_step_gains(vgtc_context *ctx, double t, const double *q_meas, const double *qd_meas, const double *ref_row,
                    const double *f_meas, const double *Kp, const double *Kv, double *efforts)
{
    if (!Kp || !Kv) return fail(efforts, VGTC_BAD_ARGUMENT);
    return vgtc_step_feedforward(ctx, t, q_meas, qd_meas, ref_row, f_meas, NULL, Kp, Kv, efforts);
}

int vgtc_step_feedforward(vgtc_context *ctx, double t, const double *q_meas, const double *qd_meas,
                          const double *ref_row, const double *f_meas, const double *f_exp, const double *Kp,
                          const double *Kv, double *efforts)
{
    const int n = VGTC_NJ;
    if (!ctx || !ctx->ready || !q_meas || !ref_row || !efforts) return fail(efforts, VGTC_BAD_ARGUMENT);
    const vgtc_params *p = &ctx->p;
    if (!Kp) Kp = p->Kp;
    if (!Kv) Kv = p->Kv;
    const int sensing = p->velocity == VGTC_VELOCITY_DIFFERENCED;
    const long k = ctx->k;
    const double *start = qd_meas ? qd_meas : ctx->zero; /* the known start of differenced velocities */
    if (!sensing && !qd_meas) return fail(efforts, VGTC_BAD_ARGUMENT);
    if (!isfinite(t) || !finite_all(n, q_meas) || !finite_all(3 * n, ref_row)
        || ((!sensing || k == 0) && !finite_all(n, start))
        || (p->observer == VGTC_OBSERVER_FORCE && f_meas && !finite_all(3, f_meas))
        || (f_exp && !finite_all(3, f_exp)) || !finite_all(n * n, Kp)
        || !finite_all(n * n, Kv))
        return fail(efforts, VGTC_NOT_FINITE);
    if (k > 0 && t < ctx->t_last) return fail(efforts, VGTC_BAD_TIME);

    /* 1. what the controller sees (measure in closed_loop.c) */
    double qm[VGTC_NJ], vm[VGTC_NJ], vd[VGTC_NJ], tau[VGTC_NJ], F[VGTC_NJ], x[4 * VGTC_NJ];
    if (measure(ctx, q_meas, qd_meas, qm, vm, vd, x)) return fail(efforts, VGTC_FUNCTION_FAILED);
    for (int i = 0; i < n; ++i)
        if (qm[i] < p->q_min[i] - p->limit_tolerance || qm[i] > p->q_max[i] + p->limit_tolerance)
            return fail(efforts, VGTC_OUTSIDE_LIMITS);

    /* 2. the estimate of the external efforts */
    if (observe(ctx, k, qm, vm, vd, x, f_meas, tau)) return fail(efforts, VGTC_FUNCTION_FAILED);

    /* 3. computed force control minus the estimate */
    const double *q_d = ref_row, *qd_d = ref_row + n, *qdd_d = ref_row + 2 * n;
    const double *in_c[8] = {qm, vm, q_d, qd_d, qdd_d, Kp, Kv, p->model};
    double *out_c[1] = {F};
    if (call(ctx, vgt_cfc, 8, in_c, 1, out_c)) return fail(efforts, VGTC_FUNCTION_FAILED);
    vgt_subtract_estimate(n, tau, F);
    if (f_exp) { /* the expected tool force through J_P(q_meas)^T (feed_forward in closed_loop.c) */
        double J[3 * VGTC_NJ], Jw[3 * VGTC_NJ], fed[VGTC_NJ];
        const double *in_j[2] = {qm, p->model};
        double *out_j[2] = {J, Jw};
        if (call(ctx, vgt_jac, 2, in_j, 2, out_j)) return fail(efforts, VGTC_FUNCTION_FAILED);
        vgt_force_feedforward(n, J, f_exp, fed);
        vgt_subtract_estimate(n, fed, F);
    }

    /* the tip error the controller sees (for switching control and monitoring) */
    double tip_d[3], tip[3];
    const double *in_t[2] = {q_d, p->model};
    double *out_t[1] = {tip_d};
    if (call(ctx, vgt_tip, 2, in_t, 1, out_t)) return fail(efforts, VGTC_FUNCTION_FAILED);
    in_t[0] = qm;
    out_t[0] = tip;
    if (call(ctx, vgt_tip, 2, in_t, 1, out_t)) return fail(efforts, VGTC_FUNCTION_FAILED);
    const double e0 = tip_d[0] - tip[0], e1 = tip_d[1] - tip[1], e2 = tip_d[2] - tip[2];

    /* 4. limits */
    int status = VGTC_OK;
    for (int i = 0; i < n; ++i) {
        if (F[i] > p->effort_max[i]) { F[i] = p->effort_max[i]; status = VGTC_SATURATED; }
        else if (F[i] < -p->effort_max[i]) { F[i] = -p->effort_max[i]; status = VGTC_SATURATED; }
    }
    if (!finite_all(n, F)) return fail(efforts, VGTC_FUNCTION_FAILED);

    /* remember this period */
    memcpy(ctx->qm2, ctx->qm1, sizeof qm);
    memcpy(ctx->qm1, qm, sizeof qm);
    memcpy(ctx->vm1, vm, sizeof vm);
    memcpy(ctx->vd1, vd, sizeof vd);
    memcpy(ctx->F2, ctx->F1, sizeof F);
    memcpy(ctx->F1, F, sizeof F);
    memcpy(ctx->tau, tau, sizeof tau);
    memcpy(ctx->fe2, ctx->fe1, sizeof ctx->fe1);
    if (f_exp) memcpy(ctx->fe1, f_exp, sizeof ctx->fe1);
    else ctx->fe1[0] = ctx->fe1[1] = ctx->fe1[2] = 0.0;
    if (p->estimator == VGTC_ESTIMATOR_KALMAN) memcpy(ctx->x1, x, sizeof x);
    ctx->tip_error = sqrt(e0 * e0 + e1 * e1 + e2 * e2);
    ctx->t_last = t;
    ctx->k = k + 1;
    memcpy(efforts, F, sizeof F);
    return status;
}

const double *vgtc_effort_estimate(const vgtc_context *ctx) { return ctx->tau; }
const double *vgtc_joint_readings(const vgtc_context *ctx) { return ctx->qm1; }
const double *vgtc_joint_velocities(const vgtc_context *ctx) { return ctx->vm1; }
double vgtc_tip_error(const vgtc_context *ctx) { return ctx->tip_error; }

const char *vgtc_status_text(int status)
{
    switch (status) {
    case VGTC_OK: return "efforts computed";
    case VGTC_SATURATED: return "efforts computed, at least one clipped to its limit";
    case VGTC_BAD_ARGUMENT: return "a required pointer is NULL, or the context is not initialised";
    case VGTC_NOT_FINITE: return "an input is NaN or infinite";
    case VGTC_OUTSIDE_LIMITS: return "a joint reading lies beyond its limit";
    case VGTC_FUNCTION_FAILED: return "a model function failed";
    case VGTC_BAD_TIME: return "the time went backwards";
    case VGTC_BAD_PARAMETER: return "a parameter is out of its range";
    default: return "unknown status";
    }
}

size_t vgtc_context_size(void) { return sizeof(vgtc_context); }
size_t vgtc_params_size(void) { return sizeof(vgtc_params); }
