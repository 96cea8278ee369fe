"""Cross-validation of our dynamics against MuJoCo's, on random assemblable states."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import checks
from ..model.robot import Robot
from .export import DIGITS
from .model import MujocoRobot


@dataclass(frozen=True)
class CheckRow:
    """The worst difference of one quantity over the states checked."""

    quantity: str
    worst: float
    unit: str


#: Most random states one check compares (a bound on a mistyped count, not a tuned value).
MAX_STATES = 1_000_000


def random_states(robot: Robot, n: int, seed: int, margin: float = 0.02) -> np.ndarray:
    """``n`` configurations uniform inside the joint limits, assemblable with ``margin`` (m)."""
    rng = np.random.default_rng(seed)
    p = robot.parameters
    chosen: list[np.ndarray] = []
    while sum(len(c) for c in chosen) < n:
        q = rng.uniform(p.lower, p.upper, size=(2 * n, len(p.q_home)))
        chosen.append(q[robot.is_assemblable(q, margin)])
    return np.concatenate(chosen)[:n]


def cross_validate(
    robot: Robot, n: int = 1000, seed: int = 0, bridge: MujocoRobot | None = None, digits: int = DIGITS
) -> list[CheckRow]:
    """Worst differences between MuJoCo (on the exported model: ``bridge``, or the MJCF as
    :func:`~.export.to_mjcf` writes it with ``digits`` significant digits) and our model (the
    paper's robot or any stack) over ``n`` random assemblable states with random velocities
    (joint speeds up to 0.05 m/s and 0.5 rad/s), efforts (about 20 N) and tip forces (about
    10 N). ``n`` is at most :data:`MAX_STATES`."""
    n = checks.whole("n", n, 1, MAX_STATES, unit="states")
    seed = checks.seed("seed", seed)  # 0 to 2**63 - 1, as every seed of vgtarm
    mj = bridge or MujocoRobot(robot, digits=digits)
    rng = np.random.default_rng(seed)
    worst: dict[str, float] = {}

    def note(name: str, value: object) -> None:
        worst[name] = max(worst.get(name, 0.0), float(value))  # type: ignore[arg-type]

    joints = robot.n_joints
    twists = [i for i, unit in enumerate(robot.joint_units) if unit == "rad"]
    zero = np.zeros(joints)
    for q in random_states(robot, n, seed):
        qd = rng.uniform(-0.05, 0.05, size=joints)
        for i in twists:
            qd[i] = rng.uniform(-0.5, 0.5)
        F = rng.normal(scale=20.0, size=joints)
        f = rng.normal(scale=10.0, size=3)
        fk = robot.forward_kinematics(q)
        mj.set_state(q, zero)
        note("tip position (m)", np.linalg.norm(mj.tip() - fk.tip))
        note("orientation (max element)", np.abs(mj.rotation() - fk.rotation).max())
        M = robot.mass_matrix(q)
        M_mj = mj.mass_matrix(q)
        note("mass matrix M (relative)", np.linalg.norm(M_mj - M) / np.linalg.norm(M))
        # bias forces (velocity products, gravity, friction): C = -M qdd at zero effort
        C = robot.bias_forces(q, qd)
        C_mj = -(M_mj @ mj.forward_dynamics(q, qd, zero))
        note("bias forces C, moving (relative)", np.linalg.norm(C_mj - C) / np.linalg.norm(C))
        for label, v, effort, force in (
            ("forward dynamics at rest, gravity only", zero, zero, None),
            ("forward dynamics at rest, efforts", zero, F, None),
            ("forward dynamics at rest, efforts and tip force", zero, F, f),
            ("forward dynamics moving, efforts and tip force", qd, F, f),
        ):
            ours = robot.forward_dynamics(q, v, effort, np.zeros(3) if force is None else force)
            theirs = mj.forward_dynamics(q, v, effort, force)
            note(label + " (relative)", np.linalg.norm(theirs - ours) / np.linalg.norm(ours))
    return [CheckRow(k, v, "") for k, v in worst.items()]


def table(rows: list[CheckRow]) -> str:
    """The rows as a Markdown table."""
    lines = ["| quantity | worst difference |", "| --- | --- |"]
    lines += [f"| {r.quantity} | {r.worst:.2e} |" for r in rows]
    return "\n".join(lines)
