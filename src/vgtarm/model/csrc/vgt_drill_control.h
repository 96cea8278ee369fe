/* Force-controlled drilling's controller in C99: the encoders' velocity and the momentum observer,
 * the hybrid force/position law in the tool frame, the phases (tare, drilling, stop, retract) and
 * the layer and breakthrough detector. The arithmetic of vgtarm/drilling/control.py and loop.py
 * (Sensing, HybridController, Detector, _advance), step for step; docs/drilling_control.md gives
 * each formula. Shared by the compiled loop (drill_loop.c) and the exported controller, so the two
 * run the same code bit for bit. No heap: the caller gives the joint-space memory
 * (VGT_DRILL_STATE_DOUBLES(nj) doubles) and the work arrays of the generated functions.
 *
 * Include after vgtarm.h (the structures) and vgt_control.h (vgt_clip, vgt_cholesky), with vgt_drill_call
 * defined by the includer: the function that evaluates one generated function (its arguments and
 * results given).
 */
#ifndef VGT_DRILL_CONTROL_H
#define VGT_DRILL_CONTROL_H

#include <math.h>
#include <string.h>

#define VGT_DRILL_PI 3.14159265358979323846
#define VGT_DRILL_TASK 5 /* task rows: lateral e1, e2, angle about e1, e2, the axis        */
#define VGT_DRILL_SERIES 13
#define VGT_DRILL_STATE_DOUBLES(nj) (10 * (nj))

/* Evaluates one generated function; 0 on success (defined by the includer). */
static int vgt_drill_call(const vgt_call *c, void *work, int n_in, const double **in, int n_out, double **out);

/* The state at the start of a run with the tip `gap` before the entry, at rest at q0 (memory: the
 * VGT_DRILL_STATE_DOUBLES(nj) doubles the state uses). */
static void vgt_drill_start(vgt_drill_state *st, int nj, const double *q0, double gap, double *memory, double *events,
                            long max_events)
{
    memset(st, 0, sizeof *st);
    memset(memory, 0, sizeof(double) * (size_t)VGT_DRILL_STATE_DOUBLES(nj));
    st->q_meas = memory;
    st->efforts = memory + 3 * nj;
    st->v_filtered = memory + 5 * nj;
    st->v_raw = memory + 6 * nj;
    st->tau_hat = memory + 8 * nj;
    st->q_centre = memory + 9 * nj;
    memcpy(st->q_centre, q0, sizeof(double) * (size_t)nj);
    st->phase = VGT_DRILL_TARE;
    st->stopped_at = INFINITY;
    st->retracted_at = INFINITY;
    st->depth_ref = -gap;
    st->limited = 1;
    st->layer = -1;
    st->events = events;
    st->max_events = max_events;
}

/* ---- small dense algebra (row-major) ---------------------------------------------------------- */

/* x = A^-1 b with L the factor of A (vgt_cholesky, vgt_control.h); b and x may be the same. */
static void vgt_drill_solve(int n, const double *L, const double *b, double *x)
{
    for (int i = 0; i < n; ++i) {
        double v = b[i];
        for (int k = 0; k < i; ++k) v -= L[i * n + k] * x[k];
        x[i] = v / L[i * n + i];
    }
    for (int i = n - 1; i >= 0; --i) {
        double v = x[i];
        for (int k = i + 1; k < n; ++k) v -= L[k * n + i] * x[k];
        x[i] = v / L[i * n + i];
    }
}

static double vgt_drill_dot3(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* ---- the model at the measured state ---------------------------------------------------------- */

/* The task of control.task_state: J (5, nj) row-major, Jdot qd (5), the held errors and rates (4
 * each), the depth and feed, and the model's M (nj, nj) and C (nj). frame: row-major 3x3 whose
 * columns are e1, e2, the axis. Returns 0 on success. */
static int vgt_drill_task(const vgt_drill_model *m, void *work, int nj, const double *p, const double *q,
                          const double *qd, const double *entry, const double *frame, const double *tool_axis,
                          double *J, double *Jdot_qd, double *held_error, double *held_rate, double *depth,
                          double *feed, double *M, double *C)
{
    double JP[3 * nj], Jw[3 * nj], tip[3], R[9], bias_tip[3], bias_w[3];
    const double *in_q[2] = {q, p};
    double *out_jac[2] = {JP, Jw};
    if (vgt_drill_call(&m->jac, work, 2, in_q, 2, out_jac)) return 1;
    double *out_tip[1] = {tip};
    if (vgt_drill_call(&m->tip, work, 2, in_q, 1, out_tip)) return 1;
    double *out_fk[m->n_fk_outputs];
    for (int i = 0; i < m->n_fk_outputs; ++i) out_fk[i] = NULL;
    out_fk[m->n_fk_outputs - 1] = R;
    if (vgt_drill_call(&m->fk, work, 2, in_q, m->n_fk_outputs, out_fk)) return 1;
    const double *in_qv[3] = {q, qd, p};
    double *out_bias[m->n_bias_outputs];
    for (int i = 0; i < m->n_bias_outputs; ++i) out_bias[i] = NULL;
    out_bias[0] = bias_tip;
    out_bias[1] = bias_w;
    if (vgt_drill_call(&m->bias_acc, work, 3, in_qv, m->n_bias_outputs, out_bias)) return 1;
    double *out_M[1] = {M};
    if (vgt_drill_call(&m->mass, work, 2, in_q, 1, out_M)) return 1;
    double *out_C[1] = {C};
    if (vgt_drill_call(&m->bias_forces, work, 3, in_qv, 1, out_C)) return 1;
    double e1[3], e2[3], axis[3], offset[3], a[3], turn[3];
    for (int i = 0; i < 3; ++i) {
        e1[i] = frame[3 * i];
        e2[i] = frame[3 * i + 1];
        axis[i] = frame[3 * i + 2];
        offset[i] = tip[i] - entry[i];
        a[i] = R[3 * i] * tool_axis[0] + R[3 * i + 1] * tool_axis[1] + R[3 * i + 2] * tool_axis[2];
    }
    const double *rows[VGT_DRILL_TASK][2] = {{e1, JP}, {e2, JP}, {e1, Jw}, {e2, Jw}, {axis, JP}};
    for (int r = 0; r < VGT_DRILL_TASK; ++r)
        for (int j = 0; j < nj; ++j) {
            const double *u = rows[r][0], *X = rows[r][1];
            J[r * nj + j] = u[0] * X[j] + u[1] * X[nj + j] + u[2] * X[2 * nj + j];
        }
    Jdot_qd[0] = vgt_drill_dot3(e1, bias_tip);
    Jdot_qd[1] = vgt_drill_dot3(e2, bias_tip);
    Jdot_qd[2] = vgt_drill_dot3(e1, bias_w);
    Jdot_qd[3] = vgt_drill_dot3(e2, bias_w);
    Jdot_qd[4] = vgt_drill_dot3(axis, bias_tip);
    turn[0] = a[1] * axis[2] - a[2] * axis[1];
    turn[1] = a[2] * axis[0] - a[0] * axis[2];
    turn[2] = a[0] * axis[1] - a[1] * axis[0];
    held_error[0] = vgt_drill_dot3(e1, offset);
    held_error[1] = vgt_drill_dot3(e2, offset);
    held_error[2] = -vgt_drill_dot3(e1, turn);
    held_error[3] = -vgt_drill_dot3(e2, turn);
    double rate[VGT_DRILL_TASK];
    for (int r = 0; r < VGT_DRILL_TASK; ++r) {
        double v = 0.0;
        for (int j = 0; j < nj; ++j) v += J[r * nj + j] * qd[j];
        rate[r] = v;
    }
    for (int r = 0; r < 4; ++r) held_rate[r] = rate[r];
    *depth = vgt_drill_dot3(axis, offset);
    *feed = rate[4];
    return 0;
}

/* The force (N, F0) at the tip whose joint efforts are tau: the least squares solution of
 * [J_P; J_W]^T w = tau through its normal equations (control.tool_wrench). */
static int vgt_drill_tool_force(const vgt_drill_model *m, void *work, int nj, const double *p, const double *q,
                                const double *tau, double force[3])
{
    double Jx[6 * nj], N[36], b[6], w[6];
    const double *in_q[2] = {q, p};
    double *out_jac[2] = {Jx, Jx + 3 * nj};
    if (vgt_drill_call(&m->jac, work, 2, in_q, 2, out_jac)) return 1;
    for (int r = 0; r < 6; ++r) {
        double v = 0.0;
        for (int j = 0; j < nj; ++j) v += Jx[r * nj + j] * tau[j];
        b[r] = v;
        for (int c = 0; c <= r; ++c) {
            double s = 0.0;
            for (int j = 0; j < nj; ++j) s += Jx[r * nj + j] * Jx[c * nj + j];
            N[r * 6 + c] = s;
            N[c * 6 + r] = s;
        }
    }
    if (!vgt_cholesky(6, N)) return 1;
    vgt_drill_solve(6, N, b, w);
    force[0] = w[0];
    force[1] = w[1];
    force[2] = w[2];
    return 0;
}

/* ---- sensing ------------------------------------------------------------------------------------ */

/* The filtered velocity of this period from the encoder reading qm (Sensing.measure; qd0 the known
 * velocity at the start). */
static void vgt_drill_measure(vgt_drill_state *st, const vgt_drill_settings *s, const double *qm, const double *qd0)
{
    const int nj = s->n_joints;
    double raw[nj];
    if (st->n_meas == 0) {
        memcpy(raw, qd0, sizeof raw);
        memcpy(st->v_filtered, raw, sizeof raw);
    } else {
        const double *last = st->q_meas + (st->n_meas - 1) * nj;
        for (int j = 0; j < nj; ++j) raw[j] = (qm[j] - last[j]) / s->dt;
        for (int j = 0; j < nj; ++j)
            st->v_filtered[j] = s->velocity_keep * st->v_filtered[j] + (1.0 - s->velocity_keep) * raw[j];
    }
    if (st->n_meas == 3) {
        memmove(st->q_meas, st->q_meas + nj, sizeof(double) * (size_t)(2 * nj));
        st->n_meas = 2;
    }
    memcpy(st->q_meas + st->n_meas * nj, qm, sizeof(double) * (size_t)nj);
    st->n_meas += 1;
    if (st->n_raw == 2) {
        memcpy(st->v_raw, st->v_raw + nj, sizeof(double) * (size_t)nj);
        st->n_raw = 1;
    }
    memcpy(st->v_raw + st->n_raw * nj, raw, sizeof raw);
    st->n_raw += 1;
}

/* The momentum observer's estimate of the external efforts (Sensing.observe). */
static int vgt_drill_observe(vgt_drill_state *st, const vgt_drill_settings *s, const vgt_drill_model *m, void *work,
                             const double *p)
{
    const int nj = s->n_joints;
    if (st->n_meas < 3 || st->n_efforts < 2) return 0; /* tau_hat stays zero */
    const double *va = st->v_raw, *vb = st->v_raw + nj;
    double acc[nj], applied[nj], raw[nj], f[3] = {0.0, 0.0, 0.0};
    for (int j = 0; j < nj; ++j) {
        applied[j] = 0.5 * (st->efforts[j] + st->efforts[nj + j]);
        acc[j] = (vb[j] - va[j]) / s->dt;
    }
    const double *in[5] = {st->q_meas, va, acc, f, p};
    double *out[1] = {raw};
    if (vgt_drill_call(&m->id, work, 5, in, 1, out)) return 1;
    for (int j = 0; j < nj; ++j) {
        raw[j] -= applied[j];
        st->tau_hat[j] = s->observer_keep * st->tau_hat[j] + (1.0 - s->observer_keep) * raw[j];
    }
    return 0;
}

static void vgt_drill_applied(vgt_drill_state *st, int nj, const double *F)
{
    if (st->n_efforts == 2) {
        memcpy(st->efforts, st->efforts + nj, sizeof(double) * (size_t)nj);
        st->n_efforts = 1;
    }
    memcpy(st->efforts + st->n_efforts * nj, F, sizeof(double) * (size_t)nj);
    st->n_efforts += 1;
}

/* ---- the detector -------------------------------------------------------------------------------- */

static void vgt_drill_event(vgt_drill_state *st, const vgt_drill_settings *s, double t, int kind, int layer, double c)
{
    if (st->n_events < st->max_events) {
        st->events[3 * st->n_events] = t;
        st->events[3 * st->n_events + 1] = kind;
        st->events[3 * st->n_events + 2] = layer;
    }
    st->n_events += 1;
    st->layer = layer;
    st->count = 0;
    st->level = c;
    st->softer = kind == VGT_DRILL_SOFTER;
    st->quiet_until = t + s->settle_time;
}

/* One sample of the detector (Detector.update) at the measured depth (m): 1 when the breakthrough
 * is detected now. */
static int vgt_drill_detect(vgt_drill_state *st, const vgt_drill_settings *s, double t, double thrust, double feed,
                            double depth)
{
    const double a = exp(-s->dt / s->estimate_time);
    const double b = exp(-s->dt / s->feed_time);
    st->thrust_f = a * st->thrust_f + (1.0 - a) * thrust;
    st->det_feed_f = st->started ? b * st->det_feed_f + (1.0 - b) * feed : feed;
    st->started = 1;
    const double g = pow(fmax(st->det_feed_f, s->told_feed_floor) / s->told_feed_ref, s->exponent);
    const double c = st->thrust_f / g;
    st->specific = c;
    if (st->layer < 0) {
        if (st->thrust_f > 0.25 * s->set_point) vgt_drill_event(st, s, t, VGT_DRILL_CONTACT, 0, c);
        return 0;
    }
    const int behind = s->told_layers - 1 - st->layer; /* a transition the bone's contrast hid: armed by depth */
    if ((behind >= 2 && depth >= s->arm_depth) || (behind == 1 && depth >= s->arm_depth_late)) {
        vgt_drill_event(st, s, t, VGT_DRILL_ARMED, s->told_layers - 1, c);
        st->quiet_until = t;
    }
    st->level = st->softer ? fmin(st->level, c) : fmax(st->level, c);
    if (t < st->quiet_until) return 0;
    if (st->layer == s->told_layers - 1) {
        const int drop = c < s->breakthrough_fraction * st->level;
        st->count = drop ? st->count + 1 : 0;
        if (st->count >= s->breakthrough_samples) {
            vgt_drill_event(st, s, t, VGT_DRILL_BREAKTHROUGH, s->told_layers, c);
            return 1;
        }
        return 0;
    }
    const int changed = st->softer ? c > (1.0 + s->layer_change) * st->level : c < (1.0 - s->layer_change) * st->level;
    st->count = changed ? st->count + 1 : 0;
    if (st->count >= s->layer_samples)
        vgt_drill_event(st, s, t, st->softer ? VGT_DRILL_HARDER : VGT_DRILL_SOFTER, st->layer + 1, c);
    return 0;
}

/* ---- the axial loop ------------------------------------------------------------------------------ */

static double vgt_drill_clip(double x, double low, double high) { return fmin(fmax(x, low), high); }

/* Explicit mode's feed limit (HybridController._feed_limited): 1 while the axis is on the position
 * loop at the feed limit. */
static int vgt_drill_feed_limited(vgt_drill_state *st, const vgt_drill_settings *s, double depth, double feed,
                                  double thrust)
{
    const double b = exp(-s->dt / s->feed_time);
    st->feed_f = b * st->feed_f + (1.0 - b) * feed;
    const int short_ = thrust < 0.95 * s->set_point;
    if (!st->limited && (st->feed_f >= 1.05 * s->feed_limit || (short_ && st->feed_f >= s->feed_limit))) {
        st->limited = 1;
        st->depth_ref = depth;
        st->feed_ref = s->feed_limit;
    } else if (st->limited && thrust >= s->set_point) {
        st->limited = 0;
        st->integral = -(1.0 + s->force_gain) * (s->set_point - thrust);
    }
    if (st->limited) {
        st->depth_ref += s->dt * s->feed_limit;
        const double lead = s->feed_limit * s->feed_lead;
        st->depth_ref = fmin(fmax(st->depth_ref, depth - lead), depth + lead);
    }
    return st->limited;
}

/* The axial reference of this sample (HybridController._reference). */
static void vgt_drill_reference(vgt_drill_state *st, const vgt_drill_settings *s, double depth, double thrust)
{
    if (st->phase == VGT_DRILL_DRILLING) {
        const double damping = s->exponent * fmax(thrust, 0.0) / fmax(st->feed_ref, 0.05 * s->feed_limit);
        const double mass = fmax(s->admittance_mass, s->admittance_time * damping);
        const double error = s->set_point - thrust;
        st->integral = vgt_drill_clip(st->integral + s->dt * error / mass, 0.0, s->feed_limit);
        const double direct = s->admittance_share * error / fmax(damping, s->admittance_mass / s->admittance_time);
        st->feed_ref = vgt_drill_clip(st->integral + direct, 0.0, s->feed_limit);
    } else if (st->phase == VGT_DRILL_RETRACTING) {
        st->feed_ref = -s->retract_speed;
    } else {
        st->feed_ref = 0.0;
    }
    if (st->phase == VGT_DRILL_RETRACTING && st->depth_ref <= st->stop_depth - s->retract_distance) st->feed_ref = 0.0;
    st->depth_ref += s->dt * st->feed_ref;
    if (st->phase == VGT_DRILL_DRILLING) {
        const double lead = s->feed_limit * s->feed_lead;
        st->depth_ref = fmin(fmax(st->depth_ref, depth - lead), depth + lead);
    }
}

/* ---- one period ------------------------------------------------------------------------------------ */

/* The phase of this sample (loop._advance). */
static void vgt_drill_advance(vgt_drill_state *st, const vgt_drill_settings *s, double t, double depth, double feed,
                              double estimate, double observed)
{
    if (st->phase == VGT_DRILL_TARE) {
        if (t >= 0.5 * s->tare_time) {
            st->tare += observed;
            st->tare_n += 1;
        }
        if (t >= s->tare_time) {
            st->offset = st->tare / (double)st->tare_n;
            st->phase = VGT_DRILL_DRILLING;
            st->depth_ref = depth;
            st->feed_ref = 0.0;
        }
        return;
    }
    if (st->phase == VGT_DRILL_DRILLING) {
        if (vgt_drill_detect(st, s, t, estimate, feed, depth)) {
            st->phase = VGT_DRILL_STOPPING;
            st->stopped_at = t;
            st->depth_ref = depth;
            st->feed_ref = 0.0;
            st->stop_depth = depth;
        }
    } else if (st->phase == VGT_DRILL_STOPPING && t >= st->stopped_at + s->stop_hold) {
        st->phase = VGT_DRILL_RETRACTING;
    } else if (st->phase == VGT_DRILL_RETRACTING && st->depth_ref <= st->stop_depth - s->retract_distance + 1e-12) {
        if (!isfinite(st->retracted_at)) st->retracted_at = t;
        if (t >= st->retracted_at + s->end_hold) st->phase = VGT_DRILL_DONE;
    }
}

/* The efforts F (nj) of the period at time t from the encoder reading qm (qd0: the velocity at the
 * start, read at the first period) and, with feedback = 1, the tip force sensor's thrust (N) of
 * the period before; out gets the thrust fed back, the observer's and the axial push. Returns 0 on
 * success, 1 when a generated function failed or a matrix was not positive definite. */
static int vgt_drill_control(vgt_drill_state *st, const vgt_drill_settings *s, const vgt_drill_model *m, void *work,
                             const double *p, const double *entry, const double *frame, const double *tool_axis,
                             double t, const double *qm, const double *qd0, double sensor_thrust, double *F,
                             vgt_drill_output *out)
{
    const int nj = s->n_joints, nt = VGT_DRILL_TASK;
    vgt_drill_measure(st, s, qm, qd0);
    if (vgt_drill_observe(st, s, m, work, p)) return 1;
    const double *vm = st->v_filtered;
    double J[VGT_DRILL_TASK * nj], Jdot_qd[VGT_DRILL_TASK], held_error[4], held_rate[4], depth, feed, M[nj * nj], C[nj];
    if (vgt_drill_task(m, work, nj, p, qm, vm, entry, frame, tool_axis, J, Jdot_qd, held_error, held_rate, &depth,
                       &feed, M, C))
        return 1;
    double force[3];
    if (vgt_drill_tool_force(m, work, nj, p, qm, st->tau_hat, force)) return 1;
    const double axis[3] = {frame[2], frame[5], frame[8]};
    const double observed = -vgt_drill_dot3(axis, force) - st->offset;
    const double estimate = s->feedback == 1 ? st->previous_thrust : observed;
    st->previous_thrust = sensor_thrust;
    vgt_drill_advance(st, s, t, depth, feed, estimate, observed);
    if (st->phase == VGT_DRILL_STOPPING && st->stopped_at == t) /* the bone is gone: so is its force */
        for (int j = 0; j < nj; ++j) st->tau_hat[j] += J[4 * nj + j] * observed; /* from the estimate */
    /* the law (HybridController.effort) */
    double L[nj * nj], MinvJt[nj * VGT_DRILL_TASK], Lam[VGT_DRILL_TASK * VGT_DRILL_TASK];
    memcpy(L, M, sizeof L);
    if (!vgt_cholesky(nj, L)) return 1;
    for (int r = 0; r < nt; ++r) {
        double col[nj];
        vgt_drill_solve(nj, L, J + r * nj, col);
        for (int j = 0; j < nj; ++j) MinvJt[j * nt + r] = col[j];
    }
    for (int r = 0; r < nt; ++r)
        for (int c = 0; c < nt; ++c) {
            double v = 0.0;
            for (int j = 0; j < nj; ++j) v += J[r * nj + j] * MinvJt[j * nt + c];
            Lam[r * nt + c] = v;
        }
    double LL[VGT_DRILL_TASK * VGT_DRILL_TASK];
    memcpy(LL, Lam, sizeof LL);
    for (int r = 0; r < nt; ++r) /* symmetric part: the factor reads the lower triangle */
        for (int c = 0; c < r; ++c) LL[r * nt + c] = 0.5 * (Lam[r * nt + c] + Lam[c * nt + r]);
    if (!vgt_cholesky(nt, LL)) return 1;
    const double wn = 2.0 * VGT_DRILL_PI * s->hold_frequency;
    double acc[VGT_DRILL_TASK] = {0.0, 0.0, 0.0, 0.0, 0.0};
    for (int r = 0; r < 4; ++r) acc[r] = -wn * wn * held_error[r] - 2.0 * wn * held_rate[r];
    double axial_force = 0.0;
    const int explicit_ = st->phase == VGT_DRILL_DRILLING && s->mode == 0;
    if (explicit_ && !vgt_drill_feed_limited(st, s, depth, feed, estimate)) {
        const double error = s->set_point - estimate;
        st->integral += s->force_rate * error * s->dt;
        axial_force = s->set_point + s->force_gain * error + st->integral - observed;
    } else {
        if (!explicit_) vgt_drill_reference(st, s, depth, estimate);
        const double wa = 2.0 * VGT_DRILL_PI * s->axial_frequency;
        acc[4] = wa * wa * (st->depth_ref - depth) + 2.0 * wa * (st->feed_ref - feed);
    }
    double Ft[VGT_DRILL_TASK], rhs[VGT_DRILL_TASK];
    for (int r = 0; r < nt; ++r) rhs[r] = acc[r] - Jdot_qd[r];
    vgt_drill_solve(nt, LL, rhs, Ft); /* Lambda (acc - Jdot qd) with Lambda = (J M^-1 J^T)^-1 */
    Ft[4] += axial_force;
    const double wp = 2.0 * VGT_DRILL_PI * s->null_frequency;
    double target[nj], posture[nj], y[VGT_DRILL_TASK];
    for (int j = 0; j < nj; ++j) target[j] = wp * wp * (st->q_centre[j] - qm[j]) - 2.0 * wp * vm[j];
    for (int i = 0; i < nj; ++i) {
        double v = 0.0;
        for (int j = 0; j < nj; ++j) v += M[i * nj + j] * target[j];
        posture[i] = v;
    }
    /* Jbar^T posture = Lambda (M^-1 J^T)^T posture */
    double z[VGT_DRILL_TASK];
    for (int r = 0; r < nt; ++r) {
        double v = 0.0;
        for (int j = 0; j < nj; ++j) v += MinvJt[j * nt + r] * posture[j];
        z[r] = v;
    }
    vgt_drill_solve(nt, LL, z, y);
    for (int j = 0; j < nj; ++j) {
        double task = 0.0, back = 0.0;
        for (int r = 0; r < nt; ++r) {
            task += J[r * nj + j] * Ft[r];
            back += J[r * nj + j] * y[r];
        }
        F[j] = task + C[j] - st->tau_hat[j] + (posture[j] - back);
    }
    if (s->force_limit) vgt_clip(nj, s->force_limit, F); /* the observer gets the effort applied */
    vgt_drill_applied(st, nj, F);
    out->estimate = estimate;
    out->observed = observed;
    out->push = axial_force;
    out->depth = depth;
    out->feed = feed;
    return 0;
}

#endif /* VGT_DRILL_CONTROL_H */
