"""MJCF export of the robot (MuJoCo's XML model format).

The paper's mechanism as a MuJoCo tree closed by equality constraints. Each module: three base
hinges on the module's plane normal (at ``A`` for the leg ``s`` and the diagonal ``p``, at ``B``
for the leg ``v``), a slide along each leg, the platform hinged at the top of ``s`` (``A'``),
and the top of ``v`` and of ``p`` tied to the platform's corner ``B'`` by ``connect``
equalities. Module 2 stands on platform 1 in its ``u1-u3`` plane, mirrored; the twist is a hinge
on platform 2's ``u3`` axis; the end-effector rides on it; a site ``tip`` marks the tool tip.

The closed legs ``v`` and ``p`` are driven through spatial tendons ``<leg>_leg`` from their foot
(a site on the module's base body) to their head (a site at ``B'`` on the platform): a tendon's
length is the leg length, and its motor and viscous friction act on the base and the platform
directly, so no effort passes through MuJoCo's soft equality constraints. The slide-jointed leg
bodies are passive followers (no motor, no damping, almost no mass) whose joints still read the
paper's joint values. The leg ``s`` is on the tree path: its motor and friction are on its slide.

Every body frame is aligned with F0 at the home pose, so joint axes and inertias are written in
F0 at home; slides have ``ref`` = their home length and the twist ``ref`` = its home angle, so the
actuated joints' positions are the paper's joint values. What MuJoCo needs that the paper's
model does not (documented in ``docs/mujoco.md``): a tiny mass on each leg (the paper's legs are
massless), and constraint solver settings that make the loop closures as stiff as MuJoCo allows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..model.parameters import JOINT_NAMES, RobotParameters
from ..model.robot import Robot

Array = NDArray[np.float64]

#: Mass (kg) and inertia (kg m^2) of each leg body, which the paper takes as massless: the
#: lightest MuJoCo solves well, a thousand times its floor ``mjMINVAL`` = 1e-15 in mass and ten
#: times in inertia (a rod's ``m L^2 / 12`` at L = 0.35 m). The closed legs' efforts act through
#: tendons, not through the soft loop closures, so all that leaks through those closures is the
#: legs' own inertia: M and forward dynamics agree with the massless legs to about 1e-12 relative
#: (docs/mujoco.md).
LEG_MASS = 1e-12
LEG_INERTIA = 1e-14


@dataclass(frozen=True)
class ModuleHome:
    """One module at the home pose, in F0: joint points, leg directions and the plane normal."""

    A: Array
    B: Array
    A_top: Array
    B_top: Array
    dir_s: Array
    dir_v: Array
    dir_p: Array
    normal: Array


def _module_home(origin: Array, R: Array, b: float, passive: Array, legs: Array) -> ModuleHome:
    """Module points from its plane map ``(h, z) -> origin + R[:, 0] h + R[:, 1] z`` (F0)."""
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
    )


@dataclass(frozen=True)
class HomeGeometry:
    """Everything the export places, at the robot's home pose (F0 coordinates)."""

    modules: tuple[ModuleHome, ModuleHome]
    O1: Array
    O2: Array
    C01: Array
    C02: Array
    C03: Array
    tip: Array
    passive: Array


def home_geometry(robot: Robot) -> HomeGeometry:
    """Everything the export places, at the robot's home pose (F0 coordinates)."""
    par = robot.parameters
    q = par.home
    fk = robot.forward_kinematics(q)
    passive = fk.passive
    C01 = fk.platform_rotation[0]
    C02 = fk.platform_rotation[1]
    O1, O2 = fk.platform_position
    # module 1: (h, z) -> (0, h, z); module 2: (h, z) -> O1 + C01 (-h, 0, z)
    plane1 = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    plane2 = C01 @ np.array([[-1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    m1 = _module_home(np.zeros(3), plane1, par.b[0], passive[0], q[0:3])
    m2 = _module_home(np.asarray(O1), plane2, par.b[1], passive[1], q[3:6])
    return HomeGeometry(
        modules=(m1, m2),
        O1=np.asarray(O1),
        O2=np.asarray(O2),
        C01=C01,
        C02=C02,
        C03=fk.rotation,
        tip=fk.tip,
        passive=passive,
    )


def _v(x: Array) -> str:
    return " ".join(f"{float(c):.17g}" for c in np.ravel(x))


def _inertial(mass: float, com: Array, inertia: Array) -> str:
    sym = 0.5 * (inertia + inertia.T)
    full = [sym[0, 0], sym[1, 1], sym[2, 2], sym[0, 1], sym[0, 2], sym[1, 2]]
    return f'<inertial pos="{_v(com)}" mass="{mass:.17g}" fullinertia="{_v(np.array(full))}"/>'


def _leg_inertial(mass: float, inertia: float) -> str:
    return f'<inertial pos="0 0 0" mass="{mass:.17g}" diaginertia="{inertia:.17g} {inertia:.17g} {inertia:.17g}"/>'


def to_mjcf(
    robot: Robot,
    *,
    timestep: float = 1e-3,
    solver_tolerance: float = 1e-12,
    leg_mass: float = LEG_MASS,
    leg_inertia: float = LEG_INERTIA,
) -> str:
    """The robot as an MJCF document (text).

    Joints and force actuators are named after the paper (``s1, v1, p1, s2, v2, p2, psi3``;
    motors, gear 1, control = effort in N or N m, no control limits); the motors of the closed
    legs ``v``, ``p`` drive the tendons ``<leg>_leg``, the others their joints; passive hinges
    ``<leg>_base`` and ``platform<k>``; the tool tip is the site ``tip``; the keyframe ``home`` is
    the robot's home pose at rest. Viscous friction is joint damping (``s``, twist) or tendon
    damping (``v``, ``p``); gravity is the robot's. ``leg_mass`` (kg) and ``leg_inertia``
    (kg m^2) are given to every leg body (the paper's legs are massless; MuJoCo refuses below
    1e-15).
    """
    par: RobotParameters = robot.parameters
    g = home_geometry(robot)
    m1, m2 = g.modules
    O1, O2, C01, C02, C03 = g.O1, g.O2, g.C01, g.C02, g.C03
    q = par.home
    names = JOINT_NAMES
    bodies = par.bodies
    damping = dict(zip(names, par.viscous, strict=True))
    # the closed legs v and p of every module (the s leg of each is on the tree path)
    closed = [n for k in range(len(par.modules)) for n in names[3 * k + 1 : 3 * k + 3]]

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

    def module(k: int, mod: ModuleHome, parent_pos: Array, platform_xml: list[str]) -> list[str]:
        s, v, p = q[3 * k : 3 * k + 3]
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
        out += platform_xml
        out += ["</body>", "</body>", "</body>"]
        out += leg(ln[1], mod.B, mod.dir_v, mod.normal, v, parent_pos) + ["</body>", "</body>"]
        out += leg(ln[2], mod.A, mod.dir_p, mod.normal, p, parent_pos) + ["</body>", "</body>"]
        return out

    # platform 2 and what rides on it, in platform-2 body coordinates (origin A'_2)
    p2_origin = m2.A_top
    ee_com = O2 + C03 @ np.array(bodies[2].com)
    twist_xml = [
        f'<body name="end_effector" pos="{_v(O2 - p2_origin)}">',
        _inertial(bodies[2].mass, ee_com - O2, C03 @ bodies[2].inertia_matrix @ C03.T),
        f'<joint name="psi3" type="hinge" axis="{_v(C02[:, 2])}" ref="{q[6]:.17g}" damping="{damping["psi3"]:.17g}"/>',
        f'<geom type="cylinder" fromto="0 0 0 {_v(par.h1 * C02[:, 2])}" size="0.03" rgba="0.7 0.7 0.8 1"/>',
        f'<site name="tip" pos="{_v(par.h1 * C02[:, 2])}" size="0.005"/>',
        "</body>",
    ]
    platform2_xml = [
        _inertial(
            bodies[1].mass, O2 + C02 @ np.array(bodies[1].com) - p2_origin, C02 @ bodies[1].inertia_matrix @ C02.T
        ),
        *twist_xml,
    ]
    p1_origin = m1.A_top
    platform1_xml = [
        _inertial(
            bodies[0].mass, O1 + C01 @ np.array(bodies[0].com) - p1_origin, C01 @ bodies[0].inertia_matrix @ C01.T
        ),
        *module(1, m2, p1_origin, platform2_xml),
    ]
    tree = module(0, m1, np.zeros(3), platform1_xml)
    equality = []
    for k, m in enumerate((m1, m2)):
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
    gravity = _v(np.array(par.gravity))
    return "\n".join(
        [
            f'<mujoco model="{par.name}">',
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
