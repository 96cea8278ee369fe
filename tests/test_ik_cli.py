"""The ``vgtarm ik`` command: CSV output, summary, one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from vgtarm.app.cli.command import main

HEADER = "t,x,y,z,s1,v1,p1,s2,v2,p2,psi3,ds1,dv1,dp1,ds2,dv2,dp2,dpsi3,dds1,ddv1,ddp1,dds2,ddv2,ddp2,ddpsi3"


def test_ik_writes_the_csv_with_the_exact_header(tmp_path, capsys, robot):
    out = tmp_path / "ref.csv"
    assert main(["ik", "--case", "2", "--dt", "0.01", "-o", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == HEADER
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    assert table.shape == (401, 25)
    assert np.abs(robot.tip_position(table[:, 4:11]) - table[:, 1:4]).max() <= 1e-9
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ref.csv"]
    summary = capsys.readouterr().out
    for word in ("401 samples", "worst", "largest", "closest approach", "ms", "s2"):
        assert word in summary


def test_ik_on_a_path_file_with_pose(tmp_path, capsys):
    source = tmp_path / "path.csv"
    t = np.linspace(0.0, 1.0, 21)
    rows = np.column_stack([t, 0.02 * np.sin(t), 0.02 * np.cos(t) - 0.02, 0.66 + 0.01 * t])
    np.savetxt(source, rows, delimiter=",", header="t,x,y,z", comments="", fmt="%.17g")
    out = tmp_path / "out.csv"
    assert main(["ik", "--path", str(source), "--pose", "--solver", "reference", "-o", str(out)]) == 0
    assert out.read_text().splitlines()[0] == HEADER
    assert "orientation" in capsys.readouterr().out


@pytest.mark.parametrize(
    "args",
    [
        ["--case", "3"],
        ["--case", "1", "--dt", "fast"],
        ["--case", "1", "--solver", "fmincon"],
        ["--case", "1", "--rates", "euler"],
        ["--case", "1", "--path", "x.csv"],
        [],
    ],
)
def test_bad_arguments_give_one_line_and_no_file(tmp_path, capsys, args):
    out = tmp_path / "ref.csv"
    assert main(["ik", *args, "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("vgtarm: error: ") and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_unreachable_path_file_is_an_error_with_no_output(tmp_path, capsys):
    source = tmp_path / "far.csv"
    t = np.linspace(0.0, 1.0, 11)
    rows = np.column_stack([t, np.zeros(11), np.zeros(11), 0.66 + 0.5 * t])
    np.savetxt(source, rows, delimiter=",", header="t,x,y,z", comments="", fmt="%.17g")
    out = tmp_path / "out.csv"
    assert main(["ik", "--path", str(source), "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "cannot be reached" in err and err.count("\n") == 1
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["far.csv"]


def test_failed_write_leaves_nothing_behind(tmp_path, robot):
    from vgtarm import paths
    from vgtarm.ik import write_csv

    result = robot.inverse_kinematics(paths.case2(0.1))
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "ref.csv").mkdir()  # the target is a folder: os.replace fails after the data is written
    with pytest.raises(OSError):
        write_csv(result, folder / "ref.csv")
    assert sorted(p.name for p in folder.iterdir()) == ["ref.csv"]
