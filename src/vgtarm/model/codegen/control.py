"""Compiled functions of the closed loop (model layer; see core.py for conventions).

The closed-loop driver (``csrc/closed_loop.c``) calls these together with ``vgt_fd`` (plant
forward dynamics) and ``vgt_tip``.
"""

from __future__ import annotations

import casadi as ca

from ..definition import PAPER, Definition
from ..symbolic import SX, body_motion
from .core import Builder, function, row_major, symbols


def computed_force(d: Definition = PAPER) -> ca.Function:
    """Computed force control, paper eq. 20: ``F = M^ (qdd_d + Kp e + Kv e_dot) + C^``.

    ``e = q_d - q``; ``Kp``, ``Kv`` are full n x n matrices given row by row (n^2 values each);
    ``M^``, ``C^`` are evaluated with the parameter vector given (the controller's model).
    """
    q, qd, p = symbols(d)
    n = d.n_joints
    q_d, qd_d, qdd_d = SX.sym("q_d", n), SX.sym("qd_d", n), SX.sym("qdd_d", n)
    kp, kv = SX.sym("Kp", n * n), SX.sym("Kv", n * n)
    Kp = ca.reshape(kp, n, n).T
    Kv = ca.reshape(kv, n, n).T
    dyn = d.dynamics(q, qd, p)
    F = dyn.M @ (qdd_d + Kp @ (q_d - q) + Kv @ (qd_d - qd)) + dyn.C
    return function(
        "vgt_cfc",
        [q, qd, q_d, qd_d, qdd_d, kp, kv, p],
        [F],
        ["q", "qd", "q_d", "qd_d", "qdd_d", "Kp", "Kv", "p"],
        ["F"],
    )


def tip_state(d: Definition = PAPER) -> ca.Function:
    """Tip point and tip velocity ``J_P qd`` (for the error and the cutting force)."""
    q, qd, p = symbols(d)
    k = d.kinematics(q, p)
    motion = body_motion(k.tip, k.C03, q, qd)
    return function("vgt_tip_state", [q, qd, p], [k.tip, motion.velocity], ["q", "qd", "p"], ["tip", "velocity"])


def tip_hessian(d: Definition = PAPER) -> ca.Function:
    """Second derivatives of the tip point, ``H[k, l, m] = d^2 P_k / dq_l dq_m`` (3 x n x n, row-major).

    The switching method's GA maps predicted joint errors to the tip through the first and second
    derivatives of the forward kinematics at the reference (``csrc/ga.c``).
    """
    q, _, p = symbols(d)
    tip = d.kinematics(q, p).tip
    rows = [ca.hessian(tip[k], q)[0] for k in range(3)]
    return function("vgt_tip_hessian", [q, p], [ca.vertcat(*[row_major(h) for h in rows])], ["q", "p"], ["H"])


#: Functions of this family, by name.
BUILDERS: dict[str, Builder] = {
    "cfc": computed_force,
    "tip_state": tip_state,
    "tip_hessian": tip_hessian,
}
