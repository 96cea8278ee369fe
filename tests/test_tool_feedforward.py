"""Feeding the expected tool force forward (``tool_force_feedforward``, docs/control.md)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import vgtarm
from vgtarm.control import ComputedForceControl
from vgtarm.model.compiled import InterpretedBackend, build_functions
from vgtarm.simulation import ExternalForce, JointReference, simulate

from .conftest import assert_close
from .test_observer import CFC, reference

CUTTING_ONLY = ExternalForce(disturbance=False)


def straight(robot, duration=0.3, dt=1e-3) -> JointReference:
    """Joints moving at constant velocities from the home pose: the tip moves at about 5 cm/s."""
    rate = np.array([0.02, -0.015, 0.01, -0.02, 0.015, -0.01, 0.0])
    t = np.arange(0.0, duration + 1e-9, dt)
    q = robot.parameters.home + rate * t[:, None]
    return JointReference(t, q, np.tile(rate, (len(t), 1)), np.zeros_like(q))


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"observer": "momentum"},
        {"observer": "momentum", "encoder_resolution": 1e-6},
        {"observer": "momentum", "encoder_resolution": 1e-6, "estimator": "kalman", "estimator_bandwidth_hz": 100.0},
        {"encoder_resolution": 1e-6, "estimator": "kalman", "tool_force_speed": 0.05},
    ],
)
def test_compiled_loop_matches_its_numpy_twin_with_the_feedforward(robot, options):
    slow = vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions()))
    ref = reference(robot, duration=0.08)
    kwargs = dict(
        external_force=ExternalForce(),
        seed=5,
        controller_model=robot.parameters.scaled(mass=1.1),
        tool_force_feedforward=True,
        **options,
    )
    fast = simulate(robot, ref, CFC, **kwargs)
    twin = simulate(slow, ref, CFC, **kwargs)
    assert fast.success and twin.success
    for name in ("q", "qd", "effort", "tip_error"):
        assert_close(getattr(fast, name), getattr(twin, name), rtol=1e-9, atol=1e-12, what=name)
    if "observer" in options:
        assert_close(fast.effort_estimate, twin.effort_estimate, rtol=1e-9, atol=1e-9, what="effort_estimate")
    plain = simulate(robot, ref, CFC, **{**kwargs, "tool_force_feedforward": False, "tool_force_speed": None})
    assert np.max(np.abs(fast.effort - plain.effort)) > 1.0  # the feedforward acted


def test_the_feedforward_removes_the_steady_error_of_the_cutting_force(robot):
    """Perfect sensing, exact model, the deterministic cutting force only. Without the feedforward
    the joints settle at the offset ``e = -M^-1 J_P^T f / Kp`` (the error dynamics ``e'' + Kv e' +
    Kp e = -M^-1 J_P^T f``); with it the force is cancelled and the offset is gone."""
    cfc = ComputedForceControl.with_gains(15000.0, 600.0)
    ref = straight(robot)
    plain = simulate(robot, ref, cfc, external_force=CUTTING_ONLY)
    fed = simulate(robot, ref, cfc, external_force=CUTTING_ONLY, tool_force_feedforward=True, tool_force_speed=1e-6)
    late = slice(200, None)  # five time constants of the slow pole (-27 1/s) after the start
    q = plain.q[late]
    M = robot.mass_matrix(q)
    Jt = np.swapaxes(robot.tip_jacobian(q), -1, -2)
    offset = -np.linalg.solve(M, (Jt @ plain.f_ext[late][..., None]))[..., 0] / 15000.0
    error = plain.q_desired[late] - plain.q[late]
    assert np.max(np.abs(error - offset)) < 0.03 * np.max(np.abs(offset))
    expected_tip = np.linalg.norm((robot.tip_jacobian(q) @ offset[..., None])[..., 0], axis=1)
    assert_close(plain.tip_error[late], expected_tip, rtol=0.02, atol=1e-8, what="the tip offset")
    assert np.min(plain.tip_error[late]) > 1e-4  # of the order of 0.1 mm
    # what is left is the decaying transient of the start (the tool cuts from the first period on)
    assert np.max(fed.tip_error[late]) < 2e-3 * np.min(plain.tip_error[late])
    assert fed.tip_error[-1] < 1e-4 * plain.tip_error[-1]


def test_the_expected_force_is_the_effort_criterions(robot):
    from vgtarm.experiment.cases import case_path
    from vgtarm.ik.effort import expected_tool_force

    path = case_path(robot, 2, 1e-3)
    model, _, _ = expected_tool_force(path, 20.0, 0.05)
    ours = ExternalForce().expected(path.velocity, 0.05)
    assert_close(ours, model, rtol=1e-12, atol=1e-12, what="expected force")
    assert np.all(ExternalForce(cutting=False).expected(path.velocity, 0.05) == 0.0)


def test_off_by_default_and_recorded_in_the_scenario(robot):
    ref = reference(robot, duration=0.05)
    default = simulate(robot, ref, CFC, external_force=ExternalForce(), seed=1)
    off = simulate(robot, ref, CFC, external_force=ExternalForce(), seed=1, tool_force_feedforward=False)
    for name in ("q", "qd", "effort", "tip_error"):
        np.testing.assert_array_equal(getattr(default, name), getattr(off, name))
    scenario = default.metadata["scenario"]
    assert scenario["tool_force_feedforward"] is False and scenario["tool_force_speed"] is None
    on = simulate(robot, ref, CFC, external_force=ExternalForce(), seed=1, tool_force_feedforward=True)
    assert on.metadata["scenario"]["tool_force_feedforward"] is True


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tool_force_feedforward": True}, "tool_force_feedforward = True without the cutting force"),
        (
            {"tool_force_feedforward": True, "external_force": ExternalForce(), "force_sensor": True},
            "with force_sensor = True",
        ),
        ({"tool_force_speed": 0.01, "external_force": ExternalForce()}, "tool_force_speed = 0.01 without"),
        (
            {"tool_force_feedforward": True, "tool_force_speed": 0.0, "external_force": ExternalForce()},
            "tool_force_speed = 0.0: expected a speed > 0",
        ),
        ({"tool_force_feedforward": "yes", "external_force": ExternalForce()}, "expected True or False"),
    ],
)
def test_bad_feedforward_arguments_are_one_clear_line(robot, kwargs, message):
    with pytest.raises(vgtarm.InputError, match=message) as info:
        simulate(robot, reference(robot, duration=0.01), CFC, **kwargs)
    assert "\n" not in str(info.value)


def test_command_line_tool_feedforward(capsys, tmp_path):
    from vgtarm.app.cli.command import main

    argv = ["simulate", "--case", "2", "--external-force", "--duration", "0.3", "--quiet", "--observer", "momentum"]
    assert main([*argv, "--tool-feedforward", "--tool-force-speed", "0.01", "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["scenario"]["tool_force_feedforward"] is True and saved["scenario"]["tool_force_speed"] == 0.01
    assert main(["simulate", "--case", "2", "--duration", "0.05", "--quiet", "--tool-feedforward"]) == 1
    _, err = capsys.readouterr()
    assert "without the cutting force" in err and err.count("\n") == 1


def test_the_low_force_preset_feeds_the_cutting_force_forward_only_with_the_tool_force():
    import argparse

    from vgtarm.app.cli import presets as cli_presets
    from vgtarm.experiment.presets import PRESETS, preset_options

    assert PRESETS["low-force"]["tool_force_feedforward"] is True
    _, with_force = preset_options("low-force", tool_force=20.0)
    _, without = preset_options("low-force", tool_force=0.0)
    assert with_force["tool_force_feedforward"] is True and "tool_force_feedforward" not in without
    for external_force in (True, False):
        args = argparse.Namespace(
            preset="low-force",
            external_force=external_force,
            tool_force_feedforward=False,
            tool_force_speed=None,
            estimator="difference",
            estimator_bandwidth_hz=None,
        )
        cli_presets.apply_preset(args)
        assert args.tool_force_feedforward is external_force
