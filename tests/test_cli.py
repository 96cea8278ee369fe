"""The command line: outputs, exit statuses and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from vgtarm.app.cli.command import main


def run(capsys, *argv):
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_describe(capsys):
    status, out, err = run(capsys, "describe")
    assert status == 0
    assert "tip @ home" in out and "0.66" in out
    assert "eigenvalues" in out


def test_fk_prints_the_tip(capsys):
    status, out, _ = run(
        capsys,
        "fk",
        "0.2844292531",
        "0.2844292531",
        "0.3753664876",
        "0.2844292531",
        "0.2844292531",
        "0.3753664876",
        "0",
    )
    assert status == 0
    assert "tip        [" in out and "0.66" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["fk", "0.22", "0.3", "0.46", "0.28", "0.28", "0.37", "0"], "module 1 cannot be assembled"),
        (["describe", "--config", "/nonexistent/robot.toml"], "/nonexistent/robot.toml: not found"),
    ],
)
def test_user_errors_are_one_line_and_exit_1(capsys, argv, message):
    status, _, err = run(capsys, *argv)
    assert status == 1
    assert err.startswith("vgtarm: error: ") and message in err
    assert err.count("\n") == 1


def test_bad_usage_exits_2(capsys):
    with pytest.raises(SystemExit) as info:
        main(["simulate", "--case", "3"])
    assert info.value.code == 2


@pytest.mark.parametrize("options", [["--force"], ["--controll", "scm"]])
def test_abbreviated_options_are_refused(capsys, options):
    """An abbreviation is a usage error, not a guess: ``--force`` once ran ``--force-sensor``."""
    option = options[0]
    with pytest.raises(SystemExit) as info:
        main(["simulate", "--case", "2", *options])
    assert info.value.code == 2
    assert f"unrecognized arguments: {option}" in capsys.readouterr().err


def test_simulate_writes_summary_timeseries_and_figure(capsys, tmp_path):
    out_dir = tmp_path / "run"
    status, out, _ = run(
        capsys,
        "simulate",
        "--case",
        "2",
        "--controller",
        "cfc",
        "--external-force",
        "--seed",
        "4",
        "--quiet",
        "--out",
        str(out_dir),
    )
    assert status == 0
    assert "max_tip_error_m" in out
    summary = json.loads((out_dir / "summary.json").read_text())
    assert summary["case"] == 2 and summary["controller"] == "cfc" and summary["external_force"] is True
    assert summary["seed"] == 4 and summary["reference_rates"] == "exact"
    assert (out_dir / "timeseries.csv").exists() and (out_dir / "figure.png").stat().st_size > 1000


def test_simulate_with_a_wrong_controller_model(capsys):
    status, out, _ = run(capsys, "simulate", "--case", "2", "--model-mass", "1.5", "--quiet")
    assert status == 0
    assert "max_tip_error_m" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--case", "1", "--controller", "cfc", "--plant", "mujoco", "--duration", "0.01", "-q"],
        ["export", "mjcf", "--out", "robot.xml"],
        ["export", "mjcf", "--out", "robot.xml", "--validate"],
        ["check", "mujoco", "--states", "2"],
    ],
    ids=["simulate", "export", "export --validate", "check"],
)
def test_mujoco_commands_without_mujoco_say_what_to_install_in_one_line(argv, tmp_path):
    """MuJoCo is an optional extra: without it (its import blocked in a fresh interpreter) each
    command that needs it ends with one line naming the extra, exit status 1, and writes nothing
    (the export too: MuJoCo's own model-editing API builds and writes the MJCF)."""
    script = (
        "import sys; sys.modules['mujoco'] = None\n"
        "from vgtarm.app.cli.command import main\n"
        f"sys.exit(main({argv!r}))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert done.returncode == 1, done.stderr
    assert done.stderr.count("\n") == 1 and "pip install 'vgtarm[mujoco]'" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "robot.xml").exists()
