"""``vgtarm retime``: the fastest timing of a path under the robot's actuators (:func:`vgtarm.retime`).

The path (a case's, or a CSV of ``t,x,y,z`` rows) is solved by the inverse kinematics, its joint
path retimed under the actuators of the robot file's ``[actuators]`` table, friction held exactly,
from rest to rest; the folder ``--out`` gets the retimed tip path as ``path.csv`` (``t,x,y,z``,
what ``vgtarm simulate --path`` and ``vgtarm ik --path`` take), the retimed joint reference as
``joints.csv`` (``t``, then ``q``, ``qd`` and ``qdd`` of each joint) and the phase-plane figure
``phase_plane.png``.
"""

from __future__ import annotations

import argparse
import io
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ConfigError, escape
from ...fileio import atomic_folder, atomic_write_text, check_output_folder
from ...model.robot import load_robot
from ...retiming import DEFAULT_GRID, MAX_GRID, retime
from .options import add_config, positive_float, positive_int
from .tool_flags import add_tool_task, tool_task

#: The files ``vgtarm retime`` writes in its folder (and may replace there).
RETIME_FILES = ("path.csv", "joints.csv", "phase_plane.png")


def add_parser(sub: Any) -> None:
    """Register ``vgtarm retime`` on the ``vgtarm`` command's subparsers."""
    parser = sub.add_parser(
        "retime",
        help="the fastest timing of a path under the robot's actuators (friction exact), rest to rest",
        description=(
            "Solve the path's inverse kinematics, then time its joint path as fast as the actuators of the "
            "robot file's [actuators] table allow (peak forces, force-speed lines, speeds, accelerations), "
            "viscous friction held exactly; write the retimed tip path (path.csv, for vgtarm simulate --path), "
            "the joint reference (joints.csv) and the phase plane (phase_plane.png). With --axis or --entry-point "
            "the joint path is that of the tool-axis task (vgtarm ik's flags)."
        ),
    )
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--case", choices=("1", "2"), help="the paper's case study path 1 or 2")
    where.add_argument("--path", type=Path, metavar="FILE", help="a CSV file of t,x,y,z rows (s, m)")
    add_tool_task(parser)
    parser.add_argument(
        "--grid", type=positive_int, default=DEFAULT_GRID, help=f"grid points of the path (default {DEFAULT_GRID})"
    )
    parser.add_argument(
        "--tool-force", type=positive_float, default=None, metavar="N", help="a tool force against the motion (N)"
    )
    parser.add_argument("--dt", type=positive_float, default=None, metavar="DT", help="period of the outputs (s)")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to write")
    add_config(parser)
    parser.set_defaults(run=cmd_retime)


def cmd_retime(args: argparse.Namespace) -> int:
    """Retime the path, print the timing and each joint's use of its limits, write the folder."""
    from ... import paths

    if args.grid > MAX_GRID:
        raise ConfigError(f"--grid {args.grid}: expected at most {MAX_GRID:,} grid points")
    inputs = [args.config, args.path]
    check_output_folder(args.out, "--out", inputs=inputs, owned=RETIME_FILES)  # before the work
    robot = load_robot(args.config)
    if robot.actuators is None:
        raise ConfigError(
            f"--config {escape(str(args.config or 'the reference robot'))}: the robot file has no [actuators] table "
            "(peak force and no-load speed per joint: see docs/actuators.md and "
            "examples/paper_robot_with_actuators.toml)"
        )
    path = paths.from_csv(args.path) if args.path is not None else getattr(paths, f"case{args.case}")()
    ik = robot.inverse_kinematics(path, **tool_task(args, path))
    timed = retime(robot, ik, grid=args.grid, tool_force=args.tool_force or 0.0, dt=args.dt)
    reference = timed.reference()
    print(f"path       {escape(path.name)}: {len(path)} samples over {path.t[-1] - path.t[0]:.6g} s as given")
    print(f"retimed    {timed.duration:.6g} s on {args.grid} grid points (friction held, rest to rest)")
    F = robot.inverse_dynamics(reference.q, reference.qd, reference.qdd)
    use = robot.actuators.utilisation(F, reference.qd)
    speed = np.abs(reference.qd) / robot.actuators.speed
    print("joint      peak force use   peak speed use")
    for i, name in enumerate(robot.joint_names):
        if robot.actuators.limited[i]:
            print(f"           {name:<6} {use[:, i].max():<16.3f} {speed[:, i].max():.3f}")
    with atomic_folder(args.out, "--out", inputs=inputs, owned=RETIME_FILES, checked=True) as folder:
        atomic_write_text(folder / "path.csv", _tip_csv(reference.t, robot.tip_position(reference.q)))
        atomic_write_text(folder / "joints.csv", _joints_csv(robot.joint_names, reference))
        timed.figure().savefig(folder / "phase_plane.png", dpi=110)
    print(f"written    {escape(str(args.out))}: {', '.join(RETIME_FILES)}")
    return 0


def _tip_csv(t: np.ndarray, tip: np.ndarray) -> str:
    stream = io.StringIO()
    stream.write("t,x,y,z\n")
    np.savetxt(stream, np.column_stack([t, tip]), delimiter=",", fmt="%.17g")
    return stream.getvalue()


def _joints_csv(names: tuple[str, ...], reference: Any) -> str:
    header = ["t", *names, *(f"{n}_d" for n in names), *(f"{n}_dd" for n in names)]
    stream = io.StringIO()
    stream.write(",".join(header) + "\n")
    table = np.column_stack([reference.t, reference.q, reference.qd, reference.qdd])
    np.savetxt(stream, table, delimiter=",", fmt="%.17g")
    return stream.getvalue()
