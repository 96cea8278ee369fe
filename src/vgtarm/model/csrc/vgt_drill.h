/* The drill's thrust and torque in a layered bone: the arithmetic of vgtarm.drilling.bone, operation
 * for operation and in the same order, so a compiled loop gives the NumPy loop's numbers bit for
 * bit (compile without contraction: -ffp-contract=off; tests/test_drilling_model.py holds the two
 * equal). C99 and libm only; no heap, no state, no I/O. Units: SI (m, m/s, rad/s, N, N m).
 *
 * The bone is given as data the Python side computes once (vgtarm.drilling.Bone):
 *   boundaries    n_layers + 1 interface depths (m) from the entry surface, 0 first;
 *   coefficients  n_layers rows of VGT_DRILL_COEFFICIENTS numbers (Bone.coefficients): thrust (N)
 *                 and its feed and speed exponents, torque (N m) and its feed and speed exponents,
 *                 at the reference feed and speed, density scaling applied;
 *   point_length  length of the drill point (m), over which the lips enter a layer;
 *   chisel_length axial length of the chisel edge (m, Bone.chisel_length), over which its share
 *                 chisel_share (0 to < 1, Bone.chisel_share) of the thrust enters a layer;
 *   feed_ref (m/s), speed_ref (rad/s) the law's references; feed_floor (m/s) the feed below which
 *                 the power law is a quadratic.
 * The caller checks its arguments (finite; speed > 0; lengths > 0): nothing is checked here.
 */
#ifndef VGT_DRILL_H
#define VGT_DRILL_H

#include <math.h>

#define VGT_DRILL_COEFFICIENTS 6

/* Engaged share of the lips, 0 to 1, with the tip u (m) past an interface: the cubic smoothstep
 * s^2 (3 - 2 s) of s = u / length clipped to [0, 1] (C1: its slope is 0 at both ends). */
static inline double vgt_drill_engagement(double u, double length)
{
    double s = u / length;
    if (s < 0.0) s = 0.0;
    if (s > 1.0) s = 1.0;
    return s * s * (3.0 - 2.0 * s);
}

/* Derivative of vgt_drill_engagement in u (1/m): 6 s (1 - s) / length, 0 outside the point. */
static inline double vgt_drill_engagement_slope(double u, double length)
{
    double s = u / length;
    if (s < 0.0) s = 0.0;
    if (s > 1.0) s = 1.0;
    return 6.0 * s * (1.0 - s) / length;
}

/* The feed's factor g of the law and its derivative dg (s/m) at the feed rate `feed` (m/s): 0 for
 * feed <= 0 (nothing is cut); (feed / feed_ref)^a from feed_floor up; below it the quadratic
 * c t ((2 - a) + (a - 1) t), t = feed / feed_floor, c = (feed_floor / feed_ref)^a, which meets the
 * power law with the same value and slope at the floor. */
static inline void vgt_drill_feed_law(double feed, double a, double feed_ref, double feed_floor, double *g,
                                      double *dg)
{
    if (feed >= feed_floor) {
        *g = pow(feed / feed_ref, a);
        *dg = a * *g / feed;
    } else if (feed > 0.0) {
        const double c = pow(feed_floor / feed_ref, a);
        const double t = feed / feed_floor;
        *g = c * t * ((2.0 - a) + (a - 1.0) * t);
        *dg = c * ((2.0 - a) + 2.0 * (a - 1.0) * t) / feed_floor;
    } else {
        *g = 0.0;
        *dg = 0.0;
    }
}

/* A layer's weight E(top) - E(bottom) and its slope (1/m) over a ramp of `length` (m), the tip `top`
 * past the layer's near side and `bottom` past its far side (E: vgt_drill_engagement). */
static inline void vgt_drill_ramp_pair(double top, double bottom, double length, double *weight, double *slope)
{
    *weight = vgt_drill_engagement(top, length) - vgt_drill_engagement(bottom, length);
    *slope = vgt_drill_engagement_slope(top, length) - vgt_drill_engagement_slope(bottom, length);
}

/* The drilling forces with the tip at `depth` (m, along the axis from the entry surface), fed at
 * `feed` (m/s) with the spindle at `speed` (rad/s, > 0): out[0] the thrust (N), out[1] the torque
 * (N m), out[2] the thrust's derivative in the depth (N/m), out[3] in the feed (N s/m). Each layer
 * i between boundaries[i] and boundaries[i + 1] weighs, in the thrust, (1 - c) w_L + c w_l, with
 * w_L = E(depth - boundaries[i]) - E(depth - boundaries[i + 1]) over point_length (the lips),
 * w_l the same over chisel_length (the chisel edge) and c = chisel_share; in the torque w_L alone. */
static inline void vgt_drill_forces(int n_layers, const double *boundaries, const double *coefficients,
                                    double point_length, double chisel_length, double chisel_share,
                                    double feed_ref, double speed_ref, double feed_floor, double depth,
                                    double feed, double speed, double out[4])
{
    double thrust = 0.0, torque = 0.0, depth_slope = 0.0, feed_slope = 0.0;
    const double speed_ratio = speed / speed_ref;
    const double keep = 1.0 - chisel_share;
    for (int i = 0; i < n_layers; ++i) {
        const double *c = coefficients + VGT_DRILL_COEFFICIENTS * i;
        double lips, lips_slope, chisel, chisel_slope;
        vgt_drill_ramp_pair(depth - boundaries[i], depth - boundaries[i + 1], point_length, &lips, &lips_slope);
        vgt_drill_ramp_pair(depth - boundaries[i], depth - boundaries[i + 1], chisel_length, &chisel, &chisel_slope);
        const double weight = keep * lips + chisel_share * chisel;
        const double slope = keep * lips_slope + chisel_share * chisel_slope;
        double g, dg, g_torque, dg_torque;
        vgt_drill_feed_law(feed, c[1], feed_ref, feed_floor, &g, &dg);
        vgt_drill_feed_law(feed, c[4], feed_ref, feed_floor, &g_torque, &dg_torque);
        const double s = pow(speed_ratio, c[2]);
        const double s_torque = pow(speed_ratio, c[5]);
        const double force = c[0] * g * s;
        thrust = thrust + force * weight;
        depth_slope = depth_slope + force * slope;
        feed_slope = feed_slope + c[0] * dg * s * weight;
        torque = torque + c[3] * g_torque * s_torque * lips;
    }
    out[0] = thrust;
    out[1] = torque;
    out[2] = depth_slope;
    out[3] = feed_slope;
}

#endif /* VGT_DRILL_H */
