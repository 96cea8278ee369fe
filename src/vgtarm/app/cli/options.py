"""Option types and options shared by the ``vgtarm`` commands (argparse ``type=`` callables that
refuse a bad value with argparse's own one-line message: ``argument --fps: expected a finite
number > 0, got -1.0``, the refusals of :mod:`vgtarm.checks` with argparse naming the option)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from ... import checks
from ...errors import shown


def _ascii(text: str) -> str:
    """``text``, refused (argparse's one line, which names the option) unless it is written in ASCII:
    Python's ``int`` and ``float`` also read other scripts' digits (``١٠٠``, Arabic-Indic, as 100;
    full-width digits), which a command line must not take silently for a number."""
    if not text.isascii():
        raise argparse.ArgumentTypeError(f"expected a number written in ASCII digits (0-9), got {shown(text, 80)}")
    return text


def number(text: str) -> float:
    """An option's number (``type=float`` of every ``vgtarm`` parser, see :func:`register_numbers`):
    written in ASCII only, else argparse's one line naming the option."""
    return float(_ascii(text))


def whole_number(text: str) -> int:
    """An option's whole number (``type=int`` of every ``vgtarm`` parser): ASCII only, as :func:`number`."""
    return int(_ascii(text))


def register_numbers(parser: argparse.ArgumentParser) -> None:
    """Make ``type=float`` and ``type=int`` of ``parser``'s options read ASCII numbers only
    (:func:`number`, :func:`whole_number`; argparse's own registry of types, looked up by the
    ``type`` given, so every option declared with the built-in types is covered)."""
    parser.register("type", float, number)
    parser.register("type", int, whole_number)


def _read(parse: Callable[[str], float], text: str) -> object:
    """``parse(text)``, or ``text`` itself if it is no number (then refused by the check, which shows it)."""
    try:
        return parse(text)
    except ValueError:
        return text


def positive_int(text: str) -> int:
    """An option's whole number >= 1."""
    return checks.whole("", _read(whole_number, text), 1, error=argparse.ArgumentTypeError)


def non_negative_int(text: str) -> int:
    """An option's whole number >= 0."""
    return checks.whole("", _read(whole_number, text), 0, error=argparse.ArgumentTypeError)


def seed_number(text: str) -> int:
    """``--seed``: a whole number from 0 to 2**63 - 1 (:data:`vgtarm.checks.MAX_SEED`, the range of
    every seed: a run's seed is stored as a 64-bit integer)."""
    return checks.seed("", _read(whole_number, text), error=argparse.ArgumentTypeError)


def positive_float(text: str) -> float:
    """An option's finite number > 0."""
    return checks.positive("", _read(number, text), error=argparse.ArgumentTypeError)


def add_config(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        metavar="FILE",
        help="robot TOML file (default: the shipped reference robot)",
    )
    add_model(parser)


def add_model(parser: argparse.ArgumentParser) -> None:
    """``--model symbolic|recursive``: a stack's model (:func:`vgtarm.model.robot.default_model` unless given)."""
    parser.add_argument(
        "--model",
        choices=("symbolic", "recursive"),
        default=None,
        help="a stack's model: the compiled symbolic library or the recursive O(n) one (default: $VGTARM_MODEL, "
        "else recursive from 7 modules on); the paper's robot is always symbolic",
    )


def joint_gains(text: str, option: str, joint_names: tuple[str, ...]) -> float | tuple[float, ...]:
    """The gain of ``option`` (``--kp``, ``--kv``): one number for every joint, or one per joint of
    ``joint_names`` separated by commas, each finite and > 0; else one line naming the option, the
    value and what was expected (:class:`~vgtarm.errors.InputError`): the one check of the gains,
    :func:`vgtarm.control.gains.gains_text`, which ``vgtarm export controller`` uses too."""
    from ...control.gains import gains_text

    return gains_text(text, option, joint_names)


def positive_int_at_most(largest: int, what: str) -> Callable[[str], int]:
    """An option type: a whole number from 1 to ``largest`` counting ``what`` (refused as "expected
    a whole number from 1 to {largest} ({what})")."""

    def parse(text: str) -> int:
        return checks.whole("", _read(whole_number, text), 1, largest, unit=what, error=argparse.ArgumentTypeError)

    return parse
