"""Compiled functions of the inverse-kinematics family (model layer; see core.py for conventions).

Inverse kinematics (paper eq. 12) needs, per sample, the equality constraints ``c(q)`` of the
task, their Jacobian and the Hessian of ``lam^T c``, all derived from the one kinematic
definition :func:`~vgtarm.model.symbolic.kinematics` by automatic differentiation:

- the **position** task: ``c(q) = P(q)`` (3 rows; the desired point is subtracted outside);
- the **pose** task: ``c(q) = [P(q); e(q, R_d)]`` (6 rows) with the orientation residual
  ``e = 0.5 vee(R_d^T R - R^T R_d)`` of the end-effector orientation ``R = C03`` against ``R_d``
  (``|e| = sin`` of the angle between them, components in the target frame).

The cost ``Phi`` is a quadratic of the joint limits, which are not part of the parameter vector; it
is evaluated in NumPy by the callers and contributes nothing to second derivatives beyond its
constant Hessian.

The **effort** criterion adds ``Phi_e(q, f) = (1/n) sum_i (s_i tau_i(q, f))^2`` (functions
``ik_effort*``), with the static generalised efforts ``tau(q, f) = G(q) - J_P(q)^T f`` that hold the
arm against gravity and a tool force ``f`` on the tip (``G`` is the velocity-product, gravity and
friction term ``C`` of the one dynamics definition at ``qd = 0``: gravity alone) and the inverse
scales ``s`` (1/N, 1/(N m)) given by the caller. The tool force moves along the path as
``f(s) = f + fd s + fdd s^2 / 2``, which has the exact first and second time derivatives at
``s = 0``; the KKT residual ``[grad Phi_e + J_P^T lam; P]`` is differentiated along ``s`` as for a
moving target orientation.

For the exact reference rates the KKT residual ``F(q, lam, s) = [J_c(q, s)^T lam; c(q, s)]`` is
differentiated along the path parameter ``s`` (time): ``*_dt`` is ``dF/ds`` at fixed ``(q, lam)``
and ``*_d2`` is ``d^2/ds^2 F(q + s qd, lam + s lam_d, s)`` at ``s = 0``. A time-varying target
orientation enters through ``R_d(s) = (I + [w] s + ([a] + [w]^2) s^2 / 2) R_d``, which has the
exact first and second derivatives of a rotation with angular velocity ``w`` and acceleration ``a``
(both in F0) at ``s = 0``. The desired point enters linearly and is handled by the callers.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca

from ..definition import PAPER, Definition
from ..symbolic import SX, vee
from .core import Builder, function, row_major
from .core import symbols as symbols_of

#: Number of equality rows of each task.
TASK_ROWS = {"position": 3, "pose": 6}


def rotation_from_row_major(values: SX) -> SX:
    """The 3x3 matrix whose rows are ``values[0:3]``, ``values[3:6]``, ``values[6:9]``."""
    return ca.reshape(values, 3, 3).T


def skew(w: SX) -> SX:
    """The skew-symmetric matrix ``[w]`` with ``[w] v = w x v``."""
    return ca.vertcat(
        ca.horzcat(0, -w[2], w[1]),
        ca.horzcat(w[2], 0, -w[0]),
        ca.horzcat(-w[1], w[0], 0),
    )


def orientation_residual(rotation: SX, target: SX) -> SX:
    """``0.5 vee(R_d^T R - R^T R_d)`` (3, 1): ``sin(angle) * axis`` in the target frame."""
    return vee(target.T @ rotation)


def pose_constraints(q: SX, target: SX, p: SX, d: Definition = PAPER) -> SX:
    """``[P(q); e(q, R_d)]`` (6, 1): tip point (m) and orientation residual of ``C03`` (rad-like)."""
    k = d.kinematics(q, p)
    return ca.vertcat(k.tip, orientation_residual(k.C03, target))


def _symbols(m: int, d: Definition) -> tuple[SX, SX, SX, SX, SX]:
    return (
        SX.sym("q", d.n_joints),
        SX.sym("lam", m),
        SX.sym("qd", d.n_joints),
        SX.sym("lam_d", m),
        SX.sym("p", d.n_parameters),
    )


def _kkt_parts(c: SX, q: SX, lam: SX) -> tuple[SX, SX]:
    """Jacobian ``J_c`` and Hessian of ``lam^T c`` with respect to ``q``."""
    J = ca.jacobian(c, q)
    H = ca.jacobian(J.T @ lam, q)
    return J, H


def position_kkt(d: Definition = PAPER) -> ca.Function:
    """``(q, lam, p) -> (P, J_P, H)``: tip (3), its Jacobian (3x7) and ``d^2(lam^T P)/dq^2`` (7x7)."""
    q, lam, _, _, p = _symbols(3, d)
    c = d.kinematics(q, p).tip
    J, H = _kkt_parts(c, q, lam)
    return function("vgt_ik_position", [q, lam, p], [c, row_major(J), row_major(H)], ["q", "lam", "p"], ["c", "J", "H"])


def position_d2(d: Definition = PAPER) -> ca.Function:
    """``(q, lam, qd, lam_d, p) -> d2`` (10): second derivative of ``[J_P^T lam; P]`` along ``(qd, lam_d)``."""
    q, lam, qd, lam_d, p = _symbols(3, d)
    c = d.kinematics(q, p).tip
    J = ca.jacobian(c, q)
    F = ca.vertcat(J.T @ lam, c)
    z, dz = ca.vertcat(q, lam), ca.vertcat(qd, lam_d)
    d2 = ca.jtimes(ca.jtimes(F, z, dz), z, dz)
    return function("vgt_ik_position_d2", [q, lam, qd, lam_d, p], [d2], ["q", "lam", "qd", "lam_d", "p"], ["d2"])


def pose_kkt(d: Definition = PAPER) -> ca.Function:
    """``(q, lam, R_d, p) -> (c, J_c, H)``: ``[P; e]`` (6), Jacobian (6x7), ``d^2(lam^T c)/dq^2`` (7x7).

    ``R_d`` is the target orientation flattened row by row (9).
    """
    q, lam, _, _, p = _symbols(6, d)
    rd = SX.sym("R_d", 9)
    c = pose_constraints(q, rotation_from_row_major(rd), p, d)
    J, H = _kkt_parts(c, q, lam)
    return function(
        "vgt_ik_pose", [q, lam, rd, p], [c, row_major(J), row_major(H)], ["q", "lam", "R_d", "p"], ["c", "J", "H"]
    )


def _moving_pose_residual(d: Definition) -> tuple[SX, list[SX], SX, SX]:
    """KKT residual ``F`` of the pose task with the target rotating along ``s`` (module docstring).

    Returns ``F`` (13), the symbols ``[q, lam, qd, lam_d, R_d, w, a, p]``, the direction
    ``(qd, lam_d, 1)`` of ``(q, lam, s)`` and ``s``.
    """
    q, lam, qd, lam_d, p = _symbols(6, d)
    rd, w, a, s = SX.sym("R_d", 9), SX.sym("w", 3), SX.sym("a", 3), SX.sym("s")
    spin = skew(w)
    moving = (SX.eye(3) + spin * s + (skew(a) + spin @ spin) * (s**2 / 2)) @ rotation_from_row_major(rd)
    c = pose_constraints(q, moving, p, d)
    F = ca.vertcat(ca.jacobian(c, q).T @ lam, c)
    z = ca.vertcat(q, lam, s)
    dz = ca.vertcat(qd, lam_d, 1)
    return F, [q, lam, qd, lam_d, rd, w, a, p], ca.jtimes(F, z, dz), s


def pose_dt(d: Definition = PAPER) -> ca.Function:
    """``(q, lam, R_d, w, a, p) -> dF/ds`` (13) at fixed ``(q, lam)``, without the desired point's term."""
    F, (q, lam, _, _, rd, w, a, p), _, s = _moving_pose_residual(d)
    dt = ca.substitute(ca.jacobian(F, s), s, 0)
    return function("vgt_ik_pose_dt", [q, lam, rd, w, a, p], [dt], ["q", "lam", "R_d", "w", "a", "p"], ["dt"])


def pose_d2(d: Definition = PAPER) -> ca.Function:
    """``(q, lam, qd, lam_d, R_d, w, a, p) -> d^2/ds^2 F(q + s qd, lam + s lam_d, s)`` (13) at ``s = 0``.

    Without the desired point's term (``-xdd`` in the position rows), which the caller adds.
    """
    _, symbols, dF, s = _moving_pose_residual(d)
    q, lam, qd, lam_d, _, _, _, _ = symbols
    z = ca.vertcat(q, lam, s)
    dz = ca.vertcat(qd, lam_d, 1)
    d2 = ca.substitute(ca.jtimes(dF, z, dz), s, 0)
    names = ["q", "lam", "qd", "lam_d", "R_d", "w", "a", "p"]
    return function("vgt_ik_pose_d2", symbols, [d2], names, ["d2"])


def _rates_through_qr(K: SX, first_rhs: SX, second_rhs_of: Callable[[SX], SX]) -> tuple[SX, SX]:
    """Solve ``K x1 = first_rhs`` and ``K x2 = second_rhs_of(x1)`` sharing one QR factorisation of ``K``."""
    Q, R = ca.qr(K)
    first = ca.solve(R, Q.T @ first_rhs)
    second = ca.solve(R, Q.T @ second_rhs_of(first))
    return first, second


def position_rates(d: Definition = PAPER) -> ca.Function:
    """Model values and exact rates at a solution where no inequality is active (the common case).

    ``(q, lam, w, xd, xdd, p) -> (P, J_P, H, qd, lam_d, qdd, lam_dd)``: ``w`` (7) is the diagonal of
    the Hessian of ``Phi``; the KKT matrix ``[[diag(w) + H, J^T], [J, 0]]`` is factorised once (QR)
    for both rate systems. Samples with active limits or triangle rows use the general path.
    """
    q, lam, qd_s, lam_d_s, p = _symbols(3, d)
    w, xd, xdd = SX.sym("w", d.n_joints), SX.sym("xd", 3), SX.sym("xdd", 3)
    c = d.kinematics(q, p).tip
    J, H = _kkt_parts(c, q, lam)
    K = ca.blockcat([[ca.diag(w) + H, J.T], [J, SX.zeros(3, 3)]])
    F = ca.vertcat(J.T @ lam, c)
    z, dz = ca.vertcat(q, lam), ca.vertcat(qd_s, lam_d_s)
    d2 = ca.jtimes(ca.jtimes(F, z, dz), z, dz)

    def second_rhs(first: SX) -> SX:
        return ca.vertcat(SX.zeros(d.n_joints), xdd) - ca.substitute(d2, dz, first)

    first, second = _rates_through_qr(K, ca.vertcat(SX.zeros(d.n_joints), xd), second_rhs)
    names = ["q", "lam", "w", "xd", "xdd", "p"]
    n = d.n_joints
    outputs = [c, row_major(J), row_major(H), first[:n], first[n:], second[:n], second[n:]]
    out_names = ["c", "J", "H", "qd", "lam_d", "qdd", "lam_dd"]
    return function("vgt_ik_position_rates", [q, lam, w, xd, xdd, p], outputs, names, out_names)


def pose_rates(d: Definition = PAPER) -> ca.Function:
    """As :func:`position_rates` for the pose task: ``(q, lam, w, xd, xdd, R_d, w_d, a_d, p) -> (c, J, H, qd,
    lam_d, qdd, lam_dd)`` with the target orientation ``R_d`` (row-major) turning at ``w_d``, ``a_d``."""
    F, (q, lam, qd_s, lam_d_s, rd, w_d, a_d, p), dF, s = _moving_pose_residual(d)
    w, xd, xdd = SX.sym("w", d.n_joints), SX.sym("xd", 3), SX.sym("xdd", 3)
    at_rest = ca.substitute(F, s, 0)
    c = at_rest[d.n_joints :]
    J, H = _kkt_parts(c, q, lam)
    K = ca.blockcat([[ca.diag(w) + H, J.T], [J, SX.zeros(6, 6)]])
    z, dz = ca.vertcat(q, lam, s), ca.vertcat(qd_s, lam_d_s, 1)
    first_rhs = ca.vertcat(SX.zeros(d.n_joints), xd, SX.zeros(3)) - ca.substitute(ca.jacobian(F, s), s, 0)
    d2 = ca.substitute(ca.jtimes(dF, z, dz), s, 0)

    def second_rhs(first: SX) -> SX:
        return ca.vertcat(SX.zeros(d.n_joints), xdd, SX.zeros(3)) - ca.substitute(d2, ca.vertcat(qd_s, lam_d_s), first)

    first, second = _rates_through_qr(K, first_rhs, second_rhs)
    names = ["q", "lam", "w", "xd", "xdd", "R_d", "w_d", "a_d", "p"]
    n = d.n_joints
    outputs = [c, row_major(J), row_major(H), first[:n], first[n:], second[:n], second[n:]]
    out_names = ["c", "J", "H", "qd", "lam_d", "qdd", "lam_dd"]
    return function("vgt_ik_pose_rates", [q, lam, w, xd, xdd, rd, w_d, a_d, p], outputs, names, out_names)


def static_efforts(q: SX, f: SX, p: SX, d: Definition = PAPER) -> SX:
    """``tau = G(q) - J_P(q)^T f`` (n, 1): the actuator efforts that hold the arm at rest at ``q``
    against gravity and the force ``f`` (3) acting on the tip.

    ``G = dV/dq`` is the gradient of the dynamics definition's potential energy: the term ``C`` of
    ``M qdd + C = F + J_P^T f`` at ``qd = 0`` (no velocity products, no viscous friction), the same
    values (``tests/test_effort.py`` checks them against ``C(q, 0)``) from an expression a third
    the size, which matters for the third and fourth derivatives the effort criterion's Newton
    steps and exact rates take of it.
    """
    qd = SX.sym("qd_rest", d.n_joints)
    dyn = d.dynamics(q, qd, p)
    gravity = ca.gradient(dyn.potential_energy, q)
    return ca.substitute(gravity - dyn.J_P.T @ f, qd, ca.DM.zeros(d.n_joints))


def effort_cost(q: SX, f: SX, scale: SX, p: SX, d: Definition = PAPER) -> SX:
    """``Phi_e = (1/n) sum_i (scale_i tau_i)^2`` (1, 1), ``tau`` of :func:`static_efforts`."""
    return ca.sumsqr(scale * static_efforts(q, f, p, d)) / d.n_joints


def _shared(f: ca.Function) -> ca.Function:
    """``f`` with its common subexpressions evaluated once (CasADi's ``cse``; every output keeps its
    value bit for bit, see :mod:`vgtarm.model.codegen`): the effort functions are new, so unlike the
    paper robot's older functions they have no generated C to keep byte for byte."""
    inputs = f.sx_in()
    return ca.Function(f.name(), inputs, f.call(inputs), f.name_in(), f.name_out(), {"cse": True})


def _effort_symbols(d: Definition) -> tuple[SX, SX, SX, SX, SX]:
    return SX.sym("f", 3), SX.sym("fd", 3), SX.sym("fdd", 3), SX.sym("s", d.n_joints), SX.sym("t")


def _moving_effort_residual(d: Definition) -> tuple[SX, list[SX], SX, SX, SX]:
    """KKT residual ``F = [grad Phi_e + J_P^T lam; P]`` (n + 3) with the tool force moving along ``t``.

    Returns ``F``, the symbols ``[q, lam, qd, lam_d, f, fd, fdd, s, p]``, the second derivative
    ``d^2/dt^2 F(q + t qd, lam + t lam_d, t)`` at ``t = 0``, ``t`` and the cost at ``t``. The
    gradient rows of that second derivative are the gradient in ``q`` of the scalar
    ``d^2/dt^2 L`` of the Lagrangian ``L = Phi_e + lam^T P`` (the shift along ``t`` and the gradient
    commute), which is far smaller than differentiating the gradient twice.
    """
    q, lam, qd, lam_d, p = _symbols(3, d)
    f, fd, fdd, scale, t = _effort_symbols(d)
    moving = f + fd * t + fdd * (t**2 / 2)
    cost = effort_cost(q, moving, scale, p, d)
    c = d.kinematics(q, p).tip
    lagrangian = cost + ca.dot(lam, c)
    F = ca.vertcat(ca.gradient(lagrangian, q), c)
    z, dz = ca.vertcat(q, lam, t), ca.vertcat(qd, lam_d, 1)
    second = ca.jtimes(ca.jtimes(lagrangian, z, dz), z, dz)
    c2 = ca.jtimes(ca.jtimes(c, q, qd), q, qd)
    d2 = ca.substitute(ca.vertcat(ca.gradient(second, q), c2), t, 0)
    return F, [q, lam, qd, lam_d, f, fd, fdd, scale, p], d2, t, cost


def effort_kkt(d: Definition = PAPER) -> ca.Function:
    """``(q, lam, f, s, p) -> (c, J, H, g, phi)``: tip (3), ``J_P`` (3xn), the Hessian of
    ``Phi_e + lam^T P`` (nxn), ``grad Phi_e`` (n) and ``Phi_e`` (1) for the tool force ``f``."""
    F, (q, lam, _, _, f, _, _, scale, p), _, t, cost = _moving_effort_residual(d)
    n = d.n_joints
    at_rest = ca.substitute(F, t, 0)
    c, g = at_rest[n:], ca.substitute(ca.gradient(cost, q), t, 0)
    J = ca.jacobian(c, q)
    H = ca.jacobian(at_rest[:n], q)
    outputs = [c, row_major(J), row_major(H), g, ca.substitute(cost, t, 0)]
    names = ["q", "lam", "f", "s", "p"]
    return _shared(function("vgt_ik_effort", [q, lam, f, scale, p], outputs, names, ["c", "J", "H", "g", "phi"]))


def effort_static(d: Definition = PAPER) -> ca.Function:
    """``(q, f, s, p) -> (tau, phi)``: the static efforts ``tau`` (n) of :func:`static_efforts` and ``Phi_e`` (1)."""
    q, _, p = symbols_of(d)
    f, _, _, scale, _ = _effort_symbols(d)
    tau = static_efforts(q, f, p, d)
    phi = ca.sumsqr(scale * tau) / d.n_joints
    return _shared(function("vgt_ik_effort_static", [q, f, scale, p], [tau, phi], ["q", "f", "s", "p"], ["tau", "phi"]))


def effort_dt(d: Definition = PAPER) -> ca.Function:
    """``(q, lam, f, fd, s, p) -> dF/dt`` (n + 3) at fixed ``(q, lam)``, without the desired point's term."""
    F, (q, lam, _, _, f, fd, fdd, scale, p), _, t, _ = _moving_effort_residual(d)
    dt = ca.substitute(ca.jacobian(F, t), ca.vertcat(t, fdd), SX.zeros(4))
    names = ["q", "lam", "f", "fd", "s", "p"]
    return _shared(function("vgt_ik_effort_dt", [q, lam, f, fd, scale, p], [dt], names, ["dt"]))


def effort_d2(d: Definition = PAPER) -> ca.Function:
    """``(q, lam, qd, lam_d, f, fd, fdd, s, p) -> d^2/dt^2 F(q + t qd, lam + t lam_d, t)`` (n + 3) at
    ``t = 0``, without the desired point's term (``-xdd`` in the position rows)."""
    _, symbols, d2, _, _ = _moving_effort_residual(d)
    names = ["q", "lam", "qd", "lam_d", "f", "fd", "fdd", "s", "p"]
    return _shared(function("vgt_ik_effort_d2", symbols, [d2], names, ["d2"]))


def effort_rates(d: Definition = PAPER) -> ca.Function:
    """As :func:`position_rates` for the effort criterion: ``(q, lam, w, xd, xdd, f, fd, fdd, s, p) ->
    (c, J, H, g, qd, lam_d, qdd, lam_dd)``, ``w`` (n) the diagonal of the joint-limit term's Hessian."""
    F, (q, lam, qd_s, lam_d_s, f, fd, fdd, scale, p), d2, t, cost = _moving_effort_residual(d)
    n = d.n_joints
    w, xd, xdd = SX.sym("w", n), SX.sym("xd", 3), SX.sym("xdd", 3)
    at_rest = ca.substitute(F, t, 0)
    c, g = at_rest[n:], ca.substitute(ca.gradient(cost, q), t, 0)
    J = ca.jacobian(c, q)
    H = ca.jacobian(at_rest[:n], q)
    K = ca.blockcat([[ca.diag(w) + H, J.T], [J, SX.zeros(3, 3)]])
    first_rhs = ca.vertcat(SX.zeros(n), xd) - ca.substitute(ca.jacobian(F, t), ca.vertcat(t, fdd), SX.zeros(4))

    def second_rhs(first: SX) -> SX:
        return ca.vertcat(SX.zeros(n), xdd) - ca.substitute(d2, ca.vertcat(qd_s, lam_d_s), first)

    first, second = _rates_through_qr(K, first_rhs, second_rhs)
    names = ["q", "lam", "w", "xd", "xdd", "f", "fd", "fdd", "s", "p"]
    outputs = [c, row_major(J), row_major(H), g, first[:n], first[n:], second[:n], second[n:]]
    out_names = ["c", "J", "H", "g", "qd", "lam_d", "qdd", "lam_dd"]
    inputs = [q, lam, w, xd, xdd, f, fd, fdd, scale, p]
    return _shared(function("vgt_ik_effort_rates", inputs, outputs, names, out_names))


#: Functions of this family, by name.
BUILDERS: dict[str, Builder] = {
    "ik_position": position_kkt,
    "ik_position_d2": position_d2,
    "ik_pose": pose_kkt,
    "ik_pose_dt": pose_dt,
    "ik_pose_d2": pose_d2,
    "ik_position_rates": position_rates,
    "ik_pose_rates": pose_rates,
    "ik_effort": effort_kkt,
    "ik_effort_static": effort_static,
    "ik_effort_dt": effort_dt,
    "ik_effort_d2": effort_d2,
    "ik_effort_rates": effort_rates,
}
