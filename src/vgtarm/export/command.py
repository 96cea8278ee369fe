"""The command-line glue of ``vgtarm export controller`` (wired into the ``vgtarm`` command by the
app layer: ``add_arguments`` on its parser, ``run`` as its action).

``run`` raises :class:`~vgtarm.errors.VgtarmError` (or ``OSError``) for the command's one-line
error; it prints only the summary of a successful export.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..control.gains import gains_text
from ..errors import ConfigError, InputError, cut, escape, shown
from ..fileio import check_output_folder, parse_toml, read_text_limited
from ..model.parameters import ROBOT_FILE_LIMIT, RobotParameters, load_parameters
from ..model.robot import load_robot, robot_parameters_from_dict
from ..model.stack import Stack
from ..simulation.checks import model_of_plant
from ..simulation.sensing import DEFAULT_ESTIMATOR_BANDWIDTH_HZ, DEFAULT_VELOCITY_FILTER_HZ, check_twist_resolution
from .controller import export_controller, probe_compiler


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``vgtarm export controller``."""
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to write")
    parser.add_argument(
        "--config", type=Path, default=None, metavar="ROBOT", help="robot file (TOML; default: the paper's)"
    )
    parser.add_argument(
        "--observer", choices=("none", "momentum"), default="none", help="estimate of the external efforts"
    )
    parser.add_argument(
        "--observer-gain", type=float, default=None, metavar="K_O", help="observer gain (1/s; default 0.5/dt)"
    )
    parser.add_argument("--force-sensor", action="store_true", help="feed the measured tool force forward instead")
    parser.add_argument(
        "--switching",
        choices=("safe", "paper"),
        default=None,
        help="export switching control too, its GA in C (default: computed force control only)",
    )
    for name, what, unit, default in (("kp", "position", "1/s^2", 15000.0), ("kv", "velocity", "1/s", 600.0)):
        parser.add_argument(
            f"--{name}",
            default=None,
            metavar="K[,K...]",
            help=f"{what} gain ({unit}): one number for every joint or one per joint, comma-separated, each > 0 "
            f"(default: case 2's, {default:g})",
        )
    parser.add_argument("--dt", type=float, default=1e-3, help="control period (s)")
    parser.add_argument("--encoder-resolution", type=float, default=0.0, metavar="M", help="leg encoder step (m)")
    parser.add_argument("--twist-resolution", type=float, default=None, metavar="RAD", help="twist encoder step (rad)")
    parser.add_argument(
        "--velocity-filter-hz",
        type=float,
        default=None,
        metavar="HZ",
        help=f"with encoders: the cut-off of the filter of the differenced velocities (default "
        f"{DEFAULT_VELOCITY_FILTER_HZ:g})",
    )
    parser.add_argument(
        "--estimator",
        choices=("difference", "kalman"),
        default="difference",
        help="with encoders: velocities from differences through the filter (default), or the Kalman filter "
        "with the controller model (gains computed at export)",
    )
    parser.add_argument(
        "--estimator-bandwidth",
        type=float,
        default=None,
        metavar="HZ",
        help=f"--estimator kalman: its bandwidth (default {DEFAULT_ESTIMATOR_BANDWIDTH_HZ:g} Hz, at most 1/(4 dt))",
    )
    parser.add_argument(
        "--model-config", type=Path, default=None, metavar="ROBOT", help="the controller's model (default: the robot)"
    )


def _parameters(config: Path | None) -> RobotParameters | Stack:
    """The robot file ``config``'s parameters (the shipped reference robot for None), read as
    :func:`~vgtarm.model.robot.load_robot` reads them, without building a model."""
    if config is None:
        return load_parameters(None)
    text = read_text_limited(config, ROBOT_FILE_LIMIT, "configuration file", error=ConfigError)
    return robot_parameters_from_dict(parse_toml(text, cut(str(config), 200), error=ConfigError), source=str(config))


def _checked_options(args: argparse.Namespace) -> tuple[dict[str, Any], RobotParameters | Stack | None]:
    """The gains given and the controller model's parameters (None: the robot's), checked with the
    checks simulate uses (the gains as ``vgtarm simulate --kp/--kv`` reads them, the twist
    encoder, the model against the robot) from the robot files' parameters, before any model is
    built; an option that would be ignored (``--velocity-filter-hz`` without encoders) is refused."""
    if args.velocity_filter_hz is not None and not args.encoder_resolution and not args.twist_resolution:
        raise InputError(
            f"--velocity-filter-hz {shown(args.velocity_filter_hz)}: filters the velocities differenced from "
            "encoders; expected --encoder-resolution (without encoders the velocities are measured)"
        )
    robot = _parameters(args.config)
    gains: dict[str, Any] = {
        name: gains_text(text, f"--{name}", robot.joint_names)
        for name, text in (("kp", args.kp), ("kv", args.kv))
        if text is not None
    }
    check_twist_resolution(robot.joint_units, args.twist_resolution, "--twist-resolution")
    model = None if args.model_config is None else _parameters(args.model_config)
    if model is not None:
        model_of_plant(robot, model, f"--model-config {shown(str(args.model_config), 200)}")
    return gains, model


def run(args: argparse.Namespace) -> int:
    """Export the controller as the options say; prints the folder and what it holds."""
    check_output_folder(args.out, "--out", inputs=[args.config, args.model_config])
    gains, model = _checked_options(args)  # before any compiler runs or any model is built
    probe_compiler()  # a broken compiler: the export's one line, before the model falls back on it
    robot = load_robot(args.config)
    done = export_controller(
        robot,
        args.out,
        **gains,  # the gains given; else export_controller's, case 2's
        dt=args.dt,
        controller_model=model,
        observer=args.observer,
        observer_gain=args.observer_gain,
        force_sensor=args.force_sensor,
        encoder_resolution=args.encoder_resolution,
        twist_resolution=args.twist_resolution,
        velocity_filter_hz=DEFAULT_VELOCITY_FILTER_HZ if args.velocity_filter_hz is None else args.velocity_filter_hz,
        estimator=args.estimator,
        estimator_bandwidth_hz=args.estimator_bandwidth,
        switching=args.switching,
    )
    settings = done.settings
    print(
        f"wrote {escape(str(done.folder))}: controller of {escape(str(settings['robot']))} ({done.n_joints} joints,"
        f" observer "
        f"{settings['observer']}, velocities {settings['velocity']}"
        f"{' by the Kalman filter' if settings['estimator'] == 'kalman' else ''}, dt = {settings['dt_s']:g} s"
        f"{', switching control ' + settings['switching']['variant'] if settings['switching'] else ''}); "
        f"checked with {done.compiler or 'no compiler'}; build it with make or cmake (README.md)"
    )
    return 0
