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

``python -m benchmarks pathwide`` (not in the default set: it takes minutes), or
``python -m benchmarks.bench_path_wide [DECIMATION]``.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import casadi as ca
import numpy as np
from scipy.interpolate import CubicSpline

import vgtarm
from vgtarm.app.cases import case_path, joint_reference, run_case
from vgtarm.ik.effort import DEFAULT_JOINT_LIMIT_WEIGHT, reference_efforts
from vgtarm.ik.options import DEFAULT_MARGIN
from vgtarm.ik.problem import IKProblem

#: Every how many 1 ms samples a node of the path-wide problem lies.
DECIMATION = 10
#: Realistic sensing of the closed loop (as the report's section beyond the paper).
ENCODER_RESOLUTION = 1e-6
MODEL_MASS = 1.1


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
    robot: vgtarm.Robot, points: np.ndarray, forces: np.ndarray, q0: np.ndarray, h: float, weight: float
) -> tuple[np.ndarray, dict[str, Any]]:
    """The path-wide optimum ``(K, n)`` at the nodes ``points`` ``(K, 3)`` (tool forces ``forces``) from ``q0``."""
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
    nlp: dict[str, Any] = {"x": x, "f": f, "g": g}
    solver = ca.nlpsol("path_wide", "ipopt", nlp, settings)
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
        "iterations": int(stats["iter_count"]),
        "status": str(stats["return_status"]),
        "cost_start": float(ca.Function("f", [x], [f])(q0.ravel())),
        "cost": float(result["f"]),
    }
    return np.asarray(result["x"]).reshape(k, n), info


def to_samples(
    robot: vgtarm.Robot, t_nodes: np.ndarray, q_nodes: np.ndarray, t: np.ndarray, points: np.ndarray
) -> np.ndarray:
    """``q`` ``(N, n)`` at the times ``t``: a cubic spline through the nodes, each sample put back on its
    tip point ``points`` by minimum-norm Gauss-Newton steps."""
    q = CubicSpline(t_nodes, q_nodes, axis=0)(t)
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


def measure(decimation: int = DECIMATION, closed_loop: bool = True) -> dict[str, Any]:
    """The path-wide optimum of case 1 against the effort criterion's answer (module docstring)."""
    robot = vgtarm.load_robot()
    start = time.perf_counter()
    reference = joint_reference(robot, 1, criterion="effort", tool_force=0.0)
    effort_seconds = time.perf_counter() - start
    path = case_path(robot, 1)
    n_samples = len(path)
    nodes = np.arange(0, n_samples, decimation)  # the path up to the last node is compared
    h = decimation * path.dt
    q_nodes, info = solve_path_wide(
        robot, path.position[nodes], np.zeros((len(nodes), 3)), reference.q[nodes], h, DEFAULT_JOINT_LIMIT_WEIGHT
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


def run(decimation: int = DECIMATION) -> dict[str, Any]:
    """Measure and print the figures (``docs/control.md``, "The path-wide version, measured")."""
    out = measure(decimation)
    change = (out["path_wide_id_rms_n"] / out["effort_id_rms_n"] - 1) * 100
    loop = (out["path_wide_closed_loop_rms_n"] / out["effort_closed_loop_rms_n"] - 1) * 100
    print(f"\n### Path-wide effort criterion (case 1, a node every {decimation} ms, {out['nodes']} nodes)\n")
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

    run(int(sys.argv[1]) if len(sys.argv) > 1 else DECIMATION)
