"""A Pinocchio twin of a stack of VGT modules (the paper's robot first): the truss itself, its loops
closed by 3-D point constraints (issue 35, item 5: the anchor of single-call speed).

Our model solves each module in closed form and keeps seven coordinates; the twin is the truss as a
multibody system, built from the robot's own parameters (no number of the robot written here):

- **Module** (in its operating plane, the frame it stands on turned by its plane angle ``phi``
  about the stack axis, as the stack model turns it): leg ``s`` is a revolute joint at ``A`` about
  the plane normal (its angle is ``alpha``) and a prismatic joint along the leg (its length ``s``);
  leg ``v`` likewise at ``B`` (``gamma``, ``v``), the diagonal ``p`` at ``A`` (``beta``, ``p``).
  The platform hangs from the end ``A'`` of leg ``s`` on a revolute joint about the normal (angle
  ``theta - alpha``); the ends of ``v`` and ``p`` are tied to the platform's point ``B'`` by two
  ``CONTACT_3D`` constraints (rows in the platform point's ``LOCAL`` frame). Seven joints, two loops: three degrees of
  freedom. A planar loop held by a 3-D point constraint is redundant out of its plane (one row of
  each constraint is identically zero), which Pinocchio's proximal solver handles (:data:`PROXIMAL`).
- **Twist**: a revolute joint about the platform normal at the platform centre; the next module
  stands ``height`` above it, as in the stack model.
- **Bodies**: the platforms, the twist parts and the end-effector with our masses, centres of mass
  and inertias, in the same frames. Legs are massless in our model, and a massless leaf of the tree
  (legs ``v`` and ``p``, whose ends are held by the constraints only) makes Pinocchio's joint-space
  inertia singular. Rather than tiny fictitious inertias (which would change the dynamics by their
  size), the twin moves a **point mass** of each platform onto the end of leg ``v`` and of leg ``p``
  (:data:`POINT_MASS_FRACTION` of the platform's mass each, at ``B'``), and the platform keeps the
  rest, its centre of mass and inertia corrected so that platform and point masses together are
  the platform's body exactly. The constraints make each point mass move with the platform's
  ``B'``, and a point mass has no rotational inertia, so the twin's dynamics is the same as a
  massless-leg truss: the same Lagrangian in the seven coordinates, with nothing to extrapolate.
- **Efforts**: our efforts act on the prismatic joints and the twist joint; viscous friction is
  added on the twin's side (``tau = F - D qd``) and the tip force as ``J^T f`` of the tip frame.

The state maps from ours: the passive angles from our forward kinematics, the passive rates by
solving the twin's constraints (``J_c v = 0`` given our rates), so the check of the dynamics is not
also a check of a rate formula of ours.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vgtarm.model.parameters import Body, RobotParameters
from vgtarm.model.stack.description import Stack, stack_from_parameters
from vgtarm.model.stack.symbolic import plane_direction

#: Share of a platform's mass moved to the end of leg ``v`` and (as much) to that of leg ``p``.
POINT_MASS_FRACTION = 0.1
#: ``(absolute accuracy, relative accuracy, mu, iterations)`` of Pinocchio's proximal solver. The
#: out-of-plane rows of the loops are redundant, which ``mu`` regularises; the proximal iterations
#: remove its effect: after two, the accelerations are those of the exact constrained system (within
#: 5e-15 of LAPACK's solve of our ``M``, ``C`` and ``J_P``, measured on 200 random states), and more
#: change nothing. Pinocchio's own stopping test never passes on redundant rows (its residual
#: stays at the size of the redundant multipliers), so the solver always runs ``iterations``:
#: two is what a user would set.
PROXIMAL = (1e-12, 1e-12, 1e-8, 2)
#: The fastest settings that stay accurate: one iteration with ``mu = 1e-12`` (its effect is then of
#: that size): within 2.3e-12 of LAPACK's solve of our model on 1,000 random states, 1 us faster
#: than :data:`PROXIMAL` on the development machine. The benchmark's anchor (fair to Pinocchio).
FASTEST = (1e-12, 1e-12, 1e-12, 1)

Array = NDArray[np.float64]


def _rz(c: float, s: float) -> Array:
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass
class ModuleJoints:
    """The twin's configuration indices of one module's joints."""

    alpha: int
    s: int
    platform: int  # theta - alpha
    gamma: int
    v: int
    beta: int
    p: int


@dataclass
class Twin:
    """A Pinocchio model of a stack's truss with its loop constraints (module docstring)."""

    pin: Any
    model: Any
    constraints: list[Any]
    modules: list[ModuleJoints]
    actuated: list[int]  # the twin's velocity index of each of our joints, in our order
    twists: list[int | None]  # per module: the twin's index of its twist joint, or None
    tip_frame: int
    viscous: Array
    loop_frames: list[tuple[int, int]]  # the frames at both points of each loop
    point_masses: list[float] = field(default_factory=list)

    @property
    def n_joints(self) -> int:
        """Our joint count."""
        return len(self.actuated)

    def configuration(self, q: Array, passive: Array) -> Array:
        """The twin's configuration of our ``q`` (n,) with our passive angles (modules, 4):
        ``alpha, beta, gamma, theta`` per module (``Robot.forward_kinematics(q).passive``)."""
        x = np.zeros(self.model.nq)
        i = 0
        for k, joints in enumerate(self.modules):
            alpha, beta, gamma, theta = passive[k]
            x[[joints.alpha, joints.beta, joints.gamma, joints.platform]] = alpha, beta, gamma, theta - alpha
            x[[joints.s, joints.v, joints.p]] = q[i : i + 3]
            i += 3
            twist = self.twists[k]
            if twist is not None:
                x[twist] = q[i]
                i += 1
        return x

    def constraint_jacobian(self, x: Array) -> Array:
        """The loops' velocity Jacobian ``J_c`` (3 per loop, nv) at the twin's configuration ``x``: the
        velocity of each loop's platform point less that of its leg's end, in the base frame (from
        the frames at both points, independently of the constraint models)."""
        pin, model = self.pin, self.model
        data = model.createData()
        pin.computeJointJacobians(model, data, x)
        pin.updateFramePlacements(model, data)
        frame = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        rows = [
            pin.getFrameJacobian(model, data, top, frame)[:3] - pin.getFrameJacobian(model, data, end, frame)[:3]
            for top, end in self.loop_frames
        ]
        return np.vstack(rows)

    def velocity(self, x: Array, qd: Array) -> Array:
        """The twin's velocity: our rates on our joints, the passive rates solving ``J_c v = 0``."""
        jac = self.constraint_jacobian(x)
        v = np.zeros(self.model.nv)
        v[self.actuated] = qd
        passive = np.setdiff1d(np.arange(self.model.nv), self.actuated)
        v[passive] = np.linalg.lstsq(jac[:, passive], -jac @ v, rcond=None)[0]
        return v

    def efforts(self, x: Array, qd: Array, F: Array, f_tip: Array | None = None) -> Array:
        """The twin's joint efforts: ``F - D qd`` on our joints, plus ``J^T f`` of the tip frame."""
        tau = np.zeros(self.model.nv)
        tau[self.actuated] = F - self.viscous * qd
        if f_tip is not None:
            pin, model = self.pin, self.model
            data = model.createData()
            pin.computeJointJacobians(model, data, x)
            pin.updateFramePlacements(model, data)
            frame = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            jac = pin.getFrameJacobian(model, data, self.tip_frame, frame)
            tau += jac[:3].T @ f_tip
        return tau

    def tip(self, x: Array) -> Array:
        """The tip point in the base frame at the twin's configuration ``x``."""
        data = self.model.createData()
        self.pin.framesForwardKinematics(self.model, data, x)
        return np.array(data.oMf[self.tip_frame].translation)

    def vector(self) -> Any:
        """The constraint models as Pinocchio's vector."""
        models = self.pin.StdVec_RigidConstraintModel()
        for c in self.constraints:
            models.append(c)
        return models

    def data_vector(self, datas: list[Any]) -> Any:
        """Constraint datas as Pinocchio's vector."""
        vector = self.pin.StdVec_RigidConstraintData()
        for d in datas:
            vector.append(d)
        return vector

    def settings(self, proximal: tuple[float, float, float, int] = PROXIMAL) -> Any:
        """Pinocchio's proximal settings (:data:`PROXIMAL`, or :data:`FASTEST`)."""
        return self.pin.ProximalSettings(*proximal)

    def prepare(self, proximal: tuple[float, float, float, int] = PROXIMAL) -> tuple[Any, Any, Any, Any]:
        """``(data, constraint models, constraint datas, settings)`` for ``constraintDynamics``,
        initialised once."""
        data = self.model.createData()
        models = self.vector()
        datas = self.data_vector([c.createData() for c in self.constraints])
        self.pin.initConstraintDynamics(self.model, data, models, datas)
        return data, models, datas, self.settings(proximal)

    def accelerations(
        self,
        q: Array,
        qd: Array,
        F: Array,
        passive: Array,
        f_tip: Array | None = None,
        proximal: tuple[float, float, float, int] = PROXIMAL,
    ) -> Array:
        """Our joints' accelerations by the twin's ``constraintDynamics`` (a check, not a fast path)."""
        x = self.configuration(q, passive)
        v = self.velocity(x, qd)
        tau = self.efforts(x, qd, F, f_tip)
        data, models, datas, settings = self.prepare(proximal)
        a = self.pin.constraintDynamics(self.model, data, x, v, tau, models, datas, settings)
        return np.asarray(a)[self.actuated]


def _inertia(body: Body, rotation: Array, origin: Array) -> tuple[float, Array, Array]:
    """``(mass, centre of mass, inertia about it)`` of ``body`` in a joint frame in which the body's
    frame has ``rotation`` and ``origin``."""
    return body.mass, origin + rotation @ np.array(body.com), rotation @ body.inertia_matrix @ rotation.T


def _without_point(mass: float, com: Array, inertia: Array, point_mass: float, at: Array) -> Any:
    """The body that, with a point mass ``point_mass`` at ``at``, makes the given body."""
    rest = mass - point_mass
    centre = (mass * com - point_mass * at) / rest

    def shift(m: float, r: Array) -> Array:
        return m * (float(r @ r) * np.eye(3) - np.outer(r, r))

    about_origin = inertia + shift(mass, com) - shift(point_mass, at)
    return rest, centre, about_origin - shift(rest, centre)


def _platform(pin: Any, model: Any, joint: int, body: Body, rotation: Array, d: float) -> float:
    """Append the platform (frame ``rotation``, centre ``(0, d, 0)`` in the platform joint's frame)
    minus the point masses at ``B' = (0, 2d, 0)``; returns each point mass."""
    mass, com, inertia = _inertia(body, rotation, np.array([0.0, d, 0.0]))
    at = np.array([0.0, 2 * d, 0.0])
    if not mass > 0:
        raise ValueError(f"platform mass = {mass!r}: the twin needs a platform with mass (it lends its legs some)")
    point = POINT_MASS_FRACTION * mass
    for _ in range(60):  # halve the point masses until what stays on the platform is a valid body
        rest, centre, rotational = _without_point(mass, com, inertia, 2 * point, at)
        if np.linalg.eigvalsh(rotational).min() > 1e-3 * np.abs(inertia).max():
            break
        point /= 2
    else:
        raise ValueError(f"platform inertia = {inertia.tolist()}: no point mass at B' leaves a valid body")
    model.appendBodyToJoint(joint, pin.Inertia(rest, centre, rotational), pin.SE3.Identity())
    return point


def _leg(pin: Any, model: Any, parent: int, placement: Any, name: str) -> tuple[int, int]:
    """A leg: a revolute joint about the plane normal (local x) and a prismatic joint along the leg
    (local y, its angle's direction). Returns both joint ids."""
    turn = model.addJoint(parent, pin.JointModelRX(), placement, f"{name}_angle")
    slide = model.addJoint(turn, pin.JointModelPY(), pin.SE3.Identity(), name)
    return turn, slide


def _module(
    pin: Any, model: Any, parent: int, stance: Any, module: Any, k: int, frames: list[tuple[int, int]]
) -> tuple[int, list[Any], float]:
    """Add module ``k`` on joint ``parent`` standing on frame ``stance``; returns the platform joint,
    the two loop constraints and the point mass (and appends the loops' point frames to ``frames``)."""
    c, s = plane_direction(module.plane)
    plane = stance * pin.SE3(_rz(c, s), np.zeros(3))
    b, d = module.b, module.d
    at_a = plane * pin.SE3(np.eye(3), np.array([0.0, -b, 0.0]))
    at_b = plane * pin.SE3(np.eye(3), np.array([0.0, b, 0.0]))
    _, v_end = _leg(pin, model, parent, at_b, f"v{k + 1}")
    _, p_end = _leg(pin, model, parent, at_a, f"p{k + 1}")
    _, s_end = _leg(pin, model, parent, at_a, f"s{k + 1}")
    platform = model.addJoint(s_end, pin.JointModelRX(), pin.SE3.Identity(), f"platform{k + 1}")
    # our platform frame is R Rz(phi) Rx(theta) Rz(-phi): in the platform joint's frame, Rz(-phi)
    point = _platform(pin, model, platform, module.platform, _rz(c, -s), d)
    for end in (v_end, p_end):
        model.appendBodyToJoint(end, pin.Inertia(point, np.zeros(3), np.zeros((3, 3))), pin.SE3.Identity())
    top = pin.SE3(np.eye(3), np.array([0.0, 2 * d, 0.0]))
    loops = []
    for end in (v_end, p_end):
        loops.append(
            pin.RigidConstraintModel(
                pin.ContactType.CONTACT_3D, model, platform, top, end, pin.SE3.Identity(), pin.ReferenceFrame.LOCAL
            )
        )
        name = model.names[end]
        frames.append(
            (
                model.addFrame(pin.Frame(f"{name}_on_platform", platform, 0, top, pin.FrameType.OP_FRAME)),
                model.addFrame(pin.Frame(f"{name}_end", end, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME)),
            )
        )
    return platform, loops, point


def build_twin(robot: RobotParameters | Stack) -> Twin:
    """The Pinocchio twin of the robot's truss (module docstring); ``ImportError`` without Pinocchio."""
    import pinocchio as pin

    stack = stack_from_parameters(robot) if isinstance(robot, RobotParameters) else robot
    model = pin.Model()
    model.gravity = pin.Motion(np.array(stack.gravity), np.zeros(3))
    parent, stance = 0, pin.SE3.Identity()
    constraints: list[Any] = []
    modules: list[ModuleJoints] = []
    twists: list[int | None] = []
    points: list[float] = []
    frames: list[tuple[int, int]] = []
    viscous: list[float] = []
    actuated_names: list[str] = []
    for k, module in enumerate(stack.modules):
        platform, loops, point = _module(pin, model, parent, stance, module, k, frames)
        constraints += loops
        points.append(point)
        actuated_names += [f"s{k + 1}", f"v{k + 1}", f"p{k + 1}"]
        viscous += list(module.viscous)
        c, s = plane_direction(module.plane)
        centre = pin.SE3(_rz(c, -s), np.array([0.0, module.d, 0.0]))  # our platform frame
        parent, stance, mount = platform, centre, centre
        twist_index = None
        if module.twist is not None:
            parent = model.addJoint(platform, pin.JointModelRZ(), centre, f"psi{k + 2}")
            twist_index = model.joints[parent].idx_q
            if module.twist.body is not None:
                body = module.twist.body
                inertia = pin.Inertia(body.mass, np.array(body.com), body.inertia_matrix)
                model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
            stance = pin.SE3(np.eye(3), np.array([0.0, 0.0, module.twist.height]))
            mount = stance
            actuated_names.append(f"psi{k + 2}")
            viscous.append(module.twist.viscous)
        twists.append(twist_index)
        modules.append(_indices(model, k))
    ee = stack.end_effector
    last = centre if stack.modules[-1].twist is None else pin.SE3.Identity()
    model.appendBodyToJoint(parent, pin.Inertia(ee.mass, np.array(ee.com), ee.inertia_matrix), last)
    tool = mount * pin.SE3(np.eye(3), np.array(stack.tool))
    tip = model.addFrame(pin.Frame("tip", parent, 0, tool, pin.FrameType.OP_FRAME))
    actuated = [model.joints[model.getJointId(name)].idx_v for name in actuated_names]
    return Twin(pin, model, constraints, modules, actuated, twists, tip, np.array(viscous), frames, points)


def _indices(model: Any, k: int) -> ModuleJoints:
    def q(name: str) -> int:
        return int(model.joints[model.getJointId(name)].idx_q)

    m = k + 1
    return ModuleJoints(
        alpha=q(f"s{m}_angle"),
        s=q(f"s{m}"),
        platform=q(f"platform{m}"),
        gamma=q(f"v{m}_angle"),
        v=q(f"v{m}"),
        beta=q(f"p{m}_angle"),
        p=q(f"p{m}"),
    )
