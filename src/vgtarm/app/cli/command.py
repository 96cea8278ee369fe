"""The ``vgtarm`` command line.

Every user error (bad file, bad number, unreachable path, diverged run) prints one line
``vgtarm: error: ...`` on standard error and exits with status 1 (2 for bad usage). A closed
pipe on standard output (``vgtarm describe | head -1``) ends quietly with status 141, like a tool
killed by SIGPIPE.
"""

from __future__ import annotations

import argparse
import os
import re
import select
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np

from ... import paths, progress
from ...errors import (
    MESSAGE_LENGTH,
    ConfigError,
    InputError,
    SimulationError,
    Terminated,
    UnreachableError,
    VgtarmError,
    cut,
    escape,
    shown,
)
from ...experiment import Experiment
from ...experiment.options import add_flags as add_option_flags
from ...experiment.options import all_options
from ...fileio import (
    atomic_folder,
    atomic_write_text,
    check_output_file,
    check_output_folder,
    placements,
    read_text_limited,
)
from ...ik import CSV_COLUMNS, write_csv
from ...ik.axis import entry_point_target, tool_task_keywords
from ...model.parameters import JOINT_NAMES, JOINT_UNITS, ROBOT_FILE_LIMIT
from ...model.robot import Robot, load_robot
from ...paths import TipPath as DesiredPath
from ...simulation.scenario import senses
from ...version import __version__
from . import calibrate as cli_calibrate
from . import drill as cli_drill
from . import drill_study as cli_drill_study
from . import identify as cli_identify
from . import mujoco as cli_mujoco
from . import presets
from . import retime as cli_retime
from . import stack as cli_stack
from . import stiffness as cli_stiffness
from . import study as cli_study
from . import visual as cli_visual
from . import workspace as cli_workspace
from .bars import progress_bar
from .options import (
    add_config,
    joint_gains,
    positive_float,
    positive_int,
    positive_int_at_most,
    register_numbers,
)
from .tool_flags import FLAGS as TOOL_FLAGS
from .tool_flags import ik_pointing, numbers

if TYPE_CHECKING:
    from ...simulation.result import SimulationResult

#: A gain of ``--kp`` or ``--kv``: one for every joint, one per joint, or None (the case's).
_Gain = float | tuple[float, ...] | None


def _format_vector(values: Sequence[float] | np.ndarray, digits: int = 6) -> str:
    return "[" + ", ".join(f"{v:.{digits}g}" for v in values) + "]"


def cmd_describe(args: argparse.Namespace) -> int:
    """Print the robot: dimensions, limits, home pose, tip at home, mass-matrix eigenvalues."""
    from ...model.stack import Stack
    from .stack import describe_stack, home_figures, model_state, print_actuators, robot_description

    p = robot_description(args.config)  # no model is built: see cli_stack
    if isinstance(p, Stack):
        with progress_bar("describe: the model at home", "step"):  # a large stack takes seconds
            return describe_stack(p)
    home = p.home
    state, figures = model_state(p), home_figures(p)  # before any line: either may refuse in one line
    print(f"robot      {escape(p.name)}")  # a name from a user's file never drives the terminal
    print(f"source     {escape(p.source)}")
    print(f"model      {state}")
    for k, module in enumerate(p.modules, start=1):
        print(f"module {k}   b = {module.b:g} m, d = {module.d:g} m")
    print(f"twist part h1 = {p.h1:g} m")
    print("joints     name   min        max        home")
    lower, upper = p.lower, p.upper
    for i, name in enumerate(JOINT_NAMES):
        unit = JOINT_UNITS[i]
        print(f"           {name:<6} {lower[i]:<10.6g} {upper[i]:<10.6g} {home[i]:.10g} {unit}")
    for body in p.bodies:
        print(f"body       {body.name:<13} mass {body.mass:g} kg, com {_format_vector(body.com)} m")
    print(f"friction   {_format_vector(p.viscous)} (N s/m; N m s/rad for psi3)")
    print_actuators(p.actuators)
    print(f"gravity    {_format_vector(p.gravity)} m/s^2")
    print(f"tip @ home {_format_vector(figures.tip, 10)} m; reach {float(np.linalg.norm(figures.tip)):.6g} m")
    if figures.eigenvalues is None:
        print(f"M @ home   {figures.mass_note}")
    else:
        print(f"M @ home   eigenvalues {_format_vector(figures.eigenvalues, 5)} (kg, kg m^2)")
    return 0


def cmd_fk(args: argparse.Namespace) -> int:
    """Print passive angles, platform centres, tip position and orientation of one configuration."""
    robot = load_robot(args.config)
    q = np.array(args.q, dtype=float)
    if q.shape != (robot.n_joints,):
        raise InputError(
            f"Q: expected {robot.n_joints} joint values ({' '.join(robot.joint_names)}), got {len(args.q)}"
        )
    fk = robot.forward_kinematics(q)
    names, units = robot.joint_names, robot.joint_units
    print("q          " + ", ".join(f"{n} = {v:.10g} {u}" for n, v, u in zip(names, q, units, strict=True)))
    for k in range(robot.n_modules):
        alpha, beta, gamma, theta = fk.passive[k]
        print(f"module {k + 1}   alpha = {alpha:.8f}, beta = {beta:.8f}, gamma = {gamma:.8f}, theta = {theta:.8f} rad")
        print(f"           platform centre O{k + 1} = {_format_vector(fk.platform_position[k], 10)} m")
    print(f"tip        {_format_vector(fk.tip, 10)} m")
    print("rotation   C03 =")
    for row in fk.rotation:
        print("           " + _format_vector(row, 10))
    return 0


def _robot_text(config: Path | None) -> str | None:
    """The text of the robot file ``config`` (None for the reference robot), to keep beside a run."""
    if config is None:
        return None
    return read_text_limited(config, ROBOT_FILE_LIMIT, "configuration file", error=ConfigError)


def cmd_simulate(args: argparse.Namespace) -> int:
    """Run one case study, print its summary, write its results and figures."""
    presets.apply_preset(args)
    with presets.named(args):  # a refusal of a value the preset set says so, never as if the user typed it
        return _simulate(args)


def _simulate(args: argparse.Namespace) -> int:
    """``vgtarm simulate`` with the preset's settings in ``args``: the options checked before any
    work, the run, its summary on standard output and its folder (``--out``)."""
    from tqdm import tqdm

    from ...simulation.result import RUN_FILES

    _check_simulate_options(args)
    inputs = [args.config, args.path]
    if args.out is not None:
        check_output_folder(args.out, "--out", inputs=inputs, owned=RUN_FILES)  # before the work
    desired = None if args.path is None else paths.from_csv(args.path)  # a bad file: one line, before the model
    robot = load_robot(args.config)
    robot_text = _robot_text(args.config)
    gains = _simulate_gains(args, robot)
    if args.plant_engine == "mujoco":
        from ... import mujoco_bridge  # noqa: F401  (registers the MuJoCo plant)
    experiment = _experiment(args, robot, desired, gains)
    if args.entry_point is not None:  # off the tip's path, said naming the flag, before the IK
        tip = experiment.desired(robot)
        point = experiment.tool_task()["entry_point"]
        entry_point_target(point, tip.position, tip.velocity, tip.acceleration, "--entry-point")
    label = f"case {args.case}" if desired is None else escape(desired.name)
    with (
        tqdm(total=100, desc=f"{label} {args.controller}", unit="%", disable=args.quiet, leave=False) as bar,
        progress_bar("inverse kinematics", "sample"),  # of the reference: a long path or a large stack
    ):

        def progress(done: int, total: int) -> None:
            bar.update(round(100 * done / total) - bar.n)

        path_file = None if desired is None else {"path_file": str(args.path)}
        try:
            result = experiment.run(progress=progress, metadata=path_file)
        except SimulationError as exc:
            if args.out is not None and exc.result is not None:
                raise _partial_results_saved(args.out, inputs, exc, robot_text) from exc
            raise
    _print_summary(result.summary())
    if args.out is not None:
        _save_run(args.out, inputs, result, robot_text)
    return 0


def _check_simulate_options(args: argparse.Namespace) -> dict[str, Any]:
    """Refuse, before any work, options that describe no run (neither or both of ``--case`` and
    ``--path``, a criterion's option without its criterion, the switching method's options where
    they cannot apply, an option the run would not use); the switching method's options
    (:func:`_scm_options`)."""
    if (args.case is None) == (args.path is None):
        raise InputError("give exactly one of --case 1|2 and --path FILE")
    _criterion(args)  # a criterion option without its criterion: refused before the work
    tool_task_keywords(args.axis, args.cone_degrees, args.entry_point, names=TOOL_FLAGS)  # naming the flags
    scm_options = _scm_options(args)  # refused before any work
    _unused_options(args)
    return scm_options


def _simulate_gains(args: argparse.Namespace, robot: Robot) -> tuple[_Gain, _Gain]:
    """``--kp`` and ``--kv`` for ``robot``'s joints (None: the case's), refused when the switching
    method cannot start from them (:func:`_check_scm_gains`)."""
    kp = None if args.kp is None else joint_gains(args.kp, "--kp", robot.joint_names)
    kv = None if args.kv is None else joint_gains(args.kv, "--kv", robot.joint_names)
    if args.controller == "scm" and (kp is not None or kv is not None):  # the GA's genes must hit them
        _check_scm_gains(args, robot.n_joints, kp, kv)
    return kp, kv


def _experiment(
    args: argparse.Namespace, robot: Robot, desired: DesiredPath | None, gains: tuple[_Gain, _Gain]
) -> Experiment:
    """The experiment of ``vgtarm simulate``'s arguments (a preset's settings already in ``args``):
    ``--case`` or the path ``desired`` on ``robot``, every declared option's flag, the gains."""
    options = {name: getattr(args, name) for name in all_options() if hasattr(args, name)}
    options.update(kp=gains[0], kv=gains[1])
    if args.case is not None:
        return Experiment(case=args.case, robot=robot, preset=args.preset, options=options)
    return Experiment(path=desired, robot=robot, preset=args.preset, options=options)


def _partial_results_saved(
    out: Path, inputs: list[Path | None], exc: SimulationError, robot_text: str | None
) -> SimulationError:
    """The error of the failed run of ``exc`` once its results up to the failure are in ``out``
    (replaced whole: no figure of an earlier run stays beside them), or could not be written: one
    line, the failure (cut so that the note is never cut off), then where its results are."""
    from ...simulation.result import ROBOT_COPY, RUN_FILES

    try:
        with (
            placements() as moved,
            atomic_folder(out, "--out", inputs=inputs, owned=RUN_FILES, checked=True) as partial,
        ):
            exc.result.save(partial)  # type: ignore[attr-defined]
            if robot_text is not None:
                atomic_write_text(partial / ROBOT_COPY, robot_text)
    except (VgtarmError, OSError, ValueError) as failure:
        note = f"partial results not written: {cut(str(failure), 120)}"
    else:
        where = moved.get(out, out)  # beside it if the folder gained a user's file
        note = f"partial results (up to the failure, success false) written to {cut(str(where), 200)}"
    return SimulationError(f"{cut(str(exc), 200)}; {note}", exc.result)


#: The lines of ``vgtarm simulate``'s summary, in order: these keys of the run's summary.
_SUMMARY_KEYS = (
    "case",
    "path",
    "path_file",
    "kp",
    "kv",
    "ik_criterion",
    "controller",
    "external_force",
    "integrator",
    "reference_rates",
    "seed",
    "observer",
    "observer_gain_per_s",
    "estimator",
    "force_sensor",
    "sensing",
    "simulated_time_s",
    "wall_time_s",
    "real_time_factor",
    "max_tip_error_m",
    "rms_tip_error_m",
    "max_tip_error_after_transient_m",
    "max_axis_error_rad",
    "max_axis_error_after_transient_rad",
    "max_entry_distance_m",
    "peak_force_n",
    "rms_force_n",
    "chatter_n",
    "actuator_energy_j",
    "ga_activations",
    "ga_time_s",
    "actuator_peak_utilisation",
    "actuator_time_at_limit_s",
    "path_centre_m",
    "path_scale",
    "ik_task",
)


def _print_summary(summary: dict[str, Any]) -> None:
    """Print ``summary``'s :data:`_SUMMARY_KEYS`, one per line (a gain the same on every joint: one number)."""
    for key in _SUMMARY_KEYS:
        if key not in summary:  # the path placement: only on a robot other than the paper's
            continue
        value = summary[key]
        if isinstance(value, list) and len(set(value)) == 1:
            value = value[0]  # one gain for every joint
        if isinstance(value, dict):  # per joint (the actuators'): "s1 0.905, v1 1, ..."
            text = ", ".join(f"{escape(str(name))} {v:.3g}" for name, v in value.items() if v is not None)
        else:
            text = f"{value:.6g}" if isinstance(value, float) else escape(str(value))
        print(f"{key:<34} {text}")


def _save_run(out: Path, inputs: list[Path | None], result: SimulationResult, robot_text: str | None) -> None:
    """Write the run, its figure and the robot's file as the folder ``out``; say where it went."""
    from ...simulation.result import ROBOT_COPY, RUN_FILES
    from ..pictures.plotting import comparison_figure, save_figure

    with (
        placements() as moved,
        atomic_folder(out, "--out", inputs=inputs, owned=RUN_FILES, checked=True) as written,
    ):
        result.save(written)
        save_figure(comparison_figure([result]), written / "figure.png")
        if robot_text is not None:  # animate and report find the run's robot by it
            atomic_write_text(written / ROBOT_COPY, robot_text)
    print(f"results written to {escape(str(moved.get(out, out)))}")  # escaped: never drives the terminal


def _scm_options(args: argparse.Namespace) -> dict[str, Any]:
    """``--scm-hold`` and ``--scm-switch-on`` as options of the safe switching method, refused in one
    line naming the option where they cannot apply (the run's summary records them: ``scm_hold``,
    ``scm_switch_on``)."""
    given = {
        flag: value
        for flag, value in (("--scm-hold", args.scm_hold), ("--scm-switch-on", args.scm_switch_on))
        if value is not None
    }
    if not given:
        return {}
    shown_flags = " ".join(f"{flag} {shown(value)}" for flag, value in given.items())
    if args.controller != "scm":
        raise InputError(f"{shown_flags}: options of the switching method; expected --controller scm")
    if args.scm_variant != "safe":
        raise InputError(
            f"{shown_flags} with --scm-variant {args.scm_variant}: the paper's variant holds a gain set for its"
            " sample only and switches on the true error; expected --scm-variant safe"
        )
    if args.scm_hold is not None and args.scm_hold > args.horizon:
        raise InputError(
            f"--scm-hold {args.scm_hold}: expected at most the GA's horizon (--horizon {args.horizon}) control periods"
        )
    return {"hold": args.scm_hold, "switch_on": args.scm_switch_on}


def _unused_options(args: argparse.Namespace) -> None:
    """Refuse, in one line naming the option, one the user typed (even with its default value,
    :func:`.presets.given`) that this run would not use: the switching method's options with
    ``--controller cfc``, the velocity filter without sensing."""
    keys = [key for key in ("scm_variant", "horizon") if presets.given(args, key)]
    if keys and args.controller != "scm":
        typed = " ".join(f"--{key.replace('_', '-')} {shown(getattr(args, key))}" for key in keys)
        raise InputError(
            f"{typed}: {'options' if len(keys) > 1 else 'an option'} of the switching method; expected --controller"
            f" scm (--controller {args.controller} does not use {'them' if len(keys) > 1 else 'it'})"
        )
    if presets.given(args, "velocity_filter_hz") and not senses(vars(args)):
        raise InputError(
            f"--velocity-filter {shown(args.velocity_filter_hz)}: filters the velocities differenced from encoders; "
            "expected --encoder-resolution or --velocity-noise (without them the controller sees the true velocities)"
        )


def _check_scm_gains(
    args: argparse.Namespace, n_joints: int, kp: float | tuple[float, ...] | None, kv: float | tuple[float, ...] | None
) -> None:
    """Refuse, naming ``--kp``/``--kv``, gains the switching method cannot start from."""
    from ...experiment.cases import PATH_GAINS_CASE, case_study

    case = case_study(args.case or PATH_GAINS_CASE).with_gains(kp, kv)
    try:
        case.controller("scm", horizon=args.horizon, n_joints=n_joints, variant=args.scm_variant)
    except InputError as exc:
        given = ", ".join(f"--{k} {shown(getattr(args, k))}" for k in ("kp", "kv") if getattr(args, k) is not None)
        raise InputError(
            f"{given} with --controller scm --scm-variant {args.scm_variant}: {exc} (the case's own gains are)"
        ) from None


def cmd_reproduce(args: argparse.Namespace) -> int:
    """Run every combination the paper reports and write report.md."""
    from tqdm import tqdm

    from ..pool import default_workers
    from ..reports.reproduce import REPRODUCE_FILES, paper_runs, reproduce

    check_output_folder(args.out, "--out", inputs=[args.config], owned=REPRODUCE_FILES)  # before the work
    robot = load_robot(args.config)
    runs = paper_runs()
    with placements() as moved, tqdm(total=len(runs), desc="reproduce", unit="run", disable=args.quiet) as bar:

        def progress(label: str, done: int, total: int) -> None:
            bar.set_postfix_str(label)
            bar.update(done - bar.n)

        made = reproduce(
            robot,
            args.out,
            seed=args.seed,
            integrator=args.integrator,
            substeps=args.substeps,
            progress=progress,
            seeds=args.seeds,
            config=args.config,
            workers=args.workers or default_workers(),
            duration=args.duration,
        )
    print(f"{'run':<26} {'max (mm)':>10} {'after 0.2 s (mm)':>17} {'GA':>5} {'wall (s)':>9}")
    for spec, result in made.results.items():
        s = result.summary()
        after = s["max_tip_error_after_transient_m"]  # None: a run shorter than the transient (--duration)
        after_text = "-" if after is None else f"{after * 1e3:.4f}"
        print(
            f"{spec.folder:<26} {s['max_tip_error_m'] * 1e3:>10.4f} {after_text:>17}"
            f" {s['ga_activations']:>5} {s['wall_time_s']:>9.3f}"
        )
    report = moved.get(args.out, args.out) / made.report.name  # beside it if the folder gained a user's file
    shown_report = f"{escape(str(report))} and {escape(str(report.with_suffix('.html')))}"
    print(f"report written to {shown_report} ({made.wall_time_s:.1f} s)")
    return 0


def _ik_path(args: argparse.Namespace) -> DesiredPath:
    """The desired path of ``vgtarm ik``: ``--case 1|2`` or ``--path FILE``, sampled at ``--dt``."""
    dt = None
    if args.dt is not None:
        try:
            dt = float(args.dt)
        except ValueError:
            raise InputError(f"--dt must be a sampling period in seconds, got {shown(args.dt)}") from None
        if not (np.isfinite(dt) and dt > 0):
            raise InputError(f"--dt must be a finite period > 0 s, got {shown(args.dt)}")
    if (args.case is None) == (args.path is None):
        raise InputError("give exactly one of --case 1|2, --path FILE and --point X,Y,Z")
    if args.path is not None:
        return paths.from_csv(args.path, dt)
    if args.case not in ("1", "2"):
        raise InputError(f"--case must be 1 or 2, got {args.case!r}")
    period = 1e-3 if dt is None else dt
    return paths.case1(period) if args.case == "1" else paths.case2(period)


def _check_ik_memory(args: argparse.Namespace, path: DesiredPath) -> None:
    """Refuse, naming the flags, a path whose inverse kinematics will not fit in memory."""
    from ...ik.solve import memory_estimate
    from ...memory import check_memory

    source = f"--path {shown(str(args.path), 200)}" if args.path is not None else f"--case {args.case}"
    spacing = f"--dt {path.dt:g} s" if args.dt is not None else f"dt {path.dt:g} s"
    check_memory(
        memory_estimate(len(path), args.pose is not None or args.axis is not None or args.entry_point is not None),
        f"{source} at {spacing}: {len(path):,} samples of inverse kinematics",
        "give a larger --dt or a shorter path",
    )


def _criterion(args: argparse.Namespace) -> dict[str, Any]:
    """The inverse kinematics' criterion options of ``--criterion`` (and ``--tool-force``; ``simulate``: the
    case's cutting force when ``--external-force`` is given)."""
    force = getattr(args, "tool_force", None)
    weight = getattr(args, "joint_limit_weight", None)
    if hasattr(args, presets.GIVEN) and not presets.given(args, "joint_limit_weight"):
        weight = None  # simulate's flag holds the declared default: only a typed weight counts
    if args.criterion == "joint_limits":  # a --tool-force is refused by the options, with its reason
        if weight is not None:
            raise InputError(f"--joint-limit-weight {weight!r}: applies to --criterion effort only")
        return {} if force is None else {"tool_force": force}
    if force is None:
        from ...simulation import ExternalForce

        force = ExternalForce().cutting_force if getattr(args, "external_force", False) else 0.0
    return {
        "criterion": args.criterion,
        "tool_force": force,
        **({} if weight is None else {"joint_limit_weight": weight}),
    }


def _ik_rotation(args: argparse.Namespace) -> np.ndarray | str | None:
    """``--pose``: None, ``"hold"`` or the rotation ``(3, 3)`` of its nine numbers."""
    if args.pose is None or args.pose == "hold":
        return args.pose
    return numbers(args.pose, "--pose", 9, "the rotation C03 row by row, R11,R12,...,R33").reshape(3, 3)


def _ik_task_line(rotation: object, pointing: dict[str, Any]) -> str:
    """What ``vgtarm ik`` solved, in words."""
    if "cone" in pointing:
        return "tip position and the tool's axis within --cone of --axis, its spin free"
    if "axis" in pointing:
        return "tip position and the tool's axis along --axis, its spin free"
    if "entry_point" in pointing:
        return "tip position and the tool's axis through --entry-point"
    return {
        None: "tip position, orientation free",
        "hold": "tip position and orientation held from the first sample",
    }.get(rotation if isinstance(rotation, str | None) else "", "tip position and the orientation of --pose")


def _ik_point(args: argparse.Namespace) -> tuple[float, np.ndarray] | None:
    """The time (s) and the point (m) of ``--point`` (time 0) or of a one-row ``--path`` file; None for a path."""
    if args.point is not None:
        if args.case is not None or args.path is not None:
            raise InputError("give exactly one of --case 1|2, --path FILE and --point X,Y,Z")
        if args.dt is not None:
            raise InputError(f"--dt {shown(args.dt)}: a single --point has no sampling period; leave --dt out")
        return 0.0, numbers(args.point, "--point", 3, "the tip point x,y,z in m")
    if args.path is not None and args.case is None:
        sample = paths.csv_point(args.path)
        if sample is not None and args.dt is not None:
            raise InputError(
                f"--dt {shown(args.dt)}: --path {shown(str(args.path), 200)} has one row, a single point with no "
                "sampling period; leave --dt out"
            )
        return sample
    return None


def cmd_ik(args: argparse.Namespace) -> int:
    """Inverse kinematics of a desired path, or of one point: write the joint reference as CSV and print a summary."""
    if args.output is not None:  # before the work; never over the path file it reads
        check_output_file(args.output, "-o", inputs=[args.path, args.config])
    rotation = _ik_rotation(args)
    pointing = ik_pointing(args)
    point = _ik_point(args)
    if point is not None:
        return _ik_one_point(args, point, rotation, pointing)
    path = _ik_path(args)
    _check_ik_memory(args, path)
    robot = load_robot(args.config)
    if args.case is not None and robot.is_stack:  # the case paths placed on the robot (app/cases.py)
        from ...experiment.cases import path_placement

        placement = path_placement(robot)
        path = path if placement is None else placement.apply(path)
    if "entry_point" in pointing:  # refused naming the flag, before the work
        from ...ik.axis import entry_point_target

        entry_point_target(pointing["entry_point"], path.position, path.velocity, path.acceleration, "--entry-point")
    with progress_bar("inverse kinematics", "sample", len(path)):  # a long path or a large stack takes seconds
        result = robot.inverse_kinematics(
            path, solver=args.solver, rates=args.rates, pose=rotation, **pointing, **_criterion(args)
        )
    if not result.success:
        raise UnreachableError(f"inverse kinematics did not verify every sample: {result.message}; nothing written")
    if args.output is not None:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        write_csv(result, args.output)
    samples = result.samples
    worst = int(np.argmax(samples.residual))
    largest = int(np.argmax(samples.phi))
    task = _ik_task_line(rotation, pointing)
    if result.task_space.endswith(("plane", "line")):  # a robot whose tip moves in a plane or a line
        task = f"{result.task_space} (its tip cannot leave it), orientation free"
    span = f"dt = {path.dt:g} s, t = {path.t[0]:g} .. {path.t[-1]:g} s"
    print(f"path       {escape(path.name)}: {len(result)} samples, {span}")  # the name of a user's file, escaped
    print(f"task       {task}")
    print(f"solver     {result.solver}, rates {result.rates}, {result.wall_time_s * 1e3:.1f} ms")
    fallbacks = int(np.count_nonzero(np.char.find(samples.method.astype(str), "fallback") >= 0))
    print(f"result     {result.message}; {fallbacks} samples re-solved by the reference solver")
    print(f"residual   worst {samples.residual[worst]:.3g} m at t = {result.t[worst]:.6g} s")
    if rotation is not None or pointing:
        what = "orientation error" if rotation is not None else "axis error"
        if "cone" in pointing:
            what = f"axis angle from --axis (cone {np.degrees(pointing['cone']):g} degrees)"
        print(f"           worst {what} {np.nanmax(samples.orientation_error):.3g} rad")
    if samples.entry_distance is not None:
        print(f"           worst distance of the axis from the entry point {samples.entry_distance.max():.3g} m")
    print(f"Phi        largest {samples.phi[largest]:.6g} at t = {result.t[largest]:.6g} s")
    print("limits     closest approach to each joint limit over the path")
    below, above = result.limit_clearance()
    for i, name in enumerate(robot.joint_names):
        side, gap = ("min", below[i]) if below[i] <= above[i] else ("max", above[i])
        column = result.q[:, i] - result.lower[i] if side == "min" else result.upper[i] - result.q[:, i]
        when = result.t[int(np.argmin(column))]
        print(f"           {name:<5} {gap:.6g} {robot.joint_units[i]} from its {side} at t = {when:.6g} s")
    if args.output is not None:
        columns = f"{', '.join(CSV_COLUMNS[:4])}, joints, rates, accelerations"
        print(f"output     {escape(str(args.output))} ({len(result)} rows: {columns})")
    return 0


def _ik_one_point(
    args: argparse.Namespace,
    sample: tuple[float, np.ndarray],
    rotation: np.ndarray | str | None,
    pointing: dict[str, Any],
) -> int:
    """``vgtarm ik --point`` (or a one-row path file): the configuration, its residual and its limit margins."""
    from ...ik import solve_point
    from ...ik.records import csv_columns

    if args.rates != "exact":  # checked although a point has no rates: a typo is never ignored
        from ...ik.rates import RATE_MODES

        if args.rates not in RATE_MODES:
            raise InputError(f"--rates {shown(args.rates)}: expected one of {', '.join(RATE_MODES)}")
    robot = load_robot(args.config)
    t, point = sample
    held = rotation is None or isinstance(rotation, str)  # "hold": the free optimum's own orientation
    solution = solve_point(
        robot, point, rotation=None if held else rotation, solver=args.solver, **pointing, **_criterion(args)
    )
    if not solution.success:
        raise UnreachableError(f"{solution.message}; nothing written")
    if args.output is not None:
        row = np.concatenate([[t], solution.point, solution.q, np.zeros(2 * robot.n_joints)])
        line = ",".join(f"{v:.17g}" for v in row)
        atomic_write_text(args.output, ",".join(csv_columns(robot.joint_names)) + "\n" + line + "\n")
    source = f"the one row of --path {escape(str(args.path))}" if args.point is None else "--point"
    print(f"point      {_format_vector(solution.point, 10)} m, from {source}")
    from ...experiment.cases import reduced_space

    space = reduced_space(robot)  # a robot whose tip moves in a plane or a line: that reduced task
    tip_task = "tip position" if space is None else f"{space.label} (its tip cannot leave it)"
    orientation = "free" if held else "of --pose"
    if pointing:
        where = "within --cone of --axis" if "cone" in pointing else "along --axis"
        orientation = "the tool's axis " + (where if "axis" in pointing else "through --entry-point")
    print(f"task       {tip_task}, orientation {orientation}")
    print(f"result     {solution.message}")
    print(f"residual   {solution.residual:.3g} m")
    if not held or pointing:
        print(f"           {'axis' if pointing else 'orientation'} error {solution.orientation_error:.3g} rad")
    print(f"Phi        {solution.phi:.6g}")
    print("q          name   value            to min       to max")
    for i, name in enumerate(robot.joint_names):
        low, high = solution.margins[i]
        unit = robot.joint_units[i]
        print(f"           {name:<6} {solution.q[i]:<16.10g} {low:<12.6g} {high:<12.6g} {unit}")
    i, side, gap = solution.closest_limit
    print(f"closest    {robot.joint_names[i]} is {gap:.6g} {robot.joint_units[i]} from its {side}")
    if args.output is not None:
        print(f"output     {escape(str(args.output))} (1 row: t, x, y, z, joints, zero rates and accelerations)")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors echo a user's text escaped and cut, and which takes no
    abbreviated options (``--force`` silently meant ``--force-sensor``), and whose numbers
    (``type=float``, ``type=int``) are ASCII only (:func:`~.options.register_numbers`); subcommands
    inherit it."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        register_numbers(self)

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: error: {cut(message, MESSAGE_LENGTH - 100)}\n")


#: One option of a command: its names (or a positional's name) and the keywords of ``add_argument``.
_Flag = tuple[tuple[str, ...], dict[str, Any]]


def _add_flags(parser: argparse.ArgumentParser, flags: Sequence[_Flag]) -> None:
    """Declare ``flags`` on ``parser``, in their order (the order of ``--help``)."""
    for names, settings in flags:
        parser.add_argument(*names, **settings)


#: ``vgtarm simulate``'s flags before the options of the experiment (declared once, in
#: :mod:`vgtarm.experiment.options` and on the scenario's fields): the path and the gains.
_SIMULATE_FLAGS: tuple[_Flag, ...] = (
    (("--case",), dict(type=int, choices=(1, 2), default=None, help="the paper's case study 1 or 2")),
    (
        ("--path",),
        dict(
            type=Path,
            default=None,
            metavar="FILE",
            help="your own path instead: a CSV file of t,x,y,z rows (s, m), as for vgtarm ik, run at its own spacing",
        ),
    ),
    *(
        (
            (f"--{name}",),
            dict(
                default=None,
                metavar="K[,K...]",
                help=f"the {what}: one number for every joint or one per joint, comma-separated (default: the case's; "
                "a path: case 1's)",
            ),
        )
        for name, what in (("kp", "stiffness Kp (N/m, N m/rad)"), ("kv", "damping Kv (N s/m, N m s/rad)"))
    ),
)

#: ``vgtarm simulate``'s flags after the options: where the results go.
_SIMULATE_OUTPUT_FLAGS: tuple[_Flag, ...] = (
    (
        ("--out",),
        dict(type=Path, default=None, metavar="DIR", help="write summary.json, the time series and a figure here"),
    ),
)

#: ``vgtarm ik``'s flags (the robot's come after them).
_IK_FLAGS: tuple[_Flag, ...] = (
    (("--case",), dict(default=None, metavar="1|2", help="the paper's case study path 1 or 2")),
    (
        ("--path",),
        dict(type=Path, default=None, metavar="FILE", help="CSV file of t,x,y,z rows (s, m); one row: one point"),
    ),
    (
        ("--point",),
        dict(default=None, metavar="X,Y,Z", help="one tip point (m): its joint configuration, residual and margins"),
    ),
    (
        ("--pose",),
        dict(
            nargs="?",
            const="hold",
            default=None,
            metavar="C03",
            help="also the end-effector orientation: alone, that of the free-orientation optimum at the first sample "
            "(held); or nine numbers R11,R12,...,R33, the rotation C03 row by row (as vgtarm fk prints it)",
        ),
    ),
    (
        ("--axis",),
        dict(
            default=None,
            metavar="X,Y,Z",
            help="also the tool's axis along this unit vector (base frame), its spin free: a drill's axis",
        ),
    ),
    (
        ("--entry-point",),
        dict(
            default=None,
            metavar="X,Y,Z",
            help="also the tool's axis through this point (m) while the tip follows the path: keyhole work",
        ),
    ),
    (
        ("--cone",),
        dict(default=None, metavar="DEG", help="with --axis: the tool's axis within this half-angle of it (degrees)"),
    ),
    (("--solver",), dict(default="fast", metavar="NAME", help="fast (default), reference, slsqp or ipopt")),
    (("--rates",), dict(default="exact", metavar="MODE", help="exact (default) or finite_difference")),
    (("--dt",), dict(default=None, metavar="DT", help="sampling period in s (case: 0.001; file: its own)")),
    (
        ("--criterion",),
        dict(choices=("joint_limits", "effort"), default="joint_limits", help="eq. 12 (default) or effort"),
    ),
    (("--tool-force",), dict(type=float, default=None, metavar="N", help="expected cutting force (effort; 0)")),
    (
        ("--joint-limit-weight",),
        dict(type=positive_float, default=None, metavar="W", help="eq. 12's weight (effort; 0.5)"),
    ),
    (("-o", "--output"), dict(type=Path, default=None, metavar="FILE", help="CSV file to write")),
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    parser = _Parser(
        prog="vgtarm",
        description="Model, plan and control the 7-DOF redundant hybrid VGT manipulator.",
    )
    parser.add_argument("--version", action="version", version=f"vgtarm {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    describe = sub.add_parser("describe", help="print the robot and its model at the home pose")
    add_config(describe)
    describe.set_defaults(run=cmd_describe)

    fk = sub.add_parser("fk", help="forward kinematics of one configuration")
    fk.add_argument(
        "q",
        nargs="+",
        type=float,
        metavar="Q",
        help=f"joint values in the order {' '.join(JOINT_NAMES)} (m, rad); a stack: one per joint, in its order",
    )
    add_config(fk)
    fk.set_defaults(run=cmd_fk)

    _add_simulate_parser(sub)
    _add_reproduce_parser(sub)
    ik = sub.add_parser("ik", help="joint reference of a desired tip path (inverse kinematics, paper eq. 12)")
    _add_flags(ik, _IK_FLAGS)
    add_config(ik)
    ik.set_defaults(run=cmd_ik)
    cli_mujoco.add_parsers(sub)  # export mjcf, check mujoco
    cli_visual.add_parsers(sub)  # draw, animate, report
    cli_study.add_parsers(sub)  # study init, run, report
    cli_stack.add_parsers(sub)  # convert-robot
    cli_retime.add_parser(sub)  # retime
    cli_workspace.add_parser(sub)  # workspace
    cli_stiffness.add_parser(sub)  # stiffness
    cli_calibrate.add_parser(sub)  # calibrate
    cli_identify.add_parser(sub)  # identify
    cli_drill.add_parser(sub)  # drill
    cli_drill_study.add_parser(sub)  # drill-study
    _add_quiet(sub)
    _accept_negative_numbers(parser)

    return parser


def _add_simulate_parser(sub: argparse._SubParsersAction) -> None:
    """``vgtarm simulate``: its own flags, the observer's, the estimator's and the presets', the
    plant and the output, a run's and the robot's; then what the user typed is recorded."""
    simulate = sub.add_parser("simulate", help="run one of the paper's case studies or your own path")
    _add_flags(simulate, _SIMULATE_FLAGS)
    add_option_flags(simulate)  # every declared option of an experiment that has a flag
    presets.add_preset_flag(simulate)
    _add_flags(simulate, _SIMULATE_OUTPUT_FLAGS)
    simulate.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    add_config(simulate)
    presets.record_given(simulate)  # every option added: what the user typed, for the preset and the checks
    simulate.set_defaults(run=cmd_simulate)


def _add_reproduce_parser(sub: argparse._SubParsersAction) -> None:
    """``vgtarm reproduce``: the output folder, the seeds, the workers and the duration, then a run's
    and the robot's flags."""
    from ..reports.seeds import MAX_SEEDS

    again = sub.add_parser("reproduce", help="run every case the paper reports and write report.md")
    flags: tuple[_Flag, ...] = (
        (
            ("--out",),
            dict(type=Path, default=Path("results"), metavar="DIR", help="output folder (default: results)"),
        ),
        (
            ("--seeds",),
            dict(
                type=positive_int_at_most(MAX_SEEDS, "seeds"),
                default=None,
                metavar="N",
                help="also run everything with seeds 0..N-1 on Dask and report mean and spread (needs the study extra)",
            ),
        ),
        (
            ("--workers",),
            dict(
                type=positive_int,
                default=None,
                metavar="N",
                help="worker processes for the runs and figures (default: the CPUs, at most 4; 1: all in this process)",
            ),
        ),
        (
            ("--duration",),
            dict(
                type=positive_float,
                default=None,
                metavar="S",
                help="run only the first S seconds of each case path (a quick look; default: the whole path)",
            ),
        ),
    )
    _add_flags(again, flags)
    add_option_flags(again, ("integrator", "substeps", "seed"))
    again.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    add_config(again)
    again.set_defaults(run=cmd_reproduce)


def _add_quiet(sub: argparse._SubParsersAction) -> None:
    """Give every command ``-q``/``--quiet`` (no progress of any kind: bars, a model build's lines)."""
    for command in set(sub.choices.values()):
        for action in command._actions:
            if isinstance(action, argparse._SubParsersAction):
                _add_quiet(action)
        if "-q" not in command._option_string_actions and not any(
            isinstance(action, argparse._SubParsersAction) for action in command._actions
        ):
            command.add_argument("-q", "--quiet", action="store_true", help="no progress of any kind")


#: What argparse takes for a negative number rather than an option: its own pattern (``-1``,
#: ``-.5``) extended to exponents (``-1e-3``, ``-1E+2``, ``-2.e5``), ``-inf``/``-nan`` and lists
#: of numbers separated by commas that start with a negative one (``--point -0.02,0,0.64``), so a
#: negative value in any form can be given as a positional value or an option's value.
_NUMBER = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|(inf|infinity|nan)"
NEGATIVE_NUMBER = re.compile(rf"^-({_NUMBER})(,\s*[-+]?({_NUMBER}))*$", re.IGNORECASE)


def _accept_negative_numbers(parser: argparse.ArgumentParser) -> None:
    """Give ``parser`` and every subparser under it the :data:`NEGATIVE_NUMBER` pattern."""
    parser._negative_number_matcher = NEGATIVE_NUMBER  # argparse's hook (private, stable since 3.2)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in set(action.choices.values()):
                _accept_negative_numbers(child)


#: Exit status when the reader of standard output went away (``vgtarm describe | head -1``): what a
#: tool killed by SIGPIPE reports (128 + 13), like ``cat`` or ``yes``; nothing is printed.
CLOSED_PIPE = 141


def _silence_stdout() -> None:
    """Point standard output at the null device, so that the flush at exit does not print
    "Broken pipe" either (the way the Python docs recommend)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # standard output without a descriptor (captured in tests)
        pass


def _stdout_reader_gone() -> bool:
    """Whether standard output is a pipe whose reader has gone (not another pipe that broke)."""
    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & (select.POLLERR | select.POLLHUP) for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll() here, or no descriptor: assume it is
        return True


def _error_line(exc: BaseException) -> str:
    """The one line printed for an error: escaped and cut, whatever the message holds (a last guard)."""
    return f"vgtarm: error: {cut(str(exc), MESSAGE_LENGTH - 60)}"


#: Exit status of an interrupted command (Ctrl-C): 128 + SIGINT, as a shell reports it.
INTERRUPTED = 130
#: Exit status of a command ended by SIGTERM: 128 + SIGTERM.
TERMINATED = 143


def _exit_interrupted(status: int = INTERRUPTED) -> NoReturn:
    """End the program at once after Ctrl-C (or SIGTERM: ``status`` 143), without the interpreter's clean-up.

    Everything that must be undone (temporary files and folders, worker processes, compiler
    runs) was undone while the ``KeyboardInterrupt`` unwound the command; what is left is module
    teardown, which takes up to a second on a busy machine with matplotlib and CasADi loaded."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more can be shown anyway
            pass
    os._exit(status)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``vgtarm`` command.

    Ctrl-C at any point after start-up prints ``vgtarm: interrupted`` and gives status 130; a
    SIGTERM (handled from :mod:`vgtarm._entry`, which raises :class:`~vgtarm.errors.Terminated`)
    unwinds the command the same way and prints ``vgtarm: terminated``, status 143. Run as the
    program (``argv`` None) it then exits at once (:func:`_exit_interrupted`)."""
    try:
        status = _main(argv)
        if not Terminated.arrived:
            return status
        raise Terminated  # it arrived, but a library swallowed the exception: the command still ends so
    except KeyboardInterrupt as exc:
        ended = isinstance(exc, Terminated) or Terminated.arrived
        print("vgtarm: terminated" if ended else "vgtarm: interrupted", file=sys.stderr)
        status = TERMINATED if ended else INTERRUPTED
        if argv is None:
            _exit_interrupted(status)
        return status


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit:  # --help, --version or a usage error: a closed pipe stays quiet here too
        try:
            sys.stdout.flush()
        except BrokenPipeError:
            _silence_stdout()
        raise
    progress.set_quiet(bool(getattr(args, "quiet", False)))  # -q: no bar, no build progress lines
    model = getattr(args, "model", None)
    before = os.environ.get("VGTARM_MODEL")
    if model is not None:  # --model: every robot this command loads (and its worker processes)
        os.environ["VGTARM_MODEL"] = model
    try:
        status = int(args.run(args))
        sys.stdout.flush()  # a reader that went away shows here, not as a traceback at exit
        return status
    except BrokenPipeError as exc:
        if _stdout_reader_gone():
            _silence_stdout()
            return CLOSED_PIPE
        print(_error_line(exc), file=sys.stderr)  # another pipe (an encoder's, a socket)
        return 1
    except VgtarmError as exc:
        print(_error_line(exc), file=sys.stderr)
        return 1
    except OSError as exc:
        print(_error_line(exc), file=sys.stderr)
        return 1
    finally:
        if model is not None:  # the process's own choice again (main runs in tests, in-process)
            if before is None:
                os.environ.pop("VGTARM_MODEL", None)
            else:
                os.environ["VGTARM_MODEL"] = before
