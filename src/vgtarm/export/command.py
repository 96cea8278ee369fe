"""The command-line glue of ``vgtarm export controller`` (wired into the ``vgtarm`` command by the
app layer: ``add_arguments`` on its parser, ``run`` as its action).

The flags of what the controller measures and estimates are generated from the scenario's
declarations (:data:`~.controller.EXPORTED_OPTIONS`, as ``vgtarm simulate``'s are), and what the
user typed of them becomes the :class:`~vgtarm.simulation.Scenario` the export takes, by name.

``run`` raises :class:`~vgtarm.errors.VgtarmError` (or ``OSError``) for the command's one-line
error; it prints only the summary of a successful export.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

from ..control.gains import gains_text
from ..errors import ConfigError, InputError, cut, escape, shown
from ..fileio import check_output_folder, parse_toml, read_text_limited
from ..model.parameters import ROBOT_FILE_LIMIT, RobotParameters, load_parameters
from ..model.robot import load_robot, robot_parameters_from_dict
from ..model.stack import Stack
from ..option import Option
from ..simulation.checks import model_of_plant
from ..simulation.scenario import Scenario
from ..simulation.sensing import check_twist_resolution
from .controller import EXPORTED_OPTIONS, checked_sensing, export_controller, probe_compiler


def exported_options() -> dict[str, Option]:
    """The declarations of the scenario's options an export carries (:data:`EXPORTED_OPTIONS`), by
    name, each with a flag: its declared one, else ``--name`` (``vgtarm simulate`` has no flag for
    the twist's encoder: it gives the twist a 20-bit encoder; the export takes it)."""
    declared = Scenario.options()
    return {
        name: declared[name] if declared[name].cli_flag else dataclasses.replace(declared[name], flag=None)
        for name in EXPORTED_OPTIONS
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``vgtarm export controller``."""
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to write")
    parser.add_argument(
        "--config", type=Path, default=None, metavar="ROBOT", help="robot file (TOML; default: the paper's)"
    )
    options = exported_options()
    for declaration in options.values():
        declaration.add_to(parser)
    parser.set_defaults(**dict.fromkeys(options))  # None: not typed, the scenario's default
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


def _scenario(args: argparse.Namespace, model: RobotParameters | Stack | None) -> Scenario:
    """The scenario of the export: the options of :func:`exported_options` the user typed, by name
    (the others: the scenario's defaults), and the controller's model ``model``."""
    typed = {name: getattr(args, name) for name in EXPORTED_OPTIONS if getattr(args, name) is not None}
    return Scenario(**typed, controller_model=model)


def _checked_options(args: argparse.Namespace) -> tuple[dict[str, Any], Scenario]:
    """The gains given and the scenario, checked with the checks simulate uses (the gains as
    ``vgtarm simulate --kp/--kv`` reads them, the twist encoder, the model against the robot, the
    sensing as the export checks it) from the robot files' parameters, before any model is built;
    an option that would be ignored (the velocity filter without encoders) is refused."""
    robot = _parameters(args.config)
    gains: dict[str, Any] = {
        name: gains_text(text, f"--{name}", robot.joint_names)
        for name, text in (("kp", args.kp), ("kv", args.kv))
        if text is not None
    }
    twist = exported_options()["twist_resolution"]
    check_twist_resolution(robot.joint_units, getattr(args, twist.name), twist.cli_flag)
    model = None if args.model_config is None else _parameters(args.model_config)
    if model is not None:
        model_of_plant(robot, model, f"--model-config {shown(str(args.model_config), 200)}")
    scenario = _scenario(args, model)
    sensing = checked_sensing(robot.joint_units, args.dt, scenario)
    cutoff = exported_options()["velocity_filter_hz"]
    if getattr(args, cutoff.name) is not None and not sensing.active:
        raise InputError(
            f"{cutoff.cli_flag} {shown(getattr(args, cutoff.name))}: filters the velocities differenced from "
            "encoders; expected --encoder-resolution (without encoders the velocities are measured)"
        )
    return gains, scenario


def run(args: argparse.Namespace) -> int:
    """Export the controller as the options say; prints the folder and what it holds."""
    check_output_folder(args.out, "--out", inputs=[args.config, args.model_config])
    gains, scenario = _checked_options(args)  # before any compiler runs or any model is built
    probe_compiler()  # a broken compiler: the export's one line, before the model falls back on it
    robot = load_robot(args.config)
    done = export_controller(
        robot,
        args.out,
        scenario=scenario,
        **gains,  # the gains given; else export_controller's, case 2's
        dt=args.dt,
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
