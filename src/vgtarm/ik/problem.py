"""The optimisation problem of one inverse-kinematics sample (paper eq. 12), as plain arrays.

``min Phi(q) = (1/n) sum_i ((q_i - q_i*) / (q_i,max - q_i,min))^2`` with ``q* `` the middle of the
joint range and ``n`` the number of joints (7 for the paper's robot, any for a stack), subject to
the task's equality constraints (tip point, optionally the
orientation), the joint limits ``lower <= q <= upper`` and assemblability with a margin: the
triangle inequalities of the truss are linear in ``q`` (:func:`vgtarm.model.assembly.linear_form`), and
every sample must satisfy ``G q + h >= margin``. Rows that the joint limits already imply with
that margin are dropped, so the active-set systems stay small (for the reference robot only the two
``s + 2d > p`` rows remain).

Inequalities are ordered: n lower limits, n upper limits, then the kept triangle rows.

The equality constraints of a path, evaluated through the compiled model.

A :class:`Task` holds the desired tip point per sample (and, for the pose variant, the desired
orientation with its angular velocity and acceleration) and evaluates, for any subset of samples,
the residual ``c(q) - c_d``, its Jacobian and the Hessian of ``lam^T c`` (functions ``ik_position``
and ``ik_pose`` of :mod:`vgtarm.model.codegen.ik`), and the path derivatives of the KKT residual that
the exact rates need.

The working arrays of a batch of inverse-kinematics samples (primal, dual, active set, last model values).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .. import checks
from ..errors import InputError
from ..model.assembly import TRIANGLE_INEQUALITIES
from ..model.parameters import JOINT_NAMES, N_JOINTS, RobotParameters
from ..model.robot import Robot
from ..model.stack import Stack
from . import axis
from .effort import EffortTerms

Array = NDArray[np.float64]

#: Default assembly margin (m): every triangle inequality holds with at least this slack.
DEFAULT_MARGIN = 5e-3


#: Largest ``rows * size(M)`` of one matrix product in :func:`rows_times` (OpenBLAS keeps products
#: below about ``2^18`` multiply-adds on the calling thread).
_BLOCK_WORK = 2**17


def rows_times(x: Array, M: Array) -> Array:
    """``x @ M.T`` for a batch ``x`` ``(n, c)`` and a small matrix ``M`` ``(r, c)``, as ``(n, r)``.

    Computed in blocks of rows small enough for OpenBLAS to run each product on the calling
    thread: one large product wakes OpenBLAS's thread pool, whose spinning threads then slow
    down the compiled model's OpenMP threads on the same cores (by a factor of about three for the
    batched rate evaluation on two cores).
    """
    n = x.shape[0]
    block = max(1, _BLOCK_WORK // max(1, M.size))
    if n <= block:
        return np.asarray(x @ M.T)
    out = np.empty((n, M.shape[0]))
    for start in range(0, n, block):
        out[start : start + block] = x[start : start + block] @ M.T
    return out


#: Widest rows that :func:`largest_magnitude`, :func:`rows_all` and :func:`rows_any` reduce column
#: by column; NumPy's reduction along a short last axis costs some tens of nanoseconds a row.
NARROW = 16


def largest_magnitude(x: Array) -> Array:
    """``np.abs(x).max(axis=1)`` ``(n,)`` of ``x`` ``(n, w)``, ``w >= 1``: the same values (a maximum
    picks one of its entries, all ``>= +0`` or NaN, which any order finds), for narrow rows
    (:data:`NARROW`) by one ``np.maximum`` per column over every row at once."""
    magnitude = np.abs(x)
    if x.shape[1] > NARROW:
        return np.asarray(magnitude.max(axis=1))
    out = magnitude[:, 0].copy()
    for j in range(1, x.shape[1]):
        np.maximum(out, magnitude[:, j], out=out)
    return out


def rows_all(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """``mask.all(axis=1)`` ``(n,)`` of ``mask`` ``(n, w)``, narrow rows column by column (:data:`NARROW`)."""
    if mask.shape[1] > NARROW or mask.shape[1] == 0:
        return np.asarray(mask.all(axis=1))
    out = mask[:, 0].copy()
    for j in range(1, mask.shape[1]):
        out &= mask[:, j]
    return out


def rows_any(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """``mask.any(axis=1)`` ``(n,)`` of ``mask`` ``(n, w)``, narrow rows column by column (:data:`NARROW`)."""
    if mask.shape[1] > NARROW or mask.shape[1] == 0:
        return np.asarray(mask.any(axis=1))
    out = mask[:, 0].copy()
    for j in range(1, mask.shape[1]):
        out |= mask[:, j]
    return out


@dataclass(frozen=True, eq=False)
class IKProblem:
    """Cost, joint limits and linear inequalities of the redundancy resolution.

    Attributes:
        lower, upper: ``(n,)`` joint limits (m, rad).
        centre: ``(n,)`` middle of each range ``q*``.
        weight: ``(n,)`` diagonal of the constant Hessian of ``Phi``: ``2 / (n (upper - lower)^2)``.
        G, h: ``(k, n)``, ``(k,)`` kept triangle rows; the constraint is ``G q + h >= margin``.
        G_all, h_all: ``(6 m, n)``, ``(6 m,)`` every triangle row of the ``m`` modules (margins
            ``G_all q + h_all``), used to keep iterates assemblable.
        margin: Assembly margin (m).
        triangle_labels: ``(k,)`` names of the kept rows.
        A, b: ``(2 n + k, n)``, ``(2 n + k,)`` every inequality as ``A q + b >= 0``, in the order of
            :attr:`constraint_labels`.
        active_scale: ``(2 n + k,)`` factor ``c`` of the active-set rule ``mu - c * slack > 0``
            (the cost curvature of the joint the row moves), so that multipliers and slacks compare.
    """

    lower: Array
    upper: Array
    centre: Array
    weight: Array
    G: Array
    h: Array
    G_all: Array
    h_all: Array
    margin: float
    triangle_labels: tuple[str, ...]
    A: Array
    b: Array
    active_scale: Array
    joint_names: tuple[str, ...] = JOINT_NAMES

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.lower.shape[0])

    @classmethod
    def from_parameters(
        cls, parameters: RobotParameters | Stack, margin: float = DEFAULT_MARGIN, joint_limit_weight: float = 1.0
    ) -> IKProblem:
        """The problem of a robot, keeping the triangle rows that the joint limits do not imply.

        ``joint_limit_weight`` multiplies ``Phi`` (the effort criterion's weight of eq. 12; 1 for eq. 12 alone).
        """
        expected = "a finite number > 0 (m; at zero margin the truss is flat and its kinematics are not differentiable)"
        margin = checks.positive("margin", margin, expected=expected)
        lower, upper = parameters.lower, parameters.upper
        G_all, h_all = parameters.margin_form()
        n = lower.shape[0]
        # Smallest value of each row over the box: the row is implied when it is >= margin.
        smallest = np.where(G_all > 0, G_all * lower, G_all * upper).sum(axis=1) + h_all
        keep = smallest < margin
        labels = tuple(
            f"module {row // 6 + 1}: {TRIANGLE_INEQUALITIES[row % 6]}" for row in np.flatnonzero(keep).tolist()
        )
        G, h = G_all[keep], h_all[keep]
        weight = 2.0 / (n * (upper - lower) ** 2)
        if joint_limit_weight != 1.0:
            weight = joint_limit_weight * weight
        return cls(
            lower=lower,
            upper=upper,
            centre=(lower + upper) / 2,
            weight=weight,
            G=G,
            h=h,
            G_all=G_all,
            h_all=h_all,
            margin=float(margin),
            triangle_labels=labels,
            A=np.concatenate([np.eye(n), -np.eye(n), G]),
            b=np.concatenate([-lower, upper, h - margin]),
            active_scale=np.concatenate([weight, weight, np.abs(G) @ weight / np.abs(G).sum(axis=1)]),
            joint_names=parameters.joint_names,
        )

    @property
    def n_triangle(self) -> int:
        """Number of kept triangle rows ``k``."""
        return int(self.G.shape[0])

    @property
    def constraint_labels(self) -> tuple[str, ...]:
        """Names of the ``2 n + k`` inequalities, in their order."""
        return (
            tuple(f"{name} >= min" for name in self.joint_names)
            + tuple(f"{name} <= max" for name in self.joint_names)
            + tuple(f"{label} (margin {self.margin:g} m)" for label in self.triangle_labels)
        )

    def phi(self, q: Array) -> Array:
        """The cost ``Phi(q)`` of eq. 12, ``(...,)`` for ``q`` of shape ``(..., n)``."""
        return np.asarray(0.5 * ((q - self.centre) ** 2 * self.weight).sum(axis=-1))

    def phi_gradient(self, q: Array) -> Array:
        """``dPhi/dq``, ``(..., n)``."""
        return np.asarray(self.weight * (q - self.centre))

    def slacks(self, q: Array) -> Array:
        """Values of the ``2 n + k`` inequalities (all ``>= 0`` when feasible), ``(..., 2 n + k)`` (m, rad)."""
        flat = np.reshape(q, (-1, self.n))
        return (rows_times(flat, self.A) + self.b).reshape(np.shape(q)[:-1] + (self.b.shape[0],))

    def assemblable(self, q: Array, margin: float = 0.0) -> NDArray[np.bool_]:
        """Whether every triangle row of ``q`` ``(..., n)`` exceeds ``margin``."""
        flat = np.reshape(q, (-1, self.n))
        inside = rows_all(rows_times(flat, self.G_all) + self.h_all > margin)
        return np.asarray(inside.reshape(np.shape(q)[:-1]))

    def feasible(self, q: Array, tolerance: float = 1e-12) -> NDArray[np.bool_]:
        """Whether ``q`` ``(..., n)`` satisfies every inequality to ``tolerance``."""
        return np.asarray((self.slacks(q) >= -tolerance).all(axis=-1))


Index = NDArray[np.intp]


#: From this many joints on, the recursive model's rates are asked for where samples stop
#: (:attr:`Task.rates_at_the_end`). Measured on case 1 (CPU, best of 3, 2026-11-27): at 21 and 35
#: joints the rates in every call were 6 % and 3 % faster (0.54 against 0.57 s, 0.87 against 0.89 s),
#: at 175 joints 14 % slower (20.0 against 17.2 s).
RATES_AT_THE_END_FROM = 64


@dataclass(frozen=True, eq=False)
class Task:
    """Targets of every sample of a path and the compiled functions of the task.

    Attributes:
        kind: ``"position"`` (3 equality rows: tip point), ``"pose"`` (6: tip point and the
            orientation residual ``0.5 vee(R_d^T R - R^T R_d)``) or ``"axis"`` (5: tip point and the
            tool's axis along a direction, :mod:`vgtarm.ik.axis`).
        t: ``(N,)`` sample times (s).
        position, velocity, acceleration: ``(N, 3)`` desired tip point and its derivatives (SI).
        rotation: ``(N, 9)`` desired orientation, row-major (the axis task: the frames ``[w1 w2 d]``
            of the target axis ``d``), or ``None`` for the position task.
        angular_velocity, angular_acceleration: ``(N, 3)`` of the desired orientation (frame) in F0
            (rad/s, rad/s^2), or ``None``.
        model: the robot whose compiled functions the task evaluates (by name, through
            :meth:`vgtarm.Robot.evaluate`).
        evaluations: a one-element counter of samples evaluated through the compiled functions,
            shared by the task and every task derived from it (a solver's work counter).
        effort: the effort criterion's terms (:mod:`vgtarm.ik.effort`), or None for eq. 12 alone.
            With them the cost is ``Phi_e + Phi`` and the Hessians ``H`` include ``Phi_e``'s.
        directions: ``(r, 3)`` orthonormal rows for a robot whose tip moves in a plane (``r = 2``)
            or a line (``r = 1``) (:mod:`vgtarm.ik.taskspace`): the position task is then the
            ``r`` rows ``E (P(q) - P_d)``, evaluated through the same compiled functions (the
            multipliers enter them as ``E^T lam``); None for the tip's three coordinates.
        tool: ``(3, 3)`` the tool rotation ``B`` in the end-effector frame (the axis task only).
        cone: for the axis task on the boundary of a cone (:mod:`vgtarm.ik.axis`), ``cos`` of its
            half-angle: one row ``d . a(q) = cone`` (the frames' first column is ``d``) instead of the
            axis' two; None for the axis itself.
    """

    kind: str
    t: Array
    position: Array
    velocity: Array
    acceleration: Array
    rotation: Array | None
    angular_velocity: Array | None
    angular_acceleration: Array | None
    model: Robot
    evaluations: list[int] = field(default_factory=lambda: [0])
    effort: EffortTerms | None = None
    directions: Array | None = None
    tool: Array | None = None
    cone: float | None = None

    def _evaluate(self, name: str, inputs: dict[str, Array], n: int) -> dict[str, Array]:
        self.evaluations[0] += n
        return self.model.evaluate(name, inputs, n)

    @property
    def m(self) -> int:
        """Number of equality rows."""
        if self.directions is not None:
            return int(self.directions.shape[0])
        if self.kind == "axis" and self.cone is not None:
            return 4
        return {"position": 3, "axis": 5}.get(self.kind, 6)

    @property
    def compiled_rates(self) -> bool:
        """Whether :meth:`evaluate_with_rates` can give the rates in its compiled call (not for a
        reduced task, whose rates :func:`vgtarm.ik.rates.exact` computes from the same conditions)."""
        return self.directions is None and self.kind != "axis"

    @property
    def rates_at_the_end(self) -> bool:
        """Whether the rates are cheaper computed once a sample has converged than in every evaluation.

        The recursive model solves the rate systems with two dense LAPACK solves of size ``n + 3`` in
        its ``ik_position_rates``: on a long stack (:data:`RATES_AT_THE_END_FROM` joints or more) the
        Newton iteration then evaluates without rates and asks for them only at the samples that stop
        (the same call on them: the same values), which costs one more evaluation of the terms per
        sample and saves the solves of every sample that needs a Newton step. The compiled libraries
        give the rates in the same generated call, nearly free.
        """
        backend = getattr(self.model, "backend", None)
        return getattr(backend, "kind", "") == "recursive" and self.model.n_joints >= RATES_AT_THE_END_FROM

    def _lift(self, lam: Array) -> Array:
        """Multipliers of the tip's three rows, ``E^T lam`` ``(n, 3)``, for a reduced task's ``lam`` ``(n, r)``."""
        assert self.directions is not None
        return np.asarray(lam @ self.directions)

    def _reduce(self, rows: Array, nj: int) -> Array:
        """A KKT-residual vector ``(n, nj + 3)`` with its three tip rows projected on the task, ``(n, nj + r)``."""
        assert self.directions is not None
        return np.concatenate([rows[:, :nj], rows[:, nj : nj + 3] @ self.directions.T], axis=1)

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
            self.model,
            self.evaluations,
            None if self.effort is None else self.effort.subset(idx),
            self.directions,
            self.tool,
            self.cone,
        )

    def with_targets(self, position: Array, rotation: Array | None, like: int = 0) -> Task:
        """A task with other target points ``(n, 3)`` (and orientations ``(n, 9)``), at rest, times ``0..n-1``
        (with sample ``like``'s tool force, for the effort criterion)."""
        n = position.shape[0]
        zeros = np.zeros((n, 3))
        moving = None if rotation is None else zeros
        return Task(
            self.kind,
            np.arange(n, dtype=float),
            position,
            zeros,
            zeros,
            rotation,
            moving,
            moving,
            self.model,
            self.evaluations,
            None if self.effort is None else self.effort.at_rest(like, n),
            self.directions,
            self.tool,
            self.cone,
        )

    def forward(self, q: Array) -> tuple[Array, Array]:
        """Tip point ``(n, 3)`` and row-major end-effector orientation ``(n, 9)`` of ``q`` ``(n, joints)``."""
        out = self._evaluate("fk", {"q": q}, q.shape[0])
        return out["tip"], out["C03"]

    def _orientation_inputs(self, idx: Index) -> dict[str, Array]:
        assert self.rotation is not None
        if self.kind == "axis":
            assert self.tool is not None
            return {"R_d": axis.compiled_target(self.rotation[idx].reshape(-1, 3, 3), self.tool)}
        return {"R_d": self.rotation[idx]}

    def _axis_rows(self) -> Array:
        """``D`` ``(2, 3)`` (the cone's boundary: ``(1, 3)``): the axis task's rows of the pose
        functions' orientation residual."""
        assert self.tool is not None
        rows = axis.task_rows(self.tool)
        return rows if self.cone is None else rows[:1]

    def _lift_axis(self, lam: Array) -> Array:
        """The pose functions' six multipliers ``[lam_P; D^T lam_a]`` of the axis task's five."""
        return np.concatenate([lam[:, :3], lam[:, 3:] @ self._axis_rows()], axis=1)

    def _reduce_axis(self, rows: Array, nj: int) -> Array:
        """A pose KKT-residual vector ``(n, nj + 6)`` with its orientation rows projected, ``(n, nj + 5)``."""
        return np.concatenate([rows[:, : nj + 3], rows[:, nj + 3 :] @ self._axis_rows().T], axis=1)

    def forward_frame(self, q: Array) -> tuple[Array, Array]:
        """As :meth:`forward`, with the rotation the task's targets compare with: the end-effector's
        (pose task) or the tool frame's ``C03 B`` (axis task, whose targets are frames ``[w1 w2 d]``)."""
        tip, rotation = self.forward(q)
        if self.kind != "axis":
            return tip, rotation
        assert self.tool is not None
        tool = self.tool if self.cone is None else self.tool @ axis.AXIS_FIRST
        return tip, (rotation.reshape(-1, 3, 3) @ tool).reshape(-1, 9)

    def _motion_inputs(self, idx: Index, suffix: str = "") -> dict[str, Array]:
        assert self.angular_velocity is not None and self.angular_acceleration is not None
        return {"w" + suffix: self.angular_velocity[idx], "a" + suffix: self.angular_acceleration[idx]}

    def evaluate(self, idx: Index, q: Array, lam: Array) -> tuple[Array, Array, Array]:
        """Residual ``c(q) - c_d`` ``(n, m)``, Jacobian ``(n, m, nj)``, ``d^2(lam^T c)/dq^2`` ``(n, nj, nj)``.

        ``idx`` selects the samples (their targets); ``q`` ``(n, nj)`` and ``lam`` ``(n, m)``. With the
        effort criterion the Hessian is that of ``Phi_e + lam^T c`` (see :meth:`evaluate_cost`).
        """
        residual, J, H, _ = self.evaluate_cost(idx, q, lam)
        return residual, J, H

    def evaluate_cost(self, idx: Index, q: Array, lam: Array) -> tuple[Array, Array, Array, Array | None]:
        """As :meth:`evaluate`, plus the gradient ``(n, nj)`` of the model part of the cost, ``Phi_e``
        (None for eq. 12 alone, whose cost the problem evaluates)."""
        n, nj = idx.shape[0], q.shape[1]
        if self.directions is not None:
            return self._evaluate_reduced(idx, q, lam)
        if self.kind == "axis":
            return self._evaluate_axis(idx, q, lam)
        g = None
        if self.effort is not None:
            out = self._evaluate("ik_effort", {"q": q, "lam": lam, **self._effort_inputs(idx)}, n)
            c, J, H, g = out["c"], out["J"], out["H"], out["g"]
            c -= self.position[idx]
        elif self.kind == "position":
            out = self._evaluate("ik_position", {"q": q, "lam": lam}, n)
            c, J, H = out["c"], out["J"], out["H"]
            c -= self.position[idx]
        else:
            out = self._evaluate("ik_pose", {"q": q, "lam": lam, **self._orientation_inputs(idx)}, n)
            c, J, H = out["c"], out["J"], out["H"]
            c[:, :3] -= self.position[idx]
        return c, J.reshape(n, self.m, nj), H.reshape(n, nj, nj), g

    def _evaluate_axis(self, idx: Index, q: Array, lam: Array) -> tuple[Array, Array, Array, Array | None]:
        """:meth:`evaluate_cost` of the axis task: the pose functions at ``M = F K B^T``, rows projected.

        With the effort criterion the Lagrangian is the effort functions' (``Phi_e`` and the tip's rows,
        ``ik_effort``) plus the pose functions' at the orientation multipliers alone: the Hessians add."""
        n, nj = idx.shape[0], q.shape[1]
        lifted = self._lift_axis(lam)
        if self.effort is not None:
            lifted[:, :3] = 0.0  # the tip's rows are the effort functions'
        out = self._evaluate("ik_pose", {"q": q, "lam": lifted, **self._orientation_inputs(idx)}, n)
        c = self._reduce_axis(out["c"], 0)
        c[:, :3] -= self.position[idx]
        if self.cone is not None:
            c[:, 3] -= self.cone
        J = out["J"].reshape(n, 6, nj)
        J = np.concatenate([J[:, :3], np.einsum("rk,nkj->nrj", self._axis_rows(), J[:, 3:])], axis=1)
        H, g = out["H"].reshape(n, nj, nj), None
        if self.effort is not None:
            effort = self._evaluate("ik_effort", {"q": q, "lam": lam[:, :3], **self._effort_inputs(idx)}, n)
            H = H + effort["H"].reshape(n, nj, nj)
            g = effort["g"]
        return c, J, H, g

    def _evaluate_reduced(self, idx: Index, q: Array, lam: Array) -> tuple[Array, Array, Array, Array | None]:
        """:meth:`evaluate_cost` of a reduced position task: the three-row functions at ``E^T lam``, projected."""
        assert self.directions is not None
        n, nj = idx.shape[0], q.shape[1]
        lifted = self._lift(lam)
        g = None
        if self.effort is not None:
            out = self._evaluate("ik_effort", {"q": q, "lam": lifted, **self._effort_inputs(idx)}, n)
            g = out["g"]
        else:
            out = self._evaluate("ik_position", {"q": q, "lam": lifted}, n)
        c = (out["c"] - self.position[idx]) @ self.directions.T
        J = np.einsum("rk,nkj->nrj", self.directions, out["J"].reshape(n, 3, nj))
        return c, J, out["H"].reshape(n, nj, nj), g

    def effort_cost(self, idx: Index, q: Array) -> Array:
        """``Phi_e`` ``(n,)`` of ``q`` ``(n, nj)`` at samples ``idx`` (zeros without the effort criterion)."""
        if self.effort is None:
            return np.zeros(q.shape[0])
        return self.static_efforts(idx, q)[1]

    def static_efforts(self, idx: Index, q: Array) -> tuple[Array, Array]:
        """Static efforts ``tau`` ``(n, nj)`` against gravity and the expected tool force, and ``Phi_e`` ``(n,)``."""
        assert self.effort is not None
        out = self._evaluate("ik_effort_static", {"q": q, **self._effort_inputs(idx)}, q.shape[0])
        return out["tau"], out["phi"][:, 0]

    def _effort_inputs(self, idx: Index, rates: bool = False) -> dict[str, Array]:
        assert self.effort is not None
        inputs = {"f": self.effort.force[idx], "s": self.effort.scale}
        if rates:
            inputs.update(fd=self.effort.force_rate[idx], fdd=self.effort.force_acceleration[idx])
        return inputs

    def evaluate_with_rates(
        self, idx: Index, q: Array, lam: Array, weight: Array
    ) -> tuple[Array, Array, Array, Array | None, tuple[Array, Array, Array, Array]]:
        """As :meth:`evaluate_cost`, plus the exact ``(qd, lam_d, qdd, lam_dd)`` for no active inequality.

        One compiled call (``ik_position_rates`` / ``ik_pose_rates`` / ``ik_effort_rates``) per sample;
        ``weight`` ``(nj,)`` is the diagonal of the Hessian of ``Phi``. The rates are valid only where
        ``(q, lam)`` is a solution with no active limit or triangle row.
        """
        if not self.compiled_rates:
            raise InputError("a reduced task's rates are not compiled; use evaluate_cost and vgtarm.ik.rates.exact")
        n, nj = idx.shape[0], q.shape[1]
        inputs = {"q": q, "lam": lam, "w": weight, "xd": self.velocity[idx], "xdd": self.acceleration[idx]}
        if self.effort is not None:
            out = self._evaluate("ik_effort_rates", {**inputs, **self._effort_inputs(idx, rates=True)}, n)
            out["c"] -= self.position[idx]
        elif self.kind == "position":
            out = self._evaluate("ik_position_rates", inputs, n)
            out["c"] -= self.position[idx]
        else:
            inputs.update(self._orientation_inputs(idx), **self._motion_inputs(idx, "_d"))
            out = self._evaluate("ik_pose_rates", inputs, n)
            out["c"][:, :3] -= self.position[idx]
        rates = (out["qd"], out["lam_d"], out["qdd"], out["lam_dd"])
        g = out.get("g")
        return out["c"], out["J"].reshape(n, self.m, nj), out["H"].reshape(n, nj, nj), g, rates

    def first_order_rhs(self, idx: Index, q: Array, lam: Array) -> Array:
        """``-dF/dt`` at fixed ``(q, lam)`` of the KKT residual ``F = [grad L; c - c_d]``, ``(n, nj + m)``."""
        n, nj = idx.shape[0], q.shape[1]
        if self.directions is not None:
            rhs = np.zeros((n, nj + 3))
            rhs[:, nj:] = self.velocity[idx]
            if self.effort is not None:
                inputs = {"q": q, "lam": self._lift(lam), **self._effort_inputs(idx), "fd": self.effort.force_rate[idx]}
                rhs -= self._evaluate("ik_effort_dt", inputs, n)["dt"]
            return self._reduce(rhs, nj)
        if self.kind == "axis":
            return self._axis_first_order_rhs(idx, q, lam)
        rhs = np.zeros((n, nj + self.m))
        rhs[:, nj : nj + 3] = self.velocity[idx]
        if self.effort is not None:
            inputs = {"q": q, "lam": lam, **self._effort_inputs(idx), "fd": self.effort.force_rate[idx]}
            rhs -= self._evaluate("ik_effort_dt", inputs, n)["dt"]
        elif self.kind == "pose":
            inputs = {"q": q, "lam": lam, **self._orientation_inputs(idx), **self._motion_inputs(idx)}
            rhs -= self._evaluate("ik_pose_dt", inputs, n)["dt"]
        return rhs

    def _axis_first_order_rhs(self, idx: Index, q: Array, lam: Array) -> Array:
        """:meth:`first_order_rhs` of the axis task: the pose functions' (the tip's rows do not depend on
        time at fixed ``q``), plus with the effort criterion the effort functions' (the force's rate)."""
        n, nj = idx.shape[0], q.shape[1]
        full = np.zeros((n, nj + 6))
        full[:, nj : nj + 3] = self.velocity[idx]
        inputs = {"q": q, "lam": self._lift_axis(lam), **self._orientation_inputs(idx), **self._motion_inputs(idx)}
        full -= self._evaluate("ik_pose_dt", inputs, n)["dt"]
        if self.effort is not None:
            inputs = {"q": q, "lam": lam[:, :3], **self._effort_inputs(idx), "fd": self.effort.force_rate[idx]}
            full[:, : nj + 3] -= self._evaluate("ik_effort_dt", inputs, n)["dt"]
        return self._reduce_axis(full, nj)

    def second_order_rhs(self, idx: Index, q: Array, lam: Array, qd: Array, lam_d: Array) -> Array:
        """``-d^2/dt^2 F(q + t qd, lam + t lam_d, t)`` at ``t = 0``, ``(n, nj + m)``.

        With ``K [qdd; lam_dd] = this`` (active set fixed), ``(qdd, lam_dd)`` are the second
        derivatives of the optimum along the path.
        """
        n = idx.shape[0]
        if self.kind == "axis":
            return self._axis_second_order_rhs(idx, q, lam, qd, lam_d)
        if self.directions is not None:
            lam, lam_d = self._lift(lam), self._lift(lam_d)
        inputs = {"q": q, "lam": lam, "qd": qd, "lam_d": lam_d}
        if self.effort is not None:
            d2 = self._evaluate("ik_effort_d2", {**inputs, **self._effort_inputs(idx, rates=True)}, n)["d2"]
        elif self.kind == "position":
            d2 = self._evaluate("ik_position_d2", inputs, n)["d2"]
        else:
            inputs.update(self._orientation_inputs(idx), **self._motion_inputs(idx))
            d2 = self._evaluate("ik_pose_d2", inputs, n)["d2"]
        rhs = -d2
        nj = q.shape[1]
        rhs[:, nj : nj + 3] += self.acceleration[idx]
        return rhs if self.directions is None else self._reduce(rhs, nj)

    def _axis_second_order_rhs(self, idx: Index, q: Array, lam: Array, qd: Array, lam_d: Array) -> Array:
        """:meth:`second_order_rhs` of the axis task; with the effort criterion the stationarity rows
        add the effort functions' (``Phi_e`` and the tip's rows, at the tip's multipliers) to the pose
        functions' at the orientation multipliers alone."""
        n, nj = idx.shape[0], q.shape[1]
        lifted, lifted_d = self._lift_axis(lam), self._lift_axis(lam_d)
        if self.effort is not None:
            lifted[:, :3] = lifted_d[:, :3] = 0.0
        inputs = {"q": q, "lam": lifted, "qd": qd, "lam_d": lifted_d}
        inputs.update(self._orientation_inputs(idx), **self._motion_inputs(idx))
        d2 = self._evaluate("ik_pose_d2", inputs, n)["d2"]
        if self.effort is not None:
            inputs = {
                "q": q,
                "lam": lam[:, :3],
                "qd": qd,
                "lam_d": lam_d[:, :3],
                **self._effort_inputs(idx, rates=True),
            }
            d2[:, :nj] += self._evaluate("ik_effort_d2", inputs, n)["d2"][:, :nj]
        rhs = -d2
        rhs[:, nj : nj + 3] += self.acceleration[idx]
        return self._reduce_axis(rhs, nj)


@dataclass
class BatchState:
    """Mutable per-sample arrays, all with ``N`` rows, updated in place by the solvers.

    Attributes:
        q: ``(N, n)`` joint values.
        lam: ``(N, m)`` multipliers of the equality rows.
        mu: ``(N, 2 n + k)`` multipliers of the inequalities (>= 0), in the problem's order.
        active: ``(N, 2 n + k)`` active flags of the inequalities.
        residual, J, H: ``(N, m)``, ``(N, m, n)``, ``(N, n, n)`` task residual, Jacobian and
            ``d^2(lam^T c)/dq^2`` at ``(q, lam)`` (valid where ``evaluated``).
        iterations: ``(N,)`` Newton (or solver) iterations spent on each sample.
        converged: ``(N,)`` whether the sample met the Newton stopping test.
        method: ``(N,)`` name of the method that produced each sample.
        qd, qdd, lam_d, lam_dd: exact rates of ``q`` and ``lam`` where ``rates_ready``.
        rates_ready: ``(N,)`` whether the exact rates of a sample are computed.
        g: ``(N, n)`` gradient of the model part of the cost (``Phi_e``, effort criterion) at ``q``
            (valid where ``evaluated``), or None for eq. 12 alone.
    """

    q: Array
    lam: Array
    mu: Array
    active: NDArray[np.bool_]
    residual: Array
    J: Array
    H: Array
    iterations: NDArray[np.int64]
    converged: NDArray[np.bool_]
    method: NDArray[np.str_]
    qd: Array
    qdd: Array
    lam_d: Array
    lam_dd: Array
    rates_ready: NDArray[np.bool_]
    g: Array | None = None

    @classmethod
    def empty(
        cls, n: int, m: int, n_inequalities: int, n_joints: int = N_JOINTS, with_gradient: bool = False
    ) -> BatchState:
        nj = n_joints
        return cls(
            q=np.zeros((n, nj)),
            lam=np.zeros((n, m)),
            mu=np.zeros((n, n_inequalities)),
            active=np.zeros((n, n_inequalities), dtype=bool),
            residual=np.full((n, m), np.nan),
            J=np.full((n, m, nj), np.nan),
            # zeros, not NaN: a long arm's H is gigabytes, and np.zeros leaves the pages to be written
            # once by the model (an unevaluated sample is refused by its NaN residual and J)
            H=np.zeros((n, nj, nj)),
            iterations=np.zeros(n, dtype=np.int64),
            converged=np.zeros(n, dtype=bool),
            method=np.full(n, "", dtype="<U24"),
            qd=np.zeros((n, nj)),
            qdd=np.zeros((n, nj)),
            lam_d=np.zeros((n, m)),
            lam_dd=np.zeros((n, m)),
            rates_ready=np.zeros(n, dtype=bool),
            g=np.full((n, nj), np.nan) if with_gradient else None,
        )
