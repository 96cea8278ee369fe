"""What this machine gives the process: the CPUs it may run on, and BLAS held to one thread.

One place for the count that the worker pools (``vgtarm reproduce``, a study's local Dask
cluster) and the compiled GA's threads are sized by, and for the thread limit that a simulation
run and the inverse kinematics put on NumPy's BLAS.
"""

from __future__ import annotations

import functools
import os
from contextlib import AbstractContextManager
from typing import Any

from threadpoolctl import ThreadpoolController


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
