"""``vgtarm drill-study``: a study of drilling runs over seeded bones, feeds, set points, modes and
feedbacks (:func:`vgtarm.drilling.study.run_drilling_study`), one row of measures per run.

The folder ``--out`` gets ``study.csv`` (a row per run: its inputs, the perturbed bone's layers and
the measures, SI units), ``summary.json`` (the runs meeting each target and every column's min,
median and max) and ``spread.png`` (protrusion, detection delay and thrust error RMS against the
feed limit, the targets drawn), atomically. Columns and methods: docs/drilling_study.md.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from ... import progress
from ...errors import escape
from ...fileio import atomic_folder, atomic_write_text, check_output_folder, json_value
from ...model.robot import load_robot
from .bars import progress_bar
from .options import add_config, positive_int

#: The files ``vgtarm drill-study`` writes in its folder (and may replace there).
DRILL_STUDY_FILES = ("study.csv", "summary.json", "spread.png")
#: How a column is printed: its scale from SI and its unit, by the start of its name.
UNITS = (
    ("thrust", 1.0, "N"),
    ("set_point", 1.0, "N"),
    ("at_feed_limit", 100.0, "%"),
    ("feed_limit", 1e3, "mm/s"),
    ("detection_delay", 1e3, "ms"),
    ("axis_error", 1e3, "mrad"),
    ("density", 1.0, "kg/m^3"),
    ("transition_delay", 1e3, "ms"),
    ("transitions", 1.0, ""),
    ("false", 1.0, ""),
    ("", 1e3, "mm"),  # protrusion, thickness, lateral deviation
)


def add_parser(sub: Any) -> None:
    """Register ``vgtarm drill-study`` on the ``vgtarm`` command's subparsers."""
    parser = sub.add_parser(
        "drill-study",
        help="a study of drilling runs over seeded bones and feeds: each run's measures against the targets",
        description=(
            "Drill every point of a drilling study file ([drilling_study]: bone files, seeds, spread, feed range or "
            "feed limits, set points, modes, feedbacks, shared settings): each seed's perturbed bone, the detector "
            "told only the nominal one; print each measure's min, median and max and the runs within the targets, "
            "and write study.csv, summary.json and spread.png."
        ),
    )
    parser.add_argument("study", type=Path, metavar="STUDY.toml", help="a drilling study file (examples/studies/)")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to write")
    parser.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        metavar="N",
        help="worker processes for the runs (default: the CPUs, at most 4; 1: all in this process)",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    add_config(parser)
    parser.set_defaults(run=cmd_drill_study)


def _scaled(name: str) -> tuple[float, str]:
    for start, scale, unit in UNITS:
        if name.startswith(start):
            return scale, unit
    return 1.0, ""  # not reached: the last entry matches every name


def spread_lines(spread: dict[str, dict[str, float]]) -> list[str]:
    """The printed table of :meth:`~vgtarm.drilling.study.DrillingStudyResult.spread`: a line per
    column, its min, median and max in the unit of :data:`UNITS`."""
    lines = [f"{'measure':<28} {'min':>10} {'median':>10} {'max':>10}  unit"]
    for name, stats in spread.items():
        scale, unit = _scaled(name)
        cells = [
            f"{scale * stats[k]:>10.4g}" if math.isfinite(stats[k]) else f"{'-':>10}" for k in ("min", "median", "max")
        ]
        lines.append(f"{name:<28} {' '.join(cells)}  {unit}")
    return lines


def cmd_drill_study(args: argparse.Namespace) -> int:
    """Run the study, print its spread and the runs within the targets, write the folder."""
    from ...drilling.study import check_drilling_study, load_drilling_study, run_drilling_study
    from ..pool import Workers, default_workers

    study = load_drilling_study(args.study)
    inputs = [args.config, args.study, *study.files]
    check_output_folder(args.out, "--out", inputs=inputs, owned=DRILL_STUDY_FILES)  # before the work
    robot = load_robot(args.config)
    check_drilling_study(robot, study)
    points = len(study.points())
    workers = min(args.workers or default_workers(), points)
    with progress_bar("drilling study", "run", points):
        if workers == 1:
            result = run_drilling_study(robot, study, progress=progress.report)
        else:
            with Workers(workers, robot.parameters, robot.backend.kind) as running:
                result = run_drilling_study(robot, study, pool=running, progress=progress.report)
    for line in spread_lines(result.spread()):
        print(line)
    counts = result.within_targets()
    met = ", ".join(f"{k.removeprefix('met_')} {v}" for k, v in counts.items() if k.startswith("met_"))
    print(f"within every target: {counts['within_targets']} of {counts['runs']} runs (each target met by: {met})")
    print(
        f"false detections: {counts['false_detections']} in {counts['runs_with_false_detections']} runs;"
        f" wall time {result.wall_time_s:.1f} s with {workers} worker(s)"
    )
    with atomic_folder(args.out, "--out", inputs=inputs, owned=DRILL_STUDY_FILES, checked=True) as folder:
        atomic_write_text(folder / "study.csv", result.table())
        atomic_write_text(folder / "summary.json", json.dumps(json_value(result.summary()), indent=2) + "\n")
        result.figure().savefig(folder / "spread.png", dpi=100)
    print(f"written    {escape(str(args.out))}: {', '.join(DRILL_STUDY_FILES)}")
    return 0
