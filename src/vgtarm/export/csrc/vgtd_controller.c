/* The drilling controller of vgtd_controller.h: the simulation's per-period arithmetic
 * (vgt_drill_control.h) on the generated model functions (vgtc_model.c). */
#include <math.h>
#include <string.h>

#include "vgt_control.h" /* vgt_clip */
#include "vgtd_controller.h"
#include "vgtc_model.h"

static int vgt_drill_call(const vgt_call *f, void *work, int n_in, const double **in, int n_out, double **out)
{
    vgtd_context *c = (vgtd_context *)work;
    const double *arg[VGTD_SZ_ARG]; /* on the stack: they point at the caller's arrays */
    double *res[VGTD_SZ_RES];
    for (int i = 0; i < n_in; ++i) arg[i] = in[i];
    for (int j = 0; j < n_out; ++j) res[j] = out[j];
    return f->f(arg, res, c->iw, c->w, 0);
}

#include "vgt_drill_control.h"

/* The context's memory holds the state's arrays. */
typedef char vgtd_memory_fits[sizeof(((vgtd_context *)0)->memory) >= sizeof(double) * VGT_DRILL_STATE_DOUBLES(VGTD_NJ)
                                  ? 1
                                  : -1];

static vgt_call vgtd_function(vgt_fn f)
{
    vgt_call c;
    memset(&c, 0, sizeof c);
    c.f = f;
    return c;
}

int vgtd_init(vgtd_context *c)
{
    memset(c, 0, sizeof *c);
    vgtd_default_settings(&c->settings);
    if (VGTD_ACTUATORS) c->settings.force_limit = vgtd_force_limit;
    c->model.tip = vgtd_function(vgt_tip);
    c->model.jac = vgtd_function(vgt_jac);
    c->model.fk = vgtd_function(vgt_fk);
    c->model.bias_acc = vgtd_function(vgt_bias_acc);
    c->model.mass = vgtd_function(vgt_mass);
    c->model.bias_forces = vgtd_function(vgt_bias_forces);
    c->model.id = vgtd_function(vgt_id);
    c->model.n_fk_outputs = VGTD_FK_OUTPUTS;
    c->model.n_bias_outputs = VGTD_BIAS_OUTPUTS;
    vgt_drill_start(&c->state, VGTD_NJ, vgtd_q0, c->settings.gap, c->memory, c->events, VGTD_MAX_EVENTS);
    return VGTD_OK;
}

int vgtd_step(vgtd_context *c, double t, const double *q_meas, double sensor_thrust, double *F,
              vgt_drill_output *out)
{
    static const double at_rest[VGTD_NJ];
    vgt_drill_output o;
    if (vgt_drill_control(&c->state, &c->settings, &c->model, c, vgtd_model_p, vgtd_entry, vgtd_frame, vgtd_tool_axis,
                          t, q_meas, at_rest, sensor_thrust, F, &o)) {
        memset(F, 0, sizeof(double) * VGTD_NJ);
        return VGTD_FAILED;
    }
    if (out) *out = o;
    return c->state.phase == VGT_DRILL_DONE ? VGTD_DONE : VGTD_OK;
}
