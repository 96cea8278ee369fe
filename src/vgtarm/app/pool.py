"""Worker processes for ``vgtarm reproduce``: its independent runs and figures on the machine's cores.

:class:`Workers` starts ``count`` fresh interpreters (the ``spawn`` start method: nothing of this
process, its OpenMP threads or its compiled libraries' state, is copied), each with its own
:class:`~vgtarm.model.robot.Robot` built from the same parameters and with one GA thread
(``VGTARM_THREADS=1``: the processes fill the cores). A run depends only on its inputs and its
seed, and the compiled GA gives the same activation with any thread count, so a run made in a
worker is bit for bit the run made here. :class:`Inline` does the same calls one after the other
in this process (one worker, or a robot without the compiled backend).

Ctrl-C: the workers start with SIGINT ignored, so the terminal's Ctrl-C, sent to the whole
process group, reaches only this process; leaving the ``with`` block by an exception (Ctrl-C or
an error) kills them at once and waits until they are gone, before any caller removes the files
they were writing.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any, TypeVar

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
    ``parameters`` (backend ``backend``); a context manager (see the module's notes on Ctrl-C)."""

    def __init__(self, count: int, parameters: RobotParameters | Stack, backend: str = "compiled") -> None:
        if not (isinstance(count, int) and count >= 1):
            raise ValueError(f"count = {count!r}: expected a whole number of workers >= 1")
        self.count, self.parameters, self.backend = count, parameters, backend
        self._executor: ProcessPoolExecutor | None = None

    def __enter__(self) -> Workers:
        context = multiprocessing.get_context(START_METHOD)
        # The workers start with SIGINT ignored, inherited through exec (Python keeps an ignored
        # SIGINT ignored); meanwhile SIGINT is blocked here too, so a Ctrl-C during the start stays
        # pending and arrives once the handler is back (Linux never discards a blocked signal).
        posix = hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if posix else set()
        handler = signal.signal(signal.SIGINT, signal.SIG_IGN) if posix else None
        try:
            self._executor = ProcessPoolExecutor(
                self.count, mp_context=context, initializer=_start_worker, initargs=(self.parameters, self.backend)
            )
            # the pool starts a process per call while none is idle: start them all now
            for _ in range(self.count):
                self._executor.submit(os.getpid)
        except BaseException:
            self._stop(kill=True)
            raise
        finally:
            if posix:
                signal.signal(signal.SIGINT, signal.default_int_handler if handler is None else handler)
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        return self

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        self._stop(kill=kind is not None)  # an error or Ctrl-C: what runs is lost anyway

    def submit(self, fn: Callable[..., T], /, *args: Any) -> Future[T]:
        """``fn(robot, *args)`` in a worker (``fn`` a module-level function, the arguments picklable)."""
        if self._executor is None:
            raise RuntimeError("Workers.submit outside the with block")
        return self._executor.submit(_call, fn, *args)

    def _stop(self, *, kill: bool) -> None:
        executor, self._executor = self._executor, None
        if executor is None:
            return
        if kill:  # at once: a worker busy in compiled code would finish its run first otherwise
            processes = list((getattr(executor, "_processes", None) or {}).values())
            for process in processes:
                process.kill()
            for process in processes:
                process.join()
        executor.shutdown(wait=True, cancel_futures=True)


#: The robot of this worker process (set by :func:`_start_worker`).
_ROBOT: list[Robot] = []


def _start_worker(parameters: RobotParameters | Stack, backend: str) -> None:
    """A worker's start: one GA thread, and its own robot (the paper's or a stack, of the backend
    kind ``backend``; a compiled library is loaded from the cache the calling process filled)."""
    from ..model.compiled import get_backend

    os.environ["VGTARM_THREADS"] = "1"
    _ROBOT.append(Robot(parameters, backend=get_backend(backend, definition_of(parameters))))


def _call(fn: Callable[..., T], *args: Any) -> T:
    return fn(_ROBOT[0], *args)
