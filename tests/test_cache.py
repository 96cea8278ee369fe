"""The compile cache: damaged, planted and untrusted entries and impossible compiles.

Every case of issue 14 that used to crash (SIGBUS, segfault), print a traceback, load a planted
library or give garbage with exit 0 must now end in a rebuilt cache or in one line. The checks
run for real; only the rebuild is made cheap in most tests by replacing ``compiled._produce``
(the step that runs CasADi's generator and the C compiler in a build process) with a copy of the
pristine library taken from the user's cache (in the commands of the entries of another structure
of issue 20, by a copy of a one-module stack's library), so three genuine compiles are left, all
of one-module stacks (the smallest model): the two stacks of the ``planars`` fixture and the
rebuild by the command of ``test_truncated_library_is_rebuilt_by_the_command``. Commands run in
subprocesses with ``VGTARM_CACHE_DIR`` pointing at a temporary folder.
"""

from __future__ import annotations

import dataclasses
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
from vgtarm.model import compiled, library_cache, outline
from vgtarm.model.definition import PAPER, Definition, StackDefinition
from vgtarm.model.stack import load_stack

#: Runs the command line in a fresh interpreter (``python -c``): exit status and streams as a user sees them.
CLI = "import sys; from vgtarm.app.cli.command import main; sys.exit(main())"
#: Prints where the process's backend came from.
WHICH = "import vgtarm; b = vgtarm.load_robot().backend; print(b.kind, getattr(b, 'library_path', ''))"
FALLBACK = "VGTARM_BACKEND=interpreted chooses it without this line"
#: The command line with its compile step (``compiled._produce``) replaced by a copy of the library
#: ``$VGTARM_TEST_LIBRARY``, built beforehand for the same model: every check around it runs for real.
CLI_COPYING = """
import os, shutil, sys
from pathlib import Path
from vgtarm.model import compiled
from vgtarm.app.cli.command import main

def copy(compiler, workdir, definition, key):
    library = Path(workdir) / "library.so"
    shutil.copyfile(os.environ["VGTARM_TEST_LIBRARY"], library)
    return library, {name: compiled.Signature.of(f) for name, f in compiled.build_functions(definition).items()}

compiled._produce = copy
sys.exit(main())
"""


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
    backend = library_cache._load(entry)
    meta = json.loads(entry.metadata.read_text())
    assert meta["size"] == entry.library.stat().st_size
    assert backend.library_path == entry.library and entry.library.is_absolute()
    assert not [p.name for p in entry.folder.iterdir() if p.name.startswith(".build-")]


# ----------------------------------------------------------------------------- damage, in process


@pytest.fixture
def cheap_rebuild(monkeypatch: pytest.MonkeyPatch, pristine: compiled.CacheEntry) -> list[Path]:
    """Replace the compile step by a copy of the pristine library; returns the build folders used."""
    signatures = library_cache._parse_metadata(pristine.metadata.read_bytes(), pristine).signatures
    builds: list[Path] = []

    def copy(compiler: str, workdir: Path, definition: object, key: str) -> tuple[Path, dict[str, compiled.Signature]]:
        assert definition == compiled.PAPER and key == pristine.key
        builds.append(workdir)
        assert workdir.parent == compiled.cache_dir() and (workdir.stat().st_mode & 0o777) == 0o700
        shutil.copyfile(pristine.library, workdir / "library.so")
        return workdir / "library.so", signatures

    monkeypatch.setattr(compiled, "_produce", copy)
    # the key of the pristine copy, even if a model source changes while the suite runs
    monkeypatch.setattr(library_cache, "_cache_key", lambda compiler, definition=compiled.PAPER: pristine.key)
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
        "metadata field functions.tip.nnz_out is [2], expected [3] for this model",
    ),
    "metadata with a wrong input size": (
        _edit_metadata(lambda m: m["functions"]["mass"]["nnz_in"].__setitem__(0, 70)),
        "metadata field functions.mass.nnz_in is [70, 45], expected [7, 45]",
    ),
    "metadata missing an output": (_edit_metadata(_fewer_outputs), "metadata field functions.fk.nnz_out is"),
    "metadata with a renamed output": (
        _edit_metadata(lambda m: m["functions"]["fk"]["out_names"].__setitem__(0, "other")),
        "metadata field functions.fk.out_names",
    ),
    "metadata of another structure": (
        _edit_metadata(lambda m: m.update(structure="stack:0.0,-,-")),
        "metadata field structure is 'stack:0.0,-,-', expected 'paper'",
    ),
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


def test_truncated_library_is_rebuilt_by_the_command(tmp_path, planars):
    """A genuine rebuild: the command that used to die of SIGBUS compiles afresh (the entry of a
    one-module stack, the cheapest compile; the check of the entry is the same for every model)."""
    path, planar = planars["90"]
    entry = compiled.CacheEntry(tmp_path / "cache", planar.key, planar.definition)
    entry.folder.mkdir(mode=0o700)
    for source in (planar.library, planar.metadata):
        shutil.copy2(source, entry.folder / source.name)
    _truncate(entry)
    q = _planar_q(path)
    args = ["fk", "--config", str(path), *(repr(float(v)) for v in q)]
    done = run(args, {"VGTARM_CACHE_DIR": str(entry.folder)}, tmp_path)
    assert done.returncode == 0, done.stderr
    lines = stderr_lines(done)
    assert len(lines) == 1 and "damaged" in lines[0] and "rebuilding the library once" in lines[0], lines
    np.testing.assert_allclose(printed_tip(done.stdout), _interpreted_tip(path, q), rtol=1e-9, atol=1e-12)
    assert_clean_entry(entry)
    again = run(args, {"VGTARM_CACHE_DIR": str(entry.folder)}, tmp_path)
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


def test_compiled_backend_required_but_impossible_is_one_error_line(tmp_path, configuration):
    env = {"VGTARM_CACHE_DIR": str(tmp_path / "cache"), "CC": "false", "VGTARM_BACKEND": "compiled"}
    done = run(fk_args(configuration), env, tmp_path)  # describe needs no compiled model: it builds none
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


# ----------------------------------------------------------------------------- entries of another model (issue 20)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.parametrize("model", ["paper", "planar_module.toml", "paper_robot.toml", "six_modules.toml[:3]"])
def test_the_outline_gives_every_function_the_sizes_of_the_real_one(model):
    """The metadata is checked against the sizes the outline computes in milliseconds: they must be
    those of the functions the symbolic construction builds. ``six_modules.toml[:3]``: that arm's
    first three modules (a twist inside the stack, both planes, a tapered module; 10 joints), whose
    symbolic construction takes a few seconds where the whole arm's took 20 to 30."""
    definition: Definition = PAPER
    if model.endswith("[:3]"):
        arm = load_stack(EXAMPLES / model.removesuffix("[:3]"))
        definition = StackDefinition.of(dataclasses.replace(arm, modules=arm.modules[:3]))
    elif model != "paper":
        definition = StackDefinition.of(load_stack(EXAMPLES / model))
    shapes = outline.shapes(definition)
    real = {key: compiled.Signature.of(f) for key, f in compiled.build_functions(definition).items()}
    assert set(shapes) == set(real)
    for key, sig in real.items():
        shape = shapes[key]
        assert (sig.name, sig.nnz_in, sig.nnz_out, sig.in_names, sig.out_names, sig.sz_arg, sig.sz_res) == (
            shape.name,
            shape.nnz_in,
            shape.nnz_out,
            shape.in_names,
            shape.out_names,
            shape.sz_arg,
            shape.sz_res,
        ), key


@pytest.fixture(scope="module")
def planars(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, compiled.CacheEntry]]:
    """Two one-module stacks of the same sizes and different structures (plane 0 and 90 degrees),
    each compiled for real into a private cache: ``{plane: (robot file, cache entry)}``."""
    if compiled.find_compiler() is None:
        pytest.skip("no C compiler")
    folder = tmp_path_factory.mktemp("planars")
    cache = folder / "cache"
    cache.mkdir(mode=0o700)
    text = (EXAMPLES / "planar_module.toml").read_text()
    made = {}
    for plane in ("0", "90"):
        path = folder / f"planar{plane}.toml"
        path.write_text(text.replace("plane = 0.0", f"plane = {plane}.0", 1))
        definition = StackDefinition.of(load_stack(path))
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv("VGTARM_CACHE_DIR", str(cache))
            patch.delenv("VGTARM_BACKEND", raising=False)
            backend = compiled.get_backend.__wrapped__("compiled", definition)
        key = backend.library_path.name.removeprefix("vgtarm_").removesuffix(".so")
        made[plane] = (path, compiled.CacheEntry(cache, key, definition))
    assert made["0"][1].key != made["90"][1].key
    return made


def _place(source: compiled.CacheEntry, target: compiled.CacheEntry, **rewrite: str) -> None:
    """``source``'s library and metadata under ``target``'s key, the metadata's key (and the fields
    ``rewrite`` names) rewritten: a consistent entry, but of another model."""
    target.folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    shutil.copy2(source.library, target.library)
    meta = json.loads(source.metadata.read_text())
    meta.update(key=target.key, library=target.library.name, **rewrite)
    target.metadata.write_text(json.dumps(meta))


def _planar_q(path: Path) -> np.ndarray:
    """A configuration off the symmetric home, so that the planes of 0 and 90 degrees move the tip apart."""
    return load_stack(path).home + np.array([0.01, -0.01, 0.0])


def _interpreted_tip(path: Path, q: np.ndarray) -> np.ndarray:
    """The tip of the stack in ``path`` at ``q`` from CasADi's interpreter, independent of any library."""
    stack = load_stack(path)
    functions = compiled.InterpretedBackend(compiled.build_functions(StackDefinition.of(stack)))
    return functions.evaluate("tip", [q, stack.vector()], 1)[0][0]


@pytest.mark.parametrize(
    ("other", "reason"),
    [
        ("90", "metadata field structure is 'stack:90.0,-,-', expected 'stack:0.0,-,-'"),  # same sizes: a wrong tip
        ("paper", "metadata field structure is 'paper', expected 'stack:0.0,-,-'"),  # other sizes: a traceback
    ],
)
def test_an_entry_of_another_structure_under_this_key_is_rebuilt_once(tmp_path, planars, pristine, other, reason):
    """Issue 20: a consistent entry of another structure, placed under this key with its key field
    rewritten, loaded and gave a wrong tip with exit 0 (same sizes) or a traceback on every command
    (other sizes). It is damage: removed and rebuilt once, with one line, and the tip is right.
    (The rebuild copies the fixture's library of this stack: ``CLI_COPYING``.)"""
    path, planar = planars["0"]
    entry = compiled.CacheEntry(tmp_path / "cache", planar.key, planar.definition)
    _place(pristine if other == "paper" else planars[other][1], entry)
    q = _planar_q(path)
    args = ["fk", "--config", str(path), *(repr(float(v)) for v in q)]
    copying = {"VGTARM_CACHE_DIR": str(entry.folder), "VGTARM_TEST_LIBRARY": str(planar.library)}
    done = run(args, copying, tmp_path, code=CLI_COPYING)
    assert done.returncode == 0, done.stderr
    found = stderr_lines(done)
    assert len(found) == 1 and reason in found[0] and "removing it and rebuilding the library once" in found[0], found
    expected = compiled.InterpretedBackend(compiled.build_functions(planar.definition))
    stack = load_stack(path)
    tip = expected.evaluate("tip", [q, stack.vector()], 1)[0][0]
    np.testing.assert_allclose(printed_tip(done.stdout), tip, rtol=1e-9, atol=1e-12)
    other_tip = compiled.InterpretedBackend(compiled.build_functions(planars["90"][1].definition))
    assert np.abs(other_tip.evaluate("tip", [q, stack.vector()], 1)[0][0] - tip).max() > 1e-3  # it was wrong
    assert_clean_entry(entry)
    assert json.loads(entry.metadata.read_text())["structure"] == "stack:0.0,-,-"
    again = run(args, {"VGTARM_CACHE_DIR": str(entry.folder)}, tmp_path)
    assert again.returncode == 0 and not again.stderr  # rebuilt once: the next command is silent


def test_an_entry_whose_structure_field_is_rewritten_too_fails_on_its_sizes(tmp_path, planars, pristine):
    _, planar = planars["0"]
    entry = compiled.CacheEntry(tmp_path / "cache", planar.key, planar.definition)
    _place(pristine, entry, structure="stack:0.0,-,-")
    with pytest.raises(
        compiled._Damaged, match=r"^metadata field functions\.fk\.nnz_in is \[7, 45\], expected \[3, \d+\]"
    ):
        library_cache._load(entry)


def test_the_library_report_is_checked_against_the_signatures(pristine):
    """Second line of defence: the library's own report of its functions' sizes (after the
    metadata's checks) catches signatures that do not describe it."""
    meta = library_cache._parse_metadata(pristine.metadata.read_bytes(), pristine)
    wrong = dict(meta.signatures)
    wrong["tip"] = compiled.Signature(**{**wrong["tip"].__dict__, "nnz_out": (2,)})
    backend = compiled.CompiledBackend(pristine.library, wrong)
    try:
        assert backend.mismatches() == ["tip: size of output 0"]
    finally:
        backend.close()
