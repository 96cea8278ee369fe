"""``vgtarm workspace``: the reachable and dexterous workspace of a robot file and its dexterity at home.

The folder ``--out`` gets ``summary.json`` (the volumes, the Monte Carlo check of each, the
dexterity measures at home), ``slices.png`` (the boundary of both workspaces at six heights),
``workspace_3d.png`` (their boundary surfaces), ``slices.csv`` (``set,z,loop,x,y`` rows, m) and
``workspace.html`` (one self-contained page: the summary and an interactive 3-D figure of both
workspaces, :mod:`vgtarm.app.reports.workspace_page`). The numbers are printed too. Methods: docs/workspace.md.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ConfigError, escape
from ...fileio import atomic_folder, atomic_write_text, check_output_folder
from ...model.robot import load_robot
from .options import add_config, positive_float, positive_int_at_most, seed_number

#: The files ``vgtarm workspace`` writes in its folder (and may replace there).
WORKSPACE_FILES = ("summary.json", "slices.png", "workspace_3d.png", "slices.csv", "workspace.html")
#: Default Monte Carlo samples of the check (``--samples``).
DEFAULT_SAMPLES = 20_000


def _cone(text: str) -> float:
    """``--cone DEG``: a half-angle in (0, 180] degrees."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a half-angle in (0, 180] (deg), got {text!r}") from None
    if not 0.0 < value <= 180.0:
        raise argparse.ArgumentTypeError(f"expected a half-angle in (0, 180] (deg), got {text!r}")
    return value


def _axis(text: str) -> tuple[float, float, float]:
    """``--axis X,Y,Z``: a nonzero direction."""
    parts = text.split(",")
    try:
        values = tuple(float(part) for part in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(np.isfinite(values)) or not np.linalg.norm(values) > 1e-12:
        raise argparse.ArgumentTypeError(f"expected a nonzero direction X,Y,Z (3 finite numbers), got {text!r}")
    return (values[0], values[1], values[2])


def _samples(text: str) -> int:
    """``--samples N``: Monte Carlo samples, at least the minimum (0 skips the check)."""
    from ...design.workspace import MAX_POINTS, MIN_SAMPLES

    try:
        value = int(text)
    except ValueError:
        value = -1
    if value != 0 and not MIN_SAMPLES <= value <= MAX_POINTS:
        raise argparse.ArgumentTypeError(
            f"expected 0 (no check) or a whole number from {MIN_SAMPLES:,} to {MAX_POINTS:,}, got {text!r}"
        )
    return value


def add_parser(sub: Any) -> None:
    """Register ``vgtarm workspace`` on the ``vgtarm`` command's subparsers."""
    from ...design.workspace import DEFAULT_CONE

    parser = sub.add_parser(
        "workspace",
        help="the reachable and dexterous workspace (volumes, slices, 3-D figure) and the dexterity at home",
        description=(
            "Compute the volume of the tool tip's reachable workspace (joint limits and assembly) and of its "
            "dexterous workspace (the tool axis within --cone degrees of --axis) by grown voxels, check each "
            "against a Monte Carlo estimate of --samples points, trace their boundaries at six heights and "
            "evaluate the manipulability, condition number and flat-truss distances at home; write "
            "summary.json, slices.png, workspace_3d.png, slices.csv and the page workspace.html."
        ),
    )
    parser.add_argument(
        "--cone", type=_cone, default=DEFAULT_CONE, metavar="DEG", help=f"half-angle (default {DEFAULT_CONE:g})"
    )
    parser.add_argument("--axis", type=_axis, default=(0.0, 0.0, 1.0), metavar="X,Y,Z", help="cone axis (default +z)")
    parser.add_argument(
        "--samples",
        type=_samples,
        default=DEFAULT_SAMPLES,
        metavar="N",
        help=f"Monte Carlo samples of the check (default {DEFAULT_SAMPLES:,}; 0: no check)",
    )
    parser.add_argument(
        "--voxel", type=positive_float, default=None, metavar="M", help="voxel edge (m; default 1/40 of the box)"
    )
    parser.add_argument(
        "--grid",
        type=positive_int_at_most(2000, "points per side"),
        default=48,
        metavar="N",
        help="points per side of each slice's grid (default 48)",
    )
    parser.add_argument("--seed", type=seed_number, default=0, metavar="S", help="seed of every sample (default 0)")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to write")
    add_config(parser)
    parser.set_defaults(run=cmd_workspace)


def _analyse(robot: Any, args: argparse.Namespace) -> dict[str, Any]:
    """The volumes, checks and slices of both workspaces, by set name."""
    from ...design import workspace as ws

    found: dict[str, Any] = {"volumes": {}, "checks": {}, "slices": {}}
    for name, angle in (("reachable", 180.0), ("dexterous", args.cone)):
        test = ws.ReachTest(robot, cone=angle, axis=args.axis, seed=args.seed)
        volume = ws.workspace_volume(robot, test=test, seed=args.seed, voxel=args.voxel)
        found["volumes"][name] = volume
        if args.samples:
            found["checks"][name] = ws.monte_carlo_volume(robot, args.samples, args.seed, test=test)
        heights = ws.default_heights(volume.lower, volume.upper)
        found["slices"][name] = ws.workspace_slices(test, heights, volume.lower, volume.upper, resolution=args.grid)
    return found


def _summary(robot: Any, found: dict[str, Any], cone: float, axis: Any, seed: int) -> dict[str, Any]:
    """The summary as plain data (SI units)."""
    from ...design.measures import dexterity

    home = dexterity(robot, robot.parameters.home)
    sets: dict[str, Any] = {}
    for name, volume in found["volumes"].items():
        entry: dict[str, Any] = {
            "volume_m3": volume.volume,
            "cone_deg": volume.cone,
            "axis": volume.axis.tolist(),
            "voxel_m": volume.voxel,
            "membership_tests": volume.tests,
            "seconds": volume.seconds,
            "bounding_box_m": [volume.lower.tolist(), volume.upper.tolist()],
            "slices": [{"z_m": s.z, "area_m2": s.area, "loops": len(s.loops)} for s in found["slices"][name]],
        }
        check = found["checks"].get(name)
        if check is not None:
            entry["monte_carlo"] = {
                "volume_m3": check.volume,
                "standard_error_m3": check.standard_error,
                "samples": check.samples,
                "seed": check.seed,
                "relative_difference": (volume.volume - check.volume) / check.volume if check.volume else None,
            }
        sets[name] = entry
    return {
        "robot": robot.parameters.name,
        "joints": robot.n_joints,
        "seed": seed,
        "cone_deg": cone,
        "axis": list(axis),
        "workspaces": sets,
        "home": {
            "q": home.q[0].tolist(),
            "manipulability": float(home.manipulability[0]),
            "condition_number": float(home.condition[0]),
            "module_distance": dict(zip(home.module_names, home.module_distance[0].tolist(), strict=True)),
        },
    }


def cmd_workspace(args: argparse.Namespace) -> int:
    """Analyse the workspace, print the numbers, write the folder."""
    from ...design import workspace as ws
    from ..reports.workspace_page import workspace_html

    inputs = [args.config]
    check_output_folder(args.out, "--out", inputs=inputs, owned=WORKSPACE_FILES)  # before the work
    robot = load_robot(args.config)
    started = time.perf_counter()
    try:
        found = _analyse(robot, args)
    except ws.NoVolumeError as error:
        raise ConfigError(f"--config {escape(str(args.config or 'the reference robot'))}: {error}") from None
    summary = _summary(robot, found, args.cone, args.axis, args.seed)
    print(f"robot      {escape(str(robot.parameters.name))}: {robot.n_joints} joints")
    for name, entry in summary["workspaces"].items():
        line = f"{name:<10} {1e3 * entry['volume_m3']:.4f} litres (cone {entry['cone_deg']:g} deg)"
        check = entry.get("monte_carlo")
        if check is not None:
            line += (
                f"; Monte Carlo {1e3 * check['volume_m3']:.4f} +- {1e3 * check['standard_error_m3']:.4f} litres "
                f"({check['samples']:,} samples), difference {100 * (check['relative_difference'] or 0):+.2f} %"
            )
        print(line)
    home = summary["home"]
    print(f"home       manipulability {home['manipulability']:.6g}, condition number {home['condition_number']:.4f}")
    distances = ", ".join(f"{k} {v:.4f}" for k, v in home["module_distance"].items())
    print(f"           flat-truss distance: {distances}")
    print(f"time       {time.perf_counter() - started:.1f} s")
    with atomic_folder(args.out, "--out", inputs=inputs, owned=WORKSPACE_FILES, checked=True) as folder:
        atomic_write_text(folder / "summary.json", json.dumps(summary, indent=2) + "\n")
        atomic_write_text(folder / "slices.csv", ws.slices_csv(found["slices"]))
        for name, figure in (
            ("slices.png", ws.plot_slices(found["slices"])),
            ("workspace_3d.png", ws.plot_workspace_3d(found["volumes"], found["slices"])),
        ):
            figure.savefig(folder / name, dpi=100)
        page = workspace_html(summary, found["volumes"], found["slices"], folder, ("slices.png", "workspace_3d.png"))
        atomic_write_text(folder / "workspace.html", page)
    print(f"written    {escape(str(args.out))}: {', '.join(WORKSPACE_FILES)}")
    return 0
