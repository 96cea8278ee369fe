"""MuJoCo as the plant of the closed loop: the exported model stepped by MuJoCo, our controller.

:class:`MujocoLoop` is the NumPy loop (:class:`vgtarm.simulation.python_loop.PythonLoop`: the
same controller, observer, sensing, tool force and divergence checks, with the controller's own
model) whose plant is MuJoCo: the tip and its velocity are read from the site ``tip``, the joint
values from the tree's joints and the closed legs' tendons, and each control period is
integrated in MuJoCo's own coordinates with the efforts held and the tool force applied at the
tip (the cutting force follows the tip velocity at every step), in ``substeps`` steps, by the
same kind of integrator as ours:

- ``euler`` (explicit, the paper's and our default): MuJoCo has none, so each step asks MuJoCo
  for the accelerations at the current state (``mj_forward``) and moves the state itself,
  ``qpos += h qvel`` (``mj_integratePos``, with the velocity at the start of the step), then
  ``qvel += h qacc``;
- ``semi_implicit_euler``: MuJoCo's ``Euler`` with its implicit damping switched off
  (``eulerdamp``), which is then exactly our semi-implicit Euler (velocity first);
- ``rk4``: MuJoCo's ``RK4``.

MuJoCo steps its tree coordinates where we step our joints, so at the same integration the runs
differ by the integrators' own error, ``O(h^2)`` per step (docs/mujoco.md).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, shown
from ..model.closedloop import LoopArrays, LoopSettings
from ..model.robot import Robot
from ..simulation.python_loop import PythonLoop
from .model import MujocoRobot

Array = NDArray[np.float64]

#: Our integrators and MuJoCo's that step them: ``None`` is explicit Euler, done here.
MUJOCO_INTEGRATOR = {"euler": None, "semi_implicit_euler": "mjINT_EULER", "rk4": "mjINT_RK4"}


class MujocoLoop(PythonLoop):
    """The closed loop on the MuJoCo plant (see the module's docstring)."""

    def __init__(self, plant: Robot, model: Robot) -> None:
        super().__init__(plant, model)
        self.bridge = MujocoRobot(plant)
        self._started = False

    def simulate(
        self, settings: LoopSettings, arrays: LoopArrays, Kp: Array, Kv: Array, k0: int, k1: int
    ) -> tuple[int, int]:
        if settings.integrator not in MUJOCO_INTEGRATOR:  # here: the loop reads a ValueError as a wreck
            raise InputError(
                f"integrator = {shown(settings.integrator)}: the MuJoCo plant runs {sorted(MUJOCO_INTEGRATOR)}"
            )
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
        m, d = b.model, b.data
        steps = max(s.substeps, 1)
        h = s.dt / steps
        m.opt.timestep = h
        m.eq_solref[:, 0] = 2.0 * h  # as stiff as MuJoCo's refsafe allows
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP  # Euler: semi-implicit, as ours
        theirs = MUJOCO_INTEGRATOR[s.integrator]
        explicit = theirs is None
        if theirs is not None:
            m.opt.integrator = getattr(mujoco.mjtIntegrator, theirs)
        for _ in range(steps):
            mujoco.mj_forward(m, d)
            _, velocity = self._tip_state(q, qd)
            # the actuators' force-speed lines at each step's velocity (held over the step: MuJoCo
            # has no velocity-dependent force range)
            b.apply(self.delivered(s, b.joint_velocities(), F), self._tool_force(s, velocity, dist))
            if explicit:
                # the efforts and the tool force enter at the acceleration stage only
                mujoco.mj_forwardSkip(m, d, mujoco.mjtStage.mjSTAGE_VEL, 1)
                qvel = d.qvel.copy()
                d.qvel += h * d.qacc
                mujoco.mj_integratePos(m, d.qpos, qvel, h)
                d.time += h
            else:
                mujoco.mj_step(m, d)
        mujoco.mj_forward(m, d)
        return b.joint_positions(), b.joint_velocities()
