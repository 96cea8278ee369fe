"""Compiled functions of the model family: kinematics, Jacobians and dynamics."""

from __future__ import annotations

import casadi as ca

from ..definition import PAPER, Definition
from ..symbolic import SX, body_motion
from .core import Builder, function, row_major, symbols


def fk(d: Definition = PAPER) -> ca.Function:
    q, _, p = symbols(d)
    k = d.kinematics(q, p)
    return function("vgt_fk", [q, p], list(k.fk_outputs), ["q", "p"], list(k.fk_names))


def tip(d: Definition = PAPER) -> ca.Function:
    q, _, p = symbols(d)
    return function("vgt_tip", [q, p], [d.kinematics(q, p).tip], ["q", "p"], ["tip"])


def jacobians(d: Definition = PAPER) -> ca.Function:
    q, qd, p = symbols(d)
    k = d.kinematics(q, p)
    motion = body_motion(k.tip, k.C03, q, qd)
    return function(
        "vgt_jac",
        [q, p],
        [row_major(motion.J_v), row_major(motion.J_w)],
        ["q", "p"],
        ["J_P", "J_W"],
    )


def com_jacobians(d: Definition = PAPER) -> ca.Function:
    q, qd, p = symbols(d)
    k = d.kinematics(q, p)
    motions = [body_motion(k.body_com[i], k.body_rotation[i], q, qd) for i in range(len(k.body_com))]
    J_v = ca.vertcat(*[row_major(m.J_v) for m in motions])
    J_w = ca.vertcat(*[row_major(m.J_w) for m in motions])
    return function("vgt_com_jac", [q, p], [J_v, J_w], ["q", "p"], ["J_v", "J_w"])


def velocities(d: Definition = PAPER) -> ca.Function:
    q, qd, p = symbols(d)
    k = d.kinematics(q, p)
    motion = body_motion(k.tip, k.C03, q, qd)
    return function(
        "vgt_velocity",
        [q, qd, p],
        [motion.velocity, motion.omega],
        ["q", "qd", "p"],
        ["tip_velocity", "omega"],
    )


def bias_accelerations(d: Definition = PAPER) -> ca.Function:
    q, qd, p = symbols(d)
    k = d.kinematics(q, p)
    tip_motion = body_motion(k.tip, k.C03, q, qd)
    bodies = [body_motion(k.body_com[i], k.body_rotation[i], q, qd) for i in range(len(k.body_com))]
    return function(
        "vgt_bias_acc",
        [q, qd, p],
        [
            tip_motion.bias_acceleration,
            tip_motion.bias_angular_acceleration,
            ca.vertcat(*[b.bias_acceleration for b in bodies]),
            ca.vertcat(*[b.bias_angular_acceleration for b in bodies]),
        ],
        ["q", "qd", "p"],
        ["tip", "angular", "com", "body_angular"],
    )


def mass_matrix(d: Definition = PAPER) -> ca.Function:
    q, qd, p = symbols(d)
    M = d.dynamics(q, qd, p).M
    return function("vgt_mass", [q, p], [row_major(M)], ["q", "p"], ["M"])


def bias_forces(d: Definition = PAPER) -> ca.Function:
    q, qd, p = symbols(d)
    return function("vgt_bias_forces", [q, qd, p], [d.dynamics(q, qd, p).C], ["q", "qd", "p"], ["C"])


def forward_dynamics(d: Definition = PAPER) -> ca.Function:
    q, qd, p = symbols(d)
    F = SX.sym("F", d.n_joints)
    f = SX.sym("f", 3)
    dyn = d.dynamics(q, qd, p)
    qdd = ca.solve(dyn.M, F + dyn.J_P.T @ f - dyn.C)
    return function("vgt_fd", [q, qd, F, f, p], [qdd], ["q", "qd", "F", "f", "p"], ["qdd"])


def inverse_dynamics(d: Definition = PAPER) -> ca.Function:
    q, qd, p = symbols(d)
    qdd = SX.sym("qdd", d.n_joints)
    f = SX.sym("f", 3)
    dyn = d.dynamics(q, qd, p)
    F = dyn.M @ qdd + dyn.C - dyn.J_P.T @ f
    return function("vgt_id", [q, qd, qdd, f, p], [F], ["q", "qd", "qdd", "f", "p"], ["F"])


def energy(d: Definition = PAPER) -> ca.Function:
    q, qd, p = symbols(d)
    dyn = d.dynamics(q, qd, p)
    return function(
        "vgt_energy",
        [q, qd, p],
        [dyn.kinetic_energy, dyn.potential_energy],
        ["q", "qd", "p"],
        ["kinetic", "potential"],
    )


#: The model's functions, by name.
BUILDERS: dict[str, Builder] = {
    "fk": fk,
    "tip": tip,
    "jac": jacobians,
    "com_jac": com_jacobians,
    "velocity": velocities,
    "bias_acc": bias_accelerations,
    "mass": mass_matrix,
    "bias_forces": bias_forces,
    "fd": forward_dynamics,
    "id": inverse_dynamics,
    "energy": energy,
}
