"""Worker processes for ``vgtarm reproduce``: its independent runs and figures on the machine's cores.

:class:`Workers` starts ``count`` fresh interpreters (the ``spawn`` start method: nothing of this
process, its OpenMP threads or its compiled libraries' state, is copied), each with its own
:class:`~vgtarm.model.robot.Robot` built from the same parameters and with one GA thread
(``VGTARM_THREADS=1``: the processes fill the cores). A run depends only on its inputs and its
seed, and the compiled GA gives the same activation with any thread count, so a run made in a
worker is bit for bit the run made here. :class:`Inline` does the same calls one after the other
in this process (one worker, or a robot without the compiled backend).

Ctrl-C: the workers are started while this thread blocks SIGINT, so they begin life with it
blocked (a signal mask survives ``exec``) and ignore it from their first instruction on: the
terminal's Ctrl-C, sent to the whole process group, reaches only this process. A Ctrl-C during
the start is held for the few milliseconds it lasts and raised right after (never lost). Leaving
the ``with`` block by an exception (Ctrl-C or an error) kills the workers at once and waits until
they are gone, before any caller removes the files they were writing.

No orphans: a worker ends within a second of this process's death, whatever killed it
(``kill -9`` included). On Linux each worker asks the kernel for SIGKILL when its parent ends
(``prctl(PR_SET_PDEATHSIG)``: it fires when the *thread* that started the worker ends, so every
worker is started by the thread that entered the ``with`` block, which outlives the block, and
:meth:`Workers.submit` refuses other threads); everywhere, a watchdog thread in each worker reads
a pipe whose only writing end this process holds, and ends the worker when the pipe closes (the
kernel closes it when this process dies). multiprocessing's resource tracker, which the workers
share with this process, ends by itself once the last of them is gone (its pipe closes).
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from multiprocessing import resource_tracker
from multiprocessing.connection import Connection
from types import FrameType
from typing import Any, TypeVar

from .. import checks
from ..machine import usable_cpus
from ..model.parameters import RobotParameters
from ..model.robot import Robot, definition_of
from ..model.stack import Stack

T = TypeVar("T")
#: Most worker processes by default (the reproduction has four long runs and about 40 short tasks).
MAX_WORKERS = 4
#: Start method of the workers: a fresh interpreter (a fork would copy OpenMP's threads' state).
START_METHOD = "spawn"


def default_workers() -> int:
    """Worker processes for this machine: the CPUs this process may use, at most :data:`MAX_WORKERS`."""
    return min(usable_cpus(), MAX_WORKERS)


class Inline:
    """Runs each call at once, in this process, with ``robot``: the serial reproduction."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.count = 1

    def __enter__(self) -> Inline:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def submit(self, fn: Callable[..., T], /, *args: Any) -> Future[T]:
        """``fn(robot, *args)`` now, its result in a finished future (an exception goes straight up,
        as from a plain call)."""
        future: Future[T] = Future()
        future.set_result(fn(self.robot, *args))
        return future


class Workers:
    """``count`` worker processes, each calling ``fn(robot, *args)`` with its own robot of
    ``parameters`` (backend ``backend``); a context manager, used from the thread that entered it
    (see the module's notes on Ctrl-C and orphans)."""

    def __init__(self, count: int, parameters: RobotParameters | Stack, backend: str = "compiled") -> None:
        checks.whole("count", count, 1, unit="workers", error=ValueError)
        self.count, self.parameters, self.backend = count, parameters, backend
        self._executor: ProcessPoolExecutor | None = None
        self._thread: threading.Thread | None = None
        self._alive: tuple[Connection, Connection] | None = None

    def __enter__(self) -> Workers:
        context = multiprocessing.get_context(START_METHOD)
        # The pipe's reading end goes to every worker; its writing end stays here only (spawned
        # processes inherit no descriptor they are not given), so it closes when this process dies.
        self._alive = context.Pipe(duplex=False)
        self._thread = threading.current_thread()
        try:
            if os.name == "posix":  # started now, outside the window below: its start unblocks SIGINT here
                resource_tracker.ensure_running()
            with _sigint_held():
                self._executor = ProcessPoolExecutor(
                    self.count,
                    mp_context=context,
                    initializer=_start_worker,
                    initargs=(self.parameters, self.backend, os.getpid(), self._alive[0]),
                )
                # the pool starts a process per call while none is idle: start them all now, here
                for _ in range(self.count):
                    self._executor.submit(os.getpid)
        except BaseException:  # an error, or a Ctrl-C raised once the start is over
            self._stop(kill=True)
            raise
        return self

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        self._stop(kill=kind is not None)  # an error or Ctrl-C: what runs is lost anyway

    def submit(self, fn: Callable[..., T], /, *args: Any) -> Future[T]:
        """``fn(robot, *args)`` in a worker (``fn`` a module-level function, the arguments picklable)."""
        if self._executor is None:
            raise RuntimeError("Workers.submit outside the with block")
        if threading.current_thread() is not self._thread:  # a worker it started would die with that thread
            raise RuntimeError("Workers.submit from another thread than the one that entered the with block")
        return self._executor.submit(_call, fn, *args)

    def _stop(self, *, kill: bool) -> None:
        executor, self._executor = self._executor, None
        alive, self._alive = self._alive, None
        try:
            if executor is None:
                return
            if kill:  # at once: a worker busy in compiled code would finish its run first otherwise
                processes = list((getattr(executor, "_processes", None) or {}).values())
                for process in processes:
                    with contextlib.suppress(OSError, ValueError):  # already gone, or never started
                        process.kill()
                for process in processes:
                    with contextlib.suppress(ValueError):
                        process.join()
            executor.shutdown(wait=True, cancel_futures=True)
        finally:
            for end in alive or ():
                end.close()  # a worker still there (none should be) sees the pipe close and ends


@contextlib.contextmanager
def _sigint_held() -> Iterator[None]:
    """SIGINT blocked in this thread, so processes started here begin with it blocked; a Ctrl-C
    meanwhile is only noted, and raised as ``KeyboardInterrupt`` on leaving (never lost).

    The handler, not just the mask, is replaced: a signal sent to the whole process is delivered
    to any thread that does not block it, and Python would raise it here at once (in the middle of
    starting a process). Outside the main thread (no signal handling there) nothing is changed."""
    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        yield
        return
    noted: list[int] = []

    def note(signum: int, frame: FrameType | None) -> None:
        noted.append(signum)

    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    before = signal.signal(signal.SIGINT, note)
    handler = signal.default_int_handler if before is None else before  # None: set outside Python
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)  # a Ctrl-C pending here goes to the handler
    if noted and callable(handler):  # Python's own handler raises KeyboardInterrupt
        handler(signal.SIGINT, None)
    elif noted and handler == signal.SIG_DFL:
        signal.raise_signal(signal.SIGINT)


#: The robot of this worker process (set by :func:`_start_worker`).
_ROBOT: list[Robot] = []
#: ``prctl`` option: the signal a process receives when the thread that started it ends (Linux).
PR_SET_PDEATHSIG = 1
#: Exit status of a worker that ends because its parent is gone.
ORPHANED = 70


def _start_worker(parameters: RobotParameters | Stack, backend: str, parent: int, alive: Connection) -> None:
    """A worker's start: bound to its parent's life, Ctrl-C ignored, one GA thread, and its own
    robot (the paper's or a stack, of the backend kind ``backend``; a compiled library is loaded
    from the cache the calling process filled)."""
    from ..model.compiled import get_backend

    die_with_parent(parent, alive)
    if hasattr(signal, "pthread_sigmask"):
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # discards a Ctrl-C pending since the start
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    os.environ["VGTARM_THREADS"] = "1"
    _ROBOT.append(Robot(parameters, backend=get_backend(backend, definition_of(parameters))))


def die_with_parent(parent: int, alive: Connection | None = None, *, kernel_signal: bool = True) -> None:
    """End this process when its parent ``parent`` (its pid) ends, however it ends.

    Linux (unless ``kernel_signal`` is False): the kernel's parent-death signal (SIGKILL), then a
    check that the parent is still ``parent`` (it may have died before the request). Everywhere,
    with ``alive`` the reading end of a pipe only the parent writes to: a daemon thread waiting on
    it ends the process when the pipe closes (the parent's death closes it), where prctl is missing
    (the kernel's signal also ends a worker in a long call that holds the interpreter's lock, which
    the watchdog would have to wait for)."""
    if kernel_signal and sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):  # no libc to call: the watchdog remains
            libc = ctypes.CDLL(None, use_errno=True)
            prctl = libc.prctl
            prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
            prctl.restype = ctypes.c_int
            prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent:
        os._exit(ORPHANED)
    if alive is not None:
        threading.Thread(target=_watch_parent, args=(alive,), name="vgtarm parent watchdog", daemon=True).start()


def _watch_parent(alive: Connection) -> None:
    """Wait on the pipe from the parent; nothing is ever written, so any return means it closed."""
    try:
        alive.recv_bytes()
    except (EOFError, OSError):
        pass
    os._exit(ORPHANED)


def _call(fn: Callable[..., T], *args: Any) -> T:
    return fn(_ROBOT[0], *args)
