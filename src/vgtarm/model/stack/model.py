"""Numerical evaluation of a stack's symbolic model through CasADi functions (no compilation yet).

:class:`StackModel` builds the CasADi functions of one stack once and evaluates them for one
configuration at a time (arrays of shape ``(n_joints,)``). Forward dynamics solves ``M qdd = rhs``
with a Cholesky factorisation in NumPy (``M`` is symmetric positive definite), so its cost does
not grow with a symbolic factorisation of an ``n x n`` matrix.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import AssemblyError, InputError, shown
from ..assembly import TRIANGLE_INEQUALITIES
from ..sanity import as_float, real_array
from ..symbolic import SX, row_major
from .description import LEG_NAMES, Stack, stack_margins
from .symbolic import stack_dynamics, stack_kinematics

Array = NDArray[np.float64]


@dataclass(frozen=True)
class StackForwardKinematics:
    """Forward kinematics of one configuration of a stack with ``m`` modules.

    Attributes:
        passive: ``(m, 4)`` passive angles ``(alpha, beta, gamma, theta)`` of each module (rad).
        platform_position: ``(m, 3)`` platform centres in F0 (m).
        platform_rotation: ``(m, 3, 3)`` orientations of the platform frames.
        tip: ``(3,)`` tool point in F0 (m).
        rotation: ``(3, 3)`` end-effector orientation (the frame of the last stage).
    """

    passive: Array
    platform_position: Array
    platform_rotation: Array
    tip: Array
    rotation: Array


class StackModel:
    """The symbolic model of a :class:`Stack`, evaluated numerically one configuration at a time.

    Every method refuses, with :class:`~vgtarm.errors.InputError`, arrays of the wrong length or
    not finite and, with :class:`~vgtarm.errors.AssemblyError`, leg sets that cannot be assembled.
    """

    def __init__(self, stack: Stack) -> None:
        if not isinstance(stack, Stack):
            raise InputError(f"stack = {shown(stack)}: expected a Stack (see vgtarm.model.stack.load_stack)")
        self.stack = stack
        self.n = stack.n_joints
        self.parameters = stack.vector()
        q, qd = SX.sym("q", self.n), SX.sym("qd", self.n)
        p = SX.sym("p", stack.n_parameters)
        kin = stack_kinematics(stack, q, p)
        dyn = stack_dynamics(stack, q, qd, p)
        self._fk = ca.Function(
            "stack_fk",
            [q, p],
            [
                kin.passive,
                ca.vertcat(*kin.platform_origins),
                ca.vertcat(*[row_major(r) for r in kin.platform_rotations]),
                kin.tip,
                row_major(kin.end_effector_rotation),
            ],
        )
        self._jac = ca.Function("stack_jac", [q, p], [dyn.J_P, dyn.J_W])
        self._mass = ca.Function("stack_mass", [q, p], [dyn.M])
        self._bias = ca.Function("stack_bias", [q, qd, p], [dyn.C])
        self._energy = ca.Function("stack_energy", [q, qd, p], [dyn.kinetic_energy, dyn.potential_energy])
        self._dynamics = ca.Function("stack_dynamics", [q, qd, p], [dyn.M, dyn.C, dyn.J_P, dyn.J_W])

    def __repr__(self) -> str:
        return f"StackModel({self.stack.name!r}, {self.stack.n_modules} modules, {self.n} joints)"

    # -- checks ----------------------------------------------------------------------------

    def _vector(self, value: ArrayLike, name: str, size: int) -> Array:
        """``value`` as ``(size,)`` floats: real numbers only (complex, ``None``, text and booleans
        refused with the user's own value, as :class:`~vgtarm.model.robot.Robot` does), finite."""
        names = self.stack.joint_names if size == self.n else ()
        raw = real_array(value, name, size, names)
        if raw.shape != (size,):
            raise InputError(f"{name} must have shape ({size},), got shape {raw.shape}")
        array = as_float(raw)
        if not np.isfinite(array).all():
            i = int(np.argmin(np.isfinite(array)))
            label = f" ({self.stack.joint_names[i]})" if size == self.n else ""
            raise InputError(f"{name} must be finite; {name}[{i}]{label} = {array[i]}")
        return array

    def _configuration(self, q: ArrayLike) -> Array:
        qa = self._vector(q, "q", self.n)
        margins = stack_margins(self.stack, qa)
        if not (margins > 0.0).all():
            k, row = np.unravel_index(int(np.argmin(margins)), margins.shape)
            legs = ", ".join(
                f"{leg}{k + 1} = {qa[i]:.6g}" for leg, i in zip(LEG_NAMES, self.stack.leg_indices[k], strict=True)
            )
            raise AssemblyError(
                f"q: module {k + 1} cannot be assembled: '{TRIANGLE_INEQUALITIES[row]}' fails "
                f"(margin {margins[k, row]:.6g} m; {legs})"
            )
        return qa

    # -- kinematics ------------------------------------------------------------------------

    def forward_kinematics(self, q: ArrayLike) -> StackForwardKinematics:
        """Passive angles, platform frames, tip point and end-effector orientation."""
        out = [np.asarray(x, dtype=float).ravel() for x in self._fk(self._configuration(q), self.parameters)]
        m = self.stack.n_modules
        return StackForwardKinematics(
            passive=out[0].reshape(m, 4),
            platform_position=out[1].reshape(m, 3),
            platform_rotation=out[2].reshape(m, 3, 3),
            tip=out[3],
            rotation=out[4].reshape(3, 3),
        )

    def tip_position(self, q: ArrayLike) -> Array:
        """Tool point in F0, ``(3,)`` (m)."""
        return self.forward_kinematics(q).tip

    def jacobians(self, q: ArrayLike) -> tuple[Array, Array]:
        """Tip Jacobian ``J_P = dP/dq`` and end-effector angular Jacobian ``J_W``, ``(3, n)`` each."""
        jp, jw = self._jac(self._configuration(q), self.parameters)
        return np.asarray(jp, dtype=float), np.asarray(jw, dtype=float)

    # -- dynamics --------------------------------------------------------------------------

    def mass_matrix(self, q: ArrayLike) -> Array:
        """Mass matrix ``M(q)``, ``(n, n)``."""
        return np.asarray(self._mass(self._configuration(q), self.parameters), dtype=float)

    def bias_forces(self, q: ArrayLike, qd: ArrayLike) -> Array:
        """``C(q, qd)``: velocity products + gravity + viscous friction, ``(n,)``."""
        qa, qda = self._configuration(q), self._vector(qd, "qd", self.n)
        return np.asarray(self._bias(qa, qda, self.parameters), dtype=float).ravel()

    def gravity_forces(self, q: ArrayLike) -> Array:
        """Gravity term of ``C`` (``C(q, 0)``), ``(n,)``."""
        return self.bias_forces(q, np.zeros(self.n))

    def energy(self, q: ArrayLike, qd: ArrayLike) -> tuple[float, float]:
        """Kinetic and potential (gravity) energy (J)."""
        qa, qda = self._configuration(q), self._vector(qd, "qd", self.n)
        kinetic, potential = self._energy(qa, qda, self.parameters)
        return float(kinetic), float(potential)

    def _wrench(self, f_tip: ArrayLike | None, m_tip: ArrayLike | None) -> tuple[Array, Array]:
        f = np.zeros(3) if f_tip is None else self._vector(f_tip, "f_tip", 3)
        m = np.zeros(3) if m_tip is None else self._vector(m_tip, "m_tip", 3)
        return f, m

    def forward_dynamics(
        self, q: ArrayLike, qd: ArrayLike, F: ArrayLike, f_tip: ArrayLike | None = None, m_tip: ArrayLike | None = None
    ) -> Array:
        """Joint accelerations ``M^-1 (F + J_P^T f_tip + J_W^T m_tip - C)``, ``(n,)``.

        ``f_tip`` (N) acts on the end-effector at the tip point and ``m_tip`` (N m) on its body,
        both in F0; each defaults to zero.
        """
        qa, qda, Fa = self._configuration(q), self._vector(qd, "qd", self.n), self._vector(F, "F", self.n)
        f, m = self._wrench(f_tip, m_tip)
        M, C, jp, jw = (np.asarray(x, dtype=float) for x in self._dynamics(qa, qda, self.parameters))
        rhs = Fa + jp.T @ f + jw.T @ m - C.ravel()
        factor = np.linalg.cholesky(M)
        return np.linalg.solve(factor.T, np.linalg.solve(factor, rhs))

    def inverse_dynamics(
        self,
        q: ArrayLike,
        qd: ArrayLike,
        qdd: ArrayLike,
        f_tip: ArrayLike | None = None,
        m_tip: ArrayLike | None = None,
    ) -> Array:
        """Actuator efforts ``M qdd + C - J_P^T f_tip - J_W^T m_tip`` that produce ``qdd``, ``(n,)``."""
        qa, qda, qdda = self._configuration(q), self._vector(qd, "qd", self.n), self._vector(qdd, "qdd", self.n)
        f, m = self._wrench(f_tip, m_tip)
        M, C, jp, jw = (np.asarray(x, dtype=float) for x in self._dynamics(qa, qda, self.parameters))
        return M @ qdda + C.ravel() - jp.T @ f - jw.T @ m
