"""The commented example study that ``vgtarm study init FILE`` writes."""

from __future__ import annotations

EXAMPLE = """\
# A vgtarm study: computed force control (CFC) against the switching method (SCM) with the tool
# force, over seeds and a controller model whose masses are off by up to 10 %.
# Run it with `vgtarm study run THIS_FILE --out DIR` and read it with `vgtarm study report DIR`.
# Every run of this file: (2 controllers) x (2 model draws) x (4 seeds) = 16 runs.

[study]
name = "cfc-vs-scm"
case = 1                # the paper's case study 1 or 2; or path = "tip.csv" (t,x,y,z rows in s and m,
                        # relative to this file; gains then default to case 1's)
duration = 1.0          # s: run only the first second of the path (leave out for the whole path)
dt = 0.001              # s: control period, the sampling of the reference
rates = "exact"         # reference rates: "exact" or "finite_difference" (the paper's)
# robot = "robot.toml"  # a robot file (default: the shipped reference robot)
seeds = 4               # seeds 0..3 of the disturbance and the GA; or [0, 7, 9]; or {start = 10, count = 4}

# Every combination of the values below is run (a single value is a list of one).
# Parameters: controller ("cfc" | "scm"), kp, kv (gains, default the case's), threshold (m, SCM),
# horizon (control periods, SCM), scm_variant ("safe" | "paper", SCM), prediction ("quadratic" |
# "linear" | "exact"), kp_max, kv_max (upper GA bounds), ga_population, ga_generations, external_force (true | false),
# cutting_force (N), disturbance (N per axis), model_mass, model_inertia, model_friction
# (factors on the controller's model), integrator ("euler" | "semi_implicit_euler" | "rk4"),
# substeps, and the simulator's own options where it has them (observer = "momentum",
# observer_gain, force_sensor, encoder_resolution, velocity_noise, estimator ("difference" |
# "kalman", with encoders), estimator_bandwidth_hz, plant_engine = "mujoco" for the MuJoCo plant
# with vgtarm[mujoco], ...), and the reference's redundancy criterion ("joint_limits", eq. 12, |
# "effort": the actuator forces) with joint_limit_weight (effort criterion only).
[grid]
controller = ["cfc", "scm"]
external_force = true

# `draws` independent draws of the parameters below (each draw is run with every seed).
# Distributions: {uniform = [a, b]}, {log_uniform = [a, b]}, {normal = [mean, sd]},
# {integers = [a, b]}, {choice = [v1, v2]}.
[random]
draws = 2
seed = 0                # seed of the draws
model_mass = {uniform = [0.9, 1.1]}
"""
