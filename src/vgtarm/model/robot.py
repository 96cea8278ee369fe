"""The user-facing robot: parameters plus the compiled model, with batch-first methods.

Every method takes arrays whose last axis is the joint (or force) vector and broadcasts over the
leading axes: ``q`` of shape ``(..., n)`` gives results of shape ``(..., ...)``, ``n`` the robot's
number of joints (7 for the paper's robot, :attr:`Robot.n_joints`). One call on a batch runs one
compiled loop, so prefer batches to Python loops over single configurations.

A robot is the paper's (:class:`RobotParameters`, the fixed 7-joint model) or any stack of modules
(:class:`~vgtarm.model.stack.Stack`, read by :func:`load_robot` from a file with ``[[modules]]``
tables): both go through the same code generation and compiled backend, a stack with a library of
its own per structure (:mod:`vgtarm.model.definition`).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ConfigError, InputError, cut, shown
from ..fileio import parse_toml, read_text_limited
from .assembly import check_margins
from .compiled import CompiledBackend, InterpretedBackend, get_backend
from .definition import PAPER, Definition, StackDefinition
from .parameters import ROBOT_FILE_LIMIT, RobotParameters, load_parameters, parameters_from_dict
from .sanity import check_joint_range, sane_range
from .stack.description import Stack, stack_from_dict

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ForwardKinematics:
    """Forward kinematics of a batch of configurations (leading shape ``S``).

    Attributes (``m`` modules: 2 for the paper's robot):
        passive: ``S + (m, 4)`` passive angles ``(alpha, beta, gamma, theta)`` of each module (rad).
        platform_position: ``S + (m, 3)`` platform centres O1, O2, ... in F0 (m).
        platform_rotation: ``S + (m, 3, 3)`` orientations C01, C02, ... of the platform frames.
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
        com: ``S + (b, 3)`` of each body's centre of mass (the paper's bodies 7, 8, 9; a stack's
            in the order of its ``body_names``).
        body_angular: ``S + (b, 3)`` of each body frame.
    """

    tip: Array
    angular: Array
    com: Array
    body_angular: Array


#: Arguments whose last axis is the joint vector (messages name the joint).
_JOINT_VECTORS = frozenset({"q", "qd", "qdd", "F"})


def _as_array(
    value: ArrayLike, name: str, last: int, finite: bool = True, names: tuple[str, ...] = ()
) -> Array:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{name} must be an array of numbers, got {shown(value)}") from None
    if array.ndim == 0 or array.shape[-1] != last:
        raise InputError(f"{name} must have shape (..., {last}), got shape {array.shape}")
    if finite and not np.isfinite(array).all():
        index = np.argwhere(~np.isfinite(array))[0]
        joint = f" ({names[index[-1]]})" if name in _JOINT_VECTORS and last == len(names) else ""
        raise InputError(f"{name} must be finite; {name}[{', '.join(map(str, index))}]{joint} = {array[tuple(index)]}")
    return array


def definition_of(parameters: RobotParameters | Stack) -> Definition:
    """The model whose compiled functions serve ``parameters``: the paper's, or a stack's structure."""
    if isinstance(parameters, RobotParameters):
        return PAPER
    if isinstance(parameters, Stack):
        return StackDefinition.of(parameters)
    raise InputError(f"parameters = {shown(parameters)}: expected RobotParameters or a Stack (see vgtarm.load_robot)")


class Robot:
    """A manipulator model: :class:`RobotParameters` (the paper's robot) or a
    :class:`~vgtarm.model.stack.Stack` evaluated through the compiled backend.

    Build one with :func:`load_robot`. ``robot.with_parameters(p)`` gives a robot with other
    parameters sharing the same compiled code (for example a controller's imperfect model; for a
    stack, a stack of the same structure).

    Every method taking joint values ``q`` refuses, with :class:`~vgtarm.errors.InputError`,
    values that are not finite or lie outside the accepted range :meth:`joint_range` (lengths
    within ten spans of their limits and >= 0, angles within 1000 turns: see
    :mod:`vgtarm.model.sanity`), and, with
    :class:`~vgtarm.errors.AssemblyError`, leg sets that cannot be assembled.
    """

    def __init__(
        self,
        parameters: RobotParameters | Stack,
        backend: CompiledBackend | InterpretedBackend | None = None,
    ) -> None:
        definition = definition_of(parameters)
        # RobotParameters or Stack (typed Any: the layers above read the fields both share)
        self.parameters: Any = parameters
        self.definition = definition
        self.backend = backend if backend is not None else get_backend(None, definition)
        self._p = parameters.vector()
        self._low, self._high = sane_range(parameters)
        self._G, self._h = parameters.margin_form()
        self.n_joints: int = parameters.n_joints
        self.joint_names: tuple[str, ...] = parameters.joint_names
        self.joint_units: tuple[str, ...] = parameters.joint_units
        self.body_names: tuple[str, ...] = definition.body_names
        self.n_modules = len(parameters.margin_legs())

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
        """The flat parameter vector given to the compiled functions ((45,) for the paper's robot)."""
        return self._p.copy()

    @property
    def is_stack(self) -> bool:
        """Whether the robot is a stack of modules (else the paper's fixed 7-joint model)."""
        return self.definition != PAPER

    def with_parameters(self, parameters: RobotParameters | Stack) -> Robot:
        """A robot with other parameters and the same compiled model (a stack: of the same structure)."""
        if not isinstance(parameters, RobotParameters | Stack):
            raise InputError(
                f"parameters = {shown(parameters)}: expected RobotParameters or a Stack (see vgtarm.load_robot)"
            )
        same = (
            isinstance(parameters, RobotParameters)
            if self.definition == PAPER
            else isinstance(parameters, Stack) and StackDefinition.of(parameters) == self.definition
        )
        if not same:
            raise InputError(
                f"parameters = {shown(parameters)}: expected parameters of the same structure as robot "
                f"{shown(self.parameters.name)} (its compiled model)"
            )
        return Robot(parameters, self.backend)

    def margin_form(self) -> tuple[Array, Array]:
        """``G`` ``(6 m, n)`` and ``h`` ``(6 m,)``: the triangle margins ``G q + h`` of the ``m`` modules
        (six rows per module, in the order of :data:`~vgtarm.model.assembly.TRIANGLE_INEQUALITIES`)."""
        return self._G.copy(), self._h.copy()

    def check_assembly(self, q: Array, *, where: str = "q") -> None:
        """Raise :class:`~vgtarm.errors.AssemblyError` naming the module and the triangle inequality
        if a configuration of ``q`` ``(..., n)`` cannot be assembled."""
        p = self.parameters
        check_margins(q, self._G, self._h, p.margin_legs(), p.b, p.d, where=where)

    def joint_range(self) -> tuple[Array, Array]:
        """Lowest and highest joint values the methods accept, ``(n,)`` each (m, rad).

        The joint limits widened on each side by :data:`~vgtarm.model.sanity.SANE_WIDENING`
        times their span for lengths (at least 0), by :data:`~vgtarm.model.sanity.SANE_TURNS`
        turns for angles; beyond, values are refused as not a configuration.
        """
        return self._low.copy(), self._high.copy()

    def in_joint_range(self, q: ArrayLike) -> NDArray[np.bool_]:
        """Whether each configuration ``(..., n)`` is finite and inside :meth:`joint_range`."""
        qa = _as_array(q, "q", self.n_joints, finite=False, names=self.joint_names)
        return np.asarray(((qa >= self._low) & (qa <= self._high)).all(axis=-1))

    # -- helpers -----------------------------------------------------------------------------

    def _evaluate(
        self, name: str, named: list[tuple[str, ArrayLike, int]], check_q: bool = True
    ) -> tuple[tuple[int, ...], list[Array]]:
        arrays = [_as_array(value, label, size, names=self.joint_names) for label, value, size in named]
        try:
            shape = np.broadcast_shapes(*[a.shape[:-1] for a in arrays])
        except ValueError:
            shapes = ", ".join(f"{label} {a.shape}" for (label, _, _), a in zip(named, arrays, strict=True))
            raise InputError(f"leading shapes do not broadcast: {shapes}") from None
        if check_q:
            check_joint_range(arrays[0], self.parameters, (self._low, self._high), where=named[0][0])
            self.check_assembly(arrays[0], where=named[0][0])
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
        """Whether each configuration ``(..., n)`` can be assembled with the given margin (m)."""
        qa = _as_array(q, "q", self.n_joints, names=self.joint_names)
        if isinstance(margin, bool) or not isinstance(margin, int | float | np.integer | np.floating):
            raise InputError(f"margin = {shown(margin)}: expected a length (m)")
        return np.asarray((qa @ self._G.T + self._h > margin).all(axis=-1))

    def forward_kinematics(self, q: ArrayLike) -> ForwardKinematics:
        """Passive angles, platform frames, tip point and orientation (paper eqs. 1-11)."""
        shape, out = self._evaluate("fk", [("q", q, self.n_joints)])
        if self.definition == PAPER:
            passive, o1, c01, o2, c02, tip, c03 = out
            origins, rotations = np.stack([o1, o2], axis=1), np.stack([c01, c02], axis=1)
        else:
            passive, origins, rotations, tip, c03 = out
        m = self.n_modules
        return ForwardKinematics(
            passive=passive.reshape(shape + (m, 4)),
            platform_position=origins.reshape(shape + (m, 3)),
            platform_rotation=rotations.reshape(shape + (m, 3, 3)),
            tip=tip.reshape(shape + (3,)),
            rotation=c03.reshape(shape + (3, 3)),
        )

    def tip_position(self, q: ArrayLike) -> Array:
        """Tip point P in F0, ``(..., 3)`` (m). Cheaper than the full forward kinematics."""
        shape, (tip,) = self._evaluate("tip", [("q", q, self.n_joints)])
        return tip.reshape(shape + (3,))

    def tip_jacobian(self, q: ArrayLike) -> Array:
        """Translational Jacobian of the tip ``J_P = dP/dq``, ``(..., 3, n)``."""
        shape, (jp, _) = self._evaluate("jac", [("q", q, self.n_joints)])
        return jp.reshape(shape + (3, self.n_joints))

    def tip_hessian(self, q: ArrayLike) -> Array:
        """Second derivatives of the tip point ``d^2 P_k / dq_l dq_m``, ``(..., 3, n, n)``."""
        n = self.n_joints
        shape, (h,) = self._evaluate("tip_hessian", [("q", q, n)])
        return h.reshape(shape + (3, n, n))

    def angular_jacobian(self, q: ArrayLike) -> Array:
        """Angular Jacobian of the end-effector (F0 components), ``(..., 3, n)``."""
        shape, (_, jw) = self._evaluate("jac", [("q", q, self.n_joints)])
        return jw.reshape(shape + (3, self.n_joints))

    def com_jacobians(self, q: ArrayLike) -> tuple[Array, Array]:
        """Jacobians of the bodies' centres of mass and angular velocities, each ``(..., b, 3, n)``.

        Axis ``-3`` is the body (:attr:`body_names`: platform 1, platform 2, end-effector for the
        paper's robot).
        """
        shape, (jv, jw) = self._evaluate("com_jac", [("q", q, self.n_joints)])
        nb, n = len(self.body_names), self.n_joints
        return jv.reshape(shape + (nb, 3, n)), jw.reshape(shape + (nb, 3, n))

    def tip_velocity(self, q: ArrayLike, qd: ArrayLike) -> tuple[Array, Array]:
        """Tip velocity ``J_P qd`` (m/s) and end-effector angular velocity (rad/s), ``(..., 3)`` each."""
        shape, (v, w) = self._evaluate("velocity", [("q", q, self.n_joints), ("qd", qd, self.n_joints)])
        return v.reshape(shape + (3,)), w.reshape(shape + (3,))

    def bias_accelerations(self, q: ArrayLike, qd: ArrayLike) -> BiasAccelerations:
        """Accelerations due to ``qd`` alone (``qdd = 0``): ``Jdot qd`` of the tip and bodies."""
        n = self.n_joints
        shape, (tip, ang, com, body_ang) = self._evaluate("bias_acc", [("q", q, n), ("qd", qd, n)])
        return BiasAccelerations(
            tip=tip.reshape(shape + (3,)),
            angular=ang.reshape(shape + (3,)),
            com=com.reshape(shape + (len(self.body_names), 3)),
            body_angular=body_ang.reshape(shape + (len(self.body_names), 3)),
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
        """Mass matrix ``M(q)`` of eq. 15, ``(..., n, n)``."""
        shape, (m,) = self._evaluate("mass", [("q", q, self.n_joints)])
        return m.reshape(shape + (self.n_joints, self.n_joints))

    def bias_forces(self, q: ArrayLike, qd: ArrayLike) -> Array:
        """``C(q, qd)`` of eq. 15: velocity products + gravity + viscous friction, ``(..., n)``."""
        shape, (c,) = self._evaluate("bias_forces", [("q", q, self.n_joints), ("qd", qd, self.n_joints)])
        return c.reshape(shape + (self.n_joints,))

    def forward_dynamics(self, q: ArrayLike, qd: ArrayLike, F: ArrayLike, f_tip: ArrayLike | None = None) -> Array:
        """Joint accelerations ``M^-1 (F + J_P^T f_tip - C)``, ``(..., n)``.

        ``F`` are the actuator efforts (N, and N m for the twist); ``f_tip`` the force acting
        on the end-effector at the tip point, in F0 (N), default zero.
        """
        f = np.zeros(3) if f_tip is None else f_tip
        n = self.n_joints
        shape, (qdd,) = self._evaluate("fd", [("q", q, n), ("qd", qd, n), ("F", F, n), ("f_tip", f, 3)])
        return qdd.reshape(shape + (self.n_joints,))

    def inverse_dynamics(self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, f_tip: ArrayLike | None = None) -> Array:
        """Actuator efforts ``M qdd + C - J_P^T f_tip`` that produce ``qdd``, ``(..., n)``."""
        f = np.zeros(3) if f_tip is None else f_tip
        n = self.n_joints
        shape, (F,) = self._evaluate("id", [("q", q, n), ("qd", qd, n), ("qdd", qdd, n), ("f_tip", f, 3)])
        return F.reshape(shape + (self.n_joints,))

    def energy(self, q: ArrayLike, qd: ArrayLike) -> tuple[Array, Array]:
        """Kinetic and potential (gravity) energy, each of shape ``(...)`` (J)."""
        shape, (t, v) = self._evaluate("energy", [("q", q, self.n_joints), ("qd", qd, self.n_joints)])
        return t.reshape(shape), v.reshape(shape)


def load_robot(config: str | Path | None = None) -> Robot:
    """Load a robot: the shipped reference robot, or the TOML file ``config``.

    A file with ``[[modules]]`` tables (or an ``[end_effector]`` table) describes a stack of modules
    (:mod:`vgtarm.model.stack.description`); any other, the paper's 7-joint robot
    (:func:`load_parameters`). Either way a bad file raises one
    :class:`~vgtarm.errors.ConfigError` line naming the field.
    """
    if config is None:
        return Robot(load_parameters(None))
    if isinstance(config, str | os.PathLike):
        text = read_text_limited(config, ROBOT_FILE_LIMIT, "configuration file", error=ConfigError)
        data = parse_toml(text, cut(str(config), 200), error=ConfigError)
        if is_stack_format(data):
            return Robot(stack_from_dict(data, source=str(config)))
    return Robot(load_parameters(config))


def is_stack_format(data: Mapping[str, Any]) -> bool:
    """Whether a parsed robot file is in the stack format (it has keys only that format has)."""
    return "modules" in data or "end_effector" in data


def robot_parameters_from_dict(data: Mapping[str, Any], *, source: str = "<dict>") -> RobotParameters | Stack:
    """The validated parameters of a parsed robot file of either format (see :func:`load_robot`);
    nothing is compiled."""
    if is_stack_format(data):
        return stack_from_dict(data, source=source)
    return parameters_from_dict(data, source=source)


def robot_from_dict(data: Mapping[str, Any], *, source: str = "<dict>") -> Robot:
    """A robot from a parsed robot file of either format (see :func:`load_robot`)."""
    return Robot(robot_parameters_from_dict(data, source=source))
