"""Evaluation of the model's CasADi functions through compiled code.

On first use the functions of :mod:`vgtarm.model.codegen` are generated as C by CasADi, compiled
together with the drivers of ``csrc/`` (batch evaluation, the closed loop; their interface is the
one header ``csrc/vgtarm.h``, read by :mod:`.interface`) into one shared library, and cached on
disk. The cache key hashes every source file of the ``vgtarm.model`` package (so no list is kept
by hand), the CasADi and cffi versions and the compiler command; the robot's parameters are a runtime input
of every function, so changing the robot never recompiles. When no C compiler is present the
same functions run in CasADi's interpreter, after a one-line warning.

Cache folder: ``$VGTARM_CACHE_DIR``, else ``$XDG_CACHE_HOME/vgtarm``, else ``~/.cache/vgtarm``.
Backend choice: ``$VGTARM_BACKEND`` = ``auto`` (default), ``compiled`` or ``interpreted``.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import casadi as ca
import cffi
import numpy as np
from cffi import FFI
from numpy.typing import NDArray

from ..fileio import atomic_write_text
from . import codegen, interface

logger = logging.getLogger("vgtarm")

_PACKAGE_DIR = Path(__file__).resolve().parent
#: Suffixes of the model package's source files that the cache key hashes.
_SOURCE_SUFFIXES = (".py", ".c", ".h", ".toml")
_CSRC = _PACKAGE_DIR / "csrc"
_CFLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off")
_GENERATED_NAME = "vgtarm_model"


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


class CompiledBackend:
    """Functions evaluated through the compiled shared library."""

    kind = "compiled"

    def __init__(self, library_path: Path, signatures: dict[str, Signature]) -> None:
        self.library_path = library_path
        self.ffi = interface.ffi()
        self.library = interface.open_library(library_path)
        self._signatures = signatures
        # the generated functions share one C type; declare them by name to find their addresses
        generated = FFI()
        generated.include(self.ffi)
        generated.cdef(
            "".join(
                f"int {sig.name}(const double **, double **, vgt_int *, double *, int);\n"
                for sig in signatures.values()
            )
        )
        symbols = generated.dlopen(str(library_path))
        self._pointers = {key: self.ffi.cast("vgt_fn", getattr(symbols, sig.name)) for key, sig in signatures.items()}
        self._keep = (generated, symbols)

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
        status = self.library.vgt_batch(
            self._pointers[name],
            sig.sz_arg,
            sig.sz_res,
            sig.sz_iw,
            sig.sz_w,
            len(arrays),
            len(outputs),
            n,
            in_ptrs,
            in_strides,
            out_ptrs,
            list(sig.nnz_out),
        )
        if status != 0:
            raise RuntimeError(f"compiled function {sig.name} failed (status {status})")
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
        key = (name, n)
        if key not in self._maps:
            if len(self._maps) > 64:
                self._maps.clear()
            self._maps[key] = self.functions[name].map(n, "serial")
        args = [ca.DM(x.T) if x.ndim == 2 else ca.DM(x) for x in arrays]
        raw = self._maps[key](*args)
        results = list(raw) if isinstance(raw, tuple | list) else [raw]
        return [
            np.array(r, dtype=np.float64).reshape(nnz, n).T.copy() for r, nnz in zip(results, sig.nnz_out, strict=True)
        ]


def build_functions() -> dict[str, ca.Function]:
    """Build every CasADi function of the model (a second or so)."""
    return {key: builder() for key, builder in codegen.all_builders().items()}


def cache_dir() -> Path:
    """Folder of the compiled libraries."""
    if "VGTARM_CACHE_DIR" in os.environ:
        return Path(os.environ["VGTARM_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "vgtarm"


def find_compiler() -> str | None:
    """The C compiler to use: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in candidates:
        found = shutil.which(name)
        if found:
            return found
    return None


def model_sources() -> list[Path]:
    """Every source file of the ``vgtarm.model`` package, in a fixed order."""
    return sorted(
        path
        for path in _PACKAGE_DIR.rglob("*")
        if path.is_file() and path.suffix in _SOURCE_SUFFIXES and "__pycache__" not in path.parts
    )


def _cache_key(compiler: str) -> str:
    digest = hashlib.sha256()
    for path in model_sources():
        digest.update(path.relative_to(_PACKAGE_DIR).as_posix().encode())
        digest.update(path.read_bytes())
    digest.update(str(getattr(ca, "__version__", "unknown")).encode())
    digest.update(str(cffi.__version__).encode())
    digest.update(" ".join((compiler, *_CFLAGS)).encode())
    return digest.hexdigest()[:20]


def _compile(built: dict[str, ca.Function], compiler: str, target: Path) -> None:
    """Generate C for ``built``, compile it with the drivers into ``target`` (atomically)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent, prefix=".build-") as tmp:
        workdir = Path(tmp)
        generator = ca.CodeGenerator(f"{_GENERATED_NAME}.c", {"with_header": False})
        for f in built.values():
            generator.add(f)
        generator.generate(str(workdir) + os.sep)
        (workdir / "layout.c").write_text(interface.layout_source())
        sources = [str(workdir / f"{_GENERATED_NAME}.c"), str(workdir / "layout.c")]
        sources += [str(path) for path in sorted(_CSRC.glob("*.c"))]
        library = workdir / target.name
        base = [compiler, *_CFLAGS, "-I", str(_CSRC), "-o", str(library), *sources, "-lm"]
        attempts = [base[:1] + ["-fopenmp"] + base[1:], base]
        errors = ""
        for command in attempts:
            done = subprocess.run(command, capture_output=True, text=True, check=False)
            if done.returncode == 0:
                os.replace(library, target)
                return
            errors = done.stderr
        raise RuntimeError(f"compiling the model failed: {errors.strip()[:2000]}")


def _save_signatures(path: Path, signatures: dict[str, Signature]) -> None:
    payload = {key: sig.__dict__ for key, sig in signatures.items()}
    atomic_write_text(path, json.dumps(payload, indent=1))


def _load_signatures(path: Path) -> dict[str, Signature]:
    payload: dict[str, dict[str, Any]] = json.loads(path.read_text())
    return {
        key: Signature(
            name=v["name"],
            nnz_in=tuple(v["nnz_in"]),
            nnz_out=tuple(v["nnz_out"]),
            sz_arg=v["sz_arg"],
            sz_res=v["sz_res"],
            sz_iw=v["sz_iw"],
            sz_w=v["sz_w"],
            in_names=tuple(v.get("in_names", ())),
            out_names=tuple(v.get("out_names", ())),
        )
        for key, v in payload.items()
    }


def _compiled_backend(compiler: str) -> CompiledBackend:
    key = _cache_key(compiler)
    folder = cache_dir()
    library = folder / f"vgtarm_{key}.so"
    meta = folder / f"vgtarm_{key}.json"
    if library.exists() and meta.exists():
        signatures = _load_signatures(meta)
        if set(signatures) == set(codegen.all_builders()):
            return CompiledBackend(library, signatures)
    built = build_functions()
    logger.info("compiling the vgtarm model into %s (once per model version)", library)
    _compile(built, compiler, library)
    signatures = {k: Signature.of(f) for k, f in built.items()}
    _save_signatures(meta, signatures)
    return CompiledBackend(library, signatures)


@functools.cache
def get_backend(kind: str | None = None) -> CompiledBackend | InterpretedBackend:
    """The process-wide backend: compiled when a C compiler is present, else interpreted.

    ``kind`` overrides ``$VGTARM_BACKEND`` (``auto``, ``compiled`` or ``interpreted``).
    """
    choice = (kind or os.environ.get("VGTARM_BACKEND", "auto")).lower()
    if choice not in ("auto", "compiled", "interpreted"):
        raise ValueError(f"VGTARM_BACKEND = {choice!r}: expected 'auto', 'compiled' or 'interpreted'")
    if choice == "interpreted":
        return InterpretedBackend(build_functions())
    compiler = find_compiler()
    if compiler is None:
        if choice == "compiled":
            raise RuntimeError("VGTARM_BACKEND = 'compiled' but no C compiler (cc, gcc, clang) was found")
        logger.warning("vgtarm: no C compiler found; using CasADi's interpreter (slower)")
        return InterpretedBackend(build_functions())
    return _compiled_backend(compiler)
