"""Evaluation of the model's CasADi functions through compiled code.

On first use the functions of :mod:`vgtarm.model.codegen` are generated as C by CasADi, compiled
together with the drivers of ``csrc/`` (batch evaluation, the closed loop; their interface is the
one header ``csrc/vgtarm.h``, read by :mod:`.interface`) into one shared library, and cached on
disk. The cache key hashes every source file of the ``vgtarm.model`` package that can shape a
library (all but the few runtime modules of :data:`RUNTIME_ONLY`, so no list of the others is kept
by hand and a new module is hashed by default), the recipe of :func:`.compiling._compile`, the CasADi and
cffi versions and the compiler command; the robot's parameters are a
runtime input of every function, so changing the robot never recompiles. A stack of modules
(:mod:`vgtarm.model.stack`) has a library of its own per *structure* (plane angles, which twist
joints and twist bodies exist: :class:`~vgtarm.model.definition.StackDefinition`), whose key also
hashes that structure; stacks that differ only in dimensions, masses or limits share it.

Cache folder: ``$VGTARM_CACHE_DIR`` (empty counts as unset; a relative value is taken from the
current folder), else platformdirs' user cache folder of ``vgtarm``: on Linux
``$XDG_CACHE_HOME/vgtarm`` (if absolute), else ``~/.cache/vgtarm``.
Backend choice: ``$VGTARM_BACKEND`` = ``auto`` (default), ``compiled`` or ``interpreted``.

Trust rules of the cache (the README repeats them for users):

- The folder must belong to the current user and be writable by nobody else (it is created with
  mode 0700); otherwise it is refused with one line saying why.
- Beside each library ``vgtarm_<key>.so`` lies ``vgtarm_<key>.json``: the key, the model's
  structure, the library's size and SHA-256 and the signatures of the generated functions. A
  library is opened only by absolute path and only after its metadata validated and its size and
  SHA-256 matched (so a truncated file is never mapped). The metadata must identify the model being
  loaded, not only carry its key: its structure must be this model's, and every function must have
  the C name, the sizes and names of inputs and outputs and the argument and result counts that the
  code generation gives this model (computed from the definition in milliseconds by
  :mod:`.outline`). Once opened, the library's own report of every function's sizes and the
  structure layout must equal the metadata. A library without metadata is never opened.
- Whatever fails a check is removed and rebuilt once, with one warning line. A build is first
  estimated from the structure and refused in one line beyond the memory available or the build
  time limit (:mod:`.budget`); it runs in a build process of its own (:mod:`.building`: Ctrl-C
  stops it within a fraction of a second, a terminal shows its phases) in a private temporary
  folder ``.build-<pid>-*`` of the cache, under a lock, and the library and then its metadata are
  moved into place atomically; the folder goes whatever happens, and build folders left by dead
  processes or older than an hour are removed.
- When the compiled model cannot be had (no or failing compiler, one past its time limit or that
  writes nothing: :mod:`vgtarm.compiler`, which runs every compiler command in a process group that
  dies with vgtarm; a file size limit that stops the build, a read-only or refused folder, a
  rebuilt library that still fails), ``auto`` runs
  CasADi's interpreter after one line naming the reason; ``VGTARM_BACKEND=interpreted`` chooses it
  silently, and ``compiled`` turns the reason into a :class:`BackendError` instead. The
  interpreter's symbolic construction is estimated and refused alike, and runs in a build process
  too unless it is short (:data:`IN_PROCESS_SYMBOLIC`). A build refused by its estimate raises
  :class:`~vgtarm.model.budget.BuildRefused` whatever the backend choice: the interpreter would
  need the same symbolic construction.

This module is the front: the backend choice and the compiled library loaded from the cache or
built into it once. The parts: :mod:`.backends` (evaluating the functions, compiled or
interpreted), :mod:`.compiling` (the compiler, its flags and commands), :mod:`.library_cache` (the
folder, the key, the metadata and every check before a library is opened), :mod:`.build_lock`
(the build lock, stale build folders) and :mod:`.library_errors` (their one-line errors).
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import os
import shutil
import tempfile
from pathlib import Path

import casadi as ca

from ..errors import ConfigError, shown
from . import budget, build_lock, building, codegen, compiling, library_cache
from .backends import (
    BATCH_CHUNK,
    INTERPRETED_CHUNK,
    Backend,
    CompiledBackend,
    InterpretedBackend,
    Signature,
    build_functions,
    functions_of,
)
from .compiling import compile_limit, find_compiler
from .definition import PAPER, Definition
from .library_cache import (
    METADATA_FORMAT,
    RUNTIME_ONLY,
    SEPARATE_LIBRARIES,
    CacheEntry,
    cache_dir,
    cache_entry,
    library_cached,
    model_sources,
    structure_of,
)
from .library_errors import BackendError, _Damaged, _shown_path, _Unavailable

__all__ = [
    "BACKEND_CHOICES",
    "BATCH_CHUNK",
    "INTERPRETED_CHUNK",
    "IN_PROCESS_SYMBOLIC",
    "METADATA_FORMAT",
    "RUNTIME_ONLY",
    "SEPARATE_LIBRARIES",
    "Backend",
    "BackendError",
    "CacheEntry",
    "CompiledBackend",
    "InterpretedBackend",
    "Signature",
    "backend_choice",
    "build_functions",
    "cache_dir",
    "cache_entry",
    "compile_limit",
    "find_compiler",
    "functions_of",
    "get_backend",
    "library_cached",
    "model_sources",
    "structure_of",
]

logger = logging.getLogger("vgtarm")

#: Values of ``$VGTARM_BACKEND`` (and of ``get_backend(kind)``).
BACKEND_CHOICES = ("auto", "compiled", "interpreted")


def _produce(compiler: str, workdir: Path, definition: Definition, key: str) -> tuple[Path, dict[str, Signature]]:
    """Run :func:`.compiling._compile` in a build process of its own (:mod:`.building`: Ctrl-C stops it at
    once, progress on a terminal) into ``workdir``; the library and the functions' signatures.

    Raises :class:`_Unavailable` with the build's one-line reason. The cache tests replace this
    function to copy a prebuilt library instead, so that the checks around it run for real
    without a compile each.
    """
    try:
        result = building.run("compile", compiler, workdir, definition, key, budget.estimate(definition))
    except building.BuildFailed as exc:
        raise _Unavailable(str(exc)) from None
    functions = result.get("functions")
    expected = set(codegen.builders_for(definition))
    if result.get("library") != "library.so" or not isinstance(functions, dict) or set(functions) != expected:
        raise _Unavailable("the build process reported no library or not every function of the model")
    try:
        signatures = {name: library_cache._parse_signature(name, functions[name]) for name in sorted(expected)}
    except _Damaged as exc:
        raise _Unavailable(f"the build process reported wrong signatures: {exc}") from None
    return workdir / "library.so", signatures


def _build(entry: CacheEntry, compiler: str, definition: Definition = PAPER) -> None:
    """Compile (in a build process) into a private temporary folder of the cache, then move the
    library and then its metadata into place (each move atomic; a library without metadata is never
    opened). The folder goes whatever happens, Ctrl-C included."""
    build_lock._clean_stale_builds(entry.folder)
    logger.info("compiling the vgtarm model into %s (once per model version and stack structure)", entry.library)
    workdir = Path(tempfile.mkdtemp(dir=entry.folder, prefix=f"{build_lock._BUILD_PREFIX}{os.getpid()}-"))
    try:
        library, signatures = _produce(compiler, workdir, definition, entry.key)
        if not library.is_file() or library.is_symlink():
            raise _Unavailable("the build process wrote no library")
        os.chmod(library, 0o755)
        size, digest = library_cache._sha256(library)
        payload = {
            "format": METADATA_FORMAT,
            "key": entry.key,
            "library": entry.library.name,
            "size": size,
            "sha256": digest,
            "compiler": compiler,
            "casadi": str(getattr(ca, "__version__", "unknown")),
            "functions": {key: sig.__dict__ for key, sig in signatures.items()},
            "structure": structure_of(definition),
        }
        metadata = workdir / "metadata.json"
        metadata.write_text(json.dumps(payload, indent=1))
        os.chmod(metadata, 0o644)
        os.replace(library, entry.library)
        os.replace(metadata, entry.metadata)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def _remove(entry: CacheEntry) -> None:
    for path in (entry.metadata, entry.library):  # metadata first: a library alone is never opened
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def _compiled_backend(compiler: str, definition: Definition = PAPER) -> CompiledBackend:
    """The compiled backend of ``definition`` from the cache, (re)built once if missing or damaged.

    Raises :class:`_Unavailable` with a one-line reason when it cannot be had.
    """
    try:
        entry = CacheEntry(cache_dir(), library_cache._cache_key(compiler, definition), definition)
    except RuntimeError as exc:  # Path.home() without a home folder
        raise _Unavailable(f"no cache folder: {exc}; set VGTARM_CACHE_DIR") from None
    info = library_cache._check_folder(entry.folder)
    damage = ""
    if os.path.lexists(entry.library) or os.path.lexists(entry.metadata):
        try:
            return library_cache._load(entry)
        except _Damaged as exc:
            damage = str(exc)
    if not library_cache._writable(entry.folder, info):
        where = f"the cache folder {_shown_path(entry.folder)} is read-only"
        why = (
            f"the cached library is damaged ({damage}) and {where}"
            if damage
            else f"{where} and holds no library of this model version"
        )
        raise _Unavailable(why)
    budget.check(budget.estimate(definition), "compiled")  # before any work: BuildRefused in one line
    compile_limit(definition)  # and a bad $VGTARM_COMPILER_TIME_LIMIT: ConfigError in one line
    try:
        with build_lock._build_lock(entry.folder):
            if os.path.lexists(entry.library) or os.path.lexists(entry.metadata):
                try:  # look again: another process may have (re)built it meanwhile
                    return library_cache._load(entry)
                except _Damaged as exc:
                    logger.warning(
                        "vgtarm: the compile cache in %s is damaged (%s); removing it and rebuilding the library once",
                        _shown_path(entry.folder),
                        exc,
                    )
                _remove(entry)
            _build(entry, compiler, definition)
    except OSError as exc:
        raise _Unavailable(
            f"cannot build in the cache folder {_shown_path(entry.folder)}: {exc.strerror or exc}"
        ) from None
    try:
        return library_cache._load(entry)
    except _Damaged as exc:
        with contextlib.suppress(OSError):
            _remove(entry)  # else every later command would find it damaged and warn twice
        raise _Unavailable(f"the library just built fails its checks: {exc}") from None


def backend_choice() -> str:
    """The backend ``$VGTARM_BACKEND`` chooses (``auto``, ``compiled`` or ``interpreted``; empty or
    unset: ``auto``); :class:`~vgtarm.errors.ConfigError` naming the value otherwise."""
    return _backend_choice(None)


def _backend_choice(kind: object) -> str:
    """The validated backend choice: ``kind``, else ``$VGTARM_BACKEND`` (empty = unset), else auto."""
    if kind is None or kind == "":
        value: object = os.environ.get("VGTARM_BACKEND", "") or "auto"
    else:
        value = kind  # the argument stands for the variable, and is named as such
    if not isinstance(value, str) or value.lower() not in BACKEND_CHOICES:
        allowed = ", ".join(repr(c) for c in BACKEND_CHOICES)
        raise ConfigError(f"VGTARM_BACKEND = {shown(value)}: expected one of {allowed}")
    return value.lower()


@functools.cache
def get_backend(kind: str | None = None, definition: Definition = PAPER) -> CompiledBackend | InterpretedBackend:
    """The process-wide backend of a model: compiled when possible, else interpreted after one line.

    ``kind`` overrides ``$VGTARM_BACKEND`` (``auto``, ``compiled`` or ``interpreted``). With
    ``compiled`` a model that cannot be compiled raises :class:`BackendError` instead.
    ``definition`` is the model (:mod:`vgtarm.model.definition`): the paper's robot by default,
    or a stack's structure, compiled into a library of its own (once per structure, cached).
    A model that must be built and whose estimated build exceeds the memory available or the build
    time limit raises :class:`~vgtarm.model.budget.BuildRefused` (:mod:`.budget`) before any work.
    """
    choice = _backend_choice(kind)
    if choice == "interpreted":
        return _interpreted(definition)
    try:
        compiler = compiling.find_compiler()
        if compiler is None:
            named = os.environ.get("CC")
            raise _Unavailable(
                f"$CC = {shown(named, 80)} names no program on the PATH"
                if named
                else "no C compiler found (cc, gcc or clang)"
            )
        return _compiled_backend(compiler, definition)
    except _Unavailable as exc:
        if choice == "compiled":
            raise BackendError(f"VGTARM_BACKEND = 'compiled', but {exc}") from None
        logger.warning(
            "vgtarm: %s; using CasADi's interpreter instead (slower; %s chooses it without this line)",
            exc,
            "VGTARM_BACKEND=interpreted",
        )
    return _interpreted(definition)


#: A symbolic construction estimated shorter than this (s) runs in this process (the paper's robot:
#: 0.15 s; its longest CasADi call, which Ctrl-C cannot break, much less); a longer one in a build
#: process (:mod:`.building`).
IN_PROCESS_SYMBOLIC = 0.5


def _interpreted(definition: Definition) -> InterpretedBackend:
    """CasADi's interpreter on the functions of ``definition``, after the estimate of their symbolic
    construction fits the limits (:class:`~vgtarm.model.budget.BuildRefused` otherwise)."""
    cost = budget.estimate(definition)
    budget.check(cost, "interpreted")
    if cost.symbolic_seconds < IN_PROCESS_SYMBOLIC:
        return InterpretedBackend(build_functions(definition))
    prefix = "vgtarm-symbolic-"
    with contextlib.suppress(OSError):  # those of commands killed meanwhile (kill -9)
        build_lock._clean_stale_builds(Path(tempfile.gettempdir()), prefix)
    folder = Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-"))
    try:
        try:
            result = building.run("functions", "", folder, definition, "", cost)
        except building.BuildFailed as exc:
            raise BackendError(f"cannot build the symbolic model of {cost.model}: {exc}") from None
        names = result.get("functions")
        expected = set(codegen.builders_for(definition))
        if not isinstance(names, list) or set(names) != expected:
            raise BackendError(f"cannot build the symbolic model of {cost.model}: not every function was built")
        return InterpretedBackend({name: ca.Function.load(str(folder / f"{name}.casadi")) for name in sorted(expected)})
    finally:
        shutil.rmtree(folder, ignore_errors=True)
