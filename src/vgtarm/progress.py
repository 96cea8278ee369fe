"""Progress of long computations, reported by the code that does them and shown by whoever listens.

A long computation (the inverse kinematics of a long path, the functions ``vgtarm describe``
builds for a large stack) calls :func:`report` with how much of it is done; nothing listens by
default, so a call costs a context-variable lookup and library users see nothing. The command line
listens (:func:`listening`) and shows a progress bar on a terminal once the computation has run
for :data:`DELAY` seconds (:mod:`vgtarm.app.cli.bars`).

``vgtarm -q`` (any command's ``-q``) sets :func:`set_quiet`: then nothing is shown at all, the
progress lines of a model build included (:mod:`vgtarm.model.building` asks :func:`quiet`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from contextvars import ContextVar

#: Seconds a computation runs before its progress is shown (a shorter one shows nothing).
DELAY = 2.0

#: A listener: called as ``listener(done, total)``.
Listener = Callable[[int, int], None]

_LISTENER: ContextVar[Listener | None] = ContextVar("vgtarm_progress_listener", default=None)
_QUIET: list[bool] = [False]


def report(done: int, total: int) -> None:
    """Tell the current listener (if any) that ``done`` of ``total`` units of the running
    computation are done; a no-op when nobody listens."""
    listener = _LISTENER.get()
    if listener is not None:
        listener(int(done), int(total))


@contextlib.contextmanager
def listening(listener: Listener | None) -> Iterator[None]:
    """Send the :func:`report` calls made inside the block (in this thread or context) to
    ``listener``; None silences them."""
    token = _LISTENER.set(listener)
    try:
        yield
    finally:
        _LISTENER.reset(token)


def set_quiet(quiet: bool) -> None:
    """Show no progress of any kind in this process from now on (True), or allow it again."""
    _QUIET[0] = bool(quiet)


def quiet() -> bool:
    """Whether progress is silenced (``-q``)."""
    return _QUIET[0]
