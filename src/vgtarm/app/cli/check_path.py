"""``vgtarm check path``: a case's or a path file's joint reference checked against the robot's
actuator limits (:func:`vgtarm.simulation.limits_check.check_path`), before any run.

Exit status: 0 when the reference stays within every limit, 1 when a limit is exceeded, 2 for bad
input or an error (one line ``vgtarm: error: ...`` on standard error), so that a script can tell a
verdict from a failure.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ... import checks, paths
from ...errors import MESSAGE_LENGTH, InputError, VgtarmError, cut, escape, shown
from ...fileio import atomic_folder, atomic_write_text, check_output_file, check_output_folder, placements
from ...model.robot import Robot, load_robot
from ...simulation.limits_check import PathCheck, check_path
from ...simulation.reference import JointReference
from .bars import progress_bar
from .options import add_config
from .tool_flags import add_tool_task, tool_task

#: Exit status of a reference within every limit, of one that exceeds a limit, and of bad input.
WITHIN, EXCEEDED, BAD_INPUT = 0, 1, 2
#: The files ``--out`` writes (and the only ones it replaces in a folder it wrote before).
TABLE_FILE, CSV_FILE, FIGURE_FILE = "path_check.txt", "path_check.csv", "path_check.png"
OUT_FILES = (TABLE_FILE, CSV_FILE, FIGURE_FILE)
#: Where the ``[actuators]`` table is described (the refusal of a robot without one says so).
ACTUATORS_DOC = "docs/actuators.md"
_CASES = {"1": 1, "2": 2, "case1": 1, "case2": 2}


def _case(args: argparse.Namespace) -> int | None:
    """The case number of ``--case`` (None: the path file), refused unless exactly one is given."""
    if (args.case is None) == (args.path is None):
        raise InputError("give exactly one of --case case1|case2 and a path file PATH.csv")
    if args.case is None:
        return None
    if args.case not in _CASES:
        checks.refuse("--case", args.case, "case1 or case2 (or 1, 2)")
    return _CASES[args.case]


def _tool_force(text: str) -> float:
    """``--tool-force``: a finite number >= 0 of newtons, written in ASCII, else one line."""
    value: object = text
    if text.isascii():
        try:
            value = float(text)
        except ValueError:
            pass
    return checks.number("--tool-force", value, minimum=0, unit="N", expected="a finite number >= 0 (N)")


def _check_outputs(args: argparse.Namespace) -> None:
    """Refuse, before any work, outputs that cannot be written or would destroy an input."""
    inputs = [args.config, args.path]
    if args.out is not None and (args.figure is not None or args.csv is not None):
        raise InputError("--out FOLDER writes the table, the CSV and the figure: give it, or --figure/--csv, not both")
    if args.out is not None:
        check_output_folder(args.out, "--out", inputs=inputs, owned=OUT_FILES)
    if args.figure is not None:
        from matplotlib.figure import Figure

        check_output_file(args.figure, "--figure", inputs=inputs)
        suffix = args.figure.suffix.lower().lstrip(".")
        supported = sorted(Figure().canvas.get_supported_filetypes())
        if suffix not in supported:
            checks.refuse("--figure", str(args.figure), f"a file name ending in one of .{', .'.join(supported)}")
    if args.csv is not None:
        check_output_file(args.csv, "--csv", inputs=inputs)
        if args.figure is not None and args.figure.resolve() == args.csv.resolve():
            raise InputError(f"--csv {shown(str(args.csv))}: is also --figure; give two files")


def _robot(config: Path | None) -> Robot:
    """The robot of ``--config``, refused in one line unless its file has an ``[actuators]`` table."""
    robot = load_robot(config)
    if robot.actuators is None:
        where = (
            "the reference robot (no --config)"
            if config is None
            else f"--config {cut(str(config), 200)}: the robot file"
        )
        raise InputError(
            f"{where} has no [actuators] table, so there are no limits to check; add one "
            f"(how to write it: {ACTUATORS_DOC}, 'Actuators and path limits')"
        )
    return robot


def _reference(args: argparse.Namespace, robot: Robot, number: int | None) -> JointReference:
    """The joint reference of ``--case`` (as ``vgtarm simulate --case``) or of the path file; with
    ``--axis``, ``--cone`` or ``--entry-point``, that of the tool-axis task (as ``vgtarm ik``)."""
    if number is not None and args.axis is None and args.entry_point is None and args.cone is None:
        from ...experiment.cases import joint_reference

        with progress_bar("inverse kinematics", "sample"):
            return joint_reference(robot, number)
    desired = paths.from_csv(args.path) if number is None else getattr(paths, f"case{number}")()
    task = tool_task(args, desired)
    with progress_bar("inverse kinematics", "sample", len(desired)):
        return JointReference.of(robot.inverse_kinematics(desired, **task), desired.name)


def _write(args: argparse.Namespace, check: PathCheck, table: str) -> None:
    """Write what was asked: the folder of ``--out``, or ``--figure`` and ``--csv``; say where."""
    from ..pictures.plotting import save_figure

    if args.out is not None:
        with (
            placements() as moved,
            atomic_folder(args.out, "--out", inputs=[args.config, args.path], owned=OUT_FILES, checked=True) as out,
        ):
            atomic_write_text(out / TABLE_FILE, table)
            check.to_csv(out / CSV_FILE)
            save_figure(check.figure(), out / FIGURE_FILE)
        print(f"written     {escape(str(moved.get(args.out, args.out)))} ({', '.join(OUT_FILES)})")
        return
    if args.csv is not None:
        check.to_csv(args.csv)
        print(f"csv         {escape(str(args.csv))}")
    if args.figure is not None:
        save_figure(check.figure(), args.figure)
        print(f"figure      {escape(str(args.figure))}")


def _run(args: argparse.Namespace) -> int:
    """``vgtarm check path`` once its arguments are read: check, print, write, give the verdict."""
    number = _case(args)
    force = _tool_force(args.tool_force)
    _check_outputs(args)
    robot = _robot(args.config)
    reference = _reference(args, robot, number)
    check = check_path(robot, reference, tool_force=force)
    table = check.table()
    print(table, end="")
    _write(args, check, table)
    return WITHIN if check.ok else EXCEEDED


def cmd_check_path(args: argparse.Namespace) -> int:
    """``vgtarm check path``: exit 0 within the limits, 1 beyond one, 2 for bad input (one line)."""
    try:
        return _run(args)
    except BrokenPipeError:  # the reader of standard output went away: the command line's own rule
        raise
    except (VgtarmError, OSError) as exc:
        print(f"vgtarm: error: {cut(str(exc), MESSAGE_LENGTH - 60)}", file=sys.stderr)
        return BAD_INPUT


def add_parser(kinds: Any) -> None:
    """Register ``path`` on the subcommands of ``vgtarm check``."""

    parser = kinds.add_parser(
        "path",
        help="a case's or a path file's joint reference against the robot's actuator limits",
        description=(
            "Check the joint reference of --case or of PATH.csv (the inverse kinematics of simulate and ik) "
            "against the actuators of the robot file's [actuators] table: each joint's effort (inverse "
            "dynamics with friction and the expected tool force) against its force bounds at its velocity, "
            "its velocity against its no-load speed, its acceleration against its limit. Prints a table. "
            f"Exit status: {WITHIN} within every limit, {EXCEEDED} when a limit is exceeded, "
            f"{BAD_INPUT} for bad input or an error."
        ),
    )
    parser.add_argument(
        "path", nargs="?", type=Path, default=None, metavar="PATH.csv", help="a desired tip path (t,x,y,z)"
    )
    parser.add_argument("--case", default=None, metavar="case1|case2", help="one of the paper's case paths")
    parser.add_argument(
        "--tool-force",
        default="0",
        metavar="N",
        help="the tool force against the tip's motion (N; the paper's cutting force is 20; default 0: none)",
    )
    add_tool_task(parser)
    parser.add_argument("--out", type=Path, default=None, metavar="FOLDER", help=f"write {', '.join(OUT_FILES)}")
    parser.add_argument("--figure", type=Path, default=None, metavar="FILE", help="write the figure (png, pdf, svg)")
    parser.add_argument("--csv", type=Path, default=None, metavar="FILE", help="write the arrays as CSV")
    add_config(parser)
    parser.set_defaults(run=cmd_check_path)
