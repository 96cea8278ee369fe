"""MuJoCo as the plant of the closed loop: the exported model stepped by MuJoCo, our controller.

:class:`MujocoLoop` is the NumPy loop (:class:`vgtarm.simulation.python_loop.PythonLoop`: the
same controller, observer, sensing, tool force and divergence checks, with the controller's own
model) whose plant is MuJoCo: the tip and its velocity are read from the site ``tip``, the joint
values from the tree's joints and the closed legs' tendons, and each control period is
integrated by MuJoCo with the efforts held and the tool force applied at the tip (the cutting
force follows the tip velocity at every MuJoCo step), in ``max(substeps, MIN_STEPS[...])``
MuJoCo steps. ``rk4`` uses MuJoCo's RK4; ``euler`` and ``semi_implicit_euler`` use MuJoCo's
``Euler`` with its implicit damping switched off, which is then exactly our semi-implicit Euler
(MuJoCo has no explicit Euler).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..model.closedloop import LoopArrays, LoopSettings
from ..model.robot import Robot
from ..simulation.python_loop import PythonLoop
from .model import MujocoRobot

Array = NDArray[np.float64]

#: MuJoCo steps per control period at least, by MuJoCo integrator: every count is stable, but
#: (semi-implicit) Euler needs 10 to bring case 1 within 2 % of the converged plant (1 step:
#: -20 %, 5: -4 %); RK4 is converged at one step (docs/mujoco.md).
MIN_STEPS = {"Euler": 10, "RK4": 1}


class MujocoLoop(PythonLoop):
    """The closed loop on the MuJoCo plant (see the module's docstring)."""

    def __init__(self, plant: Robot, model: Robot) -> None:
        super().__init__(plant, model)
        self.bridge = MujocoRobot(plant)
        self._started = False

    def simulate(
        self, settings: LoopSettings, arrays: LoopArrays, Kp: Array, Kv: Array, k0: int, k1: int
    ) -> tuple[int, int]:
        if k0 == 0 or not self._started:  # MuJoCo's state is the loop's at sample k0 afterwards
            self.bridge.set_state(arrays.q[k0], arrays.qd[k0])
            self._started = True
        return super().simulate(settings, arrays, Kp, Kv, k0, k1)

    def _tip_state(self, q: Array, qd: Array) -> tuple[Array, Array]:
        mujoco, b = self.bridge.mujoco, self.bridge
        velocity = np.zeros(6)
        mujoco.mj_objectVelocity(b.model, b.data, mujoco.mjtObj.mjOBJ_SITE, b.tip_site, velocity, 0)
        return b.tip(), velocity[3:]

    def _integrate(self, s: LoopSettings, q: Array, qd: Array, F: Array, dist: Array) -> tuple[Array, Array]:
        mujoco, b = self.bridge.mujoco, self.bridge
        integrator = "RK4" if s.integrator == "rk4" else "Euler"
        steps = max(s.substeps, MIN_STEPS[integrator])
        b.model.opt.timestep = s.dt / steps
        b.model.eq_solref[:, 0] = 2.0 * b.model.opt.timestep  # as stiff as MuJoCo's refsafe allows
        b.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP  # Euler: semi-implicit, as ours
        b.model.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{integrator.upper()}")
        for _ in range(steps):
            mujoco.mj_forward(b.model, b.data)
            _, velocity = self._tip_state(q, qd)
            b.apply(F, self._tool_force(s, velocity, dist))
            mujoco.mj_step(b.model, b.data)
        mujoco.mj_forward(b.model, b.data)
        return b.joint_positions(), b.joint_velocities()
