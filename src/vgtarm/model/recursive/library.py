"""The recursive model's one compiled library: generated once per module recipe, cached, loaded.

The library holds the generated module functions (:mod:`.joint`) and the hand-written loops over
the bodies (``csrc/vgt_rec.c``). Nothing in it depends on an arm: the arm is data
(:class:`~.model.RecursiveModel` passes it as arrays), so the first arm ever builds it (about two
seconds) and every later arm, of any size and any module types, loads it at once.

The cache is the model's (:func:`vgtarm.model.compiled.cache_dir`, with its trust rules): beside
``vgtarm_rec_<key>.so`` lies ``vgtarm_rec_<key>.json`` with the key and the library's size and
SHA-256, compared before the library is opened by its absolute path; anything that fails a check
is rebuilt once. The key hashes what shapes the library (the module recipe, the symbolic definition it is
generated from, this build recipe, the C loops), the compile flags, the CasADi and cffi versions
and the compiler command.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import shutil
import tempfile
import threading
from functools import cache
from pathlib import Path
from typing import Any

import casadi as ca
import cffi

from .. import build_lock, compiling, interface, library_cache
from ..library_errors import BackendError, _Damaged, _Unavailable
from .joint import module_functions

_HERE = Path(__file__).resolve().parent
_CSRC = _HERE / "csrc"
#: The compiled closed loop's drivers (``vgtarm.h``: the loop, the GA, batches), linked in too.
_DRIVERS = _HERE.parent / "csrc"
_HEADER = _CSRC / "vgt_rec.h"
_CFLAGS = ("-O3", "-fPIC", "-shared", "-ffp-contract=off")
_GENERATED = "vgt_rec_generated"
_LOCK = threading.Lock()


def _sources() -> list[Path]:
    """What shapes the library: the module recipe, the model's symbolic definition it is generated
    from (``solve_module``...), this build recipe and the C loops (not the Python around them)."""
    recipe = [_HERE / "joint.py", _HERE.parent / "symbolic.py", _HERE / "library.py", _HERE.parent / "interface.py"]
    drivers = sorted(p for p in _DRIVERS.iterdir() if p.suffix in (".c", ".h"))
    return recipe + sorted(p for p in _CSRC.iterdir() if p.suffix in (".c", ".h")) + drivers


def cache_key(compiler: str) -> str:
    """The key of the library for ``compiler``: the sources that shape it (:func:`_sources`), the
    flags, the CasADi and cffi versions and the compiler command."""
    digest = hashlib.sha256()
    for path in _sources():
        digest.update(path.name.encode())  # the names are distinct
        digest.update(path.read_bytes())
    digest.update(repr(_CFLAGS).encode())
    digest.update(str(getattr(ca, "__version__", "unknown")).encode())
    digest.update(str(cffi.__version__).encode())
    digest.update(compiler.encode())
    return digest.hexdigest()[:20]


def _ffi() -> cffi.FFI:
    ffi = cffi.FFI()
    ffi.cdef(_HEADER.read_text())
    return ffi


#: The macro naming the function that sums the margin rows of the drivers' assembly check
#: (``check_state`` in ``closed_loop.c``): here ``vgt_rec_margin`` (``csrc/vgt_rec_loop.c``), over
#: the nonzero entries of the rows a run bound (``vgt_rec_bind_run``), else over every entry. The
#: symbolic libraries compile ``closed_loop.c`` without it: the dense loop, as written there. Each
#: margin's sign is the same either way (a zero entry adds a zero product, and the check comes after
#: the state is found finite).
_MARGIN_ROW = "-DVGT_MARGIN_ROW=vgt_rec_margin"


#: What the bodies of the generated module functions may call, and the lane versions
#: (``csrc/vgt_rec_lanes.h``) that replace the calls in :func:`module_lanes`.
_LANE_CALLS = {"casadi_sq": "lane_sq", "sin": "lane_sin", "cos": "lane_cos", "acos": "lane_acos", "atan2": "lane_atan2"}
_LANE_CALLS |= {"sqrt": "lane_sqrt"}
_LANE_STATEMENT = re.compile(r"a\d+=[^;]*;|if \(res\[\d\]!=0\) res\[\d\]\[\d+\]=a\d+;|return 0;|casadi_real [a\d, ]+;")


def module_lanes(source: str) -> str:
    """The generated module functions ``vgt_rec_module`` (joint pose, motion subspace and bias) and
    ``vgt_rec_module_kin`` (pose, motion subspace and passive angles) as ``lane_module`` and
    ``lane_module_kin``, on vectors of doubles (``vd``, one sample per lane) with the very operations
    of the generated C in the same order: the header ``vgt_rec_module_lanes.h`` that
    ``csrc/vgt_rec_lanes.h`` includes. Empty (so that the lanes call the generated functions sample
    by sample) when the generated code holds anything else than assignments of constants, inputs,
    arithmetic and the calls of :data:`_LANE_CALLS`, and outputs."""
    head = "/* vgt_rec_module and vgt_rec_module_kin on vectors (vgtarm.model.recursive.library.module_lanes) */\n"
    parts = [head + "#define VGT_REC_MODULE_LANES 1\n"]
    for function, lane in (("vgt_rec_module", "lane_module"), ("vgt_rec_module_kin", "lane_module_kin")):
        body = _lane_body(source, function)
        if not body:
            return ""
        parts.append(f"LANE_INLINE void {lane}(const vd *const *arg, vd *const *res) {{\n{body}\n}}\n")
    return "\n".join(parts)


def _lane_body(source: str, function: str) -> str:
    """The statements of the generated ``function`` on vectors (:func:`module_lanes`), or ``""``."""
    name = re.search(rf"int {function}\(const casadi_real\*\* arg.*?\{{\s*return (casadi_f\d+)\(", source, re.S)
    body = name and re.search(
        rf"static int {name.group(1)}\(const casadi_real\*\* arg[^{{]*\{{\n(.*?)\n\}}\n", source, re.S
    )
    if not body:
        return ""
    lines = [line.strip() for line in body.group(1).splitlines()]
    if not all(_LANE_STATEMENT.fullmatch(line) for line in lines):
        return ""
    text = "\n".join("    " + line for line in lines if line != "return 0;")
    text = re.sub(r"arg\[(\d)\]\? arg\[\1\]\[(\d+)\] : 0", r"arg[\1][\2]", text)
    text = re.sub(r"=(-?[0-9.]+(?:e[-+]?\d+)?);", r"=LANE_SPLAT(\1);", text)
    calls = set(re.findall(r"\b([A-Za-z_]\w*)\(", text)) - {"LANE_SPLAT"}
    if not calls <= set(_LANE_CALLS) or "?" in text:
        return ""
    text = re.sub(r"\b(\w+)\(", lambda m: _LANE_CALLS.get(m.group(1), m.group(1)) + "(", text)
    text = text.replace("casadi_real ", "vd ")
    known = {"arg", "res", "if", "vd", "LANE_SPLAT", *_LANE_CALLS.values()}
    words = re.findall(r"\d[\d.]*(?:e[-+]?\d+)?|[A-Za-z_]\w*", text)  # numbers, then names
    if any(w not in known and not re.fullmatch(r"a\d+|\d.*", w) for w in words):
        return ""  # a name of the generated code's own (a constant such as casadi_inf)
    return text


def _compile(compiler: str, workdir: Path) -> Path:
    generator = ca.CodeGenerator(f"{_GENERATED}.c", {"with_header": True})
    for f in module_functions():
        generator.add(f)
    generator.generate(str(workdir) + os.sep)
    lanes = module_lanes((workdir / f"{_GENERATED}.c").read_text())
    (workdir / "vgt_rec_module_lanes.h").write_text(lanes)
    (workdir / "layout.c").write_text(interface.layout_source())
    library = workdir / "library.so"
    command = [compiler, *_CFLAGS, _MARGIN_ROW, "-I", str(_CSRC), "-I", str(_DRIVERS), "-I", str(workdir)]
    command += ["-o", str(library), str(workdir / f"{_GENERATED}.c"), str(_CSRC / "vgt_rec.c")]
    command += [str(_CSRC / "vgt_rec_loop.c"), str(workdir / "layout.c")]
    command += [*(str(p) for p in sorted(_DRIVERS.glob("*.c"))), "-lm"]
    failure = ""
    for attempt in (command[:1] + ["-fopenmp"] + command[1:], command):  # the GA's threads, when OpenMP is there
        done = compiling._run(compiler, attempt)
        if done.returncode == 0 and library.is_file():
            return library
        failure = compiling._compiler_failure(compiler, done)
    raise _Unavailable(failure)


def _metadata_ok(meta: Path, library: Path, key: str) -> bool:
    try:
        data = json.loads(library_cache._read_private(meta, 1 << 16))
        size, digest = library_cache._sha256(library)
    except (_Damaged, OSError, ValueError):
        return False
    return bool(data.get("key") == key and data.get("size") == size and data.get("sha256") == digest)


def _build(folder: Path, key: str, compiler: str) -> None:
    library, meta = folder / f"vgtarm_rec_{key}.so", folder / f"vgtarm_rec_{key}.json"
    workdir = Path(tempfile.mkdtemp(dir=folder, prefix=f".build-{os.getpid()}-"))
    try:
        built = _compile(compiler, workdir)
        size, digest = library_cache._sha256(built)
        text = json.dumps({"key": key, "model": "recursive", "size": size, "sha256": digest}, indent=1)
        (workdir / "meta.json").write_text(text)
        os.replace(built, library)
        os.replace(workdir / "meta.json", meta)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


@cache
def load_library() -> tuple[Any, Any]:
    """``(ffi, lib)`` of the recursive model's library, built into the cache on first use.

    Raises :class:`~vgtarm.model.compiled.BackendError` with one line when it cannot be had (no
    compiler, a refused cache folder, a failing compile)."""
    with _LOCK:
        compiler = compiling.find_compiler()
        if compiler is None:
            raise BackendError("the recursive model needs a C compiler (cc, gcc or clang, or $CC)")
        folder = library_cache.cache_dir()
        try:
            library_cache._check_folder(folder)
            key = cache_key(compiler)
            library, meta = folder / f"vgtarm_rec_{key}.so", folder / f"vgtarm_rec_{key}.json"
            if not _metadata_ok(meta, library, key):
                with build_lock._build_lock(folder):
                    if not _metadata_ok(meta, library, key):
                        for path in (meta, library):
                            with contextlib.suppress(FileNotFoundError):
                                path.unlink()
                        _build(folder, key, compiler)
                if not _metadata_ok(meta, library, key):
                    raise _Unavailable("the recursive model's library failed its checks after a rebuild")
        except _Unavailable as exc:
            raise BackendError(f"cannot build the recursive model: {exc}") from None
        ffi = _ffi()
        _PATH.append(library.resolve())
        return ffi, ffi.dlopen(str(library.resolve()))


_PATH: list[Path] = []


@cache
def loop_library() -> Any:
    """The same library opened with the compiled loop's interface (``vgtarm.h``): its drivers
    (``vgt_simulate_slice``, the GA) run on the recursive model through the adapters of
    ``csrc/vgt_rec_loop.c``. Refused with one line when its structure layout is not cffi's."""
    load_library()
    library = interface.open_library(_PATH[-1])
    out = interface.ffi().new("long[]", len(interface.layout_fields()))
    library.vgt_layout(out)
    if list(out) != interface.python_layout():
        raise BackendError("the recursive model's loop library lays out the interface's structures unlike cffi")
    return library
