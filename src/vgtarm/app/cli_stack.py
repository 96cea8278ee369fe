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

import numpy as np

from ..errors import cut, escape
from ..fileio import atomic_write_text, check_output_file
from ..model.parameters import load_parameters
from ..model.robot import Robot
from ..model.stack import Stack, stack_from_parameters, stack_to_toml


def _vector(values: object, digits: int = 6) -> str:
    return "[" + ", ".join(f"{float(v):.{digits}g}" for v in values) + "]"  # type: ignore[attr-defined]


def describe_stack(robot: Robot) -> int:
    """``vgtarm describe`` of a stack: modules, joints, bodies, tip and reach at home, mass matrix."""
    stack = robot.parameters
    assert isinstance(stack, Stack)
    home = stack.home
    tip = robot.tip_position(home)
    eigenvalues = np.linalg.eigvalsh(robot.mass_matrix(home))
    print(f"robot      {escape(stack.name)}")  # a name from a user's file never drives the terminal
    print(f"source     {escape(stack.source)}")
    print(
        f"model      {robot.backend.kind} CasADi functions, a stack of {stack.n_modules} modules, "
        f"{stack.n_joints} joints"
    )
    for k, module in enumerate(stack.modules, start=1):
        twist = "" if module.twist is None else f", then twist psi{k + 1} (height {module.twist.height:g} m)"
        print(f"module {k:<3} b = {module.b:g} m, d = {module.d:g} m, plane {module.plane:g} deg{twist}")
    print("joints     name   min        max        home")
    for i, name in enumerate(stack.joint_names):
        print(
            f"           {name:<6} {stack.q_min[i]:<10.6g} {stack.q_max[i]:<10.6g} {home[i]:.10g} "
            f"{stack.joint_units[i]}"
        )
    for name, body in zip(stack.body_names, stack.bodies, strict=True):
        print(f"body       {name:<13} mass {body.mass:g} kg, com {_vector(body.com)} m")
    print(f"tool       {_vector(stack.tool)} m from the last mount point")
    print(f"friction   {_vector(stack.viscous)} (N s/m legs; N m s/rad twists)")
    print(f"gravity    {_vector(stack.gravity)} m/s^2")
    print(f"tip @ home {_vector(tip, 10)} m; reach {float(np.linalg.norm(tip)):.6g} m")
    print(f"M @ home   eigenvalues {_vector(eigenvalues, 5)} (kg, kg m^2)")
    return 0


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
