"""The posture stiffest along the tool's axis (``vgtarm.design.stiffest_posture``): it keeps the
tool point and axis (to 1e-9), no feasible neighbour along the self-motion is stiffer (sampled
independently: Newton back onto the task from random null-space steps), the symmetric home is the
stiffest for its vertical axis, a robot without springs is refused, and the drilling loop holds the
posture it is given."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

import vgtarm
from vgtarm.design.posture import LIMIT_MARGIN, _frame, axial_compliance, stiffest_posture
from vgtarm.design.stiffness import joint_stiffness
from vgtarm.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def soft():
    return vgtarm.load_robot(ROOT / "examples" / "paper_robot_compliant.toml")


def _neighbours(robot, q, axis, tip, count, step, seed):
    """Feasible postures near ``q`` with the same tool point and axis."""
    e1, e2 = _frame(axis)

    def task(x):
        a = robot.tool_axis(x)
        return np.concatenate([robot.tip_position(x) - tip, [e1 @ a, e2 @ a]])

    def jac(x):
        a, Jw = robot.tool_axis(x), robot.angular_jacobian(x)
        turn = np.cross(Jw.T, a)
        return np.vstack([robot.tip_jacobian(x), (turn @ e1)[None], (turn @ e2)[None]])

    rng = np.random.default_rng(seed)
    null = scipy.linalg.null_space(jac(q))
    for _ in range(count):
        x = q + null @ rng.normal(0.0, step, null.shape[1])
        for _ in range(30):
            x = x - np.linalg.pinv(jac(x)) @ task(x)
        assert np.max(np.abs(task(x))) < 1e-12
        yield x


def test_the_posture_keeps_the_tool_and_no_neighbour_is_stiffer(soft):
    q0 = soft.parameters.home + np.array([0.03, -0.02, 0.01, -0.02, 0.03, 0.0, 0.3])
    found = stiffest_posture(soft, q0)
    assert np.allclose(soft.tip_position(found.q), soft.tip_position(q0), atol=1e-9)
    assert np.allclose(soft.tool_axis(found.q), soft.tool_axis(q0), atol=1e-9)
    assert found.stiffness > 1.02 * found.stiffness0  # 3 % stiffer than the start here
    k = joint_stiffness(soft)
    tip = soft.tip_position(q0)
    best = axial_compliance(soft, found.q, found.axis, 20.0, k)
    assert best == pytest.approx(found.compliance, rel=1e-12)
    lower, upper = soft.joint_limits()
    low, high = lower + LIMIT_MARGIN * (upper - lower), upper - LIMIT_MARGIN * (upper - lower)
    assert np.any(np.isclose(found.q, low) | np.isclose(found.q, high))  # here a limit bounds it
    checked = 0
    for x in _neighbours(soft, found.q, found.axis, tip, 60, 0.01, seed=4):
        if np.all((x >= low) & (x <= high)):  # the feasible ones
            checked += 1
            assert axial_compliance(soft, x, found.axis, 20.0, k) >= best * (1 - 1e-9)
    assert checked >= 10


def test_home_is_the_stiffest_for_its_axis(soft):
    home = soft.parameters.home
    q0 = next(_neighbours(soft, home, soft.tool_axis(home), soft.tip_position(home), 1, 0.02, seed=1))
    found = stiffest_posture(soft, q0)
    assert found.stiffness > found.stiffness0
    assert np.allclose(found.q[:6], home[:6], atol=1e-4)  # back to the symmetric trusses (the spin is free)


def test_a_robot_without_springs_is_refused(robot):
    with pytest.raises(InputError, match=r"has no \[stiffness\] table"):
        stiffest_posture(robot, robot.parameters.home)


def test_the_drilling_loop_holds_the_posture_it_is_given(soft):
    q0 = stiffest_posture(soft, soft.parameters.home + np.array([0.03, -0.02, 0.01, -0.02, 0.03, 0.0, 0.3])).q
    data = vgtarm.load_bone(ROOT / "examples" / "bones" / "femur_diaphysis.toml").to_dict()
    data["drill"]["diameter"] = 1.0e-3
    data["layers"] = [{"material": "cortical", "thickness": 1.5e-3}]
    bone = vgtarm.drilling.bone_from_dict(data, source="one cortex")
    result = vgtarm.drilling_run(soft, bone, vgtarm.DrillingSettings(gap=0.2e-3, feed_limit=2e-3, duration=6.0), q0=q0)
    assert result.success
    assert result.summary()["lateral_deviation_max"] < 0.05e-3 and result.summary()["axis_error_max"] < 1e-3


def test_the_command_refuses_stiffest_without_springs_and_writes_nothing(tmp_path):
    import subprocess
    import sys

    bone = ROOT / "examples" / "bones" / "femur_diaphysis.toml"
    command = [sys.executable, "-m", "vgtarm", "drill", "--bone", str(bone), "--posture", "stiffest"]
    done = subprocess.run([*command, "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert done.returncode != 0
    assert done.stderr.count("\n") == 1 and "has no [stiffness] table" in done.stderr
    assert not (tmp_path / "out").exists()
