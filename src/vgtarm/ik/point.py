"""Inverse kinematics of one tip point (optionally one orientation): a toolbox's single-pose IK.

:func:`solve_point` returns a :class:`PointSolution` record: the joint configuration that puts the
tip at the point while minimising the joint-limit cost ``Phi`` of eq. 12 (the same problem as one
sample of a path, solved and verified by the same solvers), its residual, its margins to the joint
limits, ``success`` and ``reason``. An unreachable point is not raised for: the record then holds
the feasible configuration that comes closest, ``success`` False and a one-line ``reason``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import checks
from ..errors import UnreachableError
from ..model.robot import Robot
from ..paths import MAX_COORDINATE, TipPath
from . import reference
from .axis import AxisTarget
from .options import IKOptions
from .pose import OrientationTarget, angle_error, orientation_target
from .problem import IKProblem
from .solve import REACH_TOLERANCE, _Targets, _task, inverse_kinematics

Array = NDArray[np.float64]
#: The time step of the two-sample resting path a point is solved as (s); it does not enter the answer.
_REST_DT = 1.0


@dataclass(frozen=True, eq=False)
class PointSolution:
    """The joint configuration of one tip point.

    Attributes:
        point: ``(3,)`` the target tip point in the base frame (m).
        rotation: ``(3, 3)`` the target orientation ``C03``, or ``None`` (free orientation).
        q: ``(n,)`` joint values (m, rad): the eq. 12 optimum when ``success``, else the feasible
            configuration whose tip comes closest to the point.
        residual: distance of the tip at ``q`` from the point (m).
        orientation_error: angle between the end-effector at ``q`` and ``rotation`` (rad), or
            between the tool's axis and ``axis``; NaN when the orientation is free.
        margins: ``(n, 2)`` distance of each joint to its lower limit (column 0) and to its upper
            limit (column 1), in the joint's unit; both >= 0 within the limits.
        phi: the joint-limit cost ``Phi(q)`` of eq. 12.
        success: the point was reached and the optimality conditions verified.
        status: ``"solved"``, ``"unverified"`` (reached, the optimality conditions not verified)
            or ``"unreachable"`` (``q`` is then the closest feasible configuration).
        message: one line: what was solved, or why not.
        joint_names: the robot's joint names, in the order of ``q``.
        wall_time_s: wall-clock time of the solve (s).
        robot: the :class:`~vgtarm.Robot` it was solved for (None if unknown). Not pickled (a robot
            holds its compiled library): a solution sent to another process keeps ``joint_names``.
        axis: ``(3,)`` the target direction of the tool's axis (axis and entry-point tasks), or None.
        entry_point: ``(3,)`` the entry point the tool's axis passes through (m), or None.
    """

    point: Array
    rotation: Array | None
    q: Array
    residual: float
    orientation_error: float
    margins: Array
    phi: float
    success: bool
    status: str
    message: str
    joint_names: tuple[str, ...]
    wall_time_s: float
    robot: Robot | None = None
    axis: Array | None = None
    entry_point: Array | None = None

    def __getstate__(self) -> dict[str, Any]:
        """The pickled state: everything but :attr:`robot` (its compiled library does not pickle)."""
        return {**self.__dict__, "robot": None}

    @property
    def closest_limit(self) -> tuple[int, str, float]:
        """``(joint index, "min" or "max", distance)`` of the joint nearest to one of its limits."""
        i, side = np.unravel_index(int(np.argmin(self.margins)), self.margins.shape)
        return int(i), ("min", "max")[int(side)], float(self.margins[i, side])


def _as_point(point: object) -> Array:
    p = checks.finite_array("point", point, (3,)).copy()
    if np.abs(p).max() > MAX_COORDINATE:
        checks.refuse("point", p.tolist(), f"coordinates x, y, z within +-{MAX_COORDINATE:g} (m)")
    return p


def _format(p: Array) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"


def solve_point(
    robot: Robot,
    point: object,
    *,
    rotation: object = None,
    axis: object = None,
    entry_point: object = None,
    solver: str = "fast",
    **options: Any,
) -> PointSolution:
    """Joint configuration that puts the tip of ``robot`` at ``point``, by eq. 12's joint-limit criterion.

    Args:
        robot: The robot.
        point: ``(3,)`` the tip point in the base frame (m).
        rotation: ``None`` (free orientation) or the end-effector orientation ``C03`` ``(3, 3)``
            (as ``vgtarm fk`` prints it).
        axis: ``None`` or the direction ``(3,)`` of the tool's axis in the base frame, the spin about
            it free (:mod:`vgtarm.ik.axis`).
        entry_point: ``None`` or a point ``(3,)`` (m) the tool's axis passes through (the axis is
            then the direction from it to ``point``).
        solver: an inverse-kinematics solver name (:func:`vgtarm.ik.solver_names`).
        **options: See :class:`~vgtarm.ik.options.IKOptions` (``margin``, ``initial_guess``, ...).

    Returns:
        A :class:`PointSolution`; an unreachable point gives ``success`` False, the closest
        feasible configuration, ``status`` ``"unreachable"`` and a ``message`` naming the point and
        the smallest residual.

    Raises:
        InputError: a point that is not three finite numbers within 1 km, a rotation that is not
            a rotation matrix, or a bad solver or option (as :func:`inverse_kinematics`).
    """
    started = time.perf_counter()
    p = _as_point(point)
    path = TipPath(
        "point", np.array([0.0, _REST_DT]), np.stack([p, p]), np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3))
    )
    tasks = _Targets(rotation, axis, entry_point)
    target = None if rotation is None else orientation_target(rotation, 2, True)
    pose = None if target is None else target.rotation[0]
    try:
        result = inverse_kinematics(
            robot,
            path,
            solver=solver,
            rates="finite_difference",
            pose=pose,
            axis=axis,
            entry_point=entry_point,
            **options,
        )
    except UnreachableError:
        pointing = tasks.target(path, True)
        return _closest(robot, path, p, target if pointing is None else pointing, options, started)
    q = np.array(result.q[0])
    tip, tip_rotation = robot.tip_position(q), robot.forward_kinematics(q).rotation
    error = float("nan") if pose is None else float(angle_error(tip_rotation[None], pose[None])[0])
    if result.axis is not None:  # the axis and entry-point tasks: the angle their record gives
        error = float(result.samples.orientation_error[0])
    success = bool(result.samples.success[0])
    message = (
        f"point {_format(p)} m reached and the optimality conditions of eq. 12 verified"
        if success
        else f"point {_format(p)} m: {result.message}"
    )
    status = "solved" if success else "unverified"
    solution = _solution(robot, p, pose, q, float(np.linalg.norm(tip - p)), error, status, message, started)
    return _pointing(solution, result.axis, result.entry_point)


def _pointing(solution: PointSolution, axis: Array | None, entry_point: Array | None) -> PointSolution:
    """``solution`` with the axis task's target recorded: its axis ``(N, 3)`` (None: not an axis task)
    and its entry point."""
    if axis is None:
        return solution
    return replace(solution, axis=np.array(axis[0]), entry_point=entry_point)


def _closest(
    robot: Robot, path: TipPath, p: Array, target: Any, options: dict[str, Any], started: float
) -> PointSolution:
    """The record of an unreachable point: the feasible configuration closest to it."""
    settings = IKOptions.from_keywords(options, robot.n_joints)
    problem = IKProblem.from_parameters(robot.parameters, settings.margin, 1.0)
    start = robot.parameters.home if settings.initial_guess is None else settings.initial_guess
    task = _task(robot, path, target)
    q, r = reference.closest(problem, task, 0, [np.asarray(start, dtype=float)], settings)
    residual = float(np.linalg.norm(r[:3]))
    oriented = task.m > 3
    error = float(np.arcsin(min(1.0, float(np.linalg.norm(r[3:]))))) if oriented else float("nan")
    extra = f" and {'axis' if task.kind == 'axis' else 'orientation'} error {error:.3g} rad" if oriented else ""
    message = (
        f"point {_format(p)} m cannot be reached: the closest tip within the joint limits and the assembly margin "
        f"({problem.margin:g} m) is {residual:.3g} m away{extra} (tolerance {REACH_TOLERANCE:g} m)"
    )
    pose = target.rotation[0] if isinstance(target, OrientationTarget) else None
    solution = _solution(robot, p, pose, np.array(q, dtype=float), residual, error, "unreachable", message, started)
    if not isinstance(target, AxisTarget):
        return solution
    return _pointing(solution, target.direction, target.entry_point)


def _solution(
    robot: Robot,
    p: Array,
    pose: Array | None,
    q: Array,
    residual: float,
    error: float,
    status: str,
    message: str,
    started: float,
) -> PointSolution:
    low, high = robot.joint_limits()
    margins = np.stack([q - low, high - q], axis=1)
    phi = float(IKProblem.from_parameters(robot.parameters).phi(q))
    for array in (p, q, margins):
        array.flags.writeable = False
    return PointSolution(
        point=p,
        rotation=pose,
        q=q,
        residual=residual,
        orientation_error=error,
        margins=margins,
        phi=phi,
        success=status == "solved",
        status=status,
        message=message,
        joint_names=robot.joint_names,
        wall_time_s=time.perf_counter() - started,
        robot=robot,
    )
