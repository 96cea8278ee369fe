"""Shared by the tests of the model's build machinery (progress lines, ``-q``, Ctrl-C): the cheapest
stack whose build is a *long* one, and a child process that takes Ctrl-C as a terminal's
foreground command does."""

from __future__ import annotations

import dataclasses
import signal
from pathlib import Path

from vgtarm.model import budget
from vgtarm.model.definition import StackDefinition
from vgtarm.model.stack import load_stack, stack_to_toml

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: The name of the stack :func:`long_build_stack` writes.
LONG_BUILD_NAME = "one paper module"


def long_build_stack(folder: Path) -> Path:
    """The file of the smallest stack whose compiled build is estimated longer than
    :data:`vgtarm.model.budget.LONG_BUILD` (so that it shows its phases on a terminal): the paper's
    first module with its tool twist, 4 joints (about 10 s estimated, 7 s on two cores; the fits of
    2026-11-28, ``vgtarm.model.budget``: until the tool tasks' and the effort criterion's functions
    a 4-joint build was under the bound, and this was the paper's two modules without the twist)."""
    paper = load_stack(EXAMPLES / "paper_robot.toml")
    first, second = paper.modules
    stack = dataclasses.replace(paper, name=LONG_BUILD_NAME, modules=(dataclasses.replace(first, twist=second.twist),))
    estimate = budget.estimate(StackDefinition.of(stack))
    assert estimate.seconds("compiled") > budget.LONG_BUILD, estimate  # a long build, as the tests need
    path = folder / "one_module.toml"
    path.write_text(stack_to_toml(stack))
    return path


def home_of(config: Path) -> list[str]:
    """The home configuration of the stack in ``config``, as command-line arguments."""
    return [repr(float(v)) for v in load_stack(config).home]


def default_sigint() -> None:
    """``preexec_fn`` of a child that a test interrupts: SIGINT at its default disposition, as a
    shell starts a foreground command. A test runner started in the background (``cmd &`` in a
    script, ``nohup``) ignores SIGINT, and its children inherit an ignored signal: such a child
    would never see the test's Ctrl-C (each of these tests then failed after a 60 s timeout)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
