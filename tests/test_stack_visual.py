"""Pictures of a stack of any number of modules: the drawn geometry is the model's (every leg as long
as its joint, every platform centred on the model's centre, the drawn tip the model's tip, to
1e-12 m), joints coloured per joint, and draw, animate and report work on a saved six-module run
with one line or trace per joint, named by the run's joints."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from PIL import Image

import vgtarm
from vgtarm.app.cli import command as cli
from vgtarm.app.cli.visual import robot_file_of_runs
from vgtarm.app.pictures.animation import check_same_robot, render_animation
from vgtarm.app.pictures.drawing import CLOSENESS_COLOURS, CLOSENESS_NORM, draw_mechanism, plane_views, pose_figure
from vgtarm.app.pictures.geometry import (
    SEGMENT_KINDS,
    limit_closeness,
    mechanism_geometries,
    mechanism_geometry,
    twist_joints,
)
from vgtarm.app.pictures.plotting import plot_efforts, plot_joint_errors
from vgtarm.app.reports.html import figure_errors, load_runs, page_figures
from vgtarm.errors import InputError
from vgtarm.simulation import SimulationResult

from .test_drawing import _drawn_segments

#: Tolerance on drawn lengths and points (m).
GEOMETRY_TOL = 1e-12
#: The example stacks drawn here.
STACKS = ("examples/six_modules.toml", "examples/planar_module.toml")


@pytest.fixture(scope="module")
def six() -> vgtarm.Robot:
    return vgtarm.load_robot("examples/six_modules.toml")


@pytest.fixture(scope="module", params=STACKS, ids=["six_modules", "planar_module"])
def stack(request) -> vgtarm.Robot:
    return vgtarm.load_robot(request.param)


def stack_configurations(robot: vgtarm.Robot, n: int, seed: int, margin: float = 0.005) -> np.ndarray:
    """The home pose and ``n - 1`` configurations drawn uniformly inside the joint limits and
    assemblable with ``margin`` (m)."""
    rng = np.random.default_rng(seed)
    p = robot.parameters
    chosen = [p.home[None, :]]
    while sum(len(c) for c in chosen) < n:
        q = rng.uniform(p.lower, p.upper, size=(4 * n, robot.n_joints))
        chosen.append(q[robot.is_assemblable(q, margin)])
    return np.concatenate(chosen)[:n]


@pytest.fixture(scope="module")
def poses(stack) -> np.ndarray:
    return stack_configurations(stack, 16, seed=11)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A short closed-loop run of the six-module arm, saved by ``vgtarm simulate``."""
    out = tmp_path_factory.mktemp("stack_run") / "run6"
    argv = ["simulate", "--config", "examples/six_modules.toml", "--case", "1", "--controller", "cfc"]
    assert cli.main([*argv, "--duration", "0.3", "--out", str(out), "-q"]) == 0
    return out


@pytest.fixture(scope="module")
def run(run_dir) -> SimulationResult:
    return SimulationResult.load(run_dir)


# -- the geometry is the model's ---------------------------------------------------------------


def _check_geometry(robot: vgtarm.Robot, q: np.ndarray, geometry) -> None:
    p = robot.parameters
    fk = robot.forward_kinematics(q)
    names = robot.joint_names
    for k, (module, legs) in enumerate(zip(p.modules, p.leg_indices, strict=True)):
        for index in legs:  # each leg as long as its joint says, driven by it
            leg = geometry.segment(names[index])
            assert leg.kind == "leg" and leg.joint == index
            assert abs(leg.length - q[index]) < GEOMETRY_TOL, names[index]
        s, v, pp = (geometry.segment(names[i]) for i in legs)
        np.testing.assert_allclose(s.start, pp.start, rtol=0, atol=GEOMETRY_TOL)  # A
        np.testing.assert_allclose(v.end, pp.end, rtol=0, atol=GEOMETRY_TOL)  # B'
        base, top = geometry.segment(f"base{k + 1}"), geometry.segment(f"platform{k + 1}")
        assert abs(base.length / 2 - module.b) < GEOMETRY_TOL
        assert abs(top.length / 2 - module.d) < GEOMETRY_TOL
        np.testing.assert_allclose(np.stack([s.start, v.start]), np.stack([base.start, base.end]), atol=GEOMETRY_TOL)
        np.testing.assert_allclose(np.stack([s.end, v.end]), np.stack([top.start, top.end]), atol=GEOMETRY_TOL)
        # the top edge is centred on the model's platform centre, along the plane's h axis of its frame
        np.testing.assert_allclose(0.5 * (top.start + top.end), fk.platform_position[k], rtol=0, atol=GEOMETRY_TOL)
        phi = np.radians(module.plane)
        h_axis = fk.platform_rotation[k] @ np.array([-np.sin(phi), np.cos(phi), 0.0])
        np.testing.assert_allclose((top.end - top.start) / top.length, h_axis, rtol=0, atol=1e-12)
        frame = next(f for f in geometry.frames if f.label == f"F{k + 1}")
        np.testing.assert_array_equal(frame.rotation, fk.platform_rotation[k])
    np.testing.assert_allclose(geometry.tip, robot.tip_position(q), rtol=0, atol=GEOMETRY_TOL)
    np.testing.assert_allclose(geometry.segment("tool").end, fk.tip, rtol=0, atol=GEOMETRY_TOL)
    bar = geometry.segment("end_effector")
    np.testing.assert_allclose((bar.end - bar.start) / bar.length, fk.rotation[:, 0], rtol=0, atol=1e-12)


def test_drawn_legs_platforms_and_tip_are_the_model(stack, poses):
    for q, geometry in zip(poses, mechanism_geometries(stack, poses), strict=True):
        _check_geometry(stack, q, geometry)


def test_an_inner_twist_turns_its_bar_by_its_angle_and_carries_the_next_module(six):
    poses = stack_configurations(six, 8, seed=5)
    p = six.parameters
    for q, geometry in zip(poses, mechanism_geometries(six, poses), strict=True):
        fk = six.forward_kinematics(q)
        for k, module in enumerate(p.modules[:-1]):  # the twists inside the arm: psi3, psi5
            if module.twist is None:
                continue
            index = p.leg_indices[k][2] + 1
            label = six.joint_names[index][3:]
            bar, part = geometry.segment(f"twist_bar{label}"), geometry.segment(f"twist{label}")
            assert bar.joint == index and bar.kind == "twist_bar"
            platform = fk.platform_rotation[k]
            direction = (bar.end - bar.start) / bar.length
            np.testing.assert_allclose(platform.T @ direction, [np.cos(q[index]), np.sin(q[index]), 0.0], atol=1e-12)
            # the part rises along the platform normal by its height, to the next module's base centre
            np.testing.assert_allclose(part.end - part.start, module.twist.height * platform[:, 2], atol=GEOMETRY_TOL)
            base = geometry.segment(f"base{k + 2}")
            np.testing.assert_allclose(0.5 * (base.start + base.end), part.end, rtol=0, atol=GEOMETRY_TOL)


def test_every_joint_drives_one_bar_coloured_by_its_closeness(stack, poses):
    q = poses[-1].copy()
    geometry = mechanism_geometry(stack, q)
    kinds = [SEGMENT_KINDS.index(s.kind) for s in geometry.segments]
    assert kinds == sorted(kinds)
    driven = sorted(s.joint for s in geometry.segments if s.joint is not None)
    assert driven == list(range(stack.n_joints))  # legs, twists' bars, the end-effector's
    closeness = limit_closeness(q, stack.parameters.lower, stack.parameters.upper)
    artists = draw_mechanism(geometry)
    for seg in geometry.segments:
        if seg.joint is None:
            continue
        assert seg.closeness == closeness[seg.joint]
        expected = artists.cmap(CLOSENESS_NORM(float(closeness[seg.joint])))
        assert to_rgba(artists.lines[seg.name].get_color()) == pytest.approx(expected), seg.name


def test_a_leg_near_its_limit_is_drawn_red(six):
    q = six.parameters.home.copy()
    s5 = six.joint_names.index("s5")
    q[s5] = six.parameters.upper[s5] - 1e-4  # still assemblable
    geometry = mechanism_geometry(six, q)
    artists = draw_mechanism(geometry)
    assert geometry.segment("s5").closeness > 0.99
    np.testing.assert_allclose(
        to_rgba(artists.lines["s5"].get_color())[:3], to_rgba(CLOSENESS_COLOURS[-1])[:3], atol=0.02
    )


def test_the_paper_robot_as_a_stack_draws_as_the_paper_robot(robot):
    """examples/paper_robot.toml holds the paper's robot: the same bars, plates and frames."""
    paper = vgtarm.load_robot("examples/paper_robot.toml")
    poses = stack_configurations(paper, 6, seed=2)
    for a, b in zip(mechanism_geometries(robot, poses), mechanism_geometries(paper, poses), strict=True):
        assert [s.name for s in a.segments] == [s.name for s in b.segments]
        for x, y in zip(a.segments, b.segments, strict=True):
            np.testing.assert_allclose(np.stack([x.start, x.end]), np.stack([y.start, y.end]), atol=GEOMETRY_TOL)
        assert [p.name for p in a.plates] == [p.name for p in b.plates]
        for x, y in zip(a.plates, b.plates, strict=True):
            np.testing.assert_allclose(x.vertices, y.vertices, atol=GEOMETRY_TOL)
        assert [f.label for f in a.frames] == [f.label for f in b.frames]


def test_twist_joints_are_the_angular_joints(stack, robot):
    assert twist_joints(robot.parameters) == (6,)
    angular = tuple(i for i, unit in enumerate(stack.joint_units) if unit == "rad")
    assert twist_joints(stack.parameters) == angular


# -- drawings ------------------------------------------------------------------------------


def test_the_drawing_holds_the_geometry_and_moves_with_it(stack, poses):
    geometries = mechanism_geometries(stack, poses)
    artists = draw_mechanism(geometries[0])
    for q, geometry in zip(poses[::-1], geometries[::-1], strict=True):
        artists.update(geometry)
        drawn = _drawn_segments(artists.ax)
        for index, name in enumerate(stack.joint_names):
            if name in drawn:
                assert abs(np.linalg.norm(drawn[name][1] - drawn[name][0]) - q[index]) < GEOMETRY_TOL, name
        np.testing.assert_allclose(drawn["tool"][1], stack.tip_position(q), rtol=0, atol=GEOMETRY_TOL)


@pytest.mark.parametrize(
    ("config", "azimuths"), [("examples/six_modules.toml", [0.0, -90.0]), ("examples/planar_module.toml", [0.0])]
)
def test_pose_figure_shows_each_plane_once_and_an_isometric_view(config, azimuths):
    stack = vgtarm.load_robot(config)
    fig = pose_figure(stack, stack.parameters.home)
    views = [ax for ax in fig.axes if ax.name == "3d"]
    assert [ax.azim for ax in views[:-1]] == azimuths and [ax.elev for ax in views] == [0.0] * len(azimuths) + [22.0]
    assert views[-1].get_title() == "isometric"
    assert [v[0] for v in plane_views(mechanism_geometry(stack, stack.parameters.home))][:-1] == [
        ax.get_title() for ax in views[:-1]
    ]
    title = fig.texts[0].get_text() if fig.texts else fig._suptitle.get_text()
    assert all(f"{name} = " in title for name in stack.joint_names)


@pytest.mark.parametrize("config", STACKS)
def test_draw_command_draws_a_stack(config, tmp_path, capsys):
    out = tmp_path / "pose.png"
    assert cli.main(["draw", "--config", config, "--out", str(out)]) == 0
    with Image.open(out) as image:
        assert image.format == "PNG" and image.size[0] > 1000
        pixels = np.asarray(image.convert("RGB"), dtype=float) / 255
    # leg s1 is drawn in the colour of its closeness to a limit
    stack = vgtarm.load_robot(config)
    closeness = limit_closeness(stack.parameters.home, stack.parameters.lower, stack.parameters.upper)[0]
    colour = np.array(
        draw_mechanism(mechanism_geometry(stack, stack.parameters.home)).cmap(CLOSENESS_NORM(closeness))[:3]
    )
    assert (np.abs(pixels - colour).max(axis=2) < 0.03).sum() > 300
    assert "drawing written to" in capsys.readouterr().out


def test_draw_command_refuses_a_wrong_joint_count_in_one_line(capsys):
    assert cli.main(["draw", "0.3", "0.3", "0.4", "--config", "examples/six_modules.toml", "--out", "x.png"]) == 1
    err = capsys.readouterr().err.strip()
    assert "expected 21 joint values" in err and "psi7" in err and "\n" not in err


# -- a saved stack run: plots, animation, page -----------------------------------------------


def test_a_stack_run_records_its_joints(six, run):
    assert run.joint_names == six.joint_names
    check_same_robot(six, run)


def test_efforts_and_joint_errors_have_one_line_per_joint(run):
    names = run.joint_names
    legs = [n for n in names if not n.startswith("psi")]
    twists = [n for n in names if n.startswith("psi")]
    ax = plot_efforts(run)
    assert [line.get_label() for line in ax.get_lines()] == [f"F_{n}" for n in legs]
    (twin,) = [a for a in ax.figure.axes if a is not ax]
    assert [line.get_label() for line in twin.get_lines()] == [f"τ_{n} (right)" for n in twists]
    for line, name in zip(ax.get_lines(), legs, strict=True):
        np.testing.assert_array_equal(line.get_ydata(), run.effort[:, names.index(name)])
    assert len({to_rgba(line.get_color()) for line in ax.get_lines()}) == len(legs)  # told apart
    errors = plot_joint_errors(run)
    assert [line.get_label() for line in errors.get_lines()] == legs
    (twin,) = [a for a in errors.figure.axes if a is not errors]
    assert "mrad" in twin.get_ylabel() and len(twin.get_lines()) == len(twists)
    subset = plot_efforts(run, joints=["s4", "psi5"])
    assert [line.get_label() for line in subset.get_lines()] == ["F_s4"]
    with pytest.raises(InputError, match=r"unknown \['psi9'\]"):
        plot_efforts(run, joints=["psi9"])


def test_animate_command_animates_a_stack_run(six, run, run_dir, tmp_path, capsys):
    made = render_animation(six, run, tmp_path / "direct.gif", fps=20, dpi=40, progress=False)
    np.testing.assert_allclose(made.drawn_tip, run.tip[made.plan.samples], rtol=0, atol=1e-12)
    out = tmp_path / "run.gif"
    argv = ["animate", str(run_dir), "--config", "examples/six_modules.toml", "--out", str(out)]
    assert cli.main([*argv, "--fps", "10", "--dpi", "40", "-q"]) == 0
    with Image.open(out) as gif:
        assert gif.n_frames == 3 and gif.size == (512, 256)
    assert "animation written to" in capsys.readouterr().out


def test_report_page_has_one_effort_trace_per_joint(six, run_dir):
    runs = load_runs([run_dir])
    figures = {div: fig for div, _, fig in page_figures(six, runs, max_frames=4)}
    efforts = figures["efforts"]
    names = six.joint_names
    assert len(efforts["data"]) == len(names)
    # one panel per module's legs and one for the three twists, each trace in its module's panel
    titles = [f"module {m} (N)" for m in range(1, 7)] + ["twists (N m)"]
    axes = [efforts["layout"]["yaxis" + ("" if g == 0 else str(g + 1))]["title"]["text"] for g in range(len(titles))]
    assert axes == titles and "yaxis8" not in efforts["layout"]
    legs = [n for n in names if not n.startswith("psi")]
    twists = [n for n in names if n.startswith("psi")]
    assert [t["hovertemplate"].split(":")[0] for t in efforts["data"]] == legs + twists
    panel = {t["hovertemplate"].split(":")[0]: t["yaxis"] for t in efforts["data"]}
    assert panel["s1"] == panel["p1"] == "y" and panel["v6"] == "y6" and panel["psi3"] == panel["psi7"] == "y7"
    mechanism = figures["mechanism-1"]
    legs = next(t for t in mechanism["data"] if t.get("customdata"))
    leg_names = [n for n in names if not n.startswith("psi")]
    assert legs["customdata"][::3] == leg_names
    assert len(mechanism["frames"]) == 4
    assert figure_errors(efforts) == []
    assert figure_errors(mechanism) == []


def test_report_command_writes_the_page_of_a_stack_run(run_dir, tmp_path, capsys):
    out = tmp_path / "report"
    assert cli.main(["report", str(run_dir), "--config", "examples/six_modules.toml", "--out", str(out)]) == 0
    page = (out / "report.html").read_text("utf-8")
    # a panel per module (and one for the twists), a line per joint
    assert all(f'"text":"{panel} (' in page for panel in ("module 1", "module 6", "twists"))
    assert len(re.findall(r'"hovertemplate":"psi\d', page)) == 3
    assert all(f'"hovertemplate":"{name}:' in page for name in ("s1", "p6", "psi3", "psi7"))
    assert "report written to" in capsys.readouterr().out


@pytest.mark.parametrize("command", ["animate", "report"])
def test_a_stack_run_with_the_paper_robot_is_refused_in_one_line(command, run_dir, tmp_path, capsys):
    bare = tmp_path / "bare"  # the run without the copy of its robot file: the reference robot is tried
    shutil.copytree(run_dir, bare)
    (bare / "robot.toml").unlink()
    out = tmp_path / ("a.gif" if command == "animate" else "page")
    assert cli.main([command, str(bare), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("vgtarm: error:") and "21 joints" in err and "--config" in err and "\n" not in err
    assert not out.exists()


def test_a_run_keeps_its_robot_file_and_animate_and_report_find_it(run_dir, tmp_path, capsys):
    """`simulate --config F --out RUN` copies F into RUN (robot.toml); `animate RUN` and `report RUN`
    then need no --config. Runs of different robots together are refused in one line."""
    assert (run_dir / "robot.toml").read_bytes() == Path("examples/six_modules.toml").read_bytes()
    assert cli.main(["animate", str(run_dir), "--out", str(tmp_path / "a.gif"), "--fps", "10", "-q"]) == 0
    assert cli.main(["report", str(run_dir), "--out", str(tmp_path / "page")]) == 0
    assert "psi7" in (tmp_path / "page" / "report.html").read_text("utf-8")
    paper = tmp_path / "paper_run"
    argv = ["simulate", "--case", "1", "--controller", "cfc", "--duration", "0.05", "--out", str(paper), "-q"]
    assert cli.main(argv) == 0 and not (paper / "robot.toml").exists()
    capsys.readouterr()
    assert cli.main(["report", str(run_dir), str(paper), "--out", str(tmp_path / "both")]) == 1
    err = capsys.readouterr().err
    assert "different robots" in err and err.count("\n") == 1
    assert not (tmp_path / "both").exists()


def test_runs_of_a_reproduction_find_the_robot_file_at_its_top(tmp_path):
    top = tmp_path / "results"
    (top / "beyond" / "observer").mkdir(parents=True)
    (top / "case1_cfc").mkdir()
    (top / "report.md").write_text("report")
    (top / "robot.toml").write_text("robot")
    assert robot_file_of_runs(None, [top / "case1_cfc", top / "beyond" / "observer"]) == top / "robot.toml"
    assert robot_file_of_runs(Path("mine.toml"), [top / "case1_cfc"]) == Path("mine.toml")
    (top / "report.md").unlink()  # not a reproduction: a robot.toml above a run is not taken
    assert robot_file_of_runs(None, [top / "case1_cfc"]) is None


def test_the_page_of_a_stack_run_renders_in_a_real_browser(run_dir, tmp_path):
    from tests.test_html_report import _browser_or_skip, browser_tab

    _browser_or_skip()  # before the report is written
    assert cli.main(["report", str(run_dir), "--config", "examples/six_modules.toml", "--out", str(tmp_path)]) == 0
    with browser_tab(tmp_path / "report.html", 4) as (tab, problems):
        shown = tab.evaluate(
            """() => Array.from(document.querySelectorAll('.plotly-graph-div')).map(d => ({
                id: d.id, traces: (d.data || []).length, lines: d.querySelectorAll('path.js-line').length,
                canvas: d.querySelectorAll('canvas').length}))"""
        )
        tab.screenshot(path=str(tmp_path / "page.png"), full_page=True)
    assert not problems, problems
    by_id = {plot["id"]: plot for plot in shown}
    assert by_id["efforts"]["traces"] == 21 and by_id["efforts"]["lines"] >= 21
    assert by_id["mechanism-1"]["canvas"] >= 1
