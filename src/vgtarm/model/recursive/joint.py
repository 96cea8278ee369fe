"""The one module joint of every stack, as CasADi functions generated once (not per arm).

A planar VGT module is a three-degree-of-freedom joint between the frame it stands on (its base)
and its platform frame. :func:`~vgtarm.model.symbolic.solve_module`, the one closed-form module
solution of the project, gives the platform centre ``(h, z)`` and angle ``theta`` in the module's
plane; the plane is turned by the angle ``phi`` about the base's axis (its ``h`` axis runs along
``Rz(phi) u2``), exactly as :func:`~vgtarm.model.stack.symbolic.stack_kinematics` places it.

Everything a recursive algorithm needs of the joint is derived here by automatic differentiation:

- ``pose``: the platform's rotation ``E`` (row-major, platform axes in base components) and its
  centre ``r`` in the base frame;
- ``S`` ``(6, 3)``: the motion subspace in platform coordinates, ``v_J = S qd`` with ``v_J`` the
  platform's velocity relative to the base as a spatial vector ``(omega, v)`` (angular velocity
  ``vee(E^T Edot)``, velocity of the platform centre ``E^T rdot``), stored row-major;
- ``c`` ``(6,)``: the bias ``Sdot qd`` (componentwise time derivative of ``S(q)`` in platform
  coordinates, Featherstone's apparent derivative ``c_J``);
- the passive angles ``alpha, beta, gamma, theta``;
- ``taylor``: the pose ``(E, r)`` (12 values as in ``pose``) and its first, second and third
  partial derivatives in the three legs (``3 x 12``, ``9 x 12``, ``27 x 12``: derivative index
  ``k`` slowest, then ``l``, ``m``), for the exact second- and third-order terms of the inverse
  kinematics (:mod:`.second_order`).

The geometry ``g = (b, d, cos phi, sin phi)`` is an input, not a constant, so one generated
function serves every module of every arm: the module type's recipe is this file alone.
"""

from __future__ import annotations

import casadi as ca

from ..symbolic import SX, solve_module, time_derivative, vee

#: Names of the module function's geometry input, in order.
GEOMETRY = ("b", "d", "cos_phi", "sin_phi")


def _plane_rotation(c: SX, s: SX, theta: SX) -> SX:
    """``Rz(phi) Rx(theta) Rz(-phi)`` with ``cos phi = c``, ``sin phi = s`` symbolic."""
    rz = ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
    ct, st = ca.cos(theta), ca.sin(theta)
    rx = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, ct, -st), ca.horzcat(0, st, ct))
    return rz @ rx @ rz.T


def module_expressions(q: SX, qd: SX, g: SX) -> dict[str, SX]:
    """The joint quantities (see the module docstring) as expressions of ``q``, ``qd`` (3 each)
    and the geometry ``g`` (4)."""
    b, d, c, s = g[0], g[1], g[2], g[3]
    plane = solve_module(q[0], q[1], q[2], b, d)
    r = ca.vertcat(-s * plane.centre_h, c * plane.centre_h, plane.centre_z)
    E = _plane_rotation(c, s, plane.theta)
    omega = vee(E.T @ time_derivative(E, q, qd))
    velocity = E.T @ ca.jtimes(r, q, qd)
    twist = ca.vertcat(omega, velocity)
    S = ca.jacobian(twist, qd)
    bias = ca.jtimes(S @ qd, q, qd)
    return {
        "pose": ca.vertcat(ca.vec(E.T), r),
        "S": ca.vec(S.T),
        "c": bias,
        "passive": ca.vertcat(plane.alpha, plane.beta, plane.gamma, plane.theta),
    }


def module_taylor(q: SX, g: SX) -> list[SX]:
    """The pose (12) and its partial derivatives of orders 1, 2, 3 in ``q`` (``3**k x 12`` each, flat)."""
    pose = module_expressions(q, SX.sym("qd", 3), g)["pose"]  # the pose does not depend on qd
    out = [pose]
    current = pose
    for _ in range(3):
        current = ca.vec(ca.jacobian(current, q))  # derivative index slowest in the next order's layout
        out.append(current)
    return out


def module_functions() -> list[ca.Function]:
    """The generated functions: ``vgt_rec_module_kin(q, g) -> (pose, S, passive)``,
    ``vgt_rec_module(q, qd, g) -> (pose, S, c)``, ``vgt_rec_module_taylor(q, g) -> (d0, d1, d2, d3)``
    and ``vgt_rec_module_pose(q, g) -> pose`` (the tip alone: the same expressions)."""
    q, qd, g = SX.sym("q", 3), SX.sym("qd", 3), SX.sym("g", len(GEOMETRY))
    e = module_expressions(q, qd, g)
    opts = {"cse": True}
    kin = ca.Function(
        "vgt_rec_module_kin", [q, g], [e["pose"], e["S"], e["passive"]], ["q", "g"], ["pose", "S", "passive"], opts
    )
    full = ca.Function(
        "vgt_rec_module", [q, qd, g], [e["pose"], e["S"], e["c"]], ["q", "qd", "g"], ["pose", "S", "c"], opts
    )
    taylor = ca.Function(
        "vgt_rec_module_taylor", [q, g], module_taylor(q, g), ["q", "g"], ["d0", "d1", "d2", "d3"], opts
    )
    pose = ca.Function("vgt_rec_module_pose", [q, g], [e["pose"]], ["q", "g"], ["pose"], opts)
    return [kin, full, taylor, pose]
