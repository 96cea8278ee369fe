"""The exported drilling controller (``vgtarm export drilling``): built with its own Makefile and
replayed on the encoder readings of a compiled run, its efforts and thrust estimate are the
simulation's bit for bit (admittance with the observer; explicit with the tip force sensor); its C
allocates nothing; a run the actuators cannot hold is refused in one line and nothing is written."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from vgtarm.drilling import compiled
from vgtarm.drilling.control import DrillingSettings
from vgtarm.drilling.loop import drilling_setup
from vgtarm.errors import InputError
from vgtarm.export.drilling import export_drilling, replay_inputs
from vgtarm.model.robot import load_robot

from .conftest import small_bone_of
from .test_drilling_control import FEMUR

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("make") is None or shutil.which("cc") is None, reason="no make or cc")


@pytest.fixture(scope="module")
def small_bone():
    return small_bone_of(1.0e-3, 1.2e-3, 1.0e-3)


def _replayed(folder: Path, text: str, n: int) -> tuple[np.ndarray, np.ndarray, list[int]]:
    subprocess.run(["make", "-s"], cwd=folder, check=True, capture_output=True)
    done = subprocess.run([str(folder / "vgtd_replay")], input=text, capture_output=True, text=True, check=True)
    rows = [line.split() for line in done.stdout.splitlines()]
    efforts = np.array([[float.fromhex(x) for x in row[:n]] for row in rows])
    estimate = np.array([float.fromhex(row[n]) for row in rows])
    return efforts, estimate, [int(row[-1]) for row in rows]


@pytest.mark.parametrize(
    ("mode", "feedback", "actuators"),
    [("admittance", "observer", False), ("explicit", "sensor", False), ("admittance", "observer", True)],
)
def test_the_export_is_the_simulation_bit_for_bit(robot, tight_robot, small_bone, tmp_path, mode, feedback, actuators):
    robot = tight_robot if actuators else robot
    settings = DrillingSettings(mode=mode, feedback=feedback, feed_limit=2.0e-3, gap=0.2e-3, duration=8.0)
    run = compiled.compiled_run(drilling_setup(robot, small_bone, settings), readings=True)
    assert run.status == compiled.STATUS["VGT_DONE"]
    folder = export_drilling(robot, small_bone, tmp_path / "drill", settings)
    efforts, estimate, phases = _replayed(folder, replay_inputs(run), robot.n_joints)
    assert efforts.shape == run.efforts.shape
    assert np.array_equal(efforts, run.efforts)  # every bit
    assert np.array_equal(estimate, run.series[:, 4])
    assert phases == [int(p) for p in run.series[:, 9]]
    if actuators:  # the exported controller clipped where the simulation's did
        assert np.any(np.abs(efforts) >= robot.actuators.force - 1e-12)
    for source in folder.glob("*.c"):
        code = re.sub(r"/\*.*?\*/", "", source.read_text(), flags=re.S)
        assert not re.search(r"\b(malloc|calloc|realloc|free)\s*\(", code), source.name


def test_a_set_point_the_actuators_cannot_hold_writes_nothing(small_bone, tmp_path):
    robot = load_robot(ROOT / "examples" / "paper_robot_with_actuators.toml")
    with pytest.raises(InputError, match=r"^set_point = 10000\.0: expected a thrust the actuators hold"):
        export_drilling(robot, small_bone, tmp_path / "drill", DrillingSettings(set_point=1.0e4))
    assert not (tmp_path / "drill").exists()
    assert list(tmp_path.iterdir()) == []


def test_the_command(tmp_path):
    import sys

    out = tmp_path / "drill"
    command = [sys.executable, "-m", "vgtarm", "export", "drilling", "--bone", str(FEMUR), "--out", str(out)]
    done = subprocess.run(command, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "make builds libvgtd.a and vgtd_replay" in done.stdout
    names = {p.name for p in out.iterdir()}
    assert {"vgtd_controller.c", "vgtd_defaults.c", "vgtc_model.c", "vgt_drill_control.h", "Makefile"} <= names
