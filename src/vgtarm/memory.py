"""Refusing a request that will not fit in memory, before anything is allocated for it.

Large requests (a long path sampled finely for the inverse kinematics, a long simulation) are
estimated from their sample count and a measured cost per sample, and compared with the memory
the machine can still give (``MemAvailable`` of ``/proc/meminfo``, else the free physical
memory, and never more than the address-space limit ``ulimit -v``). ``$VGTARM_MEMORY_LIMIT``
sets the limit instead: a whole number of bytes, optionally with a suffix ``k``, ``M``, ``G`` or
``T`` (powers of 1000), e.g. ``VGTARM_MEMORY_LIMIT=4G``.
"""

from __future__ import annotations

import os
import re
import resource

from .errors import ConfigError, InputError, VgtarmError, shown

#: The variable that sets the memory limit of one request (bytes, optional suffix k, M, G, T).
LIMIT_VARIABLE = "VGTARM_MEMORY_LIMIT"
#: :data:`LIMIT_VARIABLE` as ``os.environ`` keys its own dictionary (CPython; None elsewhere), for
#: :func:`limit_variable_set`.
_LIMIT_KEY: object = os.environ.encodekey(LIMIT_VARIABLE) if hasattr(os.environ, "encodekey") else None
#: A batch estimated below this many bytes is not compared with the machine's available memory
#: (reading it costs as much as evaluating a small batch); ``$VGTARM_MEMORY_LIMIT`` applies to
#: every batch.
SMALL_BATCH = 64 * 10**6
_SUFFIXES = {"": 1, "k": 10**3, "m": 10**6, "g": 10**9, "t": 10**12}
_LIMIT_TEXT = re.compile(r"^\s*(\d+)\s*([kmgt]?)b?\s*$", re.IGNORECASE)


def size_text(n_bytes: float) -> str:
    """``n_bytes`` for a message: ``"812 MB"``, ``"24.3 GB"`` (powers of 1000)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n_bytes >= scale:
            value = n_bytes / scale
            return f"{value:.3g} {unit}" if value < 100 or value >= 1e5 else f"{value:.0f} {unit}"
    return f"{int(n_bytes)} bytes"


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as stream:
            for line in stream:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def memory_limit() -> tuple[int | None, str]:
    """The bytes one request may use and where that figure comes from (for messages).

    ``(None, ...)`` when this system does not say (then nothing is refused).

    Raises:
        ConfigError: ``$VGTARM_MEMORY_LIMIT`` is set but not a size.
    """
    text = os.environ.get(LIMIT_VARIABLE, "")
    if text.strip():
        match = _LIMIT_TEXT.match(text)
        if match is None:
            raise ConfigError(
                f"{LIMIT_VARIABLE} = {shown(text)}: expected a whole number of bytes, optionally with k, M, G or T"
            )
        return int(match[1]) * _SUFFIXES[match[2].lower()], f"set by {LIMIT_VARIABLE}"
    available = _meminfo_available()
    where = f"of memory available (set {LIMIT_VARIABLE} to change the limit)"
    if available is None:
        try:
            available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (AttributeError, OSError, ValueError):
            available = None
    try:
        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (AttributeError, OSError, ValueError):
        soft = resource.RLIM_INFINITY
    if soft != resource.RLIM_INFINITY and soft >= 0 and (available is None or soft < available):
        available, where = soft, "allowed by the address-space limit (ulimit -v)"
    return available, where


def check_memory(needed: float, request: str, advice: str, *, error: type[VgtarmError] = InputError) -> None:
    """Refuse ``request`` with one line if its estimated ``needed`` bytes exceed :func:`memory_limit`.

    ``request`` names what was asked with its values (``"--path p.csv at --dt 1e-06 s: 9,000,001
    samples of inverse kinematics"``); ``advice`` says what to change. The message also names the
    estimate and the limit and where it comes from.
    """
    limit, where = memory_limit()
    if limit is None or needed <= limit:
        return
    raise error(
        f"{request}: about {size_text(needed)} of memory needed, more than the {size_text(limit)} {where}; {advice}"
    )


def limit_variable_set() -> bool:
    """Whether ``$VGTARM_MEMORY_LIMIT`` is set (even to blanks): if it is not, :func:`check_batch`
    returns at once for a batch under :data:`SMALL_BATCH`. Looked up in ``os.environ``'s own
    dictionary where CPython has one: ten times faster than ``os.environ.get``, which raises and
    catches a KeyError for an unset variable (0.4 us, a tenth of one state's forward dynamics through
    ``Robot``, which asks at every call); True when unsure (then ``os.environ`` decides)."""
    data = getattr(os.environ, "_data", None)
    if type(data) is not dict or _LIMIT_KEY is None:
        return True
    return _LIMIT_KEY in data


def check_batch(rows: int, row_bytes: float, request: str, *, error: type[VgtarmError] = InputError) -> None:
    """Refuse, with one line, a batch of ``rows`` rows of about ``row_bytes`` bytes each that will not
    fit in :func:`memory_limit`, before anything is allocated for it.

    ``request`` names what was asked (``"mass_matrix"``); the message names the rows, the estimate,
    the limit and where it comes from, and the largest part that fits. A batch under
    :data:`SMALL_BATCH` is checked only against ``$VGTARM_MEMORY_LIMIT``.
    """
    needed = rows * row_bytes
    if needed <= SMALL_BATCH and not (limit_variable_set() and os.environ.get(LIMIT_VARIABLE, "").strip()):
        return
    limit, where = memory_limit()
    if limit is None or needed <= limit:
        return
    most = int(limit // row_bytes) if row_bytes > 0 else rows
    advice = f"evaluate it in parts of at most {most:,} rows" if most > 0 else f"raise {LIMIT_VARIABLE}"
    raise error(
        f"{request}: a batch of {rows:,} rows needs about {size_text(needed)} of memory ({row_bytes:,.0f} bytes a "
        f"row), more than the {size_text(limit)} {where}; {advice}"
    )
