"""``vgtarm drill``: drill a layered bone under hybrid force and position control in the tool frame
(:func:`vgtarm.drilling.drilling_run`, the compiled loop), the thrust regulated from the observer's estimate,
the layers and the breakthrough detected, then the drill retracted.

The folder ``--out`` gets ``timeseries.csv`` (the run's series, SI units, a column per
:data:`vgtarm.drilling.SERIES` entry), ``events.csv`` (the detector's detections: ``t,kind,layer``),
``summary.json`` (the measures against the issue's targets) and ``drilling.png`` (thrust, depth and
the specific thrust against time with the detections marked). Methods: docs/drilling_control.md.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from ...errors import escape
from ...fileio import atomic_folder, atomic_write_text, check_output_folder, json_value
from ...model.robot import load_robot
from .options import add_config, positive_float

#: The files ``vgtarm drill`` writes in its folder (and may replace there).
DRILL_FILES = ("timeseries.csv", "events.csv", "summary.json", "drilling.png")
RPM = 2.0 * math.pi / 60.0


def add_parser(sub: Any) -> None:
    """Register ``vgtarm drill`` on the ``vgtarm`` command's subparsers."""
    parser = sub.add_parser(
        "drill",
        help="drill a layered bone under force control (thrust from the observer), detect breakthrough",
        description=(
            "Drill the bone of a bone file (layers, drill) along the robot's tool axis at home: the thrust "
            "regulated to its set point from the momentum observer's estimate (1 um encoders, model 10 %% heavy), "
            "the tip held on the axis, each layer and the breakthrough detected, then the feed stopped and the "
            "drill retracted; print the measures against the targets and write timeseries.csv, events.csv, "
            "summary.json and drilling.png."
        ),
    )
    add_drilling_flags(parser)
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to write")
    add_config(parser)
    parser.set_defaults(run=cmd_drill)


def add_drilling_flags(parser: argparse.ArgumentParser) -> None:
    """The run's flags, shared by ``vgtarm drill`` and ``vgtarm export drilling``."""
    parser.add_argument("--bone", type=Path, required=True, metavar="FILE", help="a bone file (examples/bones/)")
    parser.add_argument(
        "--mode", choices=("admittance", "explicit"), default="admittance", help="the force loop (default admittance)"
    )
    parser.add_argument("--set-point", type=positive_float, default=20.0, metavar="N", help="thrust (N, default 20)")
    parser.add_argument(
        "--feed", type=positive_float, default=1.0, metavar="MM_S", help="feed-rate limit (mm/s, default 1)"
    )
    parser.add_argument(
        "--spindle", type=positive_float, default=1000.0, metavar="RPM", help="spindle speed (rpm, default 1000)"
    )
    parser.add_argument(
        "--feedback", choices=("observer", "sensor"), default="observer", help="the thrust fed back (default observer)"
    )

    parser.add_argument(
        "--posture",
        choices=("home", "stiffest"),
        default="home",
        help="the posture held: home, or the one stiffest along the tool's axis with home's tool pose "
        "(needs the robot file's [stiffness]; default home)",
    )


def drilling_settings(args: argparse.Namespace) -> Any:
    """The :class:`~vgtarm.drilling.DrillingSettings` of the flags of :func:`add_drilling_flags`."""
    from ...drilling import DrillingSettings

    return DrillingSettings(
        set_point=args.set_point,
        feed_limit=1e-3 * args.feed,
        spindle_speed=RPM * args.spindle,
        mode=args.mode,
        feedback=args.feedback,
    )


def start_posture(robot: Any, args: argparse.Namespace, settings: Any) -> Any:
    """The posture the run starts from and holds: None for home, else the one stiffest along the
    tool's axis with home's tool pose (:func:`vgtarm.design.stiffest_posture`), printed."""
    if args.posture != "stiffest":
        return None
    from ...design import stiffest_posture

    posture = stiffest_posture(robot, robot.parameters.home, thrust=settings.set_point)
    print(
        f"posture    stiffest along the axis: {posture.stiffness:.4g} N/m (home {posture.stiffness0:.4g} N/m, "
        f"{100 * (posture.stiffness / posture.stiffness0 - 1):+.3g} %)"
    )
    return posture.q


def add_export_parser(formats: Any) -> None:
    """Register ``vgtarm export drilling`` on the ``export`` command's formats."""
    parser = formats.add_parser(
        "drilling",
        help="the force-controlled drilling controller as dependency-free C99 (bit for bit with vgtarm drill)",
        description=(
            "Write the drilling controller of the run `vgtarm drill` makes with the same flags as a C99 folder: "
            "the controller model's functions (CasADi), the run's numbers, the simulation's own per-period "
            "code, vgtd_replay and a Makefile; compiled with strict flags before it is put in place."
        ),
    )
    add_drilling_flags(parser)
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to write (new)")
    add_config(parser)
    parser.set_defaults(run=cmd_export_drilling)


def cmd_export_drilling(args: argparse.Namespace) -> int:
    """Export the drilling controller."""
    from ...drilling import load_bone
    from ...export.drilling import export_drilling

    check_output_folder(args.out, "--out", inputs=[args.config, args.bone], owned=())
    robot = load_robot(args.config)
    bone = load_bone(args.bone)
    settings = drilling_settings(args)
    done = export_drilling(robot, bone, args.out, settings, q0=start_posture(robot, args, settings))
    print(f"written    {escape(str(done))}: make builds libvgtd.a and vgtd_replay")
    return 0


def cmd_drill(args: argparse.Namespace) -> int:
    """Run the drilling, print its measures, write the folder."""
    from ...drilling import TARGETS, drilling_run, load_bone

    inputs = [args.config, args.bone]
    check_output_folder(args.out, "--out", inputs=inputs, owned=DRILL_FILES)  # before the work
    robot = load_robot(args.config)
    bone = load_bone(args.bone)
    settings = drilling_settings(args)
    result = drilling_run(robot, bone, settings, q0=start_posture(robot, args, settings))
    summary = result.summary()
    print(f"bone       {escape(str(args.bone))}: {len(bone.layers)} layers, {1e3 * bone.thickness:.2f} mm")
    print(f"run        {args.mode} force control, {args.feedback}; {escape(result.reason)}")
    if math.isfinite(result.fracture_time):
        short = 1e3 * -summary["protrusion"]
        print(f"cap        broke out at {result.fracture_time:.4f} s, the apex {short:.3g} mm short of the far surface")
    for layer in summary["layers"]:
        limited = f", {100 * layer['at_feed_limit']:.0f} % of it at the feed limit" if layer["at_feed_limit"] else ""
        print(
            f"layer {int(layer['layer'])}    thrust {layer['thrust_mean']:.3g} N mean, "
            f"error RMS {layer['thrust_error_rms']:.3g} N{limited}"
        )
    for name, target in TARGETS.items():
        value = summary.get(f"{name}_max", summary.get(name))
        if isinstance(value, int | float) and math.isfinite(value):
            scale, unit = (1.0, "N") if name.startswith("thrust") else (1e3, "ms" if "delay" in name else "mm")
            if name == "axis_error":
                unit = "mrad"
            mark = "ok" if value <= target else "over"
            print(f"{name:<20} {scale * value:.4g} {unit} (target {scale * target:g} {unit}: {mark})")
    with atomic_folder(args.out, "--out", inputs=inputs, owned=DRILL_FILES, checked=True) as folder:
        atomic_write_text(folder / "timeseries.csv", result.series_csv())
        atomic_write_text(folder / "events.csv", result.events_csv())
        atomic_write_text(folder / "summary.json", json.dumps(json_value(summary), indent=2) + "\n")
        result.figure().savefig(folder / "drilling.png", dpi=100)
    print(f"written    {escape(str(args.out))}: {', '.join(DRILL_FILES)}")
    return 0 if result.success else 1
