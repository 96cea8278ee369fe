/* Switching control for a real-time target (written by `vgtarm export controller --switching`).
 *
 * The switching control method of the paper around the exported computed force control
 * (vgtarm_controller.h) and its GA (vgtc_ga.h), as the simulation runs it (vgt_simulate_switching
 * in vgtarm/model/csrc/ga.c): each period the tip error is tested against the threshold; while it
 * stays within, the fixed gains control; in a period above it, one GA activation from the
 * controller's readings (joints and velocities) over the reference window ahead chooses the gains
 * of that period and, in the safe variant when the set was admitted (not dropped), of the next
 * hold - 1 periods too, during which the threshold is not tested; from the held period watch_from
 * on, a set whose error seen rises above the one seen at its activation is dropped: that period
 * runs with the fixed gains (no GA) and the next ones as usual.
 *
 * The tip error tested: the paper's variant tests the true tip error, which the controller does
 * not see (a tracker measures it; pass it as `error`); the safe variant by default tests what the
 * controller sees, |tip_d - P^(q_meas)| with its model's forward kinematics (pass error = NAN).
 *
 * Timing: a GA activation costs population x generations predictions (about 1 ms at -O3
 * -march=native on a desktop x86-64 core for the paper's 50 x 50 and a horizon of 20; see the
 * README); a period with an activation takes that long, the others a CFC step.
 */
#ifndef VGTC_SWITCHING_H
#define VGTC_SWITCHING_H

#include <stdint.h>

#include "vgtarm_controller.h"
#include "vgtc_ga.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    double threshold;        /* tip error above which the GA runs (m; 0: never)                    */
    long hold;               /* periods an admitted set controls from its activation (1: paper)    */
    long watch_from;         /* the first held period (the activation's is 0) at which a set whose  */
                             /* error seen exceeds the one seen at its activation is dropped for  */
                             /* the fixed gains (>= hold: never)                                  */
} vgtc_switching_params;

typedef struct {
    vgtc_context control;    /* the exported computed force control                                */
    vgtc_ga ga;              /* the GA                                                              */
    vgtc_switching_params p;
    long hold_left;          /* periods the current set still controls                              */
    double hold_above;       /* the error seen at its activation                                    */
    double gains[VGTC_GA_GENES]; /* the GA's last gains: Kp then Kv, row-major                      */
    /* what the last period did */
    int activated;           /* 1: the error was above the threshold (the GA ran unless no row was ahead) */
    int held;                /* 1: a held set controlled it                                         */
    int ran;                 /* 1: the GA ran (its record in `result`)                              */
    int dropped_hold;        /* 1: a held set was dropped here (its error rose): the fixed gains    */
    double error_seen;       /* the error tested (NaN when a held set controlled)                   */
    vgtc_ga_result result;
} vgtc_switching;

/* The exported threshold and hold (vgtc_defaults.c). */
void vgtc_switching_default_params(vgtc_switching_params *params);

/* Initialise the controller, its GA and the switching state; a vgtc_status. */
int vgtc_switching_init(vgtc_switching *sw, const vgtc_params *control, const vgtc_ga_params *ga,
                        const vgtc_switching_params *params);

/* One control period at time t: vgtc_step's arguments, and
 *   ref:   `rows` reference rows from this period on (3 VGTC_NJ values each: q_d, qd_d, qdd_d;
 *          the GA's window is min(horizon, rows - 1) periods ahead; rows >= 1);
 *   tip_d: `rows` desired tip positions (3 each, m);
 *   error: the tip error to test (m), or NAN for the one the controller sees;
 *   seed:  the GA's seed should this period activate (sw->ran says whether it did).
 * Returns a vgtc_status (a negative one: the efforts are zero and must not be applied). */
int vgtc_switching_step(vgtc_switching *sw, double t, const double *q_meas, const double *qd_meas, const double *ref,
                        long rows, const double *tip_d, double error, const double *f_meas, uint64_t seed,
                        double *efforts);

/* vgtc_switching_step with the expected tool force of this period fed forward (f_exp, 3, N; NULL:
 * none): every period's effort, under the fixed gains or the GA's, is vgtc_step_feedforward's. */
int vgtc_switching_step_feedforward(vgtc_switching *sw, double t, const double *q_meas, const double *qd_meas,
                                    const double *ref, long rows, const double *tip_d, double error,
                                    const double *f_meas, const double *f_exp, uint64_t seed, double *efforts);

#ifdef __cplusplus
}
#endif

#endif
