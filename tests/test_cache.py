"""The compile cache: damaged, planted and untrusted entries and impossible compiles.

Every case of issue 14 that used to crash (SIGBUS, segfault), print a traceback, load a planted
library or give garbage with exit 0 must now end in a rebuilt cache or in one line. The checks
run for real; only the rebuild is made cheap in most tests by replacing ``compiled._compile``
(the step that runs CasADi's generator and the C compiler) with a copy of the pristine library
taken from the user's cache, so one genuine compile is left (``test_truncated_library_is_rebuilt_by_the_command``).
Commands run in subprocesses with ``VGTARM_CACHE_DIR`` pointing at a temporary folder.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import vgtarm
from vgtarm.errors import ConfigError
from vgtarm.model import compiled

#: Runs the command line in a fresh interpreter (``python -c``): exit status and streams as a user sees them.
CLI = "import sys; from vgtarm.app.cli import main; sys.exit(main())"
#: Prints where the process's backend came from.
WHICH = "import vgtarm; b = vgtarm.load_robot().backend; print(b.kind, getattr(b, 'library_path', ''))"
FALLBACK = "VGTARM_BACKEND=interpreted chooses it without this line"


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> compiled.CacheEntry:
    """A copy of the user's cached library and metadata for the current sources (built if needed)."""
    backend = compiled.get_backend()
    if not isinstance(backend, compiled.CompiledBackend):
        pytest.skip("no working C compiler: nothing to cache")
    entry = compiled.cache_entry()
    assert entry.folder == backend.library_path.parent
    # the key of the library loaded (a source may have changed since, moving cache_entry's key)
    entry = compiled.CacheEntry(entry.folder, backend.library_path.name.removeprefix("vgtarm_").removesuffix(".so"))
    folder = tmp_path_factory.mktemp("pristine")
    os.chmod(folder, 0o700)
    for path in (entry.library, entry.metadata):
        shutil.copy2(path, folder / path.name)
    return compiled.CacheEntry(folder, entry.key)


@pytest.fixture(scope="module")
def configuration(robot: vgtarm.Robot) -> np.ndarray:
    """A configuration near home with every joint moved (so no tip coordinate is trivially zero)."""
    n = robot.parameters.home.size
    return robot.parameters.home + np.linspace(-0.01, 0.01, n) + np.eye(n)[-1] * 0.2


@pytest.fixture(scope="module")
def expected_tip(robot: vgtarm.Robot, configuration: np.ndarray) -> np.ndarray:
    """The tip from CasADi's interpreter, independent of any compiled library."""
    interpreted = vgtarm.Robot(robot.parameters, compiled.InterpretedBackend(compiled.build_functions()))
    return interpreted.forward_kinematics(configuration).tip


def seed(folder: Path, pristine: compiled.CacheEntry) -> compiled.CacheEntry:
    """``folder`` as a private cache holding a copy of the pristine entry."""
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    for path in (pristine.library, pristine.metadata):
        shutil.copy2(path, folder / path.name)
    return compiled.CacheEntry(folder, pristine.key)


def run(args: list[str], env: dict[str, str], cwd: Path, code: str = CLI) -> subprocess.CompletedProcess[str]:
    full = {k: v for k, v in os.environ.items() if k not in ("VGTARM_BACKEND", "VGTARM_CACHE_DIR")}
    full.update(env)
    return subprocess.run(
        [sys.executable, "-c", code, *args], env=full, cwd=cwd, capture_output=True, text=True, timeout=600
    )


def fk_args(q: np.ndarray) -> list[str]:
    return ["fk", *(repr(float(v)) for v in q)]


def printed_tip(stdout: str) -> np.ndarray:
    line = next(line for line in stdout.splitlines() if line.startswith("tip"))
    return np.array([float(v) for v in line.split("[", 1)[1].split("]", 1)[0].split(",")])


def stderr_lines(done: subprocess.CompletedProcess[str]) -> list[str]:
    return [line for line in done.stderr.splitlines() if line.strip()]


def assert_clean_entry(entry: compiled.CacheEntry) -> None:
    """The entry passes every check again, and its metadata records the file on disk."""
    backend = compiled._load(entry)
    meta = json.loads(entry.metadata.read_text())
    assert meta["size"] == entry.library.stat().st_size
    assert backend.library_path == entry.library and entry.library.is_absolute()
    assert not [p.name for p in entry.folder.iterdir() if p.name.startswith(".build-")]


# ----------------------------------------------------------------------------- damage, in process


@pytest.fixture
def cheap_rebuild(monkeypatch: pytest.MonkeyPatch, pristine: compiled.CacheEntry) -> list[Path]:
    """Replace the compile step by a copy of the pristine library; returns the build folders used."""
    signatures = compiled._parse_metadata(pristine.metadata.read_bytes(), pristine).signatures
    builds: list[Path] = []

    def copy(compiler: str, workdir: Path, definition: object = None) -> tuple[Path, dict[str, compiled.Signature]]:
        assert definition == compiled.PAPER
        builds.append(workdir)
        assert workdir.parent == compiled.cache_dir() and (workdir.stat().st_mode & 0o777) == 0o700
        shutil.copyfile(pristine.library, workdir / "library.so")
        return workdir / "library.so", signatures

    monkeypatch.setattr(compiled, "_compile", copy)
    # the key of the pristine copy, even if a model source changes while the suite runs
    monkeypatch.setattr(compiled, "_cache_key", lambda compiler, definition=compiled.PAPER: pristine.key)
    monkeypatch.delenv("VGTARM_BACKEND", raising=False)
    return builds


def _truncate(entry: compiled.CacheEntry) -> None:
    data = entry.library.read_bytes()
    entry.library.write_bytes(data[: len(data) // 2])


def _flip_byte(entry: compiled.CacheEntry) -> None:
    data = bytearray(entry.library.read_bytes())
    data[len(data) // 2] ^= 0xFF
    entry.library.write_bytes(bytes(data))


def _edit_metadata(change: Callable[[dict[str, Any]], object]) -> Callable[[compiled.CacheEntry], None]:
    def edit(entry: compiled.CacheEntry) -> None:
        meta = json.loads(entry.metadata.read_text())
        change(meta)
        entry.metadata.write_text(json.dumps(meta))

    return edit


def _fewer_outputs(meta: dict[str, Any]) -> None:
    fk = meta["functions"]["fk"]
    fk["nnz_out"], fk["out_names"] = fk["nnz_out"][:-1], fk["out_names"][:-1]


def _link_library(entry: compiled.CacheEntry) -> None:
    entry.library.unlink()
    entry.library.symlink_to(entry.metadata)


def _pipe_metadata(entry: compiled.CacheEntry) -> None:
    entry.metadata.unlink()
    os.mkfifo(entry.metadata)


DAMAGE = {
    "truncated library": (_truncate, "bytes, its metadata says"),
    "zero-byte library": (lambda e: e.library.write_bytes(b""), "has 0 bytes"),
    "library with a changed byte": (_flip_byte, "SHA-256"),
    "garbage metadata": (lambda e: e.metadata.write_bytes(b"\x00{garbage"), "not valid JSON"),
    "empty metadata": (lambda e: e.metadata.write_bytes(b""), "not valid JSON"),
    "deeply nested metadata": (lambda e: e.metadata.write_text("[" * 100_000), "not valid JSON"),
    "metadata of another format": (lambda e: e.metadata.write_text("{}"), "format"),
    "metadata with a text size": (_edit_metadata(lambda m: m["functions"]["tip"].update(sz_w="12")), "sz_w"),
    "metadata with a negative size": (_edit_metadata(lambda m: m["functions"]["tip"].update(sz_w=-1)), "sz_w"),
    "metadata with a wrong library size": (_edit_metadata(lambda m: m.update(size=m["size"] + 1)), "metadata says"),
    "metadata with a wrong output size": (
        _edit_metadata(lambda m: m["functions"]["tip"].update(nnz_out=[2])),
        "tip: size of output 0",
    ),
    "metadata with a wrong input size": (
        _edit_metadata(lambda m: m["functions"]["mass"]["nnz_in"].__setitem__(0, 70)),
        "mass: size of input 0",
    ),
    "metadata missing an output": (_edit_metadata(_fewer_outputs), "fk: number of inputs or outputs"),
    "metadata with a hostile function name": (
        _edit_metadata(lambda m: m["functions"]["tip"].update(name="x; int y")),
        "C identifier",
    ),
    "metadata without its library": (lambda e: e.library.unlink(), "missing beside its metadata"),
    "library linked from elsewhere": (_link_library, "is not a regular file"),
    "metadata that is a pipe": (_pipe_metadata, "not a regular file"),
}


@pytest.mark.parametrize("case", list(DAMAGE))
def test_damaged_entry_is_removed_and_rebuilt_once(
    case, tmp_path, monkeypatch, caplog, cheap_rebuild, pristine, configuration, expected_tip
):
    damage, reason = DAMAGE[case]
    entry = seed(tmp_path / "cache", pristine)
    damage(entry)
    monkeypatch.setenv("VGTARM_CACHE_DIR", str(entry.folder))
    with caplog.at_level(logging.WARNING, logger="vgtarm"):
        backend = compiled.get_backend.__wrapped__("auto")
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1, warnings
    assert reason in warnings[0] and "removing it and rebuilding" in warnings[0] and "\n" not in warnings[0]
    assert len(cheap_rebuild) == 1
    assert isinstance(backend, compiled.CompiledBackend) and backend.library_path == entry.library
    tip = vgtarm.Robot(vgtarm.load_robot().parameters, backend).forward_kinematics(configuration).tip
    np.testing.assert_allclose(tip, expected_tip, rtol=1e-12, atol=1e-15)
    assert_clean_entry(entry)


def test_planted_library_without_metadata_is_never_opened(
    tmp_path, monkeypatch, caplog, cheap_rebuild, pristine, expected_tip, configuration
):
    compiler = compiled.find_compiler()
    assert compiler is not None
    marker = tmp_path / "constructor-ran"
    source = tmp_path / "planted.c"
    source.write_text(
        "#include <stdio.h>\n"
        "__attribute__((constructor)) static void planted(void) {\n"
        f'    FILE *f = fopen("{marker}", "w"); if (f) fclose(f);\n'
        "}\n"
    )
    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    entry = compiled.CacheEntry(folder, pristine.key)
    subprocess.run([compiler, "-shared", "-fPIC", "-o", str(entry.library), str(source)], check=True)
    monkeypatch.setenv("VGTARM_CACHE_DIR", str(folder))
    with caplog.at_level(logging.WARNING, logger="vgtarm"):
        backend = compiled.get_backend.__wrapped__("auto")
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and "has no metadata" in warnings[0], warnings
    assert not marker.exists(), "the planted library's constructor ran"
    assert len(cheap_rebuild) == 1 and isinstance(backend, compiled.CompiledBackend)
    tip = vgtarm.Robot(vgtarm.load_robot().parameters, backend).forward_kinematics(configuration).tip
    np.testing.assert_allclose(tip, expected_tip, rtol=1e-12, atol=1e-15)
    assert entry.library.read_bytes() == pristine.library.read_bytes()
    assert_clean_entry(entry)


def test_new_cache_is_private_and_stale_build_folders_are_cleaned(tmp_path, monkeypatch, caplog, cheap_rebuild):
    folder = tmp_path / "new" / "cache"
    monkeypatch.setenv("VGTARM_CACHE_DIR", str(folder))
    compiled.get_backend.__wrapped__("auto")  # creates the folder and builds
    assert (folder.stat().st_mode & 0o777) == 0o700
    dead = folder / ".build-999999999-abc"  # above any pid the kernel hands out
    old = folder / f".build-{os.getpid()}-old"
    fresh = folder / f".build-{os.getpid()}-fresh"
    for item in (dead, old, fresh):
        item.mkdir()
        (item / "library.so").write_bytes(b"partial")
    hours_ago = time.time() - 2 * 3600
    os.utime(old, (hours_ago, hours_ago))
    compiled.cache_entry().metadata.unlink()  # a library without metadata: rebuilt
    with caplog.at_level(logging.WARNING, logger="vgtarm"):
        assert isinstance(compiled.get_backend.__wrapped__("auto"), compiled.CompiledBackend)
    assert len(cheap_rebuild) == 2
    left = sorted(p.name for p in folder.iterdir() if p.name.startswith(".build-"))
    assert left == [fresh.name], "dead and old build folders go, a live recent one stays"


def test_read_only_cache_with_a_good_library_loads_it(tmp_path, monkeypatch, cheap_rebuild, pristine, caplog):
    entry = seed(tmp_path / "cache", pristine)
    os.chmod(entry.folder, 0o500)
    monkeypatch.setenv("VGTARM_CACHE_DIR", str(entry.folder))
    try:
        with caplog.at_level(logging.WARNING, logger="vgtarm"):
            backend = compiled.get_backend.__wrapped__("auto")
    finally:
        os.chmod(entry.folder, 0o700)
    assert isinstance(backend, compiled.CompiledBackend) and not caplog.records and not cheap_rebuild


def test_cache_folder_of_another_user_is_refused(tmp_path, monkeypatch, caplog, cheap_rebuild):
    if os.geteuid() == 0:
        folder = tmp_path / "theirs"
        folder.mkdir(mode=0o700)
        os.chown(folder, 54321, 54321)
    else:
        folder = Path("/")  # root's, and not writable by others
    monkeypatch.setenv("VGTARM_CACHE_DIR", str(folder))
    with caplog.at_level(logging.WARNING, logger="vgtarm"):
        backend = compiled.get_backend.__wrapped__("auto")
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert isinstance(backend, compiled.InterpretedBackend) and len(warnings) == 1, warnings
    assert f"belongs to user id {folder.stat().st_uid}, not to you ({os.geteuid()})" in warnings[0]
    assert FALLBACK in warnings[0] and not cheap_rebuild


def test_backend_choice_is_validated(monkeypatch):
    monkeypatch.setenv("VGTARM_BACKEND", "")  # empty counts as unset
    assert compiled._backend_choice(None) == "auto"
    with pytest.raises(ConfigError, match=r"VGTARM_BACKEND = 3: expected one of 'auto', 'compiled', 'interpreted'"):
        compiled._backend_choice(3)


# ----------------------------------------------------------------------------- commands, in subprocesses


def test_truncated_library_is_rebuilt_by_the_command(tmp_path, pristine, configuration, expected_tip):
    """The one genuine rebuild: the command that used to die of SIGBUS compiles afresh."""
    entry = seed(tmp_path / "cache", pristine)
    _truncate(entry)
    done = run(fk_args(configuration), {"VGTARM_CACHE_DIR": str(entry.folder)}, tmp_path)
    assert done.returncode == 0, done.stderr
    lines = stderr_lines(done)
    assert len(lines) == 1 and "damaged" in lines[0] and "rebuilding the library once" in lines[0], lines
    np.testing.assert_allclose(printed_tip(done.stdout), expected_tip, rtol=1e-9, atol=1e-12)
    assert_clean_entry(entry)
    again = run(fk_args(configuration), {"VGTARM_CACHE_DIR": str(entry.folder)}, tmp_path)
    assert again.returncode == 0 and not again.stderr  # rebuilt once: the next command is silent


def _make_file(path: Path) -> Path:
    path.write_text("not a folder")
    return path


def _make_read_only(path: Path) -> Path:
    path.mkdir(mode=0o500)
    return path


def _make_shared(mode: int) -> Callable[[Path], Path]:
    def make(path: Path) -> Path:
        path.mkdir()
        os.chmod(path, mode)
        return path

    return make


FALLBACKS = {
    "cache path is a file": (_make_file, {}, "is not a folder"),
    "read-only cache": (_make_read_only, {}, "is read-only"),
    "group-writable cache": (_make_shared(0o770), {}, "writable by group or others (mode 0770)"),
    "world-writable cache": (_make_shared(0o777), {}, "writable by group or others (mode 0777)"),
    "cache inside a file": (lambda p: _make_file(p.parent / "file") / "cache", {}, "cannot create the cache folder"),
    "failing compiler": (lambda p: p, {"CC": "false"}, "failed (exit status 1)"),
    "missing compiler": (lambda p: p, {"CC": "no-such-compiler-here"}, "names no program on the PATH"),
}


@pytest.mark.parametrize("case", list(FALLBACKS))
def test_impossible_compile_falls_back_with_one_line(case, tmp_path, configuration, expected_tip):
    make, env, reason = FALLBACKS[case]
    folder = make(tmp_path / "cache")
    try:
        done = run(fk_args(configuration), {"VGTARM_CACHE_DIR": str(folder), **env}, tmp_path)
    finally:
        if folder.is_dir():
            os.chmod(folder, 0o700)
    assert done.returncode == 0, done.stderr
    lines = stderr_lines(done)
    assert len(lines) == 1, lines
    assert reason in lines[0] and FALLBACK in lines[0] and lines[0].startswith("vgtarm: ")
    np.testing.assert_allclose(printed_tip(done.stdout), expected_tip, rtol=1e-9, atol=1e-12)


def test_refused_cache_is_refused_even_with_a_good_library(tmp_path, pristine):
    entry = seed(tmp_path / "cache", pristine)
    os.chmod(entry.folder, 0o775)
    done = run([], {"VGTARM_CACHE_DIR": str(entry.folder)}, tmp_path, code=WHICH)
    os.chmod(entry.folder, 0o700)
    assert done.returncode == 0 and done.stdout.split()[0] == "interpreted"
    assert len(stderr_lines(done)) == 1 and "refusing the cache folder" in done.stderr


def test_compiled_backend_required_but_impossible_is_one_error_line(tmp_path):
    env = {"VGTARM_CACHE_DIR": str(tmp_path / "cache"), "CC": "false", "VGTARM_BACKEND": "compiled"}
    done = run(["describe"], env, tmp_path)
    assert done.returncode == 1 and not done.stdout
    lines = stderr_lines(done)
    assert len(lines) == 1 and lines[0].startswith("vgtarm: error: VGTARM_BACKEND = 'compiled', but the C compiler")


def test_unknown_backend_is_one_config_error_line(tmp_path):
    done = run(["describe"], {"VGTARM_BACKEND": "bogus", "VGTARM_CACHE_DIR": str(tmp_path)}, tmp_path)
    assert done.returncode == 1 and not done.stdout
    assert stderr_lines(done) == [
        "vgtarm: error: VGTARM_BACKEND = 'bogus': expected one of 'auto', 'compiled', 'interpreted'"
    ]


def test_empty_cache_dir_means_unset_and_relative_means_absolute(tmp_path, pristine):
    work = tmp_path / "work"
    work.mkdir()
    seed(tmp_path / "xdg" / "vgtarm", pristine)
    done = run([], {"VGTARM_CACHE_DIR": "", "XDG_CACHE_HOME": str(tmp_path / "xdg")}, work, code=WHICH)
    assert done.returncode == 0 and not done.stderr, done.stderr
    kind, library = done.stdout.split()
    assert kind == "compiled" and Path(library).parent == tmp_path / "xdg" / "vgtarm"
    assert not list(work.iterdir()), "nothing is compiled into the current folder"
    seed(work / "relative", pristine)
    done = run([], {"VGTARM_CACHE_DIR": "relative"}, work, code=WHICH)
    kind, library = done.stdout.split()
    assert done.returncode == 0 and kind == "compiled" and Path(library).parent == work / "relative"
