"""Writing files and folders so that a reader never sees a partial one.

A single file goes to a temporary name in the same folder and is renamed over its target
(:func:`atomic_path`, :func:`atomic_open`, :func:`atomic_write_text`). A result folder is written
the same way as one unit (:func:`atomic_folder`): into a hidden temporary sibling
``.<name>.<pid>.<random>.tmp`` that replaces the old folder whole only when complete. Errors name
the user's path, never the temporary one. :func:`check_output_folder` and
:func:`check_output_file` check an output path before a command starts its work.

Replacing a folder: on Linux ``renameat2(RENAME_EXCHANGE)`` swaps the two folders in one atomic
step. Elsewhere (or on a file system without it) the old folder is renamed aside to
``.<name>.<pid>.<random>.old``, the new one renamed in, and the old one removed; a crash between
the two renames leaves no folder at the user's path but the old one aside, which the next run
into the same parent puts back (see :func:`clean_stale`).

A folder is replaced only if vgtarm wrote everything in it: each folder written by
:func:`atomic_folder` lists its files in ``.vgtarm-output``; a folder holding anything else (a
user's notes, a video rendered into it later) is refused, never deleted.
"""

from __future__ import annotations

import ctypes
import errno
import fnmatch
import os
import re
import secrets
import shutil
import tomllib
from collections.abc import Collection, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TextIO

from .errors import InputError, VgtarmError, cut

#: The list of files a folder written by :func:`atomic_folder` holds (one relative path a line).
MANIFEST = ".vgtarm-output"
_MANIFEST_HEADER = "# written by vgtarm as one unit; a later run replaces this folder only if it holds nothing else"
#: Names of temporary files and folders: ``.<name>.<pid>.<8 hex>.tmp[<suffix>]`` or ``....old``.
_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{8}\.(?P<kind>tmp|old)(?:\.[^.]*)?$")


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


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path to write in place of ``path``; it replaces ``path`` when the block ends.

    The temporary name is in the same folder and keeps the suffix (for writers that choose the
    format from it); the writer creates the file, so it gets the usual permissions
    (``tempfile.mkstemp`` would make it private to the user). On any error the temporary file is
    removed and ``path`` is left as it was; an ``OSError`` names ``path``, not the temporary file.
    """
    target = Path(path)
    temporary = target.with_name(_temporary_name(target.stem, suffix=target.suffix))
    try:
        yield temporary
        os.replace(temporary, target)
    except OSError as exc:
        temporary.unlink(missing_ok=True)
        raise _user_path(exc, temporary, target)  # noqa: B904  (the same exception, renamed)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


@contextmanager
def atomic_open(path: str | os.PathLike[str]) -> Iterator[TextIO]:
    """A text stream whose content replaces ``path`` only when the block ends without error."""
    with atomic_path(path) as temporary, open(temporary, "x", encoding="utf-8", newline="") as stream:
        yield stream


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_open`)."""
    with atomic_open(path) as stream:
        stream.write(text)
    return Path(path)


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # it exists but belongs to someone else
        return True
    return True


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def clean_stale(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files and folders left in ``folder`` by writers that were killed.

    Only names of the form :func:`atomic_path` and :func:`atomic_folder` make, of a process id
    that no longer runs on this machine, are touched. A folder set aside while a killed run
    replaced it (``.<name>.<pid>.<random>.old``) is put back when ``<name>`` is missing, else
    removed. Returns what was removed or put back. (It assumes the folder is not shared with
    writers on other machines, whose process ids mean nothing here.)
    """
    where = Path(folder)
    touched: list[Path] = []
    try:
        entries = list(os.scandir(where))
    except OSError:
        return touched
    for entry in entries:
        match = _TEMPORARY.match(entry.name)
        if match is None or _alive(int(match["pid"])):
            continue
        path = Path(entry.path)
        original = where / match["name"]
        try:
            if match["kind"] == "old" and entry.is_dir(follow_symlinks=False) and not original.exists():
                os.rename(path, original)
            else:
                _remove(path)
        except OSError:
            continue
        touched.append(path)
    return touched


def _files(folder: Path) -> set[str]:
    """Relative paths (POSIX form) of every file and empty folder under ``folder``."""
    found: set[str] = set()
    for root, dirs, files in os.walk(folder):
        relative = Path(root).relative_to(folder)
        found.update((relative / name).as_posix() for name in files)
        if not dirs and not files and root != os.fspath(folder):
            found.add(relative.as_posix() + "/")
    return found


def _manifest(folder: Path) -> set[str] | None:
    try:
        text = (folder / MANIFEST).read_text("utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    return {line for line in text.splitlines() if line and not line.startswith("#")}


def _foreign(folder: Path, owned: Collection[str]) -> str | None:
    """Why an existing folder may not be replaced (an entry vgtarm did not write), or None."""
    listed = _manifest(folder)
    if listed is not None:
        extra = sorted(_files(folder) - listed - {MANIFEST})
        return f"the folder holds {_shown(extra[0])!r}, which vgtarm did not write there" if extra else None
    for name in sorted(os.listdir(folder)):  # a folder written before the manifest existed
        if not ((folder / name).is_file() and any(fnmatch.fnmatchcase(name, p) for p in owned)):
            return f"the folder holds {_shown(name)!r} and no {MANIFEST} list of what vgtarm wrote there"
    return None


def _named(path: str | os.PathLike[str], what: str, kind: str) -> Path:
    """``path`` as a :class:`~pathlib.Path`, or :class:`~vgtarm.errors.InputError` if it cannot name
    anything: empty, or holding a NUL character (which the system refuses in any file name)."""
    text = os.fspath(path)
    if text == "":
        raise InputError(f"{what} '': expected a {kind} name")
    if "\0" in text:
        raise InputError(f"{what} {_shown(repr(text))}: a {kind} name cannot hold a NUL character")
    return Path(text)


def _unusable(exc: OSError, path: str | os.PathLike[str], what: str) -> InputError:
    """One line for a path the system will not even look up (a name too long, a loop of links)."""
    return InputError(f"{what} {_shown(str(path))}: cannot be used ({exc.strerror or type(exc).__name__})")


def check_writable_parent(path: str | os.PathLike[str], what: str = "output") -> None:
    """Raise :class:`~vgtarm.errors.InputError` (one line naming ``path``) unless the nearest
    existing folder above ``path`` is a folder we may write in (missing ones can be created)."""
    shown = _shown(str(path))
    try:
        ancestor = _named(path, what, "file").absolute().parent
        while not ancestor.exists() and not ancestor.is_symlink():
            ancestor = ancestor.parent
        is_folder = ancestor.is_dir()
    except OSError as exc:
        raise _unusable(exc, path, what) from exc
    if not is_folder:
        raise InputError(f"{what} {shown}: {_shown(str(ancestor))} is a file, not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise InputError(f"{what} {shown}: cannot write in {_shown(str(ancestor))} (permission denied)")


def _resolved(paths: Iterable[str | os.PathLike[str] | None]) -> list[Path]:
    return [Path(p).resolve() for p in paths if p is not None and os.fspath(p) != ""]


def check_output_folder(
    path: str | os.PathLike[str],
    what: str = "output folder",
    *,
    inputs: Iterable[str | os.PathLike[str] | None] = (),
    owned: Collection[str] = (),
) -> Path:
    """Check, before any work, that a result folder can be written at ``path`` as one unit.

    ``path`` must not be a file or a symbolic link; its nearest existing parent must be a folder
    we may write in; it must not be or hold one of ``inputs`` (the files or folders the command
    reads), nor the current folder; and an existing folder there must hold only what vgtarm wrote
    (the files listed in its ``.vgtarm-output``; for a folder without that list, only files whose
    names match one of the ``owned`` patterns). ``what`` names the path in messages (``--out``).

    Raises :class:`~vgtarm.errors.InputError` with one line naming ``path`` and what is wrong.
    """
    target = _named(path, what, "folder")
    try:
        return _check_output_folder(target, _shown(str(path)), what, inputs, owned)
    except OSError as exc:
        raise _unusable(exc, path, what) from exc


def _check_output_folder(
    target: Path, shown: str, what: str, inputs: Iterable[str | os.PathLike[str] | None], owned: Collection[str]
) -> Path:
    if target.is_symlink():
        raise InputError(f"{what} {shown}: is a symbolic link; give the folder itself or a new name")
    if target.exists() and not target.is_dir():
        raise InputError(f"{what} {shown}: is a file, not a folder; give a new folder name")
    check_writable_parent(target, what)
    resolved = target.resolve()
    if resolved == resolved.parent or resolved in (Path.cwd(), *Path.cwd().parents):
        raise InputError(f"{what} {shown}: is the current folder or holds it; give a folder below it")
    for source in _resolved(inputs):
        if source == resolved:
            raise InputError(f"{what} {shown}: is an input of this command; choose another folder")
        if resolved in source.parents:
            raise InputError(f"{what} {shown}: holds {_shown(str(source))}, an input of this command; choose another")
    if target.is_dir():
        foreign = _foreign(target, owned)
        if foreign is not None:
            raise InputError(f"{what} {shown}: {foreign}; give a new or empty folder, or move that away")
    return target


def check_output_file(
    path: str | os.PathLike[str], what: str = "output file", *, inputs: Iterable[str | os.PathLike[str] | None] = ()
) -> Path:
    """Check, before any work, that a file can be written at ``path``.

    ``path`` must not be a folder, nor one of ``inputs`` (the files the command reads), and its
    nearest existing parent must be a folder we may write in. Temporary files left beside it by
    killed runs are removed (:func:`clean_stale`). Raises :class:`~vgtarm.errors.InputError` with
    one line naming ``path`` and what is wrong.
    """
    target = _named(path, what, "file")
    try:
        return _check_output_file(target, _shown(str(path)), what, inputs)
    except OSError as exc:
        raise _unusable(exc, path, what) from exc


def _check_output_file(target: Path, shown: str, what: str, inputs: Iterable[str | os.PathLike[str] | None]) -> Path:
    if target.is_dir():
        raise InputError(f"{what} {shown}: is a folder; give a file name")
    resolved = target.resolve()
    for source in _resolved(inputs):
        if source == resolved or (target.exists() and source.exists() and os.path.samefile(source, target)):
            raise InputError(f"{what} {shown}: is an input of this command; writing it would destroy it")
    check_writable_parent(target, what)
    if target.parent.is_dir():
        clean_stale(target.parent)
    return target


def _exchange(first: Path, second: Path) -> bool:
    """Swap two folders in one atomic step (Linux ``renameat2``); False where that is not possible."""
    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(first), at_fdcwd, os.fsencode(second), rename_exchange) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EPERM):
        return False
    raise OSError(code, os.strerror(code), os.fspath(second))


def _replace_folder(new: Path, target: Path) -> None:
    """Put the complete folder ``new`` at ``target``, replacing a folder there whole."""
    if not target.exists() and not target.is_symlink():
        os.rename(new, target)  # fails if a folder appeared there meanwhile: nothing is lost
        return
    if target.is_symlink() or not target.is_dir():  # it changed since it was checked
        raise FileExistsError(errno.EEXIST, "exists and is not a folder", os.fspath(target))
    if _exchange(new, target):
        shutil.rmtree(new, ignore_errors=True)  # it now holds the old folder
        return
    aside = target.with_name(_temporary_name(target.name, kind="old"))
    os.rename(target, aside)
    try:
        os.rename(new, target)
    except BaseException:
        os.rename(aside, target)
        raise
    shutil.rmtree(aside, ignore_errors=True)


@contextmanager
def atomic_folder(
    path: str | os.PathLike[str],
    what: str = "output folder",
    *,
    inputs: Iterable[str | os.PathLike[str] | None] = (),
    owned: Collection[str] = (),
) -> Iterator[Path]:
    """A new empty temporary folder to fill in place of the folder ``path``; it replaces ``path``
    whole when the block ends without error.

    On entry the target is checked (:func:`check_output_folder`, with ``what``, ``inputs`` and
    ``owned``), stale temporary siblings of killed runs are cleaned (:func:`clean_stale`), missing
    parents are created and the temporary sibling ``.<name>.<pid>.<random>.tmp`` is made. On any
    error, Ctrl-C included, the temporary folder is removed and ``path`` is left as it was. The
    finished folder lists its files in ``.vgtarm-output``. An ``OSError`` names the user's path.
    """
    target = check_output_folder(path, what, inputs=inputs, owned=owned)
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
        files = sorted(_files(temporary) - {MANIFEST})
        atomic_write_text(temporary / MANIFEST, "\n".join([_MANIFEST_HEADER, *files]) + "\n")
        _replace_folder(temporary, target)
    except BaseException as exc:
        shutil.rmtree(temporary, ignore_errors=True)
        for parent in reversed(created):  # the parents this call made, if still empty
            try:
                parent.rmdir()
            except OSError:
                break
        if isinstance(exc, OSError):
            raise _user_path(exc, temporary, target)  # noqa: B904  (the same exception, renamed)
        raise


#: Largest input file :func:`read_text_limited` reads by default (bytes): robot and study files are
#: a few kilobytes; a path CSV of a million rows is about 40 MB.
INPUT_LIMIT = 64 * 2**20


def read_text_limited(
    path: str | os.PathLike[str],
    limit: int = INPUT_LIMIT,
    what: str = "input file",
    *,
    error: type[VgtarmError] = InputError,
    encoding: str = "utf-8",
) -> str:
    """The text of the input file ``path``, read only if it holds at most ``limit`` bytes.

    At most ``limit + 1`` bytes are read, so an endless device (``/dev/zero``) or a huge file is
    refused without filling the memory. Every failure (an empty name, a missing file, a folder,
    no permission, too large, not ``encoding`` text) raises ``error`` (a subclass of
    :class:`~vgtarm.errors.VgtarmError`: ``InputError``, ``ConfigError``, ``PathError``) with one
    line naming ``what`` and ``path``.
    """
    shown = _shown(os.fspath(path))
    if os.fspath(path) == "":
        raise error(f"{what} '': expected a file name")
    try:
        with open(path, "rb") as stream:
            data = stream.read(limit + 1)
    except FileNotFoundError:
        raise error(f"{what} {shown}: not found") from None
    except IsADirectoryError:
        raise error(f"{what} {shown}: is a folder, not a file") from None
    except OSError as exc:
        raise error(f"{what} {shown}: cannot read it: {cut(exc.strerror or str(exc), 120)}") from None
    except ValueError:  # a NUL character: no file can have that name
        raise error(f"{what} {shown}: not a valid file name (it holds a NUL character)") from None
    if len(data) > limit:
        raise error(f"{what} {shown}: larger than {limit:,} bytes; expected a small text file")
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise error(f"{what} {shown}: not {encoding} text (byte {exc.start} cannot be decoded)") from None


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
