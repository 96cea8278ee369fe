"""``vgtarm convert-robot``: write a robot file in the stack format.

Registered in :func:`vgtarm.app.cli.build_parser` by :func:`add_parsers`. The stack format
(``vgtarm.model.stack``) describes any stack of VGT modules; this command turns a robot file of
the fixed 7-joint format (default: the shipped reference robot) into it, value for value, so the
stack's model gives the fixed model's numbers (see ``docs/modelling.md``, "Stacks of modules").
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..errors import cut
from ..fileio import atomic_write_text, check_output_file
from ..model.parameters import load_parameters
from ..model.stack import stack_from_parameters, stack_to_toml


def cmd_convert_robot(args: argparse.Namespace) -> int:
    """Convert a 7-joint robot file into a stack file."""
    check_output_file(args.out, "--out", inputs=[args.config])
    parameters = load_parameters(args.config)
    stack = stack_from_parameters(parameters)
    origin = "the shipped reference robot" if args.config is None else cut(str(args.config), 200)
    header = (
        f"Written by `vgtarm convert-robot` from {origin}.\n"
        "A stack of VGT modules (see docs/modelling.md, 'Stacks of modules'); units SI, plane angles in degrees.\n"
        f"Joints: {' '.join(stack.joint_names)}."
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, stack_to_toml(stack, header=header))
    print(f"stack of {stack.n_modules} modules and {stack.n_twists} twist joint written to {args.out}")
    return 0


def add_parsers(sub: Any) -> None:
    """Add ``convert-robot`` to the subparsers ``sub``."""
    convert = sub.add_parser("convert-robot", help="write a robot file as a stack of VGT modules")
    convert.add_argument(
        "--config", type=Path, default=None, metavar="FILE", help="robot TOML file (default: the reference robot)"
    )
    convert.add_argument("--out", type=Path, required=True, metavar="FILE", help="stack TOML file to write")
    convert.set_defaults(run=cmd_convert_robot)
