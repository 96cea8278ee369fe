"""Compiled functions of the model family: kinematics, Jacobians and dynamics."""

from __future__ import annotations

import casadi as ca

from ..parameters import N_JOINTS
from ..symbolic import SX, body_motion, dynamics, kinematics
from .core import Builder, function, row_major, symbols


def fk() -> ca.Function:
    q, _, p = symbols()
    k = kinematics(q, p)
    outputs = [k.passive, k.O1, row_major(k.C01), k.O2, row_major(k.C02), k.tip, row_major(k.C03)]
    names = ["passive", "O1", "C01", "O2", "C02", "tip", "C03"]
    return function("vgt_fk", [q, p], outputs, ["q", "p"], names)


def tip() -> ca.Function:
    q, _, p = symbols()
    return function("vgt_tip", [q, p], [kinematics(q, p).tip], ["q", "p"], ["tip"])


def jacobians() -> ca.Function:
    q, qd, p = symbols()
    k = kinematics(q, p)
    motion = body_motion(k.tip, k.C03, q, qd)
    return function(
        "vgt_jac",
        [q, p],
        [row_major(motion.J_v), row_major(motion.J_w)],
        ["q", "p"],
        ["J_P", "J_W"],
    )


def com_jacobians() -> ca.Function:
    q, qd, p = symbols()
    k = kinematics(q, p)
    motions = [body_motion(k.body_com[i], k.body_rotation[i], q, qd) for i in range(3)]
    J_v = ca.vertcat(*[row_major(m.J_v) for m in motions])
    J_w = ca.vertcat(*[row_major(m.J_w) for m in motions])
    return function("vgt_com_jac", [q, p], [J_v, J_w], ["q", "p"], ["J_v", "J_w"])


def velocities() -> ca.Function:
    q, qd, p = symbols()
    k = kinematics(q, p)
    motion = body_motion(k.tip, k.C03, q, qd)
    return function(
        "vgt_velocity",
        [q, qd, p],
        [motion.velocity, motion.omega],
        ["q", "qd", "p"],
        ["tip_velocity", "omega"],
    )


def bias_accelerations() -> ca.Function:
    q, qd, p = symbols()
    k = kinematics(q, p)
    tip_motion = body_motion(k.tip, k.C03, q, qd)
    bodies = [body_motion(k.body_com[i], k.body_rotation[i], q, qd) for i in range(3)]
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


def mass_matrix() -> ca.Function:
    q, qd, p = symbols()
    M = dynamics(q, qd, p).M
    return function("vgt_mass", [q, p], [row_major(M)], ["q", "p"], ["M"])


def bias_forces() -> ca.Function:
    q, qd, p = symbols()
    return function("vgt_bias_forces", [q, qd, p], [dynamics(q, qd, p).C], ["q", "qd", "p"], ["C"])


def forward_dynamics() -> ca.Function:
    q, qd, p = symbols()
    F = SX.sym("F", N_JOINTS)
    f = SX.sym("f", 3)
    dyn = dynamics(q, qd, p)
    qdd = ca.solve(dyn.M, F + dyn.J_P.T @ f - dyn.C)
    return function("vgt_fd", [q, qd, F, f, p], [qdd], ["q", "qd", "F", "f", "p"], ["qdd"])


def inverse_dynamics() -> ca.Function:
    q, qd, p = symbols()
    qdd = SX.sym("qdd", N_JOINTS)
    f = SX.sym("f", 3)
    dyn = dynamics(q, qd, p)
    F = dyn.M @ qdd + dyn.C - dyn.J_P.T @ f
    return function("vgt_id", [q, qd, qdd, f, p], [F], ["q", "qd", "qdd", "f", "p"], ["F"])


def energy() -> ca.Function:
    q, qd, p = symbols()
    dyn = dynamics(q, qd, p)
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
