"""MJCF export of a robot (MuJoCo's XML model format): the paper's robot or any stack of modules,
built with MuJoCo's model-editing API (``mujoco.MjSpec``, :func:`to_spec`) and written by it
(:func:`to_mjcf`), as a scene MuJoCo's viewer shows (base, platforms, floor, light, sky, a camera
on the tool: drawing only, no contact and no mass), every number with :data:`DIGITS` significant
digits.

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

A robot file with a ``[stiffness]`` table makes every actuated joint a spring about a reference
configuration (``spring_reference``, by default the home pose): the stiffness and ``springref`` of
the slide ``s`` and of each twist, the stiffness and ``springlength`` of each closed leg's tendon
(``docs/stiffness.md``). Without the table nothing is written (the file is as before).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..errors import InputError, escape, shown
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
#: Significant digits of every number the export writes: the fewest at which ``vgtarm check
#: mujoco`` on the written model still agrees with our dynamics to 1e-9 on every example
#: (measured for 6 to 17 digits in docs/mujoco.md). ``MAX_DIGITS`` writes every number as it is.
DIGITS = 13
MIN_DIGITS = 6
MAX_DIGITS = 17


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


def require_mujoco() -> Any:
    """The ``mujoco`` module, or one line saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise InputError("MuJoCo is not installed: pip install 'vgtarm[mujoco]'") from None
    return mujoco


def rounded(x: ArrayLike, digits: int) -> list[float]:
    """``x`` rounded to ``digits`` significant digits of its largest element (an axis ``(1, 6e-17,
    0)`` becomes ``(1, 0, 0)``; a value alone keeps ``digits`` of its own); at
    :data:`MAX_DIGITS` the values are kept as they are. Python's ``round`` gives the double
    nearest the decimal, which MuJoCo's writer (shortest round trip) prints with at most
    ``digits`` digits."""
    values = [float(v) for v in np.ravel(np.asarray(x, dtype=float))]
    largest = max((abs(v) for v in values), default=0.0)
    if digits >= MAX_DIGITS or largest == 0.0:
        return [v + 0.0 for v in values]  # "+ 0.0": no signed zeros in the file
    decimals = digits - 1 - math.floor(math.log10(largest))
    return [round(v, decimals) + 0.0 for v in values]


def _check_export(
    robot: object,
    timestep: object,
    solver_tolerance: object,
    leg_mass: object,
    leg_inertia: object,
    digits: object,
    spring_reference: object = None,
) -> Array | None:
    if not isinstance(robot, Robot):
        raise InputError(f"robot = {shown(robot)}: expected a vgtarm.Robot (see vgtarm.load_robot)")
    checks.number("timestep", timestep, above=0, maximum=MAX_TIMESTEP, unit="s")
    checks.number("solver_tolerance", solver_tolerance, above=0, maximum=1)
    checks.number("leg_mass", leg_mass, above=MJ_MINVAL, unit="kg")
    checks.number("leg_inertia", leg_inertia, above=MJ_MINVAL, unit="kg m^2")
    digits_unit = f"significant digits; {MAX_DIGITS}: every number as it is"
    checks.whole("digits", digits, MIN_DIGITS, MAX_DIGITS, unit=digits_unit)
    if spring_reference is None:
        return None
    reference = checks.finite_array("spring_reference", spring_reference, (robot.n_joints,))
    robot.check_assembly(reference, where="spring_reference")
    return reference


#: Colours of the scene (RGBA): the legs ``s`` and ``v``, the diagonals ``p``, the platforms,
#: the base and what the stack carries (twists, tool).
COLOURS = {
    "leg": (0.25, 0.62, 0.35, 1.0),
    "diagonal": (0.9, 0.55, 0.2, 1.0),
    "platform": (0.35, 0.5, 0.75, 1.0),
    "base": (0.3, 0.3, 0.33, 1.0),
    "tool": (0.78, 0.78, 0.82, 1.0),
    "tip": (0.9, 0.15, 0.15, 1.0),
}


#: A tool frame this close to the end-effector body's axes (every element) is written as the body's:
#: round-off of a home pose standing straight (2.8e-16 for ``examples/six_modules.toml``).
_SAME_AXES = 1e-12


def to_spec(
    robot: Robot,
    *,
    timestep: float = 1e-3,
    solver_tolerance: float = 1e-12,
    leg_mass: float = LEG_MASS,
    leg_inertia: float = LEG_INERTIA,
    digits: int = DIGITS,
    scene: bool = True,
    spring_reference: ArrayLike | None = None,
) -> Any:
    """The robot (the paper's or any stack of modules) as a ``mujoco.MjSpec``, MuJoCo's own model
    (see :func:`to_mjcf`, which writes it). Needs MuJoCo (``vgtarm[mujoco]``)."""
    reference = _check_export(robot, timestep, solver_tolerance, leg_mass, leg_inertia, digits, spring_reference)
    builder = _SpecBuilder(
        robot, require_mujoco(), leg_mass=leg_mass, leg_inertia=leg_inertia, digits=digits, scene=scene
    )
    builder.springs(reference)
    return builder.build(timestep, solver_tolerance)


class _SpecBuilder:
    """The ``mujoco.MjSpec`` of one robot, built by :func:`to_spec`: the options, then the tree
    module by module from the world (:meth:`module`, :meth:`stage`), then the loop closures,
    tendons and motors. Every number goes through :meth:`r` (``digits`` significant digits)."""

    def __init__(
        self, robot: Robot, mujoco: Any, *, leg_mass: float, leg_inertia: float, digits: int, scene: bool
    ) -> None:
        self.mujoco = mujoco
        self.g = home_geometry(robot)
        self.stack = self.g.stack
        self.q = self.stack.home
        self.names = self.stack.joint_names
        self.damping = dict(zip(self.names, self.stack.viscous, strict=True))
        # the closed legs v and p of every module (the s leg of each is on the tree path)
        self.closed = [self.names[j] for legs in self.stack.leg_indices for j in legs[1:]]
        self.last = len(self.g.modules) - 1
        self.tool = np.array(self.stack.tool, dtype=float)
        self.tool_rotation = self.stack.tool_rotation
        self.leg_mass = leg_mass
        self.leg_inertia = leg_inertia
        self.digits = digits
        self.scene = scene
        self.spec = mujoco.MjSpec()
        #: Per joint, its stiffness and spring reference (empty: rigid joints, no springs written).
        self.spring: dict[str, tuple[float, float]] = {}

    def springs(self, reference: Array | None) -> None:
        """Every actuated joint a spring about ``reference`` (the home pose if ``None``) when the
        robot has a ``[stiffness]`` table."""
        table = self.stack.stiffness
        if table is None:
            return
        at = self.q if reference is None else reference
        self.spring = {n: (float(k), float(x)) for n, k, x in zip(self.names, table.values, at, strict=True)}

    def spring_on(self, element: Any, name: str, reference: str) -> None:
        """The joint ``name``'s spring on ``element`` (a joint: ``springref``; a tendon:
        ``springlength``, its dead band closed), if it has one."""
        if name not in self.spring:
            return
        k, at = self.spring[name]
        element.stiffness = [self.r1(k), 0.0, 0.0]
        setattr(element, reference, self.r1(at) if reference == "springref" else [self.r1(at)] * 2)

    def r(self, x: ArrayLike) -> list[float]:
        return rounded(x, self.digits)

    def r1(self, x: float) -> float:
        return rounded(x, self.digits)[0]

    def build(self, timestep: float, solver_tolerance: float) -> Any:
        """The whole spec: options, scene, tree, loop closures, tendons, motors, keyframe."""
        self.options(timestep, solver_tolerance)
        spec = self.spec
        if self.scene:
            _surroundings(spec, self.g, self.visual, self.r, self.mujoco)
        self.module(spec.worldbody, 0, np.zeros(3))
        self.closures(timestep)
        self.drives()
        spec.add_key(name="home")  # the reference configuration: the home pose, at rest
        return spec

    def options(self, timestep: float, solver_tolerance: float) -> None:
        """The model's name, compiler settings, simulation options and (with a scene) materials."""
        mujoco, spec, r, r1 = self.mujoco, self.spec, self.r, self.r1
        spec.modelname = escape(self.stack.name)  # a user's name: no control character reaches the file
        spec.compiler.degree = False
        spec.compiler.autolimits = True
        # every body has its inertial: geoms (the scene's drawing) never add mass or inertia
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
        # written as built (fullinertia, fromto, motor, ...) and each number exactly as given
        spec.compiler.savecompiled = False
        spec.compiler.savecanonical = False
        option = spec.option
        option.timestep = r1(timestep)
        option.gravity = r(self.stack.gravity)
        option.solver = mujoco.mjtSolver.mjSOL_NEWTON
        option.iterations = 200
        option.tolerance = r1(solver_tolerance)
        option.integrator = mujoco.mjtIntegrator.mjINT_EULER
        option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        if self.scene:
            _materials(spec, mujoco)

    def visual(self, body: Any, kind: Any, size: list[float], material: str, **placement: Any) -> Any:
        """A geom that is only drawn: no contact, no mass (the compiler takes no inertia from
        geoms), in group 0 (shown)."""
        geom = body.add_geom(type=kind, size=size, contype=0, conaffinity=0, **placement)
        if self.scene:
            geom.material = material
        else:
            geom.rgba = COLOURS[material]
        return geom

    def inertial(self, body: Any, mass: float, com: ArrayLike, inertia: Array) -> None:
        r = self.r
        sym = 0.5 * (inertia + inertia.T)
        body.explicitinertial = True
        body.mass = self.r1(mass)
        body.ipos = r(com)
        body.fullinertia = r([sym[0, 0], sym[1, 1], sym[2, 2], sym[0, 1], sym[0, 2], sym[1, 2]])

    def part(self, body: Any, part: Body, origin: Array, rotation: Array, body_origin: Array) -> None:
        """``part`` (given in the frame ``rotation`` at ``origin``) as the inertial of ``body``,
        whose frame is at ``body_origin`` (F0 axes)."""
        com = origin + rotation @ np.array(part.com) - body_origin
        self.inertial(body, part.mass, com, rotation @ part.inertia_matrix @ rotation.T)

    def light(self, body: Any) -> None:
        """A leg's mass and inertia (or a twist's without a part of its own)."""
        body.explicitinertial = True
        body.mass = self.r1(self.leg_mass)
        body.ipos = [0.0, 0.0, 0.0]
        body.inertia = self.r([self.leg_inertia] * 3)

    def leg(
        self, parent: Any, name: str, base: Array, direction: Array, normal: Array, length: float, at: Array
    ) -> Any:
        """A base hinge body at ``base`` and in it a rod body sliding along ``direction``; the
        slide of a leg on the tree path (``s``) carries its friction, the closed legs' friction
        is on their tendons. Returns the rod body."""
        mujoco, r, r1 = self.mujoco, self.r, self.r1
        hinge = parent.add_body(name=f"{name}_base", pos=r(base - at))
        self.light(hinge)
        hinge.add_joint(name=f"{name}_base", type=mujoco.mjtJoint.mjJNT_HINGE, axis=r(normal))
        rod = hinge.add_body(name=f"{name}_rod")
        self.light(rod)
        slide = rod.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=r(direction), ref=r1(length))
        if name not in self.closed:
            slide.damping = [r1(self.damping[name]), 0.0, 0.0]
            self.spring_on(slide, name, "springref")
        material = "diagonal" if name.startswith("p") else "leg"
        self.visual(rod, mujoco.mjtGeom.mjGEOM_CAPSULE, [0.006], material, fromto=[0.0] * 3 + r(direction * length))
        return rod

    def effector(self, body: Any, origin: Array, rotation: Array, mount: Array) -> None:
        """The end-effector's inertial, and the tip site (with a rod from the mount point to it
        when the tool stands off), in ``body`` at ``origin`` (the last platform's centre) whose
        tool is mounted at ``mount`` from it and turned by ``rotation`` at home. The site's axes
        are the tool frame (``z`` the tool's axis, ``x`` its edge): an orientation is written
        only when that frame is not the body's (F0's axes at home), so a default tool on an arm
        standing straight at home keeps the file as it was."""
        r = self.r
        self.part(body, self.stack.end_effector, origin, rotation, origin)
        tip = mount + rotation @ self.tool
        site = body.add_site(name="tip", pos=r(tip), size=[0.005])
        frame = rotation @ self.tool_rotation  # the tool frame at home, in the body's (F0) axes
        if np.abs(frame - np.eye(3)).max() > _SAME_AXES:
            quat = np.zeros(4)
            self.mujoco.mju_mat2Quat(quat, frame.ravel())
            site.quat = r(quat)
        if self.scene:
            site.material = "tip"
        if self.tool.any():
            self.visual(body, self.mujoco.mjtGeom.mjGEOM_CAPSULE, [0.005], "tool", fromto=r(mount) + r(tip))

    def stage(self, platform: Any, k: int) -> None:
        """Everything inside platform ``k``'s body (origin ``A'``): its inertial, then the twist
        with what rides on it (:meth:`twist`), or directly what stands on the platform."""
        mod = self.g.modules[k]
        self.part(platform, self.stack.modules[k].platform, mod.centre, mod.rotation, mod.A_top)
        if mod.twist is not None:
            self.twist(platform, k, mod.twist)
        elif k < self.last:
            self.module(platform, k + 1, mod.A_top)
        else:  # the end-effector fixed on the last platform
            body = platform.add_body(name="end_effector", pos=self.r(mod.centre - mod.A_top))
            self.effector(body, mod.centre, self.g.rotation, np.zeros(3))

    def twist(self, platform: Any, k: int, twist: TwistHome) -> None:
        """The twist after module ``k`` in its platform's body: a hinged body (the end-effector
        itself when it is the last frame and has no part of its own) carrying what follows."""
        mujoco, r, r1 = self.mujoco, self.r, self.r1
        mod = self.g.modules[k]
        lumped = k == self.last and twist.body is None  # the twist's body is the end-effector
        name = "end_effector" if lumped else f"twist{twist.joint[3:]}"
        body = platform.add_body(name=name, pos=r(mod.centre - mod.A_top))
        if lumped:
            self.effector(body, mod.centre, twist.rotation, twist.mount)
        elif twist.body is None:
            self.light(body)
        else:
            self.part(body, twist.body, mod.centre, twist.rotation, mod.centre)
        hinge = body.add_joint(
            name=twist.joint,
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=r(mod.rotation[:, 2]),
            ref=r1(twist.home),
            damping=[r1(twist.viscous), 0.0, 0.0],
        )
        self.spring_on(hinge, twist.joint, "springref")
        self.visual(body, mujoco.mjtGeom.mjGEOM_CYLINDER, [0.03], "tool", fromto=[0.0] * 3 + r(twist.mount))
        if lumped:
            return
        if k == self.last:  # the end-effector fixed on the twist's part
            self.effector(body.add_body(name="end_effector"), mod.centre, twist.rotation, twist.mount)
        else:
            self.module(body, k + 1, mod.centre)

    def module(self, parent: Any, k: int, at: Array) -> None:
        """Module ``k`` (0-based) in ``parent``, a body whose origin is at ``at`` (F0)."""
        mujoco, r = self.mujoco, self.r
        mod = self.g.modules[k]
        i = self.stack.leg_indices[k][0]
        s, v, p = self.q[i : i + 3]
        ln = [f"s{k + 1}", f"v{k + 1}", f"p{k + 1}"]
        if self.scene:  # the module's base: a bar from A to B on what it stands on
            self.visual(parent, mujoco.mjtGeom.mjGEOM_CAPSULE, [0.01], "base", fromto=r(mod.A - at) + r(mod.B - at))
        # the closed legs' tendons run between these sites: their feet on the module's base
        # body, their heads at the platform's corner B'
        parent.add_site(name=f"{ln[1]}_foot", pos=r(mod.B - at), size=[0.004])
        parent.add_site(name=f"{ln[2]}_foot", pos=r(mod.A - at), size=[0.004])
        # leg s carries the platform, hinged at A'
        rod = self.leg(parent, ln[0], mod.A, mod.dir_s, mod.normal, s, at)
        platform = rod.add_body(name=f"platform{k + 1}", pos=r(mod.A_top - mod.A))
        platform.add_joint(name=f"platform{k + 1}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=r(mod.normal))
        for n in ln[1:]:
            platform.add_site(name=f"{n}_head", pos=r(mod.B_top - mod.A_top), size=[0.004])
        if self.scene:
            _platform(platform, mod, self.stack, k, self.visual, r, mujoco)
        self.stage(platform, k)
        self.leg(parent, ln[1], mod.B, mod.dir_v, mod.normal, v, at)
        self.leg(parent, ln[2], mod.A, mod.dir_p, mod.normal, p, at)

    def closures(self, timestep: float) -> None:
        """The ``connect`` equalities that close each module's legs ``v`` and ``p`` on its
        platform's corner ``B'``, as stiff as the time step allows."""
        mujoco = self.mujoco
        for k, m in enumerate(self.g.modules):
            for leg_name, base in ((f"v{k + 1}", m.B), (f"p{k + 1}", m.A)):
                closure = self.spec.add_equality(
                    name=f"close_{leg_name}",
                    type=mujoco.mjtEq.mjEQ_CONNECT,
                    objtype=mujoco.mjtObj.mjOBJ_BODY,
                    name1=f"{leg_name}_rod",
                    name2=f"platform{k + 1}",
                    solref=[float(f"{timestep / 50:.6g}"), 1.0],
                    solimp=[0.99999, 0.99999, 0.001, 0.5, 2.0],
                )
                closure.data[0:3] = self.r(m.B_top - base)

    def drives(self) -> None:
        """The closed legs' tendons (with their friction) and a motor on every joint: on its
        tendon for a closed leg, on the joint itself otherwise."""
        mujoco, spec = self.mujoco, self.spec
        for n in self.closed:
            tendon = spec.add_tendon(name=f"{n}_leg", damping=[self.r1(self.damping[n]), 0.0, 0.0], width=0.004)
            tendon.wrap_site(f"{n}_foot")
            tendon.wrap_site(f"{n}_head")
            self.spring_on(tendon, n, "springlength")
        actuators = self.stack.actuators
        peak = dict(zip(self.names, actuators.force, strict=True)) if actuators is not None else {}
        for n in self.names:
            kind = mujoco.mjtTrn.mjTRN_TENDON if n in self.closed else mujoco.mjtTrn.mjTRN_JOINT
            motor = spec.add_actuator(name=n, trntype=kind, target=f"{n}_leg" if n in self.closed else n)
            motor.set_to_motor()
            if math.isfinite(peak.get(n, math.inf)):  # the actuator's peak force, unrounded (the
                # force-speed line has no MJCF form: vgtarm's loop clips to it before MuJoCo's turn)
                motor.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
                motor.forcerange = [-float(peak[n]), float(peak[n])]


def to_mjcf(
    robot: Robot,
    *,
    timestep: float = 1e-3,
    solver_tolerance: float = 1e-12,
    leg_mass: float = LEG_MASS,
    leg_inertia: float = LEG_INERTIA,
    digits: int = DIGITS,
    scene: bool = True,
    spring_reference: ArrayLike | None = None,
) -> str:
    """The robot (the paper's or any stack of modules) as an MJCF document (text), built with
    MuJoCo's model-editing API (:func:`to_spec`, ``mujoco.MjSpec``) and written by it, indented.

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

    Every number is written with at most ``digits`` significant digits (:data:`DIGITS`, the
    fewest at which MuJoCo's dynamics still agree with ours to 1e-9, measured in
    ``docs/mujoco.md``; :data:`MAX_DIGITS` writes every number as it is). With ``scene`` (the
    default) the model opens as a scene in MuJoCo's viewer: the base, the platforms, a floor, a
    light, a sky and the camera ``tool`` that follows the end-effector, all drawing only (no
    contact, no mass: the dynamics are those of ``scene=False``). Needs MuJoCo
    (``vgtarm[mujoco]``).

    A robot with a ``[stiffness]`` table gets a spring on every actuated joint (stiffness and
    ``springref`` on the slides ``s`` and the twists, stiffness and ``springlength`` on the closed
    legs' tendons) about ``spring_reference`` ``(n,)`` (m, rad; default the home pose): the
    compliant arm of :mod:`vgtarm.design.stiffness`. A robot without one has no springs (and the
    argument changes nothing).
    """
    return str(
        to_spec(
            robot,
            timestep=timestep,
            solver_tolerance=solver_tolerance,
            leg_mass=leg_mass,
            leg_inertia=leg_inertia,
            digits=digits,
            scene=scene,
            spring_reference=spring_reference,
        ).to_xml()
    )


def _materials(spec: Any, mujoco: Any) -> None:
    """The scene's materials (one per colour of :data:`COLOURS`, the floor's checker) and sky,
    all built-in textures: the file needs no other file."""
    for name, rgba in COLOURS.items():
        spec.add_material(name=name, rgba=rgba, specular=0.3, shininess=0.4)
    spec.add_texture(
        name="sky",
        type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        rgb1=[0.62, 0.74, 0.88],
        rgb2=[0.12, 0.14, 0.18],
        width=512,
        height=3072,
    )
    spec.add_texture(
        name="checker",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        rgb1=[0.34, 0.36, 0.4],
        rgb2=[0.27, 0.29, 0.32],
        mark=mujoco.mjtMark.mjMARK_EDGE,
        markrgb=[0.55, 0.57, 0.6],
        width=300,
        height=300,
    )
    floor = spec.add_material(name="floor", texrepeat=[5.0, 5.0], texuniform=True, reflectance=0.1)
    floor.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "checker"


def _unit(x: Array) -> Array:
    return x / np.linalg.norm(x)


def _platform(platform: Any, mod: ModuleHome, stack: Stack, k: int, visual: Any, r: Any, mujoco: Any) -> None:
    """Platform ``k`` drawn in its body (origin ``A'``): a bar from ``A'`` to ``B'`` and a plate
    under its centre, wide enough for the module standing on it."""
    visual(platform, mujoco.mjtGeom.mjGEOM_CAPSULE, [0.01], "platform", fromto=[0.0] * 3 + r(mod.B_top - mod.A_top))
    above = stack.modules[k + 1].b if k + 1 < len(stack.modules) else 0.0
    radius = max(stack.modules[k].d, above) + 0.02
    centre = mod.centre - mod.A_top
    under = centre - 0.008 * mod.rotation[:, 2]
    visual(platform, mujoco.mjtGeom.mjGEOM_CYLINDER, r([radius]), "platform", fromto=r(under) + r(centre))


def _surroundings(spec: Any, g: HomeGeometry, visual: Any, r: Any, mujoco: Any) -> None:
    """What the scene has around the robot: a floor across gravity (no contact: contacts are off
    and the floor has none), the base slab under module 1, a sun light, the camera ``tool``
    that keeps the end-effector in view from beside and above the tool, and the free camera's
    first view."""
    gravity = np.array(g.stack.gravity, dtype=float)
    up = -_unit(gravity) if np.linalg.norm(gravity) > 0 else np.array([0.0, 0.0, 1.0])
    axis = np.eye(3)[0] if abs(up[0]) < 0.9 else np.eye(3)[1]
    ahead = _unit(axis - (axis @ up) * up)
    side = np.cross(up, ahead)
    points = [g.tip] + [m.centre for m in g.modules]
    size = max(0.3, *(float(np.linalg.norm(p)) for p in points))
    world = spec.worldbody
    floor = visual(world, mujoco.mjtGeom.mjGEOM_PLANE, r([2 * size, 2 * size, 0.05]), "floor", pos=r(-0.02 * up))
    floor.alt.type = mujoco.mjtOrientation.mjORIENTATION_ZAXIS
    floor.alt.zaxis = r(up)
    first = g.modules[0]
    slab = visual(
        world,
        mujoco.mjtGeom.mjGEOM_BOX,
        r([0.06, g.stack.modules[0].b + 0.05, 0.01]),
        "base",
        pos=[0.0, 0.0, -0.01],
    )
    slab.alt.type = mujoco.mjtOrientation.mjORIENTATION_XYAXES
    slab.alt.xyaxes = r(first.normal) + r(_unit(first.B - first.A))
    sun = world.add_light(
        name="sun",
        type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
        pos=r(3 * size * up),
        dir=r(_unit(-up - 0.4 * ahead + 0.3 * side)),
        castshadow=False,  # shadow maps speckle the plates in software rendering
        diffuse=[0.7, 0.7, 0.7],
        specular=[0.2, 0.2, 0.2],
    )
    sun.ambient = [0.1, 0.1, 0.1]
    world.add_camera(
        name="tool",
        mode=mujoco.mjtCamLight.mjCAMLIGHT_TARGETBODY,
        targetbody="end_effector",
        pos=r(g.tip + 1.2 * size * _unit(ahead - side + 0.5 * up)),
        fovy=45.0,
    )
    spec.visual.headlight.ambient = [0.25, 0.25, 0.25]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 960
    spec.visual.global_.azimuth = 135.0
    spec.visual.global_.elevation = -20.0
