"""The model's functions evaluated over a batch: through the compiled shared library, or by CasADi's
interpreter when there is none.

Both backends take the same inputs (one row per sample, or one value for every sample) and give
the same outputs; :func:`vgtarm.model.compiled.get_backend` chooses one. Where the library comes
from (built, cached, checked) is :mod:`.compiled`'s, :mod:`.compiling`'s and :mod:`.library_cache`'s.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Protocol

import casadi as ca
import cffi
import numpy as np
from cffi import FFI
from numpy.typing import NDArray

from ..machine import split_rows
from . import codegen, interface
from .definition import PAPER, Definition

#: Prefix of the C names of the generated code (CasADi's ``<prefix>_casadi_int_size``).
_GENERATED_NAME = "vgtarm_model"
#: Samples of one compiled batch call: at most a few tens of milliseconds (the costliest function
#: takes about 4 us a sample), so Ctrl-C is handled between two calls of a huge batch. Below the
#: 4,096 samples from which ``vgt_batch`` (``csrc/batch.c``) starts OpenMP threads of its own: a
#: batch's threads are :func:`vgtarm.machine.split_rows`'s, sized by the machine, taking chunks
#: one at a time and waiting without spinning.
BATCH_CHUNK = 4095
#: Samples of one call into CasADi's interpreter (about 50 ms at the costliest 90 us a sample).
INTERPRETED_CHUNK = 512
#: Largest size or count a sparsity pattern or a metadata field may hold (far above any real
#: function's hundreds).
_MAX_COUNT = 1 << 20


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


def single_call(
    backend: Backend, name: str, inputs: Sequence[NDArray[np.float64]], outputs: NDArray[np.float64]
) -> Callable[[], int]:
    """One sample of function ``name``, called again and again on the same buffers: the function's inputs
    are ``inputs`` (1-D float64 arrays of its input sizes, the parameters last), its outputs are written
    one after the other into ``outputs`` (1-D float64, the sum of the output sizes). The call returns 0
    when done (a generated function's own status otherwise) and gives, bit for bit, what
    ``backend.evaluate(name, [row of each input], 1)`` gives.

    The compiled backend calls the generated function directly through cffi, with pointers to the
    buffers and work arrays taken once (no batch driver, no allocation), as ``vgt_batch`` does for
    each sample; every other backend goes through its ``evaluate``. The buffers must keep their
    addresses (the call holds them), and one call runs at a time on a given set (the work arrays are
    its own): a caller on several threads keeps one set per thread.
    """
    sig = _single_signature(backend, name, inputs, outputs)
    if not isinstance(backend, CompiledBackend):
        rows = [x.reshape(1, -1) for x in inputs]

        def evaluated() -> int:
            np.concatenate([y.reshape(-1) for y in backend.evaluate(name, rows, 1)], out=outputs)
            return 0

        return evaluated
    arg, res, iw, w = _work_arrays(backend, sig, inputs, outputs)
    call = partial(backend.function_pointer(name), arg, res, iw, w, 0)
    call.buffers = [*inputs, outputs]  # type: ignore[attr-defined]  # the memory the pointers point into stays alive
    return call


def checked_single_call(
    backend: Backend,
    name: str,
    inputs: Sequence[NDArray[np.float64]],
    outputs: NDArray[np.float64],
    bounded: NDArray[np.float64],
    margins: NDArray[np.float64],
) -> Callable[[], int] | None:
    """:func:`single_call` with the checks of :class:`~vgtarm.model.robot.Robot`'s batch path, in C
    (``vgt_single_call``, ``csrc/single.c``), or None for a backend without it (not compiled).

    ``bounded`` ``(3 k,)`` is ``[low, x, high]``: the state ``x`` ``(k,)``, a 1 and then the inputs
    but the parameters one after the other (``inputs`` but the last are views of it, in order), between
    its inclusive bounds; ``margins`` ``(rows, 1 + n)`` the trusted triangle margins, whose products
    with ``x[: 1 + n]`` (``[1, q]``) must be >= 0. The call returns 0 when every input is finite and
    inside its bounds, every margin >= 0, the function succeeded and every output is finite (then
    ``outputs`` holds its result, bit for bit :func:`single_call`'s), else the nonzero
    ``vgt_single_status`` of the first check that failed. The same rules on buffers and threads."""
    sig = _single_signature(backend, name, inputs, outputs)
    if not isinstance(backend, CompiledBackend) or not hasattr(backend.library, "vgt_single_call"):
        return None
    k = len(bounded) // 3
    x = bounded[k : 2 * k]
    margins = np.ascontiguousarray(margins, dtype=np.float64)
    starts = np.cumsum((1, *sig.nnz_in[:-1])).tolist()
    if (
        bounded.dtype != np.float64
        or bounded.shape != (3 * k,)
        or not bounded.flags.c_contiguous
        or starts[-1] != k
        or margins.ndim != 2
        or margins.shape[1] != 1 + sig.nnz_in[0]
        or any(a.ctypes.data != x.ctypes.data + 8 * start for a, start in zip(inputs[:-1], starts[:-1], strict=True))
    ):
        raise ValueError(f"{sig.name}: checked_single_call expects the inputs as views of [low, (1, inputs), high]")
    ffi = backend.ffi
    arg, res, iw, w = _work_arrays(backend, sig, inputs, outputs)

    def pointer(a: NDArray[np.float64], offset: int = 0) -> Any:
        return ffi.cast("double *", a.ctypes.data) + offset

    state = ffi.new(
        "vgt_single *",
        {
            "f": backend.function_pointer(name),
            "arg": arg,
            "res": res,
            "iw": iw,
            "w": w,
            "n_x": k,
            "x": pointer(bounded, k),
            "low": pointer(bounded),
            "high": pointer(bounded, 2 * k),
            "n_margins": len(margins),
            "n_columns": margins.shape[1],
            "margins": pointer(margins),
            "n_y": len(outputs),
            "y": pointer(outputs),
        },
    )
    call = partial(backend.library.vgt_single_call, state)
    call.buffers = [*inputs, outputs, bounded, margins, arg, res, iw, w]  # type: ignore[attr-defined]
    return call


def _single_signature(
    backend: Backend, name: str, inputs: Sequence[NDArray[np.float64]], outputs: NDArray[np.float64]
) -> Signature:
    """The signature of ``name``, after checking the buffers of :func:`single_call`."""
    sig = backend.signature(name)
    arrays = [*inputs, outputs]
    sizes = (*sig.nnz_in, sum(sig.nnz_out))
    if len(inputs) != len(sig.nnz_in) or any(
        x.dtype != np.float64 or x.shape != (size,) or not x.flags.c_contiguous
        for x, size in zip(arrays, sizes, strict=True)
    ):
        raise ValueError(f"{sig.name}: single_call expects 1-D float64 buffers of sizes {sizes}")
    return sig


def _work_arrays(
    backend: CompiledBackend, sig: Signature, inputs: Sequence[NDArray[np.float64]], outputs: NDArray[np.float64]
) -> tuple[Any, Any, Any, Any]:
    """The argument and result pointers of one sample (into ``inputs`` and ``outputs``, the outputs one
    after the other) and the work arrays of ``sig``'s function, as ``vgt_batch`` sets them."""
    ffi = backend.ffi
    arg = ffi.new("const double *[]", max(sig.sz_arg, len(inputs), 1))
    res = ffi.new("double *[]", max(sig.sz_res, len(sig.nnz_out), 1))
    for i, x in enumerate(inputs):
        arg[i] = ffi.cast("double *", x.ctypes.data)
    start = ffi.cast("double *", outputs.ctypes.data)
    for j, offset in enumerate(np.cumsum((0, *sig.nnz_out[:-1])).tolist()):
        res[j] = start + offset
    return arg, res, ffi.new("vgt_int[]", max(sig.sz_iw, 1)), ffi.new("double[]", max(sig.sz_w, 1))


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
