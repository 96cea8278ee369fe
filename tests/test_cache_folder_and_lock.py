"""The compile cache's folder (platformdirs), its build lock (filelock) and the liveness check of a
stale build's process (psutil) behave as the hand-written code they replaced (issue 27, item 10).

The folder is checked against the rule written out here (the XDG specification's, as vgtarm
documents it), the lock against a second process holding a plain ``flock`` on the same file, and
the liveness check against processes this test starts and reaps.
"""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from vgtarm import fileio
from vgtarm.model import build_lock, compiled
from vgtarm.model.library_errors import _Unavailable

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the Linux folder rule and flock")


def expected_folder(env: dict[str, str], cwd: Path) -> Path:
    """The documented rule, written out: ``$VGTARM_CACHE_DIR`` (empty = unset, relative: from the
    current folder, ``~`` expanded), else ``$XDG_CACHE_HOME/vgtarm`` if absolute, else ``$HOME/.cache/vgtarm``."""
    chosen = env.get("VGTARM_CACHE_DIR", "")
    if chosen:
        chosen = env["HOME"] + chosen[1:] if chosen.startswith("~/") else chosen
        return Path(os.path.normpath(cwd / chosen))
    base = env.get("XDG_CACHE_HOME", "")
    if not base.startswith("/"):
        base = env["HOME"] + "/.cache"
    return Path(os.path.normpath(base)) / "vgtarm"


CASES = {
    "nothing set": {},
    "XDG absolute": {"XDG_CACHE_HOME": "{tmp}/xdg"},
    "XDG absolute, trailing slash": {"XDG_CACHE_HOME": "{tmp}/xdg/"},
    "XDG relative is ignored": {"XDG_CACHE_HOME": "relative/xdg"},
    "XDG empty": {"XDG_CACHE_HOME": ""},
    "XDG blank": {"XDG_CACHE_HOME": "  "},
    "VGTARM_CACHE_DIR first": {"VGTARM_CACHE_DIR": "{tmp}/mine", "XDG_CACHE_HOME": "{tmp}/xdg"},
    "VGTARM_CACHE_DIR relative": {"VGTARM_CACHE_DIR": "here/cache"},
    "VGTARM_CACHE_DIR with ~": {"VGTARM_CACHE_DIR": "~/elsewhere"},
    "VGTARM_CACHE_DIR empty is unset": {"VGTARM_CACHE_DIR": "", "XDG_CACHE_HOME": "{tmp}/xdg"},
}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_cache_folder_follows_the_documented_rule(case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    home, cwd = tmp_path / "home", tmp_path / "work"
    home.mkdir()
    cwd.mkdir()
    env = {"HOME": str(home), **{k: v.format(tmp=tmp_path) for k, v in CASES[case].items()}}
    for name in ("VGTARM_CACHE_DIR", "XDG_CACHE_HOME"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    monkeypatch.chdir(cwd)
    assert compiled.cache_dir() == expected_folder(env, cwd)
    assert compiled.cache_dir().is_absolute()


def test_cache_folder_of_a_fresh_process_is_the_same(tmp_path: Path) -> None:
    """The folder a vgtarm command would use, in a fresh interpreter (nothing monkeypatched)."""
    env = {k: v for k, v in os.environ.items() if k not in ("VGTARM_CACHE_DIR", "XDG_CACHE_HOME")}
    env["HOME"] = str(tmp_path)
    code = "from vgtarm.model.compiled import cache_dir; print(cache_dir())"
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(tmp_path / ".cache" / "vgtarm")


#: Holds a plain ``flock`` on argv[1] (what the hand-written lock took), says so, then waits for
#: its standard input to close.
HOLDER = """
import fcntl, os, sys
fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT, 0o600)
fcntl.flock(fd, fcntl.LOCK_EX)
print("held", flush=True)
sys.stdin.read()
"""


def _holder(lock: Path) -> subprocess.Popen[str]:
    process = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(lock)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert process.stdout is not None and process.stdout.readline() == "held\n"
    return process


def test_build_lock_waits_for_another_process_and_takes_the_lock_itself(tmp_path: Path) -> None:
    holder = _holder(tmp_path / ".lock")
    entered: list[float] = []
    release_at = time.monotonic() + 0.5
    try:

        def release() -> None:
            time.sleep(max(0.0, release_at - time.monotonic()))
            assert holder.stdin is not None
            holder.stdin.close()
            holder.wait(timeout=30)

        threading.Thread(target=release, daemon=True).start()
        with build_lock._build_lock(tmp_path):
            entered.append(time.monotonic())
            fd = os.open(tmp_path / ".lock", os.O_RDWR)
            try:  # held here: another open file description cannot take it
                with pytest.raises(BlockingIOError):
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            finally:
                os.close(fd)
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait()
    assert entered and entered[0] >= release_at, "the lock was entered while the other process held it"
    fd = os.open(tmp_path / ".lock", os.O_RDWR)
    try:  # released on leaving
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    finally:
        os.close(fd)
    assert ((tmp_path / ".lock").stat().st_mode & 0o777) == 0o600
    assert (tmp_path / ".lock").exists(), "the lock file stays (unlinking it would split waiters)"


def test_build_lock_goes_on_without_the_lock_after_the_longest_wait(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(build_lock, "_LOCK_WAIT", 0.3)
    holder = _holder(tmp_path / ".lock")
    try:
        start = time.monotonic()
        with build_lock._build_lock(tmp_path):
            waited = time.monotonic() - start
    finally:
        assert holder.stdin is not None
        holder.stdin.close()
        holder.wait(timeout=30)
    assert waited >= 0.3


def test_build_lock_is_created_private(tmp_path: Path) -> None:
    with build_lock._build_lock(tmp_path):
        pass
    assert ((tmp_path / ".lock").stat().st_mode & 0o777) == 0o600


def test_build_lock_never_follows_a_symbolic_link(tmp_path: Path) -> None:
    target = tmp_path / "target"
    target.write_text("keep")
    (tmp_path / ".lock").symlink_to(target)
    with pytest.raises(_Unavailable, match="cannot write in the cache folder"), build_lock._build_lock(tmp_path):
        pytest.fail("the block must not run")
    assert target.read_text() == "keep"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_build_lock_in_a_read_only_folder_is_one_reason(tmp_path: Path) -> None:
    folder = tmp_path / "ro"
    folder.mkdir(mode=0o500)
    try:
        with (
            pytest.raises(_Unavailable, match="cannot write in the cache folder"),
            build_lock._build_lock(folder),
        ):
            pytest.fail("the block must not run")
    finally:
        folder.chmod(0o700)


def test_liveness_of_a_process_is_that_of_the_system() -> None:
    """A running child is alive, a reaped one is not, this process and pid 1 (someone else's) are."""
    child = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)
    try:
        assert fileio.process_alive(child.pid)
    finally:
        assert child.stdin is not None
        child.stdin.close()
        child.wait(timeout=30)
    assert not fileio.process_alive(child.pid)
    for pid in (os.getpid(), 1):
        assert fileio.process_alive(pid)
    assert not fileio.process_alive(999_999_999)
    assert not hasattr(compiled, "_process_alive")  # one liveness check for the cache and the files
