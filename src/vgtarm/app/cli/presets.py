"""The state estimator's and the tool-force feedforward's options and the named low-force preset of
``vgtarm simulate`` (issue 22).

Kept apart from the command-line module: :func:`add_simulate_options` adds ``--estimator``,
``--estimator-bandwidth``, ``--tool-feedforward``, ``--tool-force-speed`` and ``--preset`` to a
parser, :func:`apply_preset` fills a preset's settings into the parsed arguments (those the user did not give,
known from :func:`record_defaults`), and
:func:`simulate_options` gives the scenario's options.
The presets themselves are defined once, in :mod:`vgtarm.app.presets` (``vgtarm reproduce`` runs
them too); their choice and the measured front are in ``docs/control.md``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ...simulation.external import DEFAULT_FEEDFORWARD_SPEED
from ...simulation.sensing import DEFAULT_ESTIMATOR_BANDWIDTH_HZ, ESTIMATORS
from ..presets import PRESETS, WITH_TOOL_FORCE, preset_text

#: Preset arguments that the command line takes as text (a gain for every joint or one per joint).
GAIN_TEXT = frozenset({"kp", "kv"})

__all__ = ["PRESETS", "add_simulate_options", "apply_preset", "record_defaults", "simulate_options"]


def add_simulate_options(parser: argparse.ArgumentParser) -> None:
    """``--estimator``, ``--estimator-bandwidth``, the feedforward's options and ``--preset`` on ``parser``."""

    parser.add_argument(
        "--estimator",
        choices=ESTIMATORS,
        default="difference",
        help="with encoders: velocities from differences through the filter (default), or a Kalman filter "
        "with the controller model's dynamics (and, with the observer, the disturbance) as its process model",
    )
    parser.add_argument(
        "--estimator-bandwidth",
        type=float,
        default=None,
        metavar="HZ",
        help=f"--estimator kalman: its bandwidth (default {DEFAULT_ESTIMATOR_BANDWIDTH_HZ:g} Hz, at most 1/(4 dt))",
    )
    parser.add_argument(
        "--tool-feedforward",
        action="store_true",
        help="with --external-force: feed the expected cutting force (its model along the reference's tip "
        "velocity) forward through J_P^T; the observer and the Kalman estimator estimate the rest",
    )
    parser.add_argument(
        "--tool-force-speed",
        type=float,
        default=None,
        metavar="V",
        help=f"--tool-feedforward: speed in m/s over which the expected force is smoothed where the tool starts, "
        f"turns or stops (default {DEFAULT_FEEDFORWARD_SPEED:g})",
    )
    parser.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default=None,
        help="named settings (an option you set away from its default keeps your value); low-force: "
        + preset_text("low-force"),
    )


def record_defaults(parser: argparse.ArgumentParser) -> None:
    """Keep on ``parser``'s parsed arguments the defaults of every option a preset sets (call it once
    all of them are added), so that :func:`apply_preset` can tell the options the user gave."""
    keys = sorted({key for preset in PRESETS.values() for key in preset})
    parser.set_defaults(preset_defaults={key: parser.get_default(key) for key in keys})


def apply_preset(args: argparse.Namespace) -> None:
    """Set the arguments of ``args.preset`` (none: nothing changes). An option the user gave keeps the
    user's value (``--preset low-force --kp 10000``: the preset's other settings with that gain): an
    argument differing from its default recorded by :func:`record_defaults` (without them, every
    argument of the preset is set)."""
    defaults = getattr(args, "preset_defaults", None) or {}
    for key, value in PRESETS.get(getattr(args, "preset", None) or "", {}).items():
        if key in WITH_TOOL_FORCE and not getattr(args, "external_force", False):
            continue  # as preset_options: the feedforward and its gains only with the tool force
        if key in defaults and getattr(args, key, None) != defaults[key]:
            continue  # given by the user
        setattr(args, key, repr(value) if key in GAIN_TEXT else value)


def simulate_options(args: argparse.Namespace) -> dict[str, Any]:
    """The scenario options of the estimator and feedforward arguments (none with the defaults: the
    runs of before)."""
    options: dict[str, Any] = {}
    if not (args.estimator == "difference" and args.estimator_bandwidth is None):
        options.update(estimator=args.estimator, estimator_bandwidth_hz=args.estimator_bandwidth)
    if getattr(args, "tool_feedforward", False) or getattr(args, "tool_force_speed", None) is not None:
        options.update(tool_force_feedforward=bool(args.tool_feedforward), tool_force_speed=args.tool_force_speed)
    return options
