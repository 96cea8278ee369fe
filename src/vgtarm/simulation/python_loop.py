"""The closed loop in NumPy: the interpreter fallback and the tests' second implementation.

:class:`PythonLoop` has the interface of :class:`vgtarm.closedloop.ClosedLoopDriver` and does
the same computation sample by sample through the :class:`~vgtarm.robot.Robot` methods.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ..control.law import computed_force
from ..control.scm import predict_tip_error
from ..model.closedloop import (
    ABOVE_THRESHOLD,
    DONE,
    NOT_ASSEMBLABLE,
    NOT_FINITE,
    OUTSIDE_LIMITS,
    LoopArrays,
    LoopSettings,
)
from ..model.robot import Robot

Array = NDArray[np.float64]


class PythonLoop:
    """Closed loop of computed force control on ``plant`` with the controller's model ``model``."""

    def __init__(self, plant: Robot, model: Robot) -> None:
        self.plant = plant
        self.model = model

    def _tool_force(self, s: LoopSettings, velocity: Array, dist: Array) -> Array:
        speed = float(np.linalg.norm(velocity))
        f = dist.copy()
        if s.cutting and speed > s.cutting_speed:
            f -= s.cutting_force * velocity / speed
        return f

    def _acceleration(self, s: LoopSettings, q: Array, qd: Array, F: Array, dist: Array) -> Array:
        velocity, _ = self.plant.tip_velocity(q, qd)
        return self.plant.forward_dynamics(q, qd, F, self._tool_force(s, velocity, dist))

    def _integrate(self, s: LoopSettings, q: Array, qd: Array, F: Array, dist: Array) -> tuple[Array, Array]:
        h = s.dt / max(s.substeps, 1)
        for _ in range(max(s.substeps, 1)):
            if s.integrator == "rk4":
                k1v = self._acceleration(s, q, qd, F, dist)
                k1q = qd
                k2v = self._acceleration(s, q + h / 2 * k1q, qd + h / 2 * k1v, F, dist)
                k2q = qd + h / 2 * k1v
                k3v = self._acceleration(s, q + h / 2 * k2q, qd + h / 2 * k2v, F, dist)
                k3q = qd + h / 2 * k2v
                k4v = self._acceleration(s, q + h * k3q, qd + h * k3v, F, dist)
                k4q = qd + h * k3v
                q = q + h / 6 * (k1q + 2 * k2q + 2 * k3q + k4q)
                qd = qd + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
            else:
                a = self._acceleration(s, q, qd, F, dist)
                if s.integrator == "semi_implicit_euler":
                    qd = qd + h * a
                    q = q + h * qd
                else:
                    q, qd = q + h * qd, qd + h * a
        return q, qd

    def _check(self, s: LoopSettings, arrays: LoopArrays, q: Array, qd: Array) -> int:
        if not (np.isfinite(q).all() and np.isfinite(qd).all()):
            return NOT_FINITE
        inputs = arrays.inputs
        if not (inputs["G"] @ q + inputs["h"] > 0).all():
            return NOT_ASSEMBLABLE
        if (q < inputs["q_min"] - s.limit_tolerance).any() or (q > inputs["q_max"] + s.limit_tolerance).any():
            return OUTSIDE_LIMITS
        return DONE

    def simulate(
        self, settings: LoopSettings, arrays: LoopArrays, Kp: Array, Kv: Array, k0: int, k1: int
    ) -> tuple[int, int]:
        """Run samples ``k0 .. k1-1``; returns (status, stop sample) like the compiled driver."""
        inp = arrays.inputs
        for k in range(k0, k1):
            q, qd = arrays.q[k], arrays.qd[k]
            velocity, _ = self.plant.tip_velocity(q, qd)
            arrays.tip[k] = self.plant.tip_position(q)
            arrays.error[k] = np.linalg.norm(inp["tip_d"][k] - arrays.tip[k])
            if settings.threshold > 0 and arrays.error[k] > settings.threshold:
                return ABOVE_THRESHOLD, k
            e, e_dot = inp["q_d"][k] - q, inp["qd_d"][k] - qd
            M, C = self.model.mass_matrix(q), self.model.bias_forces(q, qd)
            arrays.F[k] = computed_force(M, C, inp["qdd_d"][k], e, e_dot, Kp, Kv)
            dist = inp["disturbance"][k]
            arrays.f_ext[k] = self._tool_force(settings, velocity, dist)
            if k + 1 >= arrays.n:
                continue
            try:
                q1, qd1 = self._integrate(settings, q, qd, arrays.F[k], dist)
            except ValueError:  # an RK4 stage left the assemblable set
                return NOT_ASSEMBLABLE, k + 1
            arrays.q[k + 1], arrays.qd[k + 1] = q1, qd1
            status = self._check(settings, arrays, q1, qd1)
            if status != DONE:
                return status, k + 1
        return DONE, k1

    def ga_predictor(
        self, p_ctrl: Array, dt: float, q0: Array, qd0: Array, q_d: Array, qd_d: Array, qdd_d: Array, tip_d: Array
    ) -> Callable[[Array, Array], Array]:
        """The GA's fitness for one state and window, as :func:`vgtarm.control.scm.predict_tip_error`."""

        def predict(Kp: Array, Kv: Array) -> Array:
            return predict_tip_error(self.model, dt, q0, qd0, q_d, qd_d, qdd_d, tip_d, Kp, Kv)

        return predict
