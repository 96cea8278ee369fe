/* The compiled loop of force-controlled drilling (vgt_drill_simulate): the true robot drilling a
 * layered bone (the thrust semi-implicit in the cut's damping), the encoders, and the controller of
 * vgt_drill_control.h. The NumPy loop vgtarm/drilling/loop.py (drilling_run with engine "numpy")
 * is the same computation; tests/test_drilling_compiled.py holds the two to each other. The
 * generated functions come through vgt_drill_model, filled in by vgtarm/drilling/compiled.py.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "vgtarm.h"
#include "vgt_control.h" /* vgt_clip, vgt_saturate, vgt_cholesky */
#include "vgt_drill.h"
#include "vgt_work.h"

/* The controller's calls (vgt_drill_control.h) go through the work arrays the loop allocated. */
static int vgt_drill_call(const vgt_call *c, void *work, int n_in, const double **in, int n_out, double **out)
{
    return vgt_work_call(c, (vgt_work *)work, n_in, in, n_out, out);
}

#include "vgt_drill_control.h"

/* The truth at (q, qd): the tip's depth and feed along the axis, the drill's forces (thrust,
 * torque, their slopes), the tip and the tool's axis in F0. */
typedef struct {
    double depth, feed, forces[4], tip[3];
} drill_truth;

static int truth(const vgt_drill_model *m, vgt_work *wk, const vgt_drill_settings *s, const vgt_drill_bone *bone,
                 const vgt_drill_run *r, const double *q, const double *qd, drill_truth *out)
{
    const int layers = bone->n_layers - (isnan(r->fracture_time) ? 0 : 1); /* the cap out: the last layer cuts no more */
    double V[3], W[3];
    const double *in_q[2] = {q, r->p_plant};
    double *out_tip[1] = {out->tip};
    if (vgt_drill_call(&m->tip, wk, 2, in_q, 1, out_tip)) return 1;
    const double *in_qv[3] = {q, qd, r->p_plant};
    double *out_v[2] = {V, W};
    if (vgt_drill_call(&m->velocity, wk, 3, in_qv, 2, out_v)) return 1;
    const double axis[3] = {r->frame[2], r->frame[5], r->frame[8]};
    double offset[3] = {out->tip[0] - r->entry[0], out->tip[1] - r->entry[1], out->tip[2] - r->entry[2]};
    out->depth = vgt_drill_dot3(axis, offset);
    out->feed = vgt_drill_dot3(axis, V);
    vgt_drill_forces(layers, bone->boundaries, bone->coefficients, bone->point_length, bone->chisel_length,
                     bone->chisel_share, bone->feed_ref, bone->speed_ref, bone->feed_floor, out->depth, out->feed,
                     s->spindle_speed, out->forces);
    return 0;
}

/* One plant step of h (s) under F: (M + h b j j^T) qdd = F - C - j thrust - J_W^T axis torque,
 * then semi-implicit Euler (DrillingPlant.acceleration and step). */
static int plant_step(const vgt_drill_model *m, vgt_work *wk, const vgt_drill_settings *s,
                      const vgt_drill_bone *bone, vgt_drill_run *r, double t, double h, const double *F, double *q,
                      double *qd)
{
    const int nj = s->n_joints;
    drill_truth tr;
    if (truth(m, wk, s, bone, r, q, qd, &tr)) return 1;
    if (bone->cap_strength > 0.0 && isnan(r->fracture_time) && tr.depth > bone->boundaries[bone->n_layers - 1]) {
        const double thickness = bone->boundaries[bone->n_layers];
        const double critical = tr.forces[0] > 0.0 ? sqrt(bone->cap_factor * tr.forces[0] / bone->cap_strength) : 0.0;
        if (thickness - tr.depth < critical) { /* the cap breaks out: the forces without the last layer */
            r->fracture_time = t;
            if (truth(m, wk, s, bone, r, q, qd, &tr)) return 1;
        }
    }
    double JP[3 * nj], Jw[3 * nj], M[nj * nj], C[nj], j_axis[nj], rhs[nj], qdd[nj];
    const double *in_q[2] = {q, r->p_plant};
    double *out_jac[2] = {JP, Jw};
    if (vgt_drill_call(&m->jac, wk, 2, in_q, 2, out_jac)) return 1;
    double *out_M[1] = {M};
    if (vgt_drill_call(&m->mass, wk, 2, in_q, 1, out_M)) return 1;
    const double *in_qv[3] = {q, qd, r->p_plant};
    double *out_C[1] = {C};
    if (vgt_drill_call(&m->bias_forces, wk, 3, in_qv, 1, out_C)) return 1;
    const double axis[3] = {r->frame[2], r->frame[5], r->frame[8]};
    const double thrust = tr.forces[0], torque = tr.forces[1], damping = tr.forces[3];
    double delivered[nj];
    if (s->force_limit) { /* what the actuators deliver at this velocity */
        memcpy(delivered, F, sizeof delivered);
        vgt_saturate(nj, s->force_limit, r->speed_limit, r->force_speed, qd, delivered);
        F = delivered;
    }
    for (int j = 0; j < nj; ++j) {
        j_axis[j] = JP[j] * axis[0] + JP[nj + j] * axis[1] + JP[2 * nj + j] * axis[2];
        rhs[j] = F[j] - C[j] - j_axis[j] * thrust;
        if (s->tool_torque)
            rhs[j] -= (Jw[j] * axis[0] + Jw[nj + j] * axis[1] + Jw[2 * nj + j] * axis[2]) * torque;
    }
    for (int i = 0; i < nj; ++i)
        for (int j = 0; j < nj; ++j) M[i * nj + j] += (h * damping) * j_axis[i] * j_axis[j];
    if (!vgt_cholesky(nj, M)) return 1;
    vgt_drill_solve(nj, M, rhs, qdd);
    for (int j = 0; j < nj; ++j) {
        qd[j] += h * qdd[j];
        q[j] += h * qd[j];
    }
    return 0;
}

/* The row of vgtarm.drilling.loop.SERIES of this sample. */
static int record(const vgt_drill_model *m, vgt_work *wk, const vgt_drill_settings *s, const vgt_drill_run *r,
                  const vgt_drill_state *st, const drill_truth *tr, const double *q, double t,
                  const vgt_drill_output *o, double *row)
{
    double R[9];
    const double *in_q[2] = {q, r->p_plant};
    double *out_fk[m->n_fk_outputs];
    for (int i = 0; i < m->n_fk_outputs; ++i) out_fk[i] = NULL;
    out_fk[m->n_fk_outputs - 1] = R;
    if (vgt_drill_call(&m->fk, wk, 2, in_q, m->n_fk_outputs, out_fk)) return 1;
    const double axis[3] = {r->frame[2], r->frame[5], r->frame[8]};
    double a[3], offset[3], cross[3];
    for (int i = 0; i < 3; ++i) {
        a[i] = R[3 * i] * r->tool_axis[0] + R[3 * i + 1] * r->tool_axis[1] + R[3 * i + 2] * r->tool_axis[2];
        offset[i] = tr->tip[i] - r->entry[i];
    }
    const double along = vgt_drill_dot3(offset, axis);
    double lateral = 0.0;
    for (int i = 0; i < 3; ++i) lateral += (offset[i] - along * axis[i]) * (offset[i] - along * axis[i]);
    cross[0] = a[1] * axis[2] - a[2] * axis[1];
    cross[1] = a[2] * axis[0] - a[0] * axis[2];
    cross[2] = a[0] * axis[1] - a[1] * axis[0];
    const double values[VGT_DRILL_SERIES] = {
        t,
        tr->depth,
        tr->feed,
        tr->forces[0],
        o->estimate,
        st->phase == VGT_DRILL_DRILLING ? s->set_point : 0.0,
        tr->forces[1],
        sqrt(lateral),
        atan2(sqrt(vgt_drill_dot3(cross, cross)), vgt_drill_dot3(a, axis)),
        (double)st->phase,
        (double)st->layer,
        st->specific,
        o->push,
    };
    memcpy(row, values, sizeof values);
    return 0;
}

static int finite_state(int nj, const double *q, const double *qd)
{
    for (int j = 0; j < nj; ++j)
        if (!isfinite(q[j]) || !isfinite(qd[j])) return 0;
    return 1;
}

/* The run itself, with the work arrays and the state's memory allocated by vgt_drill_simulate. */
static int drill_run(const vgt_drill_model *m, vgt_work *wk, double *memory, const vgt_drill_settings *s,
                     const vgt_drill_bone *bone, vgt_drill_run *r)
{
    const int nj = s->n_joints;
    vgt_drill_state st;
    vgt_drill_start(&st, nj, r->q0, s->gap, memory, r->events, r->max_events);
    double q[nj], qd[nj], qd0[nj], qm[nj], F[nj];
    memcpy(q, r->q0, sizeof q);
    memset(qd, 0, sizeof qd);
    memset(qd0, 0, sizeof qd0);
    const int steps = s->substeps > 0 ? s->substeps : 1;
    const double h = s->dt / steps;
    int status = VGT_ABOVE_THRESHOLD;
    r->n_samples = 0;
    r->fracture_time = NAN;
    for (long k = 0; k < s->max_samples; ++k) {
        const double t = k * s->dt;
        drill_truth tr;
        if (!finite_state(nj, q, qd)) {
            status = VGT_NOT_FINITE;
            break;
        }
        if (truth(m, wk, s, bone, r, q, qd, &tr)) {
            status = VGT_FUNCTION_FAILED;
            break;
        }
        for (int j = 0; j < nj; ++j) {
            const double step = r->steps[j];
            qm[j] = step > 0.0 ? step * floor(q[j] / step + 0.5) : q[j];
        }
        vgt_drill_output o;
        if (vgt_drill_control(&st, s, m, wk, r->p_ctrl, r->entry, r->frame, r->tool_axis, t, qm, qd0, tr.forces[0],
                              F, &o)) {
            status = VGT_FUNCTION_FAILED;
            break;
        }
        if (record(m, wk, s, r, &st, &tr, q, t, &o, r->series + k * VGT_DRILL_SERIES)) {
            status = VGT_FUNCTION_FAILED;
            break;
        }
        memcpy(r->efforts + k * nj, F, sizeof F);
        if (r->q_meas) memcpy(r->q_meas + k * nj, qm, sizeof qm);
        r->n_samples = k + 1;
        if (st.phase == VGT_DRILL_DONE) {
            status = VGT_DONE;
            break;
        }
        int failed = 0;
        for (int i = 0; i < steps && !failed; ++i) failed = plant_step(m, wk, s, bone, r, t + i * h, h, F, q, qd);
        if (failed) {
            status = VGT_FUNCTION_FAILED;
            break;
        }
    }
    r->n_events = st.n_events < r->max_events ? st.n_events : r->max_events;
    return status;
}

int vgt_drill_simulate(const vgt_drill_model *m, const vgt_drill_settings *s, const vgt_drill_bone *bone,
                       vgt_drill_run *r)
{
    const vgt_call *calls[8] = {&m->tip, &m->velocity, &m->jac, &m->fk, &m->bias_acc, &m->mass, &m->bias_forces, &m->id};
    vgt_work wk;
    int ready = vgt_work_alloc(&wk, calls, 8);
    double *memory = malloc(sizeof(double) * (size_t)VGT_DRILL_STATE_DOUBLES(s->n_joints));
    int status = VGT_NO_MEMORY;
    if (ready && memory) status = drill_run(m, &wk, memory, s, bone, r);
    vgt_work_free(&wk);
    free(memory);
    return status;
}
