"""``vgtarm stiffness``: the tool's Cartesian stiffness and its deflection under a tool force
(:mod:`vgtarm.design.stiffness`), from the joints' stiffness of the robot file's ``[stiffness]`` table.

The arm's springs hold it about the commanded joints ``--q`` (default the home pose); the command
prints the translational stiffness of the tool point at rest under gravity (N/m, F0), its principal
stiffnesses and directions, and the deflection under ``--force`` (and ``--moment``): the exact one
(the equilibrium with the force minus the one without it, gravity on in both) and the linearised
one. ``--out DIR`` writes the same as ``stiffness.json``.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ... import checks
from ...errors import ConfigError, InputError, escape
from ...fileio import atomic_folder, atomic_write_text, check_output_folder
from ...model.robot import load_robot
from .options import add_config, number

#: The files ``vgtarm stiffness`` writes in its folder (and may replace there).
STIFFNESS_FILES = ("stiffness.json",)
#: The default tool force (N, F0): a 20 N thrust against a drill advancing along +z (the tool's
#: axis at the paper robot's home pose).
DEFAULT_FORCE = "0,0,-20"


def _triple(text: str) -> tuple[float, float, float]:
    """``FX,FY,FZ``: three finite numbers separated by commas (argparse's one line otherwise)."""
    parts = text.split(",")
    values: list[object] = []
    for part in parts:
        try:
            values.append(number(part.strip()))
        except (ValueError, argparse.ArgumentTypeError):
            values.append(part)
    triple = checks.vector("", values, 3, expected="three numbers X,Y,Z", error=argparse.ArgumentTypeError)
    return triple[0], triple[1], triple[2]


def add_parser(sub: Any) -> None:
    """Register ``vgtarm stiffness`` on the ``vgtarm`` command's subparsers."""
    parser = sub.add_parser(
        "stiffness",
        help="the tool's Cartesian stiffness and its deflection under a tool force (compliant joints)",
        description=(
            "With the joints' stiffness of the robot file's [stiffness] table (examples/paper_robot_compliant.toml), "
            "print the tool's translational stiffness at rest under gravity about the commanded joints --q, its "
            "principal directions, and the deflection under --force: exact (the equilibrium with the force minus "
            "the one without it) and linearised. See docs/stiffness.md."
        ),
    )
    parser.add_argument(
        "--q",
        nargs="+",
        default=["home"],
        metavar="Q",
        help="the commanded joints, one value per joint (m, rad), or 'home' (the default)",
    )
    parser.add_argument(
        "--force", type=_triple, default=_triple(DEFAULT_FORCE), metavar="FX,FY,FZ", help="tool force (N, F0; 0,0,-20)"
    )
    parser.add_argument(
        "--moment", type=_triple, default=(0.0, 0.0, 0.0), metavar="MX,MY,MZ", help="tool moment (N m, F0; none)"
    )
    parser.add_argument("--no-gravity", action="store_true", help="leave the bodies' weight out")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR", help="a folder to write stiffness.json in")
    add_config(parser)
    parser.set_defaults(run=cmd_stiffness)


def _joints(values: list[str], robot: Any) -> np.ndarray:
    """``--q``: ``home`` or one number per joint."""
    if values == ["home"]:
        return np.asarray(robot.parameters.home, dtype=float)
    if len(values) != robot.n_joints:
        raise InputError(
            f"--q {escape(' '.join(values))[:200]}: expected 'home' or {robot.n_joints} values "
            f"({', '.join(robot.joint_names[:8])}{', ...' if robot.n_joints > 8 else ''})"
        )
    q = []
    for name, text in zip(robot.joint_names, values, strict=True):
        try:
            q.append(number(text))
        except (ValueError, argparse.ArgumentTypeError):
            checks.refuse(f"--q ({name})", text, "a number (m, rad) or 'home' alone")
    return np.array(q)


def _vector(v: np.ndarray, scale: float = 1.0, digits: int = 6) -> str:
    return "(" + ", ".join(f"{x * scale + 0.0:.{digits}g}" for x in v) + ")"


def cmd_stiffness(args: argparse.Namespace) -> int:
    """Compute and print the stiffness and the deflection; write ``stiffness.json`` with ``--out``."""
    from ...design.stiffness import deflection

    inputs = [args.config]
    if args.out is not None:
        check_output_folder(args.out, "--out", inputs=inputs, owned=STIFFNESS_FILES)  # before the work
    robot = load_robot(args.config)
    if getattr(robot.parameters, "stiffness", None) is None:
        raise ConfigError(
            f"--config {escape(str(args.config or 'the reference robot'))}: the robot file has no [stiffness] table "
            "(one stiffness per joint, N/m and N m/rad: see docs/stiffness.md and examples/paper_robot_compliant.toml)"
        )
    q = _joints(args.q, robot)
    wrench = np.concatenate([args.force, args.moment])
    result = deflection(robot, q, wrench, gravity=not args.no_gravity)
    _print(robot, args, result)
    if args.out is not None:
        with atomic_folder(args.out, "--out", inputs=inputs, owned=STIFFNESS_FILES, checked=True) as folder:
            atomic_write_text(folder / "stiffness.json", json.dumps(_record(robot, result), indent=2) + "\n")
        print(f"written    {escape(str(args.out))}: {', '.join(STIFFNESS_FILES)}")
    return 0 if result.success else 1


def _print(robot: Any, args: argparse.Namespace, result: Any) -> None:
    s = result.stiffness
    joints = ", ".join(
        f"{n} {k:.4g} {'N m/rad' if n.startswith('psi') else 'N/m'}"
        for n, k in zip(robot.joint_names, robot.parameters.stiffness.values, strict=True)
    )
    print(f"robot      {escape(robot.parameters.name)}: {robot.n_joints} joints")
    print(f"joints     {joints}")
    print(f"q          {'home' if args.q == ['home'] else _vector(result.q_command)} (commanded: the springs' rest)")
    print(
        f"gravity    {'off' if args.no_gravity else 'on'}; tool wrench {_vector(result.wrench[:3])} N, "
        f"{_vector(result.wrench[3:])} N m (F0, at the tool point)"
    )
    print("stiffness  of the tool point at rest (N/m, F0):")
    matrix = s.translational_stiffness
    if matrix is None:
        print("           none: the tool point is rigid along some direction (see the principal stiffnesses)")
    else:
        for row in matrix:
            print("           " + "  ".join(f"{x:12.6g}" for x in row))
    print("principal  stiffness (N/m)   direction (F0)")
    for k, direction in zip(s.principal_stiffness, s.principal_directions.T, strict=True):
        print(f"           {k:<16.6g} {_vector(direction, digits=4)}")
    exact = np.linalg.norm(result.displacement)
    linear = np.linalg.norm(result.linear[:3])
    print(
        f"deflection exact   {_vector(result.displacement, 1e3)} mm, |d| = {exact * 1e3:.6g} mm; "
        f"rotation {_vector(result.rotation, 1e3)} mrad"
    )
    print(
        f"           linear  {_vector(result.linear[:3], 1e3)} mm, |d| = {linear * 1e3:.6g} mm; "
        f"rotation {_vector(result.linear[3:], 1e3)} mrad"
    )
    if not result.success:
        print(f"equilibrium not found: {result.unloaded.reason}; {result.loaded.reason}")


def _record(robot: Any, result: Any) -> dict[str, Any]:
    s = result.stiffness

    def listed(x: Any) -> Any:
        """An array as JSON: ``None`` for a missing matrix and for an infinite (rigid) stiffness."""
        if x is None:
            return None
        values = np.asarray(x, dtype=float)
        return [v if math.isfinite(v) else None for v in values.tolist()] if values.ndim == 1 else values.tolist()

    return {
        "robot": robot.parameters.name,
        "joint_names": list(robot.joint_names),
        "joint_stiffness": list(robot.parameters.stiffness.values),
        "q_command": result.q_command.tolist(),
        "wrench": result.wrench.tolist(),
        "q_unloaded": result.unloaded.q.tolist(),
        "q_loaded": result.loaded.q.tolist(),
        "success": bool(result.success),
        "displacement_m": result.displacement.tolist(),
        "rotation_rad": result.rotation.tolist(),
        "linear_displacement_m": result.linear[:3].tolist(),
        "linear_rotation_rad": result.linear[3:].tolist(),
        "translational_stiffness_N_per_m": listed(s.translational_stiffness),
        "compliance": s.compliance.tolist(),
        "principal_stiffness_N_per_m": listed(s.principal_stiffness),
        "principal_directions": s.principal_directions.tolist(),
    }
