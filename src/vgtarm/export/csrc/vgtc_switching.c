/* Switching control for a real-time target (see vgtc_switching.h): the period logic of
 * vgt_simulate_switching (vgtarm/model/csrc/ga.c) around vgtc_step_gains and vgtc_ga_activate. */
#include <math.h>
#include <string.h>

#include "vgtc_model.h"
#include "vgtc_switching.h"

int vgtc_switching_init(vgtc_switching *sw, const vgtc_params *control, const vgtc_ga_params *ga,
                        const vgtc_switching_params *params)
{
    int status;
    if (!sw || !control || !ga || !params) return VGTC_BAD_ARGUMENT;
    if (!(params->threshold >= 0.0 && isfinite(params->threshold)) || params->hold < 1 || params->hold > ga->horizon
        || params->watch_from < 1)
        return VGTC_BAD_PARAMETER;
    if (fabs(ga->dt - control->dt) > 0.0) return VGTC_BAD_PARAMETER;
    memset(sw, 0, sizeof *sw);
    if ((status = vgtc_init(&sw->control, control)) != VGTC_OK) return status;
    if ((status = vgtc_ga_init(&sw->ga, ga)) != VGTC_GA_OK) return status;
    sw->p = *params;
    return VGTC_OK;
}

int vgtc_switching_step(vgtc_switching *sw, double t, const double *q_meas, const double *qd_meas, const double *ref,
                        long rows, const double *tip_d, double error, const double *f_meas, uint64_t seed,
                        double *efforts)
{
    return vgtc_switching_step_feedforward(sw, t, q_meas, qd_meas, ref, rows, tip_d, error, f_meas, NULL, seed,
                                           efforts);
}

int vgtc_switching_step_feedforward(vgtc_switching *sw, double t, const double *q_meas, const double *qd_meas,
                                    const double *ref, long rows, const double *tip_d, double error,
                                    const double *f_meas, const double *f_exp, uint64_t seed, double *efforts)
{
    const int nn = VGTC_NJ * VGTC_NJ;
    const double *Kp, *Kv;
    double qm[VGTC_NJ], vm[VGTC_NJ];
    int status;
    if (!sw || !ref || !tip_d || rows < 1 || !efforts) {
        if (efforts) memset(efforts, 0, sizeof(double) * VGTC_NJ);
        return VGTC_BAD_ARGUMENT;
    }
    Kp = sw->control.p.Kp;
    Kv = sw->control.p.Kv;
    sw->activated = sw->held = sw->ran = sw->dropped_hold = 0;
    sw->error_seen = NAN;
    if (sw->hold_left <= 0 || sw->p.hold - sw->hold_left >= sw->p.watch_from) { /* the error is tested */
        if ((status = vgtc_readings(&sw->control, q_meas, qd_meas, qm, vm)) != VGTC_OK) {
            memset(efforts, 0, sizeof(double) * VGTC_NJ);
            return status;
        }
        if (isnan(error)) { /* what the controller sees: its model's tip at the readings */
            double tip[3], m0, m1, m2;
            const double *arg[VGTC_SZ_ARG];
            double *res[VGTC_SZ_RES];
            arg[0] = qm;
            arg[1] = sw->control.p.model;
            res[0] = tip;
            if (vgt_tip(arg, res, sw->control.iw, sw->control.w, 0)) {
                memset(efforts, 0, sizeof(double) * VGTC_NJ);
                return VGTC_FUNCTION_FAILED;
            }
            m0 = tip_d[0] - tip[0];
            m1 = tip_d[1] - tip[1];
            m2 = tip_d[2] - tip[2];
            error = sqrt(m0 * m0 + m1 * m1 + m2 * m2);
        }
        sw->error_seen = error;
    }
    if (sw->hold_left > 0) { /* an admitted set held over the periods it was certified for */
        if (sw->p.hold - sw->hold_left >= sw->p.watch_from && error > sw->hold_above) {
            /* its error rose: dropped, this period under the fixed gains (no GA) */
            status = vgtc_step_feedforward(&sw->control, t, q_meas, qd_meas, ref, f_meas, f_exp, Kp, Kv, efforts);
            if (status >= 0) {
                sw->hold_left = 0;
                sw->dropped_hold = 1;
            }
            return status;
        }
        status = vgtc_step_feedforward(&sw->control, t, q_meas, qd_meas, ref, f_meas, f_exp, sw->gains, sw->gains + nn, efforts);
        if (status >= 0) {
            sw->hold_left -= 1;
            sw->held = 1;
        }
        return status;
    }
    long hold_left = 0;
    if (sw->p.threshold > 0.0 && error > sw->p.threshold) { /* (a threshold of 0: never switched) */
        const long horizon = sw->ga.p.horizon < rows - 1 ? sw->ga.p.horizon : rows - 1;
        sw->activated = 1;
        if (horizon > 0) { /* the last period has nothing left to predict: it keeps the fixed gains */
            status = vgtc_ga_activate(&sw->ga, horizon, qm, vm, ref, tip_d, seed, sw->gains, &sw->result);
            if (status != VGTC_GA_OK) {
                memset(efforts, 0, sizeof(double) * VGTC_NJ);
                return status;
            }
            sw->ran = 1;
            Kp = sw->gains;
            Kv = sw->gains + nn;
            if (sw->p.hold > 1 && !sw->result.dropped) hold_left = sw->p.hold - 1;
        }
    }
    status = vgtc_step_feedforward(&sw->control, t, q_meas, qd_meas, ref, f_meas, f_exp, Kp, Kv, efforts);
    if (status >= 0) {
        sw->hold_left = hold_left;
        sw->hold_above = error;
    }
    return status;
}
