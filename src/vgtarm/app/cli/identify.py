"""``vgtarm identify``: the inertial and friction parameters of a robot from measured leg forces.

Two modes (:mod:`vgtarm.calibration.dynamic`, :mod:`vgtarm.calibration.excitation`):

- ``vgtarm identify --excite --out DIR [--config FILE]``: design an exciting trajectory for the
  robot and write it as ``excitation.csv`` (``t``, then ``q``, ``qd``, ``qdd`` of each joint:
  ``s1, ..., s1_d, ..., s1_dd, ...``, as ``vgtarm retime``'s ``joints.csv``).
- ``vgtarm identify --data FILE --out DIR [--config FILE]``: identify from a measurement file and
  write the identified robot (``identified_robot.toml``, which :func:`vgtarm.load_robot` reads),
  the table of base parameters with their standard errors (``base_parameters.csv``), the figures
  ``residuals.png`` (force residuals) and ``trajectory.png`` (the data's joint positions), and the
  page ``identification.html`` (:mod:`vgtarm.app.reports.calibration_page`: the trajectory, the
  base parameters, the physical consistency of each body, the validation numbers, the figures).

The measurement file is a CSV with a header: ``t`` (s), each joint's position (its name: ``s1``...),
its force (``s1_F``..., N or N m) and optionally its rate and acceleration (``s1_d``, ``s1_dd``...).
Without them they are computed from the positions by a Savitzky-Golay filter (cubic, ``--window``
samples, which needs evenly spaced times); the forces are used as measured.
"""

from __future__ import annotations

import argparse
import csv
import io
from pathlib import Path
from typing import Any

import numpy as np
import scipy.signal

from ...calibration.dynamic import (
    STANDARD_UNITS,
    Identification,
    body_standard,
    holdout_check,
    identify,
    is_consistent,
)
from ...calibration.excitation import exciting_trajectory
from ...errors import InputError, escape
from ...fileio import atomic_folder, atomic_write_text, check_output_folder, read_text_limited
from ...model.robot import Robot, load_robot
from ...model.stack.description import robot_to_toml
from .options import add_config, positive_float, positive_int, seed_number

#: The files each mode writes in its folder.
IDENTIFY_FILES = (
    "identified_robot.toml",
    "base_parameters.csv",
    "residuals.png",
    "trajectory.png",
    "identification.html",
)
EXCITE_FILES = ("excitation.csv",)
#: Largest measurement file read (bytes).
DATA_LIMIT = 2**28


def add_parser(sub: Any) -> None:
    """Register ``vgtarm identify`` on the ``vgtarm`` command's subparsers."""
    parser = sub.add_parser(
        "identify",
        help="identify the masses, inertias and viscous friction from measured leg forces",
        description=(
            "With --data: fit the base inertial and friction parameters to the measured forces and write the "
            "physically consistent identified robot (identified_robot.toml), the base parameters with their "
            "standard errors (base_parameters.csv), the residuals (residuals.png), the data's trajectory "
            "(trajectory.png) and the page identification.html. With --excite: write an "
            "exciting trajectory for the robot (excitation.csv)."
        ),
    )
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--data", type=Path, metavar="FILE", help="measurement CSV: t, q per joint, <joint>_F ...")
    mode.add_argument("--excite", action="store_true", help="write an exciting trajectory instead")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to write")
    parser.add_argument("--seed", type=seed_number, default=0, help="seed of the random choices (default 0)")
    parser.add_argument("--window", type=positive_int, default=21, help="Savitzky-Golay window (samples, odd)")
    parser.add_argument("--period", type=positive_float, default=5.0, help="excitation period (s, default 5)")
    parser.add_argument("--harmonics", type=positive_int, default=5, help="harmonics per joint (default 5)")
    parser.add_argument("--dt", type=positive_float, default=0.002, help="excitation sampling period (s)")
    parser.add_argument("--evaluations", type=positive_int, default=200, help="condition numbers searched")
    add_config(parser)
    parser.set_defaults(run=cmd_identify)


def cmd_identify(args: argparse.Namespace) -> int:
    """Run the chosen mode; return the exit code."""
    from ..reports.calibration_page import identification_html

    if args.excite:
        return _excite(args)
    inputs = [args.config, args.data]
    check_output_folder(args.out, "--out", inputs=inputs, owned=IDENTIFY_FILES)
    robot = load_robot(args.config, model=getattr(args, "model", None))
    q, qd, qdd, forces = read_measurements(args.data, robot, window=args.window)
    result = identify(robot, q, qd, qdd, forces, seed=args.seed)
    print(f"data       {escape(str(args.data))}: {result.samples} samples of {robot.n_joints} forces")
    print(f"base       {result.base.size} parameters, condition number {result.condition_number:.4g}")
    print(f"residual   RMS {result.rms_least_squares:.4g} (least squares), {result.rms_consistent:.4g} (consistent)")
    if result.base.undetermined:
        print(f"undetermined (kept at the prior): {', '.join(result.base.undetermined)}")
    summary = identification_summary(robot, result, (q, qd, qdd, forces), str(args.data))
    with atomic_folder(args.out, "--out", inputs=inputs, owned=IDENTIFY_FILES, checked=True) as folder:
        atomic_write_text(folder / "identified_robot.toml", robot_to_toml(result.parameters, header=_header(args)))
        atomic_write_text(folder / "base_parameters.csv", base_table(result))
        written = load_robot(folder / "identified_robot.toml", model=getattr(args, "model", None))
        summary["validation"]["rms_file"] = _rms(forces - written.inverse_dynamics(q, qd, qdd))
        residual_figure(result, robot.joint_names).savefig(folder / "residuals.png", dpi=110)
        trajectory_figure(robot, q).savefig(folder / "trajectory.png", dpi=110)
        pictures = [folder / "residuals.png", folder / "trajectory.png"]
        atomic_write_text(folder / "identification.html", identification_html(summary, pictures))
    print(f"written    {escape(str(args.out))}: {', '.join(IDENTIFY_FILES)}")
    return 0


def _excite(args: argparse.Namespace) -> int:
    inputs = [args.config]
    check_output_folder(args.out, "--out", inputs=inputs, owned=EXCITE_FILES)
    robot = load_robot(args.config, model=getattr(args, "model", None))
    trajectory = exciting_trajectory(
        robot,
        period=args.period,
        harmonics=args.harmonics,
        dt=args.dt,
        evaluations=args.evaluations,
        seed=args.seed,
    )
    print(f"excitation {len(trajectory.t)} samples over {trajectory.period:g} s, {args.harmonics} harmonics")
    print(f"condition  {trajectory.condition_number:.4g} (column-normalised base regressor)")
    with atomic_folder(args.out, "--out", inputs=inputs, owned=EXCITE_FILES, checked=True) as folder:
        atomic_write_text(folder / "excitation.csv", trajectory.csv_text())
    print(f"written    {escape(str(args.out))}: {', '.join(EXCITE_FILES)}")
    return 0


def _header(args: argparse.Namespace) -> str:
    return f"written by vgtarm identify from {args.data} (prior: {args.config or 'the reference robot'})"


def read_measurements(path: Path, robot: Robot, *, window: int = 21) -> tuple[np.ndarray, ...]:
    """``(q, qd, qdd, forces)`` of a measurement CSV (module docstring), each ``(N, n)``; one
    :class:`~vgtarm.errors.InputError` line for a missing column or a cell that is not a number."""
    text = read_text_limited(path, DATA_LIMIT, "--data")
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise InputError(f"--data {escape(str(path))}: empty file (expected a header t, q and forces per joint)")
    header = [name.strip() for name in rows[0]]
    values = np.empty((len(rows) - 1, len(header)))
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise InputError(f"--data {escape(str(path))} line {line}: {len(row)} cells, expected {len(header)}")
        for k, cell in enumerate(row):
            try:
                values[line - 2, k] = float(cell)
            except ValueError:
                raise InputError(
                    f"--data {escape(str(path))} line {line}, column {header[k]!r}: {cell[:40]!r} is not a number"
                ) from None
    names = robot.joint_names

    def columns(suffix: str, required: bool) -> np.ndarray | None:
        wanted = ["t"] if suffix == "t" else [f"{name}{suffix}" for name in names]
        missing = [name for name in wanted if name not in header]
        if missing and (required or len(missing) < len(wanted)):
            raise InputError(f"--data {escape(str(path))}: no column {missing[0]!r} (expected t, q, _F per joint)")
        return None if missing else values[:, [header.index(name) for name in wanted]]

    t, q, forces = columns("t", True), columns("", True), columns("_F", True)
    qd, qdd = columns("_d", False), columns("_dd", False)
    assert t is not None and q is not None and forces is not None
    if qd is None or qdd is None:
        qd, qdd = _differentiated(path, t[:, 0], q, window)
    return q, qd, qdd, forces


def _differentiated(path: Path, t: np.ndarray, q: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Rates and accelerations of evenly sampled positions by a cubic Savitzky-Golay filter."""
    if window % 2 == 0 or window < 5:
        raise InputError(f"--window {window}: expected an odd number of samples >= 5")
    if len(t) < window:
        raise InputError(f"--data {escape(str(path))}: {len(t)} rows, fewer than the --window of {window}")
    steps = np.diff(t)
    dt = float(np.mean(steps))
    if not (dt > 0 and np.allclose(steps, dt, rtol=1e-6, atol=0.0)):
        raise InputError(
            f"--data {escape(str(path))}: times not evenly spaced "
            "(needed to differentiate q; give the _d and _dd columns)"
        )
    qd = scipy.signal.savgol_filter(q, window, 3, deriv=1, delta=dt, axis=0)
    qdd = scipy.signal.savgol_filter(q, window, 3, deriv=2, delta=dt, axis=0)
    return qd, qdd


def measurements_csv(
    names: tuple[str, ...], t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, forces: np.ndarray
) -> str:
    """The text of a measurement file (module docstring) with rates and accelerations."""
    header = ["t", *names, *(f"{n}_d" for n in names), *(f"{n}_dd" for n in names), *(f"{n}_F" for n in names)]
    stream = io.StringIO()
    stream.write(",".join(header) + "\n")
    np.savetxt(stream, np.column_stack([t, q, qd, qdd, forces]), delimiter=",", fmt="%.17g")
    return stream.getvalue()


def base_table(result: Identification) -> str:
    """``base_parameters.csv``: each base parameter's least-squares estimate, standard error, consistent
    value and the prior's, then the standard parameters no force depends on."""
    stream = io.StringIO()
    writer = csv.writer(stream, lineterminator="\n")
    writer.writerow(["base_parameter", "least_squares", "standard_error", "consistent", "prior"])
    prior = result.base.of(result.prior)
    for row in zip(
        result.base.labels, result.least_squares, result.standard_errors, result.consistent, prior, strict=True
    ):
        writer.writerow([row[0], *(repr(float(x)) for x in row[1:])])
    for name in result.base.undetermined:
        writer.writerow([name, "undetermined", "", "", ""])
    return stream.getvalue()


def residual_figure(result: Identification, names: tuple[str, ...]) -> Any:
    """One panel per joint: the consistent model's force residual against the sample (N, N m)."""
    from matplotlib.figure import Figure

    n = len(names)
    fig = Figure(figsize=(8.0, 1.4 * n + 0.8), layout="constrained")
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    for k, ax in enumerate(axes):
        ax.plot(result.residual[:, k], lw=0.6)
        ax.set_ylabel(f"{names[k]}\n(RMS {np.sqrt(np.mean(result.residual[:, k] ** 2)):.3g})", fontsize=8)
    axes[-1].set_xlabel("sample")
    fig.suptitle("Force residuals of the identified model (N, N m for twists)")
    return fig


def _rms(values: np.ndarray, axis: int | None = None) -> Any:
    """Root mean square of ``values`` (over ``axis``; all of them by default)."""
    rms = np.sqrt(np.mean(np.square(values), axis=axis))
    return float(rms) if axis is None else rms


def _base_unit(result: Identification, index: int, units: tuple[str, ...]) -> str:
    """The unit of the standard parameter ``index`` (a body's ten, then the joints' viscous ones)."""
    bodies = 10 * len(result.parameters.bodies)
    if index < bodies:
        return STANDARD_UNITS[index % 10]
    return "N m s/rad" if units[index - bodies] == "rad" else "N s/m"


def _consistency(robot: Robot, result: Identification) -> dict[str, Any]:
    """Each identified body's mass, centre of mass, principal moments about it, least triangle
    margin and whether its pseudo-inertia is positive definite; the viscous coefficients."""
    bodies = []
    for body in result.parameters.bodies:
        moments = np.linalg.eigvalsh(np.asarray(body.inertia_matrix, dtype=float))  # ascending
        bodies.append(
            {
                "name": body.name,
                "mass": float(body.mass),
                "com_m": [float(c) for c in body.com],
                "principal_moments": moments.tolist(),
                "triangle_margin": float(moments[0] + moments[1] - moments[2]),
                "consistent": is_consistent(body_standard(body)),
            }
        )
    viscous = dict(zip(robot.joint_names, (float(v) for v in result.parameters.viscous), strict=True))
    return {"bodies": bodies, "viscous": viscous, "success": result.success, "message": result.message}


def _trajectory(robot: Robot, result: Identification, data: tuple[np.ndarray, ...]) -> dict[str, Any]:
    """The data's condition number and, per joint, its limits, range, largest rate and acceleration
    and RMS force."""
    q, qd, qdd, forces = data
    lower, upper = robot.joint_limits()
    joints = [
        {
            "name": name,
            "unit": unit,
            "lower": float(lower[k]),
            "upper": float(upper[k]),
            "min": float(q[:, k].min()),
            "max": float(q[:, k].max()),
            "span_used": float((q[:, k].max() - q[:, k].min()) / (upper[k] - lower[k])),
            "max_rate": float(np.abs(qd[:, k]).max()),
            "max_acceleration": float(np.abs(qdd[:, k]).max()),
            "rms_force": float(_rms(forces[:, k])),
        }
        for k, (name, unit) in enumerate(zip(robot.joint_names, robot.joint_units, strict=True))
    ]
    return {"condition_number": result.condition_number, "joints": joints}


def identification_summary(
    robot: Robot, result: Identification, data: tuple[np.ndarray, ...], source: str
) -> dict[str, Any]:
    """The data of ``identification.html`` (SI units) from the prior ``robot``, the ``result`` and
    the ``data`` ``(q, qd, qdd, forces)`` it was identified from (``source``: the file): the
    trajectory, the base parameters, the consistency checks and the validation numbers (its
    ``rms_file``, of the written robot file read back, is filled in by the command)."""
    q, qd, qdd, forces = data
    prior = result.base.of(result.prior)
    base = [
        {
            "label": label,
            "unit": _base_unit(result, lead, robot.joint_units),
            "least_squares": float(ls),
            "standard_error": float(se),
            "consistent": float(c),
            "prior": float(p),
        }
        for label, lead, ls, se, c, p in zip(
            result.base.labels,
            result.base.independent,
            result.least_squares,
            result.standard_errors,
            result.consistent,
            prior,
            strict=True,
        )
    ]
    residual = _rms(result.residual, axis=0)
    rms_force = _rms(forces, axis=0)
    joints = [
        {
            "name": name,
            "noise": float(result.noise[k]),
            "rms_residual": float(residual[k]),
            "rms_force": float(rms_force[k]),
        }
        for k, name in enumerate(robot.joint_names)
    ]
    return {
        "robot": robot.parameters.name,
        "joints": robot.n_joints,
        "data": source,
        "samples": result.samples,
        "robot_file": "identified_robot.toml",
        "trajectory": _trajectory(robot, result, data),
        "base": {
            "standard": len(result.base.names),
            "parameters": base,
            "undetermined": list(result.base.undetermined),
        },
        "consistency": _consistency(robot, result),
        "validation": {
            "rms_prior": _rms(forces - robot.inverse_dynamics(q, qd, qdd)),
            "rms_least_squares": result.rms_least_squares,
            "rms_consistent": result.rms_consistent,
            "rms_file": None,
            "holdout": holdout_check(robot, result, data),
            "joints": joints,
        },
    }


def trajectory_figure(robot: Robot, q: np.ndarray) -> Any:
    """Each joint's position in the data as a fraction of its range (0: lower limit, 1: upper)
    against the sample; returns the figure (never shown)."""
    from matplotlib.figure import Figure

    from ...markup import mpl_text

    lower, upper = robot.joint_limits()
    fig = Figure(figsize=(8.0, 3.5), layout="constrained")
    ax = fig.add_subplot()
    for k, name in enumerate(robot.joint_names):
        ax.plot((q[:, k] - lower[k]) / (upper[k] - lower[k]), lw=0.8, label=mpl_text(name))
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlabel("sample")
    ax.set_ylabel("position (fraction of the range)")
    ax.set_title("The trajectory of the data")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5))
    return fig
