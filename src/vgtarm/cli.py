"""The ``vgtarm`` command line.

Every user error (bad file, bad number, unreachable path, diverged run) prints one line
``vgtarm: error: ...`` on standard error and exits with status 1 (2 for bad usage).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from . import __version__
from .errors import VgtarmError
from .parameters import JOINT_NAMES, JOINT_UNITS
from .robot import load_robot


def _format_vector(values: Sequence[float] | np.ndarray, digits: int = 6) -> str:
    return "[" + ", ".join(f"{v:.{digits}g}" for v in values) + "]"


def cmd_describe(args: argparse.Namespace) -> int:
    """Print the robot: dimensions, limits, home pose, tip at home, mass-matrix eigenvalues."""
    robot = load_robot(args.config)
    p = robot.parameters
    home = p.home
    fk = robot.forward_kinematics(home)
    eigenvalues = np.linalg.eigvalsh(robot.mass_matrix(home))
    print(f"robot      {p.name}")
    print(f"source     {p.source}")
    print(f"model      {robot.backend.kind} CasADi functions")
    for k, module in enumerate(p.modules, start=1):
        print(f"module {k}   b = {module.b:g} m, d = {module.d:g} m")
    print(f"twist part h1 = {p.h1:g} m")
    print("joints     name   min        max        home")
    for i, name in enumerate(JOINT_NAMES):
        unit = JOINT_UNITS[i]
        print(f"           {name:<6} {p.q_min[i]:<10.6g} {p.q_max[i]:<10.6g} {home[i]:.10g} {unit}")
    for body in p.bodies:
        print(f"body       {body.name:<13} mass {body.mass:g} kg, com {_format_vector(body.com)} m")
    print(f"friction   {_format_vector(p.viscous)} (N s/m; N m s/rad for psi3)")
    print(f"gravity    {_format_vector(p.gravity)} m/s^2")
    print(f"tip @ home {_format_vector(fk.tip, 10)} m")
    print(f"M @ home   eigenvalues {_format_vector(eigenvalues, 5)} (kg, kg m^2)")
    return 0


def cmd_fk(args: argparse.Namespace) -> int:
    """Print passive angles, platform centres, tip position and orientation of one configuration."""
    robot = load_robot(args.config)
    q = np.array(args.q, dtype=float)
    fk = robot.forward_kinematics(q)
    print("q          " + ", ".join(f"{n} = {v:.10g} {u}" for n, v, u in zip(JOINT_NAMES, q, JOINT_UNITS, strict=True)))
    for k in range(2):
        alpha, beta, gamma, theta = fk.passive[k]
        print(f"module {k + 1}   alpha = {alpha:.8f}, beta = {beta:.8f}, gamma = {gamma:.8f}, theta = {theta:.8f} rad")
        print(f"           platform centre O{k + 1} = {_format_vector(fk.platform_position[k], 10)} m")
    print(f"tip        {_format_vector(fk.tip, 10)} m")
    print("rotation   C03 =")
    for row in fk.rotation:
        print("           " + _format_vector(row, 10))
    return 0


def _add_config(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        metavar="FILE",
        help="robot TOML file (default: the shipped reference robot)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="vgtarm",
        description="Model, plan and control the 7-DOF redundant hybrid VGT manipulator.",
    )
    parser.add_argument("--version", action="version", version=f"vgtarm {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    describe = sub.add_parser("describe", help="print the robot and its model at the home pose")
    _add_config(describe)
    describe.set_defaults(run=cmd_describe)

    fk = sub.add_parser("fk", help="forward kinematics of one configuration")
    fk.add_argument(
        "q", nargs=7, type=float, metavar="Q", help=f"joint values in the order {' '.join(JOINT_NAMES)} (m, rad)"
    )
    _add_config(fk)
    fk.set_defaults(run=cmd_fk)

    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``vgtarm`` command."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args))
    except VgtarmError as exc:
        print(f"vgtarm: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"vgtarm: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("vgtarm: interrupted", file=sys.stderr)
        return 130
