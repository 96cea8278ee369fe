"""``vgtarm export mjcf``, ``vgtarm export controller`` and ``vgtarm check mujoco``: the MuJoCo bridge
and the exported controller from the command line (``vgtarm check path``: :mod:`.check_path`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ...errors import escape
from ...export import command as export_command
from ...fileio import atomic_write_text, check_output_file
from ...model.robot import load_robot
from . import check_path
from . import drill as cli_drill
from .options import add_config, positive_float, positive_int, seed_number, whole_number


def digits(text: str) -> int:
    """``--digits``: a whole number of significant digits the export may write."""
    from ...mujoco_bridge.export import MAX_DIGITS, MIN_DIGITS

    value = whole_number(text)
    if not MIN_DIGITS <= value <= MAX_DIGITS:
        raise argparse.ArgumentTypeError(f"expected a whole number from {MIN_DIGITS} to {MAX_DIGITS}, got {text}")
    return value


def add_digits(parser: argparse.ArgumentParser) -> None:
    from ...mujoco_bridge.export import DIGITS, MAX_DIGITS

    parser.add_argument(
        "--digits",
        type=digits,
        default=DIGITS,
        metavar="N",
        help=f"significant digits of the numbers in the MJCF (default {DIGITS}; {MAX_DIGITS}: every number as it is)",
    )


def cmd_export(args: argparse.Namespace) -> int:
    """Write the robot as MJCF."""
    from ...mujoco_bridge.export import to_mjcf

    check_output_file(args.out, "--out", inputs=[args.config])
    robot = load_robot(args.config)
    text = to_mjcf(robot, timestep=args.timestep, digits=args.digits)
    if args.validate:
        from ...mujoco_bridge.model import require_mujoco

        require_mujoco().MjModel.from_xml_string(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, text + "\n")
    print(f"MJCF of {robot.parameters.name!r} written to {escape(str(args.out))}")
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    """Compare our dynamics with MuJoCo's on random states and print the worst differences."""
    from ...mujoco_bridge.check import cross_validate, table
    from ...mujoco_bridge.model import require_mujoco

    require_mujoco()
    robot = load_robot(args.config)
    print(table(cross_validate(robot, n=args.states, seed=args.seed, digits=args.digits)))
    return 0


def add_parsers(sub: Any) -> None:
    """Register ``export`` and ``check`` on the ``vgtarm`` command's subparsers."""
    export = sub.add_parser("export", help="export the robot or its controller for another engine or a target")
    formats = export.add_subparsers(dest="format", required=True, metavar="FORMAT")
    mjcf = formats.add_parser("mjcf", help="the robot in MuJoCo's XML model format, as a scene (needs vgtarm[mujoco])")
    mjcf.add_argument("--out", type=Path, required=True, metavar="FILE", help="the file to write (robot.xml)")
    mjcf.add_argument("--timestep", type=positive_float, default=1e-3, metavar="DT", help="MuJoCo's time step (s)")
    mjcf.add_argument("--validate", action="store_true", help="load the result in MuJoCo before writing")
    add_digits(mjcf)
    add_config(mjcf)
    mjcf.set_defaults(run=cmd_export)
    controller = formats.add_parser(
        "controller", help="computed force control (with the observer) as dependency-free C99 for a real-time target"
    )
    export_command.add_arguments(controller)
    controller.set_defaults(run=export_command.run)
    cli_drill.add_export_parser(formats)

    check_parser = sub.add_parser(
        "check", help="check the robot: our dynamics against MuJoCo's, or a path against its actuator limits"
    )
    kinds = check_parser.add_subparsers(dest="engine", required=True, metavar="WHAT")
    check = kinds.add_parser("mujoco", help="our dynamics against the exported model stepped by MuJoCo")
    check.add_argument("--states", type=positive_int, default=1000, help="random states (default 1000)")
    check.add_argument("--seed", type=seed_number, default=0, help="seed of the states (default 0; 0 to 2**63 - 1)")
    add_digits(check)
    add_config(check)
    check.set_defaults(run=cmd_check)
    check_path.add_parser(kinds)
