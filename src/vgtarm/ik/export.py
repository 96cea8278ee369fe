"""Writing the joint reference as CSV, atomically."""

from __future__ import annotations

import os

import numpy as np

from ..fileio import atomic_open
from ..model.parameters import JOINT_NAMES
from .records import IKResult

#: Columns of the CSV file: time, desired tip point, joints, rates, accelerations (SI units).
CSV_COLUMNS: tuple[str, ...] = (
    ("t", "x", "y", "z")
    + JOINT_NAMES
    + tuple(f"d{name}" for name in JOINT_NAMES)
    + tuple(f"dd{name}" for name in JOINT_NAMES)
)


def write_csv(result: IKResult, file: str | os.PathLike[str]) -> None:
    """Write one row per sample with the columns :data:`CSV_COLUMNS` (full double precision).

    The file is written atomically (:func:`vgtarm.fileio.atomic_open`): a reader never sees a
    partial file and nothing is left behind when writing fails.
    """
    table = np.column_stack([result.t, result.position, result.q, result.qd, result.qdd])
    with atomic_open(file) as stream:
        stream.write(",".join(CSV_COLUMNS) + "\n")
        np.savetxt(stream, table, delimiter=",", fmt="%.17g")
