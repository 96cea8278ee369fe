"""Inverse kinematics of a desired tip path: validation, solver dispatch, fallback, rates, records.

:func:`inverse_kinematics` is what :meth:`vgtarm.Robot.inverse_kinematics` calls.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, PathError, UnreachableError
from ..paths import Path
from . import rates as rate_modes
from . import slsqp, verify
from .options import IKOptions
from .pose import HOLD, OrientationTarget, angle_error, orientation_target
from .problem import IKProblem
from .records import IKResult, IKSamples
from .registry import Solver, get_solver
from .robot_protocol import RobotLike
from .state import BatchState
from .tasks import Task

Array = NDArray[np.float64]
FALLBACK = "slsqp (fallback)"
CLOSEST = "closest point (failed)"
#: A target counts as reachable when a feasible pose comes this close to it (m; rad for orientation).
REACH_TOLERANCE = 1e-9


def _check_start(problem: IKProblem, q: Array) -> Array:
    if not problem.assemblable(q, 0.0):
        raise InputError(f"initial_guess {q.tolist()} cannot be assembled (a triangle inequality of the truss fails)")
    return q


def _task(robot: RobotLike, path: Path, target: OrientationTarget | None) -> Task:
    common = (path.t, path.position, path.velocity, path.acceleration)
    if target is None:
        return Task("position", *common, None, None, None, robot.backend, robot.parameter_vector)
    rotation = target.rotation.reshape(-1, 9)
    return Task(
        "pose",
        *common,
        rotation,
        target.angular_velocity,
        target.angular_acceleration,
        robot.backend,
        robot.parameter_vector,
    )


def _start_for(state: BatchState, i: int, q_start: Array) -> Array:
    solved = np.flatnonzero(state.converged)
    if solved.size == 0:
        return q_start
    left = solved[solved < i]
    return np.asarray(state.q[left[-1] if left.size else solved[0]])


def _closest_or_raise(problem: IKProblem, task: Task, i: int, starts: list[Array], options: IKOptions) -> Array:
    """The feasible ``q`` closest to sample ``i``'s target; :class:`UnreachableError` if it misses by more
    than :data:`REACH_TOLERANCE`."""
    q, r = slsqp.closest(problem, task, i, starts, options)
    position = float(np.linalg.norm(r[:3]))
    orientation = float(np.arcsin(min(1.0, float(np.linalg.norm(r[3:]))))) if task.m == 6 else 0.0
    if max(position, orientation) <= REACH_TOLERANCE:
        return q
    x = ", ".join(f"{v:.6g}" for v in task.position[i])
    extra = f" and orientation error {orientation:.3g} rad" if task.m == 6 else ""
    raise UnreachableError(
        f"sample {i} at t = {task.t[i]:.6g} s cannot be reached: target tip point ({x}) m; the smallest position "
        f"residual reached within the joint limits and the assembly margin ({problem.margin:g} m) is "
        f"{position:.3g} m{extra}"
    )


def _recover(problem: IKProblem, task: Task, state: BatchState, q_start: Array, options: IKOptions) -> None:
    """Re-solve unconverged samples with the reference solver (in time order); raise for unreachable ones.

    Each failed sample is re-solved from its nearest solved neighbour, else from the feasible pose
    closest to its target (which may lie on another branch of solutions). A sample that is
    reachable but that no solver could solve keeps that closest pose and stays unconverged (its
    record says it failed).
    """
    failed = np.flatnonzero(~state.converged)
    for i in failed.tolist():
        start = _start_for(state, i, q_start)
        state.method[i] = CLOSEST
        for attempt in range(2):
            if options.fallback:
                solution = slsqp.solve_sample(problem, task, i, start, options)
                state.iterations[i] += solution.iterations
                if solution.success:
                    state.q[i], state.converged[i], state.method[i] = solution.q, True, FALLBACK
                    break
            if attempt == 0:
                # From the closest feasible pose (which may lie on another branch of solutions).
                start = state.q[i] = _closest_or_raise(problem, task, i, [start, q_start], options)
    slsqp.finish(problem, task, state, failed)


def _hold_orientation(
    robot: RobotLike, path: Path, solver: Solver, problem: IKProblem, q_start: Array, options: IKOptions
) -> Array:
    """Orientation ``(3, 3)`` of the free-orientation optimum at the first sample."""
    first = _task(robot, path, None).subset(np.array([0], dtype=np.intp))
    state = BatchState.empty(1, 3, 14 + problem.n_triangle)
    solver(problem, first, state, q_start, options)
    if not state.converged[0]:
        _recover(problem, first, state, q_start, options)
    _, rotation = first.forward(state.q[:1])
    return np.asarray(rotation[0].reshape(3, 3))


def inverse_kinematics(
    robot: RobotLike,
    path: Path,
    *,
    solver: str = "fast",
    rates: str = "exact",
    pose: object = None,
    **options: Any,
) -> IKResult:
    """Joint reference ``q, qd, qdd`` of a desired tip path by redundancy resolution (paper eq. 12).

    For each sample, ``q`` minimises the joint-limit cost ``Phi`` subject to the tip being at the
    desired point (and, with ``pose``, the end-effector at the desired orientation), the joint
    limits and assemblability with a margin.

    Args:
        robot: The robot (its parameters, compiled model and home pose).
        path: The desired tip path (:class:`vgtarm.paths.Path`).
        solver: ``"fast"`` (batched, warm-started trajectory solver), ``"slsqp"`` (per-sample
            reference; alias ``"reference"``) or ``"ipopt"``.
        rates: ``"exact"`` (differentiated optimality conditions) or ``"finite_difference"``
            (central differences of the sampled ``q``, one-sided at the ends; the paper's way).
        pose: ``None`` (free orientation), ``"hold"`` (the orientation of the free-orientation
            optimum at the first sample, held constant), a rotation ``(3, 3)`` or ``(N, 3, 3)``,
            or an :class:`~vgtarm.ik.pose.OrientationPath` with the target's angular velocity
            and acceleration (needed for exact rates of a changing orientation).
        **options: See :class:`~vgtarm.ik.options.IKOptions` (``margin``, ``initial_guess``,
            tolerances, ``fallback``, ...).

    Returns:
        An :class:`IKResult` with ``.q``, ``.qd``, ``.qdd`` ``(N, 7)`` and the per-sample record.

    Raises:
        PathError: ``path`` is not a :class:`vgtarm.paths.Path`.
        InputError: Unknown solver, rate mode or option, or a bad option value or pose.
        UnreachableError: A sample cannot be reached within the limits and the assembly margin;
            the message names its time, the target point and the smallest residual reached.
    """
    started = time.perf_counter()
    if not isinstance(path, Path):
        raise PathError(f"path must be a vgtarm.paths.Path (see vgtarm.paths), got {type(path).__name__}")
    name, solve = get_solver(solver)
    if rates not in rate_modes.RATE_MODES:
        raise InputError(f"unknown rates mode {rates!r}; valid modes are {', '.join(rate_modes.RATE_MODES)}")
    settings = IKOptions.from_keywords(options)
    problem = IKProblem.from_parameters(robot.parameters, settings.margin)
    q_start = _check_start(problem, robot.parameters.home if settings.initial_guess is None else settings.initial_guess)
    n = len(path)
    target = None
    if pose is not None:
        if isinstance(pose, str) and pose == HOLD:
            pose = _hold_orientation(robot, path, solve, problem, q_start, settings)
        elif isinstance(pose, str):
            raise InputError(f"pose must be None, {HOLD!r}, rotation matrices or an OrientationPath, got {pose!r}")
        target = orientation_target(pose, n, rates == "exact")
    task = _task(robot, path, target)
    state = BatchState.empty(n, task.m, 14 + problem.n_triangle)
    solve(problem, task, state, q_start, settings)
    _recover(problem, task, state, q_start, settings)
    if rates == "exact":
        rate_modes.exact(problem, task, state, np.flatnonzero(~state.rates_ready))
        qd, qdd = state.qd, state.qdd
    else:
        qd, qdd = rate_modes.finite_difference(state.q, path.dt)
    check = verify.verify(problem, state, settings.tolerances)
    samples = _samples(problem, task, state, check, target)
    return _result(path, state, qd, qdd, samples, target, problem, name, rates, task.kind, started)


def _samples(
    problem: IKProblem, task: Task, state: BatchState, check: verify.Verification, target: OrientationTarget | None
) -> IKSamples:
    orientation = np.full(len(task), np.nan)
    if target is not None:
        _, rotation = task.forward(state.q)
        orientation = angle_error(rotation.reshape(-1, 3, 3), target.rotation)
    samples = IKSamples(
        success=state.converged & check.passed,
        residual=np.linalg.norm(state.residual[:, :3], axis=1),
        orientation_error=orientation,
        phi=problem.phi(state.q),
        active=state.active.copy(),
        constraint_labels=problem.constraint_labels,
        multipliers=state.lam.copy(),
        inequality_multipliers=state.mu.copy(),
        stationarity=check.stationarity,
        curvature=check.curvature,
        iterations=state.iterations.copy(),
        method=state.method.copy(),
    )
    for value in vars(samples).values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return samples


def _result(
    path: Path,
    state: BatchState,
    qd: Array,
    qdd: Array,
    samples: IKSamples,
    target: OrientationTarget | None,
    problem: IKProblem,
    solver: str,
    rates: str,
    kind: str,
    started: float,
) -> IKResult:
    failed = np.flatnonzero(~samples.success)
    if failed.size:
        i = int(failed[0])
        message = (
            f"{failed.size} of {len(path)} samples failed the optimality check (first: sample {i} at t = "
            f"{path.t[i]:.6g} s, residual {samples.residual[i]:.3g} m, stationarity {samples.stationarity[i]:.3g})"
        )
    else:
        message = f"all {len(path)} samples solved and verified"
    for array in (state.q, qd, qdd):
        array.flags.writeable = False
    return IKResult(
        t=path.t,
        q=state.q,
        qd=qd,
        qdd=qdd,
        position=path.position,
        velocity=path.velocity,
        acceleration=path.acceleration,
        orientation=None if target is None else target.rotation,
        samples=samples,
        solver=solver,
        rates=rates,
        task=kind,
        margin=problem.margin,
        lower=problem.lower,
        upper=problem.upper,
        wall_time=time.perf_counter() - started,
        success=failed.size == 0,
        message=message,
    )
