"""``vgtarm identify``: the inertial and friction parameters of a robot from measured leg forces.

Two modes (:mod:`vgtarm.calibration.dynamic`, :mod:`vgtarm.calibration.excitation`):

- ``vgtarm identify --excite --out DIR [--config FILE]``: design an exciting trajectory for the
  robot and write it as ``excitation.csv`` (``t``, then ``q``, ``qd``, ``qdd`` of each joint:
  ``s1, ..., s1_d, ..., s1_dd, ...``, as ``vgtarm retime``'s ``joints.csv``).
- ``vgtarm identify --data FILE --out DIR [--config FILE]``: identify from a measurement file and
  write the identified robot (``identified_robot.toml``, which :func:`vgtarm.load_robot` reads),
  the table of base parameters with their standard errors (``base_parameters.csv``) and the
  residual figure (``residuals.png``).

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

from ...calibration.dynamic import Identification, identify
from ...calibration.excitation import exciting_trajectory
from ...errors import InputError, escape
from ...fileio import atomic_folder, atomic_write_text, check_output_folder, read_text_limited
from ...model.robot import Robot, load_robot
from ...model.stack.description import robot_to_toml
from .options import add_config, positive_float, positive_int, seed_number

#: The files each mode writes in its folder.
IDENTIFY_FILES = ("identified_robot.toml", "base_parameters.csv", "residuals.png")
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
            "standard errors (base_parameters.csv) and the residuals (residuals.png). With --excite: write an "
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
    with atomic_folder(args.out, "--out", inputs=inputs, owned=IDENTIFY_FILES, checked=True) as folder:
        atomic_write_text(folder / "identified_robot.toml", robot_to_toml(result.parameters, header=_header(args)))
        atomic_write_text(folder / "base_parameters.csv", base_table(result))
        residual_figure(result, robot.joint_names).savefig(folder / "residuals.png", dpi=110)
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
