"""A joint reference checked against the robot's actuator limits, before any run.

Along the reference ``q(t), qd(t), qdd(t)`` each actuator must give the effort of the inverse
dynamics with friction and the expected tool force,

    F = M(q) qdd + C(q, qd) - J_P(q)^T f_tool      (eq. 15; C: velocity products, gravity, friction)

with ``f_tool = -F0 V/|V|`` along the tip velocity ``V = J_P qd`` while ``|V| > cutting_speed``
(zero below it): the cutting force of the plant (:class:`~vgtarm.simulation.ExternalForce`, the C
``tool_force`` of the closed loop), of constant magnitude ``F0`` (N). Each joint's effort is then
compared with its force bounds at its own velocity (:meth:`~vgtarm.model.actuators.Actuators.bounds`,
the force-speed line where it holds), its velocity with its no-load speed, and its acceleration with
its acceleration limit where one is given. :func:`check_path` returns a :class:`PathCheck`: the
arrays, ``ok``, the :class:`Violation` rows, a plain-text table, a CSV and a figure.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .. import checks
from ..errors import InputError, cut, shown
from ..fileio import atomic_open, check_output_file
from ..model.actuators import Actuators
from ..paths import TipPath
from ..toolpaths import ToolPath
from .external import ExternalForce
from .reference import JointReference

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..model.robot import Robot

Array = NDArray[np.float64]

#: Tip speed (m/s) below which the tool force is zero: the plant's default (ExternalForce).
CUTTING_SPEED: float = ExternalForce.cutting_speed
#: The kinds of limit, in the order of the table.
KINDS = ("force", "speed", "acceleration")
#: Widest joint name shown in a column of the table (longer ones are cut, ending in ``~``).
NAME_WIDTH = 12
#: Widest robot or reference name shown in the table's heading.
TITLE_WIDTH = 80


@dataclass(frozen=True)
class Violation:
    """One joint's excess of one kind of limit along the reference.

    ``value`` is the signed effort (N, N m), velocity (m/s, rad/s) or acceleration (m/s^2, rad/s^2)
    at ``worst_time`` (s), where the excess is largest; ``limit`` the signed bound it passed there
    (for a force, the bound at that velocity); ``excess`` how far beyond (same unit, > 0) and
    ``excess_percent`` that as a percentage of ``|limit|`` (``inf`` for a bound of zero);
    ``first_time`` (s) the first sample beyond and ``time_beyond`` (s) the samples beyond times the
    sampling period."""

    joint: str
    kind: str
    unit: str
    first_time: float
    worst_time: float
    value: float
    limit: float
    excess: float
    excess_percent: float
    time_beyond: float


def _units(joint_unit: str) -> tuple[str, str, str]:
    """The force, speed and acceleration units of a joint measured in ``joint_unit`` (m or rad)."""
    return ("N m", "rad/s", "rad/s^2") if joint_unit == "rad" else ("N", "m/s", "m/s^2")


def _column_name(name: str, width: int = NAME_WIDTH) -> str:
    """A user's name as one column cell: ASCII (anything else escaped), at most ``width`` characters."""
    text = name.encode("ascii", "backslashreplace").decode("ascii")
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= width else text[: width - 1] + "~"


@dataclass(frozen=True, eq=False)
class PathCheck:
    """A reference checked against actuator limits (:func:`check_path`).

    Arrays have ``N`` rows (samples at ``t``, s) and ``n`` columns (joints, ``joint_names``):
    ``efforts`` (N, N m) of the inverse dynamics, ``lower``/``upper`` the force bounds at each
    sample's joint velocity, ``qd``/``qdd`` the reference's velocities and accelerations,
    ``tip_force`` ``(N, 3)`` the expected tool force used (N, F0). The utilisations are fractions of
    the limit (1 at a limit, 0 for a joint without one): ``force_utilisation`` in the effort's own
    direction, ``speed_utilisation`` ``|qd| / speed``, ``acceleration_utilisation`` ``|qdd| /
    acceleration`` (0 where no acceleration limit is given)."""

    t: Array
    efforts: Array
    lower: Array
    upper: Array
    qd: Array
    qdd: Array
    tip_force: Array
    force_utilisation: Array
    speed_utilisation: Array
    acceleration_utilisation: Array
    actuators: Actuators
    joint_names: tuple[str, ...]
    joint_units: tuple[str, ...]
    reference: str = "reference"
    robot: str = ""
    tool_force: float = 0.0
    cutting_speed: float = CUTTING_SPEED

    @property
    def dt(self) -> float:
        """Sampling period (s)."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))

    @property
    def ok(self) -> bool:
        """Whether every joint stays within every limit at every sample."""
        return not self.violations()

    def _series(self, kind: str, j: int) -> tuple[Array, Array, Array]:
        """The values of ``kind`` for joint ``j``, their signed limits and their excesses, each ``(N,)``."""
        if kind == "force":
            value = self.efforts[:, j]
            above = value - self.upper[:, j]
            below = self.lower[:, j] - value
            limit = np.where(above >= below, self.upper[:, j], self.lower[:, j])
            return value, limit, np.maximum(above, below)
        value = self.qd[:, j] if kind == "speed" else self.qdd[:, j]
        bound = (self.actuators.speed if kind == "speed" else self.actuators.acceleration)[j]
        limit = np.where(value >= 0.0, bound, -bound)
        return value, limit, np.abs(value) - bound

    def violations(self) -> list[Violation]:
        """One row per joint and kind of limit exceeded (joints in order, then force, speed,
        acceleration); empty when the reference stays within the limits."""
        rows = []
        for j, (name, unit) in enumerate(zip(self.joint_names, self.joint_units, strict=True)):
            if not self.actuators.limited[j]:
                continue
            for kind, shown_unit in zip(KINDS, _units(unit), strict=True):
                value, limit, excess = self._series(kind, j)
                beyond = excess > 0.0
                if not beyond.any():
                    continue
                worst = int(np.argmax(np.where(beyond, excess, -np.inf)))
                bound = abs(float(limit[worst]))
                rows.append(
                    Violation(
                        joint=name,
                        kind=kind,
                        unit=shown_unit,
                        first_time=float(self.t[int(np.argmax(beyond))]),
                        worst_time=float(self.t[worst]),
                        value=float(value[worst]),
                        limit=float(limit[worst]),
                        excess=float(excess[worst]),
                        excess_percent=100.0 * float(excess[worst]) / bound if bound > 0.0 else math.inf,
                        time_beyond=int(np.count_nonzero(beyond)) * self.dt,
                    )
                )
        return rows

    def table(self) -> str:
        """The check as plain text for a terminal: a heading, each joint's largest use of each
        limit, the verdict and the violations (names escaped and cut: never break a column)."""
        return _table(self)

    def to_csv(self, path: str | os.PathLike[str]) -> Path:
        """Write the arrays as CSV at ``path`` (a new name or a regular file, written atomically:
        never left partial): ``t``, then per joint its effort, bounds, velocity, acceleration and
        the three utilisations (SI units). Returns ``path``."""
        target = check_output_file(path, "path")
        header = ["t"]
        for name in self.joint_names:
            header += [f"{key}_{name}" for key in ("F", "F_lower", "F_upper", "qd", "qdd")]
            header += [f"use_{kind}_{name}" for kind in KINDS]
        per_joint = (
            self.efforts,
            self.lower,
            self.upper,
            self.qd,
            self.qdd,
            self.force_utilisation,
            self.speed_utilisation,
            self.acceleration_utilisation,
        )
        table = np.concatenate([self.t[:, None], np.stack(per_joint, axis=2).reshape(len(self.t), -1)], axis=1)
        target.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(target, "path") as stream:
            writer = csv.writer(stream, lineterminator="\n")
            writer.writerow(header)
            writer.writerows([f"{v:.10g}" for v in row] for row in table)
        return target

    def figure(self) -> Figure:
        """Per joint, its effort against time with the force bounds at its velocity (the band
        shaded, the excess marked in red), and beside it the use of its speed and acceleration
        limits (1: at the limit). A matplotlib Figure (Agg: no window)."""
        return _figure(self)


def _ratio(value: Array, limit: Array) -> Array:
    """``|value| / limit`` where the limit is finite, else 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.isfinite(limit), np.abs(value) / limit, 0.0)


def _reference(robot: Robot, reference: object) -> JointReference:
    """``reference`` as a :class:`JointReference` on ``robot``: a desired tip or tool path is solved
    first (inverse kinematics with its defaults; a tool path's task)."""
    if isinstance(reference, ToolPath):
        reference = robot.inverse_kinematics(reference.tip, **reference.task(robot))
    elif isinstance(reference, TipPath):
        reference = robot.inverse_kinematics(reference)
    ref = JointReference.of(reference)  # type: ignore[arg-type]
    if ref.q.shape[1] != robot.n_joints:
        checks.refuse("reference.q.shape", ref.q.shape, f"(N, {robot.n_joints}): one column per joint of the robot")
    if ref.robot_fingerprint and ref.robot_fingerprint != robot.fingerprint:
        raise InputError(
            f"reference {shown(ref.name)}: solved for robot {shown(ref.robot)} ({ref.robot_fingerprint}), not "
            f"{shown(robot.parameters.name)} ({robot.fingerprint}); solve its inverse kinematics on this robot"
        )
    return ref


def _actuators(robot: Robot, actuators: object) -> Actuators:
    """The actuators to check against: ``actuators`` or the robot's, refused in one line if none."""
    chosen = robot.actuators if actuators is None else actuators
    if chosen is None:
        raise InputError(
            f"actuators = None: robot {shown(robot.parameters.name)} has no actuators (no [actuators] table in its "
            "file); pass actuators= (a vgtarm.model.actuators.Actuators) or load a robot file with one"
        )
    if not isinstance(chosen, Actuators):
        checks.refuse("actuators", chosen, "an Actuators (vgtarm.model.actuators) or None")
    if tuple(chosen.names) != tuple(robot.joint_names):
        checks.refuse("actuators.names", chosen.names, f"the robot's joints {robot.joint_names}")
    return chosen


def expected_tool_force(velocity: Array, force: float, cutting_speed: float) -> Array:
    """The tool force ``(..., 3)`` (N) at tip velocities ``velocity`` ``(..., 3)`` (m/s):
    ``-force V/|V|`` where ``|V| > cutting_speed`` (m/s), zero elsewhere (the plant's cutting force)."""
    v = np.asarray(velocity, dtype=float)
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    moving = speed > cutting_speed
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(moving, -force * v / np.where(moving, speed, 1.0), 0.0)


def check_path(
    robot: Robot,
    reference: Any,
    *,
    actuators: Actuators | None = None,
    tool_force: float = 0.0,
    cutting_speed: float = CUTTING_SPEED,
) -> PathCheck:
    """Check ``reference`` on ``robot`` against actuator limits (see the module docstring).

    Args:
        robot: the robot whose dynamics (friction included) give the efforts.
        reference: an IK result, a :class:`JointReference` (anything with ``t``, ``q``, ``qd``,
            ``qdd``), or a desired :class:`~vgtarm.paths.TipPath` / :class:`~vgtarm.toolpaths.ToolPath`
            (solved first by the inverse kinematics with its defaults).
        actuators: the limits (default: the robot's, from its file's ``[actuators]`` table).
        tool_force: ``F0`` (N), the magnitude of the tool force against the tip's motion; 0: none.
        cutting_speed: tip speed (m/s) at or below which the tool force is zero.

    Raises :class:`~vgtarm.errors.InputError` (one line naming the argument) for a robot without
    actuators and no ``actuators``, or a bad argument.
    """
    limits = _actuators(robot, actuators)
    force = checks.number("tool_force", tool_force, minimum=0, unit="N")
    speed = checks.number("cutting_speed", cutting_speed, minimum=0, unit="m/s")
    ref = _reference(robot, reference)
    velocity, _ = robot.tip_velocity(ref.q, ref.qd)
    f_tip = expected_tool_force(velocity, force, speed)
    efforts = robot.inverse_dynamics(ref.q, ref.qd, ref.qdd, f_tip)
    lower, upper = limits.bounds(ref.qd)
    limited = limits.limited
    return PathCheck(
        t=ref.t,
        efforts=efforts,
        lower=lower,
        upper=upper,
        qd=ref.qd,
        qdd=ref.qdd,
        tip_force=f_tip,
        force_utilisation=limits.utilisation(efforts, ref.qd),
        speed_utilisation=np.where(limited, _ratio(ref.qd, limits.speed), 0.0),
        acceleration_utilisation=np.where(limited, _ratio(ref.qdd, limits.acceleration), 0.0),
        actuators=limits,
        joint_names=tuple(robot.joint_names),
        joint_units=tuple(robot.joint_units),
        reference=ref.name,
        robot=robot.parameters.name,
        tool_force=force,
        cutting_speed=speed,
    )


def _percent(fraction: float) -> str:
    return "inf" if not math.isfinite(fraction) else f"{100.0 * fraction:.1f} %"


def _heading(check: PathCheck) -> list[str]:
    """The table's first lines: what was checked, on which robot, with which tool force."""
    span = f"{len(check.t)} samples, t = {check.t[0]:.6g} .. {check.t[-1]:.6g} s, dt = {check.dt:.6g} s"
    tool = (
        f"{check.tool_force:g} N against the tip's motion (above {check.cutting_speed:g} m/s)"
        if check.tool_force > 0
        else "none"
    )
    return [
        f"reference   {cut(check.reference, TITLE_WIDTH)} ({span})",
        f"robot       {cut(check.robot, TITLE_WIDTH)}",
        f"tool force  {tool}",
    ]


def _use_rows(check: PathCheck, width: int) -> list[str]:
    """Each joint's largest use of its force, speed and acceleration limits, and its peak effort."""
    rows = [f"{'joint':<{width}}  {'force':>9}  {'speed':>9}  {'accel':>9}  {'peak effort':>16}  status"]
    failed = {row.joint for row in check.violations()}
    for j, (name, unit) in enumerate(zip(check.joint_names, check.joint_units, strict=True)):
        peak = f"{np.max(np.abs(check.efforts[:, j])):.4g} {_units(unit)[0]}"
        if not check.actuators.limited[j]:
            cells = ["-", "-", "-"]
            status = "no actuator"
        else:
            uses = [check.force_utilisation, check.speed_utilisation]
            cells = [_percent(float(np.max(u[:, j]))) for u in uses]
            finite = math.isfinite(float(check.actuators.acceleration[j]))
            cells.append(_percent(float(np.max(check.acceleration_utilisation[:, j]))) if finite else "-")
            status = "EXCEEDED" if name in failed else "ok"
        label = _column_name(name, width)
        rows.append(f"{label:<{width}}  {cells[0]:>9}  {cells[1]:>9}  {cells[2]:>9}  {peak:>16}  {status}")
    return rows


def _violation_rows(violations: list[Violation], width: int) -> list[str]:
    """The table of the violations, one row per joint and kind."""
    rows = [
        f"{'joint':<{width}}  {'kind':<12}  {'first (s)':>9}  {'worst (s)':>9}  {'value':>10}  {'limit':>10}  "
        f"{'excess':>10}  {'excess %':>9}  {'beyond (s)':>10}  unit"
    ]
    for v in violations:
        percent = "inf" if not math.isfinite(v.excess_percent) else f"{v.excess_percent:.1f}"
        rows.append(
            f"{_column_name(v.joint, width):<{width}}  {v.kind:<12}  {v.first_time:>9.4f}  {v.worst_time:>9.4f}  "
            f"{v.value:>10.4g}  {v.limit:>10.4g}  {v.excess:>10.4g}  {percent:>9}  {v.time_beyond:>10.4f}  {v.unit}"
        )
    return rows


def _table(check: PathCheck) -> str:
    """:meth:`PathCheck.table`."""
    width = max([5, *(len(_column_name(name)) for name in check.joint_names)])
    lines = [*_heading(check), "", "largest use of each limit (100 % = at the limit; force: at the joint's velocity)"]
    lines += _use_rows(check, width)
    violations = check.violations()
    lines.append("")
    if not violations:
        lines.append("result      within every limit")
        return "\n".join(lines) + "\n"
    names = ", ".join(f"{_column_name(v.joint)} {v.kind}" for v in violations)
    lines.append(f"result      {len(violations)} limit{'s' if len(violations) > 1 else ''} exceeded: {names}")
    lines += ["", *_violation_rows(violations, width)]
    return "\n".join(lines) + "\n"


def _effort_panel(ax: Any, check: PathCheck, j: int) -> None:
    """Joint ``j``'s effort, its force bounds (the band between them shaded) and the excess in red."""
    t, effort = check.t, check.efforts[:, j]
    name = _column_name(check.joint_names[j])
    unit = _units(check.joint_units[j])[0]
    ax.plot(t, effort, color="C0", lw=1.0, label="effort")
    if check.actuators.limited[j]:
        low, high = check.lower[:, j], check.upper[:, j]
        ax.fill_between(t, low, high, color="C2", alpha=0.15, lw=0, label="within the bounds")
        ax.plot(t, high, color="C2", lw=0.8)
        ax.plot(t, low, color="C2", lw=0.8)
        out = (effort > high) | (effort < low)
        if out.any():
            edge = np.where(effort > high, high, low)
            ax.fill_between(t, edge, effort, where=out, color="C3", alpha=0.5, lw=0, label="excess")
            ax.plot(t[out], effort[out], ".", color="C3", ms=2)
        margin = 0.1 * max(np.ptp(effort), 1e-9)
        ax.set_ylim(min(effort.min(), low.min()) - margin, max(effort.max(), high.max()) + margin)
    ax.set_ylabel(f"{name} ({unit})")
    ax.grid(True, alpha=0.3)


def _use_panel(ax: Any, check: PathCheck, j: int) -> None:
    """Joint ``j``'s use of its speed and acceleration limits (1: at the limit)."""
    t = check.t
    if not check.actuators.limited[j]:
        ax.text(0.5, 0.5, "no actuator", ha="center", va="center", transform=ax.transAxes)
    else:
        ax.plot(t, check.speed_utilisation[:, j], color="C1", lw=1.0, label="speed")
        if math.isfinite(float(check.actuators.acceleration[j])):
            ax.plot(t, check.acceleration_utilisation[:, j], color="C4", lw=1.0, label="acceleration")
        ax.axhline(1.0, color="C3", lw=0.8, ls="--")
        top = max(float(np.max(check.speed_utilisation[:, j])), float(np.max(check.acceleration_utilisation[:, j])))
        ax.set_ylim(0.0, 1.1 * max(top, 1.0) if math.isfinite(top) else 2.0)
    ax.set_ylabel("use (1 = limit)")
    ax.grid(True, alpha=0.3)


def _figure(check: PathCheck) -> Figure:
    """:meth:`PathCheck.figure`."""
    from matplotlib.figure import Figure

    n = len(check.joint_names)
    fig = Figure(figsize=(11.0, 1.7 * n + 1.2), layout="constrained")
    axes = fig.subplots(n, 2, sharex=True, squeeze=False)
    for j in range(n):
        _effort_panel(axes[j, 0], check, j)
        _use_panel(axes[j, 1], check, j)
    axes[0, 0].set_title("effort and its bounds at the joint's velocity")
    axes[0, 1].set_title("use of the speed and acceleration limits")
    for column in range(2):
        handles, labels = [], []
        for ax in axes[:, column]:
            for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
                if label not in labels:
                    handles.append(handle)
                    labels.append(label)
        axes[0, column].legend(handles, labels, fontsize=7, loc="upper right")
        axes[-1, column].set_xlabel("t (s)")
    verdict = "within the limits" if check.ok else "limits exceeded"
    fig.suptitle(f"{cut(check.reference, 60)} on {cut(check.robot, 60)}: {verdict}")
    return fig


__all__ = ["CUTTING_SPEED", "KINDS", "PathCheck", "Violation", "check_path", "expected_tool_force"]
