"""A study's folder: one atomic JSON file per finished run, the results tables, an execution log.

Layout of ``DIR``::

    <id>.json             one per finished run (inputs, summary, error), written atomically
                          (studies begun before issue 27 keep theirs in runs/<id>.json: read,
                          resumed and completed where they are)
    executions.log        "submit <id>" when a run is sent to the cluster, "write <id>" once stored
    results.csv           one row per run of the study: id, every input, every summary figure
    results.parquet       the same table (pyarrow)

A run file either exists complete or not at all (written to a temporary name, then renamed), so
an interrupted study resumes by running exactly the ids without a file. A run file is read only
if it holds the run its name gives (a copy of another run's file under another id is refused).

``results.csv`` is written for spreadsheets too: a text cell that would start a formula (its
first character one of ``= + - @``, a tab or a carriage return: robot and file names, error
messages) is written with a leading ``'``, so that it shows as the text it is
(:func:`spreadsheet_text`); numbers are written as they are. ``results.parquet`` keeps every
value as it is.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..errors import InputError, cut, shown
from ..fileio import atomic_path, atomic_write_text, json_value, no_room_error, open_input, read_text_limited
from ..kinds import found_columns
from .spec import Point

#: First characters that make a spreadsheet read a cell as a formula (or, tab and carriage
#: return, that some of them drop before reading the rest as one).
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")

#: Summary figures that measure the machine, not the run (they differ between two runs of a row).
TIMING_COLUMNS = (
    "wall_time_s",
    "real_time_factor",
    "ga_time_s",
    "ga_time_per_activation_s",
    "ga_activation_time_median_s",
    "ga_activation_time_p99_s",
)


#: The sub-folder that held the run files of a study begun before issue 27 (``DIR/runs/<id>.json``);
#: such a study resumes there, new studies write ``DIR/<id>.json`` as the README says.
LEGACY_RUNS = "runs"
#: Largest run file read (bytes): a run's record is a few kilobytes.
RUN_RECORD_LIMIT = 16 * 2**20
#: The name of a run file: a point's id (16 hexadecimal digits, :func:`vgtarm.study.spec.point_id_of`).
RUN_FILE = re.compile(r"[0-9a-f]{16}\.json")


class Store:
    """The results folder of a study."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        legacy = self.folder / LEGACY_RUNS
        #: Where run files go: the study folder itself, or ``runs/`` of a study begun there before.
        self.runs = legacy if legacy.is_dir() else self.folder
        self.log = self.folder / "executions.log"

    def prepare(self) -> None:
        """Create the folder."""
        self.runs.mkdir(parents=True, exist_ok=True)

    def done(self) -> set[str]:
        """Ids of the runs stored (temporary files of interrupted writes are ignored)."""
        if not self.runs.is_dir():
            return set()
        return {p.stem for p in self.runs.glob("*.json") if RUN_FILE.fullmatch(p.name)}

    def run_file(self, point_id: str) -> Path:
        """The file of run ``point_id`` (which may not exist yet)."""
        return self.runs / f"{point_id}.json"

    def write(self, record: Mapping[str, Any]) -> Path:
        """Store one finished run ``{"id", "inputs", "summary", "error"}`` atomically, then log it."""
        path = self.run_file(str(record["id"]))
        atomic_write_text(path, json.dumps(json_value(dict(record))) + "\n")
        self.note("write", [str(record["id"])])
        return path

    def note(self, what: str, ids: Iterable[str]) -> None:
        """Append ``what <id>`` lines to the execution log (one small append per call)."""
        text = "".join(f"{what} {i}\n" for i in ids)
        if text:
            try:
                fd = os.open(self.log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
                try:
                    os.write(fd, text.encode())
                finally:
                    os.close(fd)
            except OSError as exc:  # a full disk or the size limit: one line naming the log
                failure = no_room_error(exc, self.log, "study log")
                if failure is exc:
                    raise
                raise failure from exc

    def read(self, point_id: str) -> dict[str, Any]:
        """One stored run: a record ``{"id", "inputs", "summary", "error"}`` whose id is ``point_id``
        (InputError, one line, for anything else: a run file copied under another id, a damaged or
        foreign file)."""
        path = self.run_file(point_id)
        shown_path = cut(str(path), 200)
        redo = "remove it and run the study again to redo that run"
        try:  # a named pipe or a device at its name: refused before it is opened
            text = read_text_limited(path, RUN_RECORD_LIMIT, "run file")
        except InputError as exc:
            raise InputError(f"{exc}; {redo}") from None
        try:
            record = json.loads(text)
        except (ValueError, RecursionError) as exc:
            raise InputError(f"run file {shown_path}: cannot read it ({type(exc).__name__}); {redo}") from None
        if not (
            isinstance(record, dict)
            and isinstance(record.get("inputs"), dict)
            and isinstance(record.get("summary"), dict)
            and isinstance(record.get("error", ""), str)
        ):
            raise InputError(
                f"run file {shown_path}: not a run record (a table of id, inputs, summary and error); {redo}"
            )
        if record.get("id") != point_id:
            raise InputError(
                f"run file {shown_path}: holds the run id = {shown(record.get('id'))}, not {point_id!r} as its name"
                f" says (a copy of another run's file?); {redo}"
            )
        return record

    def rows(self, points: list[Point] | None = None) -> list[dict[str, Any]]:
        """The table: one row per point (in the study's order) or per stored run (by id); every row
        has every column (None where a run has no such figure)."""
        ids = [p.id for p in points] if points is not None else sorted(self.done())
        done = self.done()
        rows = [row_of(self.read(i)) for i in ids if i in done]
        columns = table_columns(rows)
        return [{c: row.get(c) for c in columns} for row in rows]

    def write_tables(self, rows: list[dict[str, Any]]) -> tuple[Path, Path]:
        """Write ``results.csv`` and ``results.parquet`` atomically."""
        columns = table_columns(rows)
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow([spreadsheet_text(c) for c in columns])
        for row in rows:
            writer.writerow([_cell(row.get(c)) for c in columns])
        csv_file = atomic_write_text(self.folder / "results.csv", buffer.getvalue())
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table({c: _arrow_column([row.get(c) for row in rows]) for c in columns})
        parquet_file = self.folder / "results.parquet"
        with atomic_path(parquet_file) as temporary:
            pq.write_table(table, temporary)
        return csv_file, parquet_file


def row_of(record: Mapping[str, Any]) -> dict[str, Any]:
    """A table row from a run record: ``id``, the inputs, ``error`` and the summary figures."""
    row: dict[str, Any] = {"id": record["id"], **record["inputs"], "error": record.get("error", "")}
    for key, value in record["summary"].items():
        if key not in row:
            row[key] = json.dumps(value) if isinstance(value, list | dict) else value
    return row


def table_columns(rows: list[dict[str, Any]]) -> list[str]:
    """Every key of the rows, in order of first appearance."""
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    return list(columns)


def read_table(folder: str | Path) -> list[dict[str, Any]]:
    """The rows of ``results.parquet`` (None for missing values)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    file = Path(folder) / "results.parquet"
    shown_file = cut(str(file), 200)
    if not os.path.lexists(file):
        raise InputError(f"study folder {cut(str(folder), 200)}: no results.parquet (run `vgtarm study run` first)")
    expected = "expected the results.parquet `vgtarm study run` writes"
    with open_input(file, "study results file") as stream:  # not a regular file: refused before it is opened
        try:
            table = pq.read_table(stream)
        except (pa.ArrowException, OSError, ValueError):
            raise InputError(f"study results file {shown_file}: not a Parquet table; {expected}") from None
    if "id" not in table.column_names:
        found = found_columns(table.column_names)
        raise InputError(f"study results file {shown_file}: no column 'id'; {expected}; {found}")
    return list(table.to_pylist())


def spreadsheet_text(text: str) -> str:
    """``text`` as a CSV cell a spreadsheet shows as text: with a leading ``'`` when its first
    character is one of :data:`FORMULA_STARTS` (the usual defence against formula injection; the
    spreadsheet hides the quote), else unchanged."""
    return f"'{text}" if text.startswith(FORMULA_STARTS) else text


def _cell(value: Any) -> Any:
    """A table value as a CSV cell: numbers as they are (floats in full), text made safe for
    spreadsheets, None and non-finite numbers empty."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return spreadsheet_text(value)
    return value


def _arrow_column(values: list[Any]) -> Any:
    import pyarrow as pa

    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return pa.array(values, type=pa.bool_())
    if present and all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        if all(isinstance(v, int) for v in present):
            return pa.array(values, type=pa.int64())
        return pa.array([None if v is None else float(v) for v in values], type=pa.float64())
    return pa.array([None if v is None else str(v) for v in values], type=pa.string())
