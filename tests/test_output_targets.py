"""What is at an output path before a writer replaces it (issue 20, items 1 and 9).

Every writer (``ik -o``, the ``--out`` of ``simulate``, ``report``, ``animate``, ``draw``,
``export mjcf``, ``convert-robot``, ``reproduce`` and ``study run``, ``study init FILE``, and the
API's :func:`~vgtarm.fileio.atomic_path`, :func:`~vgtarm.fileio.atomic_open`,
:func:`~vgtarm.fileio.atomic_write_text` and :func:`~vgtarm.fileio.atomic_folder`) refuses an
existing target that is not a regular file (or, where a folder is meant, a real folder): a
named pipe, a socket, a character device, a symbolic link to one of those or to anything else.
The command line refuses it before any work, in one line naming the path and what is there; the
writers refuse it again at the moment of writing, when it appeared during the run. The target is
never touched (same inode, same type) and nothing partial is left. A read-only file system is
found before the work too, and every path a command prints is escaped.
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
import stat
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vgtarm import fileio
from vgtarm.app.cli.command import main
from vgtarm.errors import InputError, escape
from vgtarm.fileio import (
    OutputPathError,
    atomic_folder,
    atomic_open,
    atomic_path,
    atomic_write_text,
    check_output_file,
)

#: Every writer of the command line: its arguments (``{out}`` the output path, ``{run}`` a run
#: folder to read, ``{study}`` a study file) and the name its output gets here.
WRITERS: dict[str, tuple[list[str], str]] = {
    "ik -o": (["ik", "--case", "1", "-o", "{out}"], "target.csv"),
    "simulate --out": (["simulate", "--case", "1", "--duration", "0.05", "--quiet", "--out", "{out}"], "target"),
    "report --out": (["report", "{run}", "--out", "{out}"], "target"),
    "animate --out": (["animate", "{run}", "--out", "{out}", "-q"], "target.gif"),
    "draw --out": (["draw", "--out", "{out}"], "target.png"),
    "export mjcf --out": (["export", "mjcf", "--out", "{out}"], "target.xml"),
    "convert-robot --out": (["convert-robot", "--out", "{out}"], "target.toml"),
    "reproduce --out": (["reproduce", "--quiet", "--out", "{out}"], "target"),
    "study init FILE": (["study", "init", "{out}"], "target.toml"),
    "study run --out": (["study", "run", "{study}", "--out", "{out}", "-q"], "target"),
}
#: Writers whose refusal does not say what is there (none now: ``study run`` names it too).
KIND_NOT_NAMED: set[str] = set()


def _make_device(path: Path) -> None:
    try:  # the null device's numbers, in a temporary folder: no real device is ever touched
        os.mknod(path, stat.S_IFCHR | 0o600, os.makedev(1, 3))
    except (PermissionError, AttributeError):
        pytest.skip("cannot create a character device here (needs root)")


def _make_socket(path: Path) -> None:
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    here = os.getcwd()
    try:  # bound by its short name: a socket's path must be under about 100 bytes
        os.chdir(path.parent)
        server.bind(path.name)
    finally:
        os.chdir(here)
        server.close()  # the socket file stays


def _make_link(to: Callable[[Path], None]) -> Callable[[Path], None]:
    def make(path: Path) -> None:
        aim = path.with_name("aim")
        to(aim)
        path.symlink_to(aim)

    return make


#: What is put at the output path, and a word the refusal must hold.
TARGETS: dict[str, tuple[Callable[[Path], None], str]] = {
    "named pipe": (os.mkfifo, "a named pipe (FIFO)"),
    "socket": (_make_socket, "a socket"),
    "character device": (_make_device, "a character device"),
    "link to a device": (_make_link(_make_device), "a symbolic link to a character device"),
    "link to a pipe": (_make_link(os.mkfifo), "a symbolic link to a named pipe"),
    "link to a file": (_make_link(lambda p: p.write_text("mine")), "a symbolic link to a file"),
    "link to a folder": (_make_link(os.mkdir), "a symbolic link to a folder"),
}


def _identity(path: Path) -> tuple[Any, ...]:
    """What must not change about the target: its inode, type, device numbers, a link's aim."""
    found = os.lstat(path)
    aim = os.readlink(path) if stat.S_ISLNK(found.st_mode) else None
    return found.st_ino, found.st_mode, found.st_rdev, found.st_size, aim


def _listing(folder: Path) -> dict[str, tuple[Any, ...]]:
    return {p.relative_to(folder).as_posix(): _identity(p) for p in sorted(folder.rglob("*"))}


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if a command starts its work (loads a robot or a study) before refusing."""

    def started(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("the work started although the output path is refused")

    for where in ("cli.command", "cli.visual", "cli.mujoco"):
        monkeypatch.setattr(f"vgtarm.app.{where}.load_robot", started)
    monkeypatch.setattr("vgtarm.app.cli.stack.load_parameters", started)
    monkeypatch.setattr("vgtarm.study.spec.load_study", started)


def _argv(writer: str, out: Path, tmp_path: Path) -> list[str]:
    template, _ = WRITERS[writer]
    names = {"{out}": str(out), "{run}": str(tmp_path / "run"), "{study}": str(tmp_path / "study.toml")}
    return [names.get(word, word) for word in template]


def _one_error_line(err: str) -> str:
    assert err.count("\n") == 1 and err.startswith("vgtarm: error: "), err
    return err


# --- before the work: every writer, every kind of target -------------------------------------


@pytest.mark.parametrize(
    ("writer", "target"),
    [
        pytest.param(writer, target, id=f"{writer}-{target}")
        for target in sorted(TARGETS)
        for writer in sorted(WRITERS)
        # a study's folder grows in place: a link to a folder is a valid one
        if (writer, target) != ("study run --out", "link to a folder")
    ],
)
def test_every_writer_refuses_a_target_that_is_not_a_regular_file_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_work: None, writer: str, target: str
) -> None:
    make, word = TARGETS[target]
    (tmp_path / "run").mkdir()
    out = tmp_path / WRITERS[writer][1]
    make(out)
    before = _listing(tmp_path)
    assert main(_argv(writer, out, tmp_path)) == 1
    err = _one_error_line(capsys.readouterr().err)
    if writer in KIND_NOT_NAMED:  # the path cut to 60 characters, and "is a file, not a folder"
        assert err.startswith(f"vgtarm: error: --out {str(out)[:40]}")
    else:
        flag = WRITERS[writer][0][WRITERS[writer][0].index("{out}") - 1]
        assert err.startswith(f"vgtarm: error: {flag if flag.startswith('-') else 'FILE'} {out}: is {word}")
        assert "expected" in err
    assert _listing(tmp_path) == before  # the target untouched, nothing written beside it


# --- at the moment of writing: the writers of fileio ---------------------------------------


@contextlib.contextmanager
def _writing(writer: str, path: Path) -> Iterator[None]:
    """One of the file writers of fileio, entered on ``path``, its text written; the block runs
    after the check on entry and before the rename."""
    if writer == "atomic_path":
        with atomic_path(path) as temporary:
            temporary.write_text("new")
            yield
    else:
        with atomic_open(path) as stream:
            stream.write("new")
            yield


@pytest.mark.parametrize("target", sorted(TARGETS))
@pytest.mark.parametrize("writer", ["atomic_path", "atomic_open"])
def test_a_file_writer_refuses_at_the_moment_of_writing_what_appeared_during_the_run(
    tmp_path: Path, writer: str, target: str
) -> None:
    make, word = TARGETS[target]
    out = tmp_path / "out.csv"
    with pytest.raises(OutputPathError) as info, _writing(writer, out):
        make(out)
        identity = _identity(out)
    assert str(info.value).startswith(f"output file {out}: is {word}") and "\n" not in str(info.value)
    assert _identity(out) == identity
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({"out.csv", *(["aim"] if "link" in target else [])})


@pytest.mark.parametrize("target", sorted(TARGETS))
def test_atomic_write_text_refuses_on_entry_and_leaves_the_target(tmp_path: Path, target: str) -> None:
    make, word = TARGETS[target]
    out = tmp_path / "out.txt"
    make(out)
    before = _listing(tmp_path)
    with pytest.raises(OutputPathError, match=f"^output file .*out.txt: is {re.escape(word)}"):
        atomic_write_text(out, "new")
    assert _listing(tmp_path) == before


@pytest.mark.parametrize("target", ["named pipe", "character device", "link to a file"])
def test_a_target_that_changes_between_the_last_look_and_the_exchange_is_swapped_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, target: str
) -> None:
    """The narrowest race: a regular file at the last look, something else when it is swapped out
    (Linux: the old entry is looked at again after the atomic exchange and swapped back)."""
    make, word = TARGETS[target]
    out = tmp_path / "out.txt"
    out.write_text("old")
    exchange = fileio._exchange
    identity: list[tuple[Any, ...]] = []

    def replaced_first(first: Path, second: Path) -> bool:
        if not identity:
            out.unlink()
            make(out)
            identity.append(_identity(out))
        return exchange(first, second)

    monkeypatch.setattr(fileio, "_exchange", replaced_first)
    try:
        atomic_write_text(out, "new")
    except OutputPathError as exc:
        assert f"out.txt: is {word}" in str(exc)
    else:  # no atomic exchange on this file system: the look before os.replace was the last guard
        pytest.skip("no renameat2(RENAME_EXCHANGE) here")
    assert _identity(out) == identity[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({"out.txt", *(["aim"] if "link" in target else [])})


def test_export_refuses_a_pipe_that_appeared_during_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from vgtarm.mujoco_bridge import export

    out = tmp_path / "robot.xml"
    to_mjcf = export.to_mjcf

    def with_a_pipe(*args: Any, **kwargs: Any) -> str:
        os.mkfifo(out)
        return to_mjcf(*args, **kwargs)

    monkeypatch.setattr(export, "to_mjcf", with_a_pipe)
    assert main(["export", "mjcf", "--out", str(out)]) == 1
    err = _one_error_line(capsys.readouterr().err)
    assert f"{out}: is a named pipe (FIFO); expected a regular file or a new file name" in err
    assert [p.name for p in tmp_path.iterdir()] == ["robot.xml"] and stat.S_ISFIFO(os.lstat(out).st_mode)


@pytest.mark.parametrize("target", ["named pipe", "character device", "link to a folder", "link to a file"])
def test_a_result_folder_whose_path_became_something_else_goes_beside_it(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, target: str
) -> None:
    make, word = TARGETS[target]
    out = tmp_path / "run"
    with fileio.placements() as moved, atomic_folder(out, "--out") as folder:
        (folder / "summary.json").write_text("new")
        make(out)
        identity = _identity(out)
    assert _identity(out) == identity  # left as it is
    assert moved == {out: tmp_path / "run-2"} and (tmp_path / "run-2" / "summary.json").read_text() == "new"
    [line] = [r.getMessage() for r in caplog.records]
    assert line == (
        f"vgtarm: --out {out}: is now {word}, not a folder; it is kept as it was, and the new results are in {out}-2"
    )


# --- read-only file systems, found before the work -----------------------------------------


@pytest.fixture
def read_only(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A folder whose file system ``statvfs`` reports as mounted read-only (root ignores
    permission bits, so this is the check that finds a read-only mount)."""
    folder = tmp_path / "ro"
    folder.mkdir()
    statvfs = os.statvfs

    class ReadOnly:
        def __init__(self, real: os.statvfs_result) -> None:
            self.real = real
            self.f_flag = real.f_flag | os.ST_RDONLY

    def faked(path: Any) -> Any:
        inside = Path(os.fsdecode(path)).absolute()
        return ReadOnly(statvfs(path)) if inside == folder or folder in inside.parents else statvfs(path)

    monkeypatch.setattr(os, "statvfs", faked)
    return folder


@pytest.mark.parametrize(
    ("writer", "where"),
    [
        pytest.param(writer, where, id=f"{writer}-{where}")
        for where in ("inside", "itself")
        for writer in sorted(WRITERS)
        # a file writer does not write into an existing folder: "itself" is for the folder writers
        if where == "inside" or "." not in WRITERS[writer][1]
    ],
)
def test_every_writer_finds_a_read_only_file_system_before_any_work(
    tmp_path: Path, read_only: Path, capsys: pytest.CaptureFixture[str], no_work: None, writer: str, where: str
) -> None:
    (tmp_path / "run").mkdir()
    name = WRITERS[writer][1]
    if where == "itself":  # the existing output folder is the read-only mount (parent writable)
        out = read_only
    else:
        out = read_only / "sub" / name
    before = _listing(tmp_path)
    assert main(_argv(writer, out, tmp_path)) == 1
    err = _one_error_line(capsys.readouterr().err)
    assert f"{out}: " in err and "is on a read-only file system" in err
    assert _listing(tmp_path) == before


@contextlib.contextmanager
def _bind_mount(folder: Path, *options: str) -> Iterator[Path]:
    """``folder`` bind-mounted onto itself with ``options`` (skips where mounting is not allowed)."""
    if os.geteuid() != 0:
        pytest.skip("mounting needs root")
    folder.mkdir()
    done = subprocess.run(["mount", "--bind", *options, str(folder), str(folder)], capture_output=True, check=False)
    if done.returncode != 0:
        pytest.skip(f"cannot mount here: {done.stderr.decode(errors='replace').strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], capture_output=True, check=True)


def test_a_real_read_only_mount_is_refused_before_the_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with _bind_mount(tmp_path / "ro", "-o", "ro") as ro:
        for out in (ro / "run", ro):
            assert main(["simulate", "--case", "1", "--duration", "0.05", "--quiet", "--out", str(out)]) == 1
            err = _one_error_line(capsys.readouterr().err)
            assert err.startswith(f"vgtarm: error: --out {out}: ") and "read-only file system" in err
        assert list(ro.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ro"]


def test_a_mount_point_is_refused_before_the_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A rename cannot replace a mount point: found before the work, not after the whole run."""
    with _bind_mount(tmp_path / "mounted") as mounted:
        assert main(["simulate", "--case", "1", "--duration", "0.05", "--quiet", "--out", str(mounted)]) == 1
        err = _one_error_line(capsys.readouterr().err)
        expected = (
            f"--out {mounted}: is a mount point, which vgtarm cannot replace by a rename; give a new name inside it"
        )
        assert err == f"vgtarm: error: {expected}\n"


def test_a_folder_without_write_permission_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "locked"
    folder.mkdir()
    access = os.access
    monkeypatch.setattr(os, "access", lambda path, mode: Path(path) != folder and access(path, mode))
    with pytest.raises(InputError, match=r"cannot write in .*locked \(permission denied\)$"):
        check_output_file(folder / "out.csv", "-o")


# --- printed paths are escaped -------------------------------------------------------------

#: Characters a file name may hold that must never reach the terminal raw, and some that may.
ODD = ["\n", "\r", "\t", "\x1b[31m", "\x1b]0;title\x07", "\x7f", "\x9b", "\u2028", "\u202e"]
NAMES = (
    st.lists(
        st.one_of(
            st.sampled_from([*ODD, " ", "é", "名", "'", '"', "\\", "$(id)", "-", ".", "%s", "{}"]),
            st.text(st.characters(exclude_categories=("Cs",), exclude_characters="/\0"), max_size=4),
        ),
        min_size=1,
        max_size=6,
    )
    .map("".join)
    .filter(lambda name: name not in ("", ".", "..") and len(name.encode()) <= 120)
)


def fuzz(examples: int) -> Any:
    """Reproducible settings (the project's rule), as in ``tests/test_fuzz.py``."""
    return settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )


def _clean(text: str) -> bool:
    """No character that could drive a terminal: only printable ones and the line ends."""
    return all(line.isprintable() for line in text.split("\n"))


def _written_under_an_odd_name(capsys: pytest.CaptureFixture[str], argv: list[str], line: str, name: str) -> None:
    """Run ``argv`` with ``{out}`` a path ending in ``name``: every printed character is printable
    (the path escaped in the ``written to`` line), and the folder holds the result alone, or
    nothing after a refusal."""
    with tempfile.TemporaryDirectory() as where:
        out = Path(where) / name
        capsys.readouterr()
        status = main([str(out) if word == "{out}" else word for word in argv])
        captured = capsys.readouterr()
        assert _clean(captured.out) and _clean(captured.err)
        left = sorted(os.listdir(where))
        if status == 0:
            assert captured.out.splitlines()[-1] == line.format(shown=escape(str(out)))
            assert left == [name]  # the result and nothing beside it
        else:
            _one_error_line(captured.err)
            assert left == []


@fuzz(60)
@given(name=NAMES)
def test_an_odd_file_name_is_printed_escaped_and_leaves_nothing_partial(
    capsys: pytest.CaptureFixture[str], name: str
) -> None:
    line = "stack of 2 modules and 1 twist joint written to {shown}"
    _written_under_an_odd_name(capsys, ["convert-robot", "--out", "{out}"], line, name)


@fuzz(12)
@given(name=NAMES)
def test_an_odd_folder_name_is_printed_escaped_and_leaves_nothing_partial(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, name: str
) -> None:
    """The run's figure is an empty one here: drawing the real one took most of each example's
    seconds and has nothing to do with the name (it is still written, by ``save_figure``, into the
    folder under the odd name)."""
    from matplotlib.figure import Figure

    monkeypatch.setattr("vgtarm.app.pictures.plotting.comparison_figure", lambda results: Figure(figsize=(1, 1)))
    argv = ["simulate", "--case", "1", "--duration", "0.05", "--quiet", "--out", "{out}"]
    _written_under_an_odd_name(capsys, argv, "results written to {shown}", name)


@pytest.mark.parametrize("name", ["a\ud800b", "x\0y"])
def test_names_that_cannot_be_file_names_are_refused_in_one_line(tmp_path: Path, name: str) -> None:
    with pytest.raises(InputError) as info:
        check_output_file(tmp_path / name, "-o")
    assert str(info.value).startswith("-o ") and _clean(str(info.value)) and "\n" not in str(info.value)
