"""``vgtarm calibrate``: the robot's lengths and leg-sensor offsets identified from measured tool
positions (:func:`vgtarm.calibration.kinematic.calibrate`), or the poses to measure.

Two modes, one of them required:

- ``--measurements FILE``: fit the robot (``--config``, default the reference robot) to the CSV of
  joint readings and measured ``x, y, z`` (optionally ``qw, qx, qy, qz``); the folder ``--out`` gets
  the corrected robot file ``robot.toml`` (the input's format), ``report.md`` (every parameter with
  its standard error, or undetermined; the undetermined combinations; the sensor offsets),
  ``parameters.csv``, ``residuals.csv``, the figures ``residuals.png`` and ``singular_values.png``,
  and the page ``calibration.html`` (:mod:`vgtarm.app.reports.calibration_page`: the fit, the
  identifiability, the parameters, the poses' conditioning against random poses, the figures).
- ``--plan-poses K``: choose ``K`` poses that make the identification well conditioned; the folder
  gets ``poses.csv`` (the joints to command and the nominal tool point: replace ``x, y, z`` with the
  measured ones and give it back with ``--measurements``) and ``plan.md`` (the condition number
  against random poses, what the poses will determine).
"""

from __future__ import annotations

import argparse
import io
from pathlib import Path
from typing import Any

import numpy as np

from ...calibration.kinematic import (
    DEFAULT_CANDIDATES,
    DEFAULT_POSITION_NOISE,
    DEFAULT_RTOL,
    Calibration,
    Identifiability,
    Measurements,
    PosePlan,
    calibrate,
    plan_poses,
    pose_conditioning,
    read_measurements,
)
from ...errors import escape
from ...fileio import atomic_folder, atomic_write_text, check_output_folder
from ...markup import md_code, md_text
from ...model.robot import Robot, load_robot
from .options import add_config, positive_float, positive_int

#: The files ``vgtarm calibrate`` writes in its folder (and may replace there).
CALIBRATE_FILES = (
    "robot.toml",
    "report.md",
    "parameters.csv",
    "residuals.csv",
    "residuals.png",
    "singular_values.png",
    "calibration.html",
)
PLAN_FILES = ("poses.csv", "plan.md")


def add_parser(sub: Any) -> None:
    """Register ``vgtarm calibrate`` on the ``vgtarm`` command's subparsers."""
    parser = sub.add_parser(
        "calibrate",
        help="identify the robot's lengths and leg-sensor offsets from measured tool positions",
        description=(
            "With --measurements: fit every length of the robot file and each leg sensor's zero offset to "
            "measured tool positions (a CSV: one column per joint, x, y, z in m; optionally qw, qx, qy, qz), "
            "report what the poses determine and write the corrected robot file and the page calibration.html. "
            "With --plan-poses K: choose K "
            "poses that determine the parameters well and write them as a CSV to measure."
        ),
    )
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--measurements", type=Path, metavar="FILE", help="the CSV of measured poses")
    mode.add_argument("--plan-poses", type=positive_int, metavar="K", help="choose K poses to measure")
    parser.add_argument(
        "--noise",
        type=positive_float,
        default=DEFAULT_POSITION_NOISE,
        metavar="M",
        help=f"standard deviation of the position measurements in m (default {DEFAULT_POSITION_NOISE:g})",
    )
    parser.add_argument(
        "--rtol",
        type=positive_float,
        default=DEFAULT_RTOL,
        help=f"relative singular value below which a direction is undetermined (default {DEFAULT_RTOL:g})",
    )
    parser.add_argument(
        "--no-sensor-offsets",
        dest="sensor_offsets",
        action="store_false",
        help="fit the lengths alone: the leg sensors are trusted to read true lengths (no zero offsets)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the candidate poses (--plan-poses: chosen from; --measurements: compared with; default 0)",
    )
    parser.add_argument(
        "--candidates",
        type=positive_int,
        default=DEFAULT_CANDIDATES,
        help=f"random configurations to choose from or compare with (default {DEFAULT_CANDIDATES})",
    )
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to write")
    add_config(parser)
    parser.set_defaults(run=cmd_calibrate)


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Run the chosen mode and write its folder."""
    from ..reports.calibration_page import calibration_html

    if args.plan_poses is not None:
        return _plan(args)
    inputs = [args.config, args.measurements]
    check_output_folder(args.out, "--out", inputs=inputs, owned=CALIBRATE_FILES)
    robot = load_robot(args.config)
    measurements = read_measurements(args.measurements, robot, sensor_offsets=args.sensor_offsets)
    result = calibrate(
        robot, measurements, position_noise=args.noise, rtol=args.rtol, sensor_offsets=args.sensor_offsets
    )
    print(f"poses      {len(measurements)} from {escape(str(args.measurements))}")
    print(
        f"fit        {result.message}: {result.iterations} iterations, RMS residual {1e3 * result.rms_residual:.4g} mm"
    )
    print(result.identifiability.text())
    conditioning = pose_conditioning(
        robot, result, measurements, candidates=args.candidates, seed=args.seed, sensor_offsets=args.sensor_offsets
    )
    summary = calibration_summary(robot, result, measurements, str(args.measurements), args.noise, conditioning)
    with atomic_folder(args.out, "--out", inputs=inputs, owned=CALIBRATE_FILES, checked=True) as folder:
        atomic_write_text(folder / "robot.toml", result.robot_toml())
        atomic_write_text(folder / "report.md", _report(robot, result, str(args.measurements)))
        atomic_write_text(folder / "parameters.csv", _parameters_csv(result))
        atomic_write_text(folder / "residuals.csv", _residuals_csv(result))
        result.figure().savefig(folder / "residuals.png", dpi=110)
        singular_value_figure(result.identifiability).savefig(folder / "singular_values.png", dpi=110)
        pictures = [folder / "residuals.png", folder / "singular_values.png"]
        atomic_write_text(folder / "calibration.html", calibration_html(summary, pictures))
    print(f"written    {escape(str(args.out))}: {', '.join(CALIBRATE_FILES)}")
    return 0 if result.success else 1


def calibration_summary(
    robot: Robot,
    result: Calibration,
    measurements: Measurements,
    source: str,
    noise: float,
    conditioning: dict[str, Any],
) -> dict[str, Any]:
    """The data of ``calibration.html`` (SI units): the fit, the identifiability, every parameter
    (``None`` for the value and error of a held one: undetermined), the pose ``conditioning``
    (:func:`~vgtarm.calibration.kinematic.pose_conditioning`) and the written robot file's name."""
    analysis = result.identifiability
    held = [status == "held" for status in result.status]
    parameters = [
        {
            "name": name,
            "nominal": float(x0),
            "identified": None if h else float(x),
            "standard_error": None if h else float(se),
            "status": status,
        }
        for name, x0, x, se, status, h in zip(
            result.names, result.nominal, result.values, result.standard_errors, result.status, held, strict=True
        )
    ]
    return {
        "robot": robot.parameters.name,
        "joints": robot.n_joints,
        "measurements": source,
        "poses": len(measurements),
        "orientation": measurements.rotation is not None,
        "noise_m": noise,
        "fit": {
            "success": result.success,
            "message": result.message,
            "iterations": result.iterations,
            "evaluations": result.evaluations,
            "rms_residual_m": result.rms_residual,
            "nominal_rms_residual_m": float(np.sqrt(np.mean(result.nominal_residuals[:, :3] ** 2))),
            "sigma": result.sigma,
        },
        "identifiability": {
            "rank": analysis.rank,
            "parameters": len(analysis.names),
            "tolerance": analysis.tolerance,
            "singular_values": analysis.singular_values.tolist(),
            "condition_number": analysis.condition_number,
            "undetermined": list(analysis.combinations),
        },
        "parameters": parameters,
        "offsets": result.offsets,
        "conditioning": conditioning,
        "robot_file": "robot.toml",
    }


def singular_value_figure(analysis: Identifiability) -> Any:
    """The singular values of the weighted identification Jacobian (1/m, log scale), the
    undetermined ones (at most the tolerance, drawn at it) apart; returns the figure (never shown)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 3.2), layout="constrained")
    ax = fig.add_subplot()
    s = np.asarray(analysis.singular_values, dtype=float)
    k = np.arange(1, len(s) + 1)
    determined = s > analysis.tolerance
    ax.bar(k[determined], s[determined], label="determined")
    if (~determined).any():
        drawn = np.full(int((~determined).sum()), analysis.tolerance)
        ax.bar(k[~determined], drawn, color="#d62728", label="not determined (drawn at the tolerance)")
    ax.axhline(analysis.tolerance, color="0.4", lw=0.8, ls="--", label="tolerance")
    ax.set_yscale("log")
    ax.set_xticks(k)
    ax.set_xlabel("direction")
    ax.set_ylabel("singular value (1/m)")
    ax.set_title(f"Identification Jacobian: rank {analysis.rank} of {len(s)}")
    ax.legend(fontsize=8)
    return fig


def _plan(args: argparse.Namespace) -> int:
    inputs = [args.config]
    check_output_folder(args.out, "--out", inputs=inputs, owned=PLAN_FILES)
    robot = load_robot(args.config)
    plan = plan_poses(
        robot,
        args.plan_poses,
        candidates=args.candidates,
        seed=args.seed,
        rtol=args.rtol,
        sensor_offsets=args.sensor_offsets,
    )
    print(
        f"poses      {len(plan.q)} of {plan.candidates} candidates: condition number {plan.condition_number:.4g} "
        f"(random poses: median {np.median(plan.random_condition_numbers):.4g})"
    )
    with atomic_folder(args.out, "--out", inputs=inputs, owned=PLAN_FILES, checked=True) as folder:
        atomic_write_text(folder / "poses.csv", plan.to_csv(robot.joint_names))
        atomic_write_text(folder / "plan.md", _plan_report(robot, plan, args.noise))
    print(f"written    {escape(str(args.out))}: {', '.join(PLAN_FILES)}")
    return 0


def _report(robot: Robot, result: Calibration, source: str) -> str:
    analysis = result.identifiability
    lines = [
        f"# Kinematic calibration of {md_text(robot.parameters.name)}",
        "",
        f"- measurements: {md_code(source)}, {len(result.residuals)} poses",
        f"- fit: {result.message} after {result.iterations} iterations ({result.evaluations} evaluations)",
        f"- RMS position residual: {1e3 * result.rms_residual:.4f} mm per coordinate "
        f"(nominal model: {1e3 * float(np.sqrt(np.mean(result.nominal_residuals[:, :3] ** 2))):.4f} mm)",
        f"- noise estimated from the residuals: {result.sigma:.3g} times the assumed",
        f"- {analysis.text()}".replace("\n", "\n- "),
        "",
        "Standard errors: `sigma^2 (J^T J)^-1` at the optimum. *held*: undetermined by these poses, kept at its "
        "nominal value; *given held*: determined once the held parameters are fixed at theirs.",
        "",
        result.table(),
        "",
        "Sensor offsets are not part of the robot file: subtract them from the readings (m): "
        + (", ".join(f"{k} {v:+.6g}" for k, v in result.offsets.items()) or "none fitted (--no-sensor-offsets)"),
        "",
        "![residuals](residuals.png)",
    ]
    return "\n".join(lines) + "\n"


def _plan_report(robot: Robot, plan: PosePlan, noise: float) -> str:
    randoms = plan.random_condition_numbers
    lines = [
        f"# Measurement poses for {md_text(robot.parameters.name)}",
        "",
        f"- {len(plan.q)} poses chosen greedily (D-optimal, then exchanges that lower the condition number) "
        f"from {plan.candidates} random configurations (seed {plan.seed})",
        f"- condition number of the identification Jacobian: {plan.condition_number:.4g}; {len(randoms)} random "
        f"choices of as many poses: median {np.median(randoms):.4g}, best {randoms.min():.4g}",
        f"- worst-determined direction: standard error {1e3 * noise / plan.smallest_singular_value:.4g} mm "
        f"with {1e3 * noise:.3g} mm noise",
        f"- {plan.identifiability.text()}".replace("\n", "\n- "),
        "",
        "Measure the tool point at each row of `poses.csv`, replace its `x,y,z` (the nominal robot's) with the "
        "measured ones, and run `vgtarm calibrate --measurements poses.csv`.",
    ]
    return "\n".join(lines) + "\n"


def _parameters_csv(result: Calibration) -> str:
    stream = io.StringIO()
    stream.write("parameter,nominal,fitted,standard_error,status\n")
    for name, x0, x, se, status in zip(
        result.names, result.nominal, result.values, result.standard_errors, result.status, strict=True
    ):
        fitted = "" if status == "held" else f"{x:.17g}"
        error = "" if status == "held" else f"{se:.6g}"
        stream.write(f"{name},{x0:.17g},{fitted},{error},{status}\n")
    return stream.getvalue()


def _residuals_csv(result: Calibration) -> str:
    rows = result.residuals.shape[1]
    header = ["pose", "dx", "dy", "dz"] + (["rx", "ry", "rz"] if rows == 6 else [])
    stream = io.StringIO()
    stream.write(",".join(header) + "\n")
    table = np.column_stack([np.arange(1, len(result.residuals) + 1), result.residuals])
    np.savetxt(stream, table, delimiter=",", fmt=["%d"] + ["%.9g"] * rows)
    return stream.getvalue()
