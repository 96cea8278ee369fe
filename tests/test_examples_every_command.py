"""Every robot file that ships runs every command (issue 27, item 1).

One parametrised test over ``examples/*.toml`` x the commands a user has: ``describe``, ``fk``,
``ik``, ``simulate`` with both controllers and with the observer, ``reproduce``, ``draw``,
``animate``, ``report``, ``export mjcf``, ``check mujoco`` and ``study`` (run and report). Each robot
gets one folder (a module-scoped fixture) in which its three short runs are made once and the other
commands read them. Runs are short (``--duration``, a coarse ``--dt``, few states), so the whole
file stays within about a minute or two on two cores once the models are in the cache.

The long arm (``examples/tapered_thirty.toml``, 30 modules on the recursive model) runs every
command too. Each run solves the IK of a whole case path first (6,284 samples of case 1: about 9 s
of CPU at 30 modules since the IK of long arms was made robust, ``docs/ik.md``, "Long arms"), so it
is the file's longest robot: its three runs, ``study`` and ``reproduce`` (twelve runs, four IKs of
whole paths, the GA of ``2 n^2`` genes) take about 90 s of the file's CPU on a quiet 2-core machine.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

import vgtarm
from vgtarm.app.cli import main
from vgtarm.simulation import SimulationResult

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
ROBOTS = sorted(EXAMPLES.glob("*.toml"))
#: Seconds of each run: long enough for the loop, the GA's test and the observer to act.
DURATION = "0.05"
#: The simulate runs of every robot: (folder, extra options).
RUNS = {
    "cfc": ["--case", "1", "--controller", "cfc"],
    "scm": ["--case", "2", "--controller", "scm"],
    "observer": ["--case", "2", "--controller", "cfc", "--external-force", "--observer", "momentum"],
}


class Robot:
    """One example robot: its file, its folder of outputs, its loaded model and the task it tracks."""

    def __init__(self, config: Path, folder: Path) -> None:
        self.config, self.folder = config, folder
        self.robot = vgtarm.load_robot(config)
        self.planar = self.robot.n_joints == 3

    def run(self, argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
        """``vgtarm ARGV --config FILE`` in this process; its standard output (it must succeed)."""
        status = main([*argv, "--config", str(self.config)])
        out, err = capsys.readouterr()
        assert status == 0, f"vgtarm {' '.join(argv)} on {self.config.name}: exit {status}: {err[-2000:]}"
        return out


@pytest.fixture(scope="module", params=ROBOTS, ids=[p.stem for p in ROBOTS])
def example(request, tmp_path_factory) -> Robot:
    """The example robot with its three short runs saved by ``vgtarm simulate`` (shared by the commands)."""
    robot = Robot(request.param, tmp_path_factory.mktemp(request.param.stem))
    for name, options in RUNS.items():
        argv = ["simulate", *options, "--duration", DURATION, "--out", str(robot.folder / name), "-q"]
        assert main([*argv, "--config", str(robot.config)]) == 0, (robot.config.name, name)
    return robot


def _describe(r: Robot, capsys) -> None:
    out = r.run(["describe"], capsys)
    assert r.robot.parameters.name in out and "reach" in out


def _fk(r: Robot, capsys) -> None:
    out = r.run(["fk", *(repr(float(v)) for v in r.robot.parameters.home)], capsys)
    assert "tip" in out


def _ik(r: Robot, capsys) -> None:
    out = r.run(["ik", "--case", "2", "--dt", "0.05", "-o", str(r.folder / "ik.csv")], capsys)
    assert "all 81 samples solved and verified" in out
    assert ("tip (u2, u3) in its plane" in out) == r.planar
    rows = (r.folder / "ik.csv").read_text().splitlines()
    assert len(rows) == 82 and rows[0].count(",") == 3 + 3 * r.robot.n_joints


def _simulate(r: Robot, capsys) -> None:
    """The fixture made the runs: each one's summary says what ran and which task the IK tracked."""
    for name in RUNS:
        summary = json.loads((r.folder / name / "summary.json").read_text())
        # the start's transient scales with the arm (its path is scaled by its reach: 9.5 times at 30 modules)
        tolerance = 1e-3 * max(1.0, float(summary.get("path_scale") or 1.0))
        assert summary["success"] and summary["max_tip_error_m"] < tolerance, (name, summary["max_tip_error_m"])
        assert summary["controller"] == ("scm" if name == "scm" else "cfc")
        assert summary.get("ik_task") == ("tip (u2, u3) in its plane" if r.planar else None)
        loaded = SimulationResult.load(r.folder / name)  # as animate and report read it back
        assert loaded.joint_names == r.robot.joint_names and loaded.summary()["peak_force_n"] == summary["peak_force_n"]
    assert json.loads((r.folder / "observer" / "summary.json").read_text())["observer"] == "momentum"


def _reproduce(r: Robot, capsys) -> None:
    out_dir = r.folder / "reproduce"
    out = r.run(["reproduce", "--duration", DURATION, "--workers", "1", "-q", "--out", str(out_dir)], capsys)
    assert "report written to" in out
    report = (out_dir / "report.md").read_text()
    assert f"first {float(DURATION):g} s" in report and ("tip (u2, u3) in its plane" in report) == r.planar
    assert (out_dir / "report.html").is_file() and (out_dir / "case2_scm_force" / "summary.json").is_file()
    for summary_file in out_dir.glob("beyond/*_realistic/summary.json"):  # the low-force rows are cut too
        assert json.loads(summary_file.read_text())["simulated_time_s"] <= float(DURATION) + 1e-9, summary_file


def _draw(r: Robot, capsys) -> None:
    r.run(["draw", "--out", str(r.folder / "home.png")], capsys)
    assert (r.folder / "home.png").stat().st_size > 1000


def _animate(r: Robot, capsys) -> None:
    out = r.folder / "run.gif"
    r.run(["animate", str(r.folder / "cfc"), "--out", str(out), "--fps", "40", "--dpi", "30", "-q"], capsys)
    assert out.stat().st_size > 100


def _report(r: Robot, capsys) -> None:
    runs = [str(r.folder / name) for name in RUNS]
    r.run(["report", *runs, "--out", str(r.folder / "report")], capsys)
    page = (r.folder / "report" / "report.html").read_text()
    assert ("tip (u2, u3) in its plane" in page) == r.planar


def _export_mjcf(r: Robot, capsys) -> None:
    pytest.importorskip("mujoco")
    r.run(["export", "mjcf", "--out", str(r.folder / "robot.xml"), "--validate"], capsys)
    assert "<mujoco" in (r.folder / "robot.xml").read_text()


def _check_mujoco(r: Robot, capsys) -> None:
    pytest.importorskip("mujoco")
    out = r.run(["check", "mujoco", "--states", "20"], capsys)
    assert out.strip()


def _study(r: Robot, capsys) -> None:
    pytest.importorskip("dask.distributed")
    folder = r.folder / "study"
    folder.mkdir()
    shutil.copy(r.config, folder / "robot.toml")
    (folder / "study.toml").write_text(
        '[study]\nname = "every-command"\ncase = 1\nduration = 0.02\nrobot = "robot.toml"\nseeds = [0]\n\n'
        '[grid]\ncontroller = ["cfc"]\n'
    )
    status = main(["study", "run", str(folder / "study.toml"), "--out", str(folder / "runs"), "--workers", "1", "-q"])
    assert status == 0, capsys.readouterr().err[-2000:]
    assert main(["study", "report", str(folder / "runs")]) == 0, capsys.readouterr().err[-2000:]
    capsys.readouterr()
    assert (folder / "runs" / "report.md").is_file()


COMMANDS: dict[str, Callable[[Robot, pytest.CaptureFixture[str]], None]] = {
    "describe": _describe,
    "fk": _fk,
    "ik": _ik,
    "simulate": _simulate,
    "reproduce": _reproduce,
    "draw": _draw,
    "animate": _animate,
    "report": _report,
    "export mjcf": _export_mjcf,
    "check mujoco": _check_mujoco,
    "study": _study,
}


@pytest.mark.parametrize("command", list(COMMANDS), ids=[c.replace(" ", "-") for c in COMMANDS])
def test_every_example_robot_runs_every_command(example: Robot, command: str, capsys) -> None:
    COMMANDS[command](example, capsys)


def test_a_study_robot_file_gets_the_model_load_robot_gives() -> None:
    """A study reads its robot file's text (``robot_from_dict``): a long stack gets the recursive model, as
    ``load_robot`` gives it (its symbolic library would take hours and tens of GB to build)."""
    import tomllib

    from vgtarm.model.robot import robot_from_dict

    for config in ROBOTS:
        loaded = vgtarm.load_robot(config)
        parsed = robot_from_dict(tomllib.loads(config.read_text()), source=str(config))
        assert parsed.backend.kind == loaded.backend.kind, config.name
    long = robot_from_dict(tomllib.loads((EXAMPLES / "tapered_thirty.toml").read_text()))
    assert long.backend.kind == "recursive"
