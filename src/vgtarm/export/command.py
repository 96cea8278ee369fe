"""The command-line glue of ``vgtarm export controller`` (wired into the ``vgtarm`` command by the
app layer: ``add_arguments`` on its parser, ``run`` as its action).

``run`` raises :class:`~vgtarm.errors.VgtarmError` (or ``OSError``) for the command's one-line
error; it prints only the summary of a successful export.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import escape
from ..fileio import check_output_folder
from ..model.robot import load_robot
from ..simulation.sensing import DEFAULT_ESTIMATOR_BANDWIDTH_HZ
from .controller import export_controller


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
    parser.add_argument("--kp", type=float, default=15000.0, help="position gain, every joint (1/s^2; case 2's)")
    parser.add_argument("--kv", type=float, default=600.0, help="velocity gain, every joint (1/s; case 2's)")
    parser.add_argument("--dt", type=float, default=1e-3, help="control period (s)")
    parser.add_argument("--encoder-resolution", type=float, default=0.0, metavar="M", help="leg encoder step (m)")
    parser.add_argument("--twist-resolution", type=float, default=None, metavar="RAD", help="twist encoder step (rad)")
    parser.add_argument("--velocity-filter-hz", type=float, default=100.0, metavar="HZ", help="velocity filter cut-off")
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


def run(args: argparse.Namespace) -> int:
    """Export the controller as the options say; prints the folder and what it holds."""
    check_output_folder(args.out, "--out", inputs=[args.config, args.model_config])
    robot = load_robot(args.config)
    model = load_robot(args.model_config).parameters if args.model_config is not None else None
    done = export_controller(
        robot,
        args.out,
        kp=args.kp,
        kv=args.kv,
        dt=args.dt,
        controller_model=model,
        observer=args.observer,
        observer_gain=args.observer_gain,
        force_sensor=args.force_sensor,
        encoder_resolution=args.encoder_resolution,
        twist_resolution=args.twist_resolution,
        velocity_filter_hz=args.velocity_filter_hz,
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
