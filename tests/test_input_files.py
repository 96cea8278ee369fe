"""Every input file recognised for what it is, and never overwritten (issue 33, items 1, 2, 5, 7).

For every command: an output that is one of its inputs (the same path, a symbolic link to it, a
hard link, a ``../`` path, a folder holding it) is refused in one line before anything is read,
the input unchanged byte for byte; a file argument that is not a regular file (a named pipe, a
folder, a device) is refused before it is opened, at once (a reader that blocked on a pipe would
be woken by a writer after a few seconds, and the test would fail, never hang); a file of another
kind (the joint reference ``vgtarm ik`` writes given as a path, a study file as a robot, a robot
file as a study) is refused in one line naming the file, what was expected and what was found,
never quoting the file. The refusals come before any model is built (the tests fail if one is).

The minor cases: an output beyond ``ulimit -f`` or on a full disk is one line naming the path
(and the limit) with nothing partial left; SIGTERM during ``export controller`` unwinds like
Ctrl-C (status 143, one line, no temporary file).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import resource
import signal
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from vgtarm import fileio
from vgtarm.app.cli.command import main
from vgtarm.errors import ConfigError, InputError, PathError, Terminated
from vgtarm.fileio import (
    OutputSpaceError,
    atomic_folder,
    atomic_open,
    check_input_file,
    open_input,
    read_text_limited,
)
from vgtarm.ik.records import CSV_COLUMNS
from vgtarm.model.parameters import _REFERENCE_FILE
from vgtarm.simulation.result import SimulationResult
from vgtarm.study.example import EXAMPLE

REFERENCE_TEXT = (Path(fileio.__file__).parent / "model" / "data" / _REFERENCE_FILE).read_text()
#: Longest wait for a refusal in this process (s): generous for a busy machine; a reader blocked on
#: a named pipe is woken after :data:`WAKE_AFTER` seconds, so a regression fails instead of hanging.
REFUSED_WITHIN = 4.0
WAKE_AFTER = 5.0
#: A line of the study file that must never appear in a message refusing it.
STUDY_LINE = EXAMPLE.splitlines()[0]


# --- the files a command reads ----------------------------------------------------------------


def _fake_run(folder: Path) -> Path:
    """A saved run of three samples (the files :meth:`SimulationResult.save` writes)."""
    columns = SimulationResult._columns()
    rows = np.zeros((3, len(columns)))
    rows[:, 0] = [0.0, 0.001, 0.002]
    folder.mkdir()
    lines = [",".join(columns), *(",".join(f"{v:g}" for v in row) for row in rows)]
    (folder / "timeseries.csv").write_text("\n".join(lines) + "\n")
    summary = {"success": True, "message": "completed", "wall_time_s": 0.1, "ga_time_s": 0.0, "dt_s": 0.001}
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


@pytest.fixture
def files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A folder of valid inputs (the working folder of the test): a robot file, a path file, the
    joint reference ``vgtarm ik`` writes, a study file and a saved run; no model may be built."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "robot.toml").write_text(REFERENCE_TEXT)
    t = np.linspace(0.0, 0.1, 11)
    (tmp_path / "path.csv").write_text("t,x,y,z\n" + "".join(f"{v:g},0,0.06,0.66\n" for v in t))
    row = ",".join(["0", "0", "0.06", "0.66"] + ["0.3"] * (len(CSV_COLUMNS) - 4))
    (tmp_path / "ik.csv").write_text(",".join(CSV_COLUMNS) + "\n" + row + "\n")
    (tmp_path / "study.toml").write_text(EXAMPLE)
    _fake_run(tmp_path / "run")

    def built(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("a model was built before the refusal")

    def ran(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("the study started before the refusal")

    monkeypatch.setattr("vgtarm.model.robot.get_backend", built)
    monkeypatch.setattr("vgtarm.study.runner.run_study", ran)
    return tmp_path


def _state(folder: Path) -> dict[str, tuple[Any, ...]]:
    """Every entry under ``folder``: its type, inode and, for a file, its bytes."""
    found: dict[str, tuple[Any, ...]] = {}
    for path in sorted(folder.rglob("*")):
        info = os.lstat(path)
        data = path.read_bytes() if stat.S_ISREG(info.st_mode) else None
        found[path.relative_to(folder).as_posix()] = (stat.S_IFMT(info.st_mode), info.st_ino, data)
    return found


@contextlib.contextmanager
def _woken(pipes: list[Path]) -> Iterator[None]:
    """Open each of ``pipes`` for writing (and close it) after :data:`WAKE_AFTER` seconds, so that a
    reader blocked on one (a regression) gets an end of file instead of waiting for ever."""
    done = threading.Event()

    def wake() -> None:
        if done.wait(WAKE_AFTER):
            return
        while not done.is_set():
            for pipe in pipes:
                with contextlib.suppress(OSError):  # no reader yet (ENXIO), or gone
                    os.close(os.open(pipe, os.O_WRONLY | os.O_NONBLOCK))
            done.wait(0.05)

    waker = threading.Thread(target=wake, daemon=True)
    waker.start()
    try:
        yield
    finally:
        done.set()
        waker.join()


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str], pipes: Sequence[Path] = ()) -> str:
    """Run ``argv`` in this process: it must fail at once with one line; returns the line."""
    capsys.readouterr()
    start = time.monotonic()
    with _woken(list(pipes)):
        status = main(argv)
    took = time.monotonic() - start
    err = capsys.readouterr().err
    assert status == 1, (argv, err)
    assert err.count("\n") == 1 and err.startswith("vgtarm: error: "), err
    assert took < REFUSED_WITHIN, f"{argv}: refused after {took:.1f} s"
    return err.removeprefix("vgtarm: error: ").rstrip("\n")


# --- 1. an output that is one of the inputs ---------------------------------------------------

#: Each writer with one input: its arguments ({input} the input's path, {out} the output path)
#: and the input file (relative to the folder of inputs) that the output names.
FILE_WRITERS: dict[str, tuple[list[str], str]] = {
    "ik -o, its --path": (["ik", "--path", "{input}", "-o", "{out}"], "path.csv"),
    "ik -o, its --config": (["ik", "--case", "1", "--config", "{input}", "-o", "{out}"], "robot.toml"),
    "ik --point -o, its --config": (
        ["ik", "--point", "0,0.06,0.66", "--config", "{input}", "-o", "{out}"],
        "robot.toml",
    ),
    "export mjcf --out, its --config": (["export", "mjcf", "--config", "{input}", "--out", "{out}"], "robot.toml"),
    "convert-robot --out, its --config": (["convert-robot", "--config", "{input}", "--out", "{out}"], "robot.toml"),
    "draw --out, its --config": (["draw", "--config", "{input}", "--out", "{out}"], "robot.png"),
    "animate --out, its --config": (["animate", "run", "--config", "{input}", "--out", "{out}", "-q"], "robot.gif"),
    "animate --out, its run's summary": (["animate", "run", "--out", "{out}", "-q"], "run/summary.gif"),
    "animate --out, its run's robot copy": (["animate", "run", "--out", "{out}", "-q"], "run/robot.gif"),
    "study run --out, its study file": (["study", "run", "{input}", "--out", ".", "-q"], "results.csv"),
    "study report DIR, its results": (["study", "report", "."], "report.md"),
}


def _same_path(files: Path, name: str) -> str:
    return name


def _symbolic_link(files: Path, name: str) -> str:
    link = files / "link" / Path(name).name
    link.parent.mkdir(exist_ok=True)
    link.symlink_to(files / name)
    return str(link)


def _hard_link(files: Path, name: str) -> str:
    link = files / "hard" / Path(name).name
    link.parent.mkdir(exist_ok=True)
    os.link(files / name, link)
    return str(link)


def _up_and_down(files: Path, name: str) -> str:
    (files / "sub").mkdir(exist_ok=True)
    return f"sub/../{name}"


def _linked_folder(files: Path, name: str) -> str:
    (files / "alias").symlink_to(files)
    return f"alias/{name}"


#: Other names of the same file.
SAME_FILE: dict[str, Callable[[Path, str], str]] = {
    "the same path": _same_path,
    "a symbolic link": _symbolic_link,
    "a hard link": _hard_link,
    "a ../ path": _up_and_down,
    "through a linked folder": _linked_folder,
}


def _file_writer_case(files: Path, writer: str) -> tuple[list[str], str]:
    """The arguments of ``writer`` with its input in place (the robot file, the path file, ...)."""
    template, name = FILE_WRITERS[writer]
    source = files / name
    if not source.exists():
        if name.startswith("run/"):  # another name of one of the run's files (a hard link)
            if "robot" in name:
                (files / "run" / "robot.toml").write_text(REFERENCE_TEXT)
            os.link(files / "run" / ("summary.json" if "summary" in name else "robot.toml"), source)
        elif name == "results.csv":  # a study whose own file is named like one the study writes
            source.write_text(EXAMPLE)
        elif name == "report.md":  # the report's name is another name of the results it reads
            (files / "results.parquet").write_bytes(b"PAR1")
            os.link(files / "results.parquet", source)
        else:
            source.write_text(REFERENCE_TEXT)
    return template, name


@pytest.mark.parametrize(
    ("writer", "how"),
    [
        (writer, how)
        for writer, (template, _) in sorted(FILE_WRITERS.items())
        for how in sorted(SAME_FILE)
        if "{out}" in template or how == "the same path"  # a fixed name in the study's folder: only itself
    ],
)
def test_an_output_file_that_is_an_input_is_refused_before_anything_is_read(
    files: Path, capsys: pytest.CaptureFixture[str], writer: str, how: str
) -> None:
    template, name = _file_writer_case(files, writer)
    out = SAME_FILE[how](files, name)
    before = _state(files)
    argv = [out if word == "{out}" else name if word == "{input}" else word for word in template]
    line = _refused(capsys, argv)
    if how == "a symbolic link":  # vgtarm never writes through a link, whatever it leads to
        assert "is a symbolic link to a file" in line or "is an input of this command" in line, line
    else:
        assert "is an input of this command" in line, line
    assert _state(files) == before  # the input unchanged byte for byte, nothing written beside it


#: Each writer of a folder with one input: its arguments and the input the folder holds.
FOLDER_WRITERS: dict[str, tuple[list[str], str]] = {
    "simulate --out, its --path": (["simulate", "--path", "{input}", "--quiet", "--out", "{out}"], "path.csv"),
    "simulate --out, its --config": (
        ["simulate", "--case", "1", "--config", "{input}", "--out", "{out}"],
        "robot.toml",
    ),
    "reproduce --out, its --config": (["reproduce", "--quiet", "--config", "{input}", "--out", "{out}"], "robot.toml"),
    "export controller --out, its --config": (
        ["export", "controller", "--config", "{input}", "--out", "{out}"],
        "robot.toml",
    ),
    "export controller --out, its --model-config": (
        ["export", "controller", "--model-config", "{input}", "--out", "{out}"],
        "robot.toml",
    ),
    "report --out, its run": (["report", "{input}", "--out", "{out}"], "run"),
}


@pytest.mark.parametrize("how", ["the folder itself", "a ../ path", "through a linked folder", "a link to it"])
@pytest.mark.parametrize("writer", sorted(FOLDER_WRITERS))
def test_an_output_folder_that_is_or_holds_an_input_is_refused_before_anything_is_read(
    files: Path, capsys: pytest.CaptureFixture[str], writer: str, how: str
) -> None:
    template, name = FOLDER_WRITERS[writer]
    inputs = files / "inputs"
    inputs.mkdir()
    os.replace(files / name, inputs / name)
    source = f"inputs/{name}"
    out = {
        "the folder itself": "inputs" if name != "run" else source,
        "a ../ path": "inputs/../inputs" if name != "run" else f"inputs/../{source}",
        "through a linked folder": "alias/inputs" if name != "run" else f"alias/{source}",
        "a link to it": "to-inputs",
    }[how]
    (files / "alias").symlink_to(files)
    (files / "to-inputs").symlink_to(inputs if name != "run" else inputs / name)
    before = _state(files)
    argv = [out if word == "{out}" else source if word == "{input}" else word for word in template]
    line = _refused(capsys, argv)
    if how == "a link to it":
        assert "is a symbolic link to a folder; expected the folder itself" in line, line
    else:
        assert "an input of this command" in line, line
    assert _state(files) == before


def test_a_study_folder_holding_the_path_file_it_would_write_over_is_refused(
    files: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The study's path file is the results table the study writes in its folder: refused after the
    study file is read, before any run and any write. The folder is a study folder vgtarm wrote,
    whose results.csv the study names as its path (else the folder itself is refused first)."""
    from vgtarm.study.store import Store

    Store(files / "out").claim("results.csv")  # marked, results.csv listed as vgtarm's
    os.replace(files / "path.csv", files / "out" / "results.csv")
    (files / "s.toml").write_text('[study]\npath = "out/results.csv"\n')
    before = _state(files)
    line = _refused(capsys, ["study", "run", "s.toml", "--out", "out", "-q"])
    assert line.startswith("the study's file out/results.csv: is an input of this command"), line
    assert _state(files) == before


# --- 3. a file argument that is not a regular file ----------------------------------------------


def _pipe(path: Path) -> None:
    os.mkfifo(path)


def _link_to_pipe(path: Path) -> None:
    os.mkfifo(path.with_name(path.name + ".aim"))
    path.symlink_to(path.with_name(path.name + ".aim"))


def _device(path: Path) -> None:
    path.symlink_to("/dev/zero")


def _folder(path: Path) -> None:
    path.mkdir()


#: What is put at a file argument, and the words of the refusal.
NOT_FILES: dict[str, tuple[Callable[[Path], None], str]] = {
    "a named pipe": (_pipe, "is a named pipe (FIFO); expected a regular file"),
    "a link to a named pipe": (_link_to_pipe, "is a symbolic link to a named pipe (FIFO); expected a regular file"),
    "/dev/zero": (_device, "is a symbolic link to a character device; expected a regular file"),
    "a folder": (_folder, "is a folder, not a file"),
}

#: Every command with a file argument ({x}: the argument, named "x" in the folder of inputs).
FILE_ARGUMENTS: dict[str, list[str]] = {
    "describe --config": ["describe", "--config", "{x}"],
    "fk --config": ["fk", "0.3", "0.27", "0.38", "0.29", "0.29", "0.38", "0", "--config", "{x}"],
    "simulate --config": ["simulate", "--case", "1", "--config", "{x}", "--out", "o"],
    "simulate --path": ["simulate", "--path", "{x}", "--quiet", "--out", "o"],
    "ik --path": ["ik", "--path", "{x}", "-o", "o.csv"],
    "ik --config": ["ik", "--case", "1", "--config", "{x}", "-o", "o.csv"],
    "reproduce --config": ["reproduce", "--quiet", "--config", "{x}", "--out", "o"],
    "export mjcf --config": ["export", "mjcf", "--config", "{x}", "--out", "o.xml"],
    "export controller --config": ["export", "controller", "--config", "{x}", "--out", "o"],
    "export controller --model-config": ["export", "controller", "--model-config", "{x}", "--out", "o"],
    "check mujoco --config": ["check", "mujoco", "--states", "1", "--config", "{x}"],
    "draw --config": ["draw", "--config", "{x}", "--out", "o.png"],
    "animate --config": ["animate", "run", "--config", "{x}", "--out", "o.gif", "-q"],
    "animate, a run's file": ["animate", "run", "--out", "o.gif", "-q"],
    "report --config": ["report", "run", "--config", "{x}", "--out", "o"],
    "report, a run's file": ["report", "run", "--out", "o"],
    "convert-robot --config": ["convert-robot", "--config", "{x}", "--out", "o.toml"],
    "study run STUDY": ["study", "run", "{x}", "--out", "o", "-q"],
    "study run, the study's path": ["study", "run", "s.toml", "--out", "o", "-q"],
    "study run, the study's robot": ["study", "run", "r.toml", "--out", "o", "-q"],
}
#: Where the argument is when it is not on the command line: a file of the run, a file the study names.
INSIDE = {
    "animate, a run's file": "run/summary.json",
    "report, a run's file": "run/timeseries.csv",
    "study run, the study's path": "x",
    "study run, the study's robot": "x",
}


@pytest.mark.parametrize("kind", sorted(NOT_FILES))
@pytest.mark.parametrize("command", sorted(FILE_ARGUMENTS))
def test_a_file_argument_that_is_not_a_regular_file_is_refused_before_it_is_opened(
    files: Path, capsys: pytest.CaptureFixture[str], command: str, kind: str
) -> None:
    make, words = NOT_FILES[kind]
    (files / "s.toml").write_text('[study]\npath = "x"\n')
    (files / "r.toml").write_text('[study]\ncase = 1\nrobot = "x"\n')
    where = files / INSIDE.get(command, "x")
    where.unlink(missing_ok=True)
    make(where)
    argv = ["x" if word == "{x}" else word for word in FILE_ARGUMENTS[command]]
    before = _state(files)
    line = _refused(capsys, argv, [p for p in files.rglob("*") if stat.S_ISFIFO(os.stat(p).st_mode)])
    assert words in line and f"{INSIDE.get(command, 'x')}: is" in line, line
    assert _state(files) == before


@pytest.mark.parametrize(
    ("argv", "what"),
    [
        (["animate", "x", "--out", "o.gif"], "run folder x"),
        (["report", "x", "--out", "o"], "run folder x"),
        (["study", "report", "x"], "DIR x"),
    ],
)
@pytest.mark.parametrize("kind", ["a named pipe", "/dev/zero", "a file"])
def test_a_folder_argument_that_is_not_a_folder_is_refused(
    files: Path, capsys: pytest.CaptureFixture[str], argv: list[str], what: str, kind: str
) -> None:
    make = {"a file": lambda p: p.write_text("x"), **{k: v[0] for k, v in NOT_FILES.items()}}[kind]
    make(files / "x")
    line = _refused(capsys, argv, [files / "x"])
    assert line.startswith(f"{what}: is ") and line.endswith("; expected a folder"), line


@pytest.mark.parametrize(
    "read",
    [
        lambda p: read_text_limited(p),
        lambda p: check_input_file(p),
        lambda p: open_input(p).close(),
        lambda p: SimulationResult.load(p.parent),
    ],
    ids=["read_text_limited", "check_input_file", "open_input", "SimulationResult.load"],
)
def test_the_readers_of_the_api_refuse_a_pipe_at_once(tmp_path: Path, read: Callable[[Path], Any]) -> None:
    pipe = tmp_path / "summary.json"
    os.mkfifo(pipe)
    (tmp_path / "timeseries.csv").write_text("t\n")
    start = time.monotonic()
    with (
        _woken([pipe]),
        pytest.raises(InputError, match=r"summary\.json: is a named pipe \(FIFO\); expected a regular file$"),
    ):
        read(pipe)
    assert time.monotonic() - start < REFUSED_WITHIN


def test_a_pipe_that_appears_between_the_check_and_the_opening_is_refused_too(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The descriptor is opened without waiting and looked at again (``fstat``): no window."""
    file = tmp_path / "robot.toml"
    file.write_text("x")
    check = fileio.check_input_file

    def then_a_pipe(*args: Any, **kwargs: Any) -> Any:
        found = check(*args, **kwargs)
        file.unlink()
        os.mkfifo(file)
        return found

    monkeypatch.setattr(fileio, "check_input_file", then_a_pipe)
    with (
        _woken([file]),
        pytest.raises(ConfigError, match=r"robot\.toml: is a named pipe \(FIFO\); expected a regular file$"),
    ):
        read_text_limited(file, error=ConfigError)


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--path", "pipe", "--quiet"],
        ["export", "controller", "--config", "pipe", "--out", "o"],
        ["study", "run", "s.toml", "--out", "o", "-q"],
    ],
    ids=["simulate --path", "export controller --config", "study run, its path"],
)
def test_the_commands_of_the_issue_refuse_a_pipe_as_programs(tmp_path: Path, argv: list[str]) -> None:
    """The real program, in its own process (a regression times out instead of hanging)."""
    os.mkfifo(tmp_path / "pipe")
    (tmp_path / "s.toml").write_text('[study]\npath = "pipe"\n')
    done = subprocess.run(
        [sys.executable, "-m", "vgtarm", *argv], cwd=tmp_path, capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    assert "pipe: is a named pipe (FIFO); expected a regular file" in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe", "s.toml"]


# --- 2. a file of another kind ----------------------------------------------------------------

#: A command given a file of another kind than it reads, and the words of its refusal.
WRONG_KIND: dict[str, tuple[list[str], list[str]]] = {
    "simulate --path: an ik output": (
        ["simulate", "--path", "ik.csv", "--quiet"],
        [
            "path file 'ik.csv': line 1: header must be the columns t,x,y,z",
            "found 25 columns starting t, x, y, z, s1",
            "this looks like the joint reference `vgtarm ik` writes",
        ],
    ),
    "ik --path: an ik output": (
        ["ik", "--path", "ik.csv", "-o", "o.csv"],
        ["path file 'ik.csv'", "found 25 columns", "this looks like the joint reference `vgtarm ik` writes"],
    ),
    "ik --path: a study file": (
        ["ik", "--path", "study.toml"],
        ["path file 'study.toml': line 1: header must be the columns t,x,y,z", "this looks like a study file (TOML)"],
    ),
    "ik --path: a run's time series": (
        ["ik", "--path", "run/timeseries.csv"],
        ["found 47 columns starting t, x_d, y_d, z_d, x, ...", "this looks like a run's time series"],
    ),
    "describe --config: a study file": (
        ["describe", "--config", "study.toml"],
        ["study.toml: a study file (it has the tables [study], [grid], [random]); expected a robot file"],
    ),
    **{
        f"{' '.join(words[:2])} --config: a study file": (
            [*words, "--config", "study.toml"],
            ["study.toml: a study file (it has the tables [study], [grid], [random]); expected a robot file"],
        )
        for words in (
            ["fk", "0.3", "0.27", "0.38", "0.29", "0.29", "0.38", "0"],
            ["simulate", "--case", "1", "--quiet"],
            ["ik", "--case", "1"],
            ["export", "mjcf", "--out", "o.xml"],
            ["export", "controller", "--out", "o"],
            ["draw", "--out", "o.png"],
            ["reproduce", "--quiet", "--out", "o"],
        )
    },
    "convert-robot --config: a study file": (
        ["convert-robot", "--config", "study.toml", "--out", "o.toml"],
        [
            "study.toml: a study file (it has the tables [study], [grid], [random])",
            "expected a robot file of the 7-joint",
        ],
    ),
    "convert-robot --config: a stack file": (
        ["convert-robot", "--config", "stack.toml", "--out", "o.toml"],
        ["stack.toml: a stack robot file (it has the tables [[modules]], [end_effector]); expected a robot file"],
    ),
    "study run: a robot file": (
        ["study", "run", "robot.toml", "--out", "o", "-q"],
        ["robot.toml: a robot file (it has the tables [geometry], [limits], [home], [bodies]); expected a study file"],
    ),
    "study run: a stack file": (
        ["study", "run", "stack.toml", "--out", "o", "-q"],
        ["stack.toml: a stack robot file (it has the tables [[modules]], [end_effector]); expected a study file"],
    ),
    "study run: the study's robot is a study": (
        ["study", "run", "r.toml", "--out", "o", "-q"],
        ["study.robot = 'study.toml': a study file (it has the tables [study], [grid], [random]); expected a robot"],
    ),
    "study run: the study's path is an ik output": (
        ["study", "run", "p.toml", "--out", "o", "-q"],
        ["study.path = 'ik.csv'", "found 25 columns: this looks like the joint reference `vgtarm ik` writes"],
    ),
    "report: an ik output as a run's time series": (
        ["report", "bad-run", "--out", "o"],
        [
            "run file bad-run/timeseries.csv: columns do not match a run's time series",
            "found 25 columns starting t, x, y, z, s1, ...: this looks like the joint reference `vgtarm ik` writes",
        ],
    ),
    "animate: a study file as a run's summary": (
        ["animate", "toml-run", "--out", "o.gif", "-q"],
        ["run file toml-run/summary.json: not JSON; expected a run's summary.json"],
    ),
    "study report: not a Parquet table": (
        ["study", "report", "bad-study"],
        ["study results file bad-study/results.parquet: not a Parquet table"],
    ),
    "study report: a Parquet table without ids": (
        ["study", "report", "other-study"],
        ["study results file other-study/results.parquet: no column 'id'", "found 2 columns a, b"],
    ),
}


@pytest.mark.parametrize("case", sorted(WRONG_KIND))
def test_a_file_of_another_kind_is_refused_naming_file_expected_and_found(
    files: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    from vgtarm.model.parameters import load_parameters
    from vgtarm.model.stack import stack_from_parameters, stack_to_toml

    (files / "stack.toml").write_text(stack_to_toml(stack_from_parameters(load_parameters(None))))
    (files / "r.toml").write_text('[study]\ncase = 1\nrobot = "study.toml"\n')
    (files / "p.toml").write_text('[study]\npath = "ik.csv"\n')
    (files / "bad-run").mkdir()
    (files / "bad-run" / "summary.json").write_text((files / "run" / "summary.json").read_text())
    (files / "bad-run" / "timeseries.csv").write_text((files / "ik.csv").read_text())
    (files / "toml-run").mkdir()
    (files / "toml-run" / "summary.json").write_text(EXAMPLE)
    (files / "toml-run" / "timeseries.csv").write_text((files / "run" / "timeseries.csv").read_text())
    (files / "bad-study").mkdir()
    (files / "bad-study" / "results.parquet").write_text(REFERENCE_TEXT)
    (files / "other-study").mkdir()
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table({"a": [1], "b": [2]}), files / "other-study" / "results.parquet")
    argv, expected = WRONG_KIND[case]
    before = _state(files)
    line = _refused(capsys, argv)
    for words in expected:
        assert words in line, (words, line)
    assert STUDY_LINE not in line and "[geometry.module1]" not in line  # the file is never quoted
    assert _state(files) == before


# --- 7. a full disk, the size limit, SIGTERM --------------------------------------------------


def _size_limit(limit: int) -> Callable[[], None]:
    def set_limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))

    return set_limit


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["ik", "--case", "1", "--dt", "0.01", "-o", "out.csv"], "output file out.csv"),
        (["simulate", "--case", "1", "--duration", "0.05", "--quiet", "--out", "run"], "output file run/"),
    ],
    ids=["ik -o", "simulate --out"],
)
def test_an_output_beyond_the_file_size_limit_is_one_line_naming_path_and_limit(
    robot: Any, tmp_path: Path, argv: list[str], named: str
) -> None:
    """``ulimit -f``: Python ignores SIGXFSZ, the write fails with EFBIG, and the writer says so
    (the compiled model is in the cache already: the ``robot`` fixture loaded it)."""
    done = subprocess.run(
        [sys.executable, "-m", "vgtarm", *argv],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        preexec_fn=_size_limit(4096),  # a limit of this child only
    )
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    line = done.stderr.removeprefix("vgtarm: error: ")
    assert line.startswith(named), line
    assert "larger than the file size limit of 4,096 bytes (ulimit -f); nothing was written" in line
    assert list(tmp_path.iterdir()) == []  # nothing partial, no temporary


def test_a_full_disk_is_one_line_naming_the_path_and_leaves_nothing(
    files: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def full(*args: Any, **kwargs: Any) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(fileio, "_put_file", full)
    before = _state(files)
    line = _refused(capsys, ["convert-robot", "--out", "stack.toml"])
    assert line == "output file stack.toml: no space left on the device (the disk is full); nothing was written"
    assert _state(files) == before


def test_no_room_inside_a_result_folder_names_the_users_path(tmp_path: Path) -> None:
    with pytest.raises(OutputSpaceError) as info, atomic_folder(tmp_path / "run") as folder:
        with atomic_open(folder / "timeseries.csv") as stream:
            stream.write("t\n")
            raise OSError(errno.EFBIG, os.strerror(errno.EFBIG))
    assert str(info.value).startswith(f"output file {tmp_path / 'run' / 'timeseries.csv'}: larger than the file size")
    assert isinstance(info.value, OSError) and info.value.errno == errno.EFBIG
    assert list(tmp_path.iterdir()) == []


def test_sigterm_during_export_controller_unwinds_like_ctrl_c(robot: Any, tmp_path: Path) -> None:
    """SIGTERM while the export is written: the temporary folder is removed, status 143, one line."""
    process = subprocess.Popen(
        [sys.executable, "-m", "vgtarm", "export", "controller", "--out", "exported"],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not any(p.name.startswith(".exported.") for p in tmp_path.iterdir()):  # inside the atomic folder
            assert process.poll() is None and time.monotonic() < deadline, "the export ended before it was signalled"
            time.sleep(0.01)
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert (process.returncode, err) == (143, "vgtarm: terminated\n")
    assert list(tmp_path.iterdir()) == []


def test_a_sigterm_whose_exception_a_library_swallowed_still_stops_every_writer(
    files: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """CasADi swallows an exception raised inside its calls: the flag stays, no writer puts its
    result in place after it, and the command ends with status 143 all the same."""
    monkeypatch.setattr(Terminated, "arrived", True)
    before = _state(files)
    assert main(["convert-robot", "--out", "stack.toml"]) == 143
    assert capsys.readouterr().err == "vgtarm: terminated\n"
    with pytest.raises(Terminated):
        fileio.atomic_write_text(files / "x.txt", "x")
    assert _state(files) == before


def test_sigterm_before_the_command_runs_ends_with_one_line(tmp_path: Path) -> None:
    """During the imports too (the handler is installed first): status 143, one line."""
    process = subprocess.Popen(
        [sys.executable, "-m", "vgtarm", "describe"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    caught = Path(f"/proc/{process.pid}/status")
    if not caught.exists():
        process.kill()
        process.communicate()
        pytest.skip("no /proc here to see when the handler is installed")
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and process.poll() is None:  # the handler installed: SIGTERM caught
        try:
            masks = dict(line.split(":\t", 1) for line in caught.read_text().splitlines() if ":\t" in line)
        except OSError:  # it ended meanwhile
            break
        if int(masks.get("SigCgt", "0"), 16) & (1 << (signal.SIGTERM - 1)):
            break
        time.sleep(0.001)
    process.send_signal(signal.SIGTERM)
    out, err = process.communicate(timeout=60)
    if process.returncode == 0:
        pytest.skip("describe finished before the signal")
    assert (process.returncode, err) == (143, "vgtarm: terminated\n")


def test_path_errors_keep_their_class(tmp_path: Path) -> None:
    """The one check (:func:`~vgtarm.fileio.check_input_file`) raises the reader's own class."""
    from vgtarm.paths import from_csv

    os.mkfifo(tmp_path / "p.csv")
    with _woken([tmp_path / "p.csv"]), pytest.raises(PathError, match=r"^path file .*p\.csv: is a named pipe"):
        from_csv(tmp_path / "p.csv")


def test_a_huge_regular_file_is_refused_without_reading_it_whole(
    files: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The size limit still holds for regular files (``/dev/zero`` is now refused as a device)."""
    with open(files / "huge.toml", "wb") as stream:
        stream.truncate(2**21)  # sparse: 2 MB of zeros without writing them
    line = _refused(capsys, ["describe", "--config", "huge.toml"])
    assert line == "configuration file huge.toml: larger than 1,048,576 bytes; expected a small text file"
