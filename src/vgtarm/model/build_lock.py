"""What keeps builds into the compile cache apart: the cache's build lock, and the private build
folders ``.build-<pid>-*`` that builds leave behind when killed.

A build (:mod:`.compiled`, and the recursive model's, :mod:`vgtarm.model.recursive.library`) holds
:func:`_build_lock` while it looks for a library and builds one into a fresh folder of the cache,
whose name starts with :data:`_BUILD_PREFIX` and the builder's pid; :func:`_clean_stale_builds`
removes those of dead processes and those older than :data:`_STALE_BUILD_AGE` before each build
(and, in the system's temporary folder, the interpreter's symbolic builds ``vgtarm-symbolic-<pid>-*``
before each of those).

:func:`vgtarm.fileio.clean_stale_scratch` is alike (the same liveness check,
:func:`vgtarm.fileio.process_alive`) but not the same, so it is not used here: it judges by the
pid alone, where a build folder is also stale after an hour (the README says so), since in a
container sharing the cache a killed builder's pid is soon another process's; and it leaves
anything but a real folder, where any entry at a build folder's name is removed (a link itself,
never what it points to).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import time
from collections.abc import Iterator
from pathlib import Path

from ..fileio import process_alive
from .library_errors import _shown_path, _Unavailable

#: Prefix of the private build folders inside the cache (followed by the builder's pid).
_BUILD_PREFIX = ".build-"
#: A build folder older than this (s) is stale even if its process still runs.
_STALE_BUILD_AGE = 3600.0
#: Longest wait (s) for another process's build of the same cache before building anyway.
_LOCK_WAIT = 900.0


def _clean_stale_builds(folder: Path, prefix: str = _BUILD_PREFIX) -> None:
    """Remove the build folders ``prefix<pid>-*`` of ``folder`` that are the current user's and
    whose process is gone or that are older than an hour."""
    now = time.time()
    for item in folder.iterdir():
        if not item.name.startswith(prefix):
            continue
        try:
            info = item.lstat()
        except OSError:
            continue
        if info.st_uid != os.geteuid():
            continue
        pid_text = item.name[len(prefix) :].split("-", 1)[0]
        dead = not (pid_text.isdigit() and process_alive(int(pid_text)))
        if dead or now - info.st_mtime > _STALE_BUILD_AGE:
            if stat.S_ISDIR(info.st_mode):
                shutil.rmtree(item, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    item.unlink()


@contextlib.contextmanager
def _build_lock(folder: Path) -> Iterator[None]:
    """Hold the cache's build lock (filelock's ``flock`` on ``.lock``, mode 0600, never followed
    through a symbolic link, released by the system if the holder dies); after a long wait, go on
    without it (the moves into place are atomic). A file system without ``flock`` is an error
    (:class:`OSError`), never a silent fall-back to a lock file that a killed holder would leave."""
    from filelock import FileLock, Timeout  # imported here: only a build needs it

    lock = FileLock(folder / ".lock", mode=0o600, poll_interval=0.1, fallback_to_soft=False)
    try:
        lock.acquire(timeout=_LOCK_WAIT)
        held = True
    except Timeout:  # before OSError: filelock's Timeout is a TimeoutError
        held = False
    except OSError as exc:
        raise _Unavailable(f"cannot write in the cache folder {_shown_path(folder)}: {exc.strerror or exc}") from None
    try:
        yield
    finally:
        if held:
            lock.release()
