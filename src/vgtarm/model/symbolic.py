"""The one symbolic definition of the manipulator (CasADi SX expressions).

Everything else (Jacobians, their rates, the mass matrix, the velocity-product, gravity and
friction terms, forward and inverse dynamics) is derived from :func:`kinematics` here by
automatic differentiation; nothing is re-derived by hand elsewhere.

Conventions follow ``docs/conventions.md``: joint vector ``q = (s1, v1, p1, s2, v2, p2,
psi3)``; module 1 in the ``u2-u3`` plane of F0, module 2 mirrored in the ``u1-u3`` plane of F1;
``C01 = Rx(theta1)``, ``C02 = C01 Ry(theta2)``, ``C03 = C02 Rz(psi3)``; tip
``P = r1 + C01 r2 + h1 C02 u3`` (paper eq. 6).

Expressions take the flat parameter vector of :meth:`~vgtarm.model.parameters.RobotParameters.vector`
as a symbol, so the compiled code serves every robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from .parameters import N_PARAMETERS

SX = ca.SX


@dataclass(frozen=True)
class BodyParameters:
    """Symbolic inertial parameters of one body."""

    mass: SX
    com: SX  # (3, 1) in the body frame
    inertia: SX  # (3, 3) about the centre of mass, in the body frame


@dataclass(frozen=True)
class ParameterSymbols:
    """The flat parameter vector split into named symbolic parts."""

    b: tuple[SX, SX]
    d: tuple[SX, SX]
    h1: SX
    bodies: tuple[BodyParameters, BodyParameters, BodyParameters]
    viscous: SX  # (7, 1)
    gravity: SX  # (3, 1)


def unpack_parameters(p: SX) -> ParameterSymbols:
    """Split the parameter symbol ``p`` (45, 1) following ``RobotParameters.vector``."""
    if p.shape != (N_PARAMETERS, 1):
        raise ValueError(f"parameter symbol must be ({N_PARAMETERS}, 1), got {p.shape}")
    bodies = []
    for k in range(3):
        o = 5 + 10 * k
        ixx, iyy, izz, ixy, ixz, iyz = (p[o + 4 + i] for i in range(6))
        inertia = ca.vertcat(
            ca.horzcat(ixx, ixy, ixz),
            ca.horzcat(ixy, iyy, iyz),
            ca.horzcat(ixz, iyz, izz),
        )
        bodies.append(BodyParameters(mass=p[o], com=p[o + 1 : o + 4], inertia=inertia))
    return ParameterSymbols(
        b=(p[0], p[2]),
        d=(p[1], p[3]),
        h1=p[4],
        bodies=(bodies[0], bodies[1], bodies[2]),
        viscous=p[35:42],
        gravity=p[42:45],
    )


def rot_x(angle: SX) -> SX:
    """Right-handed elementary rotation about x."""
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))


def rot_y(angle: SX) -> SX:
    """Right-handed elementary rotation about y."""
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))


def rot_z(angle: SX) -> SX:
    """Right-handed elementary rotation about z."""
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))


@dataclass(frozen=True)
class ModulePlane:
    """Closed-form solution of one planar VGT module in its plane ``(h, z)`` (paper eqs. 1-4)."""

    alpha: SX
    beta: SX
    gamma: SX
    theta: SX
    centre_h: SX
    centre_z: SX


def solve_module(s: SX, v: SX, p: SX, b: SX, d: SX) -> ModulePlane:
    """Passive angles and platform centre of a module with legs ``s, v`` and diagonal ``p``.

    Base joints ``A = (-b, 0)``, ``B = (b, 0)``; ``B' = A + p (cos beta, sin beta)`` (``B'``
    above the base), ``A' = A + s (cos alpha, sin alpha)`` with ``alpha = beta + delta`` (``A'``
    left of the diagonal). Valid only for assemblable leg sets (checked before evaluation).
    """
    beta = ca.acos((p**2 + 4 * b**2 - v**2) / (4 * b * p))
    gamma = ca.atan2(p * ca.sin(beta), p * ca.cos(beta) - 2 * b)
    delta = ca.acos((s**2 + p**2 - 4 * d**2) / (2 * s * p))
    alpha = beta + delta
    a_top_h = -b + s * ca.cos(alpha)
    a_top_z = s * ca.sin(alpha)
    b_top_h = -b + p * ca.cos(beta)
    b_top_z = p * ca.sin(beta)
    theta = ca.atan2(b_top_z - a_top_z, b_top_h - a_top_h)
    return ModulePlane(
        alpha=alpha,
        beta=beta,
        gamma=gamma,
        theta=theta,
        centre_h=(a_top_h + b_top_h) / 2,
        centre_z=(a_top_z + b_top_z) / 2,
    )


@dataclass(frozen=True)
class Kinematics:
    """All kinematic quantities of one configuration, as expressions of ``q`` and ``p``."""

    passive: SX  # (8, 1): alpha1, beta1, gamma1, theta1, alpha2, beta2, gamma2, theta2
    O1: SX  # (3, 1) platform-1 centre in F0
    C01: SX  # (3, 3)
    O2: SX  # (3, 1) platform-2 centre in F0
    C02: SX
    C03: SX  # end-effector orientation
    tip: SX  # (3, 1) tip point P in F0
    body_com: tuple[SX, SX, SX]  # centres of mass of bodies 7, 8, 9 in F0
    body_rotation: tuple[SX, SX, SX]  # orientations of the body frames F1, F2, F3


def kinematics(q: SX, p: SX) -> Kinematics:
    """Closed-form forward kinematics (paper eqs. 1-11) of ``q`` (7, 1) for parameters ``p``."""
    par = unpack_parameters(p)
    m1 = solve_module(q[0], q[1], q[2], par.b[0], par.d[0])
    m2 = solve_module(q[3], q[4], q[5], par.b[1], par.d[1])
    # Module 1 in the u2-u3 plane of F0: (h, z) -> (0, h, z).
    O1 = ca.vertcat(0, m1.centre_h, m1.centre_z)
    C01 = rot_x(m1.theta)
    # Module 2 mirrored in the u1-u3 plane of F1: (h, z) -> (-h, 0, z).
    r21 = ca.vertcat(-m2.centre_h, 0, m2.centre_z)
    O2 = O1 + C01 @ r21
    C02 = C01 @ rot_y(m2.theta)
    C03 = C02 @ rot_z(q[6])
    u3 = ca.vertcat(0, 0, 1)
    tip = O2 + par.h1 * (C02 @ u3)
    origins = (O1, O2, O2)
    rotations = (C01, C02, C03)
    coms = tuple(origins[k] + rotations[k] @ par.bodies[k].com for k in range(3))
    passive = ca.vertcat(m1.alpha, m1.beta, m1.gamma, m1.theta, m2.alpha, m2.beta, m2.gamma, m2.theta)
    return Kinematics(
        passive=passive,
        O1=O1,
        C01=C01,
        O2=O2,
        C02=C02,
        C03=C03,
        tip=tip,
        body_com=(coms[0], coms[1], coms[2]),
        body_rotation=rotations,
    )


def row_major(matrix: SX) -> SX:
    """Flatten a matrix row by row into a column vector (``vec(A.T)``: how every function's matrix
    output is laid out)."""
    return ca.vec(matrix.T)


def time_derivative(expr: SX, q: SX, qd: SX) -> SX:
    """d/dt of an expression of ``q`` (and of the constant-rate symbol ``qd``), with ``qdd = 0``.

    Works for matrices by differentiating their entries.
    """
    flat = ca.reshape(expr, expr.numel(), 1)
    return ca.reshape(ca.jtimes(flat, q, qd), expr.shape[0], expr.shape[1])


def vee(skew: SX) -> SX:
    """The vector of the skew-symmetric part of a 3x3 matrix: ``vee(w^) = w``."""
    return 0.5 * ca.vertcat(skew[2, 1] - skew[1, 2], skew[0, 2] - skew[2, 0], skew[1, 0] - skew[0, 1])


def angular_velocity(rotation: SX, q: SX, qd: SX) -> SX:
    """Angular velocity in F0 of a frame with orientation ``rotation(q)``: ``vee(Rdot R^T)``."""
    return vee(time_derivative(rotation, q, qd) @ rotation.T)


@dataclass(frozen=True)
class BodyMotion:
    """Velocity-level quantities of one body, expressions of ``q``, ``qd`` and ``p``."""

    J_v: SX  # (3, 7) Jacobian of the centre of mass
    J_w: SX  # (3, 7) angular Jacobian (F0 components)
    velocity: SX  # (3, 1)
    omega: SX  # (3, 1)
    bias_acceleration: SX  # (3, 1) centre-of-mass acceleration when qdd = 0
    bias_angular_acceleration: SX  # (3, 1) angular acceleration when qdd = 0


def body_motion(position: SX, rotation: SX, q: SX, qd: SX) -> BodyMotion:
    """Jacobians, velocities and velocity-product ("bias") accelerations of a body."""
    velocity = ca.jtimes(position, q, qd)
    omega = angular_velocity(rotation, q, qd)
    return BodyMotion(
        J_v=ca.jacobian(position, q),
        J_w=ca.jacobian(omega, qd),
        velocity=velocity,
        omega=omega,
        bias_acceleration=ca.jtimes(velocity, q, qd),
        bias_angular_acceleration=ca.jtimes(omega, q, qd),
    )


@dataclass(frozen=True)
class Dynamics:
    """Terms of the equation of motion ``M qdd + C = F + J_P^T f`` (paper eq. 15)."""

    M: SX  # (7, 7)
    C: SX  # (7, 1) velocity products + gravity + viscous friction
    J_P: SX  # (3, 7) tip Jacobian
    kinetic_energy: SX
    potential_energy: SX


def dynamics(q: SX, qd: SX, p: SX) -> Dynamics:
    """Virtual-work dynamics (paper eqs. 13-15) of the three bodies.

    ``sum_i J_v,i^T m_i (a_i - g) + J_w,i^T (I_i wdot_i + w_i x I_i w_i) + D qd = F + J_P^T f``
    with ``a_i = J_v,i qdd + a_bias,i`` and ``wdot_i = J_w,i qdd + alpha_bias,i`` (eq. 14),
    ``I_i`` the body inertia rotated into F0 and ``D`` the diagonal viscous friction.
    """
    par = unpack_parameters(p)
    kin = kinematics(q, p)
    M = SX.zeros(7, 7)
    C = par.viscous * qd
    kinetic = SX(0)
    potential = SX(0)
    for k in range(3):
        body = par.bodies[k]
        motion = body_motion(kin.body_com[k], kin.body_rotation[k], q, qd)
        R = kin.body_rotation[k]
        inertia = R @ body.inertia @ R.T
        M += body.mass * (motion.J_v.T @ motion.J_v) + motion.J_w.T @ inertia @ motion.J_w
        w = motion.omega
        C += motion.J_v.T @ (body.mass * (motion.bias_acceleration - par.gravity))
        C += motion.J_w.T @ (inertia @ motion.bias_angular_acceleration + ca.cross(w, inertia @ w))
        kinetic += 0.5 * body.mass * ca.dot(motion.velocity, motion.velocity)
        kinetic += 0.5 * ca.dot(w, inertia @ w)
        potential -= body.mass * ca.dot(par.gravity, kin.body_com[k])
    return Dynamics(
        M=M,
        C=C,
        J_P=ca.jacobian(kin.tip, q),
        kinetic_energy=kinetic,
        potential_energy=potential,
    )
