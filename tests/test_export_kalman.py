"""The exported controller with the Kalman state estimate (issue 25): case 2 with the tool force,
realistic sensing (1 um encoders, a controller model 10 % heavy), computed force control with the
momentum observer and the Kalman estimator, closed through the export, equals ``simulate`` bit for
bit in every sample (the gains are computed once in Python and exported as exact doubles; the
per-period arithmetic is ``vgt_kalman_step`` of the shared header and the same generated forward
dynamics). The folder builds strict on gcc and clang, replays the simulation's measurements to its
efforts, and runs clean under the sanitizers; bad options are one line."""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.errors import InputError
from vgtarm.experiment.cases import case_study, joint_reference
from vgtarm.export import CompiledExport, command, export_controller, simulate_exported
from vgtarm.export.controller import STRICT_FLAGS
from vgtarm.simulation import Scenario, SimulationResult, simulate
from vgtarm.simulation.sensing import kalman_gains

from .conftest import make
from .test_export_controller import _compilers, _make, _replay, assert_imports_only_allowed

CASE = case_study(2)
#: The run: the observer and the Kalman estimator with realistic sensing.
OPTIONS = {"observer": "momentum", "encoder_resolution": 1e-6, "estimator": "kalman"}
MODEL_MASS = 1.1


@pytest.fixture(scope="module")
def robot() -> vgtarm.Robot:
    return vgtarm.load_robot()


@pytest.fixture(scope="module")
def model(robot: vgtarm.Robot) -> vgtarm.RobotParameters:
    return robot.parameters.scaled(mass=MODEL_MASS)


@pytest.fixture(scope="module")
def reference(robot: vgtarm.Robot):  # type: ignore[no-untyped-def]
    return joint_reference(robot, 2, duration=0.5)


@pytest.fixture(scope="module")
def scenario(model: vgtarm.RobotParameters) -> Scenario:
    """The run: case 2's tool force, the controller model 10 % heavy, :data:`OPTIONS`; the export,
    simulate and the run through the export all take it."""
    return Scenario(external_force=CASE.external_force, controller_model=model, **OPTIONS)


@pytest.fixture(scope="module")
def folder(robot, scenario, tmp_path_factory) -> Path:  # type: ignore[no-untyped-def]
    root = tmp_path_factory.mktemp("kalman")
    return export_controller(robot, root / "kalman", scenario=scenario, kp=CASE.kp, kv=CASE.kv).folder


@pytest.fixture(scope="module")
def compiled(folder: Path) -> CompiledExport:
    """The export compiled once for the runs through it (the refusals are checked before any step)."""
    return CompiledExport(folder)


@pytest.fixture(scope="module")
def simulated(robot, scenario, reference) -> SimulationResult:  # type: ignore[no-untyped-def]
    return simulate(robot, reference, CASE.controller("cfc"), scenario)


def test_closed_through_the_export_equals_simulate_bit_for_bit(robot, model, scenario, reference, compiled, simulated):  # type: ignore[no-untyped-def]
    mine = simulate_exported(compiled, robot, reference, scenario)
    np.testing.assert_array_equal(mine.effort, simulated.effort)
    np.testing.assert_array_equal(mine.q, simulated.q)
    np.testing.assert_array_equal(mine.effort_estimate, simulated.effort_estimate)
    # the estimator made a difference: the differenced velocities give other efforts
    other = simulate(
        robot,
        reference,
        CASE.controller("cfc"),
        external_force=CASE.external_force,
        controller_model=model,
        observer="momentum",
        encoder_resolution=1e-6,
    )
    assert not np.array_equal(other.effort, simulated.effort)


def test_the_gains_are_the_simulations_as_exact_doubles(folder):  # type: ignore[no-untyped-def]
    settings = json.loads((folder / "export.json").read_text())
    assert settings["estimator"] == "kalman" and settings["estimator_bandwidth_hz"] == 60.0
    assert settings["kalman_gain"] == list(kalman_gains(1e-3, 60.0))
    defaults = (folder / "vgtc_defaults.c").read_text()
    for i, gain in enumerate(settings["kalman_gain"]):
        assert f"params->kalman_gain[{i}] = {float(gain).hex()};" in defaults
    assert "#define VGTC_KALMAN 1" in (folder / "vgtc_config.h").read_text()
    assert "Kalman filter, 60 Hz" in (folder / "README.md").read_text()


def test_a_run_with_another_estimator_or_bandwidth_is_refused(robot, model, reference, compiled):  # type: ignore[no-untyped-def]
    options = {**OPTIONS, "controller_model": model}
    with pytest.raises(InputError, match="kalman_gain"):
        simulate_exported(compiled, robot, reference, estimator_bandwidth_hz=90.0, **options)
    with pytest.raises(InputError, match="estimator"):
        simulate_exported(compiled, robot, reference, **{**options, "estimator": "difference"})


@pytest.mark.parametrize("compiler", _compilers())
def test_builds_strict_and_replay_equals_the_simulation(compiler, folder, simulated, reference, tmp_path):  # type: ignore[no-untyped-def]
    build = _make(folder, tmp_path, compiler, " ".join(f for f in STRICT_FLAGS if f != "-ffp-contract=off"))
    table = _replay(build, simulated, reference, tmp_path, force_sensor=False)
    n = simulated.q.shape[1]
    np.testing.assert_array_equal(table[:, 1 : 1 + n], simulated.effort)
    np.testing.assert_array_equal(table[:, 1 + n : 1 + 2 * n], simulated.effort_estimate)
    assert (table[:, -1] == 0).all()
    assert_imports_only_allowed(build)


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")
def test_clean_under_address_and_undefined_behaviour_sanitizers(folder, simulated, reference, tmp_path):  # type: ignore[no-untyped-def]
    flags = "-std=c99 -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=all"
    build = tmp_path / "asan"
    shutil.copytree(folder, build)
    done = make(build, "CC=gcc", f"CFLAGS={flags}", f"LDFLAGS={flags}")
    assert done.returncode == 0, done.stderr
    table = _replay(build, simulated, reference, tmp_path, force_sensor=False)
    np.testing.assert_array_equal(table[:, 1 : 1 + simulated.q.shape[1]], simulated.effort)
    timing = subprocess.run([str(build / "rt_loop"), "--steps", "2000"], capture_output=True, text=True)
    assert timing.returncode == 0, timing.stderr
    assert "runtime error" not in timing.stderr


def test_bad_estimator_options_are_one_line(robot, tmp_path):  # type: ignore[no-untyped-def]
    for options, field in (
        ({"estimator": "luenberger"}, "estimator"),
        ({"estimator": "kalman"}, "encoder_resolution"),  # the filter reads encoder counts
        ({"estimator": "kalman", "encoder_resolution": 1e-6, "estimator_bandwidth_hz": 400.0}, "estimator_bandwidth"),
        ({"estimator_bandwidth_hz": 60.0}, "estimator_bandwidth_hz"),  # only with the Kalman filter
    ):
        with pytest.raises(InputError, match=field) as caught:
            export_controller(robot, tmp_path / "out", scenario=Scenario(**options), check_build=False)
        assert "\n" not in str(caught.value)
    assert not (tmp_path / "out").exists()


def test_the_command_exports_the_estimator(tmp_path, capsys):  # type: ignore[no-untyped-def]
    parser = argparse.ArgumentParser()
    command.add_arguments(parser)
    arguments = ["--out", str(tmp_path / "ctl"), "--observer", "momentum", "--encoder-resolution", "1e-6"]
    arguments += ["--estimator", "kalman", "--estimator-bandwidth", "120"]
    assert command.run(parser.parse_args(arguments)) == 0
    assert "Kalman" in capsys.readouterr().out
    settings = json.loads((tmp_path / "ctl" / "export.json").read_text())
    assert settings["estimator_bandwidth_hz"] == 120.0
    assert settings["kalman_gain"] == list(kalman_gains(1e-3, 120.0))


def test_switching_control_on_the_kalman_estimate_equals_simulate(robot, scenario, tmp_path):  # type: ignore[no-untyped-def]
    """The safe variant predicts from the readings the next step would use (``vgtc_readings``),
    which with the Kalman filter is its estimate: with a threshold low enough to activate the GA
    often, the run through the export equals simulate's bit for bit."""
    scm = dataclasses.replace(CASE.controller("scm", variant="safe"), threshold=2e-5)
    reference = joint_reference(robot, 2, duration=0.4)
    exported = export_controller(
        robot, tmp_path / "switching", scenario=scenario, kp=CASE.kp, kv=CASE.kv, switching=scm
    )
    theirs = simulate(robot, reference, scm, scenario)
    mine = simulate_exported(CompiledExport(exported.folder), robot, reference, scenario, controller=scm)
    assert len(theirs.activations) > 10
    assert [a.sample for a in mine.activations] == [a.sample for a in theirs.activations]
    np.testing.assert_array_equal(mine.effort, theirs.effort)
