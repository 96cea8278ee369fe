"""MuJoCo as the plant of force-controlled drilling (issue 38, ``docs/drilling_mujoco.md``): its
linearly implicit accelerations against the NumPy plant's at the same state (the Sherman-Morrison
step in MuJoCo's coordinates against the solve of ``M + h b j j^T`` in ours), its trajectories
against the NumPy plant's in the air and in the cut (they differ by the integrators' error: first
order in the step), and the issue's target: the femur drilled with the default settings on both
plants, protrusion and each layer's thrust error within 5 %."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from vgtarm.drilling import load_bone  # noqa: E402
from vgtarm.drilling.control import DrillingPlant  # noqa: E402
from vgtarm.drilling.loop import drilling_run  # noqa: E402
from vgtarm.mujoco_bridge.drilling import MujocoDrillingPlant, mujoco_drilling_run  # noqa: E402

FEMUR = Path(__file__).resolve().parents[1] / "examples" / "bones" / "femur_diaphysis.toml"
SPEED = 120.0  # spindle (rad/s)


@pytest.fixture(scope="module")
def femur():
    return load_bone(FEMUR)


def _plants(robot, bone, depth, feed):
    """Both plants at the home configuration with the tip ``depth`` (m) past the entry surface,
    moving at ``feed`` (m/s) along the axis (joint rates by the pseudo-inverse)."""
    q = np.array(robot.parameters.home, dtype=np.float64)
    axis = robot.tool_axis(q)
    entry = robot.tip_position(q) - depth * axis
    qd = np.linalg.pinv(robot.tip_jacobian(q)) @ (feed * axis)
    ours = DrillingPlant(robot, bone, entry, axis, SPEED)
    theirs = MujocoDrillingPlant(robot, bone, entry, axis, SPEED)
    return ours, theirs, q, qd


def _efforts(robot, q, axis, push):
    """Gravity at ``q``, ``push`` (N) along the axis at the tip, and a small uneven effort on
    every joint (so that every joint moves)."""
    n = robot.n_joints
    uneven = np.sin(np.arange(1, n + 1)) * np.where(np.array(robot.joint_units) == "m", 2.0, 0.01)
    return robot.bias_forces(q, np.zeros(n)) + robot.tip_jacobian(q).T @ axis * push + uneven


@pytest.mark.parametrize("h", [0.0, 2.5e-4])
def test_implicit_accelerations_match_the_numpy_plant(robot, femur, h):
    """In the first cortex, the point wholly in (``d thrust / d feed`` 1.7e4 N s/m): MuJoCo's step
    accelerations read as our joints against our solve. At ``h = 0`` the models' agreement (5e-12
    measured, docs/mujoco.md); at ``h`` = 0.25 ms (5e-9 measured) the implicit term also takes
    ``j . qdd`` in each plant's own coordinates, whose velocity products differ."""
    ours, theirs, q, qd = _plants(robot, femur, 2.0e-3, 0.5e-3)
    assert ours.forces(q, qd)[3] > 1e4
    np.testing.assert_allclose(theirs.forces(q, qd), ours.forces(q, qd), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(theirs.depth_feed(q, qd), ours.depth_feed(q, qd), rtol=1e-12, atol=1e-15)
    F = _efforts(robot, q, ours.axis, 15.0)
    a_ours, thrust_ours = ours.acceleration(q, qd, F, h)
    a_theirs, thrust_theirs = theirs.acceleration(q, qd, F, h)
    assert thrust_theirs == pytest.approx(thrust_ours, rel=1e-12)
    assert np.linalg.norm(a_theirs - a_ours) < 1e-7 * np.linalg.norm(a_ours)
    if h > 0.0:  # the implicit term matters: the tip's axial acceleration is far from the explicit one
        explicit, _ = ours.acceleration(q, qd, F, 0.0)
        j = robot.tip_jacobian(q).T @ ours.axis
        assert abs(j @ (explicit - a_ours)) > 0.5 * abs(j @ explicit)


@pytest.mark.parametrize(("depth", "feed", "push"), [(-0.5e-3, 0.0, 0.0), (2.0e-3, 0.5e-3, 15.0)], ids=["air", "cut"])
def test_trajectories_agree_to_the_integrators_error(robot, femur, depth, feed, push):
    """10 periods of 1 ms under constant efforts, each plant stepped as the loop steps it: the
    joint trajectories differ by the two semi-implicit Euler integrators' own error (MuJoCo steps
    its 15 tree coordinates, we our joints), which falls as the step: four times the substeps,
    a quarter of the difference."""
    worst = {}
    for substeps in (4, 16):
        ours, theirs, q, qd = _plants(robot, femur, depth, feed)
        F = _efforts(robot, q, ours.axis, push)
        qa, qda, qb, qdb = q, qd, q, qd
        worst[substeps] = 0.0
        for _ in range(10):
            qa, qda = ours.step(qa, qda, F, 1e-3, substeps)
            qb, qdb = theirs.step(qb, qdb, F, 1e-3, substeps)
            worst[substeps] = max(worst[substeps], float(np.abs(qb - qa).max()))
        if push:
            assert ours.forces(qa, qda)[0] > 10.0  # still in the cut, pushing
        assert np.abs(qa - q).max() > 1e-4  # it moved
    assert worst[4] < 2e-8  # m or rad
    assert 3.0 < worst[4] / worst[16] < 5.0


@pytest.fixture(scope="module")
def femur_runs(robot, femur):
    """The femur drilled with the default settings on both plants (about 7 s and 15 s)."""
    return drilling_run(robot, femur).summary(), mujoco_drilling_run(robot, femur).summary()


def test_the_femur_on_mujoco_matches_ours_within_five_percent(femur_runs):
    """The issue's target for the cross-check: protrusion, the largest and each layer's thrust
    error RMS within 5 % of ours; the same detections."""
    ours, theirs = femur_runs
    assert ours["success"] and theirs["success"]
    assert theirs["protrusion"] == pytest.approx(ours["protrusion"], rel=0.05)
    assert theirs["thrust_error_rms_max"] == pytest.approx(ours["thrust_error_rms_max"], rel=0.05)
    for mine, other in zip(ours["layers"], theirs["layers"], strict=True):
        assert other["thrust_error_rms"] == pytest.approx(mine["thrust_error_rms"], rel=0.05)
    assert theirs["false_detections"] == ours["false_detections"] == 0
    for mine, other in zip(ours["transitions"], theirs["transitions"], strict=True):
        assert other["detected_time"] == pytest.approx(mine["detected_time"], abs=0.02)
    assert theirs["detection_delay"] == pytest.approx(ours["detection_delay"], abs=0.01)
