"""Runs animated: frame count = round(duration * fps / speed), every frame shows a recorded sample
and the tip drawn in it is the run's recorded tip; MP4 through imageio-ffmpeg, GIF through Pillow.
Also the saved-run loader the animation and the page read runs with."""

from __future__ import annotations

import contextlib
import dataclasses
import json

import numpy as np
import pytest

from tests.viz_support import SHORT_RUN_S, short_case1_run
from vgtarm.app.cli import command as cli
from vgtarm.app.pictures.animation import check_same_robot, frame_plan, render_animation
from vgtarm.errors import InputError
from vgtarm.simulation import SimulationResult
from vgtarm.simulation.result import MODE_NOT_RUN

#: Tolerance of the drawn tip against the record (m).
TIP_TOL = 1e-12


@pytest.fixture(scope="module")
def run(robot) -> SimulationResult:
    return short_case1_run(robot, "scm")


@pytest.fixture(scope="module")
def run_dir(run, tmp_path_factory):
    return run.save(tmp_path_factory.mktemp("run") / "case1_scm")


def _assert_same(a: SimulationResult, b: SimulationResult) -> None:
    for field in dataclasses.fields(SimulationResult):
        if field.name in ("robot", "reference"):  # the objects the run came from: not saved
            continue
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, field.name
            np.testing.assert_array_equal(x, y, err_msg=field.name)
        elif field.name == "metadata":
            assert json.loads(json.dumps(dict(x))) == dict(y)
        else:
            assert x == y, field.name
    assert a.summary() == b.summary()


def test_a_saved_run_loads_back_the_same(run, run_dir):
    assert run.activations, "the short SCM run should switch to GA gains at the start"
    _assert_same(run, SimulationResult.load(run_dir))


def test_a_partial_run_loads_back_with_its_blank_tail(run, tmp_path):
    mode = run.mode.copy()
    mode[200:] = MODE_NOT_RUN
    blank = {name: getattr(run, name).copy() for name in ("tip", "tip_error", "q", "qd", "effort", "f_ext")}
    for values in blank.values():
        values[200:] = np.nan
    partial = dataclasses.replace(run, mode=mode, activations=(), success=False, message="diverged", **blank)
    _assert_same(partial, SimulationResult.load(partial.save(tmp_path / "partial")))


@pytest.mark.parametrize(
    ("files", "message"),
    [({}, "missing summary.json"), ({"summary.json": "{}", "timeseries.csv": "t,x\n0,1\n"}, "do not match")],
)
def test_loading_a_folder_that_is_not_a_run_fails_in_one_line(tmp_path, files, message):
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    with pytest.raises(InputError, match=message):
        SimulationResult.load(tmp_path)


@pytest.mark.parametrize(("fps", "speed"), [(25.0, 1.0), (10.0, 1.0), (30.0, 0.5), (7.0, 3.0)])
def test_frame_count_is_duration_times_fps_and_frames_are_recorded_samples(run, fps, speed):
    plan = frame_plan(run, fps=fps, speed=speed)
    duration = run.t[-1] - run.t[0]
    assert len(plan) == max(1, int(np.floor(duration * fps / speed + 0.5)))
    assert plan.duration_s == duration
    # each frame is the recorded sample nearest to its time t0 + i * speed / fps
    wanted = run.t[0] + np.arange(len(plan)) * speed / fps
    assert np.all(np.abs(plan.times - wanted) <= run.dt / 2 + 1e-12)
    np.testing.assert_array_equal(plan.times, run.t[plan.samples])
    assert np.all(np.diff(plan.samples) >= 0)


def test_frame_plan_refuses_bad_rates(run):
    with pytest.raises(InputError, match="fps = 0"):
        frame_plan(run, fps=0)
    with pytest.raises(InputError, match="speed = nan"):
        frame_plan(run, speed=float("nan"))


def test_mp4_has_every_frame_and_each_drawn_tip_is_the_record(robot, run, tmp_path):
    import imageio.v2 as imageio

    made = render_animation(robot, run, tmp_path / "run.mp4", fps=20, dpi=50, progress=False)
    assert len(made.plan) == round(SHORT_RUN_S * 20)
    np.testing.assert_allclose(made.drawn_tip, run.tip[made.plan.samples], rtol=0, atol=TIP_TOL)
    reader = imageio.get_reader(made.path)
    try:
        assert reader.count_frames() == len(made.plan)
        assert reader.get_meta_data()["fps"] == pytest.approx(20)
        frames = [reader.get_data(i) for i in (0, len(made.plan) - 1)]
    finally:
        reader.close()
    assert not np.array_equal(frames[0], frames[1]), "the mechanism and the cursor move between frames"
    assert not list(tmp_path.glob(".*tmp*"))


def test_gif_fallback_has_every_frame(robot, run, tmp_path):
    from PIL import Image

    made = render_animation(robot, run, tmp_path / "run.gif", fps=10, speed=2.0, dpi=40, progress=False)
    assert len(made.plan) == round(SHORT_RUN_S * 10 / 2.0)
    with Image.open(made.path) as gif:
        assert gif.n_frames == len(made.plan)
        assert gif.info["duration"] == 100
    np.testing.assert_allclose(made.drawn_tip, run.tip[made.plan.samples], rtol=0, atol=TIP_TOL)


def test_a_run_of_another_robot_is_refused(robot, run):
    from dataclasses import replace

    longer = robot.with_parameters(replace(robot.parameters, h1=robot.parameters.h1 + 0.01))
    check_same_robot(robot, run)
    with pytest.raises(InputError, match="another robot"):
        check_same_robot(longer, run)


def test_animate_command_writes_the_video(run_dir, tmp_path, capsys):
    out = tmp_path / "anim.gif"
    assert cli.main(["animate", str(run_dir), "--out", str(out), "--fps", "10", "--dpi", "30", "-q"]) == 0
    assert out.stat().st_size > 1000
    assert "3 frames at 10 fps" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--out", "x.avi"], "expected a file name ending in one of"),
        (["--out", "x.gif", "--fps", "-1"], "argument --fps: expected a finite number > 0, got -1.0"),
    ],
)
def test_animate_command_refuses_bad_input(run_dir, tmp_path, monkeypatch, capsys, extra, message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) if "--fps" in extra else contextlib.nullcontext():
        status = cli.main(["animate", str(run_dir), *extra])
        assert status == 1
    assert message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
