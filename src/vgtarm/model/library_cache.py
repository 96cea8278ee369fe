"""The compile cache: where its libraries lie, under which key, and the checks before one is opened.

The key (:func:`_cache_key`) hashes every source file of the ``vgtarm.model`` package that can
shape a library (all but :data:`RUNTIME_ONLY` and :data:`SEPARATE_LIBRARIES`), the build recipe of
:mod:`.compiling`, the CasADi and cffi versions, the compiler command and, for a stack, its
structure. A library ``vgtarm_<key>.so`` is opened (:func:`_load`) only by absolute path, only
from a folder of the current user that nobody else can write (:func:`_check_folder`) and only after
its metadata ``vgtarm_<key>.json`` validated against the model being loaded (:func:`_parse_metadata`)
and its size and SHA-256 matched; whatever fails raises :class:`~.library_errors._Damaged`. The
trust rules are told in full in :mod:`vgtarm.model.compiled`.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import cffi

from ..errors import cut, shown
from . import codegen, compiling, outline
from .backends import _MAX_COUNT, CompiledBackend, Signature
from .definition import PAPER, Definition
from .library_errors import BackendError, _Damaged, _shown_path, _Unavailable

_PACKAGE_DIR = Path(__file__).resolve().parent
#: Suffixes of the model package's source files that the cache key hashes.
_SOURCE_SUFFIXES = (".py", ".c", ".h", ".toml")
#: Modules of the model package that never shape a compiled library: the runtime around it (the
#: Robot API, the loop bindings, the accepted joint range, the backends, this cache and its
#: builds). The key skips them, so editing one does not recompile every library (the six-module
#: arm's takes about 80 s); the build recipe of :mod:`.compiling` is hashed apart
#: (:func:`.compiling._recipe`). ``tests/test_architecture.py`` checks that no module the code
#: generation imports, directly or not, is in this set.
RUNTIME_ONLY = frozenset(
    {
        "__init__.py",
        "robot.py",
        "closedloop.py",
        "sanity.py",
        "compiled.py",
        "backends.py",
        "compiling.py",
        "library_cache.py",
        "library_errors.py",
        "build_lock.py",
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
#: Version of the metadata file's layout; another version is rebuilt.
METADATA_FORMAT = 1
#: Largest metadata file and library read (bytes): anything bigger is damaged, not read.
_MAX_METADATA_BYTES = 1 << 20
_MAX_LIBRARY_BYTES = 1 << 30
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,127}")


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


def _cache_key(compiler: str, definition: Definition = PAPER) -> str:
    """The key of the library of ``definition`` built by ``compiler`` (module docstring)."""
    digest = hashlib.sha256()
    for path in model_sources():
        digest.update(path.relative_to(_PACKAGE_DIR).as_posix().encode())
        digest.update(path.read_bytes())
    digest.update(compiling._recipe())
    digest.update(str(getattr(ca, "__version__", "unknown")).encode())
    digest.update(str(cffi.__version__).encode())
    digest.update(" ".join((compiler, *compiling._CFLAGS)).encode())
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
    compiler = compiler or compiling.find_compiler()
    if compiler is None:
        raise BackendError("no C compiler found (cc, gcc or clang on the PATH, or $CC)")
    return CacheEntry(cache_dir(), _cache_key(compiler))


def library_cached(definition: Definition = PAPER) -> bool:
    """Whether the cache holds a library and metadata for ``definition`` under the current key (not
    checked: only a load checks it)."""
    compiler = compiling.find_compiler()
    if compiler is None:
        return False
    try:
        entry = CacheEntry(cache_dir(), _cache_key(compiler, definition), definition)
    except RuntimeError:  # Path.home() without a home folder
        return False
    return os.path.lexists(entry.library) and os.path.lexists(entry.metadata)


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
