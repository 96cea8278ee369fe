"""The build process that :func:`vgtarm.model.building.run` starts: it builds one model (the
compiled library, or the symbolic functions for the interpreter) into the private folder it is
given and writes its result there (:data:`~vgtarm.model.building.RESULT`). It imports the modules
it builds with (:mod:`.compiling`, :mod:`.library_cache`); :mod:`.building`, which the cache's front
:mod:`.compiled` imports, does not import this one.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import pickle
import resource
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..memory import size_text
from . import compiling, library_cache
from .backends import build_functions
from .budget import compiler_limit, estimate
from .building import RESULT
from .definition import Definition


def _end_with(parent: int) -> None:
    """End this build (and its compiler) when the process that started it ends, however it ends.

    The kernel kills this process when its parent ends (``PR_SET_PDEATHSIG``); where it cannot, a
    watchdog kills this process's group. Either way its compiler goes too: it runs under the
    supervisor of :mod:`vgtarm.compiler`, which ends the compiler's whole group when this process
    ends (its own parent-death signal, and the end of its pipe from this process)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG: this process
    if os.getppid() != parent:  # the parent died before the line above
        os._exit(1)

    def watch() -> None:  # where the kernel has no parent-death signal
        while os.getppid() == parent:
            time.sleep(0.5)
        with contextlib.suppress(OSError):
            os.killpg(0, signal.SIGKILL)

    threading.Thread(target=watch, daemon=True).start()


def _file_limit(folder: Path, failure: str) -> str | None:
    """The reason to give when the file size limit (``ulimit -f``) stopped the build, else None."""
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft == resource.RLIM_INFINITY:
        return None
    stopped = sorted(p.name for p in folder.iterdir() if p.is_file() and p.stat().st_size >= soft)
    # EFBIG ("File too large") where the limit applies, or the compiler killed by SIGXFSZ ("File
    # size limit exceeded": Python's subprocess restores the signal's default for the compiler)
    told = any(text in failure.lower() for text in ("file too large", "file size limit exceeded"))
    if not (stopped or told):
        return None
    where = f"{stopped[0]} stopped at {soft:,} bytes" if stopped else "the compiler could not write its output"
    return (
        f"the file size limit (ulimit -f) of {soft:,} bytes ({size_text(soft)}) stopped the build: {where}; "
        "raise it (ulimit -f unlimited) and run the command again"
    )


def _compile(compiler: str, folder: Path, definition: Definition, key: str) -> dict[str, Any]:
    if library_cache._cache_key(compiler, definition) != key:
        return {"failure": "the model's source files changed while the library was being built; run the command again"}
    compiling._COMPILE_TIMEOUT = compiler_limit(estimate(definition))  # before $VGTARM_COMPILER_TIME_LIMIT
    library, signatures = compiling._compile(compiler, folder, definition)
    return {"library": library.name, "functions": {name: sig.__dict__ for name, sig in signatures.items()}}


def _functions(folder: Path, definition: Definition) -> dict[str, Any]:
    built = build_functions(definition)
    for name, f in built.items():
        f.save(str(folder / f"{name}.casadi"))
    return {"functions": sorted(built)}


def main(argv: Sequence[str]) -> int:
    """The build process: ``KIND COMPILER FOLDER KEY PARENT_PID``, the definition (pickled) on
    standard input; writes :data:`RESULT` into ``FOLDER`` (module docstring)."""
    kind, compiler, folder_text, key, parent = argv
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes beyond ulimit -f fail with EFBIG instead
    _end_with(int(parent))
    folder = Path(folder_text)
    definition = pickle.load(sys.stdin.buffer)
    try:
        result = _compile(compiler, folder, definition, key) if kind == "compile" else _functions(folder, definition)
    except Exception as exc:  # the reason, in one line, for the caller
        lines = str(exc).strip().splitlines()
        failure = lines[0] if lines else type(exc).__name__
        if type(exc).__name__ != "_Unavailable":
            failure = f"{type(exc).__name__}: {failure}"
        result = {"failure": _file_limit(folder, str(exc)) or failure}
    partial = folder / f".{RESULT}"
    try:
        partial.write_text(json.dumps(result))
        os.replace(partial, folder / RESULT)
    except OSError as exc:  # the caller reports a build that wrote no result
        print(f"cannot write the build's result: {exc.strerror or exc}", file=sys.stderr)
        return 1
    return 0
