"""The exported controller (issue 25): the C99 folder builds clean on gcc and clang and under the
sanitizers, uses nothing but libm and the C string functions, and computes the simulation's
efforts: closed through vgtarm's plant, and replayed from recorded measurements, every effort
sample equals ``simulate``'s (to 1e-12, and in fact bit for bit: the arithmetic is the same).
Refusals are one line and leave nothing behind."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.errors import ConfigError, InputError
from vgtarm.experiment.cases import case_study, joint_reference
from vgtarm.export import CompiledExport, ExportError, command, export_controller, simulate_exported
from vgtarm.export.controller import STRICT_FLAGS
from vgtarm.simulation import Scenario, SimulationResult, simulate

from .conftest import make

CASE = case_study(2)
#: The runs compared: the observer with perfect and with realistic sensing, the force sensor; each
#: one scenario, which the export, simulate and the run through the export all take.
RUNS = {
    name: Scenario(external_force=CASE.external_force, **options)
    for name, options in (
        ("observer", {"observer": "momentum"}),
        ("observer, encoders", {"observer": "momentum", "encoder_resolution": 1e-6}),
        ("force sensor", {"force_sensor": True}),
    )
}
#: Symbols an object of the controller may take from outside: libm and the C string functions.
ALLOWED_IMPORTS = {
    "exp",
    "floor",
    "sqrt",
    "sin",
    "cos",
    "tan",
    "atan2",
    "acos",
    "asin",
    "atan",
    "fabs",
    "pow",
    "log",
    "fmin",
    "fmax",
    "memcpy",
    "memset",
    "sincos",
    "hypot",
    "cbrt",
    "tanh",
    "sinh",
    "cosh",
}
CLANG_MISSING = "clang is not installed (.ci/run must install it: apt-get install -y --no-install-recommends clang)"


@pytest.fixture(scope="module")
def robot() -> vgtarm.Robot:
    return vgtarm.load_robot()


@pytest.fixture(scope="module")
def reference(robot: vgtarm.Robot):  # type: ignore[no-untyped-def]
    return joint_reference(robot, 2, duration=0.5)


@pytest.fixture(scope="module")
def exports(robot: vgtarm.Robot, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("exports")
    return {
        name: export_controller(
            robot, root / name.replace(" ", "_").replace(",", ""), scenario=scenario, kp=CASE.kp, kv=CASE.kv
        ).folder
        for name, scenario in RUNS.items()
    }


@pytest.fixture(scope="module")
def compiled(exports: dict[str, Path]) -> dict[str, CompiledExport]:
    """Each export compiled once for the runs through it (and the refusal of other options)."""
    return {name: CompiledExport(folder) for name, folder in exports.items()}


@pytest.fixture(scope="module")
def strict_builds(exports: dict[str, Path], tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """``build(compiler, name)``: the export ``name`` built with make under the strict flags, once per
    compiler and export; the tests only read the builds."""
    flags = " ".join(f for f in STRICT_FLAGS if f != "-ffp-contract=off")
    made: dict[tuple[str, str], Path] = {}

    def build(compiler: str, name: str) -> Path:
        if (compiler, name) not in made:
            where = tmp_path_factory.mktemp(f"strict-{compiler}")
            made[compiler, name] = _make(exports[name], where, compiler, flags)
        return made[compiler, name]

    return build


@pytest.fixture(scope="module")
def simulated(robot: vgtarm.Robot, reference) -> dict[str, SimulationResult]:  # type: ignore[no-untyped-def]
    return {name: simulate(robot, reference, CASE.controller("cfc"), scenario) for name, scenario in RUNS.items()}


@pytest.mark.parametrize("name", list(RUNS))
def test_closed_through_the_export_equals_simulate(name, robot, reference, compiled, simulated):  # type: ignore[no-untyped-def]
    """Case 2 with the tool force closed through the exported, compiled controller: the same run."""
    mine = simulate_exported(compiled[name], robot, reference, RUNS[name])
    theirs = simulated[name]
    assert np.abs(mine.effort - theirs.effort).max() <= 1e-12
    np.testing.assert_array_equal(mine.effort, theirs.effort)  # the same arithmetic: bit for bit
    np.testing.assert_array_equal(mine.q, theirs.q)
    if theirs.effort_estimate is not None:
        np.testing.assert_array_equal(mine.effort_estimate, theirs.effort_estimate)


def test_a_run_with_other_options_than_the_export_is_refused(robot, reference, compiled):  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match="observer_gain_per_s"):
        simulate_exported(compiled["observer"], robot, reference, observer="momentum", observer_gain=300.0)


def _compilers() -> list:  # type: ignore[type-arg]
    return [
        pytest.param("gcc", marks=pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")),
        pytest.param("clang", marks=pytest.mark.skipif(shutil.which("clang") is None, reason=CLANG_MISSING)),
    ]


def assert_imports_only_allowed(build: Path) -> None:
    """The static library built in ``build`` imports nothing but :data:`ALLOWED_IMPORTS` (``nm``)."""
    undefined = subprocess.run(["nm", "-u", str(build / "libvgtc.a")], capture_output=True, text=True, check=True)
    defined = subprocess.run(
        ["nm", "--defined-only", str(build / "libvgtc.a")], capture_output=True, text=True, check=True
    )
    names = {line.split()[-1] for line in undefined.stdout.splitlines() if line.strip() and not line.endswith(":")}
    names -= {line.split()[-1] for line in defined.stdout.splitlines() if len(line.split()) == 3}
    assert names <= ALLOWED_IMPORTS, sorted(names - ALLOWED_IMPORTS)


def _make(folder: Path, where: Path, compiler: str, flags: str) -> Path:
    """A copy of the export built with make, CC=compiler and CFLAGS=flags."""
    build = where / f"build-{compiler}"
    shutil.copytree(folder, build)
    done = make(build, f"CC={compiler}", f"CFLAGS={flags}")
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # not a single warning
    return build


def _write_csv(path: Path, header: list[str], rows: np.ndarray) -> None:
    lines = [",".join(header)] + [",".join(repr(float(v)) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")


def reference_header(n: int, expected_force: bool = False) -> list[str]:
    """The columns replay reads as a reference (README.md of the export), with the expected force or not."""
    joints = [f"{what}_{i}" for what in ("q_d", "qd_d", "qdd_d") for i in range(1, n + 1)]
    return ["t", *joints, *(["f_exp_x", "f_exp_y", "f_exp_z"] if expected_force else [])]


def measurements_header(n: int) -> list[str]:
    """The columns replay reads as measurements."""
    return ["t", *(f"{what}_{i}" for what in ("q", "qd") for i in range(1, n + 1)), "f_x", "f_y", "f_z"]


def _replay(  # type: ignore[no-untyped-def]
    build: Path, run: SimulationResult, reference, where: Path, force_sensor: bool, expected_force=None
) -> np.ndarray:
    """Replay ``run``'s measurements through the built ``replay``; its output table. With
    ``expected_force`` ``(n, 3)``, the reference file carries it as three more columns."""
    n = run.q.shape[1]
    ref_rows = np.column_stack([reference.t, reference.q, reference.qd, reference.qdd])
    if expected_force is not None:
        ref_rows = np.column_stack([ref_rows, expected_force])
    previous_force = (
        np.vstack([np.full((1, 3), np.nan), run.f_ext[:-1]]) if force_sensor else np.full((len(run.t), 3), np.nan)
    )
    meas_rows = np.column_stack([run.t, run.q, run.qd, previous_force])
    _write_csv(where / "reference.csv", reference_header(n, expected_force is not None), ref_rows)
    _write_csv(where / "measurements.csv", measurements_header(n), meas_rows)
    done = subprocess.run(
        [
            str(build / "replay"),
            str(where / "reference.csv"),
            str(where / "measurements.csv"),
            str(where / "efforts.csv"),
        ],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    return np.loadtxt(where / "efforts.csv", delimiter=",", skiprows=1, ndmin=2)


@pytest.mark.parametrize("compiler", _compilers())
def test_builds_strict_and_replay_equals_the_simulation(compiler, strict_builds, simulated, reference, tmp_path):  # type: ignore[no-untyped-def]
    """make with -std=c99 -Wall -Wextra -Werror -pedantic -O2: no warning; replay of the
    simulation's measurements gives its efforts and estimates bit for bit."""
    for name in ("observer", "observer, encoders"):
        where = tmp_path / name.replace(" ", "_").replace(",", "")
        where.mkdir()
        build = strict_builds(compiler, name)
        table = _replay(build, simulated[name], reference, where, force_sensor=False)
        n = simulated[name].q.shape[1]
        np.testing.assert_array_equal(table[:, 1 : 1 + n], simulated[name].effort)
        np.testing.assert_array_equal(table[:, 1 + n : 1 + 2 * n], simulated[name].effort_estimate)
        assert (table[:, -1] == 0).all()


def test_replay_with_the_force_sensor(exports, simulated, reference, tmp_path):  # type: ignore[no-untyped-def]
    build = _make(exports["force sensor"], tmp_path, "gcc", "-std=c99 -O2")
    table = _replay(build, simulated["force sensor"], reference, tmp_path, force_sensor=True)
    np.testing.assert_array_equal(table[:, 1:8], simulated["force sensor"].effort)


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")
def test_clean_under_address_and_undefined_behaviour_sanitizers(exports, simulated, reference, tmp_path):  # type: ignore[no-untyped-def]
    flags = "-std=c99 -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=all"
    build = tmp_path / "asan"
    shutil.copytree(exports["observer, encoders"], build)
    done = make(build, "CC=gcc", f"CFLAGS={flags}", f"LDFLAGS={flags}")
    assert done.returncode == 0, done.stderr
    table = _replay(build, simulated["observer, encoders"], reference, tmp_path, force_sensor=False)
    assert len(table) == len(reference.t)
    for extra in ([], ["--feedforward"]):  # the step with the expected tool force too
        timing = subprocess.run([str(build / "rt_loop"), "--steps", "2000", *extra], capture_output=True, text=True)
        assert timing.returncode == 0, timing.stderr
        assert "runtime error" not in timing.stderr
        assert "step time" in timing.stdout


def test_the_library_uses_only_libm_and_string_functions(strict_builds):  # type: ignore[no-untyped-def]
    """No heap, no I/O, no other dependency: the controller's objects import nothing else (the
    library as gcc builds it at -O2, with the strict flags' warnings, which change no code)."""
    assert_imports_only_allowed(strict_builds("gcc", "observer"))


def _nothing_left(parent: Path, name: str) -> None:
    assert not (parent / name).exists()
    assert [p.name for p in parent.iterdir() if name in p.name] == []


def test_missing_compiler_is_one_line_and_leaves_nothing(robot, tmp_path, monkeypatch):  # type: ignore[no-untyped-def]
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    with pytest.raises(ExportError) as caught:
        export_controller(robot, tmp_path / "out")
    assert "$CC" in str(caught.value) and "\n" not in str(caught.value)
    _nothing_left(tmp_path, "out")


def test_a_compiler_that_fails_leaves_nothing(robot, tmp_path, monkeypatch):  # type: ignore[no-untyped-def]
    monkeypatch.setenv("CC", "false")
    with pytest.raises(ExportError, match="failed") as caught:
        export_controller(robot, tmp_path / "out")
    assert "\n" not in str(caught.value)
    _nothing_left(tmp_path, "out")


def test_unwritable_folder_is_one_line_and_leaves_nothing(robot, tmp_path):  # type: ignore[no-untyped-def]
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    with pytest.raises(InputError) as caught:
        export_controller(robot, blocker / "out")
    assert "\n" not in str(caught.value)
    if os.geteuid() != 0:  # root writes anywhere
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        with pytest.raises(InputError, match="permission denied"):
            export_controller(robot, locked / "out")
        assert list(locked.iterdir()) == []


def test_bad_robot_and_bad_options_are_one_line(robot, tmp_path):  # type: ignore[no-untyped-def]
    bad = tmp_path / "robot.toml"
    bad.write_text("[geometry]\nb = -1\n")
    parser = argparse.ArgumentParser()
    command.add_arguments(parser)
    with pytest.raises(ConfigError) as caught:
        command.run(parser.parse_args(["--out", str(tmp_path / "out"), "--config", str(bad)]))
    assert "\n" not in str(caught.value)
    for options, field in (
        ({"switching": "fast"}, "switching"),
        ({"kp": [1.0, 2.0]}, "Kp"),
        ({"effort_max": -1.0}, "effort_max"),
    ):
        with pytest.raises(InputError, match=field) as caught:
            export_controller(robot, tmp_path / "out", **options)
        assert "\n" not in str(caught.value)
    for fields, field in (  # the scenario's: refused when it is built, or by the export's checks
        ({"observer": "kalman"}, "observer"),
        ({"observer": "momentum", "observer_gain": 5000.0}, "observer_gain"),
        ({"velocity_noise": 0.01}, "velocity_noise = 0.01: the noise of the simulated velocity sensor"),
        ({"limit_tolerance": -1.0}, "limit_tolerance"),
    ):
        with pytest.raises(InputError, match=field) as caught:
            export_controller(robot, tmp_path / "out", scenario=Scenario(**fields))
        assert "\n" not in str(caught.value)
    with pytest.raises(InputError, match="scenario = 'momentum': expected None or a vgtarm.simulation.Scenario"):
        export_controller(robot, tmp_path / "out", scenario="momentum")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="robot"):
        export_controller("paper", tmp_path / "out")  # type: ignore[arg-type]
    _nothing_left(tmp_path, "out")


def test_the_scenario_s_fields_as_keywords_are_deprecated_and_export_the_same(robot, exports, tmp_path):  # type: ignore[no-untyped-def]
    """The keywords export_controller took before the scenario (its fields the export reads) still
    build it, with a DeprecationWarning that points at the caller; the same folder as the scenario's."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        old = export_controller(
            robot,
            tmp_path / "old",
            kp=CASE.kp,
            kv=CASE.kv,
            check_build=False,
            observer="momentum",
            encoder_resolution=1e-6,
        ).folder
    (warning,) = caught
    assert warning.category is DeprecationWarning and warning.filename == __file__
    assert "['encoder_resolution', 'observer'] are deprecated: pass them in scenario=" in str(warning.message)
    for name in ("export.json", "vgtc_defaults.c", "vgtc_config.h", "vgtc_model.c"):
        assert (old / name).read_bytes() == (exports["observer, encoders"] / name).read_bytes(), name
    with pytest.raises(TypeError, match="unexpected keyword argument 'seed'"):  # not one the export reads
        export_controller(robot, tmp_path / "out", seed=1)
    with pytest.raises(InputError, match=r"a scenario and the options \['observer'\]") as refused:
        export_controller(robot, tmp_path / "out", scenario=Scenario(), observer="momentum")
    assert "\n" not in str(refused.value)
    _nothing_left(tmp_path, "out")


def test_command_writes_the_folder(tmp_path, capsys):  # type: ignore[no-untyped-def]
    parser = argparse.ArgumentParser()
    command.add_arguments(parser)
    assert command.run(parser.parse_args(["--out", str(tmp_path / "ctl"), "--observer", "momentum"])) == 0
    assert "wrote" in capsys.readouterr().out
    files = {p.name for p in (tmp_path / "ctl").iterdir()}
    assert {
        "vgtarm_controller.h",
        "vgtarm_controller.c",
        "vgt_control.h",
        "vgtc_model.c",
        "vgtc_defaults.c",
        "replay.c",
        "rt_loop.c",
        "Makefile",
        "CMakeLists.txt",
        "README.md",
        "export.json",
    } <= files
    # the shared arithmetic is the simulation's own header, copied unchanged
    shared = Path(vgtarm.__file__).parent / "model" / "csrc" / "vgt_control.h"
    assert (tmp_path / "ctl" / "vgt_control.h").read_text() == shared.read_text()


def test_the_vgtarm_command_exports_a_controller_and_refuses_a_pipe(tmp_path, capsys):  # type: ignore[no-untyped-def]
    from vgtarm.app.cli import main

    assert main(["export", "controller", "--out", str(tmp_path / "ctl"), "--observer", "momentum"]) == 0
    assert "wrote" in capsys.readouterr().out and (tmp_path / "ctl" / "vgtarm_controller.c").is_file()
    os.mkfifo(tmp_path / "pipe")
    assert main(["export", "controller", "--out", str(tmp_path / "pipe")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pipe" in err
    assert (tmp_path / "pipe").is_fifo()


def test_a_stack_robot_file_exports_and_closes_the_loop_like_simulate(tmp_path):  # type: ignore[no-untyped-def]
    """The paper's robot written as a stack file goes through the stack's code generation (a
    library of its own, generic in the joint count); its export equals simulate bit for bit."""
    stack = vgtarm.load_robot(Path(__file__).resolve().parents[1] / "examples" / "paper_robot.toml")
    assert stack.is_stack
    ref = joint_reference(stack, 2, duration=0.2)
    scenario = Scenario(external_force=CASE.external_force, observer="momentum")
    folder = export_controller(stack, tmp_path / "stack", scenario=scenario, kp=CASE.kp, kv=CASE.kv).folder
    through = simulate_exported(folder, stack, ref, scenario)
    direct = simulate(stack, ref, CASE.controller("cfc"), scenario)
    np.testing.assert_array_equal(through.effort, direct.effort)
    np.testing.assert_array_equal(through.q, direct.q)
