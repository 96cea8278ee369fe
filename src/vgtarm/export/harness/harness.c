/* The simulated closed loop through the exported controller (vgtarm.export.loop; not exported).
 *
 * The plant is vgtarm's: this file includes the simulation's own closed_loop.c, so the tool force,
 * the integrator and the divergence checks are the very functions vgt_simulate runs. Per sample it
 * does what vgt_simulate_slice does, with the controller's part (measure, observe, computed force
 * control) replaced by one vgtc_step of the exported controller, handed the true joints (it rounds
 * them to its encoder steps), the true velocity (or, with differenced velocities, only at the
 * start), the tool force of the previous period and, with tool_feedforward, the expected tool
 * force of the period.
 */
#include "closed_loop.c"
#include "vgtarm_controller.h"

/* Run samples k0 .. k1-1 with the exported controller ctx; returns a vgt_status (*stop as
 * vgt_simulate) and, when the controller refused a step, its status in *controller_status. */
int vgtc_harness_run(const vgt_model *m, const vgt_settings *s, const vgt_run *r, vgtc_context *ctx,
                     const double *t, long k0, long k1, long *stop, int *controller_status)
{
    const int nj = s->n_joints;
    double qi[nj], vi[nj], ref[3 * nj];
    long used = 0, substep = 0;
    vgt_work wk;
    int status = VGT_DONE;
    *stop = k1;
    *controller_status = 0;
    if (nj != VGTC_NJ) return VGT_FUNCTION_FAILED;
    if (!work_alloc(&wk, m)) {
        vgt_work_free(&wk);
        return VGT_NO_MEMORY;
    }
    for (long k = k0; k < k1; ++k) {
        const double *q = r->q + nj * k, *qd = r->qd + nj * k;
        double *F = r->F + nj * k;
        const double *dist = r->disturbance + 3 * k;
        double V[3];
        double *tip = r->tip + 3 * k;
        const double *in_ts[3] = {q, qd, r->p_plant};
        double *out_ts[2] = {tip, V};
        if (vgt_work_call(&m->tip_state, &wk, 3, in_ts, 2, out_ts)) { status = VGT_FUNCTION_FAILED; *stop = k; break; }
        const double *td = r->tip_d + 3 * k;
        double e0 = td[0] - tip[0], e1 = td[1] - tip[1], e2 = td[2] - tip[2];
        r->error[k] = sqrt(e0 * e0 + e1 * e1 + e2 * e2);
        memcpy(ref, r->q_d + nj * k, sizeof(double) * (size_t)nj);
        memcpy(ref + nj, r->qd_d + nj * k, sizeof(double) * (size_t)nj);
        memcpy(ref + 2 * nj, r->qdd_d + nj * k, sizeof(double) * (size_t)nj);
        const double *velocity = s->sensing && k > 0 ? NULL : qd;
        const double *force = s->observer == VGT_OBSERVER_FORCE && k > 0 ? r->f_ext + 3 * (k - 1) : NULL;
        const double *expected = s->tool_feedforward ? r->tool_force_expected + 3 * k : NULL;
        int cs = vgtc_step_feedforward(ctx, t[k], q, velocity, ref, force, expected, NULL, NULL, F);
        if (cs < 0) { *controller_status = cs; status = VGT_FUNCTION_FAILED; *stop = k; break; }
        memcpy(r->q_meas + nj * k, vgtc_joint_readings(ctx), sizeof(double) * (size_t)nj);
        memcpy(r->qd_meas + nj * k, vgtc_joint_velocities(ctx), sizeof(double) * (size_t)nj);
        memcpy(r->tau_hat + nj * k, vgtc_effort_estimate(ctx), sizeof(double) * (size_t)nj);
        tool_force(s, V, dist, r->f_ext + 3 * k);
        if (k + 1 >= r->n) continue;
        memcpy(qi, q, sizeof(double) * (size_t)nj);
        memcpy(vi, qd, sizeof(double) * (size_t)nj);
        substep = 0;
        status = integrate(m, s, r, &wk, F, dist, qi, vi, &substep, &used, 0);
        double *q1 = r->q + nj * (k + 1), *qd1 = r->qd + nj * (k + 1);
        if (status == VGT_DONE) {
            memcpy(q1, qi, sizeof(double) * (size_t)nj);
            memcpy(qd1, vi, sizeof(double) * (size_t)nj);
            status = check_state(s, r, q1, qd1);
        }
        if (status != VGT_DONE) { *stop = k + 1; break; }
    }
    vgt_work_free(&wk);
    return status;
}

#ifdef VGTC_SWITCHING
#include <time.h>

#include "vgtc_switching.h"

size_t vgtc_switching_size(void) { return sizeof(vgtc_switching); }
size_t vgtc_ga_params_size(void) { return sizeof(vgtc_ga_params); }
size_t vgtc_switching_params_size(void) { return sizeof(vgtc_switching_params); }

/* vgtc_harness_run under switching control: each period is one vgtc_switching_step of sw, handed
 * the reference rows from the period on (ref: r->n rows of 3 nj), the desired tip rows, the true
 * tip error when `true_error` (the paper's variant tests it), else NAN (what the controller sees),
 * and the next unused seed of `seeds`. mode[k] = 1 where the GA's gains controlled period k
 * (activated or held), as the simulation's MODE_GA, 2 where a held set was dropped; each activation's record is written to
 * sample, generations, evaluations, best_cost, seeded_cost, wall (*count of them). */
int vgtc_harness_run_switching(const vgt_model *m, const vgt_settings *s, const vgt_run *r, vgtc_switching *sw,
                               const double *t, const double *ref, const uint64_t *seeds, int true_error, long k0,
                               long k1, long *stop, int *controller_status, signed char *mode, long *count,
                               long *sample, long *generations, long *evaluations, double *best_cost,
                               double *seeded_cost, double *wall)
{
    const int nj = s->n_joints;
    double qi[nj], vi[nj];
    long used = 0, substep = 0, seeds_used = 0;
    vgt_work wk;
    int status = VGT_DONE;
    *stop = k1;
    *controller_status = 0;
    *count = 0;
    if (nj != VGTC_NJ) return VGT_FUNCTION_FAILED;
    if (!work_alloc(&wk, m)) {
        vgt_work_free(&wk);
        return VGT_NO_MEMORY;
    }
    for (long k = k0; k < k1; ++k) {
        const double *q = r->q + nj * k, *qd = r->qd + nj * k;
        double *F = r->F + nj * k;
        const double *dist = r->disturbance + 3 * k;
        double V[3];
        double *tip = r->tip + 3 * k;
        const double *in_ts[3] = {q, qd, r->p_plant};
        double *out_ts[2] = {tip, V};
        if (vgt_work_call(&m->tip_state, &wk, 3, in_ts, 2, out_ts)) { status = VGT_FUNCTION_FAILED; *stop = k; break; }
        const double *td = r->tip_d + 3 * k;
        double e0 = td[0] - tip[0], e1 = td[1] - tip[1], e2 = td[2] - tip[2];
        r->error[k] = sqrt(e0 * e0 + e1 * e1 + e2 * e2);
        const double *velocity = s->sensing && k > 0 ? NULL : qd;
        const double *force = s->observer == VGT_OBSERVER_FORCE && k > 0 ? r->f_ext + 3 * (k - 1) : NULL;
        struct timespec w0, w1;
        clock_gettime(CLOCK_MONOTONIC, &w0);
        const double *expected = s->tool_feedforward ? r->tool_force_expected + 3 * k : NULL;
        int cs = vgtc_switching_step_feedforward(sw, t[k], q, velocity, ref + 3L * nj * k, r->n - k, td,
                                                 true_error ? r->error[k] : NAN, force, expected,
                                                 seeds[seeds_used], F);
        clock_gettime(CLOCK_MONOTONIC, &w1);
        if (cs < 0) { *controller_status = cs; status = VGT_FUNCTION_FAILED; *stop = k; break; }
        mode[k] = (signed char)(sw->dropped_hold ? 2 : sw->activated || sw->held);
        if (sw->activated) {
            const long i = (*count)++;
            sample[i] = k;
            generations[i] = sw->ran ? sw->result.generations : 0;
            evaluations[i] = sw->ran ? sw->result.evaluations : 0;
            best_cost[i] = sw->ran ? sw->result.best_cost : 0.0;
            seeded_cost[i] = sw->ran ? sw->result.seeded_cost : 0.0;
            wall[i] = (double)(w1.tv_sec - w0.tv_sec) + 1e-9 * (double)(w1.tv_nsec - w0.tv_nsec);
            if (sw->ran) ++seeds_used;
        }
        memcpy(r->q_meas + nj * k, vgtc_joint_readings(&sw->control), sizeof(double) * (size_t)nj);
        memcpy(r->qd_meas + nj * k, vgtc_joint_velocities(&sw->control), sizeof(double) * (size_t)nj);
        memcpy(r->tau_hat + nj * k, vgtc_effort_estimate(&sw->control), sizeof(double) * (size_t)nj);
        tool_force(s, V, dist, r->f_ext + 3 * k);
        if (k + 1 >= r->n) continue;
        memcpy(qi, q, sizeof(double) * (size_t)nj);
        memcpy(vi, qd, sizeof(double) * (size_t)nj);
        substep = 0;
        status = integrate(m, s, r, &wk, F, dist, qi, vi, &substep, &used, 0);
        double *q1 = r->q + nj * (k + 1), *qd1 = r->qd + nj * (k + 1);
        if (status == VGT_DONE) {
            memcpy(q1, qi, sizeof(double) * (size_t)nj);
            memcpy(qd1, vi, sizeof(double) * (size_t)nj);
            status = check_state(s, r, q1, qd1);
        }
        if (status != VGT_DONE) { *stop = k + 1; break; }
    }
    vgt_work_free(&wk);
    return status;
}
#endif
