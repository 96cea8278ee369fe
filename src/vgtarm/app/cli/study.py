"""``vgtarm study init|run|report``: studies at scale on Dask (see :mod:`vgtarm.study`)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from ...errors import InputError, cut, escape
from ...fileio import (
    atomic_write_text,
    check_growing_folder,
    check_input_folder,
    check_output_file,
    check_writable_parent,
    describe,
)

#: The files ``study run`` and ``study report`` write in a study's folder, besides one ``<id>.json``
#: a run (see :mod:`vgtarm.study.store`).
STUDY_OUTPUTS = ("executions.log", "results.csv", "results.parquet", "report.md")


def _check_study_outputs(out: Path, inputs: list[Path]) -> None:
    """Refuse, in one line, a study folder ``out`` in which the study would write over one of its
    ``inputs`` (the study file, its robot and path files): one of them is (also through a link, a
    hard link or another path) a file the study writes there, or a run file of the folder. An
    existing output there that is not a regular file is refused too, before the runs rather than
    after them."""
    from ...study.store import LEGACY_RUNS, RUN_FILE

    for name in STUDY_OUTPUTS:
        check_output_file(out / name, "the study's file", inputs=inputs)
    for source in inputs:
        if not RUN_FILE.fullmatch(source.name) or not source.parent.is_dir():
            continue
        for runs in (out, out / LEGACY_RUNS):
            if runs.is_dir() and os.path.samefile(source.parent, runs):
                raise InputError(
                    f"--out {cut(str(out), 200)}: holds {cut(str(source), 200)} as a run file, but it is an input of"
                    " this command; choose another folder"
                )


def _check_study_folder(out: Path, inputs: list[Path]) -> None:
    """Refuse, in one line before any work, a results folder ``out`` that ``study run`` may not
    write in: not a folder; one of its files of fixed names is (another name of) an input; the
    current folder, an input or a folder holding one; a folder vgtarm did not make or recognise as
    a study folder of its own (:meth:`vgtarm.study.store.Store.check`)."""
    from ...study.store import Store

    if os.path.lexists(out) and not out.is_dir():  # a link to a folder is one: it grows where it leads
        raise InputError(
            f"--out {cut(str(out), 200)}: is {describe(out)}, not a folder; expected the study's results folder"
            " (a new or empty folder, or one an earlier run of the study wrote)"
        )
    check_writable_parent(out, "--out")  # a read-only file system: named for --out itself
    _check_study_outputs(out, inputs)  # an input at one of the study's file names: named as such
    check_growing_folder(out, "--out", inputs=inputs)
    Store(out).check("--out")


def _study_inputs(study_file: Path, study: object) -> list[Path]:
    """The study file and the robot and path files it names (relative to its folder)."""
    shared = getattr(study, "shared", {})
    named = [shared.get(key) for key in ("path", "robot")]
    return [study_file, *(study_file.parent / name for name in named if isinstance(name, str) and name)]


def cmd_study_init(args: argparse.Namespace) -> int:
    """Write the commented example study."""
    from ...study.example import EXAMPLE

    check_output_file(args.file, "FILE")  # a name, not a folder, in a folder we may write in
    if args.file.exists() and not args.force:
        raise InputError(f"{cut(str(args.file), 200)} exists; give --force to overwrite it")
    atomic_write_text(args.file, EXAMPLE)
    shown = escape(str(args.file))
    print(f"example study written to {shown}; run it with: vgtarm study run {shown} --out DIR")
    return 0


def cmd_study_run(args: argparse.Namespace) -> int:
    """Run (or resume) a study and write its tables."""
    from ...study.runner import run_study
    from ...study.spec import load_study
    from ..study_points import check_point, execute_point

    # The folder keeps finished runs to resume from (each run file is atomic): it grows, it is not
    # replaced; check it before the work.
    _check_study_folder(args.out, [args.study])  # before the study file is read
    study = load_study(args.study)
    _check_study_folder(args.out, _study_inputs(args.study, study))  # the files it names: before any write
    outcome = run_study(
        study,
        args.out,
        execute_point,
        check=check_point,
        scheduler=args.scheduler,
        workers=args.workers,
        progress=not args.quiet,
    )
    print(
        f"{outcome.points} runs: {outcome.skipped} already stored, {outcome.executed} run now, {outcome.failed} failed;"
        f" {outcome.wall_time_s:.1f} s"
    )
    print(f"results written to {escape(str(args.out / 'results.csv'))} and {escape(str(args.out / 'results.parquet'))}")
    if outcome.lost:
        print(f"{len(outcome.lost)} runs were lost with their workers; run the same command again to finish them")
        return 1
    return 0


def cmd_study_report(args: argparse.Namespace) -> int:
    """Write report.md and the figures of a study's results."""
    from ...study.report import write_report

    check_input_folder(args.folder, "DIR")  # a file, a pipe: refused before anything is read
    check_output_file(args.folder / "report.md", "the study's file", inputs=[args.folder / "results.parquet"])
    report = write_report(args.folder)
    print(f"report written to {escape(str(report))}")
    return 0


def add_parsers(sub: Any) -> None:
    """Register ``vgtarm study`` and its subcommands."""
    study = sub.add_parser("study", help="seeded sweeps and Monte Carlo studies of many runs on Dask")
    commands = study.add_subparsers(dest="study_command", required=True, metavar="STUDY_COMMAND")

    init = commands.add_parser("init", help="write a commented example study file")
    init.add_argument("file", type=Path, metavar="FILE")
    init.add_argument("--force", action="store_true", help="overwrite FILE")
    init.set_defaults(run=cmd_study_init)

    run = commands.add_parser("run", help="run or resume a study (only the runs not stored yet)")
    run.add_argument("study", type=Path, metavar="STUDY.toml")
    run.add_argument("--out", type=Path, required=True, metavar="DIR", help="results folder")
    run.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster on this machine)",
    )
    run.add_argument(
        "--workers", type=int, default=None, metavar="N", help="local cluster size (default: one per core)"
    )
    run.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    run.set_defaults(run=cmd_study_run)

    report = commands.add_parser("report", help="write report.md and figures from a study's results")
    report.add_argument("folder", type=Path, metavar="DIR")
    report.set_defaults(run=cmd_study_report)
