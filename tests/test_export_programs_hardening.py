"""The exported programs on hostile arguments and files (issue 33): ``replay``, ``rt_loop`` and
``ga_timing`` of one export (switching control, so all three are in it), built plain (the programs
at -O2 with the strict flags) and under AddressSanitizer and UndefinedBehaviorSanitizer.

Every refusal is one line on stderr with exit status 1, the user's files as they were byte for
byte, and no output or temporary file left; ``replay`` refuses an output that is one of its inputs
and a file argument that is not a regular file before it reads anything, recognises each input by
its header, and bounds the values it reads; ``rt_loop`` and ``ga_timing`` refuse every number they
cannot take. A seeded fuzz of arguments and files runs through the sanitized programs: no report,
no crash, nothing partial. The robot's name reaches the exported C and README escaped."""

from __future__ import annotations

import ctypes
import dataclasses
import math
import os
import random
import re
import resource
import shutil
import signal
import subprocess
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.errors import escape
from vgtarm.experiment.cases import case_study
from vgtarm.export import export_controller
from vgtarm.export.controller import STRICT_FLAGS
from vgtarm.ik.records import csv_columns
from vgtarm.simulation import Scenario

from .test_export_controller import CLANG_MISSING, measurements_header, reference_header

pytestmark = pytest.mark.skipif(
    shutil.which("gcc") is None or shutil.which("make") is None, reason="gcc is not installed"
)

CASE = case_study(2)
PROGRAMS = ("replay", "rt_loop", "ga_timing")
#: The library the programs link, built once at -O0 for the plain build (the other export tests
#: build it at -O2; here the programs are what is tested, and -O0 keeps this file fast).
LIBRARY = ("vgtarm_controller", "vgtc_model", "vgtc_defaults", "vgtc_ga", "vgtc_switching")
SANITIZE = "-std=c99 -O0 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=all"
#: A sanitizer's report ends the program with these statuses, never 0 or 1.
SANITIZER_ENV = {
    "ASAN_OPTIONS": "exitcode=86:detect_leaks=1",
    "UBSAN_OPTIONS": "exitcode=87:print_stacktrace=1:halt_on_error=1",
}
#: The rows of the good input files.
ROWS = 25
#: replay's bounds (replay.c, README.md): positions, rates, accelerations; forces; times.
MOTION_BOUND, FORCE_BOUND = 1e3, 1e5
#: rt_loop's and ga_timing's most steps and activations.
RT_MAX_STEPS, GA_MAX_ACTIVATIONS = 100_000_000, 10_000_000
SPACES = b" \t\n\v\f\r"


@pytest.fixture(scope="module")
def robot() -> vgtarm.Robot:
    return vgtarm.load_robot()


@pytest.fixture(scope="module")
def export(robot: vgtarm.Robot, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("hardening")
    scenario = Scenario(observer="momentum")
    return export_controller(
        robot, root / "export", scenario=scenario, kp=CASE.kp, kv=CASE.kv, switching="safe", check_build=False
    ).folder


def _run_all(commands: list[tuple[list[str], Path]]) -> None:
    """Run the commands at once (two cores), each without a word on stderr."""
    running = [
        (subprocess.Popen(c, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True), c)
        for c, cwd in commands
    ]
    for process, command in running:
        out, err = process.communicate(timeout=600)
        assert process.returncode == 0 and err == "", (command, err)


@pytest.fixture(scope="module")
def builds(export: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The programs built plain (strict flags, -O2) and with the sanitizers, by the export's Makefile."""
    root = tmp_path_factory.mktemp("builds")
    plain, sanitized = root / "plain", root / "sanitized"
    shutil.copytree(export, plain)
    shutil.copytree(export, sanitized)
    _run_all(
        [
            (["gcc", "-std=c99", "-O0", "-ffp-contract=off", "-c", "-o", f"{name}.o", f"{name}.c"], plain)
            for name in LIBRARY
        ]
    )
    strict = " ".join(f for f in STRICT_FLAGS if f != "-ffp-contract=off")
    _run_all(
        [
            (["make", "-s", "-j2", "CC=gcc", f"CFLAGS={strict}"], plain),
            (["make", "-s", "-j2", "CC=gcc", f"CFLAGS={SANITIZE}", f"LDFLAGS={SANITIZE}"], sanitized),
        ]
    )
    for folder in (plain, sanitized):
        for program in PROGRAMS:
            assert (folder / program).is_file()
    return {"plain": plain, "sanitized": sanitized}


def run(program: Path, args: Sequence[str | bytes | Path], cwd: Path, **options) -> subprocess.CompletedProcess[bytes]:  # type: ignore[no-untyped-def]
    """``program`` with ``args`` in ``cwd``, its output as bytes; never more than 60 s."""
    env = {**os.environ, **SANITIZER_ENV}
    return subprocess.run(
        [str(program), *args], cwd=cwd, capture_output=True, env=env, timeout=60, check=False, **options
    )


def assert_clean(done: subprocess.CompletedProcess[bytes]) -> None:
    """No sanitizer report and no crash: exit status 0 or 1."""
    err = done.stderr.decode("utf-8", "replace")
    assert "Sanitizer" not in err and "runtime error" not in err, err
    assert done.returncode in (0, 1), (done.returncode, err)


def assert_refused(done: subprocess.CompletedProcess[bytes], *words: str) -> str:
    """Exit status 1 and one line on stderr, printable ASCII (a file's or a path's bytes escaped),
    holding each of ``words``; nothing on stdout. The line."""
    assert_clean(done)
    err = done.stderr.decode("ascii", "replace")
    assert done.returncode == 1, err
    assert done.stdout == b""
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert all(" " <= c <= "~" for c in err[:-1]), err
    for word in words:
        assert word in err, (word, err)
    return err


def snapshot(folder: Path) -> dict[str, bytes | str]:
    """Every entry of ``folder`` (hidden ones included): a file's bytes, or what else it is."""
    found: dict[str, bytes | str] = {}
    for entry in sorted(folder.iterdir()):
        if entry.is_symlink():
            found[entry.name] = f"link to {os.readlink(entry)}"
        elif entry.is_file():
            found[entry.name] = entry.read_bytes()
        else:
            found[entry.name] = "folder" if entry.is_dir() else "special"
    return found


def _lines(header: list[str], rows: np.ndarray) -> list[str]:
    return [",".join(header)] + [",".join(repr(float(v)) for v in row) for row in rows]


def good_files(robot: vgtarm.Robot, where: Path, rows: int = ROWS) -> dict[str, list[str]]:
    """Good inputs in ``where``: ``ref.csv`` (the reference), ``ff.csv`` (with the expected force),
    ``ik.csv`` (vgtarm ik's columns, the same reference) and ``meas.csv`` (home pose, a slow sine);
    their lines by name."""
    n = robot.n_joints
    home = np.asarray(robot.parameters.q_home, dtype=float)
    t = np.arange(rows) * 1e-3
    wave = 1e-4 * np.sin(2 * np.pi * 5 * t)[:, None] * np.ones(n)
    zeros = np.zeros((rows, 2 * n))
    reference = np.column_stack([t, np.tile(home, (rows, 1)), zeros])
    files = {
        "ref.csv": _lines(reference_header(n), reference),
        "ff.csv": _lines(reference_header(n, True), np.column_stack([reference, np.tile([0, 0, -20.0], (rows, 1))])),
        "ik.csv": _lines(
            list(csv_columns(robot.joint_names)),
            np.column_stack([t, np.tile([0.1, 0.2, 0.9], (rows, 1)), np.tile(home, (rows, 1)), zeros]),
        ),
        "meas.csv": _lines(
            measurements_header(n), np.column_stack([t, home + wave, np.zeros((rows, n)), np.full((rows, 3), np.nan)])
        ),
    }
    where.mkdir(parents=True, exist_ok=True)
    for name, lines in files.items():
        (where / name).write_text("\n".join(lines) + "\n")
    return files


def test_the_programs_compile_clean_on_gcc_and_clang(export: Path) -> None:
    """The three programs with the strict flags (-Werror), on both compilers."""
    if shutil.which("clang") is None:
        pytest.skip(CLANG_MISSING)
    for compiler in ("gcc", "clang"):
        for program in PROGRAMS:
            done = subprocess.run(
                [compiler, *STRICT_FLAGS, "-fsyntax-only", f"{program}.c"], cwd=export, capture_output=True, text=True
            )
            assert done.returncode == 0 and done.stderr == "", (compiler, program, done.stderr)


# ---------------------------------------------------------------- replay: what it reads and writes


def test_replay_reads_its_three_reference_layouts(robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The reference, vgtarm ik's CSV (the same numbers: the same efforts, bit for bit) and the
    reference with the expected force; a header with spaces, CRLF line ends and a byte-order mark
    is the same file. Both builds give the same bytes; an existing output is replaced whole."""
    files = good_files(robot, tmp_path)
    outputs = {}
    for kind, build in builds.items():
        for reference in ("ref.csv", "ik.csv", "ff.csv"):
            out = f"{kind}-{reference}"
            done = run(build / "replay", [reference, "meas.csv", out], tmp_path)
            assert_clean(done)
            assert done.returncode == 0 and done.stderr == b"", done.stderr
            outputs[out] = (tmp_path / out).read_bytes()
    n = robot.n_joints
    header = ",".join(["t", *(f"F_{i}" for i in range(1, n + 1)), *(f"tau_hat_{i}" for i in range(1, n + 1)), "status"])
    table = outputs["plain-ref.csv"].decode().splitlines()
    assert table[0] == header and len(table) == ROWS + 1
    assert outputs["plain-ik.csv"] == outputs["plain-ref.csv"]
    assert outputs["plain-ff.csv"] != outputs["plain-ref.csv"]  # 20 N fed forward
    for name in ("ref.csv", "ik.csv", "ff.csv"):
        assert outputs[f"sanitized-{name}"] == outputs[f"plain-{name}"]
    # the same reference written otherwise
    lines = files["ref.csv"]
    text = "\ufeff" + " , ".join(lines[0].split(",")) + "\r\n" + "\r\n".join(lines[1:]) + "\r\n"
    (tmp_path / "other.csv").write_text(text, encoding="utf-8")
    (tmp_path / "old.csv").write_text("an older file\n")
    os.chmod(tmp_path / "old.csv", 0o640)
    done = run(builds["plain"] / "replay", ["other.csv", "meas.csv", "old.csv"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "old.csv").read_bytes() == outputs["plain-ref.csv"]
    assert (tmp_path / "old.csv").stat().st_mode & 0o777 == 0o640
    assert not [p for p in tmp_path.iterdir() if ".replay-" in p.name]


OUTPUT_IS_AN_INPUT = {
    "the reference itself": ("ref.csv", "REFERENCE"),
    "the measurements": ("meas.csv", "MEASUREMENTS"),
    "another path to the reference": ("sub/../ref.csv", "REFERENCE"),
    "a hard link to the reference": ("hard.csv", "REFERENCE"),
    "a symbolic link to the measurements": ("soft.csv", "MEASUREMENTS"),
}


@pytest.mark.parametrize("case", list(OUTPUT_IS_AN_INPUT))
def test_replay_refuses_an_output_that_is_one_of_its_inputs(case, robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    good_files(robot, tmp_path)
    (tmp_path / "sub").mkdir()
    os.link(tmp_path / "ref.csv", tmp_path / "hard.csv")
    os.symlink("meas.csv", tmp_path / "soft.csv")
    output, which = OUTPUT_IS_AN_INPUT[case]
    before = snapshot(tmp_path)
    for build in builds.values():
        done = run(build / "replay", ["ref.csv", "meas.csv", output], tmp_path)
        assert_refused(done, "EFFORTS", output, which, "expected another file")
        assert snapshot(tmp_path) == before


def _special(tmp_path: Path, kind: str) -> str:
    if kind == "FIFO (named pipe)":
        os.mkfifo(tmp_path / "pipe")
        return "pipe"
    if kind == "folder":
        (tmp_path / "folder").mkdir()
        return "folder"
    return "/dev/null"


@pytest.mark.parametrize("position", [0, 1, 2])
@pytest.mark.parametrize("kind", ["FIFO (named pipe)", "folder", "character device"])
def test_replay_refuses_a_file_that_is_not_a_regular_file(position, kind, robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Before it is opened: a FIFO never blocks replay (the run is held to 60 s)."""
    good_files(robot, tmp_path)
    args = ["ref.csv", "meas.csv", "out.csv"]
    args[position] = _special(tmp_path, kind)
    before = snapshot(tmp_path)
    for build in builds.values():
        done = run(build / "replay", args, tmp_path)
        assert_refused(done, ("REFERENCE", "MEASUREMENTS", "EFFORTS")[position], args[position], kind, "expected")
        assert snapshot(tmp_path) == before


def test_replay_refuses_bad_arguments_in_one_line(robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    good_files(robot, tmp_path)
    (tmp_path / "other.csv").write_text("mine\n")
    os.symlink("other.csv", tmp_path / "link.csv")
    before = snapshot(tmp_path)
    cases: list[tuple[Sequence[str | bytes | Path], tuple[str, ...]]] = [
        ([], ("usage",)),
        (["ref.csv", "meas.csv"], ("usage",)),
        (["ref.csv", "meas.csv", "a.csv", "b.csv"], ("usage",)),
        (["", "meas.csv", "out.csv"], ("REFERENCE", "empty")),
        (["ref.csv", "meas.csv", ""], ("EFFORTS", "empty")),
        (["missing.csv", "meas.csv", "out.csv"], ("REFERENCE", "missing.csv", "No such file")),
        (["ref.csv", "meas.csv", "nowhere/out.csv"], ("nowhere/out.csv", "No such file")),
        (["ref.csv", "meas.csv", "link.csv"], ("EFFORTS", "link.csv", "symbolic link", "expected")),
        ([b"\x1b[31mred\xe2\x80\xae.csv", "meas.csv", "out.csv"], ("REFERENCE", "\\x1b[31mred\\xe2\\x80\\xae.csv")),
    ]
    for build in builds.values():
        for args, words in cases:
            assert_refused(run(build / "replay", args, tmp_path), *words)
            assert snapshot(tmp_path) == before


def test_replay_recognises_each_file_by_its_header(robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A file of another kind, or of the right width with other columns, is refused naming the
    file, the columns expected and those found: no reference with expected-force columns is made
    of 25 columns that are not those (issue 33: an IK file of the wrong robot, unnamed columns)."""
    files = good_files(robot, tmp_path)
    n = robot.n_joints
    unnamed = ["t", *(f"c{i}" for i in range(3 * n))]
    written = {
        "unnamed.csv": [",".join(unnamed), *files["ref.csv"][1:]],
        "other_ik.csv": [",".join(csv_columns(tuple(f"j{i}" for i in range(n)))), *files["ik.csv"][1:]],
        "empty.csv": [],
        "header_only.csv": files["ref.csv"][:1],
        "wide.csv": ["t," + ",q" * 40000],
    }
    for name, lines in written.items():
        (tmp_path / name).write_text("".join(line + "\n" for line in lines))
    (tmp_path / "junk.csv").write_bytes(bytes(range(256)) * 8)
    before = snapshot(tmp_path)
    cases = [
        (["meas.csv", "meas.csv", "out.csv"], ("REFERENCE meas.csv", "expected t,q_d_1", "found", "(18 columns)")),
        (["ref.csv", "ref.csv", "out.csv"], ("MEASUREMENTS ref.csv", "expected t,q_1", "found", "(22 columns)")),
        (["ref.csv", "ik.csv", "out.csv"], ("MEASUREMENTS ik.csv", 'found "t,x,y,z,')),
        (["unnamed.csv", "meas.csv", "out.csv"], ("REFERENCE unnamed.csv", 'found "t,c0,c1', "(22 columns)")),
        (["other_ik.csv", "meas.csv", "out.csv"], ("REFERENCE other_ik.csv", "vgtarm ik's t,x,y,z,", "found")),
        (["empty.csv", "meas.csv", "out.csv"], ("REFERENCE empty.csv", "is empty", "expected a header")),
        (["header_only.csv", "meas.csv", "out.csv"], ("header_only.csv ends after 0 rows",)),
        (["junk.csv", "meas.csv", "out.csv"], ("REFERENCE junk.csv", "zero byte")),
        (["wide.csv", "meas.csv", "out.csv"], ("REFERENCE wide.csv", "longer than 65535")),
    ]
    for build in builds.values():
        for args, words in cases:
            assert_refused(run(build / "replay", args, tmp_path), *words)
            assert snapshot(tmp_path) == before


def _set(file: str, row: int, column: int, value: str) -> Callable[[dict[str, list[str]]], None]:
    def change(files: dict[str, list[str]]) -> None:
        fields = files[file][row].split(",")
        fields[column] = value
        files[file][row] = ",".join(fields)

    return change


def _edit(file: str, edit: Callable[[list[str]], list[str]]) -> Callable[[dict[str, list[str]]], None]:
    def change(files: dict[str, list[str]]) -> None:
        files[file] = edit(files[file])

    return change


#: A refusal: (the reference used, the change, words of the message). Rows count from 1 after the header.
REFUSALS: dict[str, tuple[str, Callable[[dict[str, list[str]]], None], tuple[str, ...]]] = {
    "a field that is not a number": (
        "ref.csv",
        _set("ref.csv", 5, 2, "abc"),
        ("row 5 (line 6) column q_d_2", "not a number"),
    ),
    "an empty field": ("ref.csv", _set("meas.csv", 2, 1, ""), ("row 2", "column q_1", "not a number")),
    "too few columns": (
        "ref.csv",
        _edit("ref.csv", lambda x: x[:4] + [x[4].rsplit(",", 2)[0]] + x[5:]),
        ("row 4", "20 columns; expected 22"),
    ),
    "too many columns": (
        "ref.csv",
        _edit("meas.csv", lambda x: x[:3] + [x[3] + ",0"] + x[4:]),
        ("row 3", "19 columns; expected 18"),
    ),
    "nan in the reference": ("ref.csv", _set("ref.csv", 2, 8, "nan"), ("row 2", "qd_d_1", "expected a finite number")),
    "inf in the measurements": ("ref.csv", _set("meas.csv", 7, 3, "inf"), ("row 7", "q_3", "expected a finite number")),
    "nan in part of the velocities": ("ref.csv", _set("meas.csv", 3, 9, "nan"), ("row 3", "qd_2", "finite")),
    "a force in part of its columns": ("ref.csv", _set("meas.csv", 3, 16, "1.5"), ("column f_y", "while f_x is nan")),
    "a reference of 1e300 m": ("ref.csv", _set("ref.csv", 6, 1, "1e300"), ("row 6", "q_d_1", "1e300", "<= 1000")),
    "an acceleration of 1e4": ("ref.csv", _set("ref.csv", 6, 15, "1e4"), ("qdd_d_1", "<= 1000")),
    "an expected force of 1e300 N": ("ff.csv", _set("ff.csv", 2, 24, "-1e300"), ("f_exp_z", "<= 100000 N")),
    "a measured force of 1e6 N": (
        "ref.csv",
        _edit("meas.csv", lambda x: x[:4] + [x[4].rsplit(",", 3)[0] + ",1e6,0,0"] + x[5:]),
        ("f_x", "1e6", "<= 100000 N"),
    ),
    "a time of 1e12 s": ("ref.csv", _set("meas.csv", 1, 0, "1e12"), ("column t", "<= 1e+09 s")),
    "the reference's time going back": ("ref.csv", _set("ref.csv", 6, 0, "0"), ("REFERENCE", "row 6", "never go back")),
    "the measured time going back": (
        "ref.csv",
        _set("meas.csv", 6, 0, "0"),
        ("MEASUREMENTS", "row 6", "went backwards"),
    ),
    "a reading beyond its joint limit": ("ref.csv", _set("meas.csv", 4, 1, "50"), ("row 4", "refused the step")),
    "a reference that ends early": ("ref.csv", _edit("ref.csv", lambda x: x[:-3]), ("REFERENCE", "ends after 22 rows")),
    "measurements that end early": (
        "ik.csv",
        _edit("meas.csv", lambda x: x[:-1]),
        ("MEASUREMENTS", "ends after 24 rows"),
    ),
    "a last row cut short": ("ref.csv", _edit("meas.csv", lambda x: x[:-1] + [x[-1][:40]]), ("row 25",)),
    "a zero byte": ("ref.csv", _edit("ref.csv", lambda x: x[:9] + [x[9] + "\0"] + x[10:]), ("line 10", "zero byte")),
    "a line of 70,000 characters": (
        "ref.csv",
        _edit("meas.csv", lambda x: x[:9] + ["1" * 70000] + x[10:]),
        ("line 10", "longer"),
    ),
    "binary junk after the rows": (
        "ref.csv",
        _edit("ref.csv", lambda x: x + ["\x01\x02\xff\x7f,,,"]),
        ("REFERENCE", "row 26"),
    ),
    "a row that is empty": ("ref.csv", _edit("ref.csv", lambda x: x[:3] + [""] + x[3:]), ("row 3", "not a number")),
}


@pytest.mark.parametrize("case", list(REFUSALS))
def test_replay_refusals_leave_nothing(case, robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Each refusal: one line naming the file, the row and the column, the inputs as they were, no
    output and no temporary file; an existing output stays as it was."""
    files = good_files(robot, tmp_path)
    reference, change, words = REFUSALS[case]
    change(files)
    for name, lines in files.items():
        (tmp_path / name).write_bytes(
            "\n".join(lines).encode("latin-1") + (b"" if case == "a last row cut short" else b"\n")
        )
    for build, existing in zip(builds.values(), (False, True), strict=True):
        if existing:
            (tmp_path / "efforts.csv").write_text("the user's own file\n")
        before = snapshot(tmp_path)
        done = run(build / "replay", [reference, "meas.csv", "efforts.csv"], tmp_path)
        assert_refused(done, *words)
        assert snapshot(tmp_path) == before


def test_replay_under_a_file_size_limit_leaves_nothing(robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``ulimit -f``: SIGXFSZ ignored, the write fails with EFBIG, the message names the path and
    the limit."""
    good_files(robot, tmp_path)
    before = snapshot(tmp_path)

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))

    for build in builds.values():
        done = run(build / "replay", ["ref.csv", "meas.csv", "efforts.csv"], tmp_path, preexec_fn=limit)
        assert_refused(done, "cannot write efforts.csv", "file-size limit", "4096 bytes")
        assert snapshot(tmp_path) == before


def test_replay_on_a_full_disk_leaves_nothing(robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A 4 kB tmpfs (mounted in a user namespace of its own): "the disk is full", nothing left."""
    good_files(robot, tmp_path)
    small = tmp_path / "small"
    small.mkdir()
    if shutil.which("unshare") is None:
        pytest.skip("unshare is not installed")
    probe = subprocess.run(
        ["unshare", "-rm", "sh", "-c", f"mount -t tmpfs -o size=4k tmpfs '{small}'"], capture_output=True, check=False
    )
    if probe.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs in a user namespace here: {probe.stderr.decode(errors='replace').strip()}")
    script = (
        'mount -t tmpfs -o size=4k tmpfs "$1" && "$2" ref.csv meas.csv "$1/efforts.csv"; s=$?; ls -A "$1" >&2; exit $s'
    )
    for build in builds.values():
        done = run(Path("unshare"), ["-rm", "sh", "-c", script, "sh", str(small), str(build / "replay")], tmp_path)
        assert_refused(done, f"cannot write {small}/efforts.csv", "the disk is full")  # ls printed nothing


def test_replay_ended_by_a_signal_leaves_nothing(robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """SIGTERM while the efforts are written: the temporary file goes with replay."""
    good_files(robot, tmp_path, rows=20000)
    before = snapshot(tmp_path)
    process = subprocess.Popen(
        [str(builds["plain"] / "replay"), "ref.csv", "meas.csv", "efforts.csv"],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 30
    while not list(tmp_path.glob(".efforts.csv.replay-*")) and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    assert process.poll() is None, "replay ended before its temporary file was seen"
    process.send_signal(signal.SIGTERM)
    process.communicate(timeout=30)
    assert process.returncode == -signal.SIGTERM
    assert snapshot(tmp_path) == before


# ---------------------------------------------------------------- rt_loop and ga_timing: arguments

RT_LOOP_REFUSALS = [
    (["--steps", "abc"], "--steps abc"),
    (["--steps", "0"], "--steps 0"),
    (["--steps", "1e3"], "--steps 1e3"),
    (["--steps", "-5"], "--steps -5"),
    (["--steps", "2305843009213693952"], "--steps 2305843009213693952"),
    (["--steps", "100000001"], "--steps 100000001"),
    (["--steps", ""], '--steps "" (empty)'),
    (["--steps", " 5"], "--steps  5"),
    (["--steps"], "--steps: its value is missing"),
    (["--seconds", "nan"], "--seconds nan"),
    (["--seconds", "inf"], "--seconds inf"),
    (["--seconds", "-inf"], "--seconds -inf"),
    (["--seconds", "1e300"], "--seconds 1e300"),
    (["--seconds", "1e-9"], "--seconds 1e-9"),
    (["--seconds", "0"], "--seconds 0"),
    (["--seconds", "-1"], "--seconds -1"),
    (["--seconds", "1s"], "--seconds 1s"),
    (["--seconds", "100001"], "--seconds 100001"),
    (["--seconds"], "--seconds: its value is missing"),
    (["--seconds", "1", "--steps", "5"], "--seconds 1 and --steps 5"),
    (["--steps", "5", "--steps", "6"], "--steps 5, then --steps 6"),
    (["--bogus"], "unknown argument --bogus"),
    (["--steps", "\x1b[2J"], "--steps \\x1b[2J"),
]


@pytest.mark.parametrize(("args", "words"), RT_LOOP_REFUSALS, ids=[" ".join(a) or "none" for a, _ in RT_LOOP_REFUSALS])
def test_rt_loop_refuses_every_argument_it_cannot_take(args, words, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    for build in builds.values():
        line = assert_refused(run(build / "rt_loop", args, tmp_path), words)
        assert "expected" in line


GA_TIMING_REFUSALS = [
    (["abc"], "ACTIVATIONS abc"),
    (["0"], "ACTIVATIONS 0"),
    (["-5"], "ACTIVATIONS -5"),
    (["1e3"], "ACTIVATIONS 1e3"),
    (["2305843009213693952"], "ACTIVATIONS 2305843009213693952"),
    (["10000001"], "ACTIVATIONS 10000001"),
    ([""], 'ACTIVATIONS "" (empty)'),
    (["1", "2"], "2 arguments"),
]


@pytest.mark.parametrize(
    ("args", "words"), GA_TIMING_REFUSALS, ids=[" ".join(a) or "empty" for a, _ in GA_TIMING_REFUSALS]
)
def test_ga_timing_refuses_every_argument_it_cannot_take(args, words, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    for build in builds.values():
        line = assert_refused(run(build / "ga_timing", args, tmp_path), words)
        assert "expected" in line or "usage" in line


def test_the_programs_still_run_on_good_arguments(builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    for build in builds.values():
        for args in (["--steps", "50"], ["--steps", "050", "--feedforward"], ["--seconds", "0.005"]):
            done = run(build / "rt_loop", args, tmp_path)
            assert_clean(done)
            assert done.returncode == 0 and b"step time" in done.stdout, done.stderr
    done = run(builds["plain"] / "ga_timing", ["1"], tmp_path)
    assert done.returncode == 0 and b"activation" in done.stdout, done.stderr


# ---------------------------------------------------------------- the fuzz

_LIBC = ctypes.CDLL(None)
_LIBC.strtod.restype = ctypes.c_double
_LIBC.strtod.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.POINTER(ctypes.c_char))]


def c_strtod(text: bytes) -> tuple[float, int]:
    """C's ``strtod`` of ``text``: the value and how many bytes it read."""
    buffer = ctypes.create_string_buffer(text)
    end = ctypes.POINTER(ctypes.c_char)()
    value = _LIBC.strtod(buffer, ctypes.byref(end))
    used = ctypes.cast(end, ctypes.c_void_p).value or ctypes.addressof(buffer)
    return value, used - ctypes.addressof(buffer)


def _count(text: bytes, most: int) -> int | None:
    return int(text) if re.fullmatch(rb"[0-9]+", text) and 1 <= int(text) <= most else None


def rt_loop_periods(args: list[bytes], dt: float) -> tuple[int, bool] | None:
    """The steps rt_loop runs for ``args`` (its rules, README.md) and whether they are periods of the
    real-time loop (else back to back); None when it must refuse them."""
    values: dict[bytes, bytes] = {}
    k = 0
    while k < len(args):
        if args[k] in (b"--steps", b"--seconds"):
            if k + 1 >= len(args) or args[k] in values:
                return None
            values[args[k]] = args[k + 1]
            k += 2
        elif args[k] == b"--feedforward":
            k += 1
        else:
            return None
    if len(values) == 2:
        return None
    if b"--steps" in values:
        steps = _count(values[b"--steps"], RT_MAX_STEPS)
        return None if steps is None else (steps, False)
    if b"--seconds" in values:
        text = values[b"--seconds"]
        if not text or text[0] in SPACES:
            return None
        seconds, used = c_strtod(text)
        periods = seconds / dt + 0.5
        if used != len(text) or not math.isfinite(seconds) or not 1.0 <= periods < RT_MAX_STEPS + 1.0:
            return None
        return int(periods), True
    return 10_000, True  # the default, 10 s


NUMBER_SHAPES = (
    "0 1 7 05 +5 -5 -0 0.0 1.5 .5 5. 1e3 1E3 1e-3 0.0004 0.0005 0.0015 0.004 2e-3 1e-400 1e300 -1e300 1e309 nan NaN"
    " -nan nan(123) inf -inf Infinity infinityx 0x10 0x1p-9 0x 1e 1e+ . - + 1_000 1,000 \u0663 \uff15 \x1b[31m"
    " \u202e5 --steps --seconds 2147483648 4294967296 9223372036854775807 9223372036854775808 18446744073709551616"
    " 2305843009213693952 100000000 100000001 10000000 10000001 99999"
).split(" ") + ["", " ", " 5", "5 ", "5\n", "\t5", "1" * 5000]


def number_text(rng: random.Random) -> str:
    """A number of some shape, or something that is not one."""
    pick = rng.random()
    if pick < 0.35:
        return rng.choice(NUMBER_SHAPES)
    if pick < 0.5:
        return str(rng.choice([-1, 1]) * rng.randint(0, 2 ** rng.randint(1, 130)))
    if pick < 0.65:
        return f"{rng.uniform(-10, 10):.{rng.randint(0, 6)}f}e{rng.randint(-500, 500)}"
    if pick < 0.8:
        return str(rng.randint(1, 3000))
    if pick < 0.9:
        return f"{rng.uniform(0, 0.012):.{rng.randint(1, 6)}g}"
    alphabet = "0123456789eE+-.xXpPinfaINFA ,_\t\x01\x7f\xe9\u202e"
    return "".join(rng.choice(alphabet) for _ in range(rng.randint(0, 30)))


def fuzz_arguments(rng: random.Random, options: list[str]) -> list[str]:
    """Tokens of options and numbers; a third of the time a run rt_loop takes (or nearly)."""
    if rng.random() < 0.35:
        value = (
            str(rng.randint(1, 2000)) if rng.random() < 0.5 else f"{rng.uniform(0.0003, 0.02):.{rng.randint(1, 5)}g}"
        )
        valid = [rng.choice(["--steps", "--seconds"]), value] + (["--feedforward"] if rng.random() < 0.5 else [])
        return valid[::-1] if len(valid) == 3 and rng.random() < 0.5 else valid
    tokens: list[str] = []
    for _ in range(rng.randint(0, 5)):
        tokens.append(rng.choice(options) if rng.random() < 0.45 else number_text(rng))
    return tokens


#: Fuzz cases of each program (bounded, seeded: the same cases every run).
FUZZ_ARGUMENTS, FUZZ_FILES = 120, 90


def test_fuzz_arguments_of_rt_loop_and_ga_timing(export, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Random and adversarial arguments through the sanitized programs: each run refuses in one line
    exactly what the rules of README.md refuse and runs the rest; no sanitizer report, no crash.
    (Valid runs longer than a moment are only predicted, not run.)"""
    import json

    dt = json.loads((export / "export.json").read_text())["dt_s"]
    rng = random.Random(33)
    build = builds["sanitized"]
    ran = refused = 0
    for _ in range(FUZZ_ARGUMENTS):
        args = fuzz_arguments(rng, ["--steps", "--seconds", "--feedforward", "--bogus", "-", ""])
        raw = [a.encode() for a in args]
        if any(b"\0" in a for a in raw):
            continue
        periods = rt_loop_periods(raw, dt)
        if periods is not None and periods[0] > (20 if periods[1] else 3000):  # at most 20 ms
            continue
        done = run(build / "rt_loop", raw, tmp_path)
        if periods is None:
            assert_refused(done, "rt_loop: ")
            refused += 1
        else:
            assert_clean(done)
            assert done.returncode == 0, (args, done.stderr)
            ran += 1
    for _ in range(FUZZ_ARGUMENTS // 3):
        args = [number_text(rng) if rng.random() < 0.9 else "1" for _ in range(rng.choice([1, 1, 1, 2, 3]))]
        raw = [a.encode() for a in args]
        activations = _count(raw[0], GA_MAX_ACTIVATIONS) if len(raw) == 1 else None
        if activations is not None and activations > 1:
            continue
        done = run(build / "ga_timing", raw, tmp_path)
        if activations is None:
            assert_refused(done, "ga_timing: ")
            refused += 1
        else:
            assert_clean(done)
            assert done.returncode == 0, (args, done.stderr)
            ran += 1
    assert refused > 60 and ran > 5, (refused, ran)


def _mutate(rng: random.Random, data: bytes) -> bytes:
    """One random change of a CSV file's bytes: a field, a row, a header, junk, a cut."""
    lines = data.split(b"\n")
    what = rng.randrange(12)
    k = rng.randrange(len(lines)) if lines else 0
    if what == 0 and lines:  # a field
        fields = lines[k].split(b",")
        fields[rng.randrange(len(fields))] = number_text(rng).encode()
        lines[k] = b",".join(fields)
    elif what == 1 and lines:  # a field less or more
        fields = lines[k].split(b",")
        if rng.random() < 0.5 and len(fields) > 1:
            del fields[rng.randrange(len(fields))]
        else:
            fields.insert(rng.randrange(len(fields) + 1), number_text(rng).encode())
        lines[k] = b",".join(fields)
    elif what == 2 and lines:  # a row less, twice, or moved
        row = lines.pop(k)
        if rng.random() < 0.5:
            lines.insert(rng.randrange(len(lines) + 1), row)
    elif what == 3:  # cut anywhere
        return data[: rng.randrange(len(data) + 1)]
    elif what == 4:  # binary junk
        at = rng.randrange(len(data) + 1)
        return data[:at] + bytes(rng.randrange(256) for _ in range(rng.randint(1, 64))) + data[at:]
    elif what == 5:  # a very long line
        lines.insert(k, b"1," * rng.choice([100, 40000]))
    elif what == 6:  # a header name
        fields = lines[0].split(b",")
        fields[rng.randrange(len(fields))] = rng.choice(
            [b"T", b"q_d_0", b"x", b"f_exp_x", b"", b"q_1 ", b"\xe2\x80\xae"]
        )
        lines[0] = b",".join(fields)
    elif what == 7:  # empty, or the header only
        return b"" if rng.random() < 0.5 else lines[0] + b"\n"
    elif what == 8:  # CRLF, spaces, a byte-order mark: the same file
        return rng.choice([b"\xef\xbb\xbf" + data, data.replace(b"\n", b"\r\n"), data.replace(b",", b" , ")])
    elif what == 9 and len(lines) > 2:  # a time
        fields = lines[k].split(b",")
        fields[0] = rng.choice([b"0", b"-1", b"1e12", b"0.0105", b"nan"])
        lines[k] = b",".join(fields)
    elif what == 10:  # the other file's header
        lines[0] = rng.choice([b"t,x,y,z", b"t," + b",".join(b"c%d" % i for i in range(21))])
    else:  # a huge or a special value in a row
        fields = lines[k].split(b",")
        fields[rng.randrange(len(fields))] = rng.choice(
            [b"1e300", b"-1e6", b"1e5", b"999.9", b"nan", b"-inf", b"1e-320"]
        )
        lines[k] = b",".join(fields)
    return b"\n".join(lines)


def test_fuzz_files_of_replay(robot, builds, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Random and adversarial inputs (and now and then an output that is an input, a folder, a
    FIFO) through the sanitized replay: exit status 0 with a complete output, or 1 with one line
    and nothing written; the inputs never change, no temporary file is ever left."""
    rng = random.Random(33)
    build = builds["sanitized"]
    base = tmp_path / "base"
    good_files(robot, base, rows=12)
    originals = {name: (base / name).read_bytes() for name in ("ref.csv", "ff.csv", "ik.csv", "meas.csv")}
    outcomes = {0: 0, 1: 0}
    for case in range(FUZZ_FILES):
        where = tmp_path / f"case{case}"
        where.mkdir()
        reference = rng.choice(["ref.csv", "ff.csv", "ik.csv"])
        changed = rng.choice([(), (reference,), ("meas.csv",), (reference, "meas.csv")])  # a quarter untouched
        for name in (reference, "meas.csv"):
            data = originals[name]
            for _ in range(rng.choice([1, 1, 2, 3]) if name in changed else 0):
                data = _mutate(rng, data)
            (where / name).write_bytes(data)
        output = rng.choice(["efforts.csv"] * 8 + ["old.csv", reference, "meas.csv", "sub", "pipe", "./" + reference])
        (where / "old.csv").write_bytes(b"the user's own\n")
        (where / "sub").mkdir()
        os.mkfifo(where / "pipe")
        before = snapshot(where)
        done = run(build / "replay", [reference, "meas.csv", output], where)
        assert_clean(done)
        outcomes[done.returncode] += 1
        after = snapshot(where)
        if done.returncode == 1:
            assert_refused(done, "replay: ")
            assert after == before, (case, done.stderr)
        else:
            assert done.stderr == b""
            written = after.pop(output.removeprefix("./"))
            assert isinstance(written, bytes), written
            before.pop(output.removeprefix("./"), None)
            assert after == before
            rows = [line for line in written.split(b"\n") if line]
            assert rows[0].startswith(b"t,F_1,") and len(rows) >= 1
            for row in rows[1:]:
                assert all(math.isfinite(float(v)) for v in row.split(b","))
    assert outcomes[0] >= 10 and outcomes[1] >= 50, outcomes


# ---------------------------------------------------------------- the robot's name


def test_a_robot_name_reaches_the_c_and_the_readme_escaped(robot, export, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Terminal control sequences and right-to-left marks in the robot's name (from the user's file)
    are escaped where the export writes it: the README, the C string rt_loop prints, the comment of
    vgtc_defaults.c. An ordinary name is written as it is (the paper robot's, in this module's export)."""
    assert '#define VGTC_ROBOT "reference (Bayram 2017, dimensions assumed)"' in (export / "vgtc_config.h").read_text()
    name = 'arm\x1b[31mRED\x1b]0;title\x07\u202eevil\u200f\u2066 \\ " ??/ */ é Ω\x85'
    hostile = robot.with_parameters(dataclasses.replace(robot.parameters, name=name))
    folder = export_controller(hostile, tmp_path / "export", check_build=False).folder
    for file in ("README.md", "vgtc_config.h", "vgtc_defaults.c"):
        text = (folder / file).read_text("utf-8")
        assert all(c.isprintable() or c == "\n" for c in text), (file, [c for c in text if not c.isprintable()][:5])
    readme = (folder / "README.md").read_text("utf-8")
    assert f"# vgtarm controller for {escape(name)}\n" in readme
    config = (folder / "vgtc_config.h").read_text("utf-8")
    assert config.isascii()
    # the string as a C program sees it
    (folder / "name.c").write_text(
        '#include <stdio.h>\n#include "vgtc_config.h"\nint main(void) { puts(VGTC_ROBOT); return 0; }\n'
    )
    done = subprocess.run(
        ["gcc", *STRICT_FLAGS, "-o", "name", "name.c"], cwd=folder, capture_output=True, text=True, check=False
    )
    assert done.returncode == 0 and done.stderr == "", done.stderr
    shown = subprocess.run([str(folder / "name")], capture_output=True, check=True).stdout.decode("utf-8")
    assert shown == "arm\\x1b_31mRED\\x1b_0_title\\x07\\u202eevil\\u200f\\u2066 _ _ __/ _/ é Ω\\x85\n"
    # the README says what vgtarm ik writes and what replay bounds
    assert "`vgtarm ik -o path.csv` writes 25 columns" in readme
    assert "have the same columns" not in readme
    assert "100,000 N" in readme and "above 1000 in SI units" in readme
