"""The MJCF export loaded in MuJoCo (issue 11, in progress): geometry, mass matrix and static
dynamics against our model. Skipped without the optional extra ``vgtarm[mujoco]``."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import vgtarm
from vgtarm.control import ComputedForceControl
from vgtarm.model.parameters import ModuleGeometry

from .conftest import random_configurations

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is optional: pip install 'vgtarm[mujoco]' to run these")

from vgtarm.mujoco_bridge.export import to_mjcf  # noqa: E402
from vgtarm.mujoco_bridge.model import MujocoRobot  # noqa: E402


@pytest.fixture(scope="module")
def bridge(robot):
    return MujocoRobot(robot)


def test_export_loads_with_the_paper_names_and_no_warnings(robot, bridge):
    model = bridge.model
    assert model.nu == 7 and [model.actuator(i).name for i in range(7)] == list(vgtarm.JOINT_NAMES)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert not any(w.number for w in data.warning)
    # the actuated joints' positions are the paper's joint values at the reference configuration
    np.testing.assert_allclose([data.qpos[bridge.qpos_of[n]] for n in vgtarm.JOINT_NAMES], robot.parameters.home)
    np.testing.assert_allclose(data.site_xpos[bridge.tip_site], robot.tip_position(robot.parameters.home), atol=1e-15)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    np.testing.assert_allclose([data.qpos[bridge.qpos_of[n]] for n in vgtarm.JOINT_NAMES], robot.parameters.home)
    assert not data.qvel.any()


def test_geometry_matches_ours_over_random_configurations(robot, bridge):
    for q in random_configurations(robot, 25, seed=3, margin=0.02):
        bridge.set_state(q, np.zeros(7))
        fk = robot.forward_kinematics(q)
        np.testing.assert_allclose(bridge.tip(), fk.tip, atol=1e-12)
        np.testing.assert_allclose(bridge.rotation(), fk.rotation, atol=1e-12)


def test_a_robot_with_other_dimensions_exports_its_own_geometry(robot):
    other = dataclasses.replace(
        robot.parameters, modules=(ModuleGeometry(0.16, 0.09), ModuleGeometry(0.14, 0.11)), h1=0.12
    )
    tall = robot.with_parameters(other)
    model = mujoco.MjModel.from_xml_string(to_mjcf(tall))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(data.site("tip").xpos, tall.tip_position(other.home), atol=1e-12)


def test_dynamics_agree_as_far_as_mujoco_allows(robot, bridge):
    """Legs of 1e-3 kg (the paper's are massless) against loop closures that MuJoCo keeps soft:
    the reduced mass matrix agrees to about 1e-3, accelerations to about 1e-2 (docs/mujoco.md)."""
    from vgtarm.mujoco_bridge.check import cross_validate

    rows = {row.quantity: row.worst for row in cross_validate(robot, n=25, seed=5, bridge=bridge)}
    assert rows["tip position (m)"] < 1e-12 and rows["orientation (max element)"] < 1e-12
    assert rows["mass matrix M (relative)"] < 2e-3
    assert rows["forward dynamics at rest, gravity only (relative)"] < 5e-4
    assert rows["forward dynamics moving, efforts and tip force (relative)"] < 2e-2


def test_export_command_writes_a_model_mujoco_loads(tmp_path, capsys):
    from vgtarm.app.cli import main

    out = tmp_path / "robot.xml"
    assert main(["export", "mjcf", "--out", str(out), "--validate"]) == 0
    model = mujoco.MjModel.from_xml_path(str(out))
    assert model.nu == 7 and model.site("tip").id >= 0
    assert main(["check", "mujoco", "--states", "3"]) == 0
    assert "mass matrix M (relative)" in capsys.readouterr().out


# ---------------------------------------------------------------------------------------------
# MuJoCo as the plant
# ---------------------------------------------------------------------------------------------


def _short(robot, number, samples):
    from vgtarm.app.cases import joint_reference
    from vgtarm.simulation import JointReference

    ref = joint_reference(robot, number)
    return JointReference(ref.t[:samples], ref.q[:samples], ref.qd[:samples], ref.qdd[:samples])


def test_closed_loop_on_the_mujoco_plant_tracks_like_ours_and_is_deterministic(robot):
    from vgtarm.app.cases import case_study
    from vgtarm.simulation import simulate

    ref = _short(robot, 1, 300)
    cfc = case_study(1).controller("cfc")
    runs = [simulate(robot, ref, cfc, plant_engine="mujoco", seed=2) for _ in range(2)]
    np.testing.assert_array_equal(runs[0].q, runs[1].q)
    assert runs[0].metadata["plant_engine"] == "mujoco"
    ours = simulate(robot, ref, cfc, integrator="semi_implicit_euler", substeps=50, seed=2)
    assert abs(runs[0].summary()["max_tip_error_m"] / ours.summary()["max_tip_error_m"] - 1) < 0.05


def test_unstable_gains_diverge_on_the_mujoco_plant_with_the_same_clear_error(robot):
    from vgtarm.simulation import simulate

    ref = _short(robot, 2, 200)
    unstable = ComputedForceControl.with_gains(15000.0, -600.0)
    messages = []
    for engine in ("model", "mujoco"):
        with pytest.raises(vgtarm.SimulationError, match=r"diverged at t = .* s \(sample \d+ of 200\)") as info:
            simulate(robot, ref, unstable, plant_engine=engine)
        messages.append(str(info.value))
    assert all("\n" not in m for m in messages)


def test_a_bad_plant_engine_is_refused(robot):
    from vgtarm.simulation import simulate

    with pytest.raises(vgtarm.InputError, match="plant_engine = 'gazebo'"):
        simulate(robot, _short(robot, 1, 10), ComputedForceControl.with_gains(1.0, 1.0), plant_engine="gazebo")
