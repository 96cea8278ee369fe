"""MJCF export of a robot (MuJoCo's XML model format): the paper's robot or any stack of modules.

The mechanism as a MuJoCo tree closed by equality constraints. Each module ``k``: three base
hinges on the module's plane normal (at ``A`` for the leg ``s`` and the diagonal ``p``, at ``B``
for the leg ``v``), a slide along each leg, the platform hinged at the top of ``s`` (``A'``), and
the top of ``v`` and of ``p`` tied to the platform's corner ``B'`` by ``connect`` equalities. A
module stands on what is below it (the world, the platform below, or the twist below) in its
operating plane, turned by the module's plane angle; a twist joint after a module is a hinge on
the platform's normal through its centre, carrying what is above (the paper's robot: module 2 on
platform 1 in its ``u1-u3`` plane, the twist ``psi3`` on platform 2 carrying the end-effector);
the end-effector rides on the last frame; a site ``tip`` marks the tool tip. The paper's robot is
exported as the stack it is (:func:`~vgtarm.model.stack.stack_from_parameters`), by the same
builder.

The closed legs ``v`` and ``p`` are driven through spatial tendons ``<leg>_leg`` from their foot
(a site on the module's base body) to their head (a site at ``B'`` on the platform): a tendon's
length is the leg length, and its motor and viscous friction act on the base and the platform
directly, so no effort passes through MuJoCo's soft equality constraints. The slide-jointed leg
bodies are passive followers (no motor, no damping, almost no mass) whose joints still read the
paper's joint values. The leg ``s`` is on the tree path: its motor and friction are on its slide.

Every body frame is aligned with F0 at the home pose, so joint axes and inertias are written in
F0 at home; slides have ``ref`` = their home length and twists ``ref`` = their home angle, so the
actuated joints' positions are the paper's joint values. What MuJoCo needs that the paper's
model does not (documented in ``docs/mujoco.md``): a tiny mass on each leg (the paper's legs are
massless) and on a twist without a part of its own, and constraint solver settings that make the
loop closures as stiff as MuJoCo allows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, shown
from ..model.parameters import Body, RobotParameters
from ..model.robot import Robot
from ..model.stack.description import Stack, stack_from_parameters
from ..model.stack.symbolic import plane_direction

Array = NDArray[np.float64]

#: Mass (kg) and inertia (kg m^2) of each leg body, which the paper takes as massless: the
#: lightest MuJoCo solves well, a thousand times its floor ``mjMINVAL`` = 1e-15 in mass and ten
#: times in inertia (a rod's ``m L^2 / 12`` at L = 0.35 m). The closed legs' efforts act through
#: tendons, not through the soft loop closures, so all that leaks through those closures is the
#: legs' own inertia: M and forward dynamics agree with the massless legs to about 1e-12 relative
#: (docs/mujoco.md). A twist joint without a part of its own (inside a stack) gets the same.
LEG_MASS = 1e-12
LEG_INERTIA = 1e-14
#: MuJoCo's floor on the mass and inertia of a moving body (``mjMINVAL``).
MJ_MINVAL = 1e-15
#: Longest time step the export accepts (s): a bound on a mistyped value, not a tuned one.
MAX_TIMESTEP = 1.0


@dataclass(frozen=True)
class TwistHome:
    """A twist joint after a module, at the home pose (F0): its joint, frame and part."""

    joint: str
    home: float
    viscous: float
    rotation: Array  # (3, 3) the twist frame (what stands above turns with it)
    mount: Array  # (3,) from the platform centre to the mount point of what follows (m)
    body: Body | None


@dataclass(frozen=True)
class ModuleHome:
    """One module at the home pose, in F0: joint points, leg directions, the plane normal, the
    platform's centre and frame, and the twist after the module (``None`` without)."""

    A: Array
    B: Array
    A_top: Array
    B_top: Array
    dir_s: Array
    dir_v: Array
    dir_p: Array
    normal: Array
    centre: Array
    rotation: Array
    twist: TwistHome | None = None


def _module_home(origin: Array, R: Array, b: float, passive: Array, legs: Array) -> ModuleHome:
    """Module points from its plane map ``(h, z) -> origin + R[:, 0] h + R[:, 1] z`` (F0); the
    platform's centre, frame and twist are filled in by :func:`home_geometry`."""
    alpha, beta, gamma, _theta = passive
    s, v, p = legs

    def point(h: float, z: float) -> Array:
        return origin + R[:, 0] * h + R[:, 1] * z

    def direction(angle: float) -> Array:
        return R[:, 0] * np.cos(angle) + R[:, 1] * np.sin(angle)

    A, B = point(-b, 0.0), point(b, 0.0)
    return ModuleHome(
        A=A,
        B=B,
        A_top=A + s * direction(alpha),
        B_top=A + p * direction(beta),
        dir_s=direction(alpha),
        dir_v=direction(gamma),
        dir_p=direction(beta),
        normal=np.cross(R[:, 0], R[:, 1]),
        centre=np.zeros(3),
        rotation=np.eye(3),
    )


@dataclass(frozen=True)
class HomeGeometry:
    """Everything the export places, at the robot's home pose (F0 coordinates).

    Attributes:
        stack: the robot as a stack of modules (the paper's robot: its two modules and twist).
        modules: each module's points, platform frame and twist.
        rotation: ``(3, 3)`` end-effector orientation at home (``C03`` of the paper's robot).
        tip: ``(3,)`` tool tip (m).
        passive: ``(m, 4)`` passive angles ``alpha, beta, gamma, theta`` of each module (rad).
    """

    stack: Stack
    modules: tuple[ModuleHome, ...]
    rotation: Array
    tip: Array
    passive: Array


def as_stack(robot: Robot) -> Stack:
    """The robot's parameters as a stack (the paper's robot: two modules and the twist ``psi3``)."""
    par = robot.parameters
    return stack_from_parameters(par) if isinstance(par, RobotParameters) else par


def _rot_z(angle: float) -> Array:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def home_geometry(robot: Robot) -> HomeGeometry:
    """Everything the export places, at the robot's home pose (F0 coordinates), module by module
    along the stack's chain (:mod:`vgtarm.model.stack.symbolic`): a module stands at the mount
    point of the frame below, in that frame's plane turned by its plane angle."""
    stack = as_stack(robot)
    q = stack.home
    fk = robot.forward_kinematics(q)
    passive = np.asarray(fk.passive)
    modules: list[ModuleHome] = []
    origin = np.zeros(3)
    below: Array | None = None  # the frame the next module stands in (None: F0)
    i = 0
    last = len(stack.modules) - 1
    for k, module in enumerate(stack.modules):
        c, s = plane_direction(module.plane)
        # (h, z) -> origin + h (-s, c, 0) + z u3 in the frame below ("0.0 - s": no signed zero)
        plane = np.array([[0.0 - s, 0.0], [c, 0.0], [0.0, 1.0]])
        if below is not None:
            plane = below @ plane
        home = _module_home(origin, plane, module.b, passive[k], q[i : i + 3])
        centre = np.asarray(fk.platform_position[k])
        frame = np.asarray(fk.platform_rotation[k])
        i += 3
        twist = None
        origin, below = centre, frame
        if module.twist is not None:
            rotation = np.asarray(fk.rotation) if k == last else frame @ _rot_z(float(q[i]))
            mount = module.twist.height * frame[:, 2]
            twist = TwistHome(
                joint=f"psi{k + 2}",
                home=float(q[i]),
                viscous=module.twist.viscous,
                rotation=rotation,
                mount=mount,
                body=module.twist.body,
            )
            origin, below = centre + mount, rotation
            i += 1
        modules.append(replace(home, centre=centre, rotation=frame, twist=twist))
    return HomeGeometry(
        stack=stack,
        modules=tuple(modules),
        rotation=np.asarray(fk.rotation),
        tip=np.asarray(fk.tip),
        passive=passive,
    )


def _v(x: Array) -> str:
    return " ".join(f"{float(c):.17g}" for c in np.ravel(x))


def _inertial(mass: float, com: Array, inertia: Array) -> str:
    sym = 0.5 * (inertia + inertia.T)
    full = [sym[0, 0], sym[1, 1], sym[2, 2], sym[0, 1], sym[0, 2], sym[1, 2]]
    return f'<inertial pos="{_v(com)}" mass="{mass:.17g}" fullinertia="{_v(np.array(full))}"/>'


def _body_inertial(body: Body, origin: Array, rotation: Array, body_origin: Array) -> str:
    """``body`` (given in the frame ``rotation`` at ``origin``) as the inertial of a MuJoCo body
    whose frame is at ``body_origin`` (F0 axes)."""
    com = origin + rotation @ np.array(body.com) - body_origin
    return _inertial(body.mass, com, rotation @ body.inertia_matrix @ rotation.T)


def _leg_inertial(mass: float, inertia: float) -> str:
    return f'<inertial pos="0 0 0" mass="{mass:.17g}" diaginertia="{inertia:.17g} {inertia:.17g} {inertia:.17g}"/>'


def _check_export(
    robot: object, timestep: object, solver_tolerance: object, leg_mass: object, leg_inertia: object
) -> None:
    if not isinstance(robot, Robot):
        raise InputError(f"robot = {shown(robot)}: expected a vgtarm.Robot (see vgtarm.load_robot)")
    for name, value, low, high in (
        ("timestep", timestep, 0.0, MAX_TIMESTEP),
        ("solver_tolerance", solver_tolerance, 0.0, 1.0),
        ("leg_mass", leg_mass, MJ_MINVAL, math.inf),
        ("leg_inertia", leg_inertia, MJ_MINVAL, math.inf),
    ):
        real = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
        if not (real and math.isfinite(float(value)) and low < float(value) <= high):  # type: ignore[arg-type]
            bound = f"<= {high:g}" if math.isfinite(high) else "finite"
            raise InputError(f"{name} = {shown(value)}: expected a number > {low:g} and {bound}")


def to_mjcf(
    robot: Robot,
    *,
    timestep: float = 1e-3,
    solver_tolerance: float = 1e-12,
    leg_mass: float = LEG_MASS,
    leg_inertia: float = LEG_INERTIA,
) -> str:
    """The robot (the paper's or any stack of modules) as an MJCF document (text).

    Joints and force actuators are named after the paper, module by module (``s1, v1, p1, s2, v2,
    p2, psi3`` for the paper's robot; :attr:`Robot.joint_names`; motors, gear 1, control = effort
    in N or N m, no control limits); the motors of the closed legs ``v``, ``p`` drive the tendons
    ``<leg>_leg``, the others their joints; passive hinges ``<leg>_base`` and ``platform<k>``;
    a twist ``psi<j>`` turns the body ``twist<j>`` (or ``end_effector``, when it is the last
    frame and has no part of its own); the tool tip is the site ``tip``; the keyframe ``home`` is
    the robot's home pose at rest. Viscous friction is joint damping (``s``, twists) or tendon
    damping (``v``, ``p``); gravity is the robot's. ``leg_mass`` (kg) and ``leg_inertia``
    (kg m^2) are given to every leg body (the paper's legs are massless; MuJoCo refuses below
    1e-15) and to a twist without a part of its own.
    """
    _check_export(robot, timestep, solver_tolerance, leg_mass, leg_inertia)
    g = home_geometry(robot)
    stack = g.stack
    q = stack.home
    names = stack.joint_names
    damping = dict(zip(names, stack.viscous, strict=True))
    # the closed legs v and p of every module (the s leg of each is on the tree path)
    closed = [names[j] for legs in stack.leg_indices for j in legs[1:]]
    last = len(g.modules) - 1
    end_effector = stack.end_effector
    tool = np.array(stack.tool, dtype=float)

    def leg(name: str, base: Array, direction: Array, normal: Array, length: float, parent_pos: Array) -> list[str]:
        """A base hinge body at ``base`` and a rod body sliding along ``direction`` in it; the
        slide of a leg on the tree path (``s``) carries its friction, the closed legs' friction
        is on their tendons."""
        friction = "" if name in closed else f' damping="{damping[name]:.17g}"'
        return [
            f'<body name="{name}_base" pos="{_v(base - parent_pos)}">',
            _leg_inertial(leg_mass, leg_inertia),
            f'<joint name="{name}_base" type="hinge" axis="{_v(normal)}"/>',
            f'<body name="{name}_rod" pos="0 0 0">',
            _leg_inertial(leg_mass, leg_inertia),
            f'<joint name="{name}" type="slide" axis="{_v(direction)}" ref="{length:.17g}"{friction}/>',
            f'<geom type="capsule" fromto="0 0 0 {_v(direction * length)}" size="0.006" rgba="0.2 0.6 0.2 1"/>',
        ]

    def effector(origin: Array, rotation: Array, mount: Array) -> tuple[str, list[str]]:
        """The end-effector's inertial, and the tip site (with a rod from the mount point to it
        when the tool stands off), in a body at ``origin`` (the last platform's centre) whose tool
        is mounted at ``mount`` from it."""
        inertial = _body_inertial(end_effector, origin, rotation, origin)
        if not tool.any():  # the tip is the mount point (no "+ 0": signed zeros kept)
            return inertial, [f'<site name="tip" pos="{_v(mount)}" size="0.005"/>']
        tip = mount + rotation @ tool
        return inertial, [
            f'<site name="tip" pos="{_v(tip)}" size="0.005"/>',
            f'<geom type="capsule" fromto="{_v(mount)} {_v(tip)}" size="0.005" rgba="0.7 0.7 0.8 1"/>',
        ]

    def stage(k: int) -> list[str]:
        """Everything inside platform ``k``'s body (origin ``A'``): its inertial, then the twist
        with what rides on it, or directly what stands on the platform."""
        mod = g.modules[k]
        out = [_body_inertial(stack.modules[k].platform, mod.centre, mod.rotation, mod.A_top)]
        twist = mod.twist
        if twist is None and k < last:
            return out + module(k + 1, mod.A_top)
        if twist is None:  # the end-effector fixed on the last platform
            inertial, tip = effector(mod.centre, g.rotation, np.zeros(3))
            return [*out, f'<body name="end_effector" pos="{_v(mod.centre - mod.A_top)}">', inertial, *tip, "</body>"]
        lumped = k == last and twist.body is None  # the twist's body is the end-effector
        inertial, tip = effector(mod.centre, twist.rotation, twist.mount)
        if lumped:
            out += [f'<body name="end_effector" pos="{_v(mod.centre - mod.A_top)}">', inertial]
        else:
            out += [f'<body name="twist{twist.joint[3:]}" pos="{_v(mod.centre - mod.A_top)}">']
            out += [
                _leg_inertial(leg_mass, leg_inertia)
                if twist.body is None
                else _body_inertial(twist.body, mod.centre, twist.rotation, mod.centre)
            ]
        out += [
            f'<joint name="{twist.joint}" type="hinge" axis="{_v(mod.rotation[:, 2])}" ref="{twist.home:.17g}" '
            f'damping="{twist.viscous:.17g}"/>',
            f'<geom type="cylinder" fromto="0 0 0 {_v(twist.mount)}" size="0.03" rgba="0.7 0.7 0.8 1"/>',
        ]
        if lumped:
            out += tip
        elif k == last:  # the end-effector fixed on the twist's part
            out += ['<body name="end_effector" pos="0 0 0">', inertial, *tip, "</body>"]
        else:
            out += module(k + 1, mod.centre)
        return [*out, "</body>"]

    def module(k: int, parent_pos: Array) -> list[str]:
        """Module ``k`` (0-based) in the coordinates of its parent body at ``parent_pos``."""
        mod = g.modules[k]
        i = stack.leg_indices[k][0]
        s, v, p = q[i : i + 3]
        ln = [f"s{k + 1}", f"v{k + 1}", f"p{k + 1}"]
        # the closed legs' tendons run between these sites: their feet on the module's base
        # body, their heads at the platform's corner B'
        out: list[str] = [
            f'<site name="{ln[1]}_foot" pos="{_v(mod.B - parent_pos)}" size="0.004"/>',
            f'<site name="{ln[2]}_foot" pos="{_v(mod.A - parent_pos)}" size="0.004"/>',
        ]
        # leg s carries the platform, hinged at A'
        out += leg(ln[0], mod.A, mod.dir_s, mod.normal, s, parent_pos)
        out += [f'<body name="platform{k + 1}" pos="{_v(mod.A_top - mod.A)}">']
        out += [f'<joint name="platform{k + 1}" type="hinge" axis="{_v(mod.normal)}"/>']
        out += [f'<site name="{n}_head" pos="{_v(mod.B_top - mod.A_top)}" size="0.004"/>' for n in ln[1:]]
        out += stage(k)
        out += ["</body>", "</body>", "</body>"]
        out += leg(ln[1], mod.B, mod.dir_v, mod.normal, v, parent_pos) + ["</body>", "</body>"]
        out += leg(ln[2], mod.A, mod.dir_p, mod.normal, p, parent_pos) + ["</body>", "</body>"]
        return out

    tree = module(0, np.zeros(3))
    equality = []
    for k, m in enumerate(g.modules):
        for leg_name, top in ((f"v{k + 1}", m.B_top), (f"p{k + 1}", m.B_top)):
            base = m.B if leg_name.startswith("v") else m.A
            equality.append(
                f'<connect name="close_{leg_name}" body1="{leg_name}_rod" body2="platform{k + 1}" '
                f'anchor="{_v(top - base)}" solref="{timestep / 50:.6g} 1" solimp="0.99999 0.99999 0.001 0.5 2"/>'
            )
    tendons = [
        f'<spatial name="{n}_leg" damping="{damping[n]:.17g}" width="0.004">'
        f'<site site="{n}_foot"/><site site="{n}_head"/></spatial>'
        for n in closed
    ]
    actuators = [
        f'<motor name="{n}" tendon="{n}_leg" gear="1"/>' if n in closed else f'<motor name="{n}" joint="{n}" gear="1"/>'
        for n in names
    ]
    gravity = _v(np.array(stack.gravity))
    return "\n".join(
        [
            f'<mujoco model="{_attribute(stack.name)}">',
            '<compiler angle="radian" autolimits="true"/>',
            f'<option timestep="{timestep:.17g}" gravity="{gravity}" solver="Newton" iterations="200" '
            f'tolerance="{solver_tolerance:g}" integrator="Euler">',
            '<flag contact="disable"/>',
            "</option>",
            "<worldbody>",
            *tree,
            "</worldbody>",
            "<equality>",
            *equality,
            "</equality>",
            "<tendon>",
            *tendons,
            "</tendon>",
            "<actuator>",
            *actuators,
            "</actuator>",
            "<keyframe>",
            '<key name="home"/>',  # the reference configuration: the home pose, at rest
            "</keyframe>",
            "</mujoco>",
        ]
    )


def _attribute(text: str) -> str:
    """``text`` as an XML attribute value (quotes, ampersands and angle brackets escaped)."""
    return text.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;").replace(">", "&gt;")
