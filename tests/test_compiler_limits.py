"""Compilers that misbehave (issue 33, item 4): every compiler vgtarm runs (:mod:`vgtarm.compiler`)
runs under ``$VGTARM_COMPILER_TIME_LIMIT``, in a process group of its own that dies with vgtarm.

Fake compilers are small shell scripts written into ``tmp_path`` and given as ``$CC``: one that
never returns, one that ignores SIGINT and SIGTERM, one that fails leaving a background child that
holds its output open, one that exits 0 without writing its output (or writes an empty one), one
that fails. Each exports a unique marker in its environment, which its children inherit, so that
what is left of it is found by the marker (psutil). With a limit of 2 s each ends in one line
naming the compiler (and the limit) within seconds, in ``vgtarm export controller`` (also when the
model runs interpreted and only the export's check compile meets it) and in a model's build; and
nothing of it is left after the limit, after a SIGKILL or SIGTERM of vgtarm, or after Ctrl-C.

The commands run concurrently (module fixtures) so that the file takes well under a minute on a
2-core machine: the model's builds spend a few seconds in the symbolic model and the C code before
the compiler runs.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import psutil
import pytest

from vgtarm import compiler
from vgtarm.errors import ConfigError, shown
from vgtarm.export import ExportError, export_controller
from vgtarm.model.stack import load_stack

SCRIPT = Path(sys.executable).parent / "vgtarm"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: The variable each fake compiler exports with its marker (inherited by its children).
MARK_VARIABLE = "VGTARM_TEST_FAKE_COMPILER"
LIMIT = compiler.TIME_LIMIT_VARIABLE
#: A real compiler, for the fakes that compile some files properly.
REAL_CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
#: Longest a command may take to say a compiler ran past a limit of 2 s, on a busy machine
#: (vgtarm's start-up, the model's symbolic construction; it was 600 s and 1800 s before).
WITHIN = 45.0
#: Longest wait for every process of a fake compiler to be gone after vgtarm ends (s).
GONE_WITHIN = 3.0

#: The fake compilers: the script's body, and words of the one line it ends in (``{limit}`` is the
#: limit's value).
FAKES: dict[str, tuple[str, tuple[str, ...]]] = {
    "never returns": ("sleep 3600\n", ("ran longer than the limit of {limit} s", LIMIT)),
    "ignores SIGINT and SIGTERM": (
        "trap '' INT TERM HUP\nsleep 3600\n",
        ("ran longer than the limit of {limit} s", LIMIT),
    ),
    "leaves a child holding its output": (
        'sleep 3600 &\necho "fake: error: no such thing" >&2\nexit 1\n',
        ("failed", "(exit status 1): fake: error: no such thing"),
    ),
    "exits 0 without output": ("exit 0\n", ("exited 0 but wrote no",)),
    "writes an empty output": (
        'prev=\nfor a; do [ "$prev" = -o ] && : > "$a"; prev=$a; done\nexit 0\n',
        ("exited 0 but wrote no",),
    ),
    "fails": (
        'echo "fake.c:1:1: error: expected something" >&2\nexit 1\n',
        ("failed", "(exit status 1): fake.c:1:1: error: expected"),
    ),
}


def fake_compiler(folder: Path, body: str) -> tuple[Path, str]:
    """A fake compiler script in ``folder`` running ``body``; its path and its marker."""
    marker = f"fake-cc-{uuid.uuid4().hex[:12]}"
    path = folder / f"{marker}.sh"
    path.write_text(f"#!/bin/sh\n{MARK_VARIABLE}={marker}\nexport {MARK_VARIABLE}\n{body}")
    path.chmod(0o755)
    return path, marker


def survivors(marker: str) -> list[str]:
    """The live processes of a fake compiler: its script (by its name) and every child (by the
    marker in their environment); zombies are dead."""
    found = []
    for process in psutil.process_iter(["cmdline", "environ", "status"]):
        info = process.info
        if info["status"] == psutil.STATUS_ZOMBIE:
            continue
        mine = (info["environ"] or {}).get(MARK_VARIABLE) == marker
        if mine or any(marker in part for part in info["cmdline"] or ()):
            found.append(f"{process.pid} {' '.join(info['cmdline'] or ())}")
    return found


def gone(marker: str, within: float = GONE_WITHIN) -> list[str]:
    """Wait up to ``within`` s for every process of a fake compiler to end; those still running."""
    deadline = time.monotonic() + within
    while (left := survivors(marker)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return left


def running(marker: str, count: int, process: Launched, within: float = 120.0) -> None:
    """Wait until at least ``count`` processes of a fake compiler run (vgtarm got to the compiler)."""
    deadline = time.monotonic() + within
    while len(survivors(marker)) < count:
        assert process.child.poll() is None, f"vgtarm ended before its compiler ran: {process.err}"
        assert time.monotonic() < deadline, "the compiler never ran"
        time.sleep(0.05)


def kill_all(marker: str) -> None:
    for line in survivors(marker):
        try:
            os.kill(int(line.split()[0]), signal.SIGKILL)
        except OSError:
            pass


class Launched:
    """A vgtarm command started in a session of its own (like a terminal's job, Ctrl-C restored to
    its default), its standard error collected and the moment it ended recorded by a thread."""

    def __init__(self, argv: list[str], env: dict[str, str], cwd: Path) -> None:
        self.started = time.monotonic()
        self.ended: float | None = None
        self.out = self.err = ""
        self.child = subprocess.Popen(
            [str(SCRIPT), *argv],
            env=env,
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # noqa: PLW1509  (not inherited ignored)
        )
        self._waiter = threading.Thread(target=self._wait, daemon=True)
        self._waiter.start()

    def _wait(self) -> None:
        self.out, self.err = self.child.communicate()
        self.ended = time.monotonic()

    def result(self, timeout: float = 300.0) -> tuple[int, list[str], float]:
        """Exit status, lines of standard error and seconds it took (bounded wait)."""
        self._waiter.join(timeout)
        assert self.ended is not None, f"still running after {timeout} s"
        lines = [line for line in self.err.splitlines() if line.strip()]
        return self.child.returncode, lines, self.ended - self.started

    def stop(self) -> None:
        if self.child.poll() is None:
            try:
                os.killpg(self.child.pid, signal.SIGKILL)
            except OSError:
                pass
        self._waiter.join(10)


def environment(cache: Path, cc: Path, **extra: str) -> dict[str, str]:
    names = ("VGTARM_BACKEND", "VGTARM_CACHE_DIR", LIMIT, "CC")
    env = {k: v for k, v in os.environ.items() if k not in names}
    return {**env, "VGTARM_CACHE_DIR": str(cache), "CC": str(cc), **extra}


def expected(words: tuple[str, ...], limit: str) -> tuple[str, ...]:
    return tuple(word.format(limit=limit) for word in words)


def named(cc: Path) -> str:
    """A compiler as vgtarm's messages name it (a long path cut)."""
    return shown(str(cc), 80)


# ---------------------------------------------------------------------- vgtarm.compiler.run itself


@pytest.mark.parametrize("case", list(FAKES))
def test_a_misbehaving_compiler_is_one_line_within_the_limit(case, tmp_path, monkeypatch):
    body, words = FAKES[case]
    cc, marker = fake_compiler(tmp_path, body)
    monkeypatch.setenv(LIMIT, "1")
    command = [str(cc), "-c", "-o", str(tmp_path / "x.o"), str(tmp_path / "x.c")]
    start = time.monotonic()
    try:
        with pytest.raises(compiler.CompilerError) as caught:
            compiler.compile_checked(command, limit=600.0, what="x.c")
        took = time.monotonic() - start
        message = str(caught.value)
        assert "\n" not in message and message.startswith(f"the C compiler {named(cc)}"), message
        assert all(word in message for word in expected(words, "1")), message
        assert "on x.c" in message
        assert took < 1.0 + 10.0, took  # the limit, and start-up on a busy machine
        if "limit" not in message:  # a failure is reported as it comes, never after the limit
            assert took < 1.0, took
        assert not gone(marker), "nothing of the compiler is left"
    finally:
        kill_all(marker)


@pytest.mark.skipif(REAL_CC is None, reason="no C compiler")
def test_a_compiler_that_leaves_a_child_holding_its_output_returns_at_once(tmp_path, monkeypatch):
    """It compiled: the wait ends when it exits, not when its child lets go of the output (files, not
    pipes), and the child is killed with its group."""
    cc, marker = fake_compiler(tmp_path, f'sleep 3600 &\nexec {REAL_CC} "$@"\n')
    (tmp_path / "x.c").write_text("int x(void);\nint x(void) { return 1; }\n")
    monkeypatch.setenv(LIMIT, "30")
    start = time.monotonic()
    try:
        done = compiler.compile_checked([str(cc), "-c", "-o", str(tmp_path / "x.o"), str(tmp_path / "x.c")])
        assert done.returncode == 0 and (tmp_path / "x.o").stat().st_size > 0
        assert time.monotonic() - start < 15.0
        assert not gone(marker)
    finally:
        kill_all(marker)


@pytest.mark.parametrize("value", ["abc", "0", "-5", "nan", "inf", "1e400", "2 s"])
def test_the_limit_is_validated_and_named(value, monkeypatch):
    monkeypatch.setenv(LIMIT, value)
    with pytest.raises(ConfigError) as caught:
        compiler.time_limit()
    assert str(caught.value) == f"{LIMIT} = {value!r}: expected a number of seconds > 0"


def test_the_limit_defaults_and_can_be_set(monkeypatch):
    monkeypatch.delenv(LIMIT, raising=False)
    assert compiler.time_limit() == compiler.CHECK_TIME_LIMIT == 120.0
    assert compiler.time_limit(600.0) == 600.0
    monkeypatch.setenv(LIMIT, "")
    assert compiler.time_limit(600.0) == 600.0
    monkeypatch.setenv(LIMIT, "2.5")
    assert compiler.time_limit(600.0) == 2.5


#: A compiler that ignores SIGINT and SIGTERM and waits for a child of its own.
WITH_A_CHILD = "trap '' INT TERM HUP\nsleep 3600 &\nwait\n"

_RUN = (
    "import signal, sys\n"
    "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
    "from vgtarm import compiler\n"
    "try:\n"
    "    compiler.run([sys.argv[1], '-c', '-o', 'x.o', 'x.c'], limit=600.0)\n"
    "except KeyboardInterrupt:\n"
    "    sys.exit(130)\n"
)


@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM", "Ctrl-C"])
def test_the_compiler_dies_with_the_process_that_runs_it(how, tmp_path):
    """A compiler that ignores SIGINT and SIGTERM, and its child, die with the Python process that
    runs them however it ends (the parent-death signal and the pipe of the supervisor; Ctrl-C:
    the group killed before the KeyboardInterrupt goes on)."""
    cc, marker = fake_compiler(tmp_path, WITH_A_CHILD)
    child = subprocess.Popen(
        [sys.executable, "-c", _RUN, str(cc)],
        cwd=tmp_path,
        stderr=subprocess.PIPE,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # noqa: PLW1509
    )
    try:
        deadline = time.monotonic() + 60
        while len(survivors(marker)) < 2:
            assert child.poll() is None and time.monotonic() < deadline, child.stderr
            time.sleep(0.05)
        sent = {"SIGKILL": signal.SIGKILL, "SIGTERM": signal.SIGTERM, "Ctrl-C": signal.SIGINT}[how]
        os.kill(child.pid, sent)
        child.wait(timeout=10)
        assert child.returncode == (130 if how == "Ctrl-C" else -sent), child.returncode
        assert not gone(marker), "nothing of the compiler is left"
    finally:
        if child.poll() is None:
            child.kill()
        child.wait(timeout=10)
        kill_all(marker)


# ---------------------------------------------------------------------- vgtarm export controller


@dataclass
class Run:
    launched: Launched
    cc: Path
    marker: str
    out: Path


@pytest.fixture(scope="module")
def exports(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Run]]:
    """``vgtarm export controller`` with each fake compiler and a limit of 2 s, all at once; with
    the model interpreted, compilers that compile the probe properly and hang, or write nothing, on
    the export's files; and a limit that is no number."""
    runs: dict[str, Run] = {}
    cases = {name: body for name, (body, _) in FAKES.items()}
    if REAL_CC is not None:
        probe = f'case "$*" in *vgtc_probe*) exec {REAL_CC} "$@" ;; esac\n'
        cases["interpreted, never returns on the export"] = probe + FAKES["never returns"][0]
        cases["interpreted, exits 0 without output on the export"] = probe + FAKES["exits 0 without output"][0]
    cases["a limit that is no number"] = FAKES["never returns"][0]
    try:
        for name, body in cases.items():
            folder = tmp_path_factory.mktemp("export")
            cc, marker = fake_compiler(folder, body)
            extra = {LIMIT: "two" if name == "a limit that is no number" else "2"}
            if name.startswith("interpreted"):
                extra["VGTARM_BACKEND"] = "interpreted"
            out = folder / "out"
            launched = Launched(
                ["export", "controller", "--out", str(out)], environment(folder / "cache", cc, **extra), folder
            )
            runs[name] = Run(launched, cc, marker, out)
        yield runs
    finally:
        for run in runs.values():
            run.launched.stop()
            kill_all(run.marker)


@pytest.mark.parametrize(
    "case",
    [
        *FAKES,
        pytest.param(
            "interpreted, never returns on the export", marks=pytest.mark.skipif(REAL_CC is None, reason="no cc")
        ),
        pytest.param(
            "interpreted, exits 0 without output on the export",
            marks=pytest.mark.skipif(REAL_CC is None, reason="no cc"),
        ),
    ],
)
def test_export_controller_ends_in_one_line_and_leaves_nothing(case, exports):
    run = exports[case]
    status, lines, took = run.launched.result()
    fake = case.removeprefix("interpreted, ").removesuffix(" on the export")
    assert status == 1 and len(lines) == 1, lines
    line = lines[0]
    assert line.startswith(f"vgtarm: error: the C compiler {named(run.cc)}"), line
    assert all(word in line for word in expected(FAKES[fake][1], "2")), line
    if case.startswith("interpreted"):  # the export's own check compile met it, on one of its files
        assert re.search(r" on \w+\.c with -std=c99 ", line), line
    else:  # tried before the robot's model is compiled with it: no fall-back line first
        assert " on a two-line test file" in line, line
    assert took < WITHIN, took
    assert not run.out.exists() and not run.launched.out, "nothing is written"
    assert [p.name for p in run.out.parent.iterdir() if p.name.startswith(".out")] == []
    assert not gone(run.marker), "nothing of the compiler is left"


def test_a_limit_that_is_no_number_is_one_line(exports):
    status, lines, _ = exports["a limit that is no number"].launched.result()
    assert status == 1 and lines == [f"vgtarm: error: {LIMIT} = 'two': expected a number of seconds > 0"], lines


@pytest.mark.skipif(REAL_CC is None, reason="no C compiler")
def test_the_python_export_never_says_it_checked_with_a_compiler_that_wrote_nothing(robot, tmp_path, monkeypatch):
    cc, marker = fake_compiler(tmp_path, FAKES["exits 0 without output"][0])
    monkeypatch.setenv("CC", str(cc))
    with pytest.raises(ExportError, match="exited 0 but wrote no object file on ") as caught:
        export_controller(robot, tmp_path / "out")
    assert "\n" not in str(caught.value)
    assert not (tmp_path / "out").exists()
    kill_all(marker)


# ---------------------------------------------------------------------- a model's build


def _fk(config: Path) -> list[str]:
    return ["fk", "--config", str(config), *(repr(float(v)) for v in load_stack(config).home)]


#: Builds of the smallest stack: a compiler past a limit of 2 s; and a compiler that ignores
#: SIGINT and SIGTERM (a long limit), for vgtarm to be killed while it runs.
BUILDS = {
    "past the limit": ("never returns", "2"),
    "exits 0 without output": ("exits 0 without output", "2"),
    "SIGKILL": ("ignores SIGINT and SIGTERM", "600"),
    "SIGTERM": ("ignores SIGINT and SIGTERM", "600"),
    "Ctrl-C": ("ignores SIGINT and SIGTERM", "600"),
}


@pytest.fixture(scope="module")
def builds(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Run]]:
    """``vgtarm fk`` of the planar module with a fresh cache, one per case of :data:`BUILDS`, all
    at once."""
    runs: dict[str, Run] = {}
    config = EXAMPLES / "planar_module.toml"
    try:
        for name, (fake, limit) in BUILDS.items():
            folder = tmp_path_factory.mktemp("build")
            body = WITH_A_CHILD if fake == "ignores SIGINT and SIGTERM" else FAKES[fake][0]
            cc, marker = fake_compiler(folder, body)
            cache = folder / "cache"
            cache.mkdir(mode=0o700)
            launched = Launched(_fk(config), environment(cache, cc, **{LIMIT: limit}), folder)
            runs[name] = Run(launched, cc, marker, cache)
        yield runs
    finally:
        for run in runs.values():
            run.launched.stop()
            kill_all(run.marker)


@pytest.mark.parametrize("case", ["past the limit", "exits 0 without output"])
def test_a_model_build_falls_back_in_one_line_naming_the_compiler(case, builds):
    run = builds[case]
    status, lines, took = run.launched.result()
    assert status == 0 and "tip" in run.launched.out, lines
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.startswith(f"vgtarm: the C compiler {named(run.cc)}") and "using CasADi's interpreter" in line, line
    words = ("ran longer than the limit of 2 s", LIMIT) if case == "past the limit" else ("exited 0 but wrote no",)
    assert all(word in line for word in words), line
    assert took < WITHIN, took
    assert not gone(run.marker)
    assert not [p.name for p in run.out.iterdir() if p.name != ".lock"], "no library, no build folder"


@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM", "Ctrl-C"])
def test_a_model_build_s_compiler_dies_with_vgtarm(how, builds):
    """However vgtarm ends during its model's build, its compiler (which ignores SIGINT and SIGTERM)
    and the compiler's child are gone within a couple of seconds."""
    run = builds[how]
    running(run.marker, 2, run.launched)  # the script and the child it waits for
    if how == "SIGKILL":
        run.launched.child.kill()
    elif how == "SIGTERM":
        run.launched.child.terminate()
    else:  # a terminal's Ctrl-C: to the command's process group
        os.killpg(run.launched.child.pid, signal.SIGINT)
    status, lines, _ = run.launched.result(timeout=30)
    assert not gone(run.marker), f"the compiler is left after {how}"
    if how == "SIGKILL":
        assert status == -signal.SIGKILL
    elif how == "SIGTERM":
        assert status in (143, -signal.SIGTERM), (status, lines)
    else:
        assert status == 130 and lines == ["vgtarm: interrupted"], (status, lines)
