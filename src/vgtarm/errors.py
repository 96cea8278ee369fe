"""Project exceptions.

Every error a user can cause derives from :class:`VgtarmError` and from the matching
built-in (``ValueError`` for bad values, ``RuntimeError`` for runs that fail), so callers can
catch either. Messages name the field, the offending value and what was expected.
"""

from __future__ import annotations


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
