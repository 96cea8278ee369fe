"""Result records of inverse kinematics: per-sample arrays and the overall result.

Writing the joint reference as CSV, atomically.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, shown
from ..fileio import atomic_open
from ..model.parameters import JOINT_NAMES
from ..model.robot import Robot
from ..paths import TipPath

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class IKSamples:
    """What happened at every sample; every array has ``N`` rows.

    Attributes:
        success: ``(N,)`` the sample was solved and its KKT conditions verified.
        residual: ``(N,)`` distance of the tip from the desired point (m).
        orientation_error: ``(N,)`` angle between the end-effector and the desired orientation
            (rad), for the axis task between the tool's axis and the desired axis; NaN for the
            free-orientation task.
        phi: ``(N,)`` the cost ``Phi(q)`` of eq. 12.
        active: ``(N, 2 n + k)`` active inequalities, labelled by ``constraint_labels``: lower
            limits, upper limits, then the assembly rows ``G q + h >= margin``.
        constraint_labels: ``(2 n + k,)`` names of the inequalities.
        multipliers: ``(N, m)`` Lagrange multipliers of the task equations (3, 5 or 6; 2 or 1 for a
            robot whose tip moves in a plane or a line).
        inequality_multipliers: ``(N, 2 n + k)`` multipliers of the inequalities (>= 0 at an optimum).
        stationarity: ``(N,)`` largest entry of the Lagrangian gradient.
        curvature: ``(N,)`` certificate of the second-order condition, positive when the Hessian of
            the Lagrangian is verified positive definite on the null space of the active
            constraints (see :func:`vgtarm.ik.kkt.reduced_curvature`).
        iterations: ``(N,)`` Newton or solver iterations spent on the sample (0: the interpolated
            guess already met the tolerances).
        method: ``(N,)`` method that produced the sample: ``"newton"``, ``"slsqp"``, ``"ipopt"``,
            or ``"slsqp (fallback)"`` for a sample the fast solver handed to the reference solver.
        entry_distance: ``(N,)`` distance of the entry point from the tool's axis (m), for the
            entry-point task; None otherwise.
    """

    success: NDArray[np.bool_]
    residual: Array
    orientation_error: Array
    phi: Array
    active: NDArray[np.bool_]
    constraint_labels: tuple[str, ...]
    multipliers: Array
    inequality_multipliers: Array
    stationarity: Array
    curvature: Array
    iterations: NDArray[np.int64]
    method: NDArray[np.str_]
    entry_distance: Array | None = None

    @property
    def n_bounds(self) -> int:
        """``2 n``: the joint-limit rows (``n`` lower, then ``n`` upper limits) among the inequalities."""
        return 2 * sum(label.endswith(" >= min") for label in self.constraint_labels)

    @property
    def active_bounds(self) -> NDArray[np.bool_]:
        """``(N, 2 n)``: lower limits of the joints then upper limits."""
        return self.active[:, : self.n_bounds]

    @property
    def active_assembly(self) -> NDArray[np.bool_]:
        """``(N, k)``: the assembly rows, labelled by ``constraint_labels[2 n:]``."""
        return self.active[:, self.n_bounds :]


@dataclass(frozen=True, eq=False)
class IKResult:
    """The joint-space reference of a desired tip path.

    Attributes:
        t: ``(N,)`` sample times (s).
        q, qd, qdd: ``(N, n)`` joint values, rates and accelerations (m, rad; per s, per s^2).
        position, velocity, acceleration: ``(N, 3)`` the desired tip path (SI).
        orientation: ``(N, 3, 3)`` the desired orientation (pose task) or ``None``.
        axis: ``(N, 3)`` the desired tool axis (axis and entry-point tasks) or ``None``.
        entry_point: ``(3,)`` the entry point the tool's axis passes through (m), or ``None``.
        samples: the per-sample record.
        solver: name of the solver (``"fast"``, ``"slsqp"``, ``"ipopt"``).
        rates: ``"exact"`` or ``"finite_difference"``.
        task: ``"position"``, ``"pose"``, ``"axis"`` or ``"entry point"``.
        margin: assembly margin used (m).
        lower, upper: ``(n,)`` joint limits.
        wall_time_s: wall-clock time of the solve (s).
        success: every sample succeeded (``status`` ``"completed"``).
        message: a one-line summary (which samples failed, if any).
        work: the solver's work counters (``n_iterations``, ``n_evaluations``, ``n_converged``,
            ``wall_time_s``; see :class:`vgtarm.ik.SolverResult`), before any fallback (summed
            over both solves of a path cut at an unreachable sample, see ``check``).
        robot_name: name of the robot the reference was solved for ("" if unknown).
        robot_fingerprint: :attr:`vgtarm.Robot.fingerprint` of that robot's parameters, so a
            simulation of another robot can say so ("" if unknown).
        joint_names: the robot's joint names, in the order of the columns of ``q``.
        path_name: the name of the desired path (:attr:`vgtarm.paths.TipPath.name`; "" if unknown).
        task_space: the tip coordinates the task constrained: ``"tip (u1, u2, u3)"`` (with
            ``" and orientation"`` for the pose task), or for a robot whose tip moves in a plane or a
            line the reduced task (:mod:`vgtarm.ik.taskspace`), e.g. ``"tip (u2, u3) in its plane"``.
        status: how the solve ended: ``"completed"`` (every sample solved and verified),
            ``"unverified"`` (every sample reached, some without their optimality conditions
            verified) or ``"unreachable"`` (``inverse_kinematics(..., check=False)`` on a path with
            a sample out of reach: the rows from that sample on are NaN, see :attr:`completed`).
        robot: the :class:`~vgtarm.Robot` it was solved for (None if unknown). Not pickled (a robot
            holds its compiled library): a result sent to another process keeps the names only.
        path: the desired :class:`~vgtarm.paths.TipPath` (None if unknown).
    """

    t: Array
    q: Array
    qd: Array
    qdd: Array
    position: Array
    velocity: Array
    acceleration: Array
    orientation: Array | None
    samples: IKSamples
    solver: str
    rates: str
    task: str
    margin: float
    lower: Array
    upper: Array
    wall_time_s: float
    success: bool
    message: str
    work: Mapping[str, float] = field(default_factory=dict)
    robot_name: str = ""
    robot_fingerprint: str = ""
    joint_names: tuple[str, ...] = JOINT_NAMES
    path_name: str = ""
    task_space: str = ""
    status: str = ""
    robot: Robot | None = None
    path: TipPath | None = None
    axis: Array | None = None
    entry_point: Array | None = None

    def __post_init__(self) -> None:
        if not self.status:  # not given: what success says (an unreachable path is said by the solve)
            object.__setattr__(self, "status", "completed" if self.success else "unverified")

    def __getstate__(self) -> dict[str, Any]:
        """The pickled state: everything but :attr:`robot` (its compiled library does not pickle)."""
        return {**self.__dict__, "robot": None}

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def completed(self) -> int:
        """Number of samples solved: all of them, or those before the unreachable one (status
        ``"unreachable"``; the rows from it on are NaN)."""
        finite = np.isfinite(self.q).all(axis=1)
        return len(self) if finite.all() else int(np.argmin(finite))

    def to_dataframe(self) -> Any:
        """The reference as a :class:`pandas.DataFrame`, one row per sample and the columns of the
        CSV file (:func:`csv_columns`: ``t``, the tip point, the joints, their rates and
        accelerations; SI units). Needs pandas (``pip install "vgtarm[dataframe]"``)."""
        try:
            import pandas
        except ImportError:
            raise ImportError('to_dataframe() needs pandas: pip install "vgtarm[dataframe]"') from None
        table = np.column_stack([self.t, self.position, self.q, self.qd, self.qdd])
        return pandas.DataFrame(table, columns=list(csv_columns(self.joint_names)))

    def plot(self, ax: Any = None) -> Any:
        """Each joint's distance to its nearer limit as a fraction of its span (0 at a limit, 0.5
        at mid-range) against time, into ``ax`` (a new figure's axes when None); returns the axes.
        This is what eq. 12's criterion spends the redundancy on."""
        if ax is None:
            from matplotlib.figure import Figure

            ax = Figure(figsize=(6.0, 3.0), layout="constrained").add_subplot()
        span = self.upper - self.lower
        clearance = np.minimum(self.q - self.lower, self.upper - self.q) / span
        for j, name in enumerate(self.joint_names):
            ax.plot(self.t, clearance[:, j], linewidth=0.9, label=name)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("clearance / span")
        ax.legend(fontsize="small", ncol=min(len(self.joint_names), 7))
        return ax

    def limit_clearance(self) -> tuple[Array, Array]:
        """Smallest distance of each joint to its lower and to its upper limit over the path, ``(n,)`` each."""
        return (self.q - self.lower).min(axis=0), (self.upper - self.q).min(axis=0)


def csv_columns(joint_names: tuple[str, ...] = JOINT_NAMES) -> tuple[str, ...]:
    """Columns of the CSV file of a robot with these joints: time, desired tip point, joints, rates,
    accelerations (SI units)."""
    return (
        ("t", "x", "y", "z")
        + tuple(joint_names)
        + tuple(f"d{name}" for name in joint_names)
        + tuple(f"dd{name}" for name in joint_names)
    )


#: Columns of the CSV file of the paper's robot (a stack's: :func:`csv_columns` of its joints).
CSV_COLUMNS: tuple[str, ...] = csv_columns()


def write_csv(result: IKResult, file: str | os.PathLike[str]) -> None:
    """Write one row per sample with the columns :func:`csv_columns` of the result's joints (full double
    precision; :data:`CSV_COLUMNS` for the paper's robot).

    The file is written atomically (:func:`vgtarm.fileio.atomic_open`): a reader never sees a
    partial file and nothing is left behind when writing fails.
    """
    if not isinstance(result, IKResult):
        raise InputError(f"result = {shown(result)}: expected an IKResult (from inverse_kinematics)")
    table = np.column_stack([result.t, result.position, result.q, result.qd, result.qdd])
    with atomic_open(file) as stream:
        stream.write(",".join(csv_columns(result.joint_names)) + "\n")
        np.savetxt(stream, table, delimiter=",", fmt="%.17g")
