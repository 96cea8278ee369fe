"""The exported robot loaded in MuJoCo, and our joint states mapped onto it."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from ..model.parameters import JOINT_NAMES
from ..model.robot import Robot
from .export import home_geometry, to_mjcf

Array = NDArray[np.float64]


def require_mujoco() -> Any:
    """The ``mujoco`` module, or one line saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise InputError("MuJoCo is not installed: pip install 'vgtarm[mujoco]'") from None
    return mujoco


class MujocoRobot:
    """The robot exported to MJCF and loaded in MuJoCo, with our ``q, qd`` mapped onto MuJoCo's
    full state (passive hinges from our closed-form passive angles, their rates from the loop
    closures' constraint Jacobian)."""

    def __init__(self, robot: Robot, *, timestep: float = 1e-3) -> None:
        mujoco = require_mujoco()
        self.mujoco = mujoco
        self.robot = robot
        self.xml = to_mjcf(robot, timestep=timestep)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.model.opt.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
        self.data = mujoco.MjData(self.model)
        joint = self.model.joint
        self.qpos_of = {self.model.joint(i).name: int(joint(i).qposadr[0]) for i in range(self.model.njnt)}
        self.dof_of = {self.model.joint(i).name: int(joint(i).dofadr[0]) for i in range(self.model.njnt)}
        self.actuated_dofs = np.array([self.dof_of[n] for n in JOINT_NAMES])
        self.passive_dofs = np.array([d for d in range(self.model.nv) if d not in set(self.actuated_dofs)])
        self.home_passive = np.asarray(home_geometry(robot).passive)
        self.effector = self.model.body("end_effector").id
        self.tip_site = self.model.site("tip").id

    def set_state(self, q: ArrayLike, qd: ArrayLike) -> None:
        """Put MuJoCo at our joint state ``q``, ``qd`` (7,) with the loop closures satisfied."""
        mujoco, m, d = self.mujoco, self.model, self.data
        q, qd = np.asarray(q, dtype=float), np.asarray(qd, dtype=float)
        passive = self.robot.forward_kinematics(q).passive
        qpos = np.zeros(m.nq)
        for k in range(2):
            alpha, beta, gamma, theta = passive[k] - self.home_passive[k]
            qpos[self.qpos_of[f"s{k + 1}_base"]] = alpha
            qpos[self.qpos_of[f"v{k + 1}_base"]] = gamma
            qpos[self.qpos_of[f"p{k + 1}_base"]] = beta
            qpos[self.qpos_of[f"platform{k + 1}"]] = theta - alpha
        for i, name in enumerate(JOINT_NAMES):
            qpos[self.qpos_of[name]] = q[i]
        d.qpos[:] = qpos
        d.qvel[:] = 0.0
        d.qvel[self.actuated_dofs] = qd
        mujoco.mj_forward(m, d)
        J = self.constraint_jacobian()
        rhs = -J[:, self.actuated_dofs] @ qd
        d.qvel[self.passive_dofs] = np.linalg.lstsq(J[:, self.passive_dofs], rhs, rcond=None)[0]
        mujoco.mj_forward(m, d)

    def constraint_jacobian(self) -> Array:
        """Rows of the loop closures (equality constraints) of the current state, (rows, nv)."""
        d = self.data
        rows = d.efc_type[: d.nefc] == self.mujoco.mjtConstraint.mjCNSTR_EQUALITY
        return np.array(d.efc_J[: d.nefc * self.model.nv]).reshape(d.nefc, self.model.nv)[rows]

    def velocity_map(self) -> Array:
        """``T`` (nv, 7): MuJoCo's velocities on the constraint manifold from our ``qd``."""
        J = self.constraint_jacobian()
        T = np.zeros((self.model.nv, 7))
        T[self.actuated_dofs] = np.eye(7)
        T[self.passive_dofs] = -np.linalg.lstsq(J[:, self.passive_dofs], J[:, self.actuated_dofs], rcond=None)[0]
        return T

    def apply(self, F: ArrayLike, f_tip: ArrayLike | None = None) -> None:
        """Efforts ``F`` (7,) on the actuators and the force ``f_tip`` (3,) on the tool tip."""
        d = self.data
        d.ctrl[:] = np.asarray(F, dtype=float)
        d.xfrc_applied[:] = 0.0
        if f_tip is not None:
            f = np.asarray(f_tip, dtype=float)
            lever = d.site_xpos[self.tip_site] - d.xipos[self.effector]
            d.xfrc_applied[self.effector, :3] = f
            d.xfrc_applied[self.effector, 3:] = np.cross(lever, f)

    def forward_dynamics(self, q: ArrayLike, qd: ArrayLike, F: ArrayLike, f_tip: ArrayLike | None = None) -> Array:
        """Joint accelerations (7,) of the actuated joints, computed by MuJoCo."""
        self.set_state(q, qd)
        self.apply(F, f_tip)
        self.mujoco.mj_forward(self.model, self.data)
        return np.array(self.data.qacc[self.actuated_dofs])

    def mass_matrix(self, q: ArrayLike) -> Array:
        """MuJoCo's mass matrix reduced to our seven joints, ``T^T M T`` (7, 7)."""
        self.set_state(q, np.zeros(7))
        full = np.zeros((self.model.nv, self.model.nv))
        self.mujoco.mj_fullM(self.model, self.data, full)
        T = self.velocity_map()
        return T.T @ full @ T

    def tip(self) -> Array:
        """The tool tip (site ``tip``) of the current state, (3,)."""
        return np.array(self.data.site_xpos[self.tip_site])

    def rotation(self) -> Array:
        """The end-effector orientation of the current state, (3, 3)."""
        return np.array(self.data.xmat[self.effector]).reshape(3, 3)
