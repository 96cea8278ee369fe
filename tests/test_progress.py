"""Progress on anything longer than two seconds (issue 27, item 4): the inverse kinematics of a path
(``vgtarm ik``, the reference inside ``simulate``) and ``describe`` of a stack show a bar on a
terminal once they have run for :data:`vgtarm.progress.DELAY` seconds; ``-q`` silences every kind
of progress, a model build's lines included; without a terminal nothing is shown.

The commands run in this process with standard error replaced by a stream that says it is a
terminal (the delay set to zero, so that a short run shows its bar), and a model build runs as a
real command on a pseudo-terminal.
"""

from __future__ import annotations

import io
import os
import sys
import time
from pathlib import Path

import pytest

from vgtarm import progress
from vgtarm.app.cli import bars
from vgtarm.app.cli.command import build_parser, main
from vgtarm.model import compiled
from vgtarm.model.stack import load_stack

from .build_support import home_of, long_build_stack
from .conftest import run_on_terminal

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCRIPT = Path(sys.executable).parent / "vgtarm"


class Terminal(io.StringIO):
    """A text stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


@pytest.fixture(autouse=True)
def _not_quiet():
    progress.set_quiet(False)
    yield
    progress.set_quiet(False)


def run(argv: list[str], monkeypatch: pytest.MonkeyPatch, stream: io.StringIO, delay: float = 0.0) -> tuple[int, str]:
    """``vgtarm argv`` in this process with ``stream`` as standard error; its status and what it showed."""
    monkeypatch.setattr(progress, "DELAY", delay)
    monkeypatch.setattr(sys, "stderr", stream)
    status = main(argv)
    monkeypatch.undo()
    return status, stream.getvalue()


def bar_states(shown: str, what: str) -> list[tuple[int, int]]:
    """The ``done/total`` counts of every drawing of the bar ``vgtarm: <what>``."""
    states = []
    for piece in shown.split("\r"):
        if piece.startswith(f"vgtarm: {what}:"):
            counts = piece.split("|")[2].split()[0]
            done, total = counts.split("/")
            states.append((int(done), int(total)))
    return states


@pytest.mark.parametrize(("solver", "dt", "samples"), [("fast", "0.05", 126), ("slsqp", "0.02", 315)])
def test_ik_of_a_path_shows_a_bar_on_a_terminal(
    solver: str, dt: str, samples: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    status, shown = run(["ik", "--case", "1", "--dt", dt, "--solver", solver], monkeypatch, Terminal())
    assert status == 0
    states = bar_states(shown, "inverse kinematics")  # drawn at most every 0.1 s (tqdm's default)
    assert states, shown
    assert {total for _, total in states} == {samples}  # the path's samples
    done = [d for d, _ in states]
    assert done == sorted(done) and done[-1] <= samples
    if solver == "slsqp":  # one report a sample (about 1 ms each): the bar advances while it runs
        assert len(set(done)) >= 2, shown
    assert shown.endswith("\r"), "the bar is removed at the end (the summary follows on standard output)"


def test_progress_reaches_the_end_of_the_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every report the solvers make, in order: they end at the path's length."""
    import vgtarm
    from vgtarm import paths

    robot, path = vgtarm.load_robot(), paths.case1(0.05)
    seen: list[tuple[int, int]] = []
    for solver in ("fast", "slsqp"):
        seen.clear()
        with progress.listening(lambda done, total: seen.append((done, total))):
            robot.inverse_kinematics(path, solver=solver)
        assert seen and seen[-1] == (len(path), len(path)), (solver, seen[-3:])
        assert [d for d, _ in seen] == sorted(d for d, _ in seen)
    seen.clear()
    robot.inverse_kinematics(path)  # nobody listens: nothing is reported anywhere
    assert seen == []


def test_a_short_computation_shows_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    status, shown = run(["ik", "--case", "1", "--dt", "0.05"], monkeypatch, Terminal(), delay=progress.DELAY)
    assert status == 0 and shown == ""


def test_without_a_terminal_nothing_is_shown(monkeypatch: pytest.MonkeyPatch) -> None:
    status, shown = run(["ik", "--case", "1", "--dt", "0.05", "--solver", "slsqp"], monkeypatch, io.StringIO())
    assert status == 0 and shown == ""


@pytest.mark.parametrize(
    "argv",
    [
        ["ik", "-q", "--case", "1", "--dt", "0.05", "--solver", "slsqp"],
        ["describe", "-q", "--config", str(EXAMPLES / "six_modules.toml")],
        ["simulate", "-q", "--case", "1", "--duration", "0.02"],
    ],
    ids=["ik", "describe", "simulate"],
)
def test_quiet_shows_nothing_even_on_a_terminal(argv: list[str], monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    monkeypatch.chdir(tmp_path)
    status, shown = run(argv, monkeypatch, Terminal())
    assert status == 0 and shown == ""


def test_describe_of_a_stack_shows_its_steps(monkeypatch: pytest.MonkeyPatch) -> None:
    status, shown = run(["describe", "--config", str(EXAMPLES / "six_modules.toml")], monkeypatch, Terminal())
    assert status == 0
    states = bar_states(shown, "describe: the model at home")
    assert states and {total for _, total in states} == {3}  # the tip's function, the mass matrix's, evaluation
    assert 1 <= states[-1][0] <= 3  # drawn at most every 0.1 s: the last step may go undrawn
    from vgtarm.app.cli.stack import home_figures

    seen: list[tuple[int, int]] = []
    with progress.listening(lambda done, total: seen.append((done, total))):
        home_figures(load_stack(EXAMPLES / "six_modules.toml"))
    assert seen == [(1, 3), (2, 3), (3, 3)]


def test_simulate_shows_the_reference_bar(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    monkeypatch.chdir(tmp_path)
    status, shown = run(["simulate", "--case", "1", "--duration", "0.02"], monkeypatch, Terminal())
    assert status == 0
    assert bar_states(shown, "inverse kinematics"), shown


def test_every_command_takes_quiet() -> None:
    parser = build_parser()
    commands = [
        ["describe"],
        ["fk", "0", "0", "0", "0", "0", "0", "0"],
        ["ik", "--case", "1"],
        ["simulate", "--case", "1"],
        ["reproduce"],
        ["convert-robot", "--out", "x.toml"],
    ]
    for argv in commands:
        assert parser.parse_args([*argv, "-q"]).quiet is True, argv
        assert parser.parse_args(argv).quiet is False, argv
    subparsers = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    pending = list(subparsers.choices.items())  # type: ignore[attr-defined]
    while pending:
        name, command = pending.pop()
        nested = [a for a in command._actions if a.__class__.__name__ == "_SubParsersAction"]
        if nested:
            pending += [(f"{name} {k}", v) for k, v in nested[0].choices.items()]  # type: ignore[attr-defined]
        else:
            assert "-q" in command._option_string_actions, name


def test_bar_helper_is_silent_with_quiet_and_off_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(progress, "DELAY", 0.0)
    for quiet, stream in ((True, Terminal()), (False, io.StringIO())):
        progress.set_quiet(quiet)
        with bars.progress_bar("work", "step", 4, stream=stream):
            for k in range(1, 5):
                progress.report(k, 4)
        assert stream.getvalue() == ""
    progress.set_quiet(False)
    stream = Terminal()
    with bars.progress_bar("work", "step", 4, stream=stream):
        for k in range(1, 5):
            time.sleep(0.12)  # longer than tqdm's shortest interval between two drawings (0.1 s)
            progress.report(k, 4)
    assert bar_states(stream.getvalue(), "work") == [(0, 4), (1, 4), (2, 4), (3, 4), (4, 4)]


@pytest.mark.skipif(compiled.find_compiler() is None, reason="no C compiler")
def test_quiet_silences_a_model_build_on_a_terminal(tmp_path: Path) -> None:
    """The cheapest long build (one module, about 10 s estimated: it shows its phases on a terminal,
    tests/test_build_budget.py) shows nothing with ``-q``."""
    cache = tmp_path / "cache"
    cache.mkdir(mode=0o700)
    config = long_build_stack(tmp_path)
    home = home_of(config)
    env = {k: v for k, v in os.environ.items() if not k.startswith("VGTARM_")}
    env["VGTARM_CACHE_DIR"] = str(cache)
    status, out, shown = run_on_terminal([str(SCRIPT), "fk", "-q", "--config", str(config), *home], env)
    assert status == 0 and b"tip" in out
    assert shown == b""
    assert any(p.suffix == ".so" for p in cache.iterdir()), "a model was built"
