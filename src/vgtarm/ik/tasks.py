"""The equality constraints of a path, evaluated through the compiled model.

A :class:`Task` holds the desired tip point per sample (and, for the pose variant, the desired
orientation with its angular velocity and acceleration) and evaluates, for any subset of samples,
the residual ``c(q) - c_d``, its Jacobian and the Hessian of ``lam^T c`` (functions ``ik_position``
and ``ik_pose`` of :mod:`vgtarm.functions_ik`), and the path derivatives of the KKT residual that
the exact rates need.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..model.compiled import Backend

Array = NDArray[np.float64]
Index = NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class Task:
    """Targets of every sample of a path and the compiled functions of the task.

    Attributes:
        kind: ``"position"`` (3 equality rows: tip point) or ``"pose"`` (6: tip point and the
            orientation residual ``0.5 vee(R_d^T R - R^T R_d)``).
        t: ``(N,)`` sample times (s).
        position, velocity, acceleration: ``(N, 3)`` desired tip point and its derivatives (SI).
        rotation: ``(N, 9)`` desired orientation, row-major, or ``None`` for the position task.
        angular_velocity, angular_acceleration: ``(N, 3)`` of the desired orientation in F0
            (rad/s, rad/s^2), or ``None``.
        backend, p: the compiled model and the parameter vector.
    """

    kind: str
    t: Array
    position: Array
    velocity: Array
    acceleration: Array
    rotation: Array | None
    angular_velocity: Array | None
    angular_acceleration: Array | None
    backend: Backend
    p: Array

    @property
    def m(self) -> int:
        """Number of equality rows."""
        return 3 if self.kind == "position" else 6

    def __len__(self) -> int:
        return int(self.position.shape[0])

    def subset(self, idx: Index) -> Task:
        """The task restricted to samples ``idx``."""

        def pick(a: Array | None) -> Array | None:
            return None if a is None else a[idx]

        return Task(
            self.kind,
            self.t[idx],
            self.position[idx],
            self.velocity[idx],
            self.acceleration[idx],
            pick(self.rotation),
            pick(self.angular_velocity),
            pick(self.angular_acceleration),
            self.backend,
            self.p,
        )

    def with_targets(self, position: Array, rotation: Array | None) -> Task:
        """A task with other target points ``(n, 3)`` (and orientations ``(n, 9)``), at rest, times ``0..n-1``."""
        n = position.shape[0]
        zeros = np.zeros((n, 3))
        moving = None if rotation is None else zeros
        return Task(
            self.kind, np.arange(n, dtype=float), position, zeros, zeros, rotation, moving, moving, self.backend, self.p
        )

    def forward(self, q: Array) -> tuple[Array, Array]:
        """Tip point ``(n, 3)`` and row-major end-effector orientation ``(n, 9)`` of ``q`` ``(n, 7)``."""
        out = self.backend.evaluate("fk", [q, self.p], q.shape[0])
        return out[5], out[6]

    def _orientation_inputs(self, idx: Index) -> list[Array]:
        assert self.rotation is not None
        return [self.rotation[idx]]

    def _motion_inputs(self, idx: Index) -> list[Array]:
        assert self.angular_velocity is not None and self.angular_acceleration is not None
        return [self.angular_velocity[idx], self.angular_acceleration[idx]]

    def evaluate(self, idx: Index, q: Array, lam: Array) -> tuple[Array, Array, Array]:
        """Residual ``c(q) - c_d`` ``(n, m)``, Jacobian ``(n, m, 7)``, ``d^2(lam^T c)/dq^2`` ``(n, 7, 7)``.

        ``idx`` selects the samples (their targets); ``q`` ``(n, 7)`` and ``lam`` ``(n, m)``.
        """
        n = idx.shape[0]
        if self.kind == "position":
            c, J, H = self.backend.evaluate("ik_position", [q, lam, self.p], n)
            c -= self.position[idx]
        else:
            c, J, H = self.backend.evaluate("ik_pose", [q, lam, *self._orientation_inputs(idx), self.p], n)
            c[:, :3] -= self.position[idx]
        return c, J.reshape(n, self.m, 7), H.reshape(n, 7, 7)

    def evaluate_with_rates(self, idx: Index, q: Array, lam: Array, weight: Array) -> tuple[Array, ...]:
        """As :meth:`evaluate`, plus the exact ``qd, lam_d, qdd, lam_dd`` for no active inequality.

        One compiled call (``ik_position_rates`` / ``ik_pose_rates``) per sample; ``weight`` ``(7,)``
        is the diagonal of the Hessian of ``Phi``. The rates are valid only where ``(q, lam)`` is
        a solution with no active limit or triangle row.
        """
        n = idx.shape[0]
        motion = [self.velocity[idx], self.acceleration[idx]]
        if self.kind == "position":
            out = self.backend.evaluate("ik_position_rates", [q, lam, weight, *motion, self.p], n)
            out[0] -= self.position[idx]
        else:
            inputs = [q, lam, weight, *motion, *self._orientation_inputs(idx), *self._motion_inputs(idx), self.p]
            out = self.backend.evaluate("ik_pose_rates", inputs, n)
            out[0][:, :3] -= self.position[idx]
        c, J, H, *rates = out
        return (c, J.reshape(n, self.m, 7), H.reshape(n, 7, 7), *rates)

    def first_order_rhs(self, idx: Index, q: Array, lam: Array) -> Array:
        """``-dF/dt`` at fixed ``(q, lam)`` of the KKT residual ``F = [grad L; c - c_d]``, ``(n, 7 + m)``."""
        n = idx.shape[0]
        rhs = np.zeros((n, 7 + self.m))
        rhs[:, 7:10] = self.velocity[idx]
        if self.kind == "pose":
            inputs = [q, lam, *self._orientation_inputs(idx), *self._motion_inputs(idx), self.p]
            (dt,) = self.backend.evaluate("ik_pose_dt", inputs, n)
            rhs -= dt
        return rhs

    def second_order_rhs(self, idx: Index, q: Array, lam: Array, qd: Array, lam_d: Array) -> Array:
        """``-d^2/dt^2 F(q + t qd, lam + t lam_d, t)`` at ``t = 0``, ``(n, 7 + m)``.

        With ``K [qdd; lam_dd] = this`` (active set fixed), ``(qdd, lam_dd)`` are the second
        derivatives of the optimum along the path.
        """
        n = idx.shape[0]
        if self.kind == "position":
            (d2,) = self.backend.evaluate("ik_position_d2", [q, lam, qd, lam_d, self.p], n)
        else:
            inputs = [q, lam, qd, lam_d, *self._orientation_inputs(idx), *self._motion_inputs(idx), self.p]
            (d2,) = self.backend.evaluate("ik_pose_d2", inputs, n)
        rhs = -d2
        rhs[:, 7:10] += self.acceleration[idx]
        return rhs
