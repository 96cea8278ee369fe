"""What the command line runs, as Python functions for a notebook or a script.

``vgtarm.run_study`` is :func:`run_study` here: the study runner of :mod:`vgtarm.study.runner`
with the points the ``vgtarm study`` command runs (:func:`~vgtarm.app.study_points.execute_point`,
checked first by :func:`~vgtarm.app.study_points.check_point`), so that a study file runs the same
from Python as from ``vgtarm study run``.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputError, shown
from ..fileio import check_writable_parent
from ..study.runner import StudyRun
from ..study.runner import run_study as _run_study
from ..study.spec import Study, load_study


def run_study(
    study: Study | str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = False,
) -> StudyRun:
    """Run (or resume) a study into the folder ``out``, as ``vgtarm study run`` does.

    Args:
        study: a study file (TOML, see ``vgtarm study init``) or a validated
            :class:`~vgtarm.study.Study`.
        out: the results folder; runs already stored there are not run again.
        scheduler: the address of a running Dask scheduler (``tcp://host:port``); default: a local
            cluster of ``workers`` processes started for this call.
        workers: processes of the local cluster (default: the number of cores).
        progress: print a progress bar on standard error.

    Returns:
        A :class:`~vgtarm.study.runner.StudyRun`: the table's rows, the counts and the wall time.

    Raises:
        ConfigError: a study file that is not valid (one line naming the key).
        InputError: ``out`` is a file or cannot be written.
    """
    from .study_points import check_point, execute_point

    if not isinstance(study, Study):
        if not isinstance(study, str | os.PathLike):
            raise InputError(f"study = {shown(study)}: expected a study file or a vgtarm.study.Study")
        study = load_study(Path(study))
    if not isinstance(out, str | os.PathLike):
        raise InputError(f"out = {shown(out)}: expected a folder name")
    folder = Path(out)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"out = {shown(str(folder))}: is a file, not a folder; give the study's results folder")
    check_writable_parent(folder, "out")
    return _run_study(
        study, folder, execute_point, check=check_point, scheduler=scheduler, workers=workers, progress=progress
    )
