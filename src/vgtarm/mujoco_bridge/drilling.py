"""MuJoCo as the plant of force-controlled drilling (issue 38, the cross-check of
``docs/drilling_control.md``; ``docs/drilling_mujoco.md``).

:class:`MujocoDrillingPlant` is a drop-in for :class:`~vgtarm.drilling.control.DrillingPlant`
whose dynamics are MuJoCo's, on the exported model of :class:`~.model.MujocoRobot`: the efforts
``F`` are the motors' controls (the closed legs' motors drive their tendons, as in
:class:`~.plant.MujocoLoop`), the bone pushes the site ``tip`` with ``-thrust * axis`` and turns
the body ``end_effector`` with ``-torque * axis`` (``xfrc_applied``), the depth and feed are read
from the site ``tip``, and the joint values it returns are ours read from MuJoCo (the tree's
slides and twists, the closed legs' tendons), so the NumPy controller, sensing and detector run
unchanged. :func:`mujoco_drilling_run` is :func:`~vgtarm.drilling.loop.drilling_run` on it.

**The cut's damping.** ``b = d thrust / d feed`` reaches 9.3e4 N s/m near zero feed; on the
tool's axial effective mass (3.5 kg at home) explicit treatment at ``h = dt / substeps`` = 0.25 ms
has ``h b / m`` up to 6.6, past explicit Euler's bound of 2 (measured, MuJoCo with the thrust
explicit, a constant 5 N push in cortex: at 4 substeps the feed ends in a limit cycle, -0.107 mm/s
after 20 ms where the converged answer is +0.0805 mm/s). Each step is therefore the same linearly
implicit (semi-implicit Euler) step as :meth:`DrillingPlant.acceleration`, taken in MuJoCo's own
coordinates with MuJoCo's own mass matrix, bias forces, constraint solver and site Jacobian:

- MuJoCo's accelerations ``a_e`` (``qacc``, the loop closures solved) under the efforts and the
  thrust and torque at the step's start, and its response ``u`` to a unit force along the axis at
  the tip (one more acceleration stage: with only equality constraints MuJoCo's Newton solver
  solves a quadratic exactly, so ``qacc`` is affine in the applied forces and ``u = G j``, the
  closed chain's inverse inertia on ``j = J_tip^T axis``);
- the thrust taken at the feed of the step's end, ``thrust + h b (j . a)``, gives
  ``a = a_e - u h b (j . a)``, solved in closed form: ``j . a = j . a_e / (1 + h b j . u)``,
  stable for any ``b`` (``j . u`` > 0 is the tip's axial inverse mass);
- then ``qvel += h a`` and ``qpos`` integrated with the new ``qvel`` (``mj_integratePos``).

This is the Sherman-Morrison form of ``(M + h b j j^T) qdd = ...`` of the NumPy plant with the
closures MuJoCo imposes in place of our closed-form elimination, so the two plants differ only
by the models' agreement (1e-12, ``docs/mujoco.md``) and by each integrator's own error in its
own coordinates, which also enters the implicit term's ``j . qdd`` (the velocity products of
the two sets of coordinates differ: 5e-9 of the step's accelerations, measured). On the 5 N test
above, 4 substeps give the converged feed (256 explicit substeps) to 2e-9 m/s. The
alternatives were weighed: MuJoCo's ``implicitfast`` with the damping as a tendon to a far site on
the axis would compute the closures' forces from the explicit accelerations (the damping being
implicit only in the velocity update that follows) and would make the robot's own friction
implicit too, unlike ours; more substeps need ``h < 2 m / b`` = 75 us at home (16 substeps, at the
edge, four times the work, and less at a lighter axial mass).
The depth stiffness (at most 1.9e4 N/m) and the cutting torque stay explicit, as in ours.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..drilling.bone import Bone, drilling_forces_at
from ..drilling.control import (
    DrillingPlant,
    DrillingSettings,
)
from ..drilling.loop import DrillingResult, drilling_run
from ..model.robot import Robot
from .model import MujocoRobot

Array = NDArray[np.float64]


@dataclass(frozen=True)
class MujocoDrillingPlant(DrillingPlant):
    """:class:`~vgtarm.drilling.control.DrillingPlant` stepped by MuJoCo (see the module's
    docstring): the same fields, ``robot`` exported and loaded in MuJoCo (:attr:`bridge`).

    MuJoCo keeps its own full state between calls (the passive hinges, the followers' slides and
    the soft closures' small gap); a ``(q, qd)`` other than the one :meth:`step` last returned
    puts MuJoCo at that joint state first (:meth:`MujocoRobot.set_state`)."""

    bridge: MujocoRobot = field(init=False, repr=False, compare=False)
    _last: list[Array] = field(init=False, repr=False, compare=False, default_factory=list)

    def __post_init__(self) -> None:
        object.__setattr__(self, "bridge", MujocoRobot(self.robot))

    def _at(self, q: Array, qd: Array) -> None:
        """MuJoCo at our joint state ``(q, qd)``: kept if it is the state last returned."""
        last = self._last
        if last and np.array_equal(last[0], q) and np.array_equal(last[1], qd):
            return
        self.bridge.set_state(q, qd)
        self._last[:] = [np.array(q, dtype=np.float64), np.array(qd, dtype=np.float64)]

    def _axial_jacobian(self) -> Array:
        """``j = J_tip^T axis`` (nv,) of MuJoCo's current state (positions computed)."""
        b = self.bridge
        jac = np.zeros((3, b.model.nv))
        b.mujoco.mj_jacSite(b.model, b.data, jac, None, b.tip_site)
        return np.asarray(self.axis @ jac, dtype=np.float64)

    def _tip_depth_feed(self, j: Array) -> tuple[float, float]:
        """Depth (m) and feed (m/s) of MuJoCo's site ``tip`` (positions and velocities computed)."""
        tip = self.bridge.data.site_xpos[self.bridge.tip_site]
        return float(self.axis @ (tip - self.entry)), float(j @ self.bridge.data.qvel)

    def depth_feed(self, q: Array, qd: Array) -> tuple[float, float]:
        """Tip depth past the entry surface along the axis (m) and the feed (m/s), from MuJoCo's
        site ``tip`` at the joint state ``(q, qd)``."""
        self._at(q, qd)
        return self._tip_depth_feed(self._axial_jacobian())

    def forces(self, q: Array, qd: Array) -> tuple[float, float, float, float]:
        """The drill's ``(thrust, torque, d thrust / d depth, d thrust / d feed)`` at MuJoCo's tip."""
        depth, feed = self.depth_feed(q, qd)
        return drilling_forces_at(self.bone, depth, feed, self.spindle_speed)

    def _push(self, force: float, torque: float) -> None:
        """``xfrc_applied``: ``-force * axis`` at the tip and ``-torque * axis`` on the end-effector
        (the tip force moved to the body's centre of mass, where MuJoCo applies it)."""
        b = self.bridge
        d = b.data
        f = -force * self.axis
        lx, ly, lz = (d.site_xpos[b.tip_site] - d.xipos[b.effector]).tolist()
        fx, fy, fz = f.tolist()
        moment = np.array([ly * fz - lz * fy, lz * fx - lx * fz, lx * fy - ly * fx]) - torque * self.axis
        d.xfrc_applied[:] = 0.0
        d.xfrc_applied[b.effector, :3] = f
        d.xfrc_applied[b.effector, 3:] = moment

    def _implicit_acceleration(self, F: Array, h: float) -> tuple[Array, float]:
        """MuJoCo's accelerations ``qacc`` (nv,) of the linearly implicit step ``h`` (s) under the
        efforts ``F`` (see the module's docstring) at MuJoCo's current state, and the thrust at its
        start (N); leaves ``qacc`` set to them."""
        b = self.bridge
        mujoco, m, d = b.mujoco, b.model, b.data
        mujoco.mj_fwdPosition(m, d)
        mujoco.mj_fwdVelocity(m, d)
        j = self._axial_jacobian()
        depth, feed = self._tip_depth_feed(j)
        thrust, torque, _, damping = drilling_forces_at(self.bone, depth, feed, self.spindle_speed)
        d.ctrl[:] = F
        self._push(thrust, torque if self.tool_torque else 0.0)
        mujoco.mj_forwardSkip(m, d, mujoco.mjtStage.mjSTAGE_VEL, 1)
        a = np.array(d.qacc)
        if damping * h > 0.0:
            self._push(thrust - 1.0, torque if self.tool_torque else 0.0)  # one newton more along +axis
            mujoco.mj_forwardSkip(m, d, mujoco.mjtStage.mjSTAGE_VEL, 1)
            u = np.array(d.qacc) - a
            axial = float(j @ a) / (1.0 + h * damping * float(j @ u))
            a = a - u * (h * damping * axial)
            d.qacc[:] = a
        return a, thrust

    def acceleration(self, q: Array, qd: Array, F: Array, h: float) -> tuple[Array, float]:
        """Our joint accelerations (n,) of MuJoCo's linearly implicit step ``h`` (s) at ``(q, qd)``
        under ``F`` (:meth:`MujocoRobot.joint_accelerations` of its ``qacc``), and the thrust (N);
        ``h = 0`` is MuJoCo's forward dynamics with the thrust explicit."""
        self._at(q, qd)
        _, thrust = self._implicit_acceleration(np.asarray(F, dtype=np.float64), h)
        return self.bridge.joint_accelerations(), thrust

    def step(self, q: Array, qd: Array, F: Array, dt: float, substeps: int) -> tuple[Array, Array]:
        """Our joint state after ``dt`` (s) under the constant efforts ``F``: ``substeps`` linearly
        implicit semi-implicit Euler steps in MuJoCo's coordinates, read back as our joints."""
        b = self.bridge
        mujoco, m, d = b.mujoco, b.model, b.data
        h = dt / substeps
        m.opt.timestep = h
        m.eq_solref[:, 0] = 2.0 * h  # the closures as stiff as MuJoCo's floor allows (as MujocoLoop)
        self._at(q, qd)
        F = np.asarray(F, dtype=np.float64)
        for _ in range(substeps):
            a, _ = self._implicit_acceleration(F, h)
            d.qvel += h * a
            mujoco.mj_integratePos(m, d.qpos, d.qvel, h)
            d.time += h
        mujoco.mj_forward(m, d)
        q_new, qd_new = b.joint_positions(), b.joint_velocities()
        self._last[:] = [q_new.copy(), qd_new.copy()]
        return q_new, qd_new


def mujoco_drilling_run(
    robot: Robot,
    bone: Bone,
    settings: DrillingSettings | None = None,
    *,
    q0: Array | None = None,
    nominal: Bone | None = None,
) -> DrillingResult:
    """:func:`~vgtarm.drilling.loop.drilling_run` with :class:`MujocoDrillingPlant` as the plant:
    the same start, controller (its model: ``robot``'s masses times ``settings.model_mass``),
    sensing, detector, phases and result, sample for sample; only the plant's dynamics are
    MuJoCo's."""
    return drilling_run(robot, bone, settings, q0=q0, nominal=nominal, engine="numpy", plant=MujocoDrillingPlant)


__all__ = ["MujocoDrillingPlant", "mujoco_drilling_run"]
