"""Compiled functions of the closed loop (model layer; see functions.py for conventions).

The closed-loop driver (``csrc/closed_loop.c``) calls these together with ``vgt_fd`` (plant
forward dynamics) and ``vgt_tip``.
"""

from __future__ import annotations

import casadi as ca

from .functions import Builder, _function, _symbols
from .symbolic import SX, body_motion, dynamics, kinematics


def computed_force() -> ca.Function:
    """Computed force control, paper eq. 20: ``F = M^ (qdd_d + Kp e + Kv e_dot) + C^``.

    ``e = q_d - q``; ``Kp``, ``Kv`` are full 7x7 matrices given row by row (49 values each);
    ``M^``, ``C^`` are evaluated with the parameter vector given (the controller's model).
    """
    q, qd, p = _symbols()
    q_d, qd_d, qdd_d = SX.sym("q_d", 7), SX.sym("qd_d", 7), SX.sym("qdd_d", 7)
    kp, kv = SX.sym("Kp", 49), SX.sym("Kv", 49)
    Kp = ca.reshape(kp, 7, 7).T
    Kv = ca.reshape(kv, 7, 7).T
    dyn = dynamics(q, qd, p)
    F = dyn.M @ (qdd_d + Kp @ (q_d - q) + Kv @ (qd_d - qd)) + dyn.C
    return _function(
        "vgt_cfc",
        [q, qd, q_d, qd_d, qdd_d, kp, kv, p],
        [F],
        ["q", "qd", "q_d", "qd_d", "qdd_d", "Kp", "Kv", "p"],
        ["F"],
    )


def tip_state() -> ca.Function:
    """Tip point and tip velocity ``J_P qd`` (for the error and the cutting force)."""
    q, qd, p = _symbols()
    k = kinematics(q, p)
    motion = body_motion(k.tip, k.C03, q, qd)
    return _function("vgt_tip_state", [q, qd, p], [k.tip, motion.velocity], ["q", "qd", "p"], ["tip", "velocity"])


#: Functions of this family, by name.
BUILDERS: dict[str, Builder] = {
    "cfc": computed_force,
    "tip_state": tip_state,
}
