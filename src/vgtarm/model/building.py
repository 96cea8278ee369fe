"""Building a model in a process of its own, which Ctrl-C stops at once and which shows its progress.

CasADi's symbolic construction and code generation are long calls into C++ that do not return to
Python for seconds to hours, so a build run in vgtarm's own process could not be interrupted.
:func:`run` starts the build process (:mod:`.build_process`) instead, in a session of its own (a
terminal's Ctrl-C does not reach it), hands it the model definition on its standard input and
waits for it in short polls: on Ctrl-C (or any other exception) it kills the build's whole process
group and its compiler's and lets the caller remove the build folder, so the command ends
within a fraction of a second with nothing left behind. The build process also ends with its
parent: the kernel kills it when the parent dies (``PR_SET_PDEATHSIG``; a watchdog where there is
none), and its compiler, which runs in a process group of its own under :mod:`vgtarm.compiler`'s
supervisor, is killed with all its children when the build process ends, however it ends, or
when it runs past its time limit (``$VGTARM_COMPILER_TIME_LIMIT``).

Two kinds of build:

- ``compile``: :func:`vgtarm.model.compiling._compile` into the private build folder the caller
  made; the result names the library and gives the functions' signatures; the caller keeps every
  check of the compile cache (metadata, SHA-256, lock, atomic moves);
- ``functions``: the symbolic functions alone, saved into the folder for CasADi's interpreter.

The build process ignores ``SIGXFSZ``, so a write beyond the file size limit (``ulimit -f``) fails
with ``EFBIG`` instead of killing it, and a build stopped by that limit is reported as such, with
the limit, and not as a compiler error. On a terminal, a build estimated longer than
:data:`vgtarm.model.budget.LONG_BUILD` prints a line per phase with the time elapsed, and one every
:data:`HEARTBEAT` seconds within a long phase, on standard error; never after ``-q``
(:func:`vgtarm.progress.quiet`).
"""

from __future__ import annotations

import contextlib
import json
import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from ..errors import cut
from ..memory import size_text
from ..progress import quiet
from .budget import LONG_BUILD, BuildEstimate, time_text
from .definition import Definition

#: What the build process writes last into its folder: the result, or the reason it failed.
RESULT = "result.json"
#: Seconds between two polls of the build process (the longest Ctrl-C can wait).
POLL = 0.05
#: Seconds between two progress lines within one long phase.
HEARTBEAT = 30.0
#: Largest result file read (bytes).
_MAX_RESULT = 1 << 22
#: The package folder the build process imports vgtarm from: the one this process runs.
_PACKAGE_ROOT = Path(__file__).resolve().parents[2]


class BuildFailed(Exception):
    """The build process failed or reported a failure; the message is the one-line reason."""


# ----------------------------------------------------------------------------- the caller's side


def _phase(kind: str, folder: Path) -> str:
    """What a build is doing, from the files it has written so far."""
    if kind == "functions" or not (folder / "vgtarm_model.c").exists():
        return "building the symbolic model"
    if not (folder / "layout.c").exists():
        return "writing the C code"
    if (folder / "vgtarm_model.o").exists():
        return "linking the library"
    return "compiling the C code"


class _Progress:
    """Progress lines on standard error (a terminal only): one per phase, with the time elapsed."""

    def __init__(self, show: bool, kind: str, cost: BuildEstimate) -> None:
        self.show, self.kind = show, kind
        self.start = self.last = time.monotonic()
        self.phase = ""
        what = "compiled model" if kind == "compile" else "symbolic model"
        mode = "compiled" if kind == "compile" else "interpreted"
        self._line(
            f"building the {what} of {cost.model}: about {time_text(cost.seconds(mode))} and "
            f"{size_text(cost.bytes(mode))} of memory (estimated); Ctrl-C stops it"
        )

    def _line(self, text: str) -> None:
        if self.show:
            with contextlib.suppress(OSError, ValueError):
                print(f"vgtarm: {text}", file=sys.stderr, flush=True)

    def update(self, folder: Path) -> None:
        now = time.monotonic()
        phase = _phase(self.kind, folder)
        if phase != self.phase:
            self.phase, self.last = phase, now
            self._line(f"{time_text(now - self.start)}: {phase}")
        elif now - self.last >= HEARTBEAT:
            self.last = now
            self._line(f"{time_text(now - self.start)}: still {phase}")

    def done(self) -> None:
        self._line(f"{time_text(time.monotonic() - self.start)}: built")


def _terminal() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def _compiler_groups(pid: int) -> set[int]:
    """The process groups below the build process ``pid`` other than its own: its compiler's, in a
    session of its own under :mod:`vgtarm.compiler`'s supervisor."""
    import psutil  # imported here: only an interrupted build needs it

    groups: set[int] = set()
    with contextlib.suppress(psutil.Error, OSError):
        for child in psutil.Process(pid).children(recursive=True):
            with contextlib.suppress(psutil.Error, OSError):
                groups.add(os.getpgid(child.pid))
    groups.discard(pid)
    return groups


def _kill(process: subprocess.Popen[bytes]) -> None:
    """Kill the build's process group and its compiler's, and reap the build.

    The compiler's group is killed here at once, while its members run (so that none writes into
    the build folder as the caller removes it); should one start meanwhile, its supervisor ends it
    when the build process ends (:mod:`vgtarm.compiler`)."""
    for group in _compiler_groups(process.pid):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(group, signal.SIGKILL)
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        process.wait(timeout=2.0)


def _ending(status: int) -> str:
    if status < 0:
        try:
            name = signal.Signals(-status).name
        except ValueError:
            name = f"signal {-status}"
        hint = " (out of memory?)" if -status == signal.SIGKILL else ""
        return f"was killed by {name}{hint}"
    return f"ended with status {status}"


def run(
    kind: str, compiler: str, folder: Path, definition: Definition, key: str, cost: BuildEstimate
) -> dict[str, Any]:
    """Build ``definition`` in a process of its own, into the private ``folder``; its result.

    ``kind`` is ``compile`` (the library, for the cache entry ``key``) or ``functions`` (the
    symbolic functions saved for the interpreter). Raises :class:`BuildFailed` with a one-line
    reason. A ``KeyboardInterrupt`` (or any other exception) while it runs kills the build process
    and its compiler before it propagates; the caller removes ``folder``.
    """
    if not sys.executable:
        raise BuildFailed("no Python interpreter to build the model with (sys.executable is empty)")
    code = (
        f"import sys; sys.path.insert(0, {str(_PACKAGE_ROOT)!r}); "
        "from vgtarm.model.build_process import main; sys.exit(main(sys.argv[1:]))"
    )
    # the same interpreter and environment (where CasADi and NumPy are found); the package this
    # process runs comes first, and the current folder of ``-c`` is the private build folder
    command = [sys.executable, "-c", code, kind, compiler, str(folder), key, str(os.getpid())]
    payload = pickle.dumps(definition, protocol=pickle.HIGHEST_PROTOCOL)
    long = cost.seconds("compiled" if kind == "compile" else "interpreted") > LONG_BUILD
    progress = _Progress(long and _terminal() and not quiet(), kind, cost)  # quiet: the command's -q
    try:
        process = subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            cwd=folder,
            start_new_session=True,
        )
    except OSError as exc:
        raise BuildFailed(f"cannot start the build process: {exc.strerror or exc}") from None
    errors = b""
    try:
        first = True
        while True:
            try:
                _, errors = process.communicate(payload if first else None, timeout=POLL)
                break
            except subprocess.TimeoutExpired:
                first = False
                progress.update(folder)
    except BaseException:
        _kill(process)
        raise
    result = _result(folder)
    if result is None:
        lines = [line for line in errors.decode(errors="replace").splitlines() if line.strip()]
        last = f": {cut(lines[-1].strip(), 160)}" if lines else ""
        raise BuildFailed(f"the build process {_ending(process.returncode)}{last}")
    if "failure" in result:
        raise BuildFailed(cut(str(result["failure"]), 300))
    progress.done()
    return result


def _result(folder: Path) -> dict[str, Any] | None:
    """The build process's result in ``folder``, or None when it wrote none (it crashed)."""
    try:
        with open(folder / RESULT, "rb") as stream:
            raw = stream.read(_MAX_RESULT + 1)
        payload = json.loads(raw) if len(raw) <= _MAX_RESULT else None
    except (OSError, ValueError):
        return None
    return payload if isinstance(payload, dict) else None
