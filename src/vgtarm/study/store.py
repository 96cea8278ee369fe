"""A study's folder: one atomic JSON file per finished run, the results tables, an execution log.

Layout of ``DIR``::

    <id>.json             one per finished run (inputs, summary, error), written atomically
                          (studies begun before issue 27 keep theirs in runs/<id>.json: read,
                          resumed and completed where they are)
    executions.log        "submit <id>" when a run is sent to the cluster, "write <id>" once stored
    results.csv           one row per run of the study: id, every input, every summary figure
    results.parquet       the same table (pyarrow)
    .vgtarm-study         the mark of a study folder vgtarm made: the files of fixed names it wrote
                          there (the four above, report.md and the figures of ``vgtarm study report``)

The folder grows in place (resume), so it is never replaced whole; vgtarm writes only in a folder
it made (a new or empty one, which gets the mark) or one it recognises as its own: marked, or,
written before the mark existed, holding only run files and the files above (it is marked then).
A file of one of the fixed names that the mark does not list is the user's: refused in one line,
never written over (:meth:`Store.check`, :meth:`Store.claim`). Every file is written atomically
(a temporary name, then a rename: never through a link); the log, which is appended to, is opened
without following a link and refused unless it is a regular file with one link that vgtarm wrote.

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
import errno
import fnmatch
import io
import json
import os
import re
import stat
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from .. import markup
from ..errors import InputError, cut, shown
from ..fileio import (
    OutputPathError,
    atomic_path,
    atomic_write_text,
    describe,
    is_temporary,
    json_value,
    no_room_error,
    open_input,
    read_text_limited,
)
from ..kinds import found_columns
from .spec import Point

#: First characters that make a spreadsheet read a cell as a formula (:mod:`vgtarm.markup`, where
#: the rule lives, with :func:`~vgtarm.markup.spreadsheet_text` and :func:`~vgtarm.markup.csv_cell`).
FORMULA_STARTS = markup.FORMULA_STARTS
spreadsheet_text = markup.spreadsheet_text
csv_cell = markup.csv_cell

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
#: The mark of a study folder vgtarm made: a first line saying so, then the files of fixed names
#: (:data:`NAMED_FILES`, the report's figures) vgtarm wrote there, one a line.
MARK = ".vgtarm-study"
_MARK_HEADER = "# a study folder of vgtarm: it writes here only run files <id>.json and the files listed below"
#: The files of fixed names a study's commands write in its folder (run files aside).
NAMED_FILES = ("executions.log", "results.csv", "results.parquet", "report.md")
#: The figures of ``vgtarm study report``.
FIGURE_FILES = "study_error_*.png"
#: Largest mark read (bytes): a few names.
_MARK_LIMIT = 2**20


def _named_file(name: str) -> bool:
    """Whether ``name`` is one of the fixed names a study writes (:data:`NAMED_FILES`, a figure)."""
    return name in NAMED_FILES or fnmatch.fnmatchcase(name, FIGURE_FILES)


class Store:
    """The results folder of a study (see the module's docstring for what it may hold)."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        legacy = self.folder / LEGACY_RUNS
        #: Where run files go: the study folder itself, or ``runs/`` of a study begun there before
        #: (a real folder: a link named ``runs`` is not followed).
        self.runs = legacy if legacy.is_dir() and not legacy.is_symlink() else self.folder
        self.log = self.folder / "executions.log"
        #: Whether the whole folder was checked and marked by this store (then each write checks
        #: only its own file and the mark: a study of 100,000 runs does not list its folder each time).
        self._checked = False

    # -- what the folder holds ----------------------------------------------------------------

    def listed(self) -> set[str] | None:
        """The files of fixed names vgtarm wrote in the folder (its mark), or None: no mark."""
        mark = self.folder / MARK
        try:
            if not stat.S_ISREG(os.lstat(mark).st_mode):
                return None
            text = read_text_limited(mark, _MARK_LIMIT, "study folder mark")
        except (OSError, InputError):
            return None
        lines = text.splitlines()
        if not lines or lines[0] != _MARK_HEADER:
            return None
        return {line for line in lines[1:] if line and not line.startswith("#")}

    def refusal(self) -> str | None:
        """Why vgtarm may not write in the folder, or None: it is new, empty, marked as a study
        folder of vgtarm (and every file of a fixed name there is listed, a regular file, the log
        with one link), or a study folder of an earlier version (only run files, the files of fixed
        names and temporaries of vgtarm's writers; at least one run file)."""
        try:
            names = sorted(os.listdir(self.folder))
        except FileNotFoundError:
            return None
        except NotADirectoryError:
            return f"is {describe(self.folder)}, not a folder"
        except OSError as exc:
            return f"cannot be read ({exc.strerror})"
        listed = self.listed()
        if listed is None:
            return None if not names else self._earlier(names)
        for name in names:  # anything else is the user's, never written (``runs`` only if a real folder)
            if _named_file(name):
                reason = self._entry(name, listed)
                if reason is not None:
                    return reason
        return None

    def _entry(self, name: str, listed: set[str] | None) -> str | None:
        """Why the file ``name`` of a fixed name may not be written (``listed``: the mark's list,
        None for a folder of an earlier version), or None."""
        try:
            found = os.lstat(self.folder / name)
        except FileNotFoundError:
            return None
        if listed is not None and name not in listed:
            return f"holds {name!r}, which vgtarm did not write there (the folder's {MARK} does not list it)"
        if not stat.S_ISREG(found.st_mode):
            return f"holds {name!r}, {describe(self.folder / name)}, where vgtarm writes a file"
        if name == "executions.log" and found.st_nlink != 1:
            return f"holds {name!r} with {found.st_nlink} links to it (vgtarm does not append through links)"
        return None

    def _earlier(self, names: list[str]) -> str | None:
        """For a folder without the mark: why it is not a study folder of an earlier version, or None."""
        runs = 0
        for name in names:
            path = self.folder / name
            try:
                found = os.lstat(path)
            except FileNotFoundError:
                continue
            if RUN_FILE.fullmatch(name) and stat.S_ISREG(found.st_mode):
                runs += 1
            elif name == LEGACY_RUNS and stat.S_ISDIR(found.st_mode):
                inside = sorted(os.listdir(path))
                other = [n for n in inside if not (RUN_FILE.fullmatch(n) or is_temporary(n))]
                if other:
                    return f"holds {LEGACY_RUNS}/{other[0]!r} and no {MARK}: not a study folder vgtarm wrote"
                runs += sum(1 for n in inside if RUN_FILE.fullmatch(n))
            elif _named_file(name):
                reason = self._entry(name, None)
                if reason is not None:
                    return reason
            elif not is_temporary(name):
                return f"holds {name!r} and no {MARK}: not a study folder vgtarm wrote"
        if runs == 0:
            return f"holds {names[0]!r} but no run file <id>.json and no {MARK}: not a study folder vgtarm wrote"
        return None

    def check(self, what: str = "study folder") -> None:
        """Raise :class:`~vgtarm.errors.InputError`, one line naming the folder as ``what``, if vgtarm
        may not write in it (:meth:`refusal`): before any work."""
        reason = self.refusal()
        if reason is not None:
            raise InputError(
                f"{what} {cut(str(self.folder), 200)}: {reason}; give a new or empty folder, or the folder of an"
                " earlier run of this study (or move that file away)"
            )

    def _refused(self, reason: str, path: Path) -> OutputPathError:
        """The one line refusing to write ``path`` in the folder (at the moment of writing)."""
        where = cut(str(self.folder), 200)
        return OutputPathError(f"study folder {where}: {reason}; move that away or give another folder", path)

    def _mark(self, names: set[str]) -> None:
        atomic_write_text(self.folder / MARK, "\n".join([_MARK_HEADER, *sorted(names)]) + "\n", "study folder mark")

    def _marked(self) -> set[str]:
        """The mark's list, after the folder is checked (:meth:`check`, :class:`OutputPathError` at
        the moment of writing), created and, when new or written by an earlier version, marked."""
        listed = self.listed() if self._checked else None
        if listed is not None:
            return listed
        reason = self.refusal()
        if reason is not None:
            raise self._refused(reason, self.folder)
        listed = self.listed()
        if listed is None:
            self.folder.mkdir(parents=True, exist_ok=True)
            listed = {n for n in os.listdir(self.folder) if _named_file(n)}  # an earlier version's
            self._mark(listed)
        self._checked = True
        return listed

    def claim(self, *names: str) -> set[str]:
        """Make the files ``names`` (fixed names) vgtarm's to write, before they are written: the
        folder must be one vgtarm may write in, and each name new or listed in its mark (a file
        vgtarm did not write is refused with :class:`OutputPathError`, one line); new names are
        listed. Returns those of ``names`` that did not exist."""
        listed = self._marked()
        new: set[str] = set()
        for name in names:
            reason = self._entry(name, listed)
            if reason is not None:
                raise self._refused(reason, self.folder / name)
            if not os.path.lexists(self.folder / name):
                new.add(name)
        if not set(names) <= listed:
            self._mark(listed | set(names))
        return new

    def discard(self, name: str) -> None:
        """Remove the file ``name`` of a fixed name if vgtarm wrote it (listed, a regular file),
        and take it off the list; never anything else."""
        listed = self.listed() or set()
        path = self.folder / name
        if name in listed and os.path.lexists(path) and stat.S_ISREG(os.lstat(path).st_mode):
            path.unlink(missing_ok=True)
        if name in listed:
            self._mark(listed - {name})

    def prepare(self) -> None:
        """Create the folder (and mark it), after the check of what it holds."""
        self._marked()
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
            fd = self._open_log()
            try:
                try:
                    os.write(fd, text.encode())
                finally:
                    os.close(fd)
            except OSError as exc:  # a full disk or the size limit: one line naming the log
                failure = no_room_error(exc, self.log, "study log")
                if failure is exc:
                    raise
                raise failure from exc

    def _open_log(self) -> int:
        """The log opened to append to: vgtarm's (listed in the mark; created new, ``O_EXCL``, when
        not there), never through a link (``O_NOFOLLOW``), never waiting on a pipe, and only a
        regular file with one link (a hard link would carry the lines elsewhere):
        :class:`OutputPathError` in one line otherwise."""
        new = self.log.name in self.claim(self.log.name)
        flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOCTTY", 0)
        flags |= getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | (os.O_EXCL if new else 0)
        where = cut(str(self.log), 200)
        try:
            fd = os.open(self.log, flags, 0o644)
        except FileExistsError:
            raise OutputPathError(f"study log {where}: appeared meanwhile; vgtarm did not write it", self.log) from None
        except OSError as exc:
            if exc.errno in (errno.ELOOP, errno.ENXIO, errno.EISDIR):  # a link, a pipe without reader, a folder
                raise OutputPathError(
                    f"study log {where}: is {describe(self.log)}; expected the regular file vgtarm writes"
                    " (it does not write through links)",
                    self.log,
                ) from None
            raise
        found = os.fstat(fd)
        if stat.S_ISREG(found.st_mode) and found.st_nlink == 1:
            return fd
        os.close(fd)
        kind = f"a file with {found.st_nlink} links to it" if stat.S_ISREG(found.st_mode) else describe(self.log)
        raise OutputPathError(
            f"study log {where}: is {kind}; expected the regular file vgtarm writes, with one link"
            " (it does not write through links)",
            self.log,
        )

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
        self.claim("results.csv", "results.parquet")  # never a user's file of that name
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


def _cell(value: Any) -> Any:
    """A table value as a CSV cell (:func:`vgtarm.markup.csv_cell`)."""
    return csv_cell(value)


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
