"""The path-wide effort criterion, measured (issue 22): is it worth building in?

The effort criterion (:mod:`vgtarm.ik.effort`) picks each sample's joints alone, by the *static*
efforts (gravity and the expected tool force). This measurement solves the whole path at once with
the *inertial* terms: decision variables ``q_k`` at every ``DECIMATION``-th sample of case 1
(``h = DECIMATION dt``), constraints ``tip(q_k) = p_k``, the joint limits and the triangle
inequalities with the IK's margin, and the cost

    (1/K) sum_k [ (1/n) sum_i (s_i F_i(q_k, qd_k, qdd_k, f_k))^2 + w_jl Phi_jl(q_k) ]

with ``F = M qdd + C + (friction, in C) - J_P^T f`` the inverse dynamics (the one symbolic definition),
``s`` the effort criterion's scales, ``qd``, ``qdd`` second-order finite differences of ``q`` over
the nodes (one-sided at the ends), ``f`` the expected tool force (0 on case 1) and ``w_jl Phi_jl`` the
same joint-limit term as the effort criterion. IPOPT (CasADi ``nlpsol``, exact Hessian) starts from
the effort criterion's answer at the nodes.

The answer is brought back to 1 ms by a cubic spline through the nodes, each sample then put back
on its tip point by Gauss-Newton steps (minimum-norm corrections, to 1e-12 m), and ``qd``, ``qdd``
by differences of that. Both references are then measured alike: the RMS leg force of the inverse
dynamics along the path (the feed-forward that holds and moves the arm), and the closed loop of
case 1 with realistic sensing (CFC, 1 um encoders, controller model 10 % heavy, seed 0), whose
RMS leg force is the figure of the issue's target.

**Case 2 with the tool force** (the case whose RMS leg-force target the effort criterion misses):
the per-sample reference is the low-force preset's, the effort criterion with the expected 20 N
cutting force (:func:`vgtarm.ik.effort.expected_tool_force`, smoothed over the criterion's default
speed), and the path-wide cost takes that same expected force at its nodes. The robot starts at rest
at ``q_d(0)``, so the path-wide reference must too (a reference moving at ``t = 0`` costs a start
transient of hundreds of newtons in the closed loop): the first node's velocity (row 0 of the first
difference) is constrained to zero, the spline through the nodes starts with a zero slope, and the
resampled rates start at zero. So is the end: left free, the optimum's last nodes ended the
reference moving (the twist at 4.9 rad/s, legs at 0.1 m/s at a node every 20 ms) although the path
stops there. The problem is expanded to scalar operations (``expand``): without it
IPOPT's iterations are slow enough that a prototype did not converge in its budget. Both references
are measured by their inverse dynamics with the plant's cutting force (``-F0 v/|v|`` along the
desired tip velocity, zero below the cutting speed) and with the expected force, and in the
closed loop of ``vgtarm simulate --case 2 --external-force --preset low-force --encoder-resolution
1e-6 --model-mass 1.1`` on seeds 0 and 1. The joint-limit weight is an argument (the per-sample
reference at another weight than the preset's is shown too, and the path-wide problem starts from it).

``python -m benchmarks pathwide`` (case 1; not in the default set: it takes minutes), or
``python -m benchmarks.bench_path_wide [DECIMATION] [CASE] [WEIGHT]``.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import casadi as ca
import numpy as np
from scipy.interpolate import CubicSpline

import vgtarm
from vgtarm.experiment.cases import case_path, case_study, joint_reference, run_case
from vgtarm.experiment.presets import preset_options
from vgtarm.ik.effort import (
    DEFAULT_JOINT_LIMIT_WEIGHT,
    DEFAULT_TOOL_FORCE_SPEED,
    expected_tool_force,
    reference_efforts,
)
from vgtarm.ik.options import DEFAULT_MARGIN
from vgtarm.ik.problem import IKProblem

#: Every how many 1 ms samples a node of the path-wide problem lies.
DECIMATION = 10
#: Realistic sensing of the closed loop (as the report's section beyond the paper).
ENCODER_RESOLUTION = 1e-6
MODEL_MASS = 1.1
#: Case 2's closed loop: the preset it runs (``vgtarm simulate --preset``) and the seeds of its disturbance.
PRESET = "low-force"
SEEDS = (0, 1)
#: How long (s) after the start and before the end a closed-loop force peak counts as a transient of them.
EDGE_S = 0.1


def difference_matrices(k: int, h: float) -> tuple[np.ndarray, np.ndarray]:
    """``(D1, D2)`` ``(k, k)``: second-order first and second differences over nodes ``h`` apart
    (central inside, one-sided at the two ends); ``Q @ D.T`` differentiates the rows of ``Q`` (n, k)."""
    d1, d2 = np.zeros((k, k)), np.zeros((k, k))
    for i in range(1, k - 1):
        d1[i, i - 1 : i + 2] = [-0.5, 0.0, 0.5]
        d2[i, i - 1 : i + 2] = [1.0, -2.0, 1.0]
    d1[0, :3], d1[-1, -3:] = [-1.5, 2.0, -0.5], [0.5, -2.0, 1.5]
    d2[0, :4], d2[-1, -4:] = [2.0, -5.0, 4.0, -1.0], [-1.0, 4.0, -5.0, 2.0]
    return d1 / h, d2 / h**2


def node_functions(robot: vgtarm.Robot) -> tuple[ca.Function, ca.Function, ca.Function]:
    """``(efforts, cost, tip)`` of one node: the inverse dynamics ``F(q, qd, qdd, f)``, the node's
    cost term (weights as parameters) and the tip point."""
    d = robot.definition
    n = d.n_joints
    q, qd, qdd = (ca.SX.sym(name, n) for name in ("q", "qd", "qdd"))
    f, p = ca.SX.sym("f", 3), ca.SX.sym("p", d.n_parameters)
    scale, weight, centre = (ca.SX.sym(name, n) for name in ("s", "w", "c"))
    dyn = d.dynamics(q, qd, p)
    efforts = dyn.M @ qdd + dyn.C - dyn.J_P.T @ f
    cost = ca.sumsqr(scale * efforts) / n + 0.5 * ca.sum1(weight * (q - centre) ** 2)
    return (
        ca.Function("node_efforts", [q, qd, qdd, f, p], [efforts]),
        ca.Function("node_cost", [q, qd, qdd, f, p, scale, weight, centre], [cost]),
        ca.Function("node_tip", [q, p], [d.kinematics(q, p).tip]),
    )


def solve_path_wide(
    robot: vgtarm.Robot,
    points: np.ndarray,
    forces: np.ndarray,
    q0: np.ndarray,
    h: float,
    weight: float,
    *,
    at_rest: bool = False,
    expand: bool = False,
) -> tuple[np.ndarray, dict[str, Any]]:
    """The path-wide optimum ``(K, n)`` at the nodes ``points`` ``(K, 3)`` (tool forces ``forces``) from ``q0``.

    ``at_rest``: the first and the last node's velocities (rows 0 and -1 of the first difference)
    are held at zero, as the robot starts at rest at ``q_d(0)`` and the path ends at rest; ``expand``:
    the problem is expanded to scalar operations before IPOPT (a longer build, faster iterations)."""
    k, n = q0.shape
    problem = IKProblem.from_parameters(robot.parameters, DEFAULT_MARGIN, weight)
    _, cost, tip = node_functions(robot)
    d1, d2 = difference_matrices(k, h)
    x = ca.MX.sym("x", n * k)
    q = ca.reshape(x, n, k)
    qd = ca.mtimes(q, ca.sparsify(ca.DM(d1.T)))
    qdd = ca.mtimes(q, ca.sparsify(ca.DM(d2.T)))
    p = ca.DM(robot.parameter_vector)
    total = cost.map(k)(
        q,
        qd,
        qdd,
        ca.DM(forces.T),
        p,
        ca.DM(1.0 / reference_efforts(robot)),
        ca.DM(problem.weight),
        ca.DM(problem.centre),
    )
    f = ca.sum2(total) / k
    g_tip = ca.vec(tip.map(k)(q, p) - ca.DM(points.T))
    g_tri = ca.vec(ca.DM(problem.G) @ q + ca.repmat(ca.DM(problem.h), 1, k))
    g = ca.vertcat(g_tip, g_tri)
    m = problem.G.shape[0]
    lbg = np.concatenate([np.zeros(3 * k), np.full(m * k, problem.margin)])
    ubg = np.concatenate([np.zeros(3 * k), np.full(m * k, np.inf)])
    if at_rest:  # linear: (D1 q^T)[0] = (D1 q^T)[-1] = 0, the end nodes' velocities
        g = ca.vertcat(g, ca.mtimes(q, ca.DM(d1[0])), ca.mtimes(q, ca.DM(d1[-1])))
        lbg, ubg = np.concatenate([lbg, np.zeros(2 * n)]), np.concatenate([ubg, np.zeros(2 * n)])
    settings: dict[str, Any] = {
        "print_time": False,
        "error_on_fail": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": 1e-10,
        "ipopt.constr_viol_tol": 1e-12,
        "ipopt.max_iter": 300,
        "ipopt.mu_init": 1e-6,
        "ipopt.warm_start_init_point": "yes",
    }
    if expand:
        settings["expand"] = True
    nlp: dict[str, Any] = {"x": x, "f": f, "g": g}
    build = time.perf_counter()
    solver = ca.nlpsol("path_wide", "ipopt", nlp, settings)
    build_seconds = time.perf_counter() - build
    start = time.perf_counter()
    result = solver(
        x0=q0.ravel(),
        lbx=np.tile(problem.lower, k),
        ubx=np.tile(problem.upper, k),
        lbg=lbg,
        ubg=ubg,
    )
    stats = solver.stats()
    info = {
        "seconds": time.perf_counter() - start,
        "build_seconds": build_seconds,
        "iterations": int(stats["iter_count"]),
        "status": str(stats["return_status"]),
        "cost_start": float(ca.Function("f", [x], [f])(q0.ravel())),
        "cost": float(result["f"]),
    }
    return np.asarray(result["x"]).reshape(k, n), info


def to_samples(
    robot: vgtarm.Robot,
    t_nodes: np.ndarray,
    q_nodes: np.ndarray,
    t: np.ndarray,
    points: np.ndarray,
    *,
    at_rest: bool = False,
) -> np.ndarray:
    """``q`` ``(N, n)`` at the times ``t``: a cubic spline through the nodes, each sample put back on its
    tip point ``points`` by minimum-norm Gauss-Newton steps. ``at_rest``: the spline's slope is zero at
    the first and the last node (else the not-a-knot ends)."""
    bc: Any = "clamped" if at_rest else "not-a-knot"  # clamped: zero first derivative at both ends
    q = CubicSpline(t_nodes, q_nodes, axis=0, bc_type=bc)(t)
    for _ in range(8):
        r = robot.tip_position(q) - points
        if np.abs(r).max() < 1e-13:
            break
        jac = robot.tip_jacobian(q)
        q = q - np.einsum("nji,nj->ni", jac, np.linalg.solve(jac @ jac.transpose(0, 2, 1), r[..., None])[..., 0])
    return q


def leg_rms(robot: vgtarm.Robot, efforts: np.ndarray) -> float:
    """RMS of the legs' efforts (the prismatic joints), as ``summary.json``'s ``rms_force_n``."""
    legs = np.array([unit == "m" for unit in robot.parameters.joint_units])
    return float(np.sqrt(np.mean(efforts[:, legs] ** 2)))


def measure(
    decimation: int = DECIMATION, closed_loop: bool = True, weight: float = DEFAULT_JOINT_LIMIT_WEIGHT
) -> dict[str, Any]:
    """The path-wide optimum of case 1 against the effort criterion's answer (module docstring)."""
    robot = vgtarm.load_robot()
    start = time.perf_counter()
    reference = joint_reference(robot, 1, criterion="effort", tool_force=0.0, joint_limit_weight=weight)
    effort_seconds = time.perf_counter() - start
    path = case_path(robot, 1)
    n_samples = len(path)
    nodes = np.arange(0, n_samples, decimation)  # the path up to the last node is compared
    h = decimation * path.dt
    q_nodes, info = solve_path_wide(
        robot, path.position[nodes], np.zeros((len(nodes), 3)), reference.q[nodes], h, weight
    )
    last = nodes[-1] + 1
    t = path.t[:last]
    q = to_samples(robot, path.t[nodes], q_nodes, t, path.position[:last])
    qd = np.gradient(q, path.dt, axis=0)
    qdd = np.gradient(qd, path.dt, axis=0)
    wide = replace(reference.head(last), q=q, qd=qd, qdd=qdd)
    effort = reference.head(last)
    out: dict[str, Any] = {
        "decimation": decimation,
        "nodes": len(nodes),
        "effort_ik_seconds": effort_seconds,
        **info,
        "tip_residual_m": float(np.abs(robot.tip_position(q) - path.position[:last]).max()),
    }
    for name, ref in (("effort", effort), ("path_wide", wide)):
        out[f"{name}_id_rms_n"] = leg_rms(robot, robot.inverse_dynamics(ref.q, ref.qd, ref.qdd))
        still = np.zeros_like(ref.q)  # the static part alone: gravity
        out[f"{name}_static_rms_n"] = leg_rms(robot, robot.inverse_dynamics(ref.q, still, still))
        if closed_loop:
            run = run_case(
                robot,
                1,
                reference=ref,
                encoder_resolution=ENCODER_RESOLUTION,
                controller_model=robot.parameters.scaled(mass=MODEL_MASS),
            ).summary()
            out[f"{name}_closed_loop_rms_n"] = run["rms_force_n"]
            out[f"{name}_max_after_transient_mm"] = run["max_tip_error_after_transient_m"] * 1e3
    return out


def rest_rates(q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(qd, qdd)`` of samples ``q`` ``(N, n)`` ``dt`` apart that start and end at rest: second-order
    differences (one-sided at the ends), the first and last velocities set to zero before the
    accelerations are taken from the velocities, so the two agree."""
    qd = np.gradient(q, dt, axis=0, edge_order=2)
    qd[0] = qd[-1] = 0.0
    return qd, np.gradient(qd, dt, axis=0, edge_order=2)


def cutting_force(velocity: np.ndarray, force: float, speed: float) -> np.ndarray:
    """The plant's cutting force ``(N, 3)`` along tip velocities ``velocity``: ``-F0 v/|v|``, zero at or below
    the cutting speed ``speed`` (the simulator's rule, without the random disturbance)."""
    norm = np.linalg.norm(velocity, axis=1, keepdims=True)
    moving = norm > speed
    return np.where(moving, -force * velocity / np.where(moving, norm, 1.0), 0.0)


def edge_peaks(robot: vgtarm.Robot, run: Any) -> tuple[float, float, float]:
    """The largest leg force (N) of a closed-loop run within ``EDGE_S`` of its start and of its end (the
    transients), and the time (s) of its overall peak."""
    legs = np.array([unit == "m" for unit in robot.parameters.joint_units])
    forces = np.abs(run.effort[:, legs]).max(axis=1)
    t = run.t - run.t[0]
    return float(forces[t <= EDGE_S].max()), float(forces[t >= t[-1] - EDGE_S].max()), float(t[np.argmax(forces)])


def measure_tool_force(
    decimation: int = DECIMATION, weight: float = DEFAULT_JOINT_LIMIT_WEIGHT, seeds: tuple[int, ...] = SEEDS
) -> dict[str, Any]:
    """The path-wide optimum of case 2 with the tool force against the effort criterion's answer, the
    low-force preset's reference (module docstring). Keys ``rows`` (one per reference: its inverse
    dynamics and closed-loop figures per seed) and the solve's figures."""
    robot = vgtarm.load_robot()
    external = case_study(2).external_force
    ik, simulation = preset_options(PRESET, tool_force=external.cutting_force)
    path = case_path(robot, 2)
    start = time.perf_counter()
    preset = joint_reference(robot, 2, **ik)
    effort_seconds = time.perf_counter() - start
    references = {"preset": preset}
    if weight != DEFAULT_JOINT_LIMIT_WEIGHT:  # the criterion's own answer at this weight, the solve's start
        references["effort_w"] = joint_reference(robot, 2, **{**ik, "joint_limit_weight": weight})
    start_reference = references.get("effort_w", preset)
    expected, _, _ = expected_tool_force(
        path, external.cutting_force, float(ik.get("tool_force_speed", DEFAULT_TOOL_FORCE_SPEED))
    )
    nodes = np.arange(0, len(path), decimation)  # the path up to the last node is compared
    q_nodes, info = solve_path_wide(
        robot,
        path.position[nodes],
        expected[nodes],
        start_reference.q[nodes],
        decimation * path.dt,
        weight,
        at_rest=True,
        expand=True,
    )
    last = nodes[-1] + 1
    q = to_samples(robot, path.t[nodes], q_nodes, path.t[:last], path.position[:last], at_rest=True)
    qd, qdd = rest_rates(q, path.dt)
    references = {name: ref.head(last) for name, ref in references.items()}
    references["path_wide"] = replace(start_reference.head(last), q=q, qd=qd, qdd=qdd)
    plant = cutting_force(path.velocity[:last], external.cutting_force, external.cutting_speed)
    out: dict[str, Any] = {
        "decimation": decimation,
        "weight": weight,
        "nodes": len(nodes),
        "simulation": simulation,
        "effort_ik_seconds": effort_seconds,
        **info,
        "tip_residual_m": float(np.abs(robot.tip_position(q) - path.position[:last]).max()),
        "rows": {},
    }
    legs = np.array([unit == "m" for unit in robot.parameters.joint_units])
    edge = round(EDGE_S / path.dt) + 1
    for name, ref in references.items():
        still = np.zeros_like(ref.q)
        row: dict[str, Any] = {
            "leg_acceleration": float(np.abs(ref.qdd[:, legs]).max()),  # m/s^2
            "twist_rate": float(np.abs(ref.qd[:, ~legs]).max()) if (~legs).any() else 0.0,  # rad/s
            "runs": {},
        }
        for label, force in (("plant", plant), ("expected", expected[:last])):
            efforts = robot.inverse_dynamics(ref.q, ref.qd, ref.qdd, f_tip=force)
            row[f"id_{label}_rms_n"] = leg_rms(robot, efforts)
            row[f"static_{label}_rms_n"] = leg_rms(robot, robot.inverse_dynamics(ref.q, still, still, f_tip=force))
            if label == "plant":  # the load near the ends, to tell a closed-loop transient from it
                peak = np.abs(efforts[:, legs]).max(axis=1)
                row["id_edge_peaks_n"] = (float(peak[:edge].max()), float(peak[-edge:].max()))
        for seed in seeds:
            result = run_case(
                robot,
                2,
                reference=ref,
                external_force=True,
                seed=seed,
                encoder_resolution=ENCODER_RESOLUTION,
                controller_model=robot.parameters.scaled(mass=MODEL_MASS),
                **simulation,
            )
            summary = result.summary()
            row["runs"][seed] = {
                "max_tip_error_mm": summary["max_tip_error_m"] * 1e3,
                "rms_force_n": summary["rms_force_n"],
                "peak_force_n": summary["peak_force_n"],
                "chatter_n": summary["chatter_n"],
                "peaks_n": edge_peaks(robot, result),
            }
        out["rows"][name] = row
    return out


def run_tool_force(decimation: int = DECIMATION, weight: float = DEFAULT_JOINT_LIMIT_WEIGHT) -> dict[str, Any]:
    """Measure and print case 2's figures with the tool force (module docstring)."""
    out = measure_tool_force(decimation, weight)
    rows = out["rows"]
    labels = {
        "preset": f"effort criterion (per sample, w_jl {DEFAULT_JOINT_LIMIT_WEIGHT:g}: the preset's)",
        "effort_w": f"effort criterion (per sample, w_jl {weight:g})",
        "path_wide": f"path-wide optimum (w_jl {weight:g})",
    }
    print(
        f"\n### Path-wide effort criterion (case 2 with the tool force, a node every {decimation} ms,"
        f" {out['nodes']} nodes, w_jl {weight:g})\n"
    )
    print(
        "| reference | RMS leg force, inverse dynamics, plant's cutting force | of it static |"
        f" peak within {EDGE_S:g} s of start / end | with the expected force | of it static |"
        " largest leg acceleration, twist rate |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    base = rows["preset"]
    for name, row in rows.items():
        change = (row["id_plant_rms_n"] / base["id_plant_rms_n"] - 1) * 100
        print(
            f"| {labels[name]} | {row['id_plant_rms_n']:.2f} N ({change:+.2f} %) | {row['static_plant_rms_n']:.2f} N |"
            f" {row['id_edge_peaks_n'][0]:.1f} / {row['id_edge_peaks_n'][1]:.1f} N |"
            f" {row['id_expected_rms_n']:.2f} N | {row['static_expected_rms_n']:.2f} N |"
            f" {row['leg_acceleration']:.2f} m/s^2, {row['twist_rate']:.2f} rad/s |"
        )
    print(
        f"\nClosed loop: `vgtarm simulate --case 2 --external-force --preset {PRESET} --encoder-resolution"
        f" {ENCODER_RESOLUTION:g} --model-mass {MODEL_MASS:g}` with the reference (the preset's options:"
        f" {', '.join(f'{key} {value}' for key, value in out['simulation'].items())}).\n"
    )
    print(
        "| reference | seed | max tip error | RMS leg force | peak leg force (at) | chatter |"
        f" peak within {EDGE_S:g} s of start / end |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name, row in rows.items():
        for seed in SEEDS:
            run = row["runs"][seed]
            change = (run["rms_force_n"] / base["runs"][seed]["rms_force_n"] - 1) * 100
            print(
                f"| {labels[name]} | {seed} | {run['max_tip_error_mm']:.4f} mm | {run['rms_force_n']:.2f} N"
                f" ({change:+.2f} %) | {run['peak_force_n']:.1f} N ({run['peaks_n'][2]:.3f} s) |"
                f" {run['chatter_n']:.2f} N | {run['peaks_n'][0]:.1f} / {run['peaks_n'][1]:.1f} N |"
            )
    print(
        f"\ncost {out['cost_start']:.6f} -> {out['cost']:.6f}; IPOPT {out['iterations']} iterations, {out['status']},"
        f" {out['seconds']:.1f} s (build {out['build_seconds']:.1f} s; effort criterion, whole path:"
        f" {out['effort_ik_seconds']:.2f} s); worst tip residual after resampling {out['tip_residual_m']:.1e} m"
    )
    return out


def run(decimation: int = DECIMATION, case: int = 1, weight: float = DEFAULT_JOINT_LIMIT_WEIGHT) -> dict[str, Any]:
    """Measure and print the figures (``docs/control.md``, "The path-wide version, measured"): case 1,
    or case 2 with the tool force."""
    if case == 2:
        return run_tool_force(decimation, weight)
    if case != 1:
        raise SystemExit(f"case {case!r}: expected 1 or 2")
    out = measure(decimation, weight=weight)
    change = (out["path_wide_id_rms_n"] / out["effort_id_rms_n"] - 1) * 100
    loop = (out["path_wide_closed_loop_rms_n"] / out["effort_closed_loop_rms_n"] - 1) * 100
    shown = "" if weight == DEFAULT_JOINT_LIMIT_WEIGHT else f", w_jl {weight:g}"
    print(f"\n### Path-wide effort criterion (case 1, a node every {decimation} ms, {out['nodes']} nodes{shown})\n")
    print(
        "| reference | RMS leg force, inverse dynamics | of it static (gravity) | closed loop, realistic sensing |"
        " max tip error after 0.2 s |"
    )
    print("| --- | --- | --- | --- | --- |")
    for name, label in (("effort", "effort criterion (per sample)"), ("path_wide", "path-wide optimum")):
        print(
            f"| {label} | {out[f'{name}_id_rms_n']:.2f} N | {out[f'{name}_static_rms_n']:.2f} N |"
            f" {out[f'{name}_closed_loop_rms_n']:.2f} N | {out[f'{name}_max_after_transient_mm']:.4f} mm |"
        )
    print(
        f"\ninverse-dynamics RMS {change:+.2f} %, closed loop {loop:+.2f} % (build it in at -5 % or better);"
        f" cost {out['cost_start']:.6f} -> {out['cost']:.6f}; IPOPT {out['iterations']} iterations,"
        f" {out['status']}, {out['seconds']:.1f} s (effort criterion, whole path: {out['effort_ik_seconds']:.2f} s);"
        f" worst tip residual after resampling {out['tip_residual_m']:.1e} m"
    )
    return out


if __name__ == "__main__":
    import sys

    args = sys.argv[1:]
    run(
        int(args[0]) if args else DECIMATION,
        int(args[1]) if len(args) > 1 else 1,
        float(args[2]) if len(args) > 2 else DEFAULT_JOINT_LIMIT_WEIGHT,
    )
