"""The workspace and dexterity analysis (vgtarm.design.workspace, vgtarm.design.measures) and
``vgtarm workspace``: each number against something independent (forward kinematics, an analytic
extreme, Monte Carlo, central differences, the closure equations built from the robot's passive
angles)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.app.cli.workspace import add_parser
from vgtarm.design import measures as dx
from vgtarm.design import workspace as ws
from vgtarm.errors import AssemblyError, InputError

from .conftest import central_difference

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: Highest tip of the reference robot: both modules symmetric with the longest legs (0.36 m), the
#: twist part (0.10 m) on top: 2 sqrt(0.36^2 - 0.05^2) + 0.1 (docs/conventions.md).
TOP = 2.0 * math.sqrt(0.36**2 - 0.05**2) + 0.1


@pytest.fixture(scope="module")
def paper() -> vgtarm.Robot:
    return vgtarm.load_robot()


@pytest.fixture(scope="module")
def six() -> vgtarm.Robot:
    return vgtarm.load_robot(EXAMPLES / "six_modules.toml")


@pytest.fixture(scope="module")
def reach(paper: vgtarm.Robot) -> ws.ReachTest:
    return ws.ReachTest(paper, cloud=5000, seed=0)


# -- the chart ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["paper", "six"])
def test_chart_maps_the_box_onto_assemblable_joints_inside_the_limits(name: str, request: pytest.FixtureRequest):
    robot = request.getfixturevalue(name)
    chart = ws.JointChart(robot)
    u, q = chart.sample(4000, np.random.default_rng(1), faces=0.3)
    lower, upper = robot.joint_limits()
    assert robot.is_assemblable(q).all()
    assert ((q >= lower) & (q <= upper)).all()
    # every feasible configuration (away from the thin layer at the folds) is reached: q -> u -> q
    rng = np.random.default_rng(2)
    drawn = rng.uniform(lower, upper, size=(4000, robot.n_joints))
    drawn = drawn[robot.is_assemblable(drawn, margin=1e-6)]
    np.testing.assert_allclose(chart.joints(chart.box(drawn))[0], drawn, atol=1e-12)


def test_chart_jacobian_matches_central_differences(paper: vgtarm.Robot):
    chart = ws.JointChart(paper)
    u = np.random.default_rng(3).uniform(0.05, 0.95, size=(40, paper.n_joints))
    _, factors = chart.joints(u)
    analytic = chart.pull_back(np.repeat(np.eye(paper.n_joints)[None], len(u), axis=0), factors)
    numeric = central_difference(lambda x: chart.joints(x)[0], u, h=1e-6)
    np.testing.assert_allclose(analytic, numeric, atol=1e-7)


# -- membership and bounds ---------------------------------------------------------------------------


def test_forward_kinematics_tips_are_inside_and_points_above_the_top_are_outside(paper, reach):
    _, q = reach.chart.sample(300, np.random.default_rng(4))
    assert reach.contains(paper.tip_position(q)).all()
    above = np.column_stack([np.zeros(20), np.linspace(-0.1, 0.1, 20), np.full(20, TOP + 0.002)])
    solved = reach.solve(above)
    assert not (solved.residual < reach.tol).any()
    assert (solved.residual >= 0.002 - 1e-9).all()  # the top is the nearest the tip gets


def test_bounding_box_top_is_the_analytic_highest_tip(reach):
    lower, upper = ws.reach_bounds(reach)
    assert upper[2] == pytest.approx(TOP, abs=1e-7)
    tips = reach.robot.tip_position(reach.chart.sample(20000, np.random.default_rng(5))[1])
    assert (tips >= lower - 1e-9).all() and (tips <= upper + 1e-9).all()


def test_dexterous_membership_holds_the_tool_axis_in_the_cone(paper):
    test = ws.ReachTest(paper, cone=15.0, axis=(0, 0, 1), cloud=5000)
    _, q = test.chart.sample(400, np.random.default_rng(6))
    tips = paper.tip_position(q)
    inside = test.in_cone(q)
    assert test.contains(tips[inside]).all()  # reached with the same configuration at least
    solved = test.solve(tips)
    found = solved.residual < test.tol
    angle = np.degrees(np.arccos(np.clip(paper.tool_axis(solved.q[found]) @ [0, 0, 1], -1, 1)))
    assert (angle <= 15.0 + 1e-3).all()
    assert found.sum() >= inside.sum()


# -- volumes -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("cone", [180.0, 25.0])
def test_voxel_volume_agrees_with_monte_carlo(paper, cone):
    """The grown-voxel volume of a coarse grid against a Monte Carlo estimate of the same set; the
    tolerance is 4 standard errors of the estimate and 2 % for the coarse grid (docs/workspace.md
    records the 10^6-sample comparison: within 0.3 %)."""
    test = ws.ReachTest(paper, cone=cone, cloud=5000, seed=0)
    extent = float((ws.reach_bounds(test)[1] - ws.reach_bounds(test)[0]).max())
    volume = ws.workspace_volume(paper, test=test, voxel=extent / 16, samples=100_000, seed=0)
    check = ws.monte_carlo_volume(paper, 4000, 1, test=test)
    assert abs(volume.volume - check.volume) <= 4 * check.standard_error + 0.02 * check.volume
    assert volume.measured > 0 and volume.tests == volume.measured * volume.refine**3


def test_planar_module_has_no_volume():
    robot = vgtarm.load_robot(EXAMPLES / "planar_module.toml")
    with pytest.raises(ws.NoVolumeError, match="no volume"):
        ws.workspace_volume(robot, samples=1000)


def test_slices_trace_the_boundary(reach):
    lower, upper = ws.reach_bounds(reach)
    (piece,) = ws.workspace_slices(reach, [0.63], lower, upper, resolution=20, bisections=10)
    assert piece.loops and piece.area == pytest.approx(piece.grid_area, rel=0.1)
    points = np.concatenate(piece.loops)
    # each boundary point lies between an inside and an outside point 1 mm apart along x or y
    offsets = np.array([[1e-3, 0], [-1e-3, 0], [0, 1e-3], [0, -1e-3]])
    near = (points[:, None, :] + offsets[None] * 0.5).reshape(-1, 2)
    found = reach.contains(np.column_stack([near, np.full(len(near), 0.63)])).reshape(len(points), 4)
    assert (found.any(axis=1) & ~found.all(axis=1)).mean() > 0.9
    text = ws.slices_csv({"reachable": (piece,)})
    assert text.startswith("set,z,loop,x,y\n") and text.count("\n") == 1 + len(points)


# -- dexterity ---------------------------------------------------------------------------------------


def test_condition_number_at_home_is_3_06_against_central_differences(paper):
    home = paper.parameters.home
    measured = dx.dexterity(paper, home)
    numeric = central_difference(paper.tip_position, home[None])[0]
    sigma = np.linalg.svd(numeric, compute_uv=False)
    assert measured.condition[0] == pytest.approx(sigma[0] / sigma[-1], rel=1e-7)
    assert measured.condition[0] == pytest.approx(3.06, abs=0.005)
    assert measured.manipulability[0] == pytest.approx(np.sqrt(np.linalg.det(numeric @ numeric.T)), rel=1e-7)


@pytest.mark.parametrize("name", ["paper", "six"])
def test_measures_on_a_batch_are_identities_of_the_singular_values(name, request):
    robot = request.getfixturevalue(name)
    q = ws.JointChart(robot).sample(50, np.random.default_rng(7))[1]
    found = dx.dexterity(robot, q)
    assert found.module_distance.shape == (50, robot.n_modules)
    np.testing.assert_allclose(found.manipulability, found.singular_values.prod(axis=1), rtol=1e-9)
    np.testing.assert_allclose(found.condition, found.singular_values[:, 0] / found.singular_values[:, 2])
    assert ((found.module_distance > 0) & (found.module_distance <= 1)).all()


def _closure_determinant(robot: vgtarm.Robot, q: np.ndarray) -> np.ndarray:
    """det of each module's closure Jacobian d(|B'-A|, |B'-B|, |A'-A|, |A'-B'|)/d(B', A') built from
    the passive angles the robot's forward kinematics returns (docs/conventions.md), ``(N, m)``."""
    passive = robot.forward_kinematics(q).passive
    legs = np.array(robot.parameters.margin_legs())
    b = np.asarray(robot.parameters.b)
    alpha, beta = passive[..., 0], passive[..., 1]
    s, p = q[:, legs[:, 0]], q[:, legs[:, 2]]
    a, bb = np.stack([-b, 0 * b], -1), np.stack([b, 0 * b], -1)
    b_top = a + p[..., None] * np.stack([np.cos(beta), np.sin(beta)], -1)
    a_top = a + s[..., None] * np.stack([np.cos(alpha), np.sin(alpha)], -1)
    rows = np.zeros(q.shape[:1] + (len(b), 4, 4))
    unit = lambda v: v / np.linalg.norm(v, axis=-1, keepdims=True)  # noqa: E731
    rows[..., 0, :2] = unit(b_top - a)
    rows[..., 1, :2] = unit(b_top - bb)
    rows[..., 2, 2:] = unit(a_top - a)
    edge = unit(a_top - b_top)
    rows[..., 3, :2], rows[..., 3, 2:] = -edge, edge
    return np.abs(np.linalg.det(rows))


def test_module_distance_is_the_closure_jacobian_and_vanishes_where_assembly_fails(paper):
    q = ws.JointChart(paper).sample(40, np.random.default_rng(8))[1]
    sin_b, sin_a = dx.triangle_sines(paper, q)
    np.testing.assert_allclose(_closure_determinant(paper, q), sin_b * sin_a, atol=1e-12)
    # towards the fold s = p - 2d of module 1: the distance goes to zero as sqrt of the margin
    home = paper.parameters.home.copy()
    home[2] = 0.44
    margins = np.array([1e-2, 1e-4, 1e-6, 1e-8])
    folds = np.tile(home, (len(margins), 1))
    folds[:, 0] = home[2] - 0.2 + margins
    distance = dx.module_distance(paper, folds)[:, 0]
    assert np.all(np.diff(distance) < 0) and distance[-1] < 1e-3
    np.testing.assert_allclose(distance / np.sqrt(margins), distance[-1] / 1e-4, rtol=0.1)
    assert np.all(_closure_determinant(paper, folds)[:, 0] <= distance + 1e-9)
    folds[-1, 0] = home[2] - 0.2  # on the fold itself: cannot be assembled
    with pytest.raises(AssemblyError):
        dx.dexterity(paper, folds)


def test_joint_grid_and_a_trajectory(paper):
    grid = dx.joint_grid(paper, {"p1": 5, "s2": 4})
    assert grid.shape[1] == paper.n_joints and 0 < len(grid) <= 20
    assert dx.dexterity(paper, grid).condition.shape == (len(grid),)
    with pytest.raises(InputError, match="counts"):
        dx.joint_grid(paper, {"x9": 3})


# -- refusals and the command ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (dict(cone=0.0), "cone = 0.0"),
        (dict(cone=181.0), "cone = 181.0"),
        (dict(axis=(0, 0, 0)), "axis = "),
        (dict(axis=(0, 1)), "axis = "),
        (dict(cloud=10), "cloud = 10"),
    ],
)
def test_bad_inputs_are_refused_in_one_line(paper, options, message):
    with pytest.raises(InputError, match=message):
        ws.ReachTest(paper, **options)


def test_bad_samples_and_configurations_are_refused(paper, reach):
    with pytest.raises(InputError, match="samples = 10"):
        ws.monte_carlo_volume(paper, 10, 0, test=reach)
    with pytest.raises(InputError, match="points"):
        reach.solve([[0.0, np.nan, 0.6]])
    with pytest.raises(InputError, match="shape"):
        dx.dexterity(paper, np.zeros((3, paper.n_joints + 1)))


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_parser(parser.add_subparsers())
    return parser.parse_args(["workspace", *argv])


@pytest.mark.parametrize("flag", [["--cone", "0"], ["--cone", "200"], ["--axis", "0,0,0"], ["--samples", "5"]])
def test_command_refuses_bad_flags(flag, tmp_path, capsys):
    with pytest.raises(SystemExit):
        _parse([*flag, "--out", str(tmp_path / "out")])
    assert "expected" in capsys.readouterr().err


def test_command_writes_the_summary_and_figures(tmp_path, capsys):
    args = _parse(["--samples", "1000", "--voxel", "0.06", "--grid", "10", "--out", str(tmp_path / "out")])
    assert args.run(args) == 0
    printed = capsys.readouterr().out
    assert "condition number 3.0559" in printed and "Monte Carlo" in printed
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["home"]["condition_number"] == pytest.approx(3.0559, abs=1e-4)
    assert summary["workspaces"]["dexterous"]["volume_m3"] < summary["workspaces"]["reachable"]["volume_m3"]
    for name in ("slices.png", "workspace_3d.png", "slices.csv", "workspace.html"):
        assert (tmp_path / "out" / name).stat().st_size > 0
    _the_page_renders_in_a_real_browser(tmp_path / "out" / "workspace.html", summary)


def _the_page_renders_in_a_real_browser(page, summary):
    """The page opens in headless Chromium with its one 3-D plot drawn (both sets' boundaries and
    slices), its PNG figures inlined, its table giving the volumes, and no error or request outside."""
    from tests.test_html_report import browser_tab

    with browser_tab(page, 1) as (tab, problems):
        traces = tab.evaluate("document.getElementById('workspace-3d').data.map(t => t.name)")
        text = tab.inner_text("body")
        images = tab.evaluate("Array.from(document.images).map(i => i.naturalWidth)")
    assert traces == ["reachable: boundary", "reachable: slices", "dexterous: boundary", "dexterous: slices"]
    assert f"{1e3 * summary['workspaces']['reachable']['volume_m3']:.4f}" in text
    assert "condition number of the tip Jacobian 3.0559" in text
    assert len(images) == 2 and min(images) > 0
    assert problems == []
