"""Symbolic kinematics and dynamics of a stack of VGT modules (CasADi SX), for any number of joints.

The same formulation as :mod:`vgtarm.model.symbolic`, whose building blocks it uses: each module
is solved in its plane in closed form (:func:`~vgtarm.model.symbolic.solve_module`), its plane is
turned by the module's angle about the axis of the frame it stands on, twist joints turn about
the platform normal (:func:`~vgtarm.model.symbolic.rot_z`), and the velocities, Jacobians and
the virtual-work dynamics are derived by automatic differentiation
(:func:`~vgtarm.model.symbolic.body_motion`).

Frames: the base of module 1 is F0. Module ``k`` stands on the frame ``(origin, R)`` below it (F0,
or the previous platform frame, or the previous twist frame moved up by the twist part's
height). In its plane ``(h, z)``, ``h`` runs along ``R Rz(phi_k) u2`` (``phi_k`` the plane angle),
so the paper's module 1 (``phi = 0``, plane ``u2-u3``) and its mirrored module 2 (``phi = 90``,
``h`` along ``-u1``) are the cases 0 and 90 degrees. Its platform frame sits at the platform
centre with ``C = R Rz(phi) Rx(theta) Rz(-phi)``: ``Rx(theta)`` for 0 and ``Ry(theta)`` for 90
degrees, as in paper eqs. 5-11. Cosines and sines of multiples of 90 degrees are exact, so the
paper's robot as a stack builds the very expressions of the fixed model.

Parameters (lengths, masses, inertias, tool, friction, gravity) enter as the symbol ``p`` laid out
as :meth:`~vgtarm.model.stack.description.Stack.vector`; the plane angles and which twist joints
and twist bodies exist are the structure, fixed when the expressions are built.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from ..symbolic import SX, BodyParameters, body_motion, rot_z, solve_module
from .description import BODY_VALUES, Stack


@dataclass(frozen=True)
class StackSymbols:
    """The stack's parameter symbol split into named parts (``None`` where the structure has none)."""

    b: tuple[SX, ...]
    d: tuple[SX, ...]
    platforms: tuple[BodyParameters, ...]
    twist_heights: tuple[SX | None, ...]  # one per module: the height of the twist after it
    twist_bodies: tuple[BodyParameters | None, ...]
    end_effector: BodyParameters
    tool: SX  # (3, 1)
    viscous: SX  # (n_joints, 1)
    gravity: SX  # (3, 1)


def _body(p: SX, o: int) -> BodyParameters:
    ixx, iyy, izz, ixy, ixz, iyz = (p[o + 4 + i] for i in range(6))
    inertia = ca.vertcat(ca.horzcat(ixx, ixy, ixz), ca.horzcat(ixy, iyy, iyz), ca.horzcat(ixz, iyz, izz))
    return BodyParameters(mass=p[o], com=p[o + 1 : o + 4], inertia=inertia)


def unpack_stack_parameters(stack: Stack, p: SX) -> StackSymbols:
    """Split ``p`` ``(n_parameters, 1)`` following :meth:`Stack.vector`."""
    if p.shape != (stack.n_parameters, 1):
        raise ValueError(f"parameter symbol must be ({stack.n_parameters}, 1), got {p.shape}")
    o = 0
    b, d, platforms, heights, twist_bodies = [], [], [], [], []
    for module in stack.modules:
        b.append(p[o])
        d.append(p[o + 1])
        platforms.append(_body(p, o + 2))
        o += 2 + BODY_VALUES
        height = body = None
        if module.twist is not None:
            height = p[o]
            o += 1
            if module.twist.body is not None:
                body = _body(p, o)
                o += BODY_VALUES
        heights.append(height)
        twist_bodies.append(body)
    end_effector = _body(p, o)
    o += BODY_VALUES
    n = stack.n_joints
    return StackSymbols(
        b=tuple(b),
        d=tuple(d),
        platforms=tuple(platforms),
        twist_heights=tuple(heights),
        twist_bodies=tuple(twist_bodies),
        end_effector=end_effector,
        tool=p[o : o + 3],
        viscous=p[o + 3 : o + 3 + n],
        gravity=p[o + 3 + n : o + 6 + n],
    )


def plane_direction(degrees: float) -> tuple[float, float]:
    """``(cos, sin)`` of a plane angle in degrees, exact (0, 1 or -1) for multiples of 90 degrees."""
    if degrees % 90.0 == 0.0:
        return ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[int(degrees // 90.0) % 4]
    radians = math.radians(degrees)
    return math.cos(radians), math.sin(radians)


def _combine(*terms: tuple[float, SX | None]) -> SX:
    """``sum c * x`` over terms ``(c, x)`` (``x = None`` is the constant 1), dropping ``c = 0`` and
    writing ``c = 1, -1`` as ``x, -x``: with exact plane directions this builds the same
    expressions as the elementary rotations."""
    total: SX | None = None
    for c, x in terms:
        if c == 0.0:
            continue
        term = SX(c) if x is None else (x if c == 1.0 else -x if c == -1.0 else c * x)
        total = term if total is None else total + term
    return SX(0) if total is None else total


def plane_rotation(direction: tuple[float, float], theta: SX) -> SX:
    """``Rz(phi) Rx(theta) Rz(-phi)``: the rotation by ``theta`` about ``(cos phi, sin phi, 0)``."""
    c, s = direction
    ct, st = ca.cos(theta), ca.sin(theta)
    off = _combine((c * s, None), (-c * s, ct))
    return ca.vertcat(
        ca.horzcat(_combine((c * c, None), (s * s, ct)), off, _combine((s, st))),
        ca.horzcat(off, _combine((s * s, None), (c * c, ct)), _combine((-c, st))),
        ca.horzcat(_combine((-s, st)), _combine((c, st)), ct),
    )


@dataclass(frozen=True)
class StackKinematics:
    """All kinematic quantities of one configuration, expressions of ``q`` and ``p``."""

    passive: SX  # (4 n_modules, 1): alpha, beta, gamma, theta of each module
    platform_origins: tuple[SX, ...]  # platform centres O_k in F0, (3, 1) each
    platform_rotations: tuple[SX, ...]  # C_0k of the platform frames, (3, 3) each
    twist_rotations: tuple[SX, ...]  # orientation of each twist frame, in joint order
    end_effector_rotation: SX  # (3, 3) frame of the last stage
    tip: SX  # (3, 1) tool point in F0
    body_com: tuple[SX, ...]  # centres of mass in F0, in the order of Stack.body_names
    body_rotation: tuple[SX, ...]  # orientations of the body frames


def stack_kinematics(stack: Stack, q: SX, p: SX) -> StackKinematics:
    """Closed-form forward kinematics of ``q`` ``(n_joints, 1)`` for parameters ``p``."""
    if q.shape != (stack.n_joints, 1):
        raise ValueError(f"joint symbol must be ({stack.n_joints}, 1), got {q.shape}")
    par = unpack_stack_parameters(stack, p)
    u3 = ca.vertcat(0, 0, 1)
    origin: SX | None = None  # None: the origin of F0
    rotation: SX | None = None  # None: the identity
    passive, origins, rotations, twists, coms, body_rotations = [], [], [], [], [], []
    i = 0
    for k, module in enumerate(stack.modules):
        plane = solve_module(q[i], q[i + 1], q[i + 2], par.b[k], par.d[k])
        passive += [plane.alpha, plane.beta, plane.gamma, plane.theta]
        c, s = plane_direction(module.plane)
        local = ca.vertcat(_combine((-s, plane.centre_h)), _combine((c, plane.centre_h)), plane.centre_z)
        centre = local if rotation is None else rotation @ local
        centre = centre if origin is None else origin + centre
        turn = plane_rotation((c, s), plane.theta)
        frame = turn if rotation is None else rotation @ turn
        origins.append(centre)
        rotations.append(frame)
        coms.append(centre + frame @ par.platforms[k].com)
        body_rotations.append(frame)
        i += 3
        origin, rotation = centre, frame
        height = par.twist_heights[k]
        if module.twist is not None and height is not None:
            rotation = frame @ rot_z(q[i])
            twists.append(rotation)
            body = par.twist_bodies[k]
            if body is not None:
                coms.append(centre + rotation @ body.com)
                body_rotations.append(rotation)
            origin = centre + height * (frame @ u3)
            i += 1
    if rotation is None or origin is None:  # a validated stack has at least one module
        raise ValueError("a stack needs at least one module")
    last_centre = origins[-1]
    coms.append(last_centre + rotation @ par.end_effector.com)
    body_rotations.append(rotation)
    tip = origin + rotation @ par.tool
    return StackKinematics(
        passive=ca.vertcat(*passive),
        platform_origins=tuple(origins),
        platform_rotations=tuple(rotations),
        twist_rotations=tuple(twists),
        end_effector_rotation=rotation,
        tip=tip,
        body_com=tuple(coms),
        body_rotation=tuple(body_rotations),
    )


def _body_parameters(stack: Stack, par: StackSymbols) -> list[BodyParameters]:
    bodies: list[BodyParameters] = []
    for k, platform in enumerate(par.platforms):
        bodies.append(platform)
        twist = par.twist_bodies[k]
        if twist is not None:
            bodies.append(twist)
    return [*bodies, par.end_effector]


@dataclass(frozen=True)
class StackDynamics:
    """Terms of ``M qdd + C = F + J_P^T f + J_W^T m`` for a tip wrench ``(f, m)`` (paper eq. 15)."""

    M: SX  # (n, n)
    C: SX  # (n, 1) velocity products + gravity + viscous friction
    J_P: SX  # (3, n) tip Jacobian
    J_W: SX  # (3, n) angular Jacobian of the end-effector frame (F0 components)
    kinetic_energy: SX
    potential_energy: SX


def stack_dynamics(stack: Stack, q: SX, qd: SX, p: SX) -> StackDynamics:
    """Virtual-work dynamics of the stack's bodies, as :func:`vgtarm.model.symbolic.dynamics`.

    ``sum_i J_v,i^T m_i (a_i - g) + J_w,i^T (I_i wdot_i + w_i x I_i w_i) + D qd = F + J^T w``.
    """
    n = stack.n_joints
    par = unpack_stack_parameters(stack, p)
    kin = stack_kinematics(stack, q, p)
    M = SX.zeros(n, n)
    C = par.viscous * qd
    kinetic = SX(0)
    potential = SX(0)
    for body, com, R in zip(_body_parameters(stack, par), kin.body_com, kin.body_rotation, strict=True):
        motion = body_motion(com, R, q, qd)
        inertia = R @ body.inertia @ R.T
        M += body.mass * (motion.J_v.T @ motion.J_v) + motion.J_w.T @ inertia @ motion.J_w
        w = motion.omega
        C += motion.J_v.T @ (body.mass * (motion.bias_acceleration - par.gravity))
        C += motion.J_w.T @ (inertia @ motion.bias_angular_acceleration + ca.cross(w, inertia @ w))
        kinetic += 0.5 * body.mass * ca.dot(motion.velocity, motion.velocity)
        kinetic += 0.5 * ca.dot(w, inertia @ w)
        potential -= body.mass * ca.dot(par.gravity, com)
    tip_motion = body_motion(kin.tip, kin.end_effector_rotation, q, qd)
    return StackDynamics(
        M=M,
        C=C,
        J_P=tip_motion.J_v,
        J_W=tip_motion.J_w,
        kinetic_energy=kinetic,
        potential_energy=potential,
    )
