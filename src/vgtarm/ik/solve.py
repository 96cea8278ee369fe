"""Inverse kinematics of a desired tip path: validation, solver dispatch, fallback, rates, records.

:func:`inverse_kinematics` is what :meth:`vgtarm.Robot.inverse_kinematics` calls.

The solvers by name: a solver is any :class:`Solver`, ``solver(problem, task, q_start, options)``
returning a :class:`SolverResult` (the per-sample state and work counters); the built-in ones fill
a fresh :class:`~vgtarm.ik.problem.BatchState` in place and are wrapped by :func:`in_place`. A
solver never raises for a sample it could not solve: it leaves it unconverged, and
:func:`inverse_kinematics` re-solves it with the reference solver or reports it unreachable.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, PathError, UnreachableError, shown
from ..machine import blas_on_one_thread
from ..memory import check_memory
from ..model.robot import Robot
from ..paths import MAX_COORDINATE, TipPath
from . import fast, kkt, reference
from . import rates as rate_modes
from .axis import (
    AXIS_FIRST,
    AxisTarget,
    axis_error,
    axis_target,
    cone_angle,
    entry_distance,
    entry_point_target,
    tool_axes,
)
from .cone import within_cone
from .effort import EffortTerms, effort_terms
from .options import IKOptions, default_coarse_step
from .pose import HOLD, OrientationTarget, angle_error, orientation_target
from .problem import BatchState, IKProblem, Task
from .records import IKResult, IKSamples
from .taskspace import TaskSpace, task_space

Array = NDArray[np.float64]
FALLBACK = "slsqp (fallback)"
CLOSEST = "closest point (failed)"
#: A target counts as reachable when a feasible pose comes this close to it (m; rad for orientation).
REACH_TOLERANCE = 1e-9
#: Peak memory of the inverse kinematics per path sample (bytes), tip position only and with the
#: orientation: the measured peak (2.4 kB and 3.1 kB a sample for 50,000 to 200,000 samples of the
#: fast solver) with a quarter more for safety.
BYTES_PER_SAMPLE = 3_000
BYTES_PER_SAMPLE_POSE = 4_000


def memory_estimate(n_samples: int, pose: bool = False) -> int:
    """Bytes the inverse kinematics of a path of ``n_samples`` samples needs at its peak (about)."""
    return int(n_samples) * (BYTES_PER_SAMPLE_POSE if pose else BYTES_PER_SAMPLE)


def _check_start(robot: Robot, problem: IKProblem, q: Array) -> Array:
    if not robot.in_joint_range(q):
        low, high = robot.joint_range()
        raise InputError(
            f"initial_guess {shown(q.tolist())} is outside the accepted joint range "
            f"(from {shown(low.round(6).tolist())} to {shown(high.round(6).tolist())})"
        )
    if not problem.assemblable(q, 0.0):
        raise InputError(f"initial_guess {q.tolist()} cannot be assembled (a triangle inequality of the truss fails)")
    return q


def _task(
    robot: Robot,
    path: TipPath,
    target: OrientationTarget | AxisTarget | None,
    effort: EffortTerms | None = None,
    space: TaskSpace | None = None,
) -> Task:
    common = (path.t, path.position, path.velocity, path.acceleration)
    if target is None:
        directions = None if space is None else space.directions
        return Task("position", *common, None, None, None, robot, effort=effort, directions=directions)
    if isinstance(target, AxisTarget):
        frames = target.frame if target.cone is None else target.frame @ AXIS_FIRST
        motion = (target.angular_velocity, target.angular_acceleration)
        tool = np.asarray(robot.tool_rotation, dtype=float)
        return Task("axis", *common, frames.reshape(-1, 9), *motion, robot, tool=tool, cone=target.cone)
    rotation = target.rotation.reshape(-1, 9)
    return Task(
        "pose",
        *common,
        rotation,
        target.angular_velocity,
        target.angular_acceleration,
        robot,
    )


def _start_for(state: BatchState, i: int, q_start: Array) -> Array:
    solved = np.flatnonzero(state.converged)
    if solved.size == 0:
        return q_start
    left = solved[solved < i]
    return np.asarray(state.q[left[-1] if left.size else solved[0]])


def _closest(
    problem: IKProblem, task: Task, i: int, starts: list[Array], options: IKOptions
) -> tuple[Array, str | None]:
    """The feasible ``q`` closest to sample ``i``'s target, and None, or why the sample cannot be reached
    (it misses by more than :data:`REACH_TOLERANCE`)."""
    q, r = reference.closest(problem, task, i, starts, options)
    position = float(np.linalg.norm(r[:3]))
    oriented = task.m > 3  # the pose (6 rows) and axis (5) tasks: their rows past the tip are sin(angle)
    orientation = float(np.arcsin(min(1.0, float(np.linalg.norm(r[3:]))))) if oriented else 0.0
    if max(position, orientation) <= REACH_TOLERANCE:
        return q, None
    x = ", ".join(f"{v:.6g}" for v in task.position[i])
    what = "axis" if task.kind == "axis" else "orientation"
    extra = f" and {what} error {orientation:.3g} rad" if oriented else ""
    return q, (
        f"sample {i} at t = {task.t[i]:.6g} s cannot be reached: target tip point ({x}) m; the smallest position "
        f"residual reached within the joint limits and the assembly margin ({problem.margin:g} m) is "
        f"{position:.3g} m{extra}"
    )


@dataclass(frozen=True)
class _Cut:
    """Where a solve with ``check=False`` stops: the first unreachable sample, and why."""

    sample: int
    message: str


def _recover(
    problem: IKProblem, task: Task, state: BatchState, q_start: Array, options: IKOptions, check: bool = True
) -> _Cut | None:
    """Re-solve unconverged samples with the reference solver (in time order); raise for the first
    unreachable one (with ``check``), or stop there and return it.

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
                solution = reference.solve_sample(problem, task, i, start, options)
                state.iterations[i] += solution.iterations
                if solution.success:
                    state.q[i], state.converged[i], state.method[i] = solution.q, True, FALLBACK
                    break
            if attempt == 0:
                # From the closest feasible pose (which may lie on another branch of solutions).
                q, unreachable = _closest(problem, task, i, [start, q_start], options)
                if unreachable is not None:
                    if check:
                        raise UnreachableError(unreachable)
                    return _Cut(i, unreachable)  # the state is left as it is: the caller solves again
                start = state.q[i] = q
    reference.finish(problem, task, state, failed)
    return None


def _hold_orientation(
    robot: Robot, path: TipPath, solver: Solver, problem: IKProblem, q_start: Array, options: IKOptions, check: bool
) -> Array | _Cut:
    """Orientation ``(3, 3)`` of the free-orientation optimum at the first sample (without ``check``,
    the cut at sample 0 when it cannot be reached)."""
    first = _task(robot, path, None).subset(np.array([0], dtype=np.intp))
    state = _checked(solver(problem, first, q_start, options), first).state
    if not state.converged[0]:
        cut = _recover(problem, first, state, q_start, options, check)
        if cut is not None:
            return cut
    _, rotation = first.forward(state.q[:1])
    return np.asarray(rotation[0].reshape(3, 3))


def inverse_kinematics(
    robot: Robot,
    path: TipPath,
    *,
    solver: str = "fast",
    rates: str = "exact",
    pose: object = None,
    axis: object = None,
    entry_point: object = None,
    cone: object = None,
    check: bool = True,
    **options: Any,
) -> IKResult:
    """Joint reference ``q, qd, qdd`` of a desired tip path by redundancy resolution (paper eq. 12).

    For each sample, ``q`` minimises the joint-limit cost ``Phi`` subject to the tip being at the
    desired point (and, with ``pose``, the end-effector at the desired orientation), the joint
    limits and assemblability with a margin.

    Args:
        robot: The robot (its parameters, compiled model and home pose).
        path: The desired tip path (:class:`vgtarm.paths.TipPath`).
        solver: ``"fast"`` (batched, warm-started trajectory solver), ``"slsqp"`` (per-sample
            reference; alias ``"reference"``) or ``"ipopt"``.
        rates: ``"exact"`` (differentiated optimality conditions) or ``"finite_difference"``
            (central differences of the sampled ``q``, one-sided at the ends; the paper's way).
        pose: ``None`` (free orientation), ``"hold"`` (the orientation of the free-orientation
            optimum at the first sample, held constant), a rotation ``(3, 3)`` or ``(N, 3, 3)``,
            or an :class:`~vgtarm.ik.pose.OrientationPath` with the target's angular velocity
            and acceleration (needed for exact rates of a changing orientation).
        axis: the tool's axis (``robot.tool_rotation``'s third column, in the end-effector frame)
            along a direction in F0, the spin about it free (:mod:`vgtarm.ik.axis`): a unit vector
            ``(3,)`` (held), one per sample ``(N, 3)``, or an :class:`~vgtarm.ik.axis.AxisPath`
            with its rate and acceleration (needed for exact rates of a changing axis).
        entry_point: a point ``(3,)`` (m) the tool's axis passes through while the tip follows the
            path (a remote centre of motion): the axis task of the direction from it to the tip.
        cone: with ``axis``, the half-angle (rad, in (0, pi/2)) of a cone about it that the tool's
            axis must stay within, the spin free (an inequality, :mod:`vgtarm.ik.cone`).
        check: raise :class:`UnreachableError` for a sample out of reach (the default). With False
            the result is returned instead: ``success`` False, ``status`` ``"unreachable"``, its
            ``message`` naming the first sample out of reach (in time order), its rows before that
            sample solved and its rows from it on NaN (as :func:`vgtarm.simulate` returns a failed
            run; :attr:`IKResult.completed` counts the rows solved). What "before" means: the
            solve is not a march along the path that could stop at the failure, but a batched one
            of the whole path, coarse to fine, whose values at a sample depend in their last bits
            on the samples after it. So the samples before the first one out of reach are solved
            again as a path of their own: those rows are bit for bit what ``check=True`` returns
            for that reachable prefix (``samples`` included), whatever follows it; ``work`` and
            ``wall_time_s`` count both solves. With ``rates="finite_difference"`` the last solved
            sample takes the one-sided difference, as at the end of any path (a single solved
            sample has NaN rates).
        **options: See :class:`~vgtarm.ik.options.IKOptions` (``margin``, ``initial_guess``,
            tolerances, ``fallback``, ...).

    Returns:
        An :class:`IKResult` with ``.q``, ``.qd``, ``.qdd`` ``(N, n)`` and the per-sample record;
        it holds the ``robot`` and the ``path`` it was solved for.

    Raises:
        PathError: ``path`` is not a :class:`vgtarm.paths.TipPath`, or has a point farther than
            :data:`vgtarm.paths.MAX_COORDINATE` (1 km) from the base.
        InputError: Unknown solver, rate mode or option, or a bad option value or pose; an
            ``initial_guess`` outside :meth:`vgtarm.Robot.joint_range`; ``robot`` not a Robot;
            ``check`` not True or False.
        UnreachableError: A sample cannot be reached within the limits and the assembly margin
            (with ``check``); the message names its time, the target point and the smallest
            residual reached.

    A result whose joint rates or accelerations are not finite (rows far too close in time)
    has ``success`` False and says so in ``message``.
    """
    # NumPy's BLAS on one thread, as in vgtarm.simulate: the batched solves of a long arm (matrices of
    # a hundred-odd rows, one LAPACK call each) are too small for threads to pay, and OpenBLAS's
    # threads then spin on the cores the work needs: the 50-module arm's case 1 took 421 s wall
    # (235 s CPU) on the 2 shared cores with them, 45 s wall (30 s CPU) without them
    with blas_on_one_thread():
        tasks = _Targets(pose, axis, entry_point)
        if cone is not None:
            return _within_cone(robot, path, tasks, cone, solver=solver, rates=rates, check=check, **options)
        return _inverse_kinematics(robot, path, solver=solver, rates=rates, tasks=tasks, check=check, **options)


def _within_cone(
    robot: Robot, path: TipPath, tasks: _Targets, cone: object, *, solver: str, rates: str, check: bool, **options: Any
) -> IKResult:
    """:func:`inverse_kinematics` with the tool's axis within a cone (:func:`vgtarm.ik.cone.within_cone`)."""
    half_angle = cone_angle(cone)
    if tasks.axis is None or tasks.given != ["axis"]:
        raise InputError(f"cone = {shown(cone)}: a cone needs its axis (axis=...) and neither pose nor entry_point")
    if options.get("criterion") == "effort":  # measured: on case 1 the boundary's multiplier turns, and the
        # released optimum leaves the cone again on 1,674 of 6,284 samples; not offered until that is solved
        raise InputError(f"cone = {shown(cone)}: the effort criterion is not supported within a cone; use axis alone")
    _check_call(robot, path, check)

    def solve(piece: TipPath, extra: dict[str, Any], start: Array | None) -> IKResult:
        settings = options if start is None else {**options, "initial_guess": start}
        task = _Targets(**extra)
        return _inverse_kinematics(robot, piece, solver=solver, rates=rates, tasks=task, check=check, **settings)

    return within_cone(robot, path, tasks.axis, half_angle, rates == "exact", solve)


@dataclass(frozen=True)
class _Targets:
    """The orientation part of the task as the user gave it: ``pose``, ``axis`` or ``entry_point`` (at
    most one), each None when not given."""

    pose: object = None
    axis: object = None
    entry_point: object = None
    #: ``cos`` of the half-angle of a cone whose boundary the axis is held on (:mod:`.cone`), or None.
    boundary: float | None = None

    def __post_init__(self) -> None:
        given = self.given
        if len(given) > 1:
            raise InputError(
                f"{' and '.join(given)} were both given: expected one of pose, axis and entry_point (an entry point "
                "sets the axis, from it to the tip)"
            )

    @property
    def given(self) -> list[str]:
        """The names of the arguments given."""
        return [name for name in ("pose", "axis", "entry_point") if getattr(self, name) is not None]

    @property
    def kind(self) -> str:
        """The task: ``"position"``, ``"pose"``, ``"axis"`` or ``"entry point"``."""
        given = self.given
        return given[0].replace("_", " ") if given else "position"

    def target(self, path: TipPath, exact: bool) -> AxisTarget | None:
        """The axis target of an axis or entry-point task (None for the others)."""
        if self.axis is not None:
            target = axis_target(self.axis, len(path), exact)
            return target if self.boundary is None else replace(target, cone=self.boundary)
        if self.entry_point is not None:
            return entry_point_target(self.entry_point, path.position, path.velocity, path.acceleration)
        return None


def _inverse_kinematics(
    robot: Robot, path: TipPath, *, solver: str, rates: str, tasks: _Targets, check: bool, **options: Any
) -> IKResult:
    """:func:`inverse_kinematics` (its BLAS limited to one thread)."""
    started = time.perf_counter()
    _check_call(robot, path, check)
    name, solve = get_solver(solver)
    if rates not in rate_modes.RATE_MODES:
        raise InputError(f"unknown rates mode {rates!r}; valid modes are {', '.join(rate_modes.RATE_MODES)}")
    settings = IKOptions.from_keywords(options, robot.n_joints)
    if settings.coarse_step is None:
        reach = float(np.linalg.norm(robot.tip_position(robot.parameters.home)))
        settings = replace(settings, coarse_step=default_coarse_step(reach))
    effort = settings.criterion == "effort"
    pose = tasks.pose
    if effort and tasks.pose is not None:
        raise InputError("criterion='effort' supports the tip, axis and entry-point tasks, not the full pose")
    problem = IKProblem.from_parameters(
        robot.parameters, settings.margin, settings.joint_limit_weight if effort else 1.0
    )
    q_start = _check_start(
        robot, problem, robot.parameters.home if settings.initial_guess is None else settings.initial_guess
    )
    space, cut = None, None
    if robot.is_stack and np.linalg.matrix_rank(robot.tip_jacobian(q_start), tol=1e-9) < 3:
        space, cut = _reduced_task(robot, path, q_start, tasks.kind, check)
    n = len(path)
    check_memory(
        memory_estimate(n, bool(tasks.given)),
        f"path {shown(path.name)}: {n:,} samples of inverse kinematics",
        "give a larger dt or a shorter path",
    )
    kind = tasks.kind
    target: OrientationTarget | AxisTarget | None = tasks.target(path, rates == "exact")
    if target is None:
        target, cut = _pose_target(robot, path, pose, rates, (solve, problem, q_start, settings), check, cut)
    terms = effort_terms(robot, path, settings.tool_force, settings.tool_force_speed) if effort else None
    whole = _task(robot, path, target, terms, space)
    task = whole if cut is None else whole.subset(np.arange(cut.sample, dtype=np.intp))
    work: dict[str, float] = {}
    while True:
        solved = _solve(solve, problem, task, q_start, settings)
        work = {key: work.get(key, 0) + value for key, value in solved.counters.items()}
        state = solved.state
        found = _recover(problem, task, state, q_start, settings, check)
        if found is None:
            break
        # check=False and a sample out of reach: the samples before it are solved again, alone (the
        # values of a batched solve of the whole path also depend, in their last bits, on what follows)
        cut, task = found, whole.subset(np.arange(found.sample, dtype=np.intp))
    solved_target = target  # the samples solved: before the cut
    if cut is not None and isinstance(target, AxisTarget):
        solved_target = target.subset(cut.sample)
    elif cut is not None and isinstance(target, OrientationTarget):
        solved_target = replace(target, rotation=target.rotation[: cut.sample])
    qd, qdd = _rates(problem, task, state, rates, path.dt)
    verification = kkt.verify(problem, state, settings.tolerances)
    samples = _samples(problem, task, state, verification, solved_target)
    q = state.q
    if cut is not None:
        q, qd, qdd, samples = _cut_at(cut, n, q, qd, qdd, samples)
    result = _result(path, q, qd, qdd, samples, target, problem, name, rates, kind, started)
    if cut is not None:
        result = replace(result, success=False, status="unreachable", message=cut.message)
    return replace(
        result,
        task_space=TASK_FULL[kind] if space is None else space.label,
        work=work,
        robot_name=robot.parameters.name,
        robot_fingerprint=robot.fingerprint,
        joint_names=robot.joint_names,
        path_name=path.name,
        robot=robot,
        path=path,
    )


#: :attr:`IKResult.task_space` of the full tasks.
TASK_FULL = MappingProxyType(
    {
        "position": "tip (u1, u2, u3)",
        "pose": "tip (u1, u2, u3) and orientation",
        "axis": "tip (u1, u2, u3) and tool axis",
        "entry point": "tip (u1, u2, u3) and tool axis through the entry point",
    }
)


def _check_call(robot: object, path: object, check: object) -> None:
    """Refuse, in one line, a call of :func:`inverse_kinematics` whose robot, path or ``check`` is
    not one, or whose path holds a point no arm reaches (the continuation towards it would never end)."""
    if not isinstance(check, bool):
        raise InputError(f"check = {shown(check)}: expected True or False")
    if not isinstance(path, TipPath):
        raise PathError(f"path must be a vgtarm.paths.TipPath (see vgtarm.paths), got {type(path).__name__}")
    if not isinstance(robot, Robot):
        raise InputError(f"robot must be a vgtarm.Robot (see vgtarm.load_robot), got {type(robot).__name__}")
    far = np.flatnonzero(np.abs(path.position).max(axis=1) > MAX_COORDINATE)
    if far.size:
        i = int(far[0])
        raise PathError(
            f"path {shown(path.name)}: sample {i} (t = {path.t[i]:.6g} s) is at {shown(path.position[i].tolist())} m;"
            f" expected coordinates within +-{MAX_COORDINATE:g} m"
        )


def _pose_target(
    robot: Robot,
    path: TipPath,
    pose: object,
    rates: str,
    solving: tuple[Solver, IKProblem, Array, IKOptions],
    check: bool,
    cut: Any,
) -> tuple[OrientationTarget | None, Any]:
    """The desired orientation of ``pose`` (None: the tip position only) and the cut of an
    unreachable path: ``pose="hold"`` whose first sample is out of reach (``check=False``) solves
    nothing and desires no orientation. ``solving``: ``(solve, problem, q_start, settings)``."""
    if pose is None:
        return None, cut
    unknown = False
    if isinstance(pose, str) and pose == HOLD:
        held = _hold_orientation(robot, path, *solving, check)
        if isinstance(held, _Cut):
            cut, pose, unknown = held, np.eye(3), True  # nothing is solved: the identity only stands in
        else:
            pose = held
    elif isinstance(pose, str):
        raise InputError(f"pose must be None, {HOLD!r}, rotation matrices or an OrientationPath, got {pose!r}")
    target = orientation_target(pose, len(path), rates == "exact")
    if unknown:  # nothing is solved, and no orientation is desired
        target = replace(target, rotation=np.full_like(target.rotation, np.nan))
    return target, cut


def _rates(problem: IKProblem, task: Task, state: BatchState, rates: str, dt: float) -> tuple[Array, Array]:
    """The joint rates of the solved samples: exact, or finite differences (NaN for a single sample
    solved before an unreachable one)."""
    if rates == "exact":
        rate_modes.exact(problem, task, state, np.flatnonzero(~state.rates_ready))
        return state.qd, state.qdd
    if len(state.q) >= 2:
        return rate_modes.finite_difference(state.q, dt)
    return np.full_like(state.q, np.nan), np.full_like(state.q, np.nan)


def _solve(solve: Solver, problem: IKProblem, task: Task, q_start: Array, settings: IKOptions) -> SolverResult:
    """``solve`` of ``task``, checked; a task of no samples (the first is out of reach) is not solved."""
    if len(task):
        return _checked(solve(problem, task, q_start, settings), task)
    n_inequalities = 2 * problem.n + problem.n_triangle
    state = BatchState.empty(0, task.m, n_inequalities, problem.n, task.effort is not None)
    return SolverResult(state=state, n_iterations=0, n_evaluations=0, n_converged=0, wall_time_s=0.0)


#: :attr:`IKSamples.method` of the unreachable sample where a solve with ``check=False`` stops, and of the
#: samples after it.
UNREACHABLE, NOT_SOLVED = "unreachable", "not solved"


def _cut_at(
    cut: _Cut, n: int, q: Array, qd: Array, qdd: Array, samples: IKSamples
) -> tuple[Array, Array, Array, IKSamples]:
    """The arrays of the samples before ``cut`` grown to the path's ``n`` rows: NaN after them (False,
    0 or :data:`NOT_SOLVED`); the method of the unreachable sample is :data:`UNREACHABLE`."""

    def grown(values: NDArray[Any], fill: object) -> NDArray[Any]:
        out = np.full((n, *values.shape[1:]), fill, dtype=values.dtype)
        out[: len(values)] = values
        out.flags.writeable = False
        return out

    fills = {"success": False, "active": False, "iterations": 0, "method": NOT_SOLVED}
    grown_samples: dict[str, Any] = {
        key: grown(value, fills.get(key, np.nan)) if isinstance(value, np.ndarray) else value
        for key, value in vars(samples).items()
    }
    method = grown_samples["method"]
    method.flags.writeable = True
    method[cut.sample] = UNREACHABLE
    method.flags.writeable = False
    return grown(q, np.nan), grown(qd, np.nan), grown(qdd, np.nan), IKSamples(**grown_samples)


def reduced_task(robot: Robot, path: TipPath, q_start: Array, pose: object = None) -> TaskSpace:
    """The plane or line of a robot whose tip Jacobian at ``q_start`` has rank < 3 (:mod:`.taskspace`),
    checked against the path: a point off it (by more than :data:`REACH_TOLERANCE`) cannot be reached
    (:class:`UnreachableError`, naming the farthest; :func:`vgtarm.ik.solve_point` then gives the
    closest configuration)."""
    space, _ = _reduced_task(robot, path, q_start, "position" if pose is None else "pose", True)
    return space


def _reduced_task(robot: Robot, path: TipPath, q_start: Array, kind: str, check: bool) -> tuple[TaskSpace, _Cut | None]:
    """:func:`reduced_task`; without ``check``, the first point off the plane or line is returned as the
    cut instead of raised for."""
    space = task_space(robot, q_start)
    name = shown(robot.parameters.name)
    if space is None:  # rank 3 elsewhere: task_space raised for the singular start; defensive
        raise InputError(f"robot {name}: the start pose is singular; start from another pose (initial_guess)")
    if kind != "position":
        given = kind.replace(" ", "_")
        raise InputError(
            f"robot {name}: its tip moves in a {'plane' if space.rank == 2 else 'line'} (task: {space.label}); "
            f"{'an' if kind[0] in 'aeiou' else 'a'} {kind} target needs a tip that moves in three directions: leave "
            f"{given} out"
        )
    off = space.distance(path.position)
    outside = np.flatnonzero(off > REACH_TOLERANCE)
    if not outside.size:
        return space, None
    i = int(np.argmax(off)) if check else int(outside[0])  # with check: the farthest, as ever; else the first
    where = "plane" if space.rank == 2 else "line"
    message = (
        f"path {shown(path.name)}: sample {i} (t = {path.t[i]:.6g} s) at "
        f"{shown(np.round(path.position[i], 12).tolist())} m is {off[i]:.3g} m off the {where} the tip of "
        f"robot {name} moves in (task: {space.label}, through {shown(np.round(space.origin, 12).tolist())} m); "
        f"expected every point in that {where} (the case paths are placed there)"
    )
    if check:
        raise UnreachableError(message)
    return space, _Cut(i, message)


def _checked(result: object, task: Task) -> SolverResult:
    """The solver's result, checked against the interface (a user's solver may get it wrong)."""
    if not isinstance(result, SolverResult):
        raise InputError(f"an inverse-kinematics solver must return a SolverResult, got {type(result).__name__}")
    n_joints = task.model.n_joints
    if result.state.q.shape != (len(task), n_joints):
        raise InputError(f"the solver returned q of shape {result.state.q.shape}, expected ({len(task)}, {n_joints})")
    return result


def _orientation_errors(
    task: Task, state: BatchState, target: OrientationTarget | AxisTarget | None
) -> tuple[Array, Array | None, NDArray[np.bool_]]:
    """The angle errors ``(N,)`` of the samples (NaN without an orientation target), the entry point's
    distance from the tool axis ``(N,)`` (entry-point task, else None) and which samples point their
    axis along the target, not against it (the axis rows also vanish at ``a = -d``)."""
    n = len(task)
    if target is None:
        return np.full(n, np.nan), None, np.ones(n, dtype=bool)
    tip, rotation = task.forward(state.q)
    if isinstance(target, OrientationTarget):
        return angle_error(rotation.reshape(-1, 3, 3), target.rotation), None, np.ones(n, dtype=bool)
    assert task.tool is not None
    axes = tool_axes(rotation.reshape(-1, 3, 3), task.tool)
    error = axis_error(axes, target.direction)
    entry = None if target.entry_point is None else entry_distance(tip, axes, target.entry_point)
    return error, entry, np.asarray(error < 0.5 * np.pi)


def _samples(
    problem: IKProblem,
    task: Task,
    state: BatchState,
    check: kkt.Verification,
    target: OrientationTarget | AxisTarget | None,
) -> IKSamples:
    orientation, entry, along = _orientation_errors(task, state, target)
    samples = IKSamples(
        success=state.converged & check.passed & along,
        residual=np.linalg.norm(state.residual[:, :3], axis=1),
        orientation_error=orientation,
        phi=problem.phi(state.q) + task.effort_cost(np.arange(len(task), dtype=np.intp), state.q),
        active=state.active.copy(),
        constraint_labels=problem.constraint_labels,
        multipliers=state.lam.copy(),
        inequality_multipliers=state.mu.copy(),
        stationarity=check.stationarity,
        curvature=check.curvature,
        iterations=state.iterations.copy(),
        method=state.method.copy(),
        entry_distance=entry,
    )
    for value in vars(samples).values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return samples


def _result(
    path: TipPath,
    q: Array,
    qd: Array,
    qdd: Array,
    samples: IKSamples,
    target: OrientationTarget | AxisTarget | None,
    problem: IKProblem,
    solver: str,
    rates: str,
    kind: str,
    started: float,
) -> IKResult:
    failed = np.flatnonzero(~samples.success)
    unbounded = np.flatnonzero(~(np.isfinite(qd).all(axis=1) & np.isfinite(qdd).all(axis=1)))
    if failed.size:
        i = int(failed[0])
        message = (
            f"{failed.size} of {len(path)} samples failed the optimality check (first: sample {i} at t = "
            f"{path.t[i]:.6g} s, residual {samples.residual[i]:.3g} m, stationarity {samples.stationarity[i]:.3g})"
        )
    elif unbounded.size:  # solved points whose rates overflowed: not a usable reference
        i = int(unbounded[0])
        message = (
            f"{unbounded.size} of {len(path)} samples have joint rates or accelerations that are not finite "
            f"(first: sample {i} at t = {path.t[i]:.6g} s; dt = {path.dt:g} s)"
        )
    else:
        message = f"all {len(path)} samples solved and verified"
    for array in (q, qd, qdd):
        array.flags.writeable = False
    return IKResult(
        t=path.t,
        q=q,
        qd=qd,
        qdd=qdd,
        position=path.position,
        velocity=path.velocity,
        acceleration=path.acceleration,
        orientation=target.rotation if isinstance(target, OrientationTarget) else None,
        axis=target.direction if isinstance(target, AxisTarget) else None,
        entry_point=target.entry_point if isinstance(target, AxisTarget) else None,
        samples=samples,
        solver=solver,
        rates=rates,
        task=kind,
        margin=problem.margin,
        lower=problem.lower,
        upper=problem.upper,
        wall_time_s=time.perf_counter() - started,
        success=failed.size == 0 and unbounded.size == 0,
        message=message,
    )


@dataclass(frozen=True)
class SolverResult:
    """What an inverse-kinematics solver returns for a batch of samples (the solver interface).

    Attributes:
        state: the per-sample arrays (:class:`~vgtarm.ik.problem.BatchState`): ``q`` for every
            sample and, where the solver succeeded, ``converged = True``, the multipliers, the
            active set and the model values at ``q``; ``iterations`` and ``method`` per sample.
        n_iterations: iterations (Newton steps, or the reference solver's) over all samples.
        n_evaluations: samples evaluated through the compiled task functions, over all calls.
        n_converged: samples the solver solved.
        wall_time_s: the solver's wall time.
    """

    state: BatchState
    n_iterations: int
    n_evaluations: int
    n_converged: int
    wall_time_s: float

    @property
    def counters(self) -> dict[str, float]:
        """The work counters by name (as recorded in :attr:`IKResult.work`)."""
        return {
            "n_iterations": self.n_iterations,
            "n_evaluations": self.n_evaluations,
            "n_converged": self.n_converged,
            "wall_time_s": self.wall_time_s,
        }


class Solver(Protocol):
    """An inverse-kinematics solver: ``solver(problem, task, q_start, options) -> SolverResult``.

    The contract, for a solver of one's own (register it with :func:`register_solver`):

    - ``problem`` (:class:`~vgtarm.ik.problem.IKProblem`) gives the cost ``Phi``, the bounds and
      the linear assembly margins; ``task`` (:class:`~vgtarm.ik.problem.Task`) the targets of every
      sample and the compiled residual, Jacobian and Hessian (``task.evaluate``); ``q_start``
      ``(n,)`` the start of the first sample; ``options`` the :class:`~vgtarm.ik.options.IKOptions`.
    - Return a :class:`SolverResult` whose ``state`` has a row per sample. A sample the solver
      could not solve is left with ``converged = False``, never raised for: the caller re-solves it
      with the reference solver or reports it unreachable, and verifies every sample's optimality
      conditions itself, whatever the solver says.
    """

    def __call__(self, problem: IKProblem, task: Task, q_start: Array, options: IKOptions) -> SolverResult: ...


InPlace = Callable[[IKProblem, Task, BatchState, Array, IKOptions], None]


def in_place(step: InPlace) -> Solver:
    """A :class:`Solver` from a function that fills a fresh :class:`BatchState` in place."""

    def solver(problem: IKProblem, task: Task, q_start: Array, options: IKOptions) -> SolverResult:
        started, evaluations = time.perf_counter(), task.evaluations[0]
        n_inequalities = 2 * problem.n + problem.n_triangle
        state = BatchState.empty(len(task), task.m, n_inequalities, problem.n, task.effort is not None)
        step(problem, task, state, q_start, options)
        return SolverResult(
            state=state,
            n_iterations=int(state.iterations.sum()),
            n_evaluations=task.evaluations[0] - evaluations,
            n_converged=int(state.converged.sum()),
            wall_time_s=time.perf_counter() - started,
        )

    solver.__doc__ = step.__doc__
    return solver


def _fast(problem: IKProblem, task: Task, state: BatchState, q_start: Array, options: IKOptions) -> None:
    """The batched, warm-started trajectory solver (:mod:`vgtarm.ik.fast`)."""
    fast.solve(problem, task, state, q_start, options.fast)


_REGISTRY: dict[str, Solver] = {
    "fast": in_place(_fast),
    "slsqp": in_place(reference.solve_slsqp),
    "ipopt": in_place(reference.solve_ipopt),
}
#: Solvers by name (a read-only view; :func:`register_solver` adds to it).
SOLVERS: MappingProxyType[str, Solver] = MappingProxyType(_REGISTRY)
#: Other names of solvers.
ALIASES: MappingProxyType[str, str] = MappingProxyType({"reference": "slsqp"})
_BUILT_IN = frozenset(_REGISTRY) | frozenset(ALIASES)


def register_solver(name: str, solver: Solver, *, replace: bool = False) -> None:
    """Make ``solver`` (see :class:`Solver`) available as ``inverse_kinematics(..., solver=name)``.

    A built-in name cannot be taken; another registered name only with ``replace=True``.
    """
    if not isinstance(name, str) or not name.isidentifier():
        raise InputError(f"solver name {name!r}: expected a name like 'my_solver'")
    if not callable(solver):
        raise InputError(f"solver {name!r}: expected a callable (problem, task, q_start, options) -> SolverResult")
    if name in _BUILT_IN or (name in _REGISTRY and not replace):
        raise InputError(f"solver name {name!r} is taken; choose another name (or replace=True for your own)")
    _REGISTRY[name] = solver


def unregister_solver(name: str) -> None:
    """Remove a solver registered with :func:`register_solver` (built-in solvers stay)."""
    if name in _BUILT_IN or name not in _REGISTRY:
        raise InputError(f"solver name {name!r}: not a registered solver of one's own")
    del _REGISTRY[name]


def solver_names() -> list[str]:
    """Every accepted name, sorted."""
    return sorted([*SOLVERS, *ALIASES])


def get_solver(name: object) -> tuple[str, Solver]:
    """The canonical name and the solver of ``name``.

    An unknown name raises :class:`InputError` listing the valid ones.
    """
    key = ALIASES.get(name, name) if isinstance(name, str) else None
    if key is None or key not in SOLVERS:
        raise InputError(f"unknown inverse-kinematics solver {name!r}; valid solvers are {', '.join(solver_names())}")
    return key, SOLVERS[key]
