"""Project exceptions.

Every error a user can cause derives from :class:`VgtarmError` and from the matching
built-in (``ValueError`` for bad values, ``RuntimeError`` for runs that fail), so callers can
catch either. Messages name the field, the offending value and what was expected.
"""

from __future__ import annotations

#: Longest rendering of a user's value in a message (the rest is cut, saying how much).
SHOWN_LENGTH = 60
#: Longest message the command line prints (a last guard; messages should stay far below).
MESSAGE_LENGTH = 400


def escape(text: str) -> str:
    """``text`` with control and other unprintable characters escaped (``\\x1b``), so that a
    message can never drive the user's terminal."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


def cut(text: str, limit: int = SHOWN_LENGTH) -> str:
    """``text`` escaped and cut to about ``limit`` characters, saying how many were left off."""
    text = escape(text)
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text) - limit} more characters)"


def shown(value: object, limit: int = SHOWN_LENGTH) -> str:
    """A user's value as it appears in a message: its ``repr``, escaped and cut to ``limit``."""
    try:
        text = repr(value)
    except Exception:  # a user's object whose repr fails still gets a message
        text = f"<{type(value).__name__}>"
    return cut(text, limit)


class VgtarmError(Exception):
    """Base class of every error raised by vgtarm on purpose."""


class Terminated(KeyboardInterrupt):
    """A SIGTERM while the ``vgtarm`` program runs, raised by its entry point (:mod:`vgtarm._entry`).

    A ``KeyboardInterrupt``, so that it unwinds a command as Ctrl-C does and every clean-up that
    undoes a Ctrl-C undoes it too; the program then ends with the line ``vgtarm: terminated`` and
    status 143. :attr:`arrived` stays True once one came: a library may swallow the exception
    (CasADi does, raised inside one of its own calls), so the writers of :mod:`vgtarm.fileio`
    raise it again before they put a result in place, and the program ends with status 143
    whatever happened to the exception."""

    #: Whether a SIGTERM arrived since the program started.
    arrived = False


class ConfigError(VgtarmError, ValueError):
    """A robot configuration (TOML file or parameters) is invalid."""


class AssemblyError(VgtarmError, ValueError):
    """A leg set of a VGT module cannot be assembled (a triangle inequality fails)."""


class InputError(VgtarmError, ValueError):
    """An argument passed to a public function has the wrong shape, type or value."""


class PathError(VgtarmError, ValueError):
    """A desired path (waypoints, CSV file, case parameters) is invalid."""


class UnreachableError(VgtarmError, RuntimeError):
    """Inverse kinematics could not reach a target point of the path."""


class SimulationError(VgtarmError, RuntimeError):
    """A closed-loop simulation diverged; ``result`` keeps the samples up to the failure."""

    def __init__(self, message: str, result: object = None) -> None:
        super().__init__(message)
        self.result = result


def refuse_masked(value: object, name: str, error: type[VgtarmError] = InputError) -> None:
    """Refuse, in one ``error`` line naming ``name``, a NumPy masked array with masked entries.

    NumPy's conversions (``np.asarray``, ``np.array``) drop the mask and keep the values under it,
    which would be used without a word; the shared converters of the public API's array arguments
    call this first. A masked array with no entry masked is its data and passes."""
    import numpy as np  # loaded already by whoever passes an array; this module stays import-light

    if not isinstance(value, np.ma.MaskedArray):
        return
    mask = np.ma.getmaskarray(value)
    if not mask.any():
        return
    first = tuple(int(i) for i in np.argwhere(mask)[0])
    where = f"[{', '.join(str(i) for i in first)}]"
    count = int(mask.sum())
    entries = "1 masked entry (at" if count == 1 else f"{count:,} masked entries (the first at"
    raise error(
        f"{name} is a masked array with {entries} {where}): expected "
        "numbers without a mask; fill them first (.filled(value)), or pass .data if the hidden values are meant"
    )
