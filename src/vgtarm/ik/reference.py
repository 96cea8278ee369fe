"""The reference solver: SciPy's SLSQP per sample (the open analogue of the paper's ``fmincon``).

Each sample is one small nonlinear program with the exact cost gradient and the exact constraint
Jacobian from the compiled model: ``min Phi(q)`` subject to ``c(q) = c_d`` (tip point, and the
orientation residual for the pose task), the joint limits as bounds and the kept triangle rows as
linear inequalities ``G q + h - margin >= 0``. Samples are solved in order, each warm-started from
the previous solution (the first from the start pose). The same machinery finds the closest
reachable point of a target (:func:`closest`), used to report unreachable samples.

A second reference solver: IPOPT (interior point, through ``casadi.nlpsol``) per sample.

The nonlinear program is the reference solver's (SLSQP, above), written symbolically
from :func:`~vgtarm.model.symbolic.kinematics` so that IPOPT gets exact first and second derivatives.
Samples are solved in order, each started from the previous solution.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import Bounds, OptimizeResult, minimize

from .. import progress
from ..model.codegen.ik import effort_cost, pose_constraints, rotation_from_row_major
from ..model.definition import PAPER, Definition
from . import kkt
from .options import IKOptions
from .problem import BatchState, IKProblem, Task

Array = NDArray[np.float64]
METHOD_SLSQP = "slsqp"
#: Slack below which a reference solution's constraint counts as active (m, rad).
ACTIVE_TOLERANCE = 1e-9
#: Scales of the closest-point objective ``scale |r|^2 / 2``, one pass each: SLSQP's ``ftol`` is
#: absolute, so a large scale resolves small residuals, but from far away it stalls SLSQP's line
#: search; the second pass starts from the first pass's answer.
DISTANCE_SCALES = (1e4, 1e8)


@dataclass(frozen=True)
class SampleSolution:
    """One sample's reference solution: joints, whether it met the tolerances, work done, reason."""

    q: Array
    success: bool
    iterations: int
    message: str
    residual: float


class _Model:
    """Residual and Jacobian of one sample at the last ``q`` asked for (SLSQP asks twice per point)."""

    def __init__(self, task: Task, i: int) -> None:
        self.task, self.idx = task, np.array([i], dtype=np.intp)
        self.zero = np.zeros((1, task.m))
        self.key = b""
        self.value: tuple[Array, Array] = (np.zeros(task.m), np.zeros((task.m, task.model.n_joints)))

    def __call__(self, q: Array) -> tuple[Array, Array]:
        key = q.tobytes()
        if key != self.key:
            r, J, _ = self.task.evaluate(self.idx, np.ascontiguousarray(q[None]), self.zero)
            self.key, self.value = key, (r[0], J[0])
        return self.value


def _minimize(
    problem: IKProblem,
    objective: Callable[[Array], tuple[float, Array]],
    q0: Array,
    equality: _Model | None,
    options: IKOptions,
) -> OptimizeResult:
    """Run SLSQP in the scaled joints ``u = (q - q*) / (upper - lower)`` and return ``q``.

    In ``u`` the cost ``Phi = |u|^2 / n`` is isotropic (in ``q`` the twist joint's curvature is
    2000 times smaller than the legs', which slows SLSQP's quasi-Newton updates considerably);
    bounds become ``[-1/2, 1/2]``. Gradients and Jacobians follow by the chain rule. The
    result's ``x`` is in ``u``.
    """
    width, centre = problem.upper - problem.lower, problem.centre

    def to_q(u: Array) -> Array:
        return centre + width * u

    constraints: list[dict[str, object]] = []
    if equality is not None:
        constraints.append(
            {
                "type": "eq",
                "fun": lambda u: equality(to_q(u))[0],
                "jac": lambda u: equality(to_q(u))[1] * width,
            }
        )
    if problem.n_triangle:
        G_u = problem.G * width
        constraints.append(
            {"type": "ineq", "fun": lambda u: problem.G @ to_q(u) + problem.h - problem.margin, "jac": lambda u: G_u}
        )

    def scaled(u: Array) -> tuple[float, Array]:
        value, gradient = objective(to_q(u))
        return value, gradient * width

    u0 = np.clip((q0 - centre) / width, -0.5, 0.5)
    result: OptimizeResult = minimize(
        scaled,
        u0,
        jac=True,
        method="SLSQP",
        bounds=Bounds(np.full(problem.n, -0.5), np.full(problem.n, 0.5)),
        constraints=constraints,
        options={"ftol": options.reference_ftol, "maxiter": options.reference_maxiter},
    )
    return result


def solve_sample(problem: IKProblem, task: Task, i: int, q0: Array, options: IKOptions) -> SampleSolution:
    """Solve sample ``i`` from ``q0``: the optimum of ``Phi`` on the task's constraints."""
    model = _Model(task, i)
    one = np.array([i], dtype=np.intp)

    def objective(q: Array) -> tuple[float, Array]:
        if task.effort is None:
            return float(problem.phi(q)), problem.phi_gradient(q)
        at = np.ascontiguousarray(q[None])
        g = task.evaluate_cost(one, at, np.zeros((1, task.m)))[3]
        assert g is not None
        return float(problem.phi(q)) + float(task.effort_cost(one, at)[0]), problem.phi_gradient(q) + g[0]

    result = _minimize(problem, objective, q0, model, options)
    q = np.clip(problem.centre + (problem.upper - problem.lower) * result.x, problem.lower, problem.upper)
    residual = float(np.abs(model(q)[0]).max()) if problem.assemblable(q) else np.inf
    success = bool(result.success) and residual <= options.accept_primal and bool(problem.feasible(q, 1e-10))
    return SampleSolution(q, success, int(result.nit), str(result.message), residual)


def closest(problem: IKProblem, task: Task, i: int, starts: list[Array], options: IKOptions) -> tuple[Array, Array]:
    """The feasible ``q`` whose task values come closest to sample ``i``'s target, and its residual ``(m,)``.

    Minimises ``|c(q) - c_d|^2`` over the joint limits and the assembly constraints from each start,
    then refines the best answer (see :data:`DISTANCE_SCALES`), and keeps the best.
    """
    model = _Model(task, i)
    best_q, best_r = starts[0], np.full(task.m, np.inf)
    for scale in DISTANCE_SCALES:

        def objective(q: Array, scale: float = scale) -> tuple[float, Array]:
            r, J = model(q)
            return 0.5 * scale * float(r @ r), scale * (J.T @ r)

        for q0 in starts if scale == DISTANCE_SCALES[0] else [best_q]:
            result = _minimize(problem, objective, q0, None, options)
            q = np.clip(problem.centre + (problem.upper - problem.lower) * result.x, problem.lower, problem.upper)
            if problem.assemblable(q):
                r = model(q)[0].copy()
                if np.linalg.norm(r) < np.linalg.norm(best_r):
                    best_q, best_r = q, r
    return best_q, best_r


def finish(problem: IKProblem, task: Task, state: BatchState, idx: NDArray[np.intp]) -> None:
    """Multipliers, active sets and model values of reference solutions at samples ``idx`` (batched)."""
    if idx.size == 0:
        return
    q = state.q[idx]
    _, J, _, g = task.evaluate_cost(idx, q, np.zeros((idx.size, task.m)))
    lam, mu, active = kkt.estimate_multipliers(problem, q, J, ACTIVE_TOLERANCE, g)
    residual, J, H, g = task.evaluate_cost(idx, q, lam)
    state.lam[idx], state.mu[idx], state.active[idx] = lam, mu, active
    state.residual[idx], state.J[idx], state.H[idx] = residual, J, H
    if g is not None and state.g is not None:
        state.g[idx] = g


def solve_path(
    problem: IKProblem,
    task: Task,
    state: BatchState,
    q_start: Array,
    options: IKOptions,
    solve_one: Callable[[IKProblem, Task, int, Array, IKOptions], SampleSolution] = solve_sample,
    method: str = METHOD_SLSQP,
) -> None:
    """Solve every sample in order with ``solve_one``, each from the previous solution (solver contract)."""
    previous = q_start
    for i in range(len(task)):
        solution = solve_one(problem, task, i, previous, options)
        state.q[i] = solution.q
        state.iterations[i] = solution.iterations
        state.converged[i] = solution.success
        state.method[i] = method
        if solution.success:
            previous = solution.q
        progress.report(i + 1, len(task))
    done = np.flatnonzero(state.converged)
    finish(problem, task, state, done)


def solve_slsqp(problem: IKProblem, task: Task, state: BatchState, q_start: Array, options: IKOptions) -> None:
    """The SLSQP reference solver (solver contract: :class:`vgtarm.ik.Solver`)."""
    solve_path(problem, task, state, q_start, options)


METHOD_IPOPT = "ipopt"


def build_ipopt(
    problem: IKProblem,
    kind: str,
    options: IKOptions,
    definition: Definition = PAPER,
    effort: bool = False,
    directions: Array | None = None,
    tool: Array | None = None,
    cone: float | None = None,
) -> ca.Function:
    """The IPOPT solver of one sample of the robot ``definition`` (default the paper's); its parameter
    is ``[target point (3), R_d row-major (9, pose only), p]``, and with ``effort`` (the effort
    criterion) ``[target point (3), (the axis task's frame (9),) tool force (3), inverse scales (n), p]``.
    With ``directions`` ``(r, 3)`` (a robot whose tip moves in a plane or a line) the position rows are
    ``E (P(q) - point)``, written symbolically here, independently of the compiled projection. The
    axis task (``kind`` ``"axis"``, ``tool`` the tool rotation ``B``) takes the frame ``[w1 w2 d]`` of its
    target axis (9, row-major) where the pose task takes ``R_d``, and its rows ``w1 . a``, ``w2 . a`` of
    the tool axis ``a = C03 B e3``, written here from the forward kinematics; on a cone's boundary
    (``cone`` its half-angle's cosine, the frame ``[d w1 w2]``) the one row ``d . a - cone``."""
    q = ca.SX.sym("q", definition.n_joints)
    point = ca.SX.sym("point", 3)
    p = ca.SX.sym("p", definition.n_parameters)
    fk = definition.kinematics(q, p)
    extra, pieces, c = None, [point], fk.tip - point
    if kind == "axis":
        assert tool is not None
        frame = ca.SX.sym("F", 9)
        pieces.append(frame)
        a = fk.C03 @ ca.DM(tool[:, 2])
        w = rotation_from_row_major(frame)
        rows = [w[:, 0].T @ a, w[:, 1].T @ a] if cone is None else [w[:, 0].T @ a - cone]
        c = ca.vertcat(c, *rows)
    elif kind == "pose":
        rd = ca.SX.sym("R_d", 9)
        pieces.append(rd)
        c = pose_constraints(q, rotation_from_row_major(rd), p, definition) - ca.vertcat(point, ca.SX.zeros(3))
    if effort:
        force, scale = ca.SX.sym("f", 3), ca.SX.sym("s", definition.n_joints)
        pieces += [force, scale]
        extra = effort_cost(q, force, scale, p, definition)
    parameters = ca.vertcat(*pieces, p)
    if directions is not None:
        c = ca.DM(directions) @ c
    cost = 0.5 * ca.sum1(ca.DM(problem.weight) * (q - ca.DM(problem.centre)) ** 2)
    if extra is not None:
        cost = cost + extra
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


def solve_ipopt(problem: IKProblem, task: Task, state: BatchState, q_start: Array, options: IKOptions) -> None:
    """The IPOPT reference solver (solver contract: :class:`vgtarm.ik.Solver`)."""
    effort = task.effort is not None
    definition = task.model.definition
    solver = build_ipopt(problem, task.kind, options, definition, effort, task.directions, task.tool, task.cone)
    m, k = task.m, problem.n_triangle
    lbg = np.concatenate([np.zeros(m), np.full(k, problem.margin)])
    ubg = np.concatenate([np.zeros(m), np.full(k, np.inf)])

    def solve_one(problem: IKProblem, task: Task, i: int, q0: Array, options: IKOptions) -> SampleSolution:
        parts = (
            [task.position[i]]
            + ([task.rotation[i]] if task.rotation is not None else [])
            + ([task.effort.force[i], task.effort.scale] if task.effort is not None else [])
            + [task.model.parameter_vector]
        )
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
        return SampleSolution(q, success, int(stats["iter_count"]), str(stats["return_status"]), residual)

    solve_path(problem, task, state, q_start, options, solve_one, METHOD_IPOPT)
