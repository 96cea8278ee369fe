"""One declaration per option of a run: its type, default, unit, bounds and help text.

An :class:`Option` says once what a value of a run may be. The records that hold the options
(:class:`vgtarm.simulation.Scenario`'s fields, declared with :func:`option`, and the experiment's own
in :mod:`vgtarm.experiment.options`) check their values with it; the command line's flags, the study
file's parameters and the presets are generated from the same declarations, so an option added to a
record appears in ``vgtarm simulate --help``, in a study's parameters and in a preset's keys without
being spelled again.

A value is checked in one message form that names the field, shows the value and says what was
expected with its unit: ``observer_gain = -1.0: expected a gain > 0 (1/s)``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import numbers
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import checks
from .errors import InputError, VgtarmError, shown

#: The values an option may take (a number, a flag, a name; None: "not set", the record's default).
Value = bool | int | float | str | None

#: Where an option counts in a study point's id: ``"always"`` (the study's parameters of the first
#: studies) or ``"optional"`` (only when set or away from its default, so an option added later
#: leaves the ids of existing studies as they were).
ID_ALWAYS = "always"
ID_OPTIONAL = "optional"


@dataclass(frozen=True)
class Option:
    """One option of a run.

    Attributes:
        name: the record's field, the study file's key and the preset's key.
        kind: ``bool``, ``int``, ``float`` or ``str``.
        default: the value when not given (None: decided by the run, e.g. the case's gain).
        expected: what a value must be, in words, with its unit (``"a gain > 0 (1/s)"``).
        help: the command line's help text.
        low, high: bounds of a number (None: none); ``strict``: ``low`` itself is refused.
        choices: the names a ``str`` option may take.
        flag: the command line's flag (default ``--name`` with dashes); ``""``: none.
        metavar: the command line's placeholder of the value.
        needs: ``(other, value)``: the option applies only when ``other`` has ``value`` (a preset's
            setting gives way when the user changes ``other``).
        in_id: :data:`ID_ALWAYS` or :data:`ID_OPTIONAL` (a study point's id).
        study: whether a study file may set it (grid, random draws).
        deferred: the record leaves its check to where the value meets the plant (a bound that
            depends on the robot: the limit tolerance); the command line and a study check its kind.
    """

    name: str
    kind: type
    default: Value
    expected: str
    help: str = ""
    low: float | None = None
    high: float | None = None
    strict: bool = False
    choices: tuple[str, ...] = ()
    flag: str | None = None
    metavar: str | None = None
    needs: tuple[str, Value] | None = None
    in_id: str = ID_OPTIONAL
    study: bool = True
    deferred: bool = False

    @property
    def cli_flag(self) -> str:
        """The command line's flag (``""``: the option has none)."""
        return f"--{self.name.replace('_', '-')}" if self.flag is None else self.flag

    def accepts(self, value: object) -> bool:
        """Whether ``value`` (of the option's kind) lies in its bounds and choices."""
        if self.choices and value not in self.choices:
            return False
        if self.kind in (int, float) and isinstance(value, int | float):
            number = value if self.kind is int else float(value)  # a whole number compared exactly (2**63 - 1)
            if not math.isfinite(number):
                return False
            if self.low is not None and (number < self.low or (self.strict and number == self.low)):
                return False
            if self.high is not None and number > self.high:
                return False
        return True

    def convert(self, value: object, *, where: str | None = None, error: type[VgtarmError] = InputError) -> Value:
        """``value`` as the option's kind (a NumPy scalar as Python's, an int as a float for a
        float option), checked; else ``error`` naming ``where`` (default the option's name), the
        value and what was expected. ``None`` passes when it is the default."""
        if value is None and self.default is None:
            return None
        converted = _as_kind(self.kind, value)
        if converted is _REFUSED or not self.accepts(converted):
            checks.refuse(where or self.name, value, self.expected, error)  # the package's one refusal
        return converted

    def argument_type(self) -> Any:
        """The ``type=`` of the command line's flag: the kind's parser that refuses a value out of
        the bounds in argparse's one line (argparse adds the flag)."""
        if self.kind is str:
            return str
        kind = self.kind

        def parse(text: str) -> Value:
            if not (text.isascii() and text.isprintable()):  # int() and float() read other scripts' digits too
                raise argparse.ArgumentTypeError(
                    f"expected a number written in ASCII digits (0-9), got {shown(text, 80)}"
                )
            refusal = argparse.ArgumentTypeError(f"expected {self.expected}, got {text}")
            try:
                value = kind(text)
            except ValueError:
                raise refusal from None
            if not self.accepts(value):
                raise refusal
            return value

        parse.__name__ = self.name  # argparse's message for a ValueError names the type
        return parse

    def add_to(self, parser: argparse.ArgumentParser) -> None:
        """Add the option's flag to ``parser`` (destination: the option's name)."""
        settings: dict[str, Any] = {"dest": self.name, "help": self.help}
        if self.kind is bool:
            settings["action"] = "store_true"
        else:
            settings.update(default=self.default, type=self.argument_type())
            if self.choices:
                settings["choices"] = self.choices
            if self.metavar is not None:
                settings["metavar"] = self.metavar
        parser.add_argument(self.cli_flag, **settings)


_REFUSED = object()


def _as_kind(kind: type, value: object) -> Any:
    """``value`` as ``kind``, or :data:`_REFUSED` (a bool is not a number; NumPy scalars are)."""
    if kind is bool:
        return bool(value) if isinstance(value, bool | np.bool_) else _REFUSED
    if kind is int:
        return int(value) if isinstance(value, numbers.Integral) and not isinstance(value, bool) else _REFUSED
    if kind is float:
        return float(value) if checks.is_number(value) else _REFUSED  # type: ignore[arg-type]
    return value if isinstance(value, str) else _REFUSED


#: The key of a dataclass field's metadata that holds its :class:`Option`.
_KEY = "vgtarm_option"


def option(default: Value, kind: type, expected: str, **settings: Any) -> Any:
    """A dataclass field declared as an option (its :class:`Option` in the field's metadata; the
    option's name is the field's, filled in by :func:`declared`)."""
    declaration = Option("", kind, default, expected, **settings)
    return field(default=default, metadata={_KEY: declaration})


def declared(record: Any) -> dict[str, Option]:
    """The options declared by the fields of the dataclass ``record`` (a class or an instance), by name, in order."""
    found: dict[str, Option] = {}
    for f in dataclasses.fields(record):
        declaration = f.metadata.get(_KEY)
        if declaration is not None:
            found[f.name] = dataclasses.replace(declaration, name=f.name)
    return found


def check_declared(record: Any) -> None:
    """Check every declared option of the dataclass instance ``record`` (:meth:`Option.convert`),
    storing the converted value (a frozen record too)."""
    for name, declaration in declared(record).items():
        if not declaration.deferred:
            object.__setattr__(record, name, declaration.convert(getattr(record, name)))


def by_flag(options: Mapping[str, Option]) -> Iterator[tuple[str, Option]]:
    """``(flag, option)`` of the options that have a command-line flag."""
    for declaration in options.values():
        if declaration.cli_flag:
            yield declaration.cli_flag, declaration
