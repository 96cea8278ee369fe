"""The closed loop in NumPy: the interpreter fallback and the tests' second implementation.

:class:`PythonLoop` has the interface of :class:`~vgtarm.model.closedloop.ClosedLoopDriver` and does
the same computation sample by sample through the :class:`~vgtarm.model.robot.Robot` methods.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ..control.law import computed_force
from ..control.scm import predict_tip_error
from ..errors import AssemblyError, InputError
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

    def _tip_state(self, q: Array, qd: Array) -> tuple[Array, Array]:
        """The plant's tip point and tip velocity at ``(q, qd)``."""
        velocity, _ = self.plant.tip_velocity(q, qd)
        return self.plant.tip_position(q), velocity

    def _tool_force(self, s: LoopSettings, velocity: Array, dist: Array) -> Array:
        speed = float(np.linalg.norm(velocity))
        f = dist.copy()
        if s.cutting and speed > s.cutting_speed:
            f -= s.cutting_force * velocity / speed
        return f

    def _acceleration(self, s: LoopSettings, q: Array, qd: Array, F: Array, dist: Array) -> Array:
        velocity, _ = self.plant.tip_velocity(q, qd)
        return self.plant.forward_dynamics(q, qd, self.delivered(s, qd, F), self._tool_force(s, velocity, dist))

    def delivered(self, s: LoopSettings, qd: Array, F: Array) -> Array:
        """The effort the plant's actuators deliver for ``F`` at the joint velocities ``qd`` (their
        force-speed lines, at every stage: ``acceleration`` in ``closed_loop.c``); ``F`` without them."""
        actuators = self.plant.actuators
        return F if not s.saturation or actuators is None else actuators.saturate(F, qd)

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
        lower, upper = inputs["q_min"], inputs["q_max"]  # the joint limits, by vgt_run's names
        if (q < lower - s.limit_tolerance).any() or (q > upper + s.limit_tolerance).any():
            return OUTSIDE_LIMITS
        return DONE

    def _measure(self, s: LoopSettings, arrays: LoopArrays, k: int) -> None:
        """What the controller sees at sample ``k`` (as ``measure`` in ``closed_loop.c``)."""
        q, qd = arrays.q[k], arrays.qd[k]
        if not s.sensing:
            arrays.q_meas[k], arrays.qd_meas[k] = q, qd
            return
        step = arrays.inputs["resolution"]
        safe = np.where(step > 0, step, 1.0)
        arrays.q_meas[k] = np.where(step > 0, step * np.floor(q / safe + 0.5), q)
        if k == 0:
            arrays.qd_meas[k] = qd
            return
        if s.estimator == "kalman":  # the velocity is the estimator's (_estimate)
            return
        raw = (arrays.q_meas[k] - arrays.q_meas[k - 1]) / s.dt + arrays.inputs["velocity_noise"][k]
        arrays.qd_meas[k] = s.velocity_filter * arrays.qd_meas[k - 1] + (1.0 - s.velocity_filter) * raw

    def _estimate(self, s: LoopSettings, arrays: LoopArrays, k: int) -> None:
        """The Kalman estimator at sample ``k`` (as ``estimate`` in ``closed_loop.c``)."""
        x, z = arrays.x_hat[k], arrays.q_meas[k]
        if k == 0:
            x[0], x[1], x[2], x[3] = z, arrays.qd[0], 0.0, 0.0
        else:
            q0, v0, d0 = arrays.x_hat[k - 1, 0], arrays.x_hat[k - 1, 1], arrays.x_hat[k - 1, 2]
            a = self.model.forward_dynamics(q0, v0, arrays.F[k - 1], self._expected(s, arrays, k - 1))
            acc = a + d0
            qp = q0 + s.dt * v0 + 0.5 * s.dt * s.dt * acc
            vp = v0 + s.dt * acc
            innovation = z - qp
            L = s.kalman_gain
            x[0], x[1], x[2], x[3] = qp + L[0] * innovation, vp + L[1] * innovation, d0 + L[2] * innovation, a
        arrays.qd_meas[k] = x[1]

    @staticmethod
    def _expected(s: LoopSettings, arrays: LoopArrays, j: int) -> Array:
        """The expected tool force of sample ``j`` the controller takes as known (zero without the feedforward)."""
        if not s.tool_feedforward:
            return np.zeros(3)
        return np.asarray(arrays.inputs["tool_force_expected"][j])

    def _differenced(self, s: LoopSettings, arrays: LoopArrays, j: int) -> Array:
        """Velocity of sample ``j`` differenced from the encoders, unfiltered (as ``differenced``)."""
        if j == 0:
            return arrays.qd[0]
        return (arrays.q_meas[j] - arrays.q_meas[j - 1]) / s.dt + arrays.inputs["velocity_noise"][j]

    def _observe(self, s: LoopSettings, arrays: LoopArrays, k: int) -> None:
        """Estimated external joint efforts at sample ``k`` (as ``observe`` in ``closed_loop.c``); with
        the tool-force feedforward, the rest beyond the expected tool force."""
        if s.observer == "none" or k == 0 or (s.observer == "momentum" and s.sensing and k < 2):
            arrays.tau_hat[k] = 0.0
            return
        if s.observer == "force":
            J = self.model.tip_jacobian(arrays.q_meas[k])
            arrays.tau_hat[k] = J.T @ arrays.f_ext[k - 1]
            return
        if s.sensing and s.estimator == "kalman":  # the model's acceleration plus the disturbance
            x0, x = arrays.x_hat[k - 1], arrays.x_hat[k]
            f1 = self._expected(s, arrays, k - 1)
            raw = self.model.inverse_dynamics(x0[0], x0[1], x[3] + x[2], f1) - arrays.F[k - 1]
            keep = math.exp(-s.observer_gain * s.dt)
            arrays.tau_hat[k] = keep * arrays.tau_hat[k - 1] + (1.0 - keep) * raw
            return
        if s.sensing:  # differenced velocities: the change spans the two last periods
            va, vb = self._differenced(s, arrays, k - 1), self._differenced(s, arrays, k)
            qa, applied = arrays.q_meas[k - 2], 0.5 * (arrays.F[k - 2] + arrays.F[k - 1])
            f = 0.5 * (self._expected(s, arrays, k - 2) + self._expected(s, arrays, k - 1))
        else:
            va, vb = arrays.qd_meas[k - 1], arrays.qd_meas[k]
            qa, applied = arrays.q_meas[k - 1], arrays.F[k - 1]
            f = self._expected(s, arrays, k - 1)
        raw = self.model.inverse_dynamics(qa, va, (vb - va) / s.dt, f) - applied
        keep = math.exp(-s.observer_gain * s.dt)
        arrays.tau_hat[k] = keep * arrays.tau_hat[k - 1] + (1.0 - keep) * raw

    def simulate(
        self, settings: LoopSettings, arrays: LoopArrays, Kp: Array, Kv: Array, k0: int, k1: int
    ) -> tuple[int, int]:
        """Run samples ``k0 .. k1-1``; returns (status, stop sample) like the compiled driver."""
        inp = arrays.inputs
        for k in range(k0, k1):
            q, qd = arrays.q[k], arrays.qd[k]
            try:
                arrays.tip[k], velocity = self._tip_state(q, qd)
            except InputError:  # a diverging run's state beyond any the model accepts
                return NOT_FINITE, k
            arrays.error[k] = np.linalg.norm(inp["tip_d"][k] - arrays.tip[k])
            self._measure(settings, arrays, k)
            if settings.sensing and settings.estimator == "kalman":
                try:
                    self._estimate(settings, arrays, k)
                except (AssemblyError, InputError):  # a diverging run's estimate beyond the model
                    return NOT_FINITE, k
            if settings.threshold > 0:
                seen = arrays.error[k]
                if settings.threshold_measured:  # what the controller sees: its model's tip at q_meas
                    try:
                        seen = np.linalg.norm(inp["tip_d"][k] - self.model.tip_position(arrays.q_meas[k]))
                    except (AssemblyError, InputError):
                        return NOT_FINITE, k
                arrays.seen[k] = seen
                if seen > settings.threshold:
                    return ABOVE_THRESHOLD, k
            try:
                self._observe(settings, arrays, k)
                qm, vm = arrays.q_meas[k], arrays.qd_meas[k]
                e, e_dot = inp["q_d"][k] - qm, inp["qd_d"][k] - vm
                M, C = self.model.mass_matrix(qm), self.model.bias_forces(qm, vm)
            except AssemblyError:  # the measured legs cannot be assembled
                return NOT_ASSEMBLABLE, k
            except InputError:  # a diverging run's measured state beyond any the model accepts
                return NOT_FINITE, k
            arrays.F[k] = computed_force(M, C, inp["qdd_d"][k], e, e_dot, Kp, Kv, arrays.tau_hat[k])
            if settings.tool_feedforward:  # the expected tool force through J_P^T at what the controller sees
                try:
                    J = self.model.tip_jacobian(qm)
                except (AssemblyError, InputError):
                    return NOT_FINITE, k
                arrays.F[k] = arrays.F[k] - J.T @ inp["tool_force_expected"][k]
            if settings.saturation:  # the controller's clip to its actuators' peak forces (vgt_clip)
                peak = inp["force_limit"]
                arrays.F[k] = np.minimum(np.maximum(arrays.F[k], -peak), peak)
            dist = inp["disturbance"][k]
            arrays.f_ext[k] = self._tool_force(settings, velocity, dist)
            if k + 1 >= arrays.n:
                continue
            try:
                q1, qd1 = self._integrate(settings, q, qd, arrays.F[k], dist)
            except AssemblyError:  # an RK4 stage left the assemblable set
                return NOT_ASSEMBLABLE, k + 1
            except InputError:  # a stage's state or efforts beyond any the model accepts: diverging
                return NOT_FINITE, k + 1
            arrays.q[k + 1], arrays.qd[k + 1] = q1, qd1
            status = self._check(settings, arrays, q1, qd1)
            if status != DONE:
                return status, k + 1
        return DONE, k1

    def ga_predictor(
        self,
        p_ctrl: Array,
        dt: float,
        q0: Array,
        qd0: Array,
        q_d: Array,
        qd_d: Array,
        qdd_d: Array,
        tip_d: Array,
        actuators: tuple[Array, Array, Array] | None = None,
    ) -> Callable[[Array, Array], Array]:
        """The GA's fitness for one state and window, as :func:`vgtarm.control.scm.predict_tip_error`;
        with ``actuators`` (the run's limits, which are the plant's) its effort clipped to them."""
        limits = None if actuators is None else self.plant.actuators

        def predict(Kp: Array, Kv: Array) -> Array:
            return predict_tip_error(self.model, dt, q0, qd0, q_d, qd_d, qdd_d, tip_d, Kp, Kv, limits)

        return predict
