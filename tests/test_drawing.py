"""The drawn mechanism is the model's geometry: lengths, half-widths, centres and tip read back from
the drawing's own data equal the forward kinematics and the robot file to 1e-12 m."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Line3D

from tests.conftest import random_configurations
from vgtarm.app.cli import command as cli
from vgtarm.app.pictures.drawing import CLOSENESS_NORM, MM, VIEWS, draw_mechanism, pose_figure
from vgtarm.app.pictures.geometry import (
    SEGMENT_KINDS,
    leg_joints,
    limit_closeness,
    mechanism_geometries,
    mechanism_geometry,
    twist_joint,
)
from vgtarm.errors import InputError
from vgtarm.model.parameters import JOINT_NAMES

#: Tolerance on drawn lengths and points (m).
GEOMETRY_TOL = 1e-12


@pytest.fixture(scope="module")
def poses(robot):
    """The home pose and random assemblable configurations inside the limits."""
    return np.vstack([robot.parameters.home, random_configurations(robot, 24, seed=7)])


def _drawn_segments(ax) -> dict[str, np.ndarray]:
    """Every bar's two end points (2, 3) in m, read back from the Axes' Line3D artists by gid."""
    found = {}
    for line in ax.get_lines():
        if isinstance(line, Line3D) and line.get_gid():
            xs, ys, zs = line.get_data_3d()
            found[line.get_gid()] = np.column_stack([xs, ys, zs]).astype(float) / MM
    return found


def _check_against_model(robot, q, segments: dict[str, np.ndarray]) -> None:
    p = robot.parameters
    fk = robot.forward_kinematics(q)
    for module, legs in enumerate(leg_joints(p)):
        for index in legs:
            start, end = segments[JOINT_NAMES[index]]
            assert abs(np.linalg.norm(end - start) - q[index]) < GEOMETRY_TOL, JOINT_NAMES[index]
        base = segments[f"base{module + 1}"]
        top = segments[f"platform{module + 1}"]
        assert abs(np.linalg.norm(base[1] - base[0]) / 2 - p.modules[module].b) < GEOMETRY_TOL
        assert abs(np.linalg.norm(top[1] - top[0]) / 2 - p.modules[module].d) < GEOMETRY_TOL
        # the platform's top edge is centred on the model's platform centre, along its frame's axis
        np.testing.assert_allclose(top.mean(axis=0), fk.platform_position[module], rtol=0, atol=GEOMETRY_TOL)
        direction = (top[1] - top[0]) / np.linalg.norm(top[1] - top[0])
        expected = fk.platform_rotation[module][:, 1] if module == 0 else -fk.platform_rotation[module][:, 0]
        np.testing.assert_allclose(direction, expected, rtol=0, atol=1e-12)
        # legs meet at the joints: s and p share A, v and p share B'
        s, v, pp = (segments[JOINT_NAMES[i]] for i in legs)
        np.testing.assert_allclose(s[0], pp[0], rtol=0, atol=GEOMETRY_TOL)
        np.testing.assert_allclose(v[1], pp[1], rtol=0, atol=GEOMETRY_TOL)
        np.testing.assert_allclose(np.stack([s[0], v[0]]), base, rtol=0, atol=GEOMETRY_TOL)
        np.testing.assert_allclose(np.stack([s[1], v[1]]), top, rtol=0, atol=GEOMETRY_TOL)
    tool = segments["tool"]
    np.testing.assert_allclose(tool[1], fk.tip, rtol=0, atol=GEOMETRY_TOL)
    assert abs(np.linalg.norm(tool[1] - tool[0]) - p.h1) < GEOMETRY_TOL
    bar = segments["end_effector"]
    direction = (bar[1] - bar[0]) / np.linalg.norm(bar[1] - bar[0])
    np.testing.assert_allclose(direction, fk.rotation[:, 0], rtol=0, atol=1e-12)


def test_drawn_lengths_half_widths_and_tip_equal_the_model(robot, poses):
    for q in poses:
        artists = draw_mechanism(mechanism_geometry(robot, q))
        _check_against_model(robot, q, _drawn_segments(artists.ax))


def test_moving_the_drawing_keeps_it_the_model(robot, poses):
    """The animation's path: one drawing updated pose after pose."""
    geometries = mechanism_geometries(robot, poses)
    artists = draw_mechanism(geometries[0])
    for q, geometry in zip(poses[::-1], geometries[::-1], strict=True):
        artists.update(geometry)
        _check_against_model(robot, q, _drawn_segments(artists.ax))
        joints = np.column_stack(artists.joints._offsets3d) / MM
        expected = [p for name, p in geometry.joints.items() if name not in ("O1", "O2", "P")]
        np.testing.assert_allclose(joints, expected, rtol=0, atol=GEOMETRY_TOL)


def test_batched_geometry_equals_one_by_one(robot, poses):
    for q, batched in zip(poses[:5], mechanism_geometries(robot, poses[:5]), strict=True):
        single = mechanism_geometry(robot, q)
        for a, b in zip(single.segments, batched.segments, strict=True):
            assert a.name == b.name
            np.testing.assert_array_equal(a.start, b.start)
            np.testing.assert_array_equal(a.end, b.end)


def test_segments_come_in_drawing_order_and_every_joint_drives_one_bar(robot):
    geometry = mechanism_geometry(robot, robot.parameters.home)
    kinds = [SEGMENT_KINDS.index(s.kind) for s in geometry.segments]
    assert kinds == sorted(kinds)
    driven = sorted(s.joint for s in geometry.segments if s.joint is not None)
    assert driven == list(range(len(robot.parameters.home)))
    assert geometry.segment("end_effector").joint == twist_joint()
    with pytest.raises(InputError, match="segment = 'elbow'"):
        geometry.segment("elbow")


def test_limit_closeness_is_zero_mid_range_and_one_at_the_limits():
    lower, upper = np.array([0.2, -np.pi]), np.array([0.4, np.pi])
    np.testing.assert_allclose(limit_closeness([0.3, 0.0], lower, upper), [0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(limit_closeness(lower, lower, upper), [1.0, 1.0])
    np.testing.assert_allclose(limit_closeness(upper, lower, upper), [1.0, 1.0])
    np.testing.assert_allclose(limit_closeness([0.25, np.pi / 2], lower, upper), [0.5, 0.5])


def test_legs_are_coloured_by_their_closeness(robot):
    p = robot.parameters
    q = p.home.copy()
    s1 = JOINT_NAMES.index("s1")
    q[s1] = p.upper[s1] - 1e-4  # s1 near its upper limit (still assemblable)
    geometry = mechanism_geometry(robot, q)
    artists = draw_mechanism(geometry)
    for seg in geometry.segments:
        if seg.closeness is None:
            continue
        expected = artists.cmap(CLOSENESS_NORM(float(limit_closeness(q, p.lower, p.upper)[seg.joint])))
        assert to_rgba(artists.lines[seg.name].get_color()) == pytest.approx(expected)
    assert geometry.segment("s1").closeness > 0.99


def test_pose_figure_has_the_three_views_and_a_colour_bar(robot):
    fig = pose_figure(robot, robot.parameters.home)
    assert isinstance(fig, Figure)
    views = [ax for ax in fig.axes if ax.name == "3d"]
    assert [ax.get_title() for ax in views] == [v[0] for v in VIEWS]
    assert [(ax.elev, ax.azim) for ax in views] == [v[1] for v in VIEWS]
    colour_bars = [ax for ax in fig.axes if ax.name != "3d"]
    assert len(colour_bars) == 1 and "closeness" in colour_bars[0].get_ylabel()
    for ax in views:  # equal scaling: the box's sides are proportional to the axes' ranges
        ranges = np.array([np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()), np.ptp(ax.get_zlim())])
        np.testing.assert_allclose(ax.get_box_aspect() / ax.get_box_aspect().max(), ranges / ranges.max(), rtol=1e-9)


def test_pose_figure_refuses_a_wrong_joint_count(robot):
    with pytest.raises(InputError, match="joint values"):
        pose_figure(robot, robot.parameters.home[:-1])


def test_draw_command_writes_png_and_svg(tmp_path, capsys):
    home = [str(v) for v in cli.load_robot().parameters.home]
    assert cli.main(["draw", *home, "--out", str(tmp_path / "pose.png")]) == 0
    assert (tmp_path / "pose.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert cli.main(["draw", "--out", str(tmp_path / "home.svg")]) == 0
    assert b"<svg" in (tmp_path / "home.svg").read_bytes()[:400]
    assert "drawing written to" in capsys.readouterr().out
    assert not list(tmp_path.glob(".*tmp*"))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["draw", "0.3", "0.3", "--out", "x.png"], "joint values"),
        (["draw", "--out", "x.jpg"], "expected a file name ending in one of"),
        (["draw", "0.22", "0.30", "0.46", "0.28", "0.28", "0.37", "0", "--out", "x.png"], "triangle"),
    ],
)
def test_draw_command_reports_bad_input_in_one_line(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("vgtarm: error:") and message in err and "\n" not in err
    assert not list(tmp_path.iterdir())


def test_readme_images_are_small_pngs(robot, tmp_path):
    from vgtarm.app.pictures.readme_images import make_images

    for path in make_images(robot, tmp_path):
        data = path.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and 5_000 < len(data) < 80_000, (path.name, len(data))
