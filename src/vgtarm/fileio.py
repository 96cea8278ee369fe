"""Writing files so that a reader never sees a partial one."""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TextIO


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path to write in place of ``path``; it replaces ``path`` when the block ends.

    The temporary name is in the same folder and keeps the suffix (for writers that choose the
    format from it); the writer creates the file, so it gets the usual permissions
    (``tempfile.mkstemp`` would make it private to the user). On any error the temporary file is
    removed and ``path`` is left as it was.
    """
    target = Path(path)
    temporary = target.with_name(f".{target.stem}.{os.getpid()}.{secrets.token_hex(4)}.tmp{target.suffix}")
    try:
        yield temporary
        os.replace(temporary, target)
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
