"""Robotics Toolbox's Levenberg-Marquardt IK on a vgtarm robot: the anchor of the tool-axis IK (issue 36, item 5).

Robotics Toolbox for Python (Corke; ``roboticstoolbox-python``, the ``bench`` extra) solves a
*masked* pose: the tip at a point and the tool frame at a rotation, each of the six error
components weighted by a mask. Its Python solver classes (``roboticstoolbox.IK_LM``, the
``IKSolver`` family of ``roboticstoolbox/robot/IK.py``) use nothing of a robot but ``ets.eval(q)``
(the 4x4 pose), ``ets.jacob0(q)`` (the ``6 x n`` base-frame Jacobian, linear rows first),
``ets.n``, ``ets.qlim``, ``ets.jindices`` and ``ets.joints()``, so :class:`VgtEts` gives them a
vgtarm robot, a closed-chain truss that no ETS chain can describe, through vgtarm's own forward
kinematics and Jacobians. (The C++ ``ikine_LM`` of an ``ERobot`` walks a real ETS and cannot.)

The task is vgtarm's 5-D tool-axis task (``solve_point(robot, point, axis=d)``) for a **vertical**
axis ``d = (0, 0, 1)`` only: RTB's mask weighs the components of the angle-axis error
``log(R_target R^T)`` **in the base frame**, so ``mask = [1, 1, 1, 1, 1, 0]`` frees the rotation
about the base ``z`` axis, which is the spin about the tool's axis only when that axis is the base
``z`` axis. (Masked error zero means ``R_target R^T`` is a rotation about ``z``, so the tool's axis
is ``R_target``'s ``z`` column, vertical.) The target rotation's spin is that of the start ``q0``
(its tool ``x`` projected onto the horizontal plane), which keeps the unweighted spin error away
from the half-turn where the angle-axis error is singular.

RTB knows joint limits (``joint_limits=True`` rejects a converged ``q`` outside ``qlim`` and
restarts from a random ``q`` within them, drawn from the solver's seeded generator) but not
vgtarm's assembly condition (each module's triangle inequalities, ``robot.is_assemblable``). A step
can leave the assemblable set, where vgtarm's forward kinematics raises ``AssemblyError`` (or
jump so far that vgtarm refuses ``q`` with ``InputError``: not a configuration of the robot). RTB's
LM has no step rejection (it always takes the damped Gauss-Newton step, so a large error does not
make it back off), so the adapter answers such a ``q`` with a pose 1 km from the origin (a finite,
large error: never converged) and its Jacobian with ``numpy.linalg.LinAlgError``, which RTB treats
as a failed search: it abandons it and restarts from its next random ``q``. :class:`VgtEts` counts
these events. RTB does not minimise vgtarm's joint-limit cost ``Phi`` (eq. 12) nor keep an assembly
margin: :func:`run` reports both for its answers.

RTB's solver as used here: ``IK_LM`` with Sugihara's damping (:data:`METHOD`, :data:`DAMPING`; its
default, Chan's, stalls short of the tolerance on this robot), RTB's iteration and search limits,
and a tolerance tight enough for vgtarm's reach checks (:data:`TOLERANCE`).

Run ``python -m benchmarks.rtb_anchor``: 50 seeded reachable vertical-axis targets, RTB's
``IK_LM`` (from vgtarm's start, home; with Chan's damping; from random starts) against vgtarm's
``solve_point`` and one batched ``inverse_kinematics`` call over the targets.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

import vgtarm
from vgtarm.errors import AssemblyError, InputError, VgtarmError
from vgtarm.ik import inverse_kinematics, solve_point
from vgtarm.ik.problem import IKProblem
from vgtarm.paths import TipPath

Array = NDArray[np.float64]

#: RTB's mask: tip position and the rotations about the base x and y axes; the base z spin free.
MASK = (1.0, 1.0, 1.0, 1.0, 1.0, 0.0)
#: Convergence threshold on RTB's ``E = e^T W e / 2``: the masked error ``|e| < 1.4e-10`` (m, rad).
#: RTB's default (1e-6, ``|e| < 1.4e-3``) is far looser than vgtarm's reach tolerance.
TOLERANCE = 1e-20
#: RTB's defaults: iterations per search, searches (the first from ``q0``, then random restarts).
ITERATIONS = 30
SEARCHES = 100
#: RTB's LM damping ``W_n``: Sugihara's ``E + k`` with ``k = 1e-3 m^2``, about ``0.01 l^2`` for the
#: legs' ``l ~ 0.3 m`` (Sugihara's advice). RTB's default, Chan's ``k E`` (``k = 1``), vanishes with
#: the error, and on this 7-joint robot with a rank-5 masked task ``J^T W J + k E I`` is then
#: conditioned like ``1/E`` (presumably why its steps stall): measured on :func:`run`'s targets from
#: home, Chan's reaches ``E < 1e-16`` in 3-4 iterations but :data:`TOLERANCE` on only 20 of 50, after
#: ~1,500 iterations of random restarts, where Sugihara's reaches it on 50/50 in 4-5 iterations.
METHOD = "sugihara"
DAMPING = 1e-3
#: The assembly margin vgtarm's IK keeps (m); RTB's answers are checked against it.
ASSEMBLY_MARGIN = 5e-3
#: Where the adapter puts the tool of a configuration that cannot be assembled (m from the origin).
_FAR = 1e3


@dataclass(frozen=True)
class _Joint:
    """What RTB's solvers read of a joint: its index in ``q`` and whether it turns."""

    jindex: int
    isrotation: bool


class VgtEts:
    """A vgtarm robot as the "ETS" of Robotics Toolbox's Python IK solvers (duck-typed).

    Attributes:
        robot: the vgtarm robot.
        n: number of joints.
        qlim: ``(2, n)`` joint limits (lower row first; m, rad).
        jindices: ``(n,)`` the joints' indices in ``q``: ``0 .. n-1``.
        invalid_evaluations: calls of :meth:`eval` at a ``q`` that cannot be assembled (or that vgtarm
            refuses as out of its accepted range).
        abandoned_searches: calls of :meth:`jacob0` there (each ends one of RTB's searches).
    """

    def __init__(self, robot: vgtarm.Robot) -> None:
        self.robot = robot
        self.n = robot.n_joints
        low, high = robot.joint_limits()
        self.qlim = np.stack([low, high])
        self.jindices = np.arange(self.n)
        self._joints = [_Joint(j, unit == "rad") for j, unit in enumerate(robot.joint_units)]
        self.invalid_evaluations = 0
        self.abandoned_searches = 0

    def joints(self) -> list[_Joint]:
        """The joints, in the order of ``q``."""
        return list(self._joints)

    def eval(self, q: Array) -> Array:
        """``(4, 4)`` homogeneous transform of the tool frame in the base frame F0 at ``q`` ``(n,)``;
        a pose 1 km from the origin if ``q`` cannot be assembled (or is refused)."""
        try:
            point, rotation = self.robot.tool_frame(np.asarray(q, dtype=float)[: self.n])
        except (AssemblyError, InputError):
            point, rotation = np.full(3, np.nan), np.eye(3)
        T = np.eye(4)
        if not (np.isfinite(point).all() and np.isfinite(rotation).all()):
            self.invalid_evaluations += 1
            T[:3, 3] = _FAR
            return T
        T[:3, :3] = rotation
        T[:3, 3] = point
        return T

    def jacob0(self, q: Array) -> Array:
        """``(6, n)`` Jacobian of the tool frame in F0: tip velocity rows, then angular velocity.

        Raises:
            numpy.linalg.LinAlgError: ``q`` cannot be assembled or is refused (RTB then abandons the search).
        """
        qa = np.asarray(q, dtype=float)[: self.n]
        try:
            J = np.vstack([self.robot.tip_jacobian(qa), self.robot.angular_jacobian(qa)])
        except (AssemblyError, InputError):
            J = np.full((6, self.n), np.nan)
        if not np.isfinite(J).all():
            self.abandoned_searches += 1
            raise np.linalg.LinAlgError(f"q = {qa.tolist()} is not a configuration of the robot")
        return J


def vertical_target(ets: VgtEts, point: Array, q0: Array) -> Array:
    """``(4, 4)`` RTB target: the tip at ``point``, the tool's axis vertical, the spin of ``q0``."""
    T = np.eye(4)
    T[:3, 3] = point
    x = ets.eval(q0)[:3, 0].copy()
    x[2] = 0.0
    if np.linalg.norm(x) > 1e-6:
        x /= np.linalg.norm(x)
        T[:3, :3] = np.column_stack([x, np.cross([0.0, 0.0, 1.0], x), [0.0, 0.0, 1.0]])
    return T


class MaskedSolve(NamedTuple):
    """One RTB solve: ``(q, success, iterations, seconds)``."""

    q: Array
    success: bool
    iterations: int
    seconds: float


def solve_masked(
    robot: vgtarm.Robot,
    point: object,
    q0: object,
    *,
    seed: int = 0,
    ets: VgtEts | None = None,
    method: str = METHOD,
    k: float = DAMPING,
) -> MaskedSolve:
    """RTB's ``IK_LM`` for the tip at ``point`` ``(3,)`` (m) with the tool's axis vertical, from ``q0`` ``(n,)``.

    The mask is in the base frame (:data:`MASK`): the rotation about the base ``z`` axis is free,
    so the target axis must be ``(0, 0, 1)``. Joint limits are enforced as RTB does (a converged
    ``q`` outside them is rejected and the search restarted from a random ``q`` of the generator
    seeded with ``seed``). ``ets`` (a :class:`VgtEts` of ``robot``) may be passed to read its counters;
    ``method`` and ``k`` are ``IK_LM``'s damping (:data:`METHOD`, :data:`DAMPING`).

    Returns:
        ``(q, success, iterations, seconds)``: the answer ``(n,)``, RTB's success flag, its
        iterations over all searches and the wall time of the solve (s).
    """
    import roboticstoolbox as rtb

    adapter = VgtEts(robot) if ets is None else ets
    start = np.asarray(q0, dtype=float)
    solver = rtb.IK_LM(
        ilimit=ITERATIONS, slimit=SEARCHES, tol=TOLERANCE, mask=MASK, joint_limits=True, seed=seed, method=method, k=k
    )
    target = vertical_target(adapter, np.asarray(point, dtype=float), start)
    started = time.perf_counter()
    solution = solver.solve(adapter, target, start)  # type: ignore[arg-type]  # duck-typed ETS
    seconds = time.perf_counter() - started
    return MaskedSolve(np.array(solution.q, dtype=float), bool(solution.success), int(solution.iterations), seconds)


def axis_angle(robot: vgtarm.Robot, q: Array, direction: Array) -> float:
    """Angle between the tool's axis at ``q`` and the unit ``direction`` (rad)."""
    axis = robot.tool_axis(q)
    return math.atan2(float(np.linalg.norm(np.cross(axis, direction))), float(axis @ direction))


def targets(robot: vgtarm.Robot, count: int, seed: int = 0) -> tuple[list[Array], list[Any], int]:
    """``count`` reachable vertical-axis targets: tips of random configurations (each joint in the middle
    half of its range, assemblable with the margin) that vgtarm's ``solve_point`` solves with the axis
    vertical. Returns the points, vgtarm's solutions and the number of candidates drawn."""
    rng = np.random.default_rng(seed)
    low, high = robot.joint_limits()
    points: list[Array] = []
    solutions: list[Any] = []
    drawn = 0
    while len(points) < count:
        drawn += 1
        q = low + (0.25 + 0.5 * rng.random(robot.n_joints)) * (high - low)
        if not robot.is_assemblable(q, ASSEMBLY_MARGIN):
            continue
        point = robot.tip_position(q)
        solution = solve_point(robot, point, axis=[0.0, 0.0, 1.0])
        if solution.success:
            points.append(point)
            solutions.append(solution)
    return points, solutions, drawn


@dataclass
class _Column:
    """One method's figures over the targets."""

    name: str
    seconds: list[float] = field(default_factory=list)
    success: list[bool] = field(default_factory=list)
    phi: list[float] = field(default_factory=list)
    joint_margin: list[float] = field(default_factory=list)
    assemblable: list[bool] = field(default_factory=list)

    def add(self, robot: vgtarm.Robot, problem: IKProblem, q: Array, success: bool, seconds: float) -> None:
        """Record one answer ``q`` ``(n,)``: its cost, smallest joint-limit margin and assemblability."""
        low, high = robot.joint_limits()
        self.seconds.append(seconds)
        self.success.append(success)
        self.phi.append(float(problem.phi(q)))
        self.joint_margin.append(float(min((q - low).min(), (high - q).min())))
        self.assemblable.append(bool(robot.is_assemblable(q, ASSEMBLY_MARGIN)))

    def line(self) -> str:
        ok = [i for i, s in enumerate(self.success) if s]
        phi = statistics.median(self.phi[i] for i in ok) if ok else float("nan")
        margin = min((self.joint_margin[i] for i in ok), default=float("nan"))
        assembled = sum(self.assemblable[i] for i in ok)
        return (
            f"| {self.name} | {1e3 * statistics.median(self.seconds):.2f} | {1e3 * statistics.mean(self.seconds):.2f} "
            f"| {len(ok)}/{len(self.success)} | {phi:.4g} | {margin:.4g} | {assembled}/{len(ok)} |"
        )


def _batched(robot: vgtarm.Robot, problem: IKProblem, points: list[Array]) -> _Column:
    """One ``inverse_kinematics`` call over the targets as the samples of one (jumping) path; its time
    is shared equally among the samples."""
    positions = np.stack(points)
    zeros = np.zeros_like(positions)
    path = TipPath("targets", np.arange(len(points), dtype=float), positions, zeros, zeros, zeros)
    started = time.perf_counter()
    result = inverse_kinematics(robot, path, axis=[0.0, 0.0, 1.0], rates="finite_difference", check=False)
    share = (time.perf_counter() - started) / len(points)
    column = _Column(f"vgtarm inverse_kinematics (one call, {len(points)} samples)")
    for q, success in zip(np.asarray(result.q), np.asarray(result.samples.success), strict=True):
        column.add(robot, problem, q, bool(success), share)
    return column


@dataclass
class _Anchor:
    """RTB's answers with one damping: its figures, iterations and largest errors."""

    column: _Column
    method: str
    k: float
    ets: VgtEts
    random_start: bool = False
    iterations: list[int] = field(default_factory=list)
    not_lower: int = 0
    tip_error: float = 0.0
    axis_error: float = 0.0

    def solve(self, problem: IKProblem, point: Array, q0: Array, seed: int, phi: float) -> None:
        """Solve one target from ``q0`` and compare its ``Phi`` with vgtarm's ``phi``."""
        robot = self.ets.robot
        q, success, iterations, seconds = solve_masked(
            robot, point, q0, seed=seed, ets=self.ets, method=self.method, k=self.k
        )
        self.column.add(robot, problem, q, success, seconds)
        self.iterations.append(iterations)
        if success:
            self.not_lower += self.column.phi[-1] >= phi - 1e-12
            self.tip_error = max(self.tip_error, float(np.linalg.norm(robot.tip_position(q) - point)))
            self.axis_error = max(self.axis_error, axis_angle(robot, q, np.array([0.0, 0.0, 1.0])))

    def summary(self) -> str:
        return (
            f"{self.column.name}: iterations median {statistics.median(self.iterations):g}, "
            f"max {max(self.iterations)}; "
            f"Phi >= vgtarm's - 1e-12 on {self.not_lower}/{sum(self.column.success)} solved; worst tip error "
            f"{self.tip_error:.2e} m, axis error {self.axis_error:.2e} rad; evaluations at non-configurations "
            f"{self.ets.invalid_evaluations}, searches abandoned there {self.ets.abandoned_searches}"
        )


def _starts(robot: vgtarm.Robot, count: int, seed: int) -> list[Array]:
    """``count`` seeded configurations uniform within the joint limits that can be assembled."""
    rng = np.random.default_rng(seed + 1)
    low, high = robot.joint_limits()
    starts: list[Array] = []
    while len(starts) < count:
        q = rng.uniform(low, high)
        if robot.is_assemblable(q):
            starts.append(q)
    return starts


def run(count: int = 50, seed: int = 0) -> None:
    """Print RTB's ``IK_LM`` against vgtarm's ``solve_point`` on ``count`` seeded vertical-axis targets."""
    robot = vgtarm.load_robot()
    problem = IKProblem.from_parameters(robot.parameters)
    home = np.asarray(robot.parameters.home, dtype=float)
    points, _, drawn = targets(robot, count, seed)
    ours = _Column("vgtarm solve_point (axis)")
    anchors = [
        _Anchor(_Column(f"RTB IK_LM {method} k={k:g}{' random q0' if far else ''}"), method, k, VgtEts(robot), far)
        for method, k, far in ((METHOD, DAMPING, False), ("chan", 1.0, False), (METHOD, DAMPING, True))
    ]
    starts = _starts(robot, count, seed)
    for i, point in enumerate(points):
        started = time.perf_counter()
        solution = solve_point(robot, point, axis=[0.0, 0.0, 1.0])
        ours.add(robot, problem, np.asarray(solution.q), solution.success, time.perf_counter() - started)
        for anchor in anchors:
            anchor.solve(problem, point, starts[i] if anchor.random_start else home, seed + i, solution.phi)
    print(
        f"{count} vertical-axis targets ({drawn} candidates drawn, seed {seed}); q0 = home (vgtarm's start) unless "
        f"'random q0' (assemblable, uniform within the limits); RTB tol {TOLERANCE:g}\n"
    )
    print("| method | median ms | mean ms | success | median Phi | min joint margin | assemblable 5 mm |")
    print("|---|---|---|---|---|---|---|")
    for column in [ours, *(anchor.column for anchor in anchors)]:
        print(column.line())
    try:
        print(_batched(robot, problem, points).line())
    except VgtarmError as error:
        print(f"| vgtarm inverse_kinematics (one call) | failed: {error} | | | | | |")
    print()
    for anchor in anchors:
        ratio = statistics.median(anchor.column.seconds) / statistics.median(ours.seconds)
        print(f"- {anchor.summary()}; median time {ratio:.2f}x solve_point's")


if __name__ == "__main__":
    run()
