"""A second reference solver: IPOPT (interior point, through ``casadi.nlpsol``) per sample.

The nonlinear program is the reference solver's (:mod:`vgtarm.ik.slsqp`), written symbolically
from :func:`vgtarm.symbolic.kinematics` so that IPOPT gets exact first and second derivatives.
Samples are solved in order, each started from the previous solution.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ..model.codegen.ik import pose_constraints, rotation_from_row_major
from ..model.parameters import N_PARAMETERS
from ..model.symbolic import kinematics
from . import slsqp
from .options import IKOptions
from .problem import IKProblem
from .state import BatchState
from .tasks import Task

Array = NDArray[np.float64]
METHOD = "ipopt"


def build(problem: IKProblem, kind: str, options: IKOptions) -> ca.Function:
    """The IPOPT solver of one sample; its parameter is ``[target point (3), R_d row-major (9, pose only), p]``."""
    q = ca.SX.sym("q", 7)
    point = ca.SX.sym("point", 3)
    p = ca.SX.sym("p", N_PARAMETERS)
    if kind == "position":
        parameters = ca.vertcat(point, p)
        c = kinematics(q, p).tip - point
    else:
        rd = ca.SX.sym("R_d", 9)
        parameters = ca.vertcat(point, rd, p)
        c = pose_constraints(q, rotation_from_row_major(rd), p) - ca.vertcat(point, ca.SX.zeros(3))
    cost = 0.5 * ca.sum1(ca.DM(problem.weight) * (q - ca.DM(problem.centre)) ** 2)
    g = ca.vertcat(c, ca.DM(problem.G) @ q + ca.DM(problem.h))
    settings: dict[str, Any] = {
        "print_time": False,
        "error_on_fail": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": 1e-12,
        "ipopt.constr_viol_tol": 1e-12,
        "ipopt.max_iter": options.reference_maxiter,
    }
    return ca.nlpsol("vgtarm_ik_ipopt", "ipopt", {"x": q, "p": parameters, "f": cost, "g": g}, settings)


def solve(problem: IKProblem, task: Task, state: BatchState, q_start: Array, options: IKOptions) -> None:
    """The IPOPT reference solver (solver contract of :mod:`vgtarm.ik.registry`)."""
    solver = build(problem, task.kind, options)
    m, k = task.m, problem.n_triangle
    lbg = np.concatenate([np.zeros(m), np.full(k, problem.margin)])
    ubg = np.concatenate([np.zeros(m), np.full(k, np.inf)])

    def solve_one(problem: IKProblem, task: Task, i: int, q0: Array, options: IKOptions) -> slsqp.SampleSolution:
        parts = [task.position[i]] + ([task.rotation[i]] if task.rotation is not None else []) + [task.p]
        result = solver(
            x0=np.clip(q0, problem.lower, problem.upper),
            p=np.concatenate(parts),
            lbx=problem.lower,
            ubx=problem.upper,
            lbg=lbg,
            ubg=ubg,
        )
        stats = solver.stats()
        q = np.asarray(result["x"], dtype=float).ravel()
        residual = float(np.abs(np.asarray(result["g"]).ravel()[:m]).max())
        success = bool(stats["success"]) and residual <= options.accept_primal and bool(problem.feasible(q, 1e-10))
        return slsqp.SampleSolution(q, success, int(stats["iter_count"]), str(stats["return_status"]), residual)

    slsqp.solve_path(problem, task, state, q_start, options, solve_one, METHOD)
