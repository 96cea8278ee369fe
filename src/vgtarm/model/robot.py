"""The user-facing robot: parameters plus the compiled model, with batch-first methods.

Every method takes arrays whose last axis is the joint (or force) vector and broadcasts over the
leading axes: ``q`` of shape ``(..., 7)`` gives results of shape ``(..., ...)``. One call on a
batch runs one compiled loop, so prefer batches to Python loops over single configurations.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError, shown
from .assembly import check_assembly, triangle_margins
from .compiled import CompiledBackend, InterpretedBackend, get_backend
from .parameters import JOINT_NAMES, RobotParameters, load_parameters
from .sanity import check_joint_range, sane_range

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ForwardKinematics:
    """Forward kinematics of a batch of configurations (leading shape ``S``).

    Attributes:
        passive: ``S + (2, 4)`` passive angles ``(alpha, beta, gamma, theta)`` of each module (rad).
        platform_position: ``S + (2, 3)`` platform centres O1, O2 in F0 (m).
        platform_rotation: ``S + (2, 3, 3)`` orientations C01, C02 of the platform frames.
        tip: ``S + (3,)`` tip point P in F0 (m).
        rotation: ``S + (3, 3)`` end-effector orientation C03.
    """

    passive: Array
    platform_position: Array
    platform_rotation: Array
    tip: Array
    rotation: Array


@dataclass(frozen=True)
class BiasAccelerations:
    """Velocity-product ("bias") accelerations, i.e. accelerations when ``qdd = 0``.

    Attributes:
        tip: ``S + (3,)`` of the tip point (m/s^2), so ``a_tip = J_P qdd + tip``.
        angular: ``S + (3,)`` of the end-effector frame (rad/s^2).
        com: ``S + (3, 3)`` of each body's centre of mass (bodies 7, 8, 9).
        body_angular: ``S + (3, 3)`` of each body frame.
    """

    tip: Array
    angular: Array
    com: Array
    body_angular: Array


#: Arguments whose last axis is the joint vector (messages name the joint).
_JOINT_VECTORS = frozenset({"q", "qd", "qdd", "F"})


def _as_array(value: ArrayLike, name: str, last: int, finite: bool = True) -> Array:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{name} must be an array of numbers, got {shown(value)}") from None
    if array.ndim == 0 or array.shape[-1] != last:
        raise InputError(f"{name} must have shape (..., {last}), got shape {array.shape}")
    if finite and not np.isfinite(array).all():
        index = np.argwhere(~np.isfinite(array))[0]
        joint = f" ({JOINT_NAMES[index[-1]]})" if name in _JOINT_VECTORS and last == len(JOINT_NAMES) else ""
        raise InputError(f"{name} must be finite; {name}[{', '.join(map(str, index))}]{joint} = {array[tuple(index)]}")
    return array


class Robot:
    """A manipulator model: :class:`RobotParameters` evaluated through the compiled backend.

    Build one with :func:`load_robot`. ``robot.with_parameters(p)`` gives a robot with other
    parameters sharing the same compiled code (for example a controller's imperfect model).

    Every method taking joint values ``q`` refuses, with :class:`~vgtarm.errors.InputError`,
    values that are not finite or lie outside the accepted range :meth:`joint_range` (lengths
    within ten spans of their limits and >= 0, angles within 1000 turns: see
    :mod:`vgtarm.model.sanity`), and, with
    :class:`~vgtarm.errors.AssemblyError`, leg sets that cannot be assembled.
    """

    def __init__(
        self,
        parameters: RobotParameters,
        backend: CompiledBackend | InterpretedBackend | None = None,
    ) -> None:
        if not isinstance(parameters, RobotParameters):
            raise InputError(f"parameters = {shown(parameters)}: expected RobotParameters (see vgtarm.load_parameters)")
        self.parameters = parameters
        self.backend = backend if backend is not None else get_backend()
        self._p = parameters.vector()
        self._low, self._high = sane_range(parameters)

    def __repr__(self) -> str:
        return f"Robot({self.parameters.name!r}, backend={self.backend.kind!r})"

    @property
    def fingerprint(self) -> str:
        """A short hash (12 hex digits) of the parameters and joint limits: two robots with the same
        fingerprint have the same model. Results record it (an IK result says which robot it was
        solved for)."""
        digest = hashlib.sha256(np.ascontiguousarray(self._p, dtype="<f8").tobytes())
        limits = [self.parameters.lower, self.parameters.upper]
        digest.update(np.ascontiguousarray(limits, dtype="<f8").tobytes())
        return digest.hexdigest()[:12]

    @property
    def parameter_vector(self) -> Array:
        """The flat parameter vector (45,) given to the compiled functions."""
        return self._p.copy()

    def with_parameters(self, parameters: RobotParameters) -> Robot:
        """A robot with other parameters and the same compiled model."""
        return Robot(parameters, self.backend)

    def joint_range(self) -> tuple[Array, Array]:
        """Lowest and highest joint values the methods accept, ``(7,)`` each (m, rad).

        The joint limits widened on each side by :data:`~vgtarm.model.sanity.SANE_WIDENING`
        times their span for lengths (at least 0), by :data:`~vgtarm.model.sanity.SANE_TURNS`
        turns for angles; beyond, values are refused as not a configuration.
        """
        return self._low.copy(), self._high.copy()

    def in_joint_range(self, q: ArrayLike) -> NDArray[np.bool_]:
        """Whether each configuration ``(..., 7)`` is finite and inside :meth:`joint_range`."""
        qa = _as_array(q, "q", 7, finite=False)
        return np.asarray(((qa >= self._low) & (qa <= self._high)).all(axis=-1))

    # -- helpers -----------------------------------------------------------------------------

    def _evaluate(
        self, name: str, named: list[tuple[str, ArrayLike, int]], check_q: bool = True
    ) -> tuple[tuple[int, ...], list[Array]]:
        arrays = [_as_array(value, label, size) for label, value, size in named]
        try:
            shape = np.broadcast_shapes(*[a.shape[:-1] for a in arrays])
        except ValueError:
            shapes = ", ".join(f"{label} {a.shape}" for (label, _, _), a in zip(named, arrays, strict=True))
            raise InputError(f"leading shapes do not broadcast: {shapes}") from None
        if check_q:
            check_joint_range(arrays[0], self.parameters, (self._low, self._high), where=named[0][0])
            check_assembly(arrays[0], self.parameters.b, self.parameters.d, where=named[0][0])
        n = int(np.prod(shape, dtype=int))
        flat = [np.broadcast_to(a, shape + a.shape[-1:]).reshape(n, a.shape[-1]) for a in arrays]
        outputs = self.backend.evaluate(name, [*flat, self._p], n)
        return shape, outputs

    def evaluate(self, name: str, inputs: Mapping[str, ArrayLike], n: int) -> dict[str, Array]:
        """Evaluate the compiled function ``name`` on ``n`` samples, inputs and outputs by name.

        ``inputs`` maps each input name of the function but ``p`` (the robot's parameters, added
        here) to an ``(n, size)`` array or a ``(size,)`` value shared by every sample. Returns
        ``{output name: (n, size)}``. This is how layers above (inverse kinematics) reach the
        generated functions that have no method of their own.
        """
        try:
            sig = self.backend.signature(name)
        except (KeyError, TypeError):
            raise InputError(f"evaluate: no compiled function named {shown(name)}") from None
        wanted = [label for label in sig.in_names if label != "p"]
        unknown = sorted(set(inputs) - set(wanted))
        missing = [label for label in wanted if label not in inputs]
        if unknown or missing:
            raise InputError(f"{name}: inputs {wanted} expected, got unknown {unknown} and missing {missing}")
        arrays = [np.asarray(inputs[label], dtype=np.float64) for label in wanted]
        outputs = self.backend.evaluate(name, [*arrays, self._p], n)
        return dict(zip(sig.out_names, outputs, strict=True))

    # -- kinematics --------------------------------------------------------------------------

    def is_assemblable(self, q: ArrayLike, margin: float = 0.0) -> NDArray[np.bool_]:
        """Whether each configuration ``(..., 7)`` can be assembled with the given margin (m)."""
        qa = _as_array(q, "q", 7)
        if isinstance(margin, bool) or not isinstance(margin, int | float | np.integer | np.floating):
            raise InputError(f"margin = {shown(margin)}: expected a length (m)")
        return np.asarray((triangle_margins(qa, self.parameters.b, self.parameters.d) > margin).all(axis=-1))

    def forward_kinematics(self, q: ArrayLike) -> ForwardKinematics:
        """Passive angles, platform frames, tip point and orientation (paper eqs. 1-11)."""
        shape, out = self._evaluate("fk", [("q", q, 7)])
        passive, o1, c01, o2, c02, tip, c03 = out
        return ForwardKinematics(
            passive=passive.reshape(shape + (2, 4)),
            platform_position=np.stack([o1, o2], axis=1).reshape(shape + (2, 3)),
            platform_rotation=np.stack([c01, c02], axis=1).reshape(shape + (2, 3, 3)),
            tip=tip.reshape(shape + (3,)),
            rotation=c03.reshape(shape + (3, 3)),
        )

    def tip_position(self, q: ArrayLike) -> Array:
        """Tip point P in F0, ``(..., 3)`` (m). Cheaper than the full forward kinematics."""
        shape, (tip,) = self._evaluate("tip", [("q", q, 7)])
        return tip.reshape(shape + (3,))

    def tip_jacobian(self, q: ArrayLike) -> Array:
        """Translational Jacobian of the tip ``J_P = dP/dq``, ``(..., 3, 7)``."""
        shape, (jp, _) = self._evaluate("jac", [("q", q, 7)])
        return jp.reshape(shape + (3, 7))

    def tip_hessian(self, q: ArrayLike) -> Array:
        """Second derivatives of the tip point ``d^2 P_k / dq_l dq_m``, ``(..., 3, n, n)``."""
        n = self.parameters.home.shape[-1]
        shape, (h,) = self._evaluate("tip_hessian", [("q", q, n)])
        return h.reshape(shape + (3, n, n))

    def angular_jacobian(self, q: ArrayLike) -> Array:
        """Angular Jacobian of the end-effector (F0 components), ``(..., 3, 7)``."""
        shape, (_, jw) = self._evaluate("jac", [("q", q, 7)])
        return jw.reshape(shape + (3, 7))

    def com_jacobians(self, q: ArrayLike) -> tuple[Array, Array]:
        """Jacobians of the bodies' centres of mass and angular velocities, each ``(..., 3, 3, 7)``.

        Axis ``-3`` is the body (platform 1, platform 2, end-effector).
        """
        shape, (jv, jw) = self._evaluate("com_jac", [("q", q, 7)])
        return jv.reshape(shape + (3, 3, 7)), jw.reshape(shape + (3, 3, 7))

    def tip_velocity(self, q: ArrayLike, qd: ArrayLike) -> tuple[Array, Array]:
        """Tip velocity ``J_P qd`` (m/s) and end-effector angular velocity (rad/s), ``(..., 3)`` each."""
        shape, (v, w) = self._evaluate("velocity", [("q", q, 7), ("qd", qd, 7)])
        return v.reshape(shape + (3,)), w.reshape(shape + (3,))

    def bias_accelerations(self, q: ArrayLike, qd: ArrayLike) -> BiasAccelerations:
        """Accelerations due to ``qd`` alone (``qdd = 0``): ``Jdot qd`` of the tip and bodies."""
        shape, (tip, ang, com, body_ang) = self._evaluate("bias_acc", [("q", q, 7), ("qd", qd, 7)])
        return BiasAccelerations(
            tip=tip.reshape(shape + (3,)),
            angular=ang.reshape(shape + (3,)),
            com=com.reshape(shape + (3, 3)),
            body_angular=body_ang.reshape(shape + (3, 3)),
        )

    def inverse_kinematics(self, path: Any, **options: Any) -> Any:
        """Convenience for :func:`vgtarm.ik.inverse_kinematics` ``(self, path, **options)``.

        The model layer does not depend on inverse kinematics: the ``ik`` package is imported
        only when this method is called (``import vgtarm.model`` never loads it).
        """
        from ..ik import inverse_kinematics  # the one upward reference, resolved at call time

        return inverse_kinematics(self, path, **options)

    # -- dynamics ----------------------------------------------------------------------------

    def mass_matrix(self, q: ArrayLike) -> Array:
        """Mass matrix ``M(q)`` of eq. 15, ``(..., 7, 7)``."""
        shape, (m,) = self._evaluate("mass", [("q", q, 7)])
        return m.reshape(shape + (7, 7))

    def bias_forces(self, q: ArrayLike, qd: ArrayLike) -> Array:
        """``C(q, qd)`` of eq. 15: velocity products + gravity + viscous friction, ``(..., 7)``."""
        shape, (c,) = self._evaluate("bias_forces", [("q", q, 7), ("qd", qd, 7)])
        return c.reshape(shape + (7,))

    def forward_dynamics(self, q: ArrayLike, qd: ArrayLike, F: ArrayLike, f_tip: ArrayLike | None = None) -> Array:
        """Joint accelerations ``M^-1 (F + J_P^T f_tip - C)``, ``(..., 7)``.

        ``F`` are the actuator efforts (N, and N m for the twist); ``f_tip`` the force acting
        on the end-effector at the tip point, in F0 (N), default zero.
        """
        f = np.zeros(3) if f_tip is None else f_tip
        shape, (qdd,) = self._evaluate("fd", [("q", q, 7), ("qd", qd, 7), ("F", F, 7), ("f_tip", f, 3)])
        return qdd.reshape(shape + (7,))

    def inverse_dynamics(self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, f_tip: ArrayLike | None = None) -> Array:
        """Actuator efforts ``M qdd + C - J_P^T f_tip`` that produce ``qdd``, ``(..., 7)``."""
        f = np.zeros(3) if f_tip is None else f_tip
        shape, (F,) = self._evaluate("id", [("q", q, 7), ("qd", qd, 7), ("qdd", qdd, 7), ("f_tip", f, 3)])
        return F.reshape(shape + (7,))

    def energy(self, q: ArrayLike, qd: ArrayLike) -> tuple[Array, Array]:
        """Kinetic and potential (gravity) energy, each of shape ``(...)`` (J)."""
        shape, (t, v) = self._evaluate("energy", [("q", q, 7), ("qd", qd, 7)])
        return t.reshape(shape), v.reshape(shape)


def load_robot(config: str | Path | None = None) -> Robot:
    """Load a robot: the shipped reference robot, or the TOML file ``config``."""
    return Robot(load_parameters(config))
