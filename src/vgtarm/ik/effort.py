"""The effort criterion of the redundancy resolution: the static actuator efforts along the path.

Beside the joint-limit cost of eq. 12, ``criterion="effort"`` minimises per sample

``Phi(q) = Phi_e(q, f(t)) + w_jl Phi_jl(q)``, ``Phi_e = (1/n) sum_i (tau_i(q, f) / tau_ref_i)^2``,

with the static generalised efforts ``tau = G(q) - J_P(q)^T f`` that hold the arm at rest at
``q`` against gravity and the expected tool force ``f`` on the tip (compiled functions
``ik_effort*``, derived from the one dynamics definition), ``Phi_jl`` the joint-limit cost of
eq. 12 and ``w_jl`` the user's weight of it (option ``joint_limit_weight``).

**Normalisation.** Each effort is divided by what the arm's own weight makes of it:
``tau_ref = m g`` (N) for a prismatic joint and ``m g r`` (N m) for a revolute one, with ``m`` the
robot's total mass, ``g = 9.81 m/s^2`` and ``r`` the distance of the tip from the base at the home
pose. ``Phi_e`` is then dimensionless and of the size of ``Phi_jl`` (both about 0.1 to 0.3 for the
paper's robot), so ``w_jl = 1`` weighs the two alike. ``w_jl > 0`` is required: gravity and a tip
force exert no torque about the twist axis of the paper's robot, so without the joint-limit term the
twist angle would be free and the optimum not unique.

**The expected tool force** is the path's cutting-force model (paper eq. 16) with the disturbance's
mean, zero: ``f = -F0 v |v|^2 / (|v|^2 + v_s^2)^(3/2)`` along the desired tip velocity ``v``
(:func:`vgtarm.simulation.external.expected_cutting_force`, the feed-forward's formula). The cutting
force the plant applies switches on at a small speed (``ExternalForce.cutting_speed``); the expected
force is smoothed over ``v_s`` (the smoothing speed of
:class:`~vgtarm.ik.IKOptions`, 3 cm/s by default) so that the
optimum, and with it the reference, moves smoothly at the rest-to-rest corners of a path, and it
grows with the cube of the speed from rest, so the optimum's rate is zero where the path rests: the
reference starts at rest with the path (``docs/control.md``, "A reference that starts at rest").
Its first and second time derivatives (for the exact rates) follow from the path's acceleration and
jerk by automatic differentiation.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..model.robot import Robot
from ..paths import TipPath

Array = NDArray[np.float64]

#: Names of the redundancy criteria.
CRITERIA = ("joint_limits", "effort")
#: Standard gravity used in the normalisation (m/s^2).
STANDARD_GRAVITY = 9.81
#: Default weight of the joint-limit cost in the effort criterion.
DEFAULT_JOINT_LIMIT_WEIGHT = 0.5
#: Default smoothing speed of the expected tool force (m/s).
DEFAULT_TOOL_FORCE_SPEED = 0.03


@dataclass(frozen=True, eq=False)
class EffortTerms:
    """What the effort criterion needs per sample.

    Attributes:
        force, force_rate, force_acceleration: ``(N, 3)`` expected tool force on the tip (N) and
            its first and second time derivatives.
        scale: ``(n,)`` inverse reference efforts ``1 / tau_ref`` (1/N, 1/(N m)).
    """

    force: Array
    force_rate: Array
    force_acceleration: Array
    scale: Array

    def subset(self, idx: NDArray[np.intp]) -> EffortTerms:
        """The terms of samples ``idx``."""
        return EffortTerms(self.force[idx], self.force_rate[idx], self.force_acceleration[idx], self.scale)

    def at_rest(self, i: int, n: int) -> EffortTerms:
        """``n`` samples all with sample ``i``'s force, not moving (the continuation from the start pose)."""
        still = np.zeros((n, 3))
        return EffortTerms(np.repeat(self.force[i : i + 1], n, axis=0), still, still.copy(), self.scale)


def reference_efforts(robot: Robot) -> Array:
    """``tau_ref`` ``(n,)``: ``m g`` (N) for prismatic joints, ``m g r`` (N m) for revolute ones (module docstring)."""
    weight = robot.parameters.total_mass * STANDARD_GRAVITY
    reach = float(np.linalg.norm(robot.tip_position(robot.parameters.home)))
    units = robot.parameters.joint_units
    return np.array([weight * reach if unit == "rad" else weight for unit in units])


@functools.cache
def _force_model() -> ca.Function:
    v, a, j = ca.SX.sym("v", 3), ca.SX.sym("a", 3), ca.SX.sym("j", 3)
    f0, speed, t = ca.SX.sym("F0"), ca.SX.sym("v_s"), ca.SX.sym("t")
    moving = v + a * t + j * (t**2 / 2)
    squared = ca.sumsqr(moving)
    f = -f0 * moving * squared / (squared + speed**2) ** 1.5  # expected_cutting_force
    fd = ca.jacobian(f, t)
    fdd = ca.jacobian(fd, t)
    outputs = [ca.substitute(e, t, 0) for e in (f, fd, fdd)]
    return ca.Function("expected_tool_force", [v, a, j, f0, speed], outputs)


def expected_tool_force(path: TipPath, force: float, speed: float) -> tuple[Array, Array, Array]:
    """Expected tool force ``(N, 3)`` on the tip along ``path`` and its two time derivatives (module docstring).

    Raises :class:`InputError` when the force acts and the path has no jerk (a hand-made
    :class:`~vgtarm.paths.TipPath` without one): the second derivative needs it.
    """
    n = len(path)
    if force == 0.0:
        zero = np.zeros((n, 3))
        return zero, zero.copy(), zero.copy()
    if path.jerk is None:
        raise InputError(
            f"path {path.name!r} has no jerk: the effort criterion with tool_force = {force:g} N needs the path's "
            "third derivative (every constructor of vgtarm.paths gives it; pass jerk= to TipPath)"
        )
    mapped = _force_model().map(n)
    out = mapped(path.velocity.T, path.acceleration.T, path.jerk.T, force, speed)
    f, fd, fdd = (np.asarray(o, dtype=float).T.copy() for o in out)
    return f, fd, fdd


def effort_terms(robot: Robot, path: TipPath, force: float, speed: float) -> EffortTerms:
    """The effort criterion's per-sample terms for ``robot`` along ``path``."""
    f, fd, fdd = expected_tool_force(path, force, speed)
    return EffortTerms(f, fd, fdd, 1.0 / reference_efforts(robot))
