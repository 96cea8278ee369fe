"""Result folders written as units, output paths checked before the work, quiet closed pipes.

The folder helper (:func:`vgtarm.fileio.atomic_folder`) is tested directly, with the Linux
atomic exchange and with the rename-aside fallback; the command-line cases are the ones of
issue 14: a failed run into the folder of an earlier run, Ctrl-C while the figure is drawn, an
output path that is a file, ``ik -o`` naming its input, ``describe | head -1``. Issue 20 (item 2):
a folder that gains a user's file, folder or pipe during the run, or at the last moment around
the swap, keeps it, and the result goes beside it with one line saying where.
"""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import textwrap
from pathlib import Path
from unittest.mock import ANY

import pytest

from vgtarm import fileio
from vgtarm.app.cli.command import CLOSED_PIPE, main
from vgtarm.errors import InputError
from vgtarm.fileio import MANIFEST, atomic_folder, atomic_path, check_output_file, check_output_folder, clean_stale

#: A short, cheap run of case 1 (50 control periods).
SHORT = ["simulate", "--case", "1", "--duration", "0.05", "--quiet"]
#: The same run with a controller model 1000 times too heavy: it diverges within a few periods.
DIVERGING = [*SHORT, "--model-mass", "1000", "--model-inertia", "1000"]


def _listing(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


@pytest.fixture(params=["exchange", "rename-aside"])
def swap(request, monkeypatch):
    """Run a test with the atomic exchange of Linux and again with the portable fallback."""
    if request.param == "rename-aside":
        monkeypatch.setattr(fileio, "_exchange", lambda first, second: False)
    return request.param


# --- the helper -----------------------------------------------------------------------------


def test_a_complete_folder_replaces_the_old_one_whole(tmp_path, swap):
    target = tmp_path / "run"
    with atomic_folder(target) as folder:
        (folder / "figure.png").write_bytes(b"old figure")
        (folder / "sub").mkdir()
        (folder / "sub" / "a.csv").write_text("old")
    with atomic_folder(target) as folder:
        assert folder.parent == tmp_path and folder.name.startswith(".run.") and not target.samefile(folder)
        (folder / "summary.json").write_text("new")
        assert (target / "figure.png").read_bytes() == b"old figure"  # untouched until complete
    assert sorted(_listing(target)) == [MANIFEST, "summary.json"]
    assert (target / MANIFEST).read_text().splitlines()[1:] == ["summary.json"]
    assert [p.name for p in tmp_path.iterdir()] == ["run"]  # no temporary or set-aside folder left


@pytest.mark.parametrize("error", [RuntimeError("boom"), KeyboardInterrupt()])
def test_an_error_or_ctrl_c_leaves_the_old_folder_and_no_temporary(tmp_path, swap, error):
    target = tmp_path / "run"
    with atomic_folder(target) as folder:
        (folder / "summary.json").write_text("old")
    before = _listing(target)
    with pytest.raises(type(error)), atomic_folder(target) as folder:
        (folder / "summary.json").write_text("new")
        raise error
    assert _listing(target) == before
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_an_error_in_a_new_folder_leaves_nothing_not_even_its_parents(tmp_path):
    with pytest.raises(RuntimeError), atomic_folder(tmp_path / "a" / "b" / "run") as folder:
        (folder / "x").write_text("partial")
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_stale_temporaries_of_dead_processes_are_cleaned_on_the_next_run(tmp_path):
    dead, alive = _dead_pid(), os.getpid()
    stale_folder = tmp_path / f".run.{dead}.0123abcd.tmp"
    stale_folder.mkdir()
    (stale_folder / "summary.json").write_text("half")
    stale_file = tmp_path / f".figure.{dead}.89abcdef.tmp.png"
    stale_file.write_bytes(b"half")
    in_use = tmp_path / f".other.{alive}.00000000.tmp"  # a live writer's: kept
    in_use.mkdir()
    set_aside = tmp_path / f".kept.{dead}.11111111.old"  # killed between the two renames: put back
    set_aside.mkdir()
    (set_aside / "summary.json").write_text("the old run")
    user = tmp_path / f".notes.{dead}.tmp"  # not our pattern (no random part): never touched
    user.write_text("mine")
    with atomic_folder(tmp_path / "run") as folder:
        (folder / "summary.json").write_text("new")
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == sorted([in_use.name, user.name, "kept", "run"])
    assert (tmp_path / "kept" / "summary.json").read_text() == "the old run"
    assert clean_stale(tmp_path) == []


def test_sigkill_leaves_only_a_hidden_temporary_that_the_next_run_removes(tmp_path):
    target = tmp_path / "run"
    with atomic_folder(target) as folder:
        (folder / "summary.json").write_text("old")
    script = textwrap.dedent(
        f"""
        import sys, time
        from vgtarm.fileio import atomic_folder
        with atomic_folder({str(target)!r}) as folder:
            (folder / "summary.json").write_text("new, not finished")
            print("writing", flush=True)
            time.sleep(60)
        """
    )
    child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None and child.stdout.readline() == "writing\n"
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left[1:] == ["run"] and left[0].startswith(f".run.{child.pid}.") and left[0].endswith(".tmp")
    assert (target / "summary.json").read_text() == "old"
    with atomic_folder(target) as folder:
        (folder / "summary.json").write_text("next")
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_a_folder_with_files_vgtarm_did_not_write_is_refused_not_deleted(tmp_path):
    target = tmp_path / "mine"
    target.mkdir()
    (target / "notes.txt").write_text("keep me")
    with pytest.raises(InputError, match=r"^--out .*mine: the folder holds 'notes.txt' and no \.vgtarm-output list"):
        with atomic_folder(target, "--out"):
            pytest.fail("the block must not run")
    with atomic_folder(tmp_path / "run") as folder:  # a run folder the user added a video to later
        (folder / "summary.json").write_text("run")
    (tmp_path / "run" / "video.mp4").write_bytes(b"video")
    with pytest.raises(InputError, match="'video.mp4', which vgtarm did not write"):
        check_output_folder(tmp_path / "run")
    assert (target / "notes.txt").read_text() == "keep me" and (tmp_path / "run" / "video.mp4").exists()


def test_a_folder_written_before_the_file_list_existed_is_replaced_if_it_holds_only_run_files(tmp_path):
    legacy = tmp_path / "run"
    legacy.mkdir()
    (legacy / "summary.json").write_text("old")
    (legacy / "figure.png").write_bytes(b"old")
    with atomic_folder(legacy, owned=("summary.json", "*.png")) as folder:
        (folder / "summary.json").write_text("new")
    assert sorted(_listing(legacy)) == [MANIFEST, "summary.json"]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: p.write_text("x"), "is a file, not a folder"),
        (lambda p: (p.parent.joinpath("f").write_text("x"), p.parent / "f" / "run")[1], "f is a file, not a folder"),
        (lambda p: p.symlink_to(p.parent), "is a symbolic link"),
    ],
)
def test_bad_output_folders_are_named_in_one_line(tmp_path, make, message):
    path = tmp_path / "out"
    made = make(path)
    target = made if isinstance(made, Path) else path
    with pytest.raises(InputError, match=message) as info:
        check_output_folder(target, "--out")
    assert str(info.value).startswith(f"--out {target}:") and "\n" not in str(info.value)


def test_the_current_folder_and_a_folder_holding_an_input_are_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match="is the current folder"):
        check_output_folder(".", "--out")
    (tmp_path / "runs" / "a").mkdir(parents=True)
    with pytest.raises(InputError, match=r"runs: holds .*a, an input of this command"):
        check_output_folder(tmp_path / "runs", "--out", inputs=[Path("runs/a"), None])


def test_bad_output_files_are_named_in_one_line(tmp_path):
    source = tmp_path / "path.csv"
    source.write_text("t,x,y,z\n")
    with pytest.raises(InputError, match=r"^-o .*path\.csv: is an input of this command"):
        check_output_file(tmp_path / "." / "path.csv", "-o", inputs=[source])
    with pytest.raises(InputError, match="is a folder; give a file name"):
        check_output_file(tmp_path, "-o")
    with pytest.raises(InputError, match="path.csv is a file, not a folder"):
        check_output_file(source / "ref.csv", "-o")
    assert check_output_file(tmp_path / "new" / "ref.csv", "-o") == tmp_path / "new" / "ref.csv"


@pytest.mark.parametrize("check", [check_output_file, check_output_folder])
def test_names_the_system_cannot_look_up_are_one_line_errors(tmp_path, check):
    """A NUL character (possible only through the API, or a file the user gives) or a name too
    long for the file system: an InputError naming the flag and the value, never a ValueError."""
    kind = "file" if check is check_output_file else "folder"
    with pytest.raises(InputError, match=rf"^-o '.*/a\\x00b': a {kind} name cannot hold a NUL character$"):
        check(f"{tmp_path}/a\0b", "-o")
    with pytest.raises(InputError, match=r"^--out 'x\\x00': a"):
        check(Path("x\0"), "--out")
    long = tmp_path / ("n" * 300) / "x.csv"
    too_long = r"^-o .*nnn\.\.\. \(\d+ more characters\): cannot be used \(File name too long\)$"
    with pytest.raises(InputError, match=too_long):
        check(long, "-o")
    with pytest.raises(InputError, match="cannot hold a NUL character"), atomic_folder(tmp_path / "r\0n"):
        raise AssertionError("the block ran")
    assert list(tmp_path.iterdir()) == []


def test_write_errors_name_the_users_path_not_the_temporary(tmp_path):
    target = tmp_path / "run"
    with pytest.raises(FileNotFoundError) as info, atomic_folder(target) as folder:
        (folder / "missing" / "figure.png").write_bytes(b"x")
    assert info.value.filename == str(target / "missing" / "figure.png") and ".tmp" not in str(info.value)
    with pytest.raises(OSError) as info, atomic_path(tmp_path / "no" / "ref.csv") as temporary:
        temporary.write_text("x")
    assert info.value.filename == str(tmp_path / "no" / "ref.csv")


# --- files added during the run (issue 20, item 2) --------------------------------------------


def _add_notes(folder: Path) -> None:
    (folder / "NOTES.txt").write_text("mine")


def _add_video_folder(folder: Path) -> None:
    (folder / "videos").mkdir()
    (folder / "videos" / "case1.gif").write_bytes(b"GIF89a")


def _add_empty_folder(folder: Path) -> None:
    (folder / "later").mkdir()


def _replace_a_listed_file_by_a_pipe(folder: Path) -> None:
    (folder / "summary.json").unlink()
    os.mkfifo(folder / "summary.json")


FOREIGN = {
    "a note": _add_notes,
    "a folder with a video": _add_video_folder,
    "an empty folder": _add_empty_folder,
    "a pipe in place of a listed file": _replace_a_listed_file_by_a_pipe,
}


def _tree(folder: Path) -> dict[str, object]:
    """Every entry under ``folder``: a file's bytes, else its kind (a pipe is never opened)."""
    found: dict[str, object] = {}
    for path in sorted(folder.rglob("*")):
        mode = path.lstat().st_mode
        found[path.relative_to(folder).as_posix()] = path.read_bytes() if stat.S_ISREG(mode) else stat.S_IFMT(mode)
    return found


@pytest.mark.parametrize("added", sorted(FOREIGN))
def test_a_folder_that_gained_a_users_file_during_the_run_is_kept_and_the_result_goes_beside_it(
    tmp_path, swap, caplog, added
):
    target = tmp_path / "run"
    with atomic_folder(target) as folder:
        (folder / "summary.json").write_text("old")
        (folder / "figure.png").write_bytes(b"old figure")
    with fileio.placements() as moved, atomic_folder(target, "--out") as folder:
        (folder / "summary.json").write_text("new")
        FOREIGN[added](target)  # while the run writes its temporary folder
        during = _tree(target)
    assert _tree(target) == during  # nothing of the old folder touched, the user's entry kept
    assert moved == {target: tmp_path / "run-2"}
    assert _listing(tmp_path / "run-2") == {MANIFEST: ANY, "summary.json": b"new"}
    [line] = [r.getMessage() for r in caplog.records]
    assert line.startswith(f"vgtarm: --out {target}: the folder holds '") and "\n" not in line
    assert line.endswith(
        f"which vgtarm did not write there; it is kept as it was, and the new results are in {target}-2"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run", "run-2"]


def test_an_old_folder_without_a_file_list_that_gained_a_file_is_kept_too(tmp_path, swap, caplog):
    legacy = tmp_path / "run"
    legacy.mkdir()
    (legacy / "summary.json").write_text("old")
    with fileio.placements() as moved, atomic_folder(legacy, owned=("summary.json",)) as folder:
        (folder / "summary.json").write_text("new")
        (legacy / "notes.md").write_text("mine")
    assert _listing(legacy) == {"summary.json": b"old", "notes.md": b"mine"}
    assert moved[legacy] == tmp_path / "run-2" and "no .vgtarm-output list" in caplog.records[0].getMessage()


@pytest.mark.parametrize("second", [False, True], ids=["after the first look", "after the look again"])
def test_a_file_added_at_the_last_moment_is_never_deleted(tmp_path, swap, monkeypatch, caplog, second):
    """The race: a file lands in the old folder after a check at the swap. After the first look
    (before the exchange or the rename aside), the look again finds it: the old folder is put
    back and the result goes beside. After the look again (the old folder already swapped out),
    emptying it from its list leaves that file, and the folder is kept beside."""
    target = tmp_path / "run"
    with atomic_folder(target) as folder:
        (folder / "summary.json").write_text("old")
    looked: list[Path] = []
    foreign = fileio._foreign

    def late_file(folder: Path, owned):
        reason = foreign(folder, owned)
        looked.append(folder)
        if len(looked) == (2 if second else 1):
            (folder / "late.txt").write_text("mine")  # the old folder, wherever it is now
        return reason

    with fileio.placements() as moved, atomic_folder(target) as folder:
        (folder / "summary.json").write_text("new")
        monkeypatch.setattr(fileio, "_foreign", late_file)
    assert len(looked) == 2  # looked at twice at the swap
    [line] = [r.getMessage() for r in caplog.records]
    kept = tmp_path / "run-2"
    if second:  # the new result is in place; the old folder's own files are gone, the late one kept
        assert _listing(target) == {MANIFEST: ANY, "summary.json": b"new"} and moved == {}
        assert _listing(kept) == {"late.txt": b"mine"}
        assert line == (
            f"vgtarm: output folder {target}: files vgtarm did not write appeared in the folder while it was"
            f" replaced; kept them in {kept}"
        )
    else:  # the old folder is back as it was, with the late file; the result beside it
        assert _listing(target) == {MANIFEST: ANY, "summary.json": b"old", "late.txt": b"mine"}
        assert _listing(kept) == {MANIFEST: ANY, "summary.json": b"new"} and moved == {target: kept}
        assert "the folder holds 'late.txt'" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run", "run-2"]


def test_a_killed_swap_leaves_foreign_files_that_the_next_run_keeps(tmp_path, caplog):
    """An old folder set aside by a run killed after its swap is emptied from its list by the
    next run, never removed as a tree; a pipe at a temporary name is never touched."""
    dead = _dead_pid()
    with atomic_folder(tmp_path / "run") as folder:
        (folder / "summary.json").write_text("new")
    aside = tmp_path / f".run.{dead}.0123abcd.old"
    with atomic_folder(aside) as folder:  # an old run folder, with its list
        (folder / "summary.json").write_text("old")
    (aside / "NOTES.txt").write_text("mine")
    pipe = tmp_path / f".other.{dead}.89abcdef.tmp"
    os.mkfifo(pipe)
    clean_stale(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([pipe.name, "run", "run-2"])
    assert _listing(tmp_path / "run-2") == {"NOTES.txt": b"mine"} and "kept them in" in caplog.records[0].getMessage()


# --- the command line -----------------------------------------------------------------------


def test_a_failed_run_replaces_the_folder_of_an_earlier_run_whole(tmp_path, capsys):
    out = tmp_path / "run"
    assert main([*SHORT, "--out", str(out)]) == 0
    assert (out / "figure.png").exists() and json.loads((out / "summary.json").read_text())["success"] is True
    capsys.readouterr()
    assert main([*DIVERGING, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("vgtarm: error: diverged at t = ")  # one line, saying where
    assert err.endswith(f"; partial results (up to the failure, success false) written to {out}\n")
    assert sorted(_listing(out)) == [MANIFEST, "ga_activations.csv", "summary.json", "timeseries.csv"]  # no figure
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success"] is False and 0 < summary["samples_completed"] < summary["samples"]
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_ctrl_c_while_the_figure_is_drawn_leaves_the_earlier_run(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    assert main([*SHORT, "--out", str(out)]) == 0
    before = _listing(out)

    def interrupted(fig, path, **kwargs):
        Path(path).write_bytes(b"half a figure")
        raise KeyboardInterrupt

    monkeypatch.setattr("vgtarm.app.pictures.plotting.save_figure", interrupted)
    assert main([*SHORT, "--seed", "3", "--out", str(out)]) == 130
    assert _listing(out) == before
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


@pytest.mark.parametrize("kind", ["file", "parent is a file", "foreign folder"])
def test_a_bad_output_folder_fails_before_the_run(tmp_path, capsys, monkeypatch, kind):
    def no_run(*args, **kwargs):
        raise AssertionError("the run started although the output path is bad")

    monkeypatch.setattr("vgtarm.experiment.cases.run_case", no_run)
    out = tmp_path / "out"
    if kind == "file":
        out.write_text("a file")
    elif kind == "parent is a file":
        (tmp_path / "f").write_text("a file")
        out = tmp_path / "f" / "out"
    else:
        out.mkdir()
        (out / "notes.txt").write_text("mine")
    before = _listing(tmp_path)
    assert main([*SHORT, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"vgtarm: error: --out {out}:") and err.count("\n") == 1
    assert _listing(tmp_path) == before  # no summary anywhere


def test_report_refuses_to_replace_the_run_it_reads(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    assert main(["report", str(run), "--out", str(run)]) == 1
    err = capsys.readouterr().err
    assert err == f"vgtarm: error: --out {run}: is an input of this command; choose another folder\n"


def test_ik_refuses_to_overwrite_its_input_before_any_work(tmp_path, capsys):
    source = tmp_path / "path.csv"
    source.write_text("t,x,y,z\n0,0,0,0.66\n0.1,0,0,0.661\n")
    before = source.read_bytes()
    assert main(["ik", "--path", str(source), "-o", str(source)]) == 1
    err = capsys.readouterr().err
    assert err == f"vgtarm: error: -o {source}: is an input of this command; writing it would destroy it\n"
    assert source.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["path.csv"]


@pytest.mark.parametrize("when", ["during the run", "while the results are written"])
def test_a_users_file_added_during_simulate_is_kept_and_the_line_names_where_the_run_went(
    tmp_path, capsys, caplog, monkeypatch, when
):
    """The folder was checked before the run; a file the user adds to it afterwards (while the run
    computes, or while its files are written) is kept, and the run goes beside it."""
    from vgtarm.app.pictures import plotting as plotting
    from vgtarm.experiment import record

    out = tmp_path / "run"
    assert main([*SHORT, "--out", str(out)]) == 0
    patched, name = (record, "simulate") if when == "during the run" else (plotting, "save_figure")
    original = getattr(patched, name)

    def user_writes_notes(*args, **kwargs):
        (out / "NOTES.txt").write_text("mine")  # the user, in the folder of the earlier run
        return original(*args, **kwargs)

    monkeypatch.setattr(patched, name, user_writes_notes)
    before = _listing(out)
    capsys.readouterr()
    assert main([*SHORT, "--seed", "3", "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.out.splitlines()[-1] == f"results written to {out}-2"
    [warning] = [r.getMessage() for r in caplog.records if r.name == "vgtarm"]
    assert warning.startswith(f"vgtarm: --out {out}: the folder holds 'NOTES.txt'")
    assert warning.endswith(f"the new results are in {out}-2")
    assert _listing(out) == {**before, "NOTES.txt": b"mine"}
    assert json.loads((tmp_path / "run-2" / "summary.json").read_text())["seed"] == 3
    assert (tmp_path / "run-2" / "figure.png").exists()


def test_the_line_saying_where_the_run_went_reaches_the_terminal(tmp_path):
    """As a program (no logging set up): the warning is one line on standard error, exit 0."""
    out = tmp_path / "run"
    assert main([*SHORT, "--out", str(out)]) == 0
    script = (
        "import sys\nfrom vgtarm.experiment import record\nfrom vgtarm.app.cli.command import main\n"
        "simulate = record.simulate\n"
        "def with_notes(*args, **kwargs):\n"
        "    open(sys.argv[1] + '/NOTES.txt', 'w').write('mine')\n"
        "    return simulate(*args, **kwargs)\n"
        f"record.simulate = with_notes\nsys.exit(main({SHORT!r} + ['--out', sys.argv[1]]))\n"
    )
    done = subprocess.run([sys.executable, "-c", script, str(out)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr == (
        f"vgtarm: --out {out}: the folder holds 'NOTES.txt', which vgtarm did not write there;"
        f" it is kept as it was, and the new results are in {out}-2\n"
    )
    assert done.stdout.splitlines()[-1] == f"results written to {out}-2"
    assert (out / "NOTES.txt").read_text() == "mine" and (tmp_path / "run-2" / "figure.png").exists()


def test_reproduce_names_the_folder_beside_when_its_folder_gained_a_file(tmp_path, capsys, monkeypatch):
    """``vgtarm reproduce --out X &``, then ``echo notes > X/NOTES.txt`` during the run."""
    from vgtarm.app.reports import reproduce as report
    from vgtarm.app.reports.reproduce import REPRODUCE_FILES, Reproduction

    out = tmp_path / "results"
    with atomic_folder(out) as folder:
        (folder / "report.md").write_text("old")

    def fake_reproduce(robot, where, **kwargs):
        with atomic_folder(where, "out", owned=REPRODUCE_FILES) as folder:
            (folder / "report.md").write_text("new")
            (out / "NOTES.txt").write_text("notes")
        return Reproduction({}, Path(where) / "report.md", 0.0)

    monkeypatch.setattr(report, "reproduce", fake_reproduce)
    assert main(["reproduce", "--quiet", "--out", str(out)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == (
        f"report written to {out}-2/report.md and {out}-2/report.html (0.0 s)"
    )
    assert _listing(out) == {MANIFEST: ANY, "report.md": b"old", "NOTES.txt": b"notes"}
    assert (tmp_path / "results-2" / "report.md").read_text() == "new"


@pytest.mark.parametrize(("argv", "status"), [(["describe"], CLOSED_PIPE), (["--help"], 0)])
def test_a_closed_pipe_ends_quietly(argv, status):
    """``vgtarm describe | head -1``: the reader is gone before vgtarm writes."""
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run(
            [sys.executable, "-c", "import sys; from vgtarm.app.cli.command import main; sys.exit(main())", *argv],
            stdout=write,
            stderr=subprocess.PIPE,
            timeout=120,
        )
    finally:
        os.close(write)
    assert done.stderr == b""
    assert done.returncode == status


def test_a_broken_pipe_that_is_not_standard_output_is_still_an_error():
    """An encoder's or a socket's broken pipe is a failure, not a reader that went away."""
    script = (
        "import sys\nfrom vgtarm.app.cli import command as cli\n"
        "def broken(args):\n    raise BrokenPipeError(32, 'Broken pipe')\n"
        "cli.cmd_describe = broken\nsys.exit(cli.main(['describe']))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and done.stderr == "vgtarm: error: [Errno 32] Broken pipe\n"


# --- the video encoder ----------------------------------------------------------------------

#: Stand-ins for ffmpeg: one that refuses at once, one that reads every frame and then fails.
FAKE_FFMPEG = {
    "refuses": (
        "echo '[libx264 @ 0x55] frame size too large' >&2\n"
        "echo 'Error initializing output stream 0:0 -- Error while opening encoder' >&2\nexit 1\n",
        "ffmpeg ended with status 1: Error initializing output stream 0:0 -- Error while opening encoder",
    ),
    "disk full at the end": (
        'cat > /dev/null\nfor last; do :; done\necho "$last: No space left on device" >&2\nexit 1\n',
        "ffmpeg ended with status 1: {out}: No space left on device",  # its temporary file shown as the user's
    ),
}


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("animate") / "run"
    assert main([*SHORT, "--out", str(run)]) == 0
    return run


@pytest.mark.parametrize("fake", sorted(FAKE_FFMPEG))
def test_a_failing_video_encoder_is_one_line_and_leaves_no_file(tmp_path, saved_run, capfd, monkeypatch, fake):
    """ffmpeg's own messages never reach the terminal; its last one is the reason in vgtarm's line."""
    pytest.importorskip("imageio_ffmpeg")
    script, reason = FAKE_FFMPEG[fake]
    exe = tmp_path / "ffmpeg"
    exe.write_text("#!/bin/sh\n" + script)
    exe.chmod(0o755)
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(exe))
    out = tmp_path / "video" / "run.mp4"
    capfd.readouterr()
    assert main(["animate", str(saved_run), "--out", str(out), "--fps", "200", "-q"]) == 1
    captured = capfd.readouterr()
    assert captured.err == f"vgtarm: error: {out}: {reason.format(out=out)}\n" and captured.out == ""
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["ffmpeg", "video"]


def test_ctrl_c_while_a_video_is_encoded_stops_ffmpeg_and_leaves_no_file(tmp_path, saved_run, capfd, monkeypatch):
    pytest.importorskip("imageio_ffmpeg")
    from vgtarm.app.pictures import animation as animation

    started: list[int] = []
    start = animation._FfmpegWriter._start

    def recorded(self, height, width):
        process = start(self, height, width)
        started.append(process.pid)
        return process

    show = animation._Scene.show

    def interrupted_at_the_third_frame(self, geometry, k):
        if len(frames) == 2:
            raise KeyboardInterrupt
        frames.append(k)
        return show(self, geometry, k)

    frames: list[int] = []
    monkeypatch.setattr(animation._FfmpegWriter, "_start", recorded)
    monkeypatch.setattr(animation._Scene, "show", interrupted_at_the_third_frame)
    out = tmp_path / "run.mp4"
    assert main(["animate", str(saved_run), "--out", str(out), "--fps", "200", "-q"]) == 130
    assert capfd.readouterr().err == "vgtarm: interrupted\n"
    assert len(started) == 1 and not Path(f"/proc/{started[0]}").exists()  # killed and reaped
    assert list(tmp_path.iterdir()) == []
