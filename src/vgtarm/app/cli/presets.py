"""``vgtarm simulate --preset``: the flag, the preset's settings filled into the parsed arguments,
and what the user typed.

:func:`add_preset_flag` adds ``--preset`` to a parser, :func:`apply_preset` fills a preset's settings
into the parsed arguments (those the user did not type, known from :func:`record_given`: what argparse
took from the command line, not a comparison with the defaults; which settings apply beside the
user's options is :func:`vgtarm.experiment.presets.applied_settings`'s rule), and :func:`named` says
which values a refusal's message holds came from the preset. The presets themselves are defined once,
in :mod:`vgtarm.experiment.presets` (``vgtarm reproduce`` runs them too); their choice and the
measured front are in ``docs/control.md``.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from ...errors import InputError
from ...experiment.options import all_options
from ...experiment.presets import PRESETS, applied_settings, preset_text

#: Preset arguments that the command line takes as text (a gain for every joint or one per joint).
GAIN_TEXT = frozenset({"kp", "kv"})
#: The parsed arguments' set of the destinations of the options the user typed (:func:`record_given`).
GIVEN = "given_options"
#: The parsed arguments' record of what :func:`apply_preset` set: ``{argument: value}``.
APPLIED = "preset_applied"

__all__ = [
    "GIVEN",
    "PRESETS",
    "add_preset_flag",
    "apply_preset",
    "given",
    "named",
    "record_given",
]


def add_preset_flag(parser: argparse.ArgumentParser) -> None:
    """``--preset`` on ``parser``."""
    parser.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default=None,
        help="named settings (an option you give keeps your value, and the settings that go with the one it "
        "replaces give way: --observer none drops the observer's gain, --force-sensor the observer and the "
        "feedforward); low-force: " + preset_text("low-force") + " (the gains with --controller cfc only)",
    )


#: The recording subclass of each argparse action class (:func:`_recording`).
_RECORDING: dict[type[argparse.Action], type[argparse.Action]] = {}


def _recording(kind: type[argparse.Action]) -> type[argparse.Action]:
    """``kind`` that also adds its destination to the parsed arguments' :data:`GIVEN` when argparse
    takes it from the command line (argparse calls an option's action only then)."""
    if kind not in _RECORDING:

        def call(self: argparse.Action, parser: Any, namespace: Any, values: Any, option_string: Any = None) -> None:
            kind.__call__(self, parser, namespace, values, option_string)
            setattr(namespace, GIVEN, getattr(namespace, GIVEN, frozenset()) | {self.dest})

        _RECORDING[kind] = type(f"Given{kind.__name__}", (kind,), {"__call__": call})
    return _RECORDING[kind]


def record_given(parser: argparse.ArgumentParser) -> None:
    """Make ``parser`` record, in its parsed arguments' :data:`GIVEN` (a frozenset of destinations),
    every option argparse takes from the command line (call it once all options are added): an
    option the user typed, even with its default value (``--observer none``), is told from one left
    out by what was parsed, never by comparing values with the defaults."""
    parser.set_defaults(**{GIVEN: frozenset()})
    for action in parser._actions:  # argparse's list of the parser's actions (stable since 3.2)
        if action.option_strings and not isinstance(action, argparse._HelpAction | argparse._VersionAction):
            action.__class__ = _recording(type(action))


def given(args: argparse.Namespace, key: str) -> bool:
    """Whether the user typed the option whose destination is ``key`` (:func:`record_given`)."""
    return key in getattr(args, GIVEN, frozenset())


def apply_preset(args: argparse.Namespace) -> None:
    """Set the arguments of ``args.preset`` (none: nothing changes), recorded in ``args``'s
    :data:`APPLIED`. An option the user typed keeps the user's value (``--preset low-force --kp
    10000``: the preset's other settings with that gain; ``--observer none``: no observer, and so
    none of its gain), known from :data:`GIVEN` (:func:`record_given`; without it, every argument
    of the preset is set); a setting that needs what the user replaced gives way
    (:func:`vgtarm.experiment.presets.applies`)."""
    name = getattr(args, "preset", None) or ""
    applied: dict[str, Any] = {}
    if name:
        values = {key: getattr(args, key) for key in all_options() if hasattr(args, key)}
        typed = {key: values[key] for key in values if given(args, key)}
        for key, value in applied_settings(name, typed, values).items():
            setattr(args, key, repr(value) if key in GAIN_TEXT else value)
            applied[key] = value
    setattr(args, APPLIED, applied)


def _settings_text(applied: dict[str, Any]) -> str:
    """``--criterion effort, --observer momentum, ...``: the preset's settings as options."""

    def value_text(value: Any) -> str:
        return "" if value is True else f" {value:g}" if isinstance(value, float) else f" {value}"

    options = all_options()
    return ", ".join(f"{options[key].cli_flag or '--' + key}{value_text(value)}" for key, value in applied.items())


@contextmanager
def named(args: argparse.Namespace) -> Iterator[None]:
    """Around a command's work after :func:`apply_preset`: first refuses in one line naming the
    preset a setting of it that cannot run beside the user's options (its Kalman estimator reads
    encoders: without ``--encoder-resolution``); then a refusal (:class:`InputError`) of the work is
    said to come with the values the preset set, so that none of them reads as if the user typed it."""
    applied = getattr(args, APPLIED, None) or {}
    preset = getattr(args, "preset", "")
    if applied.get("estimator") == "kalman" and not getattr(args, "encoder_resolution", 0.0):
        raise InputError(
            f"--preset {preset} sets --estimator kalman, which estimates the state from encoder counts: expected "
            "--encoder-resolution R (the preset was chosen with 1e-6 m), or --estimator difference"
        )
    try:
        yield
    except InputError as exc:
        if not applied:
            raise
        raise InputError(f"with --preset {preset}, which set {_settings_text(applied)}: {exc}") from None
