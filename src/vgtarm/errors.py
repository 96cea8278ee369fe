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
