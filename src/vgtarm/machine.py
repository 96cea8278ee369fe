"""What this machine gives the process: the CPUs it may run on, BLAS held to one thread, and the
threads a batch of the model runs on.

One place for the count that the worker pools (``vgtarm reproduce``, a study's local Dask
cluster), the compiled GA's threads and the model's batches (:func:`split_rows`) are sized by, and
for the thread limit that a simulation run, the inverse kinematics and the Robot's margin check
put on NumPy's BLAS.
"""

from __future__ import annotations

import functools
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import AbstractContextManager
from typing import Any

from threadpoolctl import ThreadpoolController

from .errors import ConfigError, shown


def usable_cpus() -> int:
    """The CPUs this process may run on: its affinity mask where the system has one (Linux, so a
    ``taskset`` or a container's CPU set counts), else the machine's CPU count; at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


@functools.cache
def _thread_pools() -> ThreadpoolController:
    """The thread pools of the libraries loaded in this process, looked up once: the look-up scans
    the loaded libraries and took 2 ms, 3 % of a 10-module arm's CFC run of case 1 (NumPy's BLAS,
    the one that matters, is loaded with NumPy, before any run)."""
    return ThreadpoolController()


def blas_on_one_thread() -> AbstractContextManager[Any]:
    """A context in which every loaded BLAS runs on one thread; the limits are restored on leaving.

    A run's or a sample's matrices are small, so BLAS threads never help them; once woken,
    OpenBLAS's threads spin after each call and take the cores the compiled loop, the GA's threads
    or the next sample need."""
    return _thread_pools().limit(limits=1, user_api="blas")


# -- batches of the model on several threads -------------------------------------------------------

#: Most threads a batch of the model runs on by default (``$VGTARM_THREADS`` overrides it).
MAX_BATCH_THREADS = 4
#: The variable that sets the thread count of the compiled GA's prediction and of the model's
#: batches (a study's workers set 1: they already fill the CPUs).
THREADS_VARIABLE = "VGTARM_THREADS"
#: Rows the calling thread evaluates first, timed, to size the rest of the batch (and the chunks).
PROBE_ROWS = 8
#: Estimated work (s) left after the probe below which a batch stays on the calling thread: waking
#: a worker costs some tens of microseconds.
MIN_PARALLEL_SECONDS = 2e-4
#: Work (s) of one chunk that a thread takes at a time: long enough that taking one (a few
#: microseconds of Python) costs about 2 %, short enough that a thread the scheduler leaves
#: waiting (a core held by another process) delays the end of the batch by little.
CHUNK_SECONDS = 2e-4
#: Least number of chunks per thread, so that the threads end together.
CHUNKS_PER_THREAD = 4


def threads_setting() -> int | None:
    """``$VGTARM_THREADS`` as a whole number from 1 to 256, ``None`` when unset (a
    :class:`~vgtarm.errors.ConfigError` when it is something else)."""
    text = os.environ.get(THREADS_VARIABLE, "").strip()
    if not text:
        return None
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= 256:
        raise ConfigError(f"{THREADS_VARIABLE} = {shown(text)}: expected a whole number of threads from 1 to 256")
    return value


def batch_threads() -> int:
    """Threads a batch of the model may run on: ``$VGTARM_THREADS``, else the CPUs this process may
    use (:func:`usable_cpus`), at most :data:`MAX_BATCH_THREADS`."""
    value = threads_setting()
    return value if value is not None else min(usable_cpus(), MAX_BATCH_THREADS)


class _Rows:
    """One batch shared by threads: each takes the next chunk of rows until none is left, then the
    calling thread waits (blocked, not spinning) until the chunks taken are done."""

    def __init__(self, work: Callable[[int, int], None], start: int, stop: int, chunk: int) -> None:
        self.work, self.position, self.stop, self.chunk = work, start, stop, chunk
        self.running = 0
        self.halted = False
        self.error: BaseException | None = None
        self.idle = threading.Condition(threading.Lock())

    def drain(self) -> None:
        idle = self.idle
        while True:
            with idle:
                if self.halted or self.position >= self.stop:
                    return
                start = self.position
                self.position = end = min(start + self.chunk, self.stop)
                self.running += 1
            try:
                self.work(start, end)
            except BaseException as exc:  # the first one is raised by the calling thread
                with idle:
                    self.halted = True
                    if self.error is None:
                        self.error = exc
            finally:
                with idle:
                    self.running -= 1
                    if not self.running:
                        idle.notify_all()

    def wait(self) -> None:
        with self.idle:
            while self.running:
                self.idle.wait()


_workers_state = threading.local()
_pool: list[tuple[int, ThreadPoolExecutor]] = []
_pool_lock = threading.Lock()


def _executor() -> ThreadPoolExecutor:
    """The process's pool of batch workers (made again in a forked child: a fork copies no thread)."""
    with _pool_lock:
        if not _pool or _pool[0][0] != os.getpid():
            _pool[:] = [(os.getpid(), ThreadPoolExecutor(max_workers=256, thread_name_prefix="vgtarm-batch"))]
        return _pool[0][1]


def _worker(rows: _Rows) -> None:
    _workers_state.inside = True
    rows.drain()


def split_rows(n: int, work: Callable[[int, int], None], threads: int | None = None) -> int:
    """Call ``work(start, stop)`` over the rows ``[0, n)`` of a batch, on up to ``threads`` threads
    (default :func:`batch_threads`); the number of threads used.

    Each row must be independent of the others (the model's batches: every sample is computed
    alone), so the results do not depend on how the rows are split. The calling thread times its
    first :data:`PROBE_ROWS` rows: a batch whose rest is estimated under :data:`MIN_PARALLEL_SECONDS`
    stays on it. Otherwise the rest is cut into chunks of about :data:`CHUNK_SECONDS` that the
    calling thread and the workers take one at a time: a thread that gets no core (another process
    holds it) takes few, the others take the rest, so a busy machine costs about the time of one
    chunk. Waiting threads block (no spinning). The work must release the GIL to gain anything (a
    call into C through cffi does). A call from a worker itself runs on its own thread.
    """
    count = batch_threads() if threads is None else max(1, int(threads))
    if count <= 1 or n <= PROBE_ROWS or getattr(_workers_state, "inside", False):
        if n > 0:
            work(0, n)
        return 1
    begin = time.perf_counter()
    work(0, PROBE_ROWS)
    per_row = (time.perf_counter() - begin) / PROBE_ROWS
    rest = n - PROBE_ROWS
    if per_row * rest < MIN_PARALLEL_SECONDS:
        work(PROBE_ROWS, n)
        return 1
    chunk = max(1, min(int(CHUNK_SECONDS / max(per_row, 1e-9)), -(-rest // (CHUNKS_PER_THREAD * count))))
    count = min(count, -(-rest // chunk))
    rows = _Rows(work, PROBE_ROWS, n, chunk)
    pool = _executor()
    for _ in range(count - 1):
        try:
            pool.submit(_worker, rows)
        except RuntimeError:  # the interpreter is shutting down: the calling thread does the rest
            break
    try:
        rows.drain()
    except BaseException:  # noqa: B036 - a KeyboardInterrupt between two chunks: stop the others
        with rows.idle:
            rows.halted = True
        rows.wait()
        raise
    rows.wait()
    if rows.error is not None:
        raise rows.error
    return count
