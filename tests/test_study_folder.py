"""A study's results folder (issue 33, second probe): vgtarm writes only in a folder it made or
recognises as a study folder of its own, never over a user's file of the study's names and never
through a link; and the scratch folders of the export's compiler runs do not outlive a SIGKILL.

- ``study run --out DIR`` refuses, in one line before any work, a folder that is not empty and not
  a study folder vgtarm wrote (``.vgtarm-study``), the current folder, and a folder that is or
  holds an input (the study file, its robot or path file); a marked folder whose files of the
  study's names are not all listed, or whose log has another link; ``study report`` refuses a
  ``report.md`` or figure vgtarm did not write;
- at the moment of writing the log is opened without following a link and refused unless it is
  a regular file with one link; the tables and the report only replace files vgtarm listed;
- a folder written before the mark existed (run files and the study's own names only) resumes and
  is marked;
- ``vgtarm.fileio.scratch_folder`` names its folders ``<prefix><pid>-*`` and removes those of
  processes that are gone (the export's check compile and compiler probe use it).

The one real study (one point, 50 ms of case 1) runs once for the module; every other case is
refused before any work or resumes without running anything (no cluster is started).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

from vgtarm.app.cli.command import main  # noqa: E402
from vgtarm.app.study_points import execute_point  # noqa: E402
from vgtarm.errors import InputError  # noqa: E402
from vgtarm.fileio import OutputPathError, clean_stale_scratch, scratch_folder  # noqa: E402
from vgtarm.study import Store, load_study  # noqa: E402
from vgtarm.study.report import write_report  # noqa: E402
from vgtarm.study.runner import run_study  # noqa: E402
from vgtarm.study.store import MARK  # noqa: E402

STUDY = '[study]\ncase = 1\nduration = 0.05\nseeds = [0]\n[grid]\ncontroller = "cfc"\n'
#: Longest time a refusal may take (s): it comes before any work.
REFUSED_WITHIN = 5.0


def _state(folder: Path) -> dict[str, tuple[Any, ...]]:
    """Every entry under ``folder``: its type, inode, links and, for a file, its bytes."""
    found: dict[str, tuple[Any, ...]] = {}
    for path in sorted(folder.rglob("*")):
        info = os.lstat(path)
        data = path.read_bytes() if stat.S_ISREG(info.st_mode) else None
        found[path.relative_to(folder).as_posix()] = (stat.S_IFMT(info.st_mode), info.st_ino, info.st_nlink, data)
    return found


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """Run ``argv`` here: it must fail at once with one line; returns the line."""
    capsys.readouterr()
    start = time.monotonic()
    status = main(argv)
    took = time.monotonic() - start
    err = capsys.readouterr().err
    assert status == 1, (argv, err)
    assert err.count("\n") == 1 and err.startswith("vgtarm: error: "), err
    assert took < REFUSED_WITHIN, f"{argv}: refused after {took:.1f} s"
    return err.removeprefix("vgtarm: error: ").rstrip("\n")


@pytest.fixture(scope="module")
def study_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A study folder vgtarm wrote: one point run into a folder that existed, empty."""
    folder = tmp_path_factory.mktemp("study")
    (folder / "s.toml").write_text(STUDY)
    (folder / "out").mkdir()
    run = run_study(load_study(folder / "s.toml"), folder / "out", execute_point, workers=1, progress=False)
    assert run.executed == 1 and run.failed == 0
    return folder / "out"


@pytest.fixture
def here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The working folder of a test: the study file ``s.toml``; no study may start."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(STUDY)

    def ran(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("the study started before the refusal")

    monkeypatch.setattr("vgtarm.study.runner.run_study", ran)
    return tmp_path


def _copy(study_run: Path, to: Path) -> Path:
    shutil.copytree(study_run, to)
    return to


# --- study run --out: refused before any work -------------------------------------------------


def _user_files(here: Path, study_run: Path) -> str:
    (here / "userdir").mkdir()
    (here / "userdir" / "results.csv").write_text("data\n")
    (here / "userdir" / "executions.log").write_text("log\n")
    return "userdir"


def _user_notes(here: Path, study_run: Path) -> str:
    (here / "userdir").mkdir()
    (here / "userdir" / "notes.txt").write_text("mine\n")
    return "userdir"


def _hard_linked_log_of_a_user(here: Path, study_run: Path) -> str:
    (here / "userdir").mkdir()
    (here / "victim.txt").write_text("victim\n")
    os.link(here / "victim.txt", here / "userdir" / "executions.log")
    return "userdir"


def _current_folder(here: Path, study_run: Path) -> str:
    return "."


def _holds_the_study_file(here: Path, study_run: Path) -> str:
    (here / "inputs").mkdir()
    os.replace(here / "s.toml", here / "inputs" / "s.toml")
    (here / "s.toml").symlink_to(here / "inputs" / "s.toml")  # the command names ./s.toml
    return "inputs"


def _holds_the_path_file(here: Path, study_run: Path) -> str:
    _copy(study_run, here / "out")  # a study folder of vgtarm's: found holding the input once the study is read
    (here / "out" / "tip.csv").write_text("t,x,y,z\n0,0,0.06,0.66\n0.01,0,0.06,0.66\n")
    (here / "s.toml").write_text('[study]\npath = "out/tip.csv"\nseeds = [0]\n[grid]\ncontroller = "cfc"\n')
    return "out"


def _holds_the_robot_file(here: Path, study_run: Path) -> str:
    from importlib import resources

    _copy(study_run, here / "out")
    robot = resources.files("vgtarm.model.data").joinpath("reference_robot.toml").read_text("utf-8")
    (here / "out" / "robot.toml").write_text(robot)
    (here / "s.toml").write_text(STUDY.replace("seeds", 'robot = "out/robot.toml"\nseeds'))
    return "out"


def _marked_with_a_user_table(here: Path, study_run: Path) -> str:
    out = _copy(study_run, here / "out")
    (out / "results.csv").unlink()
    (out / "results.csv").write_text("mine\n")
    (out / MARK).write_text((out / MARK).read_text().replace("results.csv\n", ""))
    return "out"


def _marked_with_a_user_figure(here: Path, study_run: Path) -> str:
    out = _copy(study_run, here / "out")
    (out / "study_error_distribution.png").write_bytes(b"mine")
    return "out"


def _marked_with_a_hard_linked_log(here: Path, study_run: Path) -> str:
    out = _copy(study_run, here / "out")
    (out / "executions.log").unlink()
    (here / "victim.txt").write_text("victim\n")
    os.link(here / "victim.txt", out / "executions.log")
    return "out"


def _marked_with_a_linked_log(here: Path, study_run: Path) -> str:
    out = _copy(study_run, here / "out")
    (out / "executions.log").unlink()
    (here / "victim.txt").write_text("victim\n")
    (out / "executions.log").symlink_to(here / "victim.txt")
    return "out"


def _an_earlier_version_without_run_files(here: Path, study_run: Path) -> str:
    out = _copy(study_run, here / "out")
    (out / MARK).unlink()
    for run in out.glob("*.json"):
        run.unlink()
    return "out"


#: What is at --out, made by a function of (the working folder, a study folder vgtarm wrote) that
#: returns the --out, and words the refusal holds.
REFUSED: dict[str, tuple[Callable[[Path, Path], str], str]] = {
    "a user's results.csv and executions.log": (_user_files, "--out userdir: holds 'executions.log' but no run file"),
    "a user's notes": (_user_notes, "--out userdir: holds 'notes.txt' and no .vgtarm-study"),
    "a user's log, a hard link": (_hard_linked_log_of_a_user, "holds 'executions.log' with 2 links to it"),
    "the current folder": (_current_folder, "--out .: is the current folder"),
    "the folder of the study file": (_holds_the_study_file, "--out inputs: holds"),
    "the folder of the path file": (_holds_the_path_file, "an input of this command"),
    "the folder of the robot file": (_holds_the_robot_file, "an input of this command"),
    "a study folder with a user's table": (_marked_with_a_user_table, "holds 'results.csv', which vgtarm did not"),
    "a study folder with a user's figure": (_marked_with_a_user_figure, "holds 'study_error_distribution.png'"),
    "a study folder whose log has a hard link": (_marked_with_a_hard_linked_log, "with 2 links to it"),
    "a study folder whose log is a symbolic link": (_marked_with_a_linked_log, "is a symbolic link to a file"),
    "an earlier version's names, no run file": (_an_earlier_version_without_run_files, "but no run file"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_study_run_writes_only_in_a_study_folder_of_its_own(
    here: Path, study_run: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    make, words = REFUSED[case]
    out = make(here, study_run)
    before = _state(here)
    line = _refused(capsys, ["study", "run", "s.toml", "--out", out, "-q"])
    assert words in line, line
    assert _state(here) == before  # nothing changed, nothing written beside


# --- resuming a study folder: no cluster, nothing run -------------------------------------------


def _resume(out: Path, study_file: Path) -> Any:
    run = run_study(load_study(study_file), out, execute_point, workers=1, progress=False)
    assert run.executed == 0 and run.skipped == 1
    return run


def test_a_study_folder_vgtarm_wrote_is_marked_and_resumes_leaving_a_user_s_notes(
    study_run: Path, tmp_path: Path
) -> None:
    listed = (study_run / MARK).read_text().splitlines()[1:]
    assert listed == ["executions.log", "results.csv", "results.parquet"]
    out = _copy(study_run, tmp_path / "out")
    (out / "notes.txt").write_text("mine\n")
    table = os.lstat(out / "results.csv").st_ino
    _resume(out, study_run.parent / "s.toml")
    assert (out / "notes.txt").read_text() == "mine\n"
    assert os.lstat(out / "results.csv").st_ino != table  # replaced by a rename, never written in place


def test_a_study_folder_of_an_earlier_version_resumes_and_is_marked(study_run: Path, tmp_path: Path) -> None:
    out = _copy(study_run, tmp_path / "out")
    (out / MARK).unlink()
    (out / "report.md").write_text("an earlier version's report\n")
    _resume(out, study_run.parent / "s.toml")
    listed = (out / MARK).read_text().splitlines()[1:]
    assert listed == ["executions.log", "report.md", "results.csv", "results.parquet"]


#: What the log becomes during the run, and a word the refusal holds.
LOG_CHANGES = {"a hard link": "2 links", "a symbolic link": "symbolic link", "a named pipe": "named pipe"}


@pytest.mark.parametrize("race", [False, True], ids=["found by the claim", "found on the open descriptor"])
@pytest.mark.parametrize("what", sorted(LOG_CHANGES))
def test_the_log_is_never_appended_through_a_link_made_during_the_run(
    study_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, what: str, race: bool
) -> None:
    out = _copy(study_run, tmp_path / "out")
    store = Store(out)
    store.prepare()  # checked and marked: the run goes on, then the log changes under it
    victim = tmp_path / "victim.txt"
    victim.write_text("victim\n")
    if what == "a hard link":
        os.link(out / "executions.log", tmp_path / "elsewhere.log")
    else:
        (out / "executions.log").unlink()
        if what == "a symbolic link":
            (out / "executions.log").symlink_to(victim)
        else:
            os.mkfifo(out / "executions.log")
    if race:  # the change comes after the claim looked: the open itself refuses
        monkeypatch.setattr(Store, "_entry", lambda self, name, listed: None)
    with pytest.raises(OutputPathError, match="executions.log") as caught:
        store.note("write", ["0123456789abcdef"])
    assert "\n" not in str(caught.value) and LOG_CHANGES[what] in str(caught.value)
    assert str(caught.value).startswith("study log " if race else "study folder "), caught.value
    assert victim.read_text() == "victim\n"
    if what == "a hard link":
        assert "0123456789abcdef" not in (tmp_path / "elsewhere.log").read_text()


def test_the_tables_never_replace_a_user_s_file_that_appeared_during_the_run(study_run: Path, tmp_path: Path) -> None:
    out = _copy(study_run, tmp_path / "out")
    store = Store(out)
    store.prepare()
    (out / "results.parquet").unlink()
    (out / MARK).write_text((out / MARK).read_text().replace("results.parquet\n", ""))
    (out / "results.parquet").write_text("mine\n")
    with pytest.raises(OutputPathError, match="holds 'results.parquet', which vgtarm did not write there"):
        store.write_tables(store.rows())
    assert (out / "results.parquet").read_text() == "mine\n"


def test_a_new_log_is_created_only_if_no_file_is_there(tmp_path: Path) -> None:
    store = Store(tmp_path / "new")
    store.prepare()
    store.note("submit", ["a"])
    assert (tmp_path / "new" / "executions.log").read_text() == "submit a\n"
    assert "executions.log" in (store.listed() or set())


def test_run_study_refuses_a_folder_it_may_not_write_in_before_any_run(tmp_path: Path) -> None:
    (tmp_path / "s.toml").write_text(STUDY)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "results.csv").write_text("mine\n")
    with pytest.raises(InputError, match="^study folder .*out: holds 'results.csv' but no run file"):
        run_study(load_study(tmp_path / "s.toml"), tmp_path / "out", execute_point, workers=1, progress=False)
    assert (tmp_path / "out" / "results.csv").read_text() == "mine\n"


# --- study report -------------------------------------------------------------------------------


def test_study_report_refuses_a_user_s_report_and_writes_its_own(
    study_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = _copy(study_run, tmp_path / "out")
    (out / "report.md").write_text("my report\n")
    before = _state(out)
    line = _refused(capsys, ["study", "report", str(out)])
    assert "holds 'report.md', which vgtarm did not write there" in line, line
    assert _state(out) == before
    (out / "report.md").unlink()
    assert main(["study", "report", str(out)]) == 0
    assert {"report.md", "study_error_distribution.png"} <= set((out / MARK).read_text().splitlines())
    assert main(["study", "report", str(out)]) == 0  # its own report: replaced


def test_study_report_writes_only_in_a_study_folder(tmp_path: Path, study_run: Path) -> None:
    """A folder holding a valid results table but no run file and no mark is not a study folder."""
    folder = tmp_path / "tables"
    folder.mkdir()
    shutil.copyfile(study_run / "results.parquet", folder / "results.parquet")
    before = _state(folder)
    with pytest.raises(OutputPathError, match="holds 'results.parquet' but no run file"):
        write_report(folder)
    assert _state(folder) == before


# --- scratch folders of the compiler runs -------------------------------------------------------


def _dead_pid() -> int:
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


@pytest.fixture
def scratch_here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The system's temporary folder, for this test: ``tmp_path / "tmp"``."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


@pytest.mark.parametrize("prefix", ["vgtc-check-", "vgtc-probe-"])
def test_scratch_folders_carry_the_pid_and_those_of_gone_processes_are_removed(scratch_here: Path, prefix: str) -> None:
    dead = scratch_here / f"{prefix}{_dead_pid()}-abc"
    (dead / "sub").mkdir(parents=True)
    (dead / "sub" / "x.o").write_text("object")
    alive = scratch_here / f"{prefix}1-abc"  # init's: a process that runs
    alive.mkdir()
    elsewhere = scratch_here.parent / "keep"
    elsewhere.mkdir()
    link = scratch_here / f"{prefix}{_dead_pid()}-link"
    link.symlink_to(elsewhere)
    other = scratch_here / f"{prefix}abc"  # not a name of this pattern
    other.mkdir()
    with scratch_folder(prefix) as scratch:
        assert re.fullmatch(rf"{prefix}{os.getpid()}-\S+", scratch.name) and scratch.parent == scratch_here
        assert not dead.exists()
    assert not scratch.exists()
    assert alive.is_dir() and link.is_symlink() and elsewhere.is_dir() and other.is_dir()


def test_a_scratch_folder_left_by_a_sigkill_is_removed_by_the_next_run(scratch_here: Path) -> None:
    code = (
        "import os, signal\n"
        "from vgtarm.fileio import scratch_folder\n"
        "with scratch_folder('vgtc-check-') as s:\n"
        "    (s / 'vgt.o').write_text('object')\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], env={**os.environ, "TMPDIR": str(scratch_here)}, timeout=60)
    assert done.returncode == -signal.SIGKILL
    (left,) = scratch_here.iterdir()  # what a SIGKILL leaves
    assert re.fullmatch(r"vgtc-check-\d+-\S+", left.name) and (left / "vgt.o").exists()
    assert clean_stale_scratch("vgtc-check-") == [left]
    assert not left.exists()


def test_the_export_s_check_compile_and_probe_use_scratch_folders_of_their_pid(
    scratch_here: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from vgtarm.export import controller

    outputs: list[Path] = []

    def compiled(command: list[str], what: str, *, limit: float | None = None) -> None:
        outputs.append(Path(command[command.index("-o") + 1]))

    monkeypatch.setattr(controller, "run_compiler", compiled)
    monkeypatch.setattr(controller, "_compiler", lambda: "cc")
    stale = [scratch_here / f"vgtc-{kind}-{_dead_pid()}-x" for kind in ("check", "probe")]
    for folder in stale:
        folder.mkdir()
    export = tmp_path / "export"
    export.mkdir()
    (export / "vgt_control.c").write_text("int x;\n")
    controller.probe_compiler()
    controller.check_compile(export, "cc")
    assert [p.parent.name.rsplit("-", 1)[0] for p in outputs] == [
        f"vgtc-probe-{os.getpid()}",
        f"vgtc-check-{os.getpid()}",
    ]
    assert not any(p.exists() for p in stale) and list(scratch_here.iterdir()) == []
