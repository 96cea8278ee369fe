"""Studies on Dask: local and remote clusters give the same table, an interrupted study resumes
without running anything twice, a row is reproduced by `vgtarm simulate`, bad files are refused."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

from vgtarm.app.cli.command import main  # noqa: E402
from vgtarm.app.study_points import check_point, execute_point, simulate_command  # noqa: E402
from vgtarm.errors import ConfigError, InputError  # noqa: E402
from vgtarm.study import TIMING_COLUMNS, Store, load_study, parse_study  # noqa: E402
from vgtarm.study.report import group_statistics, write_report  # noqa: E402
from vgtarm.study.runner import run_study  # noqa: E402

DASK = Path(sys.executable).parent / "dask"

TINY = """
[study]
name = "tiny"
case = 1
duration = 0.1
seeds = [0, 1]

[grid]
controller = ["cfc", "scm"]
external_force = true

[random]
draws = 2
seed = 3
model_mass = {uniform = [0.9, 1.1]}
"""


def _comparable(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in rows]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("study")
    (folder / "tiny.toml").write_text(TINY)
    return folder / "tiny.toml"


@pytest.fixture(scope="module")
def local_run(tiny: Path) -> Any:
    return run_study(load_study(tiny), tiny.parent / "local", execute_point, check=check_point, progress=False)


def test_expansion_and_ids(tiny: Path) -> None:
    study = load_study(tiny)
    points = study.points()
    assert len(points) == 2 * 2 * 2  # controllers x draws x seeds
    assert [p.id for p in points] == [p.id for p in load_study(tiny).points()]  # stable
    assert len({p.id for p in points}) == len(points)
    masses = sorted({p.inputs["model_mass"] for p in points})
    expected = sorted(np.random.default_rng(3).uniform(0.9, 1.1, 2).tolist())  # the draws, independently
    assert masses == expected
    changed = parse_study({**_toml(TINY), "study": {**_toml(TINY)["study"], "duration": 0.2}})
    assert not {p.id for p in points} & {p.id for p in changed.points()}


def _toml(text: str) -> dict[str, Any]:
    import tomllib

    return tomllib.loads(text)


def test_local_study_writes_every_run(local_run: Any, tiny: Path) -> None:
    points = load_study(tiny).points()
    assert local_run.executed == len(points) and local_run.failed == 0 and not local_run.lost
    rows = local_run.rows
    assert [r["id"] for r in rows] == [p.id for p in points]
    assert all(r["success"] and r["max_tip_error_m"] > 0 for r in rows)
    assert {r["controller"] for r in rows} == {"cfc", "scm"}
    assert any(r["ga_activations"] > 0 for r in rows if r["controller"] == "scm")
    csv_lines = (local_run.folder / "results.csv").read_text().splitlines()
    assert len(csv_lines) == len(points) + 1
    import pyarrow.parquet as pq

    table = pq.read_table(local_run.folder / "results.parquet").to_pylist()
    assert _comparable(table) == _comparable(rows)


def test_runs_land_where_the_readme_says_and_a_study_of_before_resumes(local_run: Any, tiny: Path) -> None:
    """``DIR/<id>.json`` (the README); a study begun before, with ``DIR/runs/<id>.json``, resumes
    there: nothing is run again and no file moves."""
    ids = {p.id for p in load_study(tiny).points()}
    assert {p.stem for p in local_run.folder.glob("*.json")} == ids
    assert not (local_run.folder / "runs").exists()
    old = tiny.parent / "before"
    (old / "runs").mkdir(parents=True)
    for point_id in ids:
        shutil.copyfile(local_run.folder / f"{point_id}.json", old / "runs" / f"{point_id}.json")
    resumed = run_study(load_study(tiny), old, execute_point, progress=False)
    assert resumed.skipped == len(ids) and resumed.executed == 0
    assert _comparable(resumed.rows) == _comparable(local_run.rows)
    assert not list(old.glob("*.json")) and {p.stem for p in (old / "runs").glob("*.json")} == ids


def test_the_dashboard_line(monkeypatch: pytest.MonkeyPatch) -> None:
    from vgtarm.study import runner

    class Cluster:
        dashboard_link = "http://127.0.0.1:40123/status"

    monkeypatch.setattr(runner.importlib.util, "find_spec", lambda name: object())
    assert runner.dashboard_address() == "127.0.0.1:0"  # loopback only, a free port
    assert runner.dashboard_line(Cluster()) == "Dask dashboard of the local cluster: http://127.0.0.1:40123/status"
    monkeypatch.setattr(runner.importlib.util, "find_spec", lambda name: None)
    assert runner.dashboard_address() is None
    assert "needs Bokeh" in runner.dashboard_line(Cluster())


def test_remote_scheduler_gives_the_same_table(local_run: Any, tiny: Path) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "DASK_DISTRIBUTED__LOGGING__DISTRIBUTED": "error"}
    started: list[subprocess.Popen[bytes]] = []
    try:
        started.append(
            subprocess.Popen(
                [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                env=env,
            )
        )
        started.append(
            subprocess.Popen(
                [str(DASK), "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard"],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                env=env,
            )
        )
        from distributed import Client

        deadline = time.monotonic() + 60
        while True:
            try:
                with Client(address, timeout=5) as client:
                    client.wait_for_workers(1, timeout=60)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        remote = run_study(load_study(tiny), tiny.parent / "remote", execute_point, scheduler=address, progress=False)
    finally:
        for process in reversed(started):
            process.terminate()
        for process in reversed(started):
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(timeout=10)
    assert remote.executed == len(local_run.rows)
    assert _comparable(remote.rows) == _comparable(local_run.rows)


def test_row_reproduced_by_vgtarm_simulate(local_run: Any, tmp_path: Path) -> None:
    record = Store(local_run.folder).read(
        next(r["id"] for r in local_run.rows if r["controller"] == "scm" and r["seed"] == 1)
    )
    out = tmp_path / "again"
    assert main([*simulate_command(record["inputs"]), "--out", str(out), "-q"]) == 0
    again = json.loads((out / "summary.json").read_text())
    stored = {k: v for k, v in record["summary"].items() if k not in TIMING_COLUMNS}
    assert {k: v for k, v in again.items() if k not in TIMING_COLUMNS} == stored
    assert stored["ga_activations"] > 0  # the GA (seeded) and the disturbance (seeded) both acted


@pytest.mark.parametrize(
    ("controller", "key", "value", "flag"),
    [("cfc", "kp", 4000.0, True), ("scm", "kv", 100.0, True), ("scm", "kv", 600.0, False)],
)
def test_a_row_with_its_own_gains_is_reproduced_by_simulate_kp_kv(
    tmp_path: Path, controller: str, key: str, value: float, flag: bool
) -> None:
    """``--kp``/``--kv`` re-run a row with its gains (same summary, timings aside); a gain the
    switching method's GA bounds do not hold keeps its refusal (simulate would widen the bounds).
    The switching method's gains are values its genes represent exactly (kv 100 = 300 * 85/255)."""
    text = f'[study]\ncase = 1\nduration = 0.02\nseeds = [0]\n[grid]\ncontroller = "{controller}"\n{key} = {value}\n'
    (tmp_path / "gains.toml").write_text(text)
    (point,) = load_study(tmp_path / "gains.toml").points()
    if not flag:
        with pytest.raises(InputError, match=f"{key} = {value}"):
            simulate_command(point.inputs)
        return
    command = simulate_command(point.inputs)
    other = "kv" if key == "kp" else "kp"
    assert command[command.index(f"--{key}") + 1] == repr(value) and f"--{other}" not in command
    stored, error = execute_point(point.inputs, {})
    assert error == "" and stored[key] == [value] * 7 and stored[other] == [5000.0 if other == "kp" else 300.0] * 7
    out = tmp_path / "again"
    assert main([*command, "--out", str(out), "-q"]) == 0
    again = json.loads((out / "summary.json").read_text())
    assert {k: v for k, v in again.items() if k not in TIMING_COLUMNS} == {
        k: v for k, v in stored.items() if k not in TIMING_COLUMNS
    }


KILLABLE = """
[study]
name = "killable"
case = 1
duration = 0.08
seeds = 40

[grid]
controller = "scm"
external_force = true
"""


def test_killed_study_resumes_without_running_anything_twice(tmp_path: Path) -> None:
    study_file = tmp_path / "killable.toml"
    study_file.write_text(KILLABLE)
    out = tmp_path / "out"
    runs = out  # DIR/<id>.json, as the README says
    total = len(load_study(study_file).points())
    command = [str(Path(sys.executable).parent / "vgtarm"), "study", "run", str(study_file), "--out", str(out)]
    process = subprocess.Popen(
        [*command, "--workers", "1", "-q"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # its own process group: the kill takes the local cluster with it
    )
    try:
        deadline = time.monotonic() + 60
        while not (runs.is_dir() and len(list(runs.glob("[!.]*.json"))) >= 3):
            assert process.poll() is None, "the study ended before it could be killed"
            assert time.monotonic() < deadline, "no run was written in 60 s"
            time.sleep(0.02)
        os.killpg(process.pid, signal.SIGKILL)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=20)
    before = {p.stem for p in runs.glob("[!.]*.json")}
    assert 3 <= len(before) < total, "kill the study midway"
    for file in runs.glob("[!.]*.json"):
        assert json.loads(file.read_text())["id"] == file.stem  # complete files only
    log_before = (out / "executions.log").read_text().splitlines()

    resumed = run_study(load_study(study_file), out, execute_point, workers=1, progress=False)

    assert resumed.skipped == len(before) and resumed.executed == total - len(before)
    log = (out / "executions.log").read_text().splitlines()
    submitted_again = {line.split()[1] for line in log[len(log_before) :] if line.startswith("submit")}
    assert not submitted_again & before
    written = [line.split()[1] for line in log if line.startswith("write")]
    assert len(written) == len(set(written))  # no run stored twice
    assert {p.stem for p in runs.glob("[!.]*.json")} == {p.id for p in load_study(study_file).points()}
    assert len((out / "results.csv").read_text().splitlines()) == total + 1


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ('[grid]\ncontroller = "pid"', "grid.controller = 'pid'"),
        ("[grid]\nkp = -5.0", "grid.kp = -5.0"),
        ("[grid]\nspeed = 2.0", "grid.speed"),
        ("[grid]\nexternal_force = 1", "grid.external_force = 1"),
        ("[random]\ndraws = 3\nmodel_mass = {uniform = [1.2, 0.8]}", "random.model_mass.uniform"),
        ("[random]\ndraws = 3\nmodel_mass = {normal = [0.0, 0.5]}", "random.model_mass (draw"),
        ('[grid]\nintegrator = "rk5"', "grid.integrator = 'rk5'"),
        ("[other]\nx = 1", "[other]"),
    ],
)
def test_bad_study_files_are_refused(tmp_path: Path, text: str, named: str, capsys: pytest.CaptureFixture[str]) -> None:
    study_file = tmp_path / "bad.toml"
    study_file.write_text("[study]\ncase = 1\nduration = 0.05\nseeds = 3\n" + text + "\n")
    with pytest.raises(ConfigError) as error:
        load_study(study_file)
    assert named in str(error.value) and "\n" not in str(error.value)
    assert main(["study", "run", str(study_file), "--out", str(tmp_path / "out"), "-q"]) == 1
    assert named in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # refused before any run


def test_simulator_options_are_checked_before_any_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from vgtarm.simulation import Scenario

    assert "observer" in Scenario.option_names()  # a study parameter found from the scenario's fields
    study_file = tmp_path / "bad.toml"
    study_file.write_text('[study]\ncase = 1\nduration = 0.05\n[grid]\nobserver = ["none", "kalman"]\n')
    with pytest.raises(ConfigError, match=r"grid\.observer = 'kalman': expected one of \['none', 'momentum'\]"):
        load_study(study_file)  # the scenario's declaration of the option has its choices
    assert main(["study", "run", str(study_file), "--out", str(tmp_path / "out"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "kalman" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()  # refused before any run
    study_file.write_text('[study]\ncase = 1\nduration = 0.05\n[grid]\nobserver = "momentum"\nobserver_gain = 5e3\n')
    assert len(load_study(study_file).points()) == 1  # in the declared bounds: at most 1/dt is the simulator's check
    assert main(["study", "run", str(study_file), "--out", str(tmp_path / "out"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "observer_gain = 5000.0: expected at most 1/dt" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()  # the simulator's own check ran before any run


def test_study_init_writes_a_valid_study(tmp_path: Path) -> None:
    file = tmp_path / "example.toml"
    assert main(["study", "init", str(file)]) == 0
    study = load_study(file)
    assert {p.inputs["controller"] for p in study.points()} == {"cfc", "scm"}
    assert main(["study", "init", str(file)]) == 1  # no overwrite without --force


def test_report_statistics_and_figures(local_run: Any) -> None:
    rows = local_run.rows
    stats = group_statistics(rows, "max_tip_error_m")
    for controller, s in stats.items():
        values = [r["max_tip_error_m"] for r in rows if r["controller"] == controller]
        assert s["n"] == len(values)
        assert s["mean"] == pytest.approx(sum(values) / len(values), rel=1e-12)
        assert s["std"] == pytest.approx(float(np.std(values, ddof=1)), rel=1e-12)
        assert s["worst"]["max_tip_error_m"] == max(values)
    report = write_report(local_run.folder)
    text = report.read_text()
    assert "| CFC |" in text and "| SCM |" in text
    assert (local_run.folder / "study_error_distribution.png").stat().st_size > 0
    assert (local_run.folder / "study_error_vs_model_mass.png").stat().st_size > 0


def test_reproduce_seeds_section_matches_single_runs(tmp_path: Path) -> None:
    from vgtarm import load_robot
    from vgtarm.app.reports.reproduce import RunSpec
    from vgtarm.app.reports.seeds import seed_rows, seed_section
    from vgtarm.experiment.cases import joint_reference, run_case

    specs = [RunSpec(1, "cfc", True, "exact")]
    section = seed_section(tmp_path / "seeds", 3, specs)
    rows = seed_rows(tmp_path / "seeds", 3, specs)  # stored: nothing runs again
    robot = load_robot()
    reference = joint_reference(robot, 1)
    by_hand = [
        run_case(robot, 1, external_force=True, seed=s, reference=reference).summary()["max_tip_error_m"]
        for s in range(3)
    ]
    assert sorted(r["seed"] for r in rows) == [0, 1, 2]
    assert [r["max_tip_error_m"] for r in sorted(rows, key=lambda r: r["seed"])] == by_hand
    mean, std = 1e3 * np.mean(by_hand), 1e3 * np.std(by_hand, ddof=1)
    assert f"| {1e3 * by_hand[0]:.4f} | {mean:.4f} ± {std:.4f} |" in section[-1]


STACK_STUDY = """
[study]
name = "six modules"
case = 1
duration = 0.05
robot = "six_modules.toml"
seeds = [0]

[grid]
controller = ["cfc", "scm"]
"""


def test_a_study_runs_on_a_stack_of_modules_and_its_rows_are_reproduced(tmp_path: Path) -> None:
    """The robot file may be a stack: the case path is placed on it, the controllers are sized by
    its 21 joints, and `vgtarm simulate --config` re-runs a row to the same summary."""
    examples = Path(__file__).resolve().parents[1] / "examples"
    (tmp_path / "six_modules.toml").write_text((examples / "six_modules.toml").read_text())
    (tmp_path / "study.toml").write_text(STACK_STUDY)
    run = run_study(load_study(tmp_path / "study.toml"), tmp_path / "runs", execute_point, workers=1, progress=False)
    assert len(run.rows) == 2 and all(row["success"] for row in run.rows), run.rows
    record = Store(run.folder).read(next(r["id"] for r in run.rows if r["controller"] == "scm"))
    assert record["summary"]["path_scale"] == pytest.approx(1.54 / 0.66)
    out = tmp_path / "again"
    assert main([*simulate_command(record["inputs"], study_folder=tmp_path), "--out", str(out), "-q"]) == 0
    again = json.loads((out / "summary.json").read_text())
    robots = [summary["experiment"].pop("robot") for summary in (again, record["summary"])]
    assert robots[0]["name"] == robots[1]["name"] and robots[1]["source"] == "study robot file six_modules.toml"
    assert {k: v for k, v in again.items() if k not in TIMING_COLUMNS} == {
        k: v for k, v in record["summary"].items() if k not in TIMING_COLUMNS
    }  # where the robot was read aside (the study ships its text to the workers)
