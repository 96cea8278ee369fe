"""The exported robot loaded in MuJoCo, and our joint states mapped onto it."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError, shown
from ..model.robot import Robot
from .export import MAX_DIGITS, home_geometry, require_mujoco, to_mjcf

Array = NDArray[np.float64]


class MujocoRobot:
    """The robot (the paper's or any stack of modules) exported to MJCF and loaded in MuJoCo, with
    our ``q, qd`` (``n`` joints, :attr:`Robot.joint_names`) mapped onto MuJoCo's full state
    (passive hinges from our closed-form passive angles, their rates from the loop closures'
    constraint Jacobian) and MuJoCo's state read back as our joints (the tree's slides and twists,
    the closed legs' tendons). ``export`` options go to :func:`to_mjcf`; ``digits`` is the
    precision of the model's numbers, by default every number as it is (``vgtarm check mujoco``
    checks the file ``vgtarm export mjcf`` writes, at :data:`~.export.DIGITS`)."""

    def __init__(self, robot: Robot, *, timestep: float = 1e-3, digits: int = MAX_DIGITS, **export: Any) -> None:
        if not isinstance(robot, Robot):
            raise InputError(f"robot = {shown(robot)}: expected a vgtarm.Robot (see vgtarm.load_robot)")
        mujoco = require_mujoco()
        self.mujoco = mujoco
        self.robot = robot
        self.xml = to_mjcf(robot, timestep=timestep, digits=digits, **export)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.model.opt.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
        self.data = mujoco.MjData(self.model)
        joint = self.model.joint
        self.qpos_of = {self.model.joint(i).name: int(joint(i).qposadr[0]) for i in range(self.model.njnt)}
        self.dof_of = {self.model.joint(i).name: int(joint(i).dofadr[0]) for i in range(self.model.njnt)}
        names = self.joint_names = robot.joint_names
        self.actuated_dofs = np.array([self.dof_of[n] for n in names])
        self.passive_dofs = np.array([d for d in range(self.model.nv) if d not in set(self.actuated_dofs)])
        home = home_geometry(robot)
        self.home_passive = np.asarray(home.passive)
        self.home_rotation = np.asarray(home.rotation)
        self.effector = self.model.body("end_effector").id
        self.tip_site = self.model.site("tip").id
        # our joints read from the tree (joint i of MuJoCo) or from a tendon (the closed legs)
        tendons = {self.model.tendon(i).name: i for i in range(self.model.ntendon)}
        self.tendon_of = {n: tendons[f"{n}_leg"] for n in names if f"{n}_leg" in tendons}
        self.tree_joints = np.array([i for i, n in enumerate(names) if n not in self.tendon_of], dtype=int)
        self.tendon_joints = np.array([i for i, n in enumerate(names) if n in self.tendon_of], dtype=int)
        self.tree_qpos = np.array([self.qpos_of[names[i]] for i in self.tree_joints], dtype=int)
        self.tree_dofs = np.array([self.dof_of[names[i]] for i in self.tree_joints], dtype=int)
        self.tendons = np.array([self.tendon_of[names[i]] for i in self.tendon_joints], dtype=int)
        site = self.model.site
        self.tendon_sites = [(site(f"{names[i]}_foot").id, site(f"{names[i]}_head").id) for i in self.tendon_joints]

    def set_state(self, q: ArrayLike, qd: ArrayLike) -> None:
        """Put MuJoCo at our joint state ``q``, ``qd`` (n,) with the loop closures satisfied."""
        mujoco, m, d = self.mujoco, self.model, self.data
        q, qd = np.asarray(q, dtype=float), np.asarray(qd, dtype=float)
        passive = self.robot.forward_kinematics(q).passive
        qpos = np.zeros(m.nq)
        for k in range(len(self.home_passive)):
            alpha, beta, gamma, theta = passive[k] - self.home_passive[k]
            qpos[self.qpos_of[f"s{k + 1}_base"]] = alpha
            qpos[self.qpos_of[f"v{k + 1}_base"]] = gamma
            qpos[self.qpos_of[f"p{k + 1}_base"]] = beta
            qpos[self.qpos_of[f"platform{k + 1}"]] = theta - alpha
        for i, name in enumerate(self.joint_names):
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
        """``T`` (nv, n): MuJoCo's velocities on the constraint manifold from our ``qd``."""
        J = self.constraint_jacobian()
        joints = len(self.actuated_dofs)
        T = np.zeros((self.model.nv, joints))
        T[self.actuated_dofs] = np.eye(joints)
        T[self.passive_dofs] = -np.linalg.lstsq(J[:, self.passive_dofs], J[:, self.actuated_dofs], rcond=None)[0]
        return T

    def apply(self, F: ArrayLike, f_tip: ArrayLike | None = None) -> None:
        """Efforts ``F`` (n,) on the actuators and the force ``f_tip`` (3,) on the tool tip."""
        d = self.data
        d.ctrl[:] = np.asarray(F, dtype=float)
        d.xfrc_applied[:] = 0.0
        if f_tip is not None:
            f = np.asarray(f_tip, dtype=float)
            lever = d.site_xpos[self.tip_site] - d.xipos[self.effector]
            d.xfrc_applied[self.effector, :3] = f
            d.xfrc_applied[self.effector, 3:] = np.cross(lever, f)

    def forward_dynamics(self, q: ArrayLike, qd: ArrayLike, F: ArrayLike, f_tip: ArrayLike | None = None) -> Array:
        """Our joint accelerations (n,) computed by MuJoCo (:meth:`joint_accelerations`)."""
        self.set_state(q, qd)
        self.apply(F, f_tip)
        self.mujoco.mj_forward(self.model, self.data)
        return self.joint_accelerations()

    def joint_positions(self) -> Array:
        """Our joint values (n,) of the current state: the tree's slides and twists, and the closed
        legs' lengths from their tendons (exact, unlike the followers' slides behind the soft
        closures)."""
        d = self.data
        q = np.empty(len(self.joint_names))
        q[self.tree_joints] = d.qpos[self.tree_qpos]
        q[self.tendon_joints] = d.ten_length[self.tendons]
        return q

    def joint_velocities(self) -> Array:
        """Our joint velocities (n,) of the current state (as :meth:`joint_positions`)."""
        d = self.data
        qd = np.empty(len(self.joint_names))
        qd[self.tree_joints] = d.qvel[self.tree_dofs]
        qd[self.tendon_joints] = d.ten_velocity[self.tendons]
        return qd

    def joint_accelerations(self) -> Array:
        """Our joint accelerations (n,) from MuJoCo's ``qacc`` of the current state (after
        ``mj_forward``). A closed leg's is its tendon's, the length ``L = |x_head - x_foot|``
        differentiated twice: ``L'' = u . (a_head - a_foot) + (|d'|^2 - L'^2) / L`` with ``d`` the
        foot-to-head vector, ``u = d / L`` and each site's acceleration ``J qacc + Jdot qvel``
        (the velocity-product term that MuJoCo leaves out of constraint accelerations)."""
        mujoco, m, d = self.mujoco, self.model, self.data
        qdd = np.empty(len(self.joint_names))
        qdd[self.tree_joints] = d.qacc[self.tree_dofs]
        for j, (foot, head) in zip(self.tendon_joints, self.tendon_sites, strict=True):
            rel = np.zeros(3)
            acc = np.zeros(3)
            for sign, site in ((-1.0, foot), (1.0, head)):
                jac, jac_dot = np.zeros((3, m.nv)), np.zeros((3, m.nv))
                mujoco.mj_jacSite(m, d, jac, None, site)
                mujoco.mj_jacDot(m, d, jac_dot, None, d.site_xpos[site], m.site_bodyid[site])
                rel += sign * (jac @ d.qvel)
                acc += sign * (jac @ d.qacc + jac_dot @ d.qvel)
            delta = d.site_xpos[head] - d.site_xpos[foot]
            length = float(np.linalg.norm(delta))
            u = delta / length
            qdd[j] = u @ acc + (rel @ rel - (u @ rel) ** 2) / length
        return qdd

    def mass_matrix(self, q: ArrayLike) -> Array:
        """MuJoCo's mass matrix reduced to our ``n`` joints, ``T^T M T`` (n, n)."""
        self.set_state(q, np.zeros(len(self.actuated_dofs)))
        full = np.zeros((self.model.nv, self.model.nv))
        self.mujoco.mj_fullM(self.model, self.data, full)
        T = self.velocity_map()
        return T.T @ full @ T

    def tip(self) -> Array:
        """The tool tip (site ``tip``) of the current state, (3,)."""
        return np.array(self.data.site_xpos[self.tip_site])

    def rotation(self) -> Array:
        """The end-effector orientation of the current state, (3, 3): the body's turn from the home
        pose (MuJoCo's body frames are aligned with F0 at home) applied to its home orientation."""
        return np.array(self.data.xmat[self.effector]).reshape(3, 3) @ self.home_rotation
