"""``vgtarm draw``, ``vgtarm animate`` and ``vgtarm report``: see the robot.

Registered in :func:`vgtarm.app.cli.command.build_parser` by :func:`add_parsers`. Plotly and
imageio-ffmpeg (the ``viz`` extra) are imported only when a command needs them.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ...errors import InputError, escape
from ...fileio import atomic_folder, check_output_file, check_output_folder, placements, read_bytes_limited
from ...model.parameters import JOINT_NAMES, ROBOT_FILE_LIMIT
from ...model.robot import load_robot
from .options import add_model, positive_float

#: Picture formats of ``vgtarm draw``.
PICTURE_FORMATS = (".png", ".svg", ".pdf")


def _config(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config", type=Path, default=None, metavar="FILE", help="robot TOML file (default: the reference robot)"
    )
    add_model(parser)


def cmd_draw(args: argparse.Namespace) -> int:
    """Draw the robot at one configuration: its operating planes and an isometric view."""
    from ..pictures.drawing import pose_figure
    from ..pictures.plotting import save_figure

    if args.out.suffix.lower() not in PICTURE_FORMATS:
        raise InputError(f"--out {args.out}: expected a file name ending in one of {list(PICTURE_FORMATS)}")
    check_output_file(args.out, "--out", inputs=[args.config])
    robot = load_robot(args.config)
    q = args.q or robot.parameters.home
    if len(q) != robot.n_joints:
        raise InputError(f"Q: expected {robot.n_joints} joint values ({' '.join(robot.joint_names)}), got {len(q)}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_figure(pose_figure(robot, q), args.out)
    print(f"drawing written to {escape(str(args.out))}")  # escaped: a path never drives the terminal
    return 0


def robot_file_of_runs(config: Path | None, runs: list[Path]) -> Path | None:
    """The robot file for saved ``runs``: ``config`` when given; else the copy of the robot file
    the runs were made with (``robot.toml``, kept by ``simulate --out`` in the run's folder and by
    ``reproduce`` at the top of its folder, up to two levels above a run); else None, the
    reference robot. Runs made with different robot files are refused in one line."""
    if config is not None:
        return config
    copies = [_robot_copy(run) for run in runs]
    texts = {
        None if copy is None else read_bytes_limited(copy, ROBOT_FILE_LIMIT, "robot file of the run") for copy in copies
    }
    if len(texts) > 1:
        raise InputError(
            "the runs were made with different robots (compare their robot.toml files): give one robot with --config"
        )
    return copies[0] if copies else None


def run_inputs(runs: list[Path]) -> list[Path]:
    """What a command reads from saved ``runs`` (the run folders, their files, and the copies of
    the robot file :func:`robot_file_of_runs` may read): the inputs an output must not be."""
    from ...simulation.result import ROBOT_COPY

    files: list[Path] = []
    for run in runs:
        files += [run, run / "summary.json", run / "timeseries.csv", run / "ga_activations.csv"]
        files += [folder / ROBOT_COPY for folder in (run, run.parent, run.parent.parent)]
    return files


def _robot_copy(run: Path) -> Path | None:
    """The ``robot.toml`` of a run's folder, or of the reproduction (a folder with ``report.md``,
    one or two levels up) that holds it; None when there is none."""
    from ...simulation.result import ROBOT_COPY

    if (run / ROBOT_COPY).is_file():
        return run / ROBOT_COPY
    for folder in (run.parent, run.parent.parent):
        if (folder / ROBOT_COPY).is_file() and (folder / "report.md").is_file():
            return folder / ROBOT_COPY
    return None


def _load_run(folder: Path) -> Any:
    from ...simulation import SimulationResult

    return SimulationResult.load(folder)


def cmd_animate(args: argparse.Namespace) -> int:
    """Render a saved run as MP4 or GIF."""
    from ..pictures.animation import render_animation

    check_output_file(args.out, "--out", inputs=[args.config, *run_inputs([args.run_dir])])  # before any read
    run = _load_run(args.run_dir)  # a folder that is not a run: refused before any model is built
    robot = load_robot(robot_file_of_runs(args.config, [args.run_dir]))
    made = render_animation(robot, run, args.out, fps=args.fps, speed=args.speed, dpi=args.dpi, progress=not args.quiet)
    print(
        f"animation written to {escape(str(made.path))} ({len(made.plan)} frames at {made.plan.fps:g} fps,"
        f" {made.plan.duration_s:.3f} s of run at {made.plan.speed:g}x)"
    )
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Write report.html for saved runs."""
    from ..reports.html import PLOTLY_JS, load_runs, write_html_report
    from ..reports.runs import task_note

    inputs, owned = [*run_inputs(list(args.runs)), args.config], ("*.html", PLOTLY_JS)
    check_output_folder(args.out, "--out", inputs=inputs, owned=owned)  # before the work; never over a run
    runs = load_runs(args.runs)  # folders that are not runs: refused before any model is built
    robot = load_robot(robot_file_of_runs(args.config, list(args.runs)))
    intro = "Runs: " + ", ".join(p.name for p in args.runs)
    note = task_note(r.result.metadata for r in runs)  # a robot whose tip moves in a plane: its task
    intro = f"{intro}. {note}" if note else intro
    with placements() as moved, atomic_folder(args.out, "--out", inputs=inputs, owned=owned, checked=True) as folder:
        page = write_html_report(robot, runs, folder, title=args.title, intro=intro)
    where = moved.get(args.out, args.out)  # beside it if the folder gained a user's file during the run
    print(f"report written to {escape(str(where / page.name))}")
    return 0


def add_parsers(sub: Any) -> None:
    """Add ``draw``, ``animate`` and ``report`` to the subparsers ``sub``."""
    draw = sub.add_parser("draw", help="draw the robot at a configuration (its operating planes and isometric)")
    draw.add_argument(
        "q",
        nargs="*",
        type=float,
        metavar="Q",
        default=None,
        help=f"joint values {' '.join(JOINT_NAMES)} (m, rad); a stack: one per joint, in its order;"
        " none: the home pose",
    )
    draw.add_argument("--out", type=Path, required=True, metavar="FILE", help="picture file: .png, .svg or .pdf")
    _config(draw)
    draw.set_defaults(run=cmd_draw)

    animate = sub.add_parser("animate", help="animate a saved run (MP4, or GIF without the encoder)")
    animate.add_argument(
        "run_dir", type=Path, metavar="RUN_DIR", help="a folder written by simulate --out or reproduce"
    )
    animate.add_argument("--out", type=Path, required=True, metavar="FILE", help="video file: .mp4 or .gif")
    animate.add_argument("--fps", type=positive_float, default=25.0, help="frames per second of video (default 25)")
    animate.add_argument(
        "--speed", type=positive_float, default=1.0, help="simulated seconds per second of video (default 1)"
    )
    animate.add_argument("--dpi", type=positive_float, default=100.0, help="resolution; 100 gives 1280 x 640 (default)")
    animate.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    _config(animate)
    animate.set_defaults(run=cmd_animate)

    report = sub.add_parser("report", help="write an interactive report.html for saved runs")
    report.add_argument("runs", type=Path, nargs="+", metavar="RUN_DIR", help="folders of saved runs")
    report.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder of report.html")
    report.add_argument("--title", default="vgtarm: runs", help="title of the page")
    _config(report)
    report.set_defaults(run=cmd_report)
