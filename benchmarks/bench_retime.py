"""Retiming benchmark: :func:`vgtarm.retiming.retime` against toppra's TOPP-RA on case 1 and case 2.

Both solve the same problem, measured in the same run: the IK path's geometry (the retiming's
cubic Hermite with the exact rates, given to toppra as its path), the same uniform grid of the
path parameter, the friction-free robot (toppra, linear in ``(sddot, sdot^2)``, cannot hold
viscous friction), every leg 60 N and 0.05 m/s, the twist 5 N m and 3 rad/s (box limits: toppra
has no force-speed line), toppra's collocation (our ``scheme="departure"``), ``ParametrizeConstAccel``.
Timed: from the IK result to the duration (toppra: building the constraints and the problem,
``compute_trajectory``; ours: ``retime``), the best of several rounds. Printed: each time, the
speed-up, both durations and their relative difference, the largest force excess of our
friction-free profile resampled at 1 ms (between the grid points, where TOPP-RA's collocation does
not look: toppra's profile has the same) and of our default scheme's (``"interval"``), then ours
(default scheme) with the legs' friction exact (200 N s/m) and with force-speed lines, which
toppra cannot take.
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

import numpy as np

import vgtarm
from vgtarm import retiming
from vgtarm.model.actuators import Actuator, Actuators

from .common import Row, best_time, print_table

#: Grid points compared.
GRIDS = (200, 400, 800)
CASES = ("case1", "case2")


def limits(robot: vgtarm.Robot, *, line: bool = False) -> Actuators:
    """Legs 60 N and 0.05 m/s, the twist 5 N m and 3 rad/s (with force-speed lines if ``line``)."""
    legs = Actuator(force=60.0, speed=0.05, force_speed=line)
    twist = Actuator(force=5.0, speed=3.0, force_speed=line)
    return Actuators(
        names=robot.joint_names, joints=tuple(twist if n.startswith("psi") else legs for n in robot.joint_names)
    )


def toppra_path(geometry: retiming.Geometry) -> Any:
    """The retiming's geometry as a toppra path (toppra imported here: an optional dependency)."""
    import toppra as ta

    class Path(ta.interpolator.AbstractGeometricPath):
        def __call__(self, s: Any, order: int = 0) -> np.ndarray:
            values = geometry(np.atleast_1d(np.asarray(s, dtype=float)))[order]
            return values if np.ndim(s) else values[0]

        @property
        def dof(self) -> int:
            return int(geometry.q.shape[1])

        @property
        def path_interval(self) -> np.ndarray:
            return np.array([geometry.t[0], geometry.t[-1]])

    return Path()


def toppra_problem(robot: vgtarm.Robot, reference: Any, actuators: Actuators, grid: int) -> tuple[Any, Any]:
    """toppra's TOPP-RA problem (``algorithm.TOPPRA``) on the retiming's geometry of ``reference``, a
    uniform grid of ``grid`` points and the box limits of ``actuators`` (``robot``: its dynamics),
    and that geometry; the one problem the benchmark times and the tests compare with."""
    from toppra import algorithm, constraint

    geometry = retiming.Geometry(reference.t, reference.q, reference.qd, reference.qdd)
    speed = np.stack([-actuators.speed, actuators.speed], axis=1)
    force = np.stack([-actuators.force, actuators.force], axis=1)
    constraints = [
        constraint.JointVelocityConstraint(speed),
        constraint.JointTorqueConstraint(robot.inverse_dynamics, force, np.zeros(robot.n_joints)),
    ]
    s = np.linspace(reference.t[0], reference.t[-1], grid)
    problem = algorithm.TOPPRA(constraints, toppra_path(geometry), gridpoints=s, parametrizer="ParametrizeConstAccel")
    return problem, geometry


def toppra_duration(robot: vgtarm.Robot, reference: Any, actuators: Actuators, grid: int) -> float:
    """toppra's TOPP-RA duration (s) on the same geometry, grid and box limits."""
    problem, _ = toppra_problem(robot, reference, actuators, grid)
    return float(problem.compute_trajectory(0, 0).duration)


def _compare(
    robot: vgtarm.Robot, frictionless: vgtarm.Robot, case: str, reference: Any, grid: int
) -> tuple[list[Row], str]:
    """One case and grid: the timing rows (toppra's scheme, our default) and the line of durations."""
    box = limits(robot)
    theirs = toppra_duration(frictionless, reference, box, grid)
    ours = retiming.retime(frictionless, reference, actuators=box, grid=grid, scheme="departure", refine=0)
    t_theirs = best_time(lambda: toppra_duration(frictionless, reference, box, grid), repeat=3)
    t_ours = best_time(
        lambda: retiming.retime(frictionless, reference, actuators=box, grid=grid, scheme="departure", refine=0),
        repeat=3,
    )
    t_default = best_time(
        lambda: retiming.retime(frictionless, reference, actuators=box, grid=grid, refine=0), repeat=3
    )
    t_refined = best_time(lambda: retiming.retime(robot, reference, actuators=box, grid=grid), repeat=3)
    rows = [
        Row(f"{case}, {grid} points", t_ours, "path", 1, "toppra 0.6.10", t_theirs, ">= 1x"),
        Row(f"{case}, {grid} points, scheme interval", t_default, "path", 1, "toppra 0.6.10", t_theirs, ">= 1x"),
        # what a user gets by default: friction held and the grid refined until the 1 ms path is within
        # its limits (a harder problem than toppra's: shown, no target)
        Row(f"{case}, {grid} points, friction, refined", t_refined, "path", 1, "toppra 0.6.10", t_theirs, "-"),
    ]
    between = retiming.force_excess(frictionless, ours.reference(1e-3), box).max()
    default = retiming.retime(frictionless, reference, actuators=box, grid=grid).reference(1e-3)
    between_default = retiming.force_excess(frictionless, default, box).max()
    friction = retiming.retime(robot, reference, actuators=box, grid=grid).duration
    line = retiming.retime(robot, reference, actuators=limits(robot, line=True), grid=grid).duration
    text = (
        f"| {case} | {grid} | {theirs:.6f} | {ours.duration:.6f} | {ours.duration / theirs - 1:+.1e} "
        f"| {between:.2f} | {between_default:.2f} | {friction:.6f} | {line:.6f} |"
    )
    return rows, text


def run() -> None:
    try:
        import toppra  # noqa: F401
    except ImportError:
        print("\n### Retiming against toppra\n\ntoppra is not installed (pip install toppra): skipped.")
        return
    logging.getLogger("toppra").setLevel(logging.WARNING)
    robot = vgtarm.load_robot()
    frictionless = robot.with_parameters(dataclasses.replace(robot.parameters, viscous=(0.0,) * robot.n_joints))
    rows: list[Row] = []
    lines = [
        "| path | grid | toppra (s) | ours (s) | ours / toppra - 1 | excess at 1 ms (N) "
        "| excess at 1 ms, refined (N) | ours, friction exact (s) | ours, lines (s) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for case in CASES:
        reference = vgtarm.inverse_kinematics(robot, getattr(vgtarm.paths, case)())
        for grid in GRIDS:
            found, text = _compare(robot, frictionless, case, reference, grid)
            rows += found
            lines.append(text)
    print_table("Retiming: ours against toppra (same problem, friction-free, box limits)", rows)
    print("\n### Retiming: durations (s)\n")
    print("\n".join(lines))


main = run

if __name__ == "__main__":
    run()
