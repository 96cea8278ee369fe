"""The tool-force feedforward in the exported controller (``vgtc_step_feedforward``): case 2 with
the tool force, the expected cutting force fed forward, closed through the export, equals
``simulate`` bit for bit with measured velocities, with 1 um encoders and differenced velocities,
and with the low-force preset's estimate (momentum observer K_O 1000 and the Kalman filter at 100
Hz, a controller model 10 % heavy); the feedforward acts; the replay of a reference with the
expected force columns gives the simulation's efforts; switching control with it equals
``simulate`` too."""

from __future__ import annotations

import dataclasses
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import vgtarm
from vgtarm.experiment.cases import case_study, joint_reference
from vgtarm.export import CompiledExport, export_controller, simulate_exported
from vgtarm.simulation import Scenario, simulate
from vgtarm.simulation.external import DEFAULT_FEEDFORWARD_SPEED

from .test_export_controller import _make, _replay

CASE = case_study(2)
#: Runs with the feedforward: the options of the export and of the simulation alike.
RUNS: dict[str, dict[str, Any]] = {
    "measured velocities": {"observer": "momentum"},
    "encoders, differences": {"observer": "momentum", "encoder_resolution": 1e-6},
    "low-force estimate": {
        "observer": "momentum",
        "observer_gain": 1000.0,
        "encoder_resolution": 1e-6,
        "estimator": "kalman",
        "estimator_bandwidth_hz": 100.0,
        "model_mass": 1.1,
    },
}


@pytest.fixture(scope="module")
def robot() -> vgtarm.Robot:
    return vgtarm.load_robot()


@pytest.fixture(scope="module")
def reference(robot: vgtarm.Robot):  # type: ignore[no-untyped-def]
    return joint_reference(robot, 2, duration=0.4)


@pytest.fixture(scope="module")
def momentum_export(robot: vgtarm.Robot, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The export with the momentum observer and measured velocities (``RUNS["measured velocities"]``),
    made once: its closed run, its replay and the step's refusal of a non-finite force all read it."""
    options = _options(robot, "measured velocities")
    where = tmp_path_factory.mktemp("momentum") / "x"
    return export_controller(robot, where, scenario=Scenario(**options), kp=CASE.kp, kv=CASE.kv).folder


@pytest.fixture(scope="module")
def momentum_build(momentum_export: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """That export built once with make (gcc, ``-std=c99 -O2``); the tests only read it."""
    return _make(momentum_export, tmp_path_factory.mktemp("momentum_build"), "gcc", "-std=c99 -O2")


def _options(robot: vgtarm.Robot, name: str) -> dict[str, Any]:
    options = dict(RUNS[name])
    mass = options.pop("model_mass", None)
    if mass is not None:
        options["controller_model"] = robot.parameters.scaled(mass=mass)
    return options


def _simulate(robot, reference, options, **extra):  # type: ignore[no-untyped-def]
    return simulate(robot, reference, CASE.controller("cfc"), external_force=CASE.external_force, **options, **extra)


@pytest.mark.parametrize("name", list(RUNS))
def test_closed_through_the_export_with_the_feedforward_equals_simulate(name, robot, reference, tmp_path, request):  # type: ignore[no-untyped-def]
    options = _options(robot, name)
    if name == "measured velocities":  # the shared export of these options
        folder = request.getfixturevalue("momentum_export")
    else:
        folder = export_controller(robot, tmp_path / "x", scenario=Scenario(**options), kp=CASE.kp, kv=CASE.kv).folder
    theirs = _simulate(robot, reference, options, tool_force_feedforward=True)
    mine = simulate_exported(
        CompiledExport(folder),
        robot,
        reference,
        external_force=CASE.external_force,
        tool_force_feedforward=True,
        **options,
    )
    np.testing.assert_array_equal(mine.effort, theirs.effort)  # the same arithmetic: bit for bit
    np.testing.assert_array_equal(mine.q, theirs.q)
    np.testing.assert_array_equal(mine.effort_estimate, theirs.effort_estimate)
    if name == "low-force estimate":  # the feedforward acted: the same export without it, the run without it
        plain = simulate_exported(
            CompiledExport(folder), robot, reference, external_force=CASE.external_force, **options
        )
        np.testing.assert_array_equal(plain.effort, _simulate(robot, reference, options).effort)
        assert np.abs(plain.effort - mine.effort).max() > 0.5


def test_replay_feeds_the_reference_files_expected_force_forward(robot, reference, momentum_build, tmp_path):  # type: ignore[no-untyped-def]
    """replay with three more columns in reference.csv, the expected tool force: the efforts of the
    simulation with the feedforward, from its own measurements (measured velocities)."""
    options = _options(robot, "measured velocities")
    build = momentum_build
    theirs = _simulate(robot, reference, options, tool_force_feedforward=True)
    # the expected force as simulate computes it: the cutting model along the desired tip velocity
    f_exp = CASE.external_force.expected(robot.tip_velocity(reference.q, reference.qd)[0], DEFAULT_FEEDFORWARD_SPEED)
    table = _replay(build, theirs, reference, tmp_path, force_sensor=False, expected_force=f_exp)
    n = robot.n_joints
    np.testing.assert_array_equal(table[:, 1 : 1 + n], theirs.effort)
    np.testing.assert_array_equal(table[:, 1 + n : 1 + 2 * n], theirs.effort_estimate)
    (tmp_path / "plain").mkdir()
    plain = _replay(build, theirs, reference, tmp_path / "plain", force_sensor=False)
    assert np.abs(plain[:, 1 : 1 + n] - theirs.effort).max() > 0.5  # without the columns: no feedforward


def test_switching_control_with_the_feedforward_equals_simulate(robot, reference, tmp_path):  # type: ignore[no-untyped-def]
    """vgtc_switching_step_feedforward: every period's effort, under the fixed gains or the GA's,
    with the expected tool force fed forward, as simulate's switching control with it (the safe
    variant with the Kalman estimate; the variants share the step)."""
    options = {"observer": "momentum", "encoder_resolution": 1e-6, "estimator": "kalman"}
    # the feedforward holds the tip within case 2's threshold: a tenth of it, so that the GA runs
    scm = dataclasses.replace(CASE, threshold=CASE.threshold / 10).controller("scm", variant="safe")
    exported = Scenario(**options)  # the run's: the export reads what the controller measures and estimates
    folder = export_controller(robot, tmp_path / "x", scenario=exported, kp=CASE.kp, kv=CASE.kv, switching=scm).folder
    kwargs = {"external_force": CASE.external_force, "tool_force_feedforward": True, **options}
    theirs = simulate(robot, reference, scm, **kwargs)
    mine = simulate_exported(folder, robot, reference, controller=scm, **kwargs)
    assert len(theirs.activations) >= 3  # the GA ran
    np.testing.assert_array_equal(mine.effort, theirs.effort)
    np.testing.assert_array_equal(mine.mode, theirs.mode)
    without = simulate(robot, reference, scm, **{**kwargs, "tool_force_feedforward": False})
    assert np.abs(without.effort - theirs.effort).max() > 0.5


def test_a_non_finite_expected_force_is_refused_by_the_step(momentum_build, tmp_path):  # type: ignore[no-untyped-def]
    """vgtc_step_feedforward refuses a NaN in f_exp (VGTC_NOT_FINITE) and leaves zero efforts
    (the export of ``observer="momentum"`` and the case's gains, its library built with gcc)."""
    build = momentum_build
    driver = tmp_path / "driver.c"  # beside the shared build, which stays as make left it
    driver.write_text(_DRIVER)
    subprocess.run(
        ["gcc", "-std=c99", "-O2", "-ffp-contract=off", f"-I{build}", "-o", "driver", "driver.c",
         str(build / "libvgtc.a"), "-lm"],
        cwd=tmp_path,
        check=True,
    )  # fmt: skip
    done = subprocess.run([str(tmp_path / "driver")], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["ok", "refused", "zeros"]


_DRIVER = r"""
#include <math.h>
#include <stdio.h>
#include "vgtarm_controller.h"
static vgtc_context ctx;
int main(void)
{
    vgtc_params p;
    double q[VGTC_NJ], qd[VGTC_NJ], ref[3 * VGTC_NJ], F[VGTC_NJ], f[3] = {1.0, -2.0, 3.0};
    vgtc_default_params(&p);
    if (vgtc_init(&ctx, &p) != VGTC_OK) return 2;
    for (int i = 0; i < VGTC_NJ; ++i) {
        q[i] = ref[i] = vgtc_home[i];
        qd[i] = ref[VGTC_NJ + i] = ref[2 * VGTC_NJ + i] = 0.0;
    }
    if (vgtc_step_feedforward(&ctx, 0.0, q, qd, ref, NULL, f, NULL, NULL, F) >= 0) printf("ok\n");
    f[1] = NAN;
    if (vgtc_step_feedforward(&ctx, 0.001, q, qd, ref, NULL, f, NULL, NULL, F) == VGTC_NOT_FINITE) printf("refused\n");
    int zeros = 1;
    for (int i = 0; i < VGTC_NJ; ++i) zeros &= F[i] == 0.0;
    if (zeros) printf("zeros\n");
    return 0;
}
"""
