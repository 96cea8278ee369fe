"""Evaluation of the model's CasADi functions through compiled code.

On first use the functions of :mod:`vgtarm.model.codegen` are generated as C by CasADi, compiled
together with the drivers of ``csrc/`` (batch evaluation, the closed loop; their interface is the
one header ``csrc/vgtarm.h``, read by :mod:`.interface`) into one shared library, and cached on
disk. The cache key hashes every source file of the ``vgtarm.model`` package that can shape a
library (all but the few runtime modules of :data:`RUNTIME_ONLY`, so no list of the others is kept
by hand and a new module is hashed by default), the recipe of :func:`_compile`, the CasADi and
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
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import inspect
import json
import logging
import os
import re
import shutil
import stat
import subprocess
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import casadi as ca
import cffi
import numpy as np
from cffi import FFI
from numpy.typing import NDArray

from .. import compiler as compilers
from ..errors import ConfigError, VgtarmError, cut, shown
from ..fileio import process_alive
from ..machine import split_rows
from . import budget, building, codegen, interface, outline
from .definition import PAPER, Definition

logger = logging.getLogger("vgtarm")

_PACKAGE_DIR = Path(__file__).resolve().parent
#: Suffixes of the model package's source files that the cache key hashes.
_SOURCE_SUFFIXES = (".py", ".c", ".h", ".toml")
#: Modules of the model package that never shape a compiled library: the runtime around it (the
#: Robot API, the loop bindings, the accepted joint range, this cache). The key skips them, so
#: editing one does not recompile every library (the six-module arm's takes about 80 s); the build
#: recipe of this module is hashed apart (:func:`_recipe`). ``tests/test_architecture.py`` checks
#: that no module the code generation imports, directly or not, is in this set.
RUNTIME_ONLY = frozenset(
    {
        "__init__.py",
        "robot.py",
        "closedloop.py",
        "sanity.py",
        "compiled.py",
        "stack/model.py",
        "budget.py",
        "building.py",
        "build_process.py",
        "outline.py",
    }
)
#: Sub-packages of the model package that build and cache a library of their own, with a key of
#: their own (the recursive model, :mod:`vgtarm.model.recursive`): the key of this module's
#: libraries skips them, as no code generation here imports them (tested).
SEPARATE_LIBRARIES = frozenset({"recursive"})
_CSRC = _PACKAGE_DIR / "csrc"
_CFLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off")
#: Flags of a stack's generated functions, compiled apart before the link with the drivers (built
#: with :data:`_CFLAGS`): its straight-line code is ten times the paper robot's (17 MB of C for six
#: modules, 12.6 MB with common-subexpression elimination), and GCC's -O2 spent 4 min 19 s on it
#: where -O1 took 1 min 22 s (measured on this 2-core machine; 77 s with the elimination). Neither
#: changes a floating-point result: no contraction, no fast math.
_STACK_GENERATED_CFLAGS = ("-O1", "-fPIC", "-ffp-contract=off")
_GENERATED_NAME = "vgtarm_model"

#: Values of ``$VGTARM_BACKEND`` (and of ``get_backend(kind)``).
BACKEND_CHOICES = ("auto", "compiled", "interpreted")
#: Version of the metadata file's layout; another version is rebuilt.
METADATA_FORMAT = 1
#: Prefix of the private build folders inside the cache (followed by the builder's pid).
_BUILD_PREFIX = ".build-"
#: A build folder older than this (s) is stale even if its process still runs.
_STALE_BUILD_AGE = 3600.0
#: Longest wait (s) for another process's build of the same cache before building anyway.
_LOCK_WAIT = 900.0
#: Default limit (s) of one compiler command (:mod:`vgtarm.compiler`, before
#: ``$VGTARM_COMPILER_TIME_LIMIT``): the build process sets it from its model's estimate
#: (:func:`compile_limit`); the recursive model's library (a few seconds) keeps this one.
_COMPILE_TIMEOUT = budget.COMPILER_LIMIT_FLOOR
#: Samples of one compiled batch call: at most a few tens of milliseconds (the costliest function
#: takes about 4 us a sample), so Ctrl-C is handled between two calls of a huge batch. Below the
#: 4,096 samples from which ``vgt_batch`` (``csrc/batch.c``) starts OpenMP threads of its own: a
#: batch's threads are :func:`vgtarm.machine.split_rows`'s, sized by the machine, taking chunks
#: one at a time and waiting without spinning.
BATCH_CHUNK = 4095
#: Samples of one call into CasADi's interpreter (about 50 ms at the costliest 90 us a sample).
INTERPRETED_CHUNK = 512
#: Largest metadata file and library read (bytes): anything bigger is damaged, not read.
_MAX_METADATA_BYTES = 1 << 20
_MAX_LIBRARY_BYTES = 1 << 30
#: Largest size or count a metadata field may hold (far above any real function's hundreds).
_MAX_COUNT = 1 << 20
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,127}")


class BackendError(VgtarmError, RuntimeError):
    """``VGTARM_BACKEND=compiled`` was asked for, but the model cannot be compiled or loaded."""


class _Unavailable(Exception):
    """The compiled backend cannot be had; the message is the one-line reason."""


class _Damaged(Exception):
    """A cached library or its metadata fails a check; the message says which and how."""


@dataclass(frozen=True)
class Signature:
    """Sizes of one function's inputs and outputs and its work arrays."""

    name: str
    nnz_in: tuple[int, ...]
    nnz_out: tuple[int, ...]
    sz_arg: int
    sz_res: int
    sz_iw: int
    sz_w: int
    in_names: tuple[str, ...] = ()
    out_names: tuple[str, ...] = ()

    @classmethod
    def of(cls, f: ca.Function) -> Signature:
        return cls(
            name=f.name(),
            nnz_in=tuple(f.nnz_in(i) for i in range(f.n_in())),
            nnz_out=tuple(f.nnz_out(i) for i in range(f.n_out())),
            sz_arg=int(f.sz_arg()),
            sz_res=int(f.sz_res()),
            sz_iw=int(f.sz_iw()),
            sz_w=int(f.sz_w()),
            in_names=tuple(f.name_in()),
            out_names=tuple(f.name_out()),
        )


class Backend(Protocol):
    """What the model layers need: evaluate a named function over a batch."""

    kind: str

    def evaluate(self, name: str, inputs: Sequence[NDArray[np.float64]], n: int) -> list[NDArray[np.float64]]:
        """Evaluate function ``name`` on ``n`` samples.

        Each input is either ``(n, nnz)`` (one row per sample) or ``(nnz,)`` (the same value for
        every sample). Returns one ``(n, nnz_out)`` array per output.
        """
        ...

    def signature(self, name: str) -> Signature:
        """Sizes of function ``name``."""
        ...


def _check_inputs(sig: Signature, inputs: Sequence[NDArray[np.float64]], n: int) -> None:
    if len(inputs) != len(sig.nnz_in):
        raise ValueError(f"{sig.name}: expected {len(sig.nnz_in)} inputs, got {len(inputs)}")
    for i, (x, nnz) in enumerate(zip(inputs, sig.nnz_in, strict=True)):
        if x.shape not in ((n, nnz), (nnz,)):
            raise ValueError(f"{sig.name}: input {i} has shape {x.shape}, expected ({n}, {nnz}) or ({nnz},)")


def _declarations(names: Sequence[str]) -> str:
    """cffi declarations of the generated functions ``names`` and of CasADi's report of their sizes."""
    lines = [f"int {_GENERATED_NAME}_casadi_int_size(void);"]
    for name in names:
        lines += [
            f"int {name}(const double **, double **, vgt_int *, double *, int);",
            f"vgt_int {name}_n_in(void);",
            f"vgt_int {name}_n_out(void);",
            f"const vgt_int *{name}_sparsity_in(vgt_int);",
            f"const vgt_int *{name}_sparsity_out(vgt_int);",
            f"const char *{name}_name_in(vgt_int);",
            f"const char *{name}_name_out(vgt_int);",
            f"int {name}_work(vgt_int *, vgt_int *, vgt_int *, vgt_int *);",
        ]
    return "\n".join(lines) + "\n"


def _nonzeros(pattern: Any) -> int | None:
    """Number of nonzeros of a CasADi sparsity pattern (``nrow, ncol, 1`` when dense, else
    ``nrow, ncol, colind[ncol + 1], row[nnz]``); None for a null or absurd pattern."""
    if pattern == cffi.FFI.NULL:
        return None
    nrow, ncol = int(pattern[0]), int(pattern[1])
    if not (0 <= nrow <= _MAX_COUNT and 0 <= ncol <= _MAX_COUNT):
        return None
    return nrow * ncol if int(pattern[2]) == 1 else int(pattern[2 + ncol])


class CompiledBackend:
    """Functions evaluated through the compiled shared library (opened by absolute path)."""

    kind = "compiled"

    def __init__(self, library_path: Path, signatures: dict[str, Signature]) -> None:
        if not library_path.is_absolute():
            raise ValueError(f"a compiled library is opened only by absolute path, not {library_path}")
        self.library_path = library_path
        #: Threads of a batch (:func:`vgtarm.machine.split_rows`): ``None``, the default, as many as
        #: :func:`vgtarm.machine.batch_threads` gives; 1 the calling thread alone. Every sample is
        #: computed alone, so the results are the same bit for bit.
        self.threads: int | None = None
        self.ffi = interface.ffi()
        self.library = interface.open_library(library_path)
        self._signatures = signatures
        # the generated functions share one C type; declare them by name to find their addresses
        generated = FFI()
        generated.include(self.ffi)
        generated.cdef(_declarations([sig.name for sig in signatures.values()]))
        try:
            symbols = generated.dlopen(str(library_path))
            self._generated, self._symbols = generated, symbols
            self._pointers = {
                key: self.ffi.cast("vgt_fn", getattr(symbols, sig.name)) for key, sig in signatures.items()
            }
        except BaseException:
            self.ffi.dlclose(self.library)
            raise

    def close(self) -> None:
        """Let go of the library (after a failed check); the backend is unusable afterwards."""
        self._generated.dlclose(self._symbols)
        self.ffi.dlclose(self.library)

    def mismatches(self) -> list[str]:
        """Where the library's own report (CasADi's size functions, the structure layout) contradicts
        the signatures it was opened with; empty when they agree."""
        lib = self._symbols
        found: list[str] = []
        if getattr(lib, f"{_GENERATED_NAME}_casadi_int_size")() != self.ffi.sizeof("vgt_int"):
            found.append("integer size")
        if self.layout() != interface.python_layout():
            found.append("structure layout")
        sizes = self._generated.new("vgt_int[4]")
        for key, sig in self._signatures.items():
            name = sig.name
            counts = [
                (getattr(lib, f"{name}_n_in")(), len(sig.nnz_in)),
                (getattr(lib, f"{name}_n_out")(), len(sig.nnz_out)),
            ]
            if any(got != want for got, want in counts):
                found.append(f"{key}: number of inputs or outputs")
                continue
            for side, expected, names in (("in", sig.nnz_in, sig.in_names), ("out", sig.nnz_out, sig.out_names)):
                sparsity, label = getattr(lib, f"{name}_sparsity_{side}"), getattr(lib, f"{name}_name_{side}")
                for i, nnz in enumerate(expected):
                    if _nonzeros(sparsity(i)) != nnz:
                        found.append(f"{key}: size of {side}put {i}")
                    text = label(i)
                    if names and (text == cffi.FFI.NULL or self.ffi.string(text).decode(errors="replace") != names[i]):
                        found.append(f"{key}: name of {side}put {i}")
            # the generated code may need less work space than the CasADi function reports
            # (local variables instead of w), never more: the metadata's sizes are allocated
            status = getattr(lib, f"{name}_work")(sizes, sizes + 1, sizes + 2, sizes + 3)
            recorded = (sig.sz_arg, sig.sz_res, sig.sz_iw, sig.sz_w)
            if status != 0 or any(need > have for need, have in zip(sizes, recorded, strict=True)):
                found.append(f"{key}: work sizes")
        return found

    def signature(self, name: str) -> Signature:
        return self._signatures[name]

    def function_pointer(self, name: str) -> Any:
        """The generated C function ``name`` as a ``vgt_fn`` (for the closed-loop drivers)."""
        return self._pointers[name]

    def call(self, name: str) -> Any:
        """A ``vgt_call`` structure (function and work sizes) of the generated function ``name``."""
        sig = self._signatures[name]
        return self.ffi.new("vgt_call *", [self._pointers[name], sig.sz_arg, sig.sz_res, sig.sz_iw, sig.sz_w])[0]

    def layout(self) -> list[int]:
        """Sizes and field offsets of the interface's structures as the compiler laid them out."""
        out = self.ffi.new("long[]", len(interface.layout_fields()))
        self.library.vgt_layout(out)
        return list(out)

    def evaluate(self, name: str, inputs: Sequence[NDArray[np.float64]], n: int) -> list[NDArray[np.float64]]:
        sig = self._signatures[name]
        arrays = [np.ascontiguousarray(x, dtype=np.float64) for x in inputs]
        _check_inputs(sig, arrays, n)
        outputs = [np.empty((n, nnz)) for nnz in sig.nnz_out]
        if n == 0:
            return outputs
        ffi = self.ffi
        in_ptrs = [ffi.cast("double *", x.ctypes.data) for x in arrays]
        in_strides = [0 if x.ndim == 1 else x.shape[1] for x in arrays]
        out_ptrs = [ffi.cast("double *", y.ctypes.data) for y in outputs]
        out_strides = list(sig.nnz_out)
        batch, function = self.library.vgt_batch, self._pointers[name]

        def work(begin: int, end: int) -> None:
            for start in range(begin, end, BATCH_CHUNK):  # Ctrl-C is handled between two chunks
                status = batch(
                    function,
                    sig.sz_arg,
                    sig.sz_res,
                    sig.sz_iw,
                    sig.sz_w,
                    len(arrays),
                    len(outputs),
                    min(BATCH_CHUNK, end - start),
                    [p + start * s for p, s in zip(in_ptrs, in_strides, strict=True)],
                    in_strides,
                    [p + start * s for p, s in zip(out_ptrs, out_strides, strict=True)],
                    out_strides,
                )
                if status != 0:
                    raise RuntimeError(f"compiled function {sig.name} failed (status {status})")

        if self.threads == 1:
            work(0, n)
        else:
            split_rows(n, work, self.threads)
        return outputs


class InterpretedBackend:
    """The same functions evaluated by CasADi's virtual machine (no compiler needed)."""

    kind = "interpreted"

    def __init__(self, built: dict[str, ca.Function]) -> None:
        self.functions = built
        self._signatures = {key: Signature.of(f) for key, f in built.items()}
        self._maps: dict[tuple[str, int], ca.Function] = {}

    def signature(self, name: str) -> Signature:
        return self._signatures[name]

    def evaluate(self, name: str, inputs: Sequence[NDArray[np.float64]], n: int) -> list[NDArray[np.float64]]:
        sig = self._signatures[name]
        arrays = [np.asarray(x, dtype=np.float64) for x in inputs]
        _check_inputs(sig, arrays, n)
        if n == 0:
            return [np.empty((0, nnz)) for nnz in sig.nnz_out]
        outputs = [np.empty((n, nnz)) for nnz in sig.nnz_out]
        for start in range(0, n, INTERPRETED_CHUNK):  # Ctrl-C is handled between two chunks
            rows = slice(start, min(start + INTERPRETED_CHUNK, n))
            m = rows.stop - rows.start
            key = (name, m)
            if key not in self._maps:
                if len(self._maps) > 64:
                    self._maps.clear()
                self._maps[key] = self.functions[name].map(m, "serial")
            args = [ca.DM(x[rows].T) if x.ndim == 2 else ca.DM(x) for x in arrays]
            raw = self._maps[key](*args)
            results = list(raw) if isinstance(raw, tuple | list) else [raw]
            for out, r, nnz in zip(outputs, results, sig.nnz_out, strict=True):
                out[rows] = np.array(r, dtype=np.float64).reshape(nnz, m).T
        return outputs


def build_functions(definition: Definition = PAPER) -> dict[str, ca.Function]:
    """Build every CasADi function of the model (a second or so): the paper's robot, or the stack
    structure ``definition``."""
    return {key: builder() for key, builder in codegen.builders_for(definition).items()}


def functions_of(definition: Definition, names: Sequence[str]) -> InterpretedBackend:
    """CasADi's interpreter on the functions ``names`` of ``definition`` alone, built in this process
    (for a few functions known to be cheap: nothing is estimated or compiled)."""
    builders = codegen.builders_for(definition)
    return InterpretedBackend({name: builders[name]() for name in names})


def library_cached(definition: Definition = PAPER) -> bool:
    """Whether the cache holds a library and metadata for ``definition`` under the current key (not
    checked: only a load checks it)."""
    compiler = find_compiler()
    if compiler is None:
        return False
    try:
        entry = CacheEntry(cache_dir(), _cache_key(compiler, definition), definition)
    except RuntimeError:  # Path.home() without a home folder
        return False
    return os.path.lexists(entry.library) and os.path.lexists(entry.metadata)


def cache_dir() -> Path:
    """Folder of the compiled libraries, always absolute.

    ``$VGTARM_CACHE_DIR`` when set and not empty (a relative value is taken from the current
    folder), else platformdirs' user cache folder: on Linux ``$XDG_CACHE_HOME/vgtarm`` when that is
    absolute, else ``~/.cache/vgtarm`` (macOS: ``~/Library/Caches/vgtarm``). ``RuntimeError``
    when there is no home folder to be found.
    """
    chosen = os.environ.get("VGTARM_CACHE_DIR", "")
    if chosen:
        return Path(os.path.abspath(os.path.expanduser(chosen)))
    import platformdirs  # imported here: only this lookup needs it

    # Linux: $XDG_CACHE_HOME/vgtarm when absolute (a relative value is ignored, as the XDG
    # specification says), else ~/.cache/vgtarm; RuntimeError without a home folder
    return Path(os.path.abspath(platformdirs.user_cache_dir("vgtarm", appauthor=False)))


def find_compiler() -> str | None:
    """The C compiler to use: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in candidates:
        found = shutil.which(name)
        if found:
            return found
    return None


def model_sources() -> list[Path]:
    """Every source file of the ``vgtarm.model`` package that can shape a compiled library (all
    but :data:`RUNTIME_ONLY` and :data:`SEPARATE_LIBRARIES`), in a fixed order."""
    return sorted(
        path
        for path in _PACKAGE_DIR.rglob("*")
        if path.is_file()
        and path.suffix in _SOURCE_SUFFIXES
        and "__pycache__" not in path.parts
        and path.relative_to(_PACKAGE_DIR).as_posix() not in RUNTIME_ONLY
        and path.relative_to(_PACKAGE_DIR).parts[0] not in SEPARATE_LIBRARIES
    )


def _recipe() -> bytes:
    """How this module turns the generated C into a library: the source of :func:`_compile` and
    every flag it uses (the rest of this module loads, checks and caches; it is not hashed)."""
    flags = (_CFLAGS, _STACK_GENERATED_CFLAGS, _GENERATED_NAME)
    return inspect.getsource(_compile).encode() + repr(flags).encode()


def _cache_key(compiler: str, definition: Definition = PAPER) -> str:
    digest = hashlib.sha256()
    for path in model_sources():
        digest.update(path.relative_to(_PACKAGE_DIR).as_posix().encode())
        digest.update(path.read_bytes())
    digest.update(_recipe())
    digest.update(str(getattr(ca, "__version__", "unknown")).encode())
    digest.update(str(cffi.__version__).encode())
    digest.update(" ".join((compiler, *_CFLAGS)).encode())
    if definition.key:  # a stack's structure (the paper's robot adds nothing: its key is unchanged)
        digest.update(definition.key.encode())
    return digest.hexdigest()[:20]


@dataclass(frozen=True)
class CacheEntry:
    """Where the library of one cache key lives: ``folder/vgtarm_<key>.so`` and its ``.json``, and
    the model it must be the library of (its metadata is checked against it)."""

    folder: Path
    key: str
    definition: Definition = PAPER

    @property
    def library(self) -> Path:
        return self.folder / f"vgtarm_{self.key}.so"

    @property
    def metadata(self) -> Path:
        return self.folder / f"vgtarm_{self.key}.json"


def cache_entry(compiler: str | None = None) -> CacheEntry:
    """The cache entry of this process's model sources and ``compiler`` (default: the one found).

    Raises :class:`BackendError` when no compiler is given and none is found.
    """
    compiler = compiler or find_compiler()
    if compiler is None:
        raise BackendError("no C compiler found (cc, gcc or clang on the PATH, or $CC)")
    return CacheEntry(cache_dir(), _cache_key(compiler))


def _shown_path(path: Path) -> str:
    return shown(str(path), 160)


# ----------------------------------------------------------------------------- trust and checks


def _check_folder(folder: Path) -> os.stat_result:
    """The cache folder's status, creating it (mode 0700) if missing; :class:`_Unavailable`
    unless it is a folder of the current user that nobody else can write."""
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    except FileExistsError:  # a file (or a dangling link) holds the name: reported below
        pass
    except OSError as exc:
        raise _Unavailable(f"cannot create the cache folder {_shown_path(folder)}: {exc.strerror or exc}") from None
    try:
        info = os.stat(folder)
    except OSError as exc:
        raise _Unavailable(f"cannot use the cache folder {_shown_path(folder)}: {exc.strerror or exc}") from None
    if not stat.S_ISDIR(info.st_mode):
        raise _Unavailable(f"the cache folder {_shown_path(folder)} is not a folder; set VGTARM_CACHE_DIR to a folder")
    if info.st_uid != os.geteuid():
        raise _Unavailable(
            f"refusing the cache folder {_shown_path(folder)}: it belongs to user id {info.st_uid}, not to you "
            f"({os.geteuid()}); set VGTARM_CACHE_DIR to a folder of yours"
        )
    if info.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        raise _Unavailable(
            f"refusing the cache folder {_shown_path(folder)}: it is writable by group or others (mode "
            f"{stat.S_IMODE(info.st_mode):04o}), so anyone could plant a library; run chmod go-w on it"
        )
    return info


def _writable(folder: Path, info: os.stat_result) -> bool:
    """Whether a build can write into ``folder``: its owner's write bit is set (a folder made
    read-only counts as such even for root) and the system grants the access."""
    return bool(info.st_mode & stat.S_IWUSR) and os.access(folder, os.W_OK | os.X_OK)


def _read_private(path: Path, limit: int) -> bytes:
    """The bytes of a regular file of the current user that nobody else can write, at most
    ``limit`` of them (never following a link, never blocking on a pipe)."""
    flags = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise _Damaged(f"{path.name} is missing") from None
    except OSError as exc:
        raise _Damaged(f"{path.name} cannot be opened ({exc.strerror or exc})") from None
    with os.fdopen(fd, "rb") as handle:
        info = os.fstat(handle.fileno())
        if not stat.S_ISREG(info.st_mode):
            raise _Damaged(f"{path.name} is not a regular file")
        if info.st_uid != os.geteuid() or info.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
            raise _Damaged(f"{path.name} belongs to someone else or is writable by others")
        if info.st_size > limit:
            raise _Damaged(f"{path.name} is too large ({info.st_size} bytes)")
        return handle.read(limit + 1)


def _count(value: object, where: str, limit: int = _MAX_COUNT) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= limit:
        raise _Damaged(f"metadata field {where} is {shown(value, 30)}, expected a count")
    return value


def _counts(value: object, where: str) -> tuple[int, ...]:
    if not isinstance(value, list) or len(value) > 1000:
        raise _Damaged(f"metadata field {where} is {shown(value, 30)}, expected a list of counts")
    return tuple(_count(v, f"{where}[{i}]") for i, v in enumerate(value))


def _names(value: object, where: str, length: int) -> tuple[str, ...]:
    if not (
        isinstance(value, list) and len(value) == length and all(isinstance(v, str) and len(v) < 200 for v in value)
    ):
        raise _Damaged(f"metadata field {where} is {shown(value, 30)}, expected {length} names")
    return tuple(value)


def _parse_signature(key: str, value: object) -> Signature:
    where = f"functions.{key}"
    if not isinstance(value, dict):
        raise _Damaged(f"metadata field {where} is {shown(value, 30)}, expected a table")
    name = value.get("name")
    if not (isinstance(name, str) and _IDENTIFIER.fullmatch(name)):
        raise _Damaged(f"metadata field {where}.name is {shown(name, 30)}, expected a C identifier")
    nnz_in, nnz_out = _counts(value.get("nnz_in"), f"{where}.nnz_in"), _counts(value.get("nnz_out"), f"{where}.nnz_out")
    sz_arg, sz_res = _count(value.get("sz_arg"), f"{where}.sz_arg"), _count(value.get("sz_res"), f"{where}.sz_res")
    if sz_arg < len(nnz_in) or sz_res < len(nnz_out):
        raise _Damaged(f"metadata fields {where}.sz_arg and sz_res are fewer than the inputs and outputs")
    return Signature(
        name=name,
        nnz_in=nnz_in,
        nnz_out=nnz_out,
        sz_arg=sz_arg,
        sz_res=sz_res,
        sz_iw=_count(value.get("sz_iw"), f"{where}.sz_iw"),
        sz_w=_count(value.get("sz_w"), f"{where}.sz_w"),
        in_names=_names(value.get("in_names"), f"{where}.in_names", len(nnz_in)),
        out_names=_names(value.get("out_names"), f"{where}.out_names", len(nnz_out)),
    )


@dataclass(frozen=True)
class _Metadata:
    size: int
    sha256: str
    signatures: dict[str, Signature]


def structure_of(definition: Definition) -> str:
    """The structure a library's metadata records: ``paper``, or a stack's structure key."""
    return definition.key or "paper"


def _check_shapes(signatures: dict[str, Signature], definition: Definition) -> None:
    """:class:`_Damaged` unless every function has the C name and the sizes and names of inputs and
    outputs that the code generation gives ``definition`` (:mod:`.outline`)."""
    for key, shape in outline.shapes(definition).items():
        sig = signatures[key]
        for field in ("name", "nnz_in", "nnz_out", "in_names", "out_names", "sz_arg", "sz_res"):
            found, expected = getattr(sig, field), getattr(shape, field)
            if found != expected:
                shown_found = list(found) if isinstance(found, tuple) else found
                shown_expected = list(expected) if isinstance(expected, tuple) else expected
                raise _Damaged(
                    f"metadata field functions.{key}.{field} is {shown(shown_found, 40)}, expected "
                    f"{shown(shown_expected, 40)} for this model"
                )


def _parse_metadata(raw: bytes, entry: CacheEntry) -> _Metadata:
    """The validated metadata of ``entry``: the format, the key, the model's structure, the
    library's size and SHA-256, and one signature for each function the model generates, with the
    names and sizes the code generation gives this model (distinct C names)."""
    try:
        payload = json.loads(raw)
    except (ValueError, RecursionError):
        raise _Damaged(f"{entry.metadata.name} is not valid JSON") from None
    if not isinstance(payload, dict) or payload.get("format") != METADATA_FORMAT:
        raise _Damaged(f"{entry.metadata.name} is not metadata of format {METADATA_FORMAT}")
    if payload.get("key") != entry.key:
        raise _Damaged(f"metadata field key is {shown(payload.get('key'), 30)}, expected {entry.key!r}")
    structure = structure_of(entry.definition)
    if payload.get("structure") != structure:
        raise _Damaged(
            f"metadata field structure is {shown(payload.get('structure'), 50)}, expected {shown(structure, 50)}"
        )
    size = _count(payload.get("size"), "size", _MAX_LIBRARY_BYTES)
    sha256 = payload.get("sha256")
    if not (isinstance(sha256, str) and re.fullmatch(r"[0-9a-f]{64}", sha256)):
        raise _Damaged(f"metadata field sha256 is {shown(sha256, 30)}, expected 64 hexadecimal digits")
    functions = payload.get("functions")
    expected = set(codegen.builders_for(entry.definition))
    if not isinstance(functions, dict) or set(functions) != expected:
        raise _Damaged("metadata field functions does not list exactly the model's functions")
    signatures = {key: _parse_signature(key, functions[key]) for key in sorted(expected)}
    if len({sig.name for sig in signatures.values()}) != len(signatures):
        raise _Damaged("metadata field functions repeats a C name")
    _check_shapes(signatures, entry.definition)
    return _Metadata(size, sha256, signatures)


def _sha256(path: Path, limit: int = _MAX_LIBRARY_BYTES) -> tuple[int, str]:
    """Size and SHA-256 of a private regular file (see :func:`_read_private`)."""
    data = _read_private(path, limit)
    return len(data), hashlib.sha256(data).hexdigest()


def _load(entry: CacheEntry) -> CompiledBackend:
    """Open the cached library of ``entry`` after every check; :class:`_Damaged` if one fails.

    Order matters: the metadata is validated and the file's size and SHA-256 compared before the
    library is handed to the system loader, so a truncated, foreign or planted file is never
    mapped (a truncated one would end the process with SIGBUS).
    """
    try:
        return _load_checked(entry)
    except OSError as exc:  # a read error of a file that passed lstat
        raise _Damaged(f"{entry.library.name} cannot be read ({exc.strerror or exc})") from None


def _load_checked(entry: CacheEntry) -> CompiledBackend:
    if not os.path.lexists(entry.metadata):
        raise _Damaged(f"{entry.library.name} has no metadata")
    meta = _parse_metadata(_read_private(entry.metadata, _MAX_METADATA_BYTES), entry)
    if not os.path.lexists(entry.library):
        raise _Damaged(f"{entry.library.name} is missing beside its metadata")
    info = os.lstat(entry.library)
    if not stat.S_ISREG(info.st_mode):
        raise _Damaged(f"{entry.library.name} is not a regular file")
    on_disk = info.st_size
    if on_disk != meta.size:
        raise _Damaged(f"{entry.library.name} has {on_disk} bytes, its metadata says {meta.size}")
    size, digest = _sha256(entry.library, meta.size)
    if size != meta.size or digest != meta.sha256:
        raise _Damaged(f"the SHA-256 of {entry.library.name} differs from its metadata")
    try:
        backend = CompiledBackend(entry.library, meta.signatures)
    except (OSError, AttributeError, cffi.FFIError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise _Damaged(f"{entry.library.name} does not load ({cut(first, 120)})") from None
    try:
        wrong = backend.mismatches()
    except (AttributeError, cffi.FFIError) as exc:
        wrong = [f"missing {cut(str(exc), 80)}"]
    if wrong:
        backend.close()
        more = f" and {len(wrong) - 1} more" if len(wrong) > 1 else ""
        raise _Damaged(f"{entry.library.name} does not match its metadata ({wrong[0]}{more})")
    return backend


# ----------------------------------------------------------------------------- building


def _clean_stale_builds(folder: Path, prefix: str = _BUILD_PREFIX) -> None:
    """Remove the build folders ``prefix<pid>-*`` of ``folder`` that are the current user's and
    whose process is gone or that are older than an hour."""
    now = time.time()
    for item in folder.iterdir():
        if not item.name.startswith(prefix):
            continue
        try:
            info = item.lstat()
        except OSError:
            continue
        if info.st_uid != os.geteuid():
            continue
        pid_text = item.name[len(prefix) :].split("-", 1)[0]
        dead = not (pid_text.isdigit() and process_alive(int(pid_text)))
        if dead or now - info.st_mtime > _STALE_BUILD_AGE:
            if stat.S_ISDIR(info.st_mode):
                shutil.rmtree(item, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    item.unlink()


@contextlib.contextmanager
def _build_lock(folder: Path) -> Iterator[None]:
    """Hold the cache's build lock (filelock's ``flock`` on ``.lock``, mode 0600, never followed
    through a symbolic link, released by the system if the holder dies); after a long wait, go on
    without it (the moves into place are atomic). A file system without ``flock`` is an error
    (:class:`OSError`), never a silent fall-back to a lock file that a killed holder would leave."""
    from filelock import FileLock, Timeout  # imported here: only a build needs it

    lock = FileLock(folder / ".lock", mode=0o600, poll_interval=0.1, fallback_to_soft=False)
    try:
        lock.acquire(timeout=_LOCK_WAIT)
        held = True
    except Timeout:  # before OSError: filelock's Timeout is a TimeoutError
        held = False
    except OSError as exc:
        raise _Unavailable(f"cannot write in the cache folder {_shown_path(folder)}: {exc.strerror or exc}") from None
    try:
        yield
    finally:
        if held:
            lock.release()


def _compiler_failure(compiler: str, done: subprocess.CompletedProcess[str]) -> str:
    ending = compilers.ending(done.returncode)
    return f"the C compiler {shown(compiler, 80)} failed ({ending}): {compilers.first_error(done)}"


def compile_limit(definition: Definition = PAPER) -> float:
    """The limit (s) of one compiler command building ``definition``: ``$VGTARM_COMPILER_TIME_LIMIT``,
    else a generous multiple of the estimated compile (:func:`~vgtarm.model.budget.compiler_limit`).

    Raises:
        ConfigError: the variable is set but not a number of seconds > 0.
    """
    return compilers.time_limit(budget.compiler_limit(budget.estimate(definition)))


def _run(compiler: str, command: list[str]) -> subprocess.CompletedProcess[str]:
    """Run one compiler command under its time limit, in a process group of its own that dies with
    this process (:func:`vgtarm.compiler.run`), and return what it did; :class:`_Unavailable` when
    it cannot run, runs past the limit, or exits 0 without writing its output (``-o``)."""
    try:
        done = compilers.run(command, limit=_COMPILE_TIMEOUT)
    except compilers.CompilerError as exc:
        raise _Unavailable(str(exc)) from None
    if done.returncode == 0 and compilers.wrote_nothing(command):
        raise _Unavailable(f"the C compiler {shown(compiler, 80)} exited 0 but wrote no {compilers.product(command)}")
    return done


def _run_compiler(compiler: str, command: list[str]) -> None:
    """Run one compiler command; :class:`_Unavailable` with the first error line when it fails."""
    done = _run(compiler, command)
    if done.returncode != 0:
        raise _Unavailable(_compiler_failure(compiler, done))


def _compile(compiler: str, workdir: Path, definition: Definition = PAPER) -> tuple[Path, dict[str, Signature]]:
    """Generate C for every model function into ``workdir`` and compile it with the drivers.

    Returns the library (inside ``workdir``) and the functions' signatures; raises
    :class:`_Unavailable` when the compiler cannot run or fails. The cache tests replace this
    function to copy a prebuilt library instead, so that the checks around it run for real
    without a 10-20 s compile each.
    """
    built = build_functions(definition)
    generator = ca.CodeGenerator(f"{_GENERATED_NAME}.c", {"with_header": False})
    for f in built.values():
        generator.add(f)
    generator.generate(str(workdir) + os.sep)
    (workdir / "layout.c").write_text(interface.layout_source())
    sources = [str(workdir / f"{_GENERATED_NAME}.c"), str(workdir / "layout.c")]
    sources += [str(path) for path in sorted(_CSRC.glob("*.c"))]
    library = workdir / "library.so"
    if definition != PAPER:  # a stack: its generated code compiled apart (_STACK_GENERATED_CFLAGS)
        generated = workdir / f"{_GENERATED_NAME}.o"
        _run_compiler(compiler, [compiler, *_STACK_GENERATED_CFLAGS, "-c", "-o", str(generated), sources[0]])
        if not generated.is_file():
            raise _Unavailable(f"the C compiler {shown(compiler, 80)} wrote no object file")
        sources[0] = str(generated)
    base = [compiler, *_CFLAGS, "-I", str(_CSRC), "-o", str(library), *sources, "-lm"]
    failure = ""
    for command in (base[:1] + ["-fopenmp"] + base[1:], base):
        done = _run(compiler, command)
        if done.returncode == 0 and library.is_file():
            return library, {key: Signature.of(f) for key, f in built.items()}
        failure = _compiler_failure(compiler, done)
    raise _Unavailable(failure)


def _produce(compiler: str, workdir: Path, definition: Definition, key: str) -> tuple[Path, dict[str, Signature]]:
    """Run :func:`_compile` in a build process of its own (:mod:`.building`: Ctrl-C stops it at
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
        signatures = {name: _parse_signature(name, functions[name]) for name in sorted(expected)}
    except _Damaged as exc:
        raise _Unavailable(f"the build process reported wrong signatures: {exc}") from None
    return workdir / "library.so", signatures


def _build(entry: CacheEntry, compiler: str, definition: Definition = PAPER) -> None:
    """Compile (in a build process) into a private temporary folder of the cache, then move the
    library and then its metadata into place (each move atomic; a library without metadata is never
    opened). The folder goes whatever happens, Ctrl-C included."""
    _clean_stale_builds(entry.folder)
    logger.info("compiling the vgtarm model into %s (once per model version and stack structure)", entry.library)
    workdir = Path(tempfile.mkdtemp(dir=entry.folder, prefix=f"{_BUILD_PREFIX}{os.getpid()}-"))
    try:
        library, signatures = _produce(compiler, workdir, definition, entry.key)
        if not library.is_file() or library.is_symlink():
            raise _Unavailable("the build process wrote no library")
        os.chmod(library, 0o755)
        size, digest = _sha256(library)
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
        entry = CacheEntry(cache_dir(), _cache_key(compiler, definition), definition)
    except RuntimeError as exc:  # Path.home() without a home folder
        raise _Unavailable(f"no cache folder: {exc}; set VGTARM_CACHE_DIR") from None
    info = _check_folder(entry.folder)
    damage = ""
    if os.path.lexists(entry.library) or os.path.lexists(entry.metadata):
        try:
            return _load(entry)
        except _Damaged as exc:
            damage = str(exc)
    if not _writable(entry.folder, info):
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
        with _build_lock(entry.folder):
            if os.path.lexists(entry.library) or os.path.lexists(entry.metadata):
                try:  # look again: another process may have (re)built it meanwhile
                    return _load(entry)
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
        return _load(entry)
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
        compiler = find_compiler()
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
        _clean_stale_builds(Path(tempfile.gettempdir()), prefix)
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
