"""The command line's flags of a tool-axis task, one parser for every command that takes them:
``--axis X,Y,Z``, ``--cone DEG`` and ``--entry-point X,Y,Z`` (``vgtarm ik``, ``vgtarm retime``,
``vgtarm check path``), and the comma-separated numbers they are written as."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from ...errors import InputError, shown


def numbers(text: str, field: str, count: int, meaning: str) -> np.ndarray:
    """``count`` comma-separated finite numbers of the option ``field``, or one line naming it."""
    cells = text.split(",")
    try:
        values = np.array([float(cell) for cell in cells])
    except ValueError:
        values = np.array([np.nan])
    if values.shape != (count,) or not np.isfinite(values).all():
        raise InputError(f"{field} {shown(text)}: expected {count} finite numbers separated by commas ({meaning})")
    return values


def ik_pointing(args: argparse.Namespace) -> dict[str, Any]:
    """``--axis`` (a unit vector) and ``--entry-point`` (a point): the keywords of the tool-axis tasks."""
    from ...ik.axis import unit_directions

    out: dict[str, Any] = {}
    if args.axis is not None:
        values = numbers(args.axis, "--axis", 3, "the direction of the tool's axis x,y,z, a unit vector")
        out["axis"] = unit_directions(values, 1, "--axis")[0]
    if args.entry_point is not None:
        out["entry_point"] = numbers(args.entry_point, "--entry-point", 3, "the entry point x,y,z in m")
    if args.cone is not None:
        if args.axis is None:
            raise InputError(f"--cone {shown(args.cone)}: a cone needs its axis, --axis X,Y,Z")
        degrees = numbers(args.cone, "--cone", 1, "the cone's half-angle in degrees, in (0, 90)")[0]
        if not 0.0 < degrees < 90.0:
            raise InputError(f"--cone {shown(args.cone)}: expected a half-angle in (0, 90) degrees")
        out["cone"] = float(np.radians(degrees))
    given = [
        flag for flag, on in (("--pose", args.pose), ("--axis", args.axis), ("--entry-point", args.entry_point)) if on
    ]
    if len(given) > 1:
        raise InputError(f"{' and '.join(given)}: expected one of --pose, --axis and --entry-point")
    return out


def add_tool_task(parser: argparse.ArgumentParser) -> None:
    """``--axis``, ``--cone`` and ``--entry-point``: a tool-axis task instead of the tip alone, as
    ``vgtarm ik`` takes them (``vgtarm retime``, ``vgtarm check path``)."""
    parser.add_argument(
        "--axis", default=None, metavar="X,Y,Z", help="the tool's axis held along this unit vector, its spin free"
    )
    parser.add_argument("--cone", default=None, metavar="DEG", help="with --axis: the axis within this half-angle")
    parser.add_argument(
        "--entry-point", default=None, metavar="X,Y,Z", help="the tool's axis through this point (m): keyhole work"
    )


def tool_task(args: argparse.Namespace, path: Any) -> dict[str, Any]:
    """The keywords of the tool-axis task of ``--axis``, ``--cone`` and ``--entry-point`` for ``path``,
    refused as ``vgtarm ik`` refuses them (the same checks, naming the flag); none: the tip alone."""
    from ...ik.axis import entry_point_target

    pointing = ik_pointing(argparse.Namespace(axis=args.axis, entry_point=args.entry_point, cone=args.cone, pose=None))
    if "entry_point" in pointing:
        entry_point_target(pointing["entry_point"], path.position, path.velocity, path.acceleration, "--entry-point")
    return pointing
