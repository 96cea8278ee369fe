"""The command line's flags of a tool-axis task, one parser for every command that takes them:
``--axis X,Y,Z``, ``--cone DEG`` and ``--entry-point X,Y,Z`` (``vgtarm ik``, ``vgtarm retime``,
``vgtarm check path``), and the comma-separated numbers they are written as."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from ... import checks
from ...errors import InputError

#: The flags of a tool-axis task, in the order of :func:`vgtarm.ik.axis.tool_task_keywords`'s names.
FLAGS = ("--axis", "--cone", "--entry-point")


def numbers(text: str, field: str, count: int, meaning: str) -> np.ndarray:
    """``count`` comma-separated finite numbers of the option ``field``, or one line naming it."""
    return checks.comma_numbers(field, text, count, meaning)


def ik_pointing(args: argparse.Namespace) -> dict[str, Any]:
    """``--axis`` (a unit vector), ``--cone`` (degrees) and ``--entry-point`` (a point): the keywords of
    the tool-axis tasks (:func:`vgtarm.ik.axis.tool_task_keywords`, naming the flags); with ``--pose``
    refused too."""
    from ...ik.axis import tool_task_keywords

    out = tool_task_keywords(args.axis, args.cone, args.entry_point, names=FLAGS)
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
