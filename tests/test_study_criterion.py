"""The redundancy criterion, its joint-limit weight and the state estimator as study parameters
(issue 22): swept on a real local Dask cluster, each row equal to its own single run (and to
`vgtarm simulate` where it has the flags), bad values refused in one line before any run."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

from vgtarm.app.cli.command import main  # noqa: E402
from vgtarm.app.study_points import check_point, execute_point, simulate_command  # noqa: E402
from vgtarm.errors import ConfigError  # noqa: E402
from vgtarm.study import TIMING_COLUMNS, load_study  # noqa: E402
from vgtarm.study.runner import run_study  # noqa: E402

CRITERIA = """
[study]
name = "criteria"
case = 2
duration = 0.3
seeds = [0]

[grid]
external_force = true
encoder_resolution = 1e-6
observer = "momentum"
criterion = ["joint_limits", "effort"]
joint_limit_weight = [0.5, 2.0]
estimator = ["difference", "kalman"]
"""


def _timeless(summary: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in summary.items() if k not in TIMING_COLUMNS}


@pytest.fixture(scope="module")
def study_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("criteria")
    (folder / "criteria.toml").write_text(CRITERIA)
    return folder / "criteria.toml"


@pytest.fixture(scope="module")
def criteria_run(study_file: Path) -> Any:
    return run_study(
        load_study(study_file), study_file.parent / "runs", execute_point, check=check_point, progress=False
    )


def test_eq12_points_are_not_repeated_per_weight(study_file: Path) -> None:
    points = load_study(study_file).points()
    assert len(points) == (1 + 2) * 2  # (eq. 12, effort x 2 weights) x 2 estimators
    plain = [p for p in points if p.inputs["criterion"] == "joint_limits"]
    assert {p.inputs["joint_limit_weight"] for p in plain} == {0.5}  # the default: the weight is the effort's


def test_ids_of_a_study_without_the_new_parameters_do_not_change(tmp_path: Path) -> None:
    """A study that does not name them keeps its ids (they count only when named or away from their default)."""
    base = "[study]\ncase = 1\nduration = 0.05\n[grid]\ncontroller = 'cfc'\n"
    (tmp_path / "a.toml").write_text(base)
    (tmp_path / "b.toml").write_text(base + "criterion = 'effort'\n")
    (a,), (b,) = load_study(tmp_path / "a.toml").points(), load_study(tmp_path / "b.toml").points()
    assert a.inputs["criterion"] == "joint_limits" and a.id != b.id
    from vgtarm.study.spec import point_id_of

    without = {k: v for k, v in a.inputs.items() if k not in ("criterion", "joint_limit_weight")}
    assert point_id_of(without, {}, explicit={"controller"}) == a.id


def test_the_local_cluster_sweeps_criterion_weight_and_estimator(criteria_run: Any, study_file: Path) -> None:
    points = load_study(study_file).points()
    assert criteria_run.executed == len(points) and criteria_run.failed == 0 and not criteria_run.lost
    rows = {(r["criterion"], r["joint_limit_weight"], r["estimator"]): r for r in criteria_run.rows}
    assert len(rows) == len(points)
    for estimator in ("difference", "kalman"):
        plain, low, high = (
            rows[(c, w, estimator)] for c, w in (("joint_limits", 0.5), ("effort", 0.5), ("effort", 2.0))
        )
        assert "ik_criterion" not in plain or not plain["ik_criterion"]
        assert low["ik_criterion"] == "effort" == high["ik_criterion"]
        # three different references: the criterion and its weight reach the run
        assert len({plain["rms_force_n"], low["rms_force_n"], high["rms_force_n"]}) == 3
        assert low["estimator"] == estimator
    # the estimator reaches the run: the Kalman estimate changes the chatter of the same reference
    assert rows[("effort", 0.5, "kalman")]["chatter_n"] != rows[("effort", 0.5, "difference")]["chatter_n"]


@pytest.mark.parametrize(("weight", "estimator"), [(0.5, "kalman"), (2.0, "difference")])
def test_a_row_is_its_single_run_and_its_simulate_command(
    criteria_run: Any, tmp_path: Path, weight: float, estimator: str
) -> None:
    from vgtarm.study import Store

    store = Store(criteria_run.folder)
    wanted = next(
        r["id"]
        for r in criteria_run.rows
        if r["criterion"] == "effort" and r["joint_limit_weight"] == weight and r["estimator"] == estimator
    )
    record = store.read(wanted)
    again, error = execute_point(record["inputs"], {})  # here, not on the cluster
    assert error == "" and _timeless(again) == _timeless(record["summary"])
    command = simulate_command(record["inputs"])
    assert command[command.index("--criterion") + 1] == "effort"
    assert ("--estimator" in command) == (estimator != "difference")  # the default is not written
    assert ("--joint-limit-weight" in command) == (weight != 0.5)
    out = tmp_path / "again"
    assert main([*command, "--out", str(out), "-q"]) == 0
    assert _timeless(json.loads((out / "summary.json").read_text())) == _timeless(record["summary"])


def test_simulate_refuses_a_weight_without_the_effort_criterion(tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    out = tmp_path / "out"
    assert main(["simulate", "--case", "1", "--joint-limit-weight", "0.3", "--out", str(out), "-q"]) == 1
    err = capsys.readouterr().err
    assert "--joint-limit-weight 0.3: applies to --criterion effort only" in err and err.count("\n") == 1
    assert not out.exists()
    with pytest.raises(SystemExit):
        main(["simulate", "--case", "1", "--criterion", "effort", "--joint-limit-weight", "0"])


@pytest.mark.parametrize(
    ("grid", "named"),
    [
        ('criterion = "limits"', "grid.criterion = 'limits': expected one of ['joint_limits', 'effort']"),
        ('criterion = "effort"\njoint_limit_weight = -1.0', "grid.joint_limit_weight = -1.0: expected a weight > 0"),
        ('criterion = "effort"\njoint_limit_weight = 0', "grid.joint_limit_weight = 0: expected a weight > 0"),
        ("joint_limit_weight = 0.3", "grid.joint_limit_weight: applies to criterion = 'effort' only"),
        ('criterion = ["effort"]\nestimator = 3', "grid.estimator = 3: expected one of ['difference', 'kalman']"),
    ],
)
def test_bad_criterion_values_are_refused_before_any_run(
    tmp_path: Path, grid: str, named: str, capsys: pytest.CaptureFixture[str]
) -> None:
    study_file = tmp_path / "bad.toml"
    study_file.write_text(f"[study]\ncase = 1\nduration = 0.05\n[grid]\n{grid}\n")
    with pytest.raises(ConfigError) as error:
        load_study(study_file)
    assert named in str(error.value) and "\n" not in str(error.value)
    assert main(["study", "run", str(study_file), "--out", str(tmp_path / "out"), "-q"]) == 1
    assert named in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("grid", "named"),
    [
        ('estimator = "kalmann"\nencoder_resolution = 1e-6', "estimator = 'kalmann': expected one of"),
        ('estimator = "kalman"', "estimator"),  # needs encoders: the simulator's own check says so
    ],
)
def test_bad_estimator_values_are_refused_by_the_simulators_check(
    tmp_path: Path, grid: str, named: str, capsys: pytest.CaptureFixture[str]
) -> None:
    study_file = tmp_path / "bad.toml"
    study_file.write_text(f"[study]\ncase = 1\nduration = 0.05\n[grid]\n{grid}\n")
    assert main(["study", "run", str(study_file), "--out", str(tmp_path / "out"), "-q"]) == 1
    err = capsys.readouterr().err
    assert named in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
