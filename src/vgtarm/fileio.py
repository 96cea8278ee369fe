"""Writing files and folders so that a reader never sees a partial one, and nothing that is not
vgtarm's own is ever replaced or deleted.

A single file goes to a temporary name in the same folder and is renamed over its target
(:func:`atomic_path`, :func:`atomic_open`, :func:`atomic_write_text`). A result folder is written
the same way as one unit (:func:`atomic_folder`): into a hidden temporary sibling
``.<name>.<pid>.<random>.tmp`` that replaces the old folder whole only when complete. Errors name
the user's path, never the temporary one. :func:`check_output_folder` and
:func:`check_output_file` check an output path before a command starts its work.

What may be replaced (checked before the work, and again at the moment of writing with
``lstat``, so that a link is judged itself, never what it points to):

- a file only by a file: a new name, or an existing *regular* file. A device (``/dev/full``), a
  named pipe, a socket, a folder or a symbolic link (to anything, a regular file included: vgtarm
  does not write through links) is refused in one line naming the path, what it is and what was
  expected. On Linux the new file and the old one are swapped in one atomic step
  (``renameat2(RENAME_EXCHANGE)``) and what was swapped out is looked at again: if it is not a
  regular file (it changed since the check) it is swapped back and the write refused, so no
  window remains between the check and the rename.
- a folder only by a folder: a new name, or an existing real folder (not a link, not a mount
  point) holding only what vgtarm wrote: the files listed in its ``.vgtarm-output``, or, for a
  folder written before that list existed, only files whose names match the writer's ``owned``
  patterns. A folder holding anything else is refused before the work, never deleted.

A folder that changed during the run: when the result is complete, the old folder is checked
again; if it gained files vgtarm did not write (a user's notes, a video rendered into it), or is
no longer a real folder, it is left exactly as it is and the new result goes beside it, to the
first free name ``<name>-2``, ``<name>-3``, ...; one warning line on the ``vgtarm`` logger says so
and :func:`placements` tells the caller where the result went. The check is repeated after the
atomic exchange on the folder swapped out, which is swapped back if it gained a file between the
two. The folder replaced is then emptied file by file from its own list, never removed as a
tree: anything left in it (a file written into it at the last moment) is kept beside, again with
one warning line.

Replacing a folder: on Linux ``renameat2(RENAME_EXCHANGE)`` swaps the two folders in one atomic
step. Elsewhere (or on a file system without it) the old folder is renamed aside to
``.<name>.<pid>.<random>.old``, checked, the new one renamed in, and the old one emptied; a crash
between the two renames leaves no folder at the user's path but the old one aside, which the next
run into the same parent puts back (see :func:`clean_stale`).

A read-only file system, a folder without write permission and a mount point (which a rename
cannot replace) are found by the checks before the work. A write that meets a full disk, a quota
or the file size limit (``ulimit -f``) raises :class:`OutputSpaceError`, one line naming the path
(and the limit); the temporary file or folder is removed.

Inputs: every reader of a user's file goes through :func:`open_input` (or :func:`read_text_limited`,
:func:`read_bytes_limited` on it), which refuses anything but a regular file (a named pipe, a
device, a socket, a folder) before it is opened, with :func:`check_input_file`, and again on the
descriptor opened without waiting, so no read ever blocks on a pipe or never ends on a device.
:func:`check_input_folder` does the same for an input folder (a saved run, a study's folder).

A folder that grows in place rather than being replaced (a study's results) is checked with
:func:`check_growing_folder`; its writer decides what it may hold (:mod:`vgtarm.study.store`).
Scratch folders of the programs vgtarm runs (a compiler's objects) come from
:func:`scratch_folder`: ``<tmp>/<prefix><pid>-<random>``, so that those of a process killed with
SIGKILL are removed by the next run (:func:`clean_stale_scratch`).
"""

from __future__ import annotations

import contextvars
import ctypes
import errno
import fnmatch
import functools
import logging
import math
import os
import re
import secrets
import shutil
import stat
import tempfile
import tomllib
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any, BinaryIO, TextIO

from .errors import InputError, Terminated, VgtarmError, cut

logger = logging.getLogger("vgtarm")

#: The list of files a folder written by :func:`atomic_folder` holds (one relative path a line).
MANIFEST = ".vgtarm-output"
_MANIFEST_HEADER = "# written by vgtarm as one unit; a later run replaces this folder only if it holds nothing else"
#: Names of temporary files and folders: ``.<name>.<pid>.<8 hex>.tmp[<suffix>]`` or ``....old``.
_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{8}\.(?P<kind>tmp|old)(?:\.[^.]*)?$")
#: How often a rename looks again at a target that changes under it before giving up.
_ATTEMPTS = 5
#: Highest ``k`` of the names ``<name>-k`` tried beside a folder that may not be replaced.
_BESIDE_LIMIT = 10_000


#: Longest rendering of a path in a message (longer than other values: the name is at the end).
PATH_LENGTH = 200


def _shown(path: str) -> str:
    return cut(path, PATH_LENGTH)


def _temporary_name(name: str, kind: str = "tmp", suffix: str = "") -> str:
    return f".{name}.{os.getpid()}.{secrets.token_hex(4)}.{kind}{suffix}"


def _user_path(exc: OSError, temporary: Path, target: Path) -> OSError:
    """``exc`` with every file name inside ``temporary`` shown as the same name inside ``target``."""
    prefix = os.fspath(temporary)

    def mapped(name: object) -> object:
        if isinstance(name, str | bytes) and os.fsdecode(name).startswith(prefix):
            return os.fspath(target) + os.fsdecode(name)[len(prefix) :]
        return name

    # assigned only when set: an OSError given a file name of None prints "[Errno None] None: None"
    if exc.filename is not None:
        exc.filename = mapped(exc.filename)
    if exc.filename2 is not None:
        exc.filename2 = mapped(exc.filename2)
    return exc


# --- what is at a path ----------------------------------------------------------------------


def _kind(mode: int) -> str:
    """What a file system entry of ``mode`` (from ``lstat``) is, for a message."""
    kinds: list[tuple[Callable[[int], bool], str]] = [
        (stat.S_ISREG, "a file"),
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISFIFO, "a named pipe (FIFO)"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
    ]
    return next((name for test, name in kinds if test(mode)), "a special file")


def _lstat(path: str | os.PathLike[str]) -> os.stat_result | None:
    """``os.lstat(path)``, or None when nothing is there (a missing name, or a parent that is a
    file: :func:`check_writable_parent` names that)."""
    try:
        return os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None


def describe(path: str | os.PathLike[str]) -> str:
    """What is at ``path``, judged without following a link: ``"a named pipe (FIFO)"``,
    ``"a symbolic link to a character device"``, ``"nothing"``."""
    found = _lstat(path)
    if found is None:
        return "nothing"
    if not stat.S_ISLNK(found.st_mode):
        return _kind(found.st_mode)
    try:
        return f"a symbolic link to {_kind(os.stat(path).st_mode)}"
    except OSError:
        return "a symbolic link that leads nowhere"


class OutputPathError(VgtarmError, FileExistsError):
    """An output path holds, at the moment of writing, something a writer may not replace (a
    device, a pipe, a socket, a link, a folder): a user's error and a state of the file system, so
    both a :class:`~vgtarm.errors.VgtarmError` and a :class:`FileExistsError`. Its text is the one
    line naming the path, what is there and what was expected. (The checks before the work raise
    :class:`~vgtarm.errors.InputError` for the same paths.)"""

    def __init__(self, message: str, path: str | os.PathLike[str]) -> None:
        super().__init__(errno.EEXIST, message, os.fspath(path))

    def __str__(self) -> str:
        return str(self.strerror)


#: What a write that failed for want of room ran into, by ``errno``.
_NO_ROOM = {
    errno.ENOSPC: "no space left on the device (the disk is full)",
    errno.EDQUOT: "the disk quota is exceeded",
    errno.EFBIG: "larger than the file size limit",
}


def _size_limit() -> str:
    """The file size limit of this process (``ulimit -f``) for a message: ``" of 4,096 bytes
    (ulimit -f)"``, or ``""`` when there is none (the file system's own limit was met)."""
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    except (ImportError, OSError, ValueError):  # no resource module (Windows)
        return ""
    return "" if soft == resource.RLIM_INFINITY else f" of {soft:,} bytes (ulimit -f)"


class OutputSpaceError(VgtarmError, OSError):
    """Writing an output failed for want of room: a full disk (``ENOSPC``), a quota (``EDQUOT``)
    or the file size limit (``EFBIG``; Python ignores ``SIGXFSZ``, so ``ulimit -f`` ends a write
    with this error rather than killing the process). Nothing partial is left (the writers of this
    module remove their temporary file or folder). Its text is one line naming the output (its
    :attr:`filename`, the user's path), the reason and, for the size limit, the limit."""

    #: How the output is named in the message (``--out``, ``output file``).
    what = "output file"

    def __str__(self) -> str:
        reason = _NO_ROOM.get(self.errno or 0, str(self.strerror))
        if self.errno == errno.EFBIG:
            reason += _size_limit()
        return f"{self.what} {_shown(os.fsdecode(self.filename or ''))}: {reason}; nothing was written"


def no_room_error(exc: OSError, target: str | os.PathLike[str], what: str = "output file") -> OSError:
    """``exc`` as an :class:`OutputSpaceError` naming ``target`` (shown as ``what``) when it says
    the disk, a quota or the file size limit was full; else ``exc`` itself. For writers that
    cannot write atomically (an append to a log)."""
    if isinstance(exc, OutputSpaceError) or exc.errno not in _NO_ROOM:
        return exc
    error = OutputSpaceError(exc.errno, exc.strerror, os.fspath(target))
    error.what = what
    return error


def _file_refusal(target: Path, what: str, found: os.stat_result) -> str:
    """The one line refusing to write the file ``target`` over ``found``, which is not a regular file."""
    shown = _shown(str(target))
    if stat.S_ISDIR(found.st_mode):
        return f"{what} {shown}: is a folder; give a file name"
    link = " (vgtarm does not write through links)" if stat.S_ISLNK(found.st_mode) else ""
    return f"{what} {shown}: is {describe(target)}; expected a regular file or a new file name{link}"


def _not_a_file(target: Path, what: str, found: os.stat_result) -> OutputPathError:
    return OutputPathError(_file_refusal(target, what, found), target)


def _not_a_folder(target: Path, what: str) -> InputError:
    """The one line refusing to write a result folder at ``target``, which is not a real folder."""
    shown = _shown(str(target))
    found = describe(target)
    if found.startswith("a symbolic link"):
        return InputError(f"{what} {shown}: is {found}; expected the folder itself (not a link) or a new folder name")
    return InputError(f"{what} {shown}: is {found}, not a folder; expected a folder or a new folder name")


def _mount_points() -> frozenset[str]:
    """The mount points of this process now (Linux ``/proc/self/mountinfo``; empty elsewhere),
    which also shows a bind mount of a folder of the same file system (``os.path.ismount`` does not)."""
    try:
        with open("/proc/self/mountinfo", encoding="utf-8", errors="surrogateescape") as stream:
            lines = stream.read(4 * 2**20).splitlines()
    except OSError:
        return frozenset()
    octal = re.compile(r"\\([0-7]{3})")  # the kernel writes a space as \040, a backslash as \134
    return frozenset(octal.sub(lambda m: chr(int(m[1], 8)), line.split()[4]) for line in lines if len(line.split()) > 4)


def _is_mount_point(path: Path) -> bool:
    try:
        if os.path.ismount(path):
            return True
        return os.fspath(path.resolve()) in _mount_points()
    except (OSError, ValueError):
        return False


def _read_only(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` lies on a file system mounted read-only (which even root cannot write)."""
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):  # no statvfs here (Windows), or it cannot tell: not refused
        return False


# --- renames --------------------------------------------------------------------------------

_AT_FDCWD, _RENAME_NOREPLACE, _RENAME_EXCHANGE = -100, 1, 2
#: What ``renameat2`` reports when the system or the file system cannot do what was asked.
_UNSUPPORTED = (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EPERM)


@functools.cache
def _renameat2() -> Any:
    """The C library's ``renameat2`` (Linux), or None."""
    try:
        return ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return None


def _rename2(first: Path, second: Path, flags: int) -> bool:
    """``renameat2(first, second, flags)``: True if done, False where it is not possible here;
    any other failure raises :class:`OSError` naming ``second``."""
    call = _renameat2()
    if call is None:
        return False
    if call(_AT_FDCWD, os.fsencode(first), _AT_FDCWD, os.fsencode(second), flags) == 0:
        return True
    code = ctypes.get_errno()
    if code in _UNSUPPORTED:
        return False
    raise OSError(code, os.strerror(code), os.fspath(second))


def _exchange(first: Path, second: Path) -> bool:
    """Swap two entries in one atomic step (Linux ``renameat2``); False where that is not possible."""
    return _rename2(first, second, _RENAME_EXCHANGE)


def _rename_new(source: Path, target: Path) -> bool:
    """Rename ``source`` to ``target`` only if nothing is there: True if done, False if something
    is (atomic on Linux; elsewhere checked just before the rename)."""
    try:
        if _rename2(source, target, _RENAME_NOREPLACE):
            return True
    except FileExistsError:
        return False
    if os.path.lexists(target):
        return False
    try:
        os.rename(source, target)
    except OSError as exc:  # a folder (not empty) or a file appeared there meanwhile
        if exc.errno in (errno.EEXIST, errno.ENOTEMPTY, errno.ENOTDIR, errno.EISDIR):
            return False
        raise
    return True


def _rename_beside(source: Path, target: Path) -> Path:
    """Rename ``source`` to the first free name ``<target>-2``, ``<target>-3``, ...; return it."""
    for k in range(2, _BESIDE_LIMIT):
        candidate = target.with_name(f"{target.name}-{k}")
        if _rename_new(source, candidate):
            return candidate
    raise FileExistsError(errno.EEXIST, f"no free name {target.name}-k beside it", os.fspath(target))


#: Where :func:`atomic_folder` put results it could not put at their path, while :func:`placements` runs.
_PLACED: contextvars.ContextVar[dict[Path, Path] | None] = contextvars.ContextVar("vgtarm_placed", default=None)


@contextmanager
def placements() -> Iterator[dict[Path, Path]]:
    """Record, while the block runs, where :func:`atomic_folder` wrote results it could not put at
    their path (the folder there gained files vgtarm did not write, or became something else
    during the run): ``{path as given: the folder beside it that holds the results}``. A command
    prints the path it finds here instead of the one it asked for."""
    record: dict[Path, Path] = {}
    token = _PLACED.set(record)
    try:
        yield record
    finally:
        _PLACED.reset(token)


def _placed_beside(new: Path, target: Path, what: str, reason: str) -> Path:
    """Put the finished folder ``new`` beside ``target`` (which is left as it is), saying why in one line."""
    placed = _rename_beside(new, target)
    logger.warning(
        "vgtarm: %s %s: %s; it is kept as it was, and the new results are in %s",
        what,
        _shown(str(target)),
        reason,
        _shown(str(placed)),
    )
    record = _PLACED.get()
    if record is not None:
        record[target] = placed
    return placed


# --- single files ---------------------------------------------------------------------------


def _refuse_unless_file(target: Path, what: str) -> None:
    """Raise :class:`OutputPathError` if something that is not a regular file is at ``target``."""
    found = _lstat(target)
    if found is not None and not stat.S_ISREG(found.st_mode):
        raise _not_a_file(target, what, found)


def _put_file(temporary: Path, target: Path, what: str) -> None:
    """Rename the finished file ``temporary`` to ``target``: to a new name, or over a regular file;
    never over anything else, looked at with ``lstat`` at the last moment (and, after an atomic
    exchange, looked at again and swapped back if it changed in between)."""
    _stop_if_terminated()
    for _ in range(_ATTEMPTS):
        found = _lstat(target)
        if found is None:
            if _rename_new(temporary, target):
                return
            continue  # something appeared there meanwhile: look at it
        if not stat.S_ISREG(found.st_mode):
            raise _not_a_file(target, what, found)
        try:
            exchanged = _exchange(temporary, target)
        except FileNotFoundError:
            continue  # it went away meanwhile
        if not exchanged:  # no atomic exchange here: the look above is the last guard
            os.replace(temporary, target)
            return
        old = os.lstat(temporary)  # what was at the target until now
        if stat.S_ISREG(old.st_mode):
            os.unlink(temporary)
            return
        _exchange(temporary, target)  # it changed after the look: put it back, refuse
        raise _not_a_file(target, what, old)
    raise FileExistsError(errno.EEXIST, "changed again and again while it was written", os.fspath(target))


def _stop_if_terminated() -> None:
    """Raise :class:`~vgtarm.errors.Terminated` again if a SIGTERM arrived (its exception may have
    been swallowed by a library): no result is put in place after it, the temporary is removed."""
    if Terminated.arrived:
        raise Terminated


def _drop_temporary(temporary: Path) -> None:
    """Remove a temporary file of ours (never anything else that may sit at its name)."""
    found = _lstat(temporary)
    if found is not None and stat.S_ISREG(found.st_mode):
        temporary.unlink(missing_ok=True)


@contextmanager
def atomic_path(path: str | os.PathLike[str], what: str = "output file") -> Iterator[Path]:
    """A temporary path to write in place of ``path``; it replaces ``path`` when the block ends.

    The temporary name is in the same folder and keeps the suffix (for writers that choose the
    format from it); the writer creates the file, so it gets the usual permissions
    (``tempfile.mkstemp`` would make it private to the user). ``path`` must be a new name or a
    regular file, when the block starts and again when it ends (``lstat``: a symbolic link is
    refused, whatever it points to); else :class:`OutputPathError` names ``what``, the path, what
    is there and what was expected. On any error the temporary file is removed and
    ``path`` is left as it was; an ``OSError`` names ``path``, not the temporary file.
    """
    target = Path(path)
    _refuse_unless_file(target, what)
    temporary = target.with_name(_temporary_name(target.stem, suffix=target.suffix))
    try:
        yield temporary
        _put_file(temporary, target, what)
    except OSError as exc:
        _drop_temporary(temporary)
        failure = no_room_error(_user_path(exc, temporary, target), target, what)
        if failure is exc:
            raise  # the same exception, renamed
        raise failure from exc
    except BaseException:
        _drop_temporary(temporary)
        raise


@contextmanager
def atomic_open(path: str | os.PathLike[str], what: str = "output file") -> Iterator[TextIO]:
    """A text stream whose content replaces ``path`` only when the block ends without error
    (the rules of :func:`atomic_path`)."""
    with atomic_path(path, what) as temporary, open(temporary, "x", encoding="utf-8", newline="") as stream:
        yield stream


def atomic_write_text(path: str | os.PathLike[str], text: str, what: str = "output file") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_open`)."""
    with atomic_open(path, what) as stream:
        stream.write(text)
    return Path(path)


# --- what a folder holds --------------------------------------------------------------------


def _entries(folder: Path) -> dict[str, int]:
    """Every entry under ``folder`` by relative POSIX path, with its ``lstat`` mode: files and
    anything else that is not a folder, and each empty folder as ``"name/"``. Links are not
    followed; an entry that vanishes while it is looked at is left out."""
    found: dict[str, int] = {}
    pending = [(os.fspath(folder), "")]
    while pending:
        where, prefix = pending.pop()
        try:
            with os.scandir(where) as listing:
                children = list(listing)
        except OSError:
            if not prefix:
                raise
            found[prefix] = stat.S_IFDIR  # a folder that cannot be read: listed as such, never assumed empty
            continue
        if not children and prefix:
            found[prefix] = stat.S_IFDIR
        for child in children:
            try:
                mode = child.stat(follow_symlinks=False).st_mode
            except FileNotFoundError:
                continue
            if stat.S_ISDIR(mode):
                pending.append((child.path, f"{prefix}{child.name}/"))
            else:
                found[prefix + child.name] = mode
    return found


def _manifest(folder: Path) -> set[str] | None:
    """The list of what vgtarm wrote in ``folder`` (its regular file ``.vgtarm-output``), or None."""
    found = _lstat(folder / MANIFEST)
    if found is None or not stat.S_ISREG(found.st_mode):
        return None
    try:
        text = (folder / MANIFEST).read_text("utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    return {line for line in text.splitlines() if line and not line.startswith("#")}


def _ours(name: str, mode: int, listed: Collection[str]) -> bool:
    """Whether the entry ``name`` (``mode`` from ``lstat``) is one vgtarm wrote: listed, and a
    regular file (or an empty folder listed as one)."""
    return name in listed and (stat.S_ISREG(mode) or (name.endswith("/") and stat.S_ISDIR(mode)))


def _legacy(folder: Path, owned: Collection[str]) -> tuple[list[str], str | None]:
    """For a folder without ``.vgtarm-output``: its entries that are regular files named by one of
    the ``owned`` patterns, and why it may not be replaced (another entry), or None."""
    written: list[str] = []
    for name in sorted(os.listdir(folder)):
        found = _lstat(folder / name)
        if found is None:
            continue
        if not (stat.S_ISREG(found.st_mode) and any(fnmatch.fnmatchcase(name, p) for p in owned)):
            return written, f"the folder holds {_shown(repr(name))} and no {MANIFEST} list of what vgtarm wrote there"
        written.append(name)
    return written, None


def _foreign(folder: Path, owned: Collection[str]) -> str | None:
    """Why an existing folder may not be replaced (an entry vgtarm did not write), or None."""
    listed = _manifest(folder)
    if listed is None:  # a folder written before the list existed
        return _legacy(folder, owned)[1]
    entries = _entries(folder)
    extra = sorted(name for name, mode in entries.items() if name != MANIFEST and not _ours(name, mode, listed))
    if not extra:
        return None
    kind = f", {_kind(entries[extra[0]])}" if extra[0] in listed else ""  # a listed name, now a pipe
    return f"the folder holds {_shown(repr(extra[0]))}{kind}, which vgtarm did not write there"


def _written(folder: Path, owned: Collection[str]) -> list[str]:
    """The entries of ``folder`` that vgtarm wrote (its list, or the ``owned`` files of an old folder)."""
    listed = _manifest(folder)
    if listed is None:
        return _legacy(folder, owned)[0]
    entries = _entries(folder)
    return [name for name, mode in entries.items() if _ours(name, mode, listed)] + [MANIFEST]


def _empty(old: Path, target: Path, what: str, owned: Collection[str]) -> None:
    """Remove the replaced folder ``old`` (set aside at an ``.old`` name) entry by entry from what
    vgtarm wrote in it, never as a tree. Anything left (a file written into it at the last moment) is
    kept: the folder goes beside ``target`` with one warning line."""
    written = _written(old, owned)
    folders = {old}
    for name in written:
        path = old / name.rstrip("/")
        folders.update(p for p in path.parents if old in p.parents)
        if name.endswith("/"):
            folders.add(path)
        else:
            found = _lstat(path)
            if found is not None and stat.S_ISREG(found.st_mode):
                with suppress(OSError):
                    path.unlink()
    for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):  # the deepest first
        with suppress(OSError):
            folder.rmdir()
    if not os.path.lexists(old):
        return
    with suppress(OSError):
        kept = _rename_beside(old, target)
        logger.warning(
            "vgtarm: %s %s: files vgtarm did not write appeared in the folder while it was replaced; kept them in %s",
            what,
            _shown(str(target)),
            _shown(str(kept)),
        )


def is_temporary(name: str) -> bool:
    """Whether ``name`` is one of the temporary names this module's writers give a file or folder
    while it is written (``.<name>.<pid>.<random>.tmp``, ``....old``): a writer's, never a user's."""
    return _TEMPORARY.match(name) is not None


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (somebody else's too; on Linux a thread's id is no process):
    whether the writer of a temporary file, scratch folder or build folder named by its pid still runs."""
    import psutil  # imported here: only the clean-up of stale files and folders needs it

    return psutil.pid_exists(pid)


def clean_stale(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files and folders left in ``folder`` by writers that were killed.

    Only names of the form :func:`atomic_path` and :func:`atomic_folder` make, of a process id
    that no longer runs on this machine, are touched, and only if they are regular files or real
    folders (a device, pipe, socket or link at such a name is left alone). A folder set aside while
    a killed run replaced it (``.<name>.<pid>.<random>.old``) is put back when ``<name>`` is
    missing, else emptied from its list of files (``.vgtarm-output``) only, anything else in it
    kept beside ``<name>`` (:func:`atomic_folder`'s rule). An unfinished result
    (``.<name>.<pid>.<random>.tmp``, in which only vgtarm writes) is removed. Returns what was
    removed or put back. (It assumes the folder is not shared with writers on other machines,
    whose process ids mean nothing here.)
    """
    where = Path(folder)
    touched: list[Path] = []
    try:
        entries = list(os.scandir(where))
    except OSError:
        return touched
    for entry in entries:
        match = _TEMPORARY.match(entry.name)
        if match is None or process_alive(int(match["pid"])):
            continue
        path = Path(entry.path)
        original = where / match["name"]
        try:
            if entry.is_file(follow_symlinks=False):
                path.unlink()
            elif not entry.is_dir(follow_symlinks=False):
                continue
            elif match["kind"] == "tmp":  # an unfinished result: only vgtarm writes in it
                shutil.rmtree(path, ignore_errors=True)
            elif not os.path.lexists(original):
                os.rename(path, original)
            elif _manifest(path) is not None:
                _empty(path, original, "folder", ())
            else:  # an old folder of the time before folders listed their files
                shutil.rmtree(path, ignore_errors=True)
        except OSError:
            continue
        touched.append(path)
    return touched


def clean_stale_scratch(prefix: str, folder: str | os.PathLike[str] | None = None) -> list[Path]:
    """Remove the scratch folders ``<prefix><pid>-<random>`` (:func:`scratch_folder`) left in
    ``folder`` (default: the system's temporary folder) by processes that were killed: only real
    folders (never a link) of the current user whose process no longer runs (:func:`process_alive`, the
    rule of :func:`clean_stale`). Returns what was removed."""
    where = Path(tempfile.gettempdir() if folder is None else folder)
    pattern = re.compile(re.escape(prefix) + r"(?P<pid>\d+)-")
    removed: list[Path] = []
    try:
        entries = list(os.scandir(where))
    except OSError:
        return removed
    for entry in entries:
        match = pattern.match(entry.name)
        try:
            if match is None or not entry.is_dir(follow_symlinks=False):
                continue
            if entry.stat(follow_symlinks=False).st_uid != os.geteuid() or process_alive(int(match["pid"])):
                continue
        except OSError:
            continue
        shutil.rmtree(entry.path, ignore_errors=True)  # only vgtarm writes in it
        removed.append(Path(entry.path))
    return removed


@contextmanager
def scratch_folder(prefix: str) -> Iterator[Path]:
    """A new private folder ``<tmp>/<prefix><pid>-<random>`` for the block's scratch files (a
    compiler's objects), removed with what it holds when the block ends. Those of killed
    processes (a SIGKILL leaves them) are removed first (:func:`clean_stale_scratch`)."""
    clean_stale_scratch(prefix)
    with tempfile.TemporaryDirectory(prefix=f"{prefix}{os.getpid()}-") as scratch:
        yield Path(scratch)


# --- checks before the work -----------------------------------------------------------------


def _named(path: str | os.PathLike[str], what: str, kind: str) -> Path:
    """``path`` as a :class:`~pathlib.Path`, or :class:`~vgtarm.errors.InputError` if it cannot name
    anything: empty, holding a NUL character (which the system refuses in any file name), or
    characters that have no bytes in the file system's encoding (possible only from Python)."""
    text = os.fspath(path)
    if text == "":
        raise InputError(f"{what} '': expected a {kind} name")
    if "\0" in text:
        raise InputError(f"{what} {_shown(repr(text))}: a {kind} name cannot hold a NUL character")
    try:
        os.fsencode(text)
    except UnicodeError:
        raise InputError(f"{what} {_shown(repr(text))}: not a valid {kind} name on this system") from None
    return Path(text)


def _unusable(exc: OSError, path: str | os.PathLike[str], what: str) -> InputError:
    """One line for a path the system will not even look up (a name too long, a loop of links)."""
    return InputError(f"{what} {_shown(str(path))}: cannot be used ({exc.strerror or type(exc).__name__})")


def _check_writable(folder: Path, path: str | os.PathLike[str], what: str) -> None:
    """Refuse, naming ``path``, unless we may create entries in the existing ``folder``."""
    where = "" if folder == Path(path).absolute() else f"{_shown(str(folder))} "
    if _read_only(folder):
        raise InputError(
            f"{what} {_shown(str(path))}: {where}is on a read-only file system; give a folder you can write in"
        )
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{what} {_shown(str(path))}: cannot write in {_shown(str(folder))} (permission denied)")


def check_writable_parent(path: str | os.PathLike[str], what: str = "output") -> None:
    """Raise :class:`~vgtarm.errors.InputError` (one line naming ``path``) unless the nearest
    existing folder above ``path`` is a folder we may write in (missing ones can be created), and
    so is ``path`` itself when it is an existing folder (a result folder is written in as it is
    replaced; a study's folder grows). A read-only file system is found here, before the work
    (``statvfs``; permission bits alone would not show it to root), as is a missing permission."""
    shown = _shown(str(path))
    try:
        named = _named(path, what, "file").absolute()
        ancestor = named.parent
        while not ancestor.exists() and not ancestor.is_symlink():
            ancestor = ancestor.parent
        is_folder = ancestor.is_dir()
        itself = _lstat(named)
    except OSError as exc:
        raise _unusable(exc, path, what) from exc
    if not is_folder:
        raise InputError(f"{what} {shown}: {_shown(str(ancestor))} is a file, not a folder")
    _check_writable(ancestor, path, what)
    if itself is not None and stat.S_ISDIR(itself.st_mode):
        _check_writable(named, path, what)


def _same_entry(first: Path, second: Path) -> bool:
    """Whether two paths lead to the same file or folder (device and inode, links followed)."""
    try:
        return os.path.samefile(first, second)
    except (OSError, ValueError):  # one of them is missing, or cannot be looked up
        return False


def _resolved(paths: Iterable[str | os.PathLike[str] | None]) -> list[Path]:
    return [Path(p).resolve() for p in paths if p is not None and os.fspath(p) != ""]


def _refuse_mount_point(target: Path, shown: str, what: str) -> None:
    if _is_mount_point(target):
        raise InputError(
            f"{what} {shown}: is a mount point, which vgtarm cannot replace by a rename; give a new name inside it"
        )


def check_output_folder(
    path: str | os.PathLike[str],
    what: str = "output folder",
    *,
    inputs: Iterable[str | os.PathLike[str] | None] = (),
    owned: Collection[str] = (),
) -> Path:
    """Check, before any work, that a result folder can be written at ``path`` as one unit.

    ``path`` must be a new name or a real folder (not a file, device, pipe, socket or symbolic
    link, judged with ``lstat``; not a mount point); its nearest existing parent, and the folder
    itself, must be folders we may write in, on a file system that is not read-only; it must not
    be or hold one of ``inputs`` (the files or folders the command reads), nor the current folder;
    and an existing folder there must hold only what vgtarm wrote (the files listed in its
    ``.vgtarm-output``; for a folder without that list, only files whose names match one of the
    ``owned`` patterns). ``what`` names the path in messages (``--out``).

    Raises :class:`~vgtarm.errors.InputError` with one line naming ``path``, what is there and
    what was expected.
    """
    return _checked_folder(path, what, inputs, owned, foreign=True)


def _checked_folder(
    path: str | os.PathLike[str],
    what: str,
    inputs: Iterable[str | os.PathLike[str] | None],
    owned: Collection[str],
    *,
    foreign: bool,
) -> Path:
    """:func:`check_output_folder`; with ``foreign`` False, a folder holding files vgtarm did not
    write passes (they are looked for again at the swap)."""
    target = _named(path, what, "folder")
    try:
        return _check_output_folder(target, _shown(str(path)), what, inputs, owned, foreign)
    except OSError as exc:
        raise _unusable(exc, path, what) from exc


def _check_output_folder(
    target: Path,
    shown: str,
    what: str,
    inputs: Iterable[str | os.PathLike[str] | None],
    owned: Collection[str],
    foreign: bool,
) -> Path:
    found = _lstat(target)
    if found is not None and not stat.S_ISDIR(found.st_mode):
        raise _not_a_folder(target, what)
    check_writable_parent(target, what)
    _refuse_inputs(target, found is not None, shown, what, inputs)
    if found is not None:
        _refuse_mount_point(target, shown, what)
        reason = _foreign(target, owned) if foreign else None
        if reason is not None:
            raise InputError(f"{what} {shown}: {reason}; give a new or empty folder, or move that away")
    return target


def _refuse_inputs(
    target: Path, exists: bool, shown: str, what: str, inputs: Iterable[str | os.PathLike[str] | None]
) -> None:
    """Refuse an output folder ``target`` that is the current folder or holds it, or is or holds one
    of ``inputs`` (by name, and, when it ``exists``, by device and inode: another path to it)."""
    resolved = target.resolve()
    if resolved == resolved.parent or resolved in (Path.cwd(), *Path.cwd().parents):
        raise InputError(f"{what} {shown}: is the current folder or holds it; give a folder below it")
    for source in _resolved(inputs):
        # by name, and by device and inode (another path to the folder: a bind mount)
        if source == resolved or (exists and _same_entry(source, target)):
            raise InputError(f"{what} {shown}: is an input of this command; choose another folder")
        if resolved in source.parents or (exists and any(_same_entry(p, target) for p in source.parents)):
            raise InputError(f"{what} {shown}: holds {_shown(str(source))}, an input of this command; choose another")


def check_growing_folder(
    path: str | os.PathLike[str], what: str = "output folder", *, inputs: Iterable[str | os.PathLike[str] | None] = ()
) -> Path:
    """Check, before any work, a folder that a command writes in file by file and that grows from
    run to run, so is never replaced whole (a study's results folder, :mod:`vgtarm.study.store`).

    ``path`` must be a new name or a folder (a symbolic link to a folder included: no file is ever
    written through a link in it, and the folder itself is never renamed); the folder, or the
    nearest existing parent, one we may write in, on a file system that is not read-only; not the
    current folder or one that holds it; not one of ``inputs`` and not holding one of them (by
    name, and by device and inode). What the folder may hold is its writer's rule. Raises
    :class:`~vgtarm.errors.InputError` with one line naming ``path``, what is there and what was
    expected.
    """
    target = _named(path, what, "folder")
    shown = _shown(str(path))
    try:
        found = _lstat(target)
        if found is not None and not target.is_dir():
            raise InputError(
                f"{what} {shown}: is {describe(target)}, not a folder; expected a folder or a new folder name"
            )
        check_writable_parent(target, what)
        if found is not None and stat.S_ISLNK(found.st_mode):  # the folder it leads to is written in
            _check_writable(target.resolve(), path, what)
        _refuse_inputs(target, found is not None, shown, what, inputs)
    except OSError as exc:
        raise _unusable(exc, path, what) from exc
    return target


def check_output_file(
    path: str | os.PathLike[str], what: str = "output file", *, inputs: Iterable[str | os.PathLike[str] | None] = ()
) -> Path:
    """Check, before any work, that a file can be written at ``path``.

    ``path`` must be a new name or an existing regular file (``lstat``: a folder, device, named
    pipe, socket or symbolic link is refused, a link even to a regular file; nor a mount point),
    not one of ``inputs`` (the files the command reads), and its nearest existing parent must be
    a folder we may write in, on a file system that is not read-only. Temporary files left beside
    it by killed runs are removed (:func:`clean_stale`). Raises
    :class:`~vgtarm.errors.InputError` with one line naming ``path``, what is there and what was
    expected.
    """
    target = _named(path, what, "file")
    try:
        return _check_output_file(target, _shown(str(path)), what, inputs)
    except OSError as exc:
        raise _unusable(exc, path, what) from exc


def _check_output_file(target: Path, shown: str, what: str, inputs: Iterable[str | os.PathLike[str] | None]) -> Path:
    found = _lstat(target)
    if found is not None and not stat.S_ISREG(found.st_mode):
        raise InputError(_file_refusal(target, what, found))
    resolved = target.resolve()
    for source in _resolved(inputs):  # by name, and by device and inode (a hard link, another path)
        if source == resolved or (found is not None and _same_entry(source, target)):
            raise InputError(f"{what} {shown}: is an input of this command; writing it would destroy it")
    check_writable_parent(target, what)
    if found is not None:
        _refuse_mount_point(target, shown, what)
    if target.parent.is_dir():
        clean_stale(target.parent)
    return target


# --- result folders -------------------------------------------------------------------------


def _swap_back(new: Path, target: Path, what: str) -> bool:
    """After an exchange: put the old folder (now at ``new``) back at ``target``; True if done.
    Should that fail, the old folder is kept beside ``target`` (never at a temporary name, which a
    later run would clean) and the new one stays at ``target``: False."""
    try:
        if _exchange(new, target):
            return True
    except OSError:
        pass
    kept = _rename_beside(new, target)
    logger.warning(
        "vgtarm: %s %s: could not put the earlier folder back; it is kept as it was in %s",
        what,
        _shown(str(target)),
        _shown(str(kept)),
    )
    return False


def _replace_folder(new: Path, target: Path, what: str, owned: Collection[str]) -> Path:
    """Put the complete folder ``new`` at ``target``, replacing a folder there whole if it holds
    only what vgtarm wrote; else leave it as it is and put ``new`` beside it. Returns where ``new`` went."""
    _stop_if_terminated()
    for _ in range(_ATTEMPTS):
        found = _lstat(target)
        if found is None:
            if _rename_new(new, target):
                return target
            continue  # something appeared there meanwhile: look at it
        if not stat.S_ISDIR(found.st_mode):  # it changed since it was checked
            return _placed_beside(new, target, what, f"is now {describe(target)}, not a folder")
        reason = _foreign(target, owned)
        if reason is not None:
            return _placed_beside(new, target, what, reason)
        try:
            exchanged = _exchange(new, target)
        except FileNotFoundError:
            continue
        if exchanged:  # new now holds the old folder: look at it again, where nothing can reach it
            try:
                reason = _foreign(new, owned)
            except BaseException:
                _swap_back(new, target, what)
                raise
            if reason is not None:
                return _placed_beside(new, target, what, reason) if _swap_back(new, target, what) else target
            aside = target.with_name(_temporary_name(target.name, kind="old"))
            os.rename(new, aside)  # an old folder is only ever at an .old name (see clean_stale)
            _empty(aside, target, what, owned)
            return target
        aside = target.with_name(_temporary_name(target.name, kind="old"))
        os.rename(target, aside)
        try:
            reason = _foreign(aside, owned)
            if reason is None:
                os.rename(new, target)
        except BaseException:
            os.rename(aside, target)
            raise
        if reason is not None:
            os.rename(aside, target)
            return _placed_beside(new, target, what, reason)
        _empty(aside, target, what, owned)
        return target
    raise FileExistsError(errno.EEXIST, "changed again and again while it was replaced", os.fspath(target))


@contextmanager
def atomic_folder(
    path: str | os.PathLike[str],
    what: str = "output folder",
    *,
    inputs: Iterable[str | os.PathLike[str] | None] = (),
    owned: Collection[str] = (),
    checked: bool = False,
) -> Iterator[Path]:
    """A new empty temporary folder to fill in place of the folder ``path``; it replaces ``path``
    whole when the block ends without error.

    On entry the target is checked (:func:`check_output_folder`, with ``what``, ``inputs`` and
    ``owned``), stale temporary siblings of killed runs are cleaned (:func:`clean_stale`), missing
    parents are created and the temporary sibling ``.<name>.<pid>.<random>.tmp`` is made. On any
    error, Ctrl-C included, the temporary folder is removed and ``path`` is left as it was. The
    finished folder lists its files in ``.vgtarm-output``. An ``OSError`` names the user's path.

    If, when the block ends, the folder at ``path`` holds files vgtarm did not write (added during
    the run) or is no longer a real folder, it is left as it is and the result goes beside it
    (``<name>-2``, ...), with one warning line on the ``vgtarm`` logger; :func:`placements`
    tells the caller where. ``checked``: the caller checked ``path`` with
    :func:`check_output_folder` before its work and enters this block only after it (a command
    that writes its results at the end); files the folder gained since are then the user's,
    added during the run: they are kept the same way, not refused here.
    """
    target = _checked_folder(path, what, inputs, owned, foreign=not checked)
    created = [p for p in reversed(target.absolute().parents) if not p.exists()]
    temporary = target.with_name(_temporary_name(target.name))
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        clean_stale(target.parent)
        os.mkdir(temporary)
    except OSError as exc:
        raise _user_path(exc, temporary, target)  # noqa: B904  (the same exception, renamed)
    try:
        yield temporary
        files = sorted(set(_entries(temporary)) - {MANIFEST})
        atomic_write_text(temporary / MANIFEST, "\n".join([_MANIFEST_HEADER, *files]) + "\n")
        _replace_folder(temporary, target, what, owned)
    except BaseException as exc:
        shutil.rmtree(temporary, ignore_errors=True)  # only vgtarm writes in it
        for parent in reversed(created):  # the parents this call made, if still empty
            try:
                parent.rmdir()
            except OSError:
                break
        if isinstance(exc, OSError):
            failure = no_room_error(_user_path(exc, temporary, target), target, what)
            if failure is exc:
                raise  # the same exception, renamed
            raise failure from exc
        raise


# --- inputs ---------------------------------------------------------------------------------

#: Largest input file :func:`read_text_limited` reads by default (bytes): robot and study files are
#: a few kilobytes; a path CSV of a million rows is about 40 MB.
INPUT_LIMIT = 64 * 2**20
#: How an input is opened: never waiting for a writer (a named pipe that appeared after the check
#: is opened at once and refused by ``fstat``), never becoming the controlling terminal, not
#: inherited by the programs vgtarm runs.
_INPUT_FLAGS = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)


def _input_refusal(path: str | os.PathLike[str], what: str, found: os.stat_result, expected: str) -> str:
    """The one line refusing the input ``path`` (``found``: what ``stat`` sees there, links
    followed), which is not the ``expected`` kind (``"a file"``, ``"a folder"``)."""
    shown = _shown(os.fspath(path))
    if expected == "a file" and stat.S_ISDIR(found.st_mode):
        return f"{what} {shown}: is a folder, not a file"
    there = describe(path)  # a link is named as one, with what it leads to
    if there == "nothing":  # gone since it was looked at: what it was
        there = _kind(found.st_mode)
    regular = "a regular file" if expected == "a file" else "a folder"
    return f"{what} {shown}: is {there}; expected {regular}"


def _stat_input(path: str | os.PathLike[str], what: str, error: type[VgtarmError], kind: str) -> os.stat_result:
    """``os.stat(path)`` (links followed) or ``error`` in one line: an empty or invalid name, a
    missing path, one the system will not look up."""
    text = os.fspath(path)
    shown = _shown(text)
    if text == "":
        raise error(f"{what} '': expected a {kind} name")
    if "\0" in text:
        raise error(f"{what} {shown}: not a valid {kind} name (it holds a NUL character)")
    try:
        return os.stat(path)
    except FileNotFoundError:
        raise error(f"{what} {shown}: not found") from None
    except NotADirectoryError:
        raise error(f"{what} {shown}: not found (a part of the path is a file, not a folder)") from None
    except UnicodeError:  # characters with no bytes in the file system's encoding (possible only from Python)
        raise error(f"{what} {shown}: not a valid {kind} name on this system") from None
    except OSError as exc:  # no permission on a folder above, a loop of links, a name too long
        raise error(f"{what} {shown}: cannot read it: {cut(exc.strerror or str(exc), 120)}") from None


def check_input_file(
    path: str | os.PathLike[str], what: str = "input file", *, error: type[VgtarmError] = InputError
) -> os.stat_result:
    """Check, without opening it, that the input ``path`` is a regular file (a link to one
    included); returns what ``stat`` found.

    A named pipe (which would block the reader until a writer comes), a device (``/dev/zero``
    never ends, ``/dev/tty`` waits for the user), a socket or a folder is refused in one line
    naming ``what``, the path, what is there and what was expected, as are an empty name, a
    missing file and one the system will not look up; ``error`` is the class raised (a subclass
    of :class:`~vgtarm.errors.VgtarmError`: ``InputError``, ``ConfigError``, ``PathError``).
    Every reader of a user's file calls this (through :func:`open_input`) before it opens it.
    """
    found = _stat_input(path, what, error, "file")
    if not stat.S_ISREG(found.st_mode):
        raise error(_input_refusal(path, what, found, "a file"))
    return found


def check_input_folder(
    path: str | os.PathLike[str], what: str = "input folder", *, error: type[VgtarmError] = InputError
) -> os.stat_result:
    """Check that the input ``path`` is a folder (a link to one included), as
    :func:`check_input_file` checks a file: anything else is refused in one line."""
    found = _stat_input(path, what, error, "folder")
    if not stat.S_ISDIR(found.st_mode):
        raise error(_input_refusal(path, what, found, "a folder"))
    return found


def open_input(
    path: str | os.PathLike[str], what: str = "input file", *, error: type[VgtarmError] = InputError
) -> BinaryIO:
    """The input file ``path`` opened for reading (binary), after :func:`check_input_file`.

    It is opened without waiting (``O_NONBLOCK``) and looked at again on the open descriptor
    (``fstat``): a path that became a named pipe or a device between the check and the opening
    is refused as well, so no reader ever blocks on it. Failures raise ``error`` in one line.
    """
    check_input_file(path, what, error=error)
    shown = _shown(os.fspath(path))
    try:
        fd = os.open(path, _INPUT_FLAGS)
    except FileNotFoundError:
        raise error(f"{what} {shown}: not found") from None
    except OSError as exc:
        raise error(f"{what} {shown}: cannot read it: {cut(exc.strerror or str(exc), 120)}") from None
    try:
        found = os.fstat(fd)
        if not stat.S_ISREG(found.st_mode):  # it changed since the check
            raise error(_input_refusal(path, what, found, "a file"))
        os.set_blocking(fd, True)  # a regular file: reads as usual
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes_limited(
    path: str | os.PathLike[str],
    limit: int = INPUT_LIMIT,
    what: str = "input file",
    *,
    error: type[VgtarmError] = InputError,
) -> bytes:
    """The bytes of the input file ``path`` (:func:`open_input`), read only if it holds at most
    ``limit`` bytes (at most ``limit + 1`` are read, so a huge file never fills the memory)."""
    with open_input(path, what, error=error) as stream:
        try:
            data = stream.read(limit + 1)
        except OSError as exc:
            raise error(
                f"{what} {_shown(os.fspath(path))}: cannot read it: {cut(exc.strerror or str(exc), 120)}"
            ) from None
    if len(data) > limit:
        raise error(f"{what} {_shown(os.fspath(path))}: larger than {limit:,} bytes; expected a small text file")
    return data


def read_text_limited(
    path: str | os.PathLike[str],
    limit: int = INPUT_LIMIT,
    what: str = "input file",
    *,
    error: type[VgtarmError] = InputError,
    encoding: str = "utf-8",
) -> str:
    """The text of the input file ``path``, read only if it holds at most ``limit`` bytes.

    The path must be a regular file (:func:`check_input_file`): a named pipe, a device, a socket
    or a folder is refused before it is opened, so no read ever blocks or never ends. At most
    ``limit + 1`` bytes are read, so a huge file is refused without filling the memory. Every
    failure (an empty name, a missing file, not a regular file, no permission, too large, not
    ``encoding`` text) raises ``error`` (a subclass of :class:`~vgtarm.errors.VgtarmError`:
    ``InputError``, ``ConfigError``, ``PathError``) with one line naming ``what`` and ``path``.
    """
    data = read_bytes_limited(path, limit, what, error=error)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise error(
            f"{what} {_shown(os.fspath(path))}: not {encoding} text (byte {exc.start} cannot be decoded)"
        ) from None


def parse_toml(text: str, source: str, *, error: type[VgtarmError] = InputError) -> dict[str, Any]:
    """``text`` parsed as TOML, or ``error`` with one line starting with ``source`` (already cut
    for a message). Nesting too deep for the parser (``a = [[[[...]]]]``, which makes
    :mod:`tomllib` exceed the recursion limit) is refused like any syntax error."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{source}: not valid TOML: {cut(str(exc), 120)}") from None
    except RecursionError:
        raise error(f"{source}: not valid TOML: arrays or tables nested too deep") from None


def json_value(value: Any) -> Any:
    """``value`` as plain JSON data, for ``json.dumps`` of a record (``summary.json``, a study's
    run records): mappings with their keys, sequences and NumPy arrays as lists, NumPy scalars as
    Python numbers, and a non-finite number as ``None`` (JSON has no NaN or infinity)."""
    if isinstance(value, Mapping):
        return {key: json_value(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [json_value(item) for item in value]
    if hasattr(value, "tolist") and not isinstance(value, str | bytes):  # a NumPy array or scalar
        return json_value(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
