"""The redundancy spent on stiffness along the tool's axis: the posture, among those that keep the tool
point and the tool's axis where they are, whose tool is stiffest along that axis under a thrust
(issue 38; ``docs/drilling_control.md``, "Null space").

The arm has ``n`` joints and the drilling task fixes five coordinates (the tool point, the axis's
direction), so its self-motion has ``n - 5`` dimensions (2 for the paper robot: the spin about the
axis and a motion of the two trusses that leaves the tool's pose unchanged). :func:`stiffest_posture`
searches them for the least axial compliance ``a^T C a`` (``C``: the translational compliance of
:func:`~.stiffness.cartesian_stiffness`, the joints' springs of the robot file's ``[stiffness]``
table, the geometric terms of the thrust and of the weight included), by SciPy's SLSQP with the
five task constraints' exact Jacobians and the joints within their limits less a margin. The drilling
loop then holds that posture in its null space (:func:`vgtarm.drilling.drilling_run`'s ``q0``;
``vgtarm drill --posture stiffest``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..errors import InputError
from ..model.robot import Robot
from .stiffness import _configuration, cartesian_stiffness, joint_stiffness

Array = NDArray[np.float64]

#: Share of each joint's range kept clear of its limits.
LIMIT_MARGIN = 0.05


@dataclass(frozen=True)
class StiffPosture:
    """The result of :func:`stiffest_posture`: the posture ``q`` ``(n,)``, the start ``q0``, the
    axis (unit, F0), the axial compliance at each (m/N) and the axial stiffness at each (N/m), the
    task's residual at ``q`` (m and rad, the largest), the solver's iterations and message."""

    q: Array
    q0: Array
    axis: Array
    compliance0: float
    compliance: float
    residual: float
    iterations: int
    message: str

    @property
    def stiffness0(self) -> float:
        return 1.0 / self.compliance0

    @property
    def stiffness(self) -> float:
        return 1.0 / self.compliance


def axial_compliance(robot: Robot, q: Array, axis: Array, thrust: float, stiffness: Array) -> float:
    """``a^T C a`` (m/N) at ``q`` under the thrust ``thrust`` (N) along ``-axis`` at the tool."""
    c = cartesian_stiffness(robot, q, -thrust * axis, stiffness=stiffness).translational_compliance
    return float(axis @ c @ axis)


def _frame(axis: Array) -> tuple[Array, Array]:
    """Two unit vectors normal to ``axis`` and to each other."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def stiffest_posture(
    robot: Robot,
    q0: ArrayLike,
    *,
    thrust: float = 20.0,
    stiffness: ArrayLike | None = None,
    max_iterations: int = 100,
) -> StiffPosture:
    """The posture of ``robot`` with the tool point and the tool's axis of ``q0`` whose tool is
    stiffest along that axis under ``thrust`` (N, pushing the tool back along its axis); the joints'
    springs are the robot file's ``[stiffness]`` or ``stiffness`` ``(n,)`` (one line refuses a robot
    with neither). See the module's docstring."""
    k = joint_stiffness(robot, stiffness)
    start = _configuration(robot, q0, "q0")
    checks.positive("thrust", thrust, "N", maximum=1e4)
    checks.whole("max_iterations", max_iterations, minimum=1, maximum=10_000)
    tip0 = robot.tip_position(start)
    axis = robot.tool_axis(start)
    e1, e2 = _frame(axis)
    lower, upper = robot.joint_limits()
    span = upper - lower
    bounds = list(zip(lower + LIMIT_MARGIN * span, upper - LIMIT_MARGIN * span, strict=True))
    scale = axial_compliance(robot, start, axis, thrust, k)

    def objective(q: Array) -> float:
        return axial_compliance(robot, q, axis, thrust, k) / scale

    def task(q: Array) -> Array:
        a = robot.tool_axis(q)
        return np.concatenate([robot.tip_position(q) - tip0, [e1 @ a, e2 @ a]])

    def task_jacobian(q: Array) -> Array:
        a, Jw = robot.tool_axis(q), robot.angular_jacobian(q)
        turn = np.cross(Jw.T, a)  # (n, 3): d a / d q_k = (J_w[:, k]) x a
        return np.vstack([robot.tip_jacobian(q), (turn @ e1)[None], (turn @ e2)[None]])

    found = scipy.optimize.minimize(
        objective,
        np.clip(start, [b[0] for b in bounds], [b[1] for b in bounds]),
        method="SLSQP",
        bounds=bounds,
        constraints=[{"type": "eq", "fun": task, "jac": task_jacobian}],
        options={"maxiter": max_iterations, "ftol": 1e-12},
    )
    q = np.asarray(found.x, dtype=np.float64)
    residual = float(np.max(np.abs(task(q))))
    if not found.success or residual > 1e-8:
        raise InputError(
            f"q0: no stiffer posture with the same tool pose was found ({found.message}; task residual {residual:.2g})"
        )
    robot.check_assembly(q, where="the stiffest posture")
    return StiffPosture(
        q, start, axis, scale, axial_compliance(robot, q, axis, thrust, k), residual, int(found.nit), str(found.message)
    )
