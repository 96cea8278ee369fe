"""Why a compiled library cannot be had, in one line: the errors of the compile cache and its builds.

:class:`BackendError` is public (``VGTARM_BACKEND=compiled`` asked for what cannot be had); the two
others stay inside the model package: :class:`_Unavailable` becomes the interpreter fall-back's
line or a :class:`BackendError` (:func:`vgtarm.model.compiled.get_backend`), :class:`_Damaged`
(a check of :mod:`.library_cache` that failed) a removal and one rebuild (:mod:`.compiled`).
"""

from __future__ import annotations

from pathlib import Path

from ..errors import VgtarmError, shown


class BackendError(VgtarmError, RuntimeError):
    """``VGTARM_BACKEND=compiled`` was asked for, but the model cannot be compiled or loaded."""


class _Unavailable(Exception):
    """The compiled backend cannot be had; the message is the one-line reason."""


class _Damaged(Exception):
    """A cached library or its metadata fails a check; the message says which and how."""


def _shown_path(path: Path) -> str:
    """A cache path as a message shows it."""
    return shown(str(path), 160)
