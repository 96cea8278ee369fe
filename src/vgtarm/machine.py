"""What this machine gives the process: the CPUs it may run on.

One place for the count that the worker pools (``vgtarm reproduce``, a study's local Dask
cluster) and the compiled GA's threads are sized by.
"""

from __future__ import annotations

import os


def usable_cpus() -> int:
    """The CPUs this process may run on: its affinity mask where the system has one (Linux, so a
    ``taskset`` or a container's CPU set counts), else the machine's CPU count; at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)
