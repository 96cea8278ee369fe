"""Tests of vgtarm.paths: sample grids, analytic derivatives, fitted paths and input errors."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

import vgtarm.paths as paths
from vgtarm.errors import PathError

WAYPOINT_TIMES = (0.0, 0.7, 1.5, 2.4)
WAYPOINT_POINTS = (
    (0.0, 0.0, 0.60),
    (0.05, -0.02, 0.65),
    (0.0, 0.04, 0.62),
    (-0.03, 0.01, 0.60),
)
CASE2_CORNERS = ((0.03, -0.04, 0.64), (-0.04, 0.03, 0.68), (0.04, 0.05, 0.62))


def case1_exact(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Paper eq. 22 at the default parameters, written independently of paths.case1."""
    ax, ay, az, z0 = 0.06, 0.06, 0.03, 0.66
    s2, c2 = np.sin(2 * t), np.cos(2 * t)
    position = np.column_stack((ax * np.sin(t), ay * np.cos(t), z0 + az * s2 * c2))
    velocity = np.column_stack((ax * np.cos(t), -ay * np.sin(t), 2 * az * (c2**2 - s2**2)))
    acceleration = np.column_stack((-ax * np.sin(t), -ay * np.cos(t), -16 * az * s2 * c2))
    return position, velocity, acceleration


def write_csv(file, t: np.ndarray, position: np.ndarray, header: str = "t,x,y,z") -> None:
    """Write rows ``t,x,y,z`` with full float precision under ``header``."""
    rows = np.column_stack((t, position))
    np.savetxt(file, rows, fmt="%.17g", delimiter=",", header=header, comments="")


def write_text(tmp_path, text: str):
    file = tmp_path / "path.csv"
    file.write_text(text)
    return file


# --- Path record -----------------------------------------------------------------------------


def test_path_is_frozen_and_read_only():
    path = paths.case1(0.01)
    with pytest.raises(ValueError, match="read-only"):
        path.position[0, 0] = 1.0
    with pytest.raises(AttributeError):
        path.name = "other"  # type: ignore[misc]
    assert len(path) == path.t.shape[0]
    assert path.dt == pytest.approx(0.01, rel=1e-12)


def test_path_copies_its_inputs():
    t = np.arange(3) * 0.1
    position = np.zeros((3, 3))
    path = paths.TipPath("p", t, position, position, position)
    position[0, 0] = 1.0
    assert path.position[0, 0] == 0.0
    assert position.flags.writeable


@pytest.mark.parametrize(
    ("t", "position", "match"),
    [
        ([0.0], np.zeros((1, 3)), r"t must have shape \(N,\) with N >= 2"),
        ([0.0, 0.1, 0.3], np.zeros((3, 3)), r"t must be uniformly spaced.*t\[1\]"),
        ([0.2, 0.1, 0.0], np.zeros((3, 3)), "t must be strictly increasing"),
        ([0.0, np.nan, 0.2], np.zeros((3, 3)), r"^t\[1\] = nan: expected a finite number$"),
        ([0.0, 0.1, 0.2], np.zeros((3, 2)), r"position must have shape \(3, 3\)"),
        (
            [0.0, 0.1, 0.2],
            [[0, 0, 0], [0, np.inf, 0], [0, 0, 0]],
            r"^position\[1, 1\] = inf: expected a finite number$",
        ),
    ],
)
def test_path_validation_names_field(t, position, match):
    with pytest.raises(PathError, match=match):
        paths.TipPath("p", t, position, np.zeros((len(t), 3)), np.zeros((len(t), 3)))


# --- case 1 ----------------------------------------------------------------------------------


def test_case1_sample_grid():
    path = paths.case1(1e-3)
    assert path.name == "case1"
    assert len(path) == 6284
    assert path.t[0] == 0.0
    assert path.t[-1] == pytest.approx(6.283, abs=1e-12)
    np.testing.assert_allclose(np.diff(path.t), 1e-3, rtol=1e-9)
    assert path.dt == pytest.approx(1e-3, rel=1e-12)


def test_case1_endpoints_and_formula():
    path = paths.case1(1e-3)
    np.testing.assert_allclose(path.position[0], [0.0, 0.06, 0.66], atol=1e-15)
    np.testing.assert_allclose(path.velocity[0], [0.06, 0.0, 0.06], atol=1e-15)
    np.testing.assert_allclose(path.acceleration[0], [0.0, -0.06, 0.0], atol=1e-15)
    for k in (0, 1, 785, 1571, 3000, 6283):
        expected = case1_exact(path.t[k : k + 1])
        np.testing.assert_allclose(path.position[k], expected[0][0], rtol=0, atol=1e-14)
        np.testing.assert_allclose(path.velocity[k], expected[1][0], rtol=0, atol=1e-14)
        np.testing.assert_allclose(path.acceleration[k], expected[2][0], rtol=0, atol=1e-14)


def test_case1_parameters_and_duration():
    path = paths.case1(0.01, x0=0.1, y0=-0.2, z0=0.5, ax=0.02, ay=0.03, az=0.0, duration=1.0)
    assert len(path) == 101
    t = path.t
    np.testing.assert_allclose(path.position[:, 0], 0.1 + 0.02 * np.sin(t), atol=1e-15)
    np.testing.assert_allclose(path.position[:, 1], -0.2 + 0.03 * np.cos(t), atol=1e-15)
    np.testing.assert_allclose(path.position[:, 2], 0.5, atol=1e-15)


# --- analytic derivatives against finite differences ----------------------------------------

FD_DT = 1e-3


def _case1() -> tuple[paths.TipPath, tuple[float, ...]]:
    return paths.case1(FD_DT), ()


def _case2() -> tuple[paths.TipPath, tuple[float, ...]]:
    return paths.case2(FD_DT), (2.0,)


def _blend(blend: str) -> Callable[[], tuple[paths.TipPath, tuple[float, ...]]]:
    def make() -> tuple[paths.TipPath, tuple[float, ...]]:
        return paths.waypoints(WAYPOINT_TIMES, WAYPOINT_POINTS, FD_DT, blend=blend), (WAYPOINT_TIMES)

    return make


def _samples() -> tuple[paths.TipPath, tuple[float, ...]]:
    coarse = paths.case1(0.01)
    return paths.from_samples(coarse.t, coarse.position, FD_DT), tuple(coarse.t)


CONSTRUCTORS = {
    "case1": _case1,
    "case2": _case2,
    "cubic": _blend("cubic"),
    "quintic": _blend("quintic"),
    "spline": _blend("spline"),
    "from_samples": _samples,
}


@pytest.mark.parametrize("make", CONSTRUCTORS.values(), ids=CONSTRUCTORS.keys())
def test_derivatives_match_central_differences(make):
    """v = dx/dt and a = dv/dt to O(dt^2), away from knots where the pieces change.

    Central differences err by about dt^2/6 times the next derivative; 50 dt^2 leaves room for
    the largest (the quintic's fourth derivative, about 75 m/s^4) and is far below the size of
    any sign or factor mistake (~0.01 m/s).
    """
    path, knots = make()
    dt = path.dt
    tol = 50 * dt**2
    t = path.t[1:-1]
    interior = np.ones(t.shape, dtype=bool)
    for knot in knots:
        interior &= np.abs(t - knot) > 1.5 * dt
    fd_velocity = (path.position[2:] - path.position[:-2]) / (2 * dt)
    fd_acceleration = (path.velocity[2:] - path.velocity[:-2]) / (2 * dt)
    np.testing.assert_allclose(fd_velocity[interior], path.velocity[1:-1][interior], rtol=0, atol=tol)
    np.testing.assert_allclose(fd_acceleration[interior], path.acceleration[1:-1][interior], rtol=0, atol=tol)


# --- case 2 and waypoint blends --------------------------------------------------------------


def test_case2_corners_and_rest():
    path = paths.case2(1e-3)
    assert path.name == "case2"
    assert len(path) == 4001
    assert path.t[-1] == pytest.approx(4.0, abs=1e-12)
    for k, corner in zip((0, 2000, 4000), CASE2_CORNERS, strict=True):
        assert path.t[k] == pytest.approx(2.0 * k / 2000, abs=1e-12)
        np.testing.assert_allclose(path.position[k], corner, atol=1e-15)
        np.testing.assert_allclose(path.velocity[k], 0.0, atol=1e-15)


def test_case2_boundary_sample_uses_later_segment():
    path = paths.case2(1e-3)
    p0, p1, p2 = (np.array(c) for c in CASE2_CORNERS)
    np.testing.assert_allclose(path.acceleration[2000], 6 / 2.0**2 * (p2 - p1), atol=1e-14)
    np.testing.assert_allclose(path.acceleration[0], 6 / 2.0**2 * (p1 - p0), atol=1e-14)
    np.testing.assert_allclose(path.acceleration[-1], -6 / 2.0**2 * (p2 - p1), atol=1e-14)


def test_case2_is_cubic_waypoints():
    direct = paths.waypoints((0.0, 1.0, 2.5), CASE2_CORNERS, 1e-3, blend="cubic")
    path = paths.case2(1e-3, durations=(1.0, 1.5))
    for field in ("t", "position", "velocity", "acceleration"):
        np.testing.assert_array_equal(getattr(path, field), getattr(direct, field))


def test_case2_any_number_of_corners():
    corners = ((0, 0, 0.6), (0.01, 0, 0.6), (0.01, 0.01, 0.6), (0, 0.01, 0.6), (0, 0, 0.6))
    path = paths.case2(0.01, corners=corners, durations=(0.5, 0.5, 0.5, 0.5))
    assert len(path) == 201
    np.testing.assert_allclose(path.position[[0, 50, 100, 150, 200]], corners, atol=1e-15)


def _waypoint_indices(path: paths.TipPath) -> np.ndarray:
    return np.rint((np.array(WAYPOINT_TIMES) - path.t[0]) / path.dt).astype(int)


@pytest.mark.parametrize("blend", ["cubic", "quintic", "spline"])
def test_blends_pass_through_waypoints(blend):
    path = paths.waypoints(WAYPOINT_TIMES, WAYPOINT_POINTS, 1e-3, blend=blend)
    assert path.name == f"waypoints-{blend}"
    assert len(path) == 2401
    index = _waypoint_indices(path)
    np.testing.assert_allclose(path.t[index], WAYPOINT_TIMES, atol=1e-12)
    np.testing.assert_allclose(path.position[index], WAYPOINT_POINTS, atol=1e-14)
    np.testing.assert_allclose(path.velocity[[0, -1]], 0.0, atol=1e-14)


def test_quintic_rests_at_waypoints():
    path = paths.waypoints(WAYPOINT_TIMES, WAYPOINT_POINTS, 1e-3, blend="quintic")
    index = _waypoint_indices(path)
    np.testing.assert_allclose(path.velocity[index], 0.0, atol=1e-14)
    np.testing.assert_allclose(path.acceleration[index], 0.0, atol=1e-12)


@pytest.mark.parametrize(("blend", "continuous"), [("spline", True), ("cubic", False)])
def test_acceleration_continuity_across_knots(blend, continuous):
    """The spline is C2: across an interior knot acceleration changes only by ~2 dt * jerk."""
    path = paths.waypoints(WAYPOINT_TIMES, WAYPOINT_POINTS, 1e-4, blend=blend)
    index = _waypoint_indices(path)[1:-1]
    jump = np.abs(path.acceleration[index + 1] - path.acceleration[index - 1]).max()
    if continuous:
        assert jump < 1e-3
    else:
        assert jump > 0.1


def test_waypoints_not_multiple_of_dt_stops_before_end():
    path = paths.waypoints((0.0, 0.105), ((0, 0, 0), (0.01, 0, 0)), 0.01, blend="quintic")
    assert len(path) == 11
    assert path.t[-1] == pytest.approx(0.1)


# --- fitted paths: from_samples and from_csv -------------------------------------------------


def test_from_csv_round_trip(tmp_path):
    exact = paths.case1(1e-3)
    file = tmp_path / "case1.csv"
    write_csv(file, exact.t, exact.position)
    path = paths.from_csv(file)
    assert path.name == "case1"
    assert len(path) == len(exact)
    np.testing.assert_allclose(path.t, exact.t, rtol=0, atol=1e-12)
    inner = slice(50, -50)
    np.testing.assert_allclose(path.position, exact.position, rtol=0, atol=1e-14)
    np.testing.assert_allclose(path.velocity[inner], exact.velocity[inner], rtol=0, atol=1e-9)
    np.testing.assert_allclose(path.acceleration[inner], exact.acceleration[inner], rtol=0, atol=1e-6)


def test_from_csv_header_tolerance_and_resampling(tmp_path):
    exact = paths.case1(0.01, duration=1.0)
    file = tmp_path / "loose.csv"
    write_csv(file, exact.t, exact.position, header=" T , X,y ,Z ")
    path = paths.from_csv(file, dt=0.002, name="loose")
    assert path.name == "loose"
    assert len(path) == 501
    assert path.dt == pytest.approx(0.002)
    np.testing.assert_allclose(path.position[::5], exact.position, atol=1e-14)


def test_from_samples_needs_dt_for_uneven_times():
    t = np.array([0.0, 0.1, 0.25, 0.4])
    position = np.column_stack((t, t**2, np.zeros(4)))
    with pytest.raises(PathError, match=r"step 0\.1 s from index 0 to index 1.*pass dt"):
        paths.from_samples(t, position)
    path = paths.from_samples(t, position, dt=0.05, name="uneven")
    assert path.name == "uneven"
    assert len(path) == 9
    np.testing.assert_allclose(path.position[:, 1], path.t**2, atol=1e-14)
    np.testing.assert_allclose(path.acceleration[:, 1], 2.0, atol=1e-12)


# --- input errors ----------------------------------------------------------------------------

GOOD_POINTS = ((0.0, 0.0, 0.6), (0.01, 0.0, 0.6), (0.01, 0.01, 0.6))


@pytest.mark.parametrize("dt", [0.0, -1e-3, math.nan, math.inf, "fast"])
@pytest.mark.parametrize(
    "call",
    [
        lambda dt: paths.case1(dt),
        lambda dt: paths.case2(dt),
        lambda dt: paths.waypoints((0.0, 1.0, 2.0), GOOD_POINTS, dt),
        lambda dt: paths.from_samples((0.0, 1.0, 2.0), GOOD_POINTS, dt),
    ],
    ids=["case1", "case2", "waypoints", "from_samples"],
)
def test_bad_dt(call, dt):
    with pytest.raises(PathError, match=r"^dt = .*: expected a finite number >= 1e-06 \(s\)$"):
        call(dt)


def test_dt_longer_than_path():
    with pytest.raises(PathError, match="shorter than dt"):
        paths.waypoints((0.0, 0.5), GOOD_POINTS[:2], 1.0)


@pytest.mark.parametrize("call", [paths.waypoints, paths.from_samples], ids=["waypoints", "from_samples"])
@pytest.mark.parametrize(
    ("times", "points", "match"),
    [
        ((0.0, 1.0, 1.0), GOOD_POINTS, r"index 2: .* strictly increasing, got 1\.0 after 1\.0"),
        ((0.0, 2.0, 1.0), GOOD_POINTS, r"index 2: .* strictly increasing, got 1\.0 after 2\.0"),
        ((0.0,), GOOD_POINTS[:1], r"need at least 2 points, got 1"),
        ((0.0, 1.0, 2.0), ((0, 0), (1, 1), (2, 2)), r"shape \(n, 3\), got shape \(3, 2\)"),
        ((0.0, 1.0), GOOD_POINTS, r"same length, got 2 times and 3 points"),
        (((0.0, 1.0),), GOOD_POINTS, r"must be 1-dimensional"),
        ((0.0, math.nan, 2.0), GOOD_POINTS, r"index 1: .* is nan, must be finite"),
        ((0.0, 1.0, 2.0), (*GOOD_POINTS[:2], (0, math.inf, 0)), r"index 2: .* column 'y' is inf, must be finite"),
        ((0.0, 1.0, 2.0), "abc", r"must be an array of numbers"),
    ],
)
def test_bad_timed_points(call, times, points, match):
    with pytest.raises(PathError, match=match):
        call(times, points, 0.1)


def test_unknown_blend_lists_valid_names():
    with pytest.raises(PathError, match=r"^blend = 'linear': expected one of \['cubic', 'quintic', 'spline'\]$"):
        paths.waypoints((0.0, 1.0), GOOD_POINTS[:2], blend="linear")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"durations": (2.0,)}, r"durations must have one entry per line, shape \(2,\)"),
        ({"durations": (2.0, 0.0)}, r"^durations\[1\] = 0\.0: expected a finite number > 0 \(s\)$"),
        ({"durations": (math.nan, 2.0)}, r"^durations\[0\] = nan: expected a finite number > 0"),
        ({"corners": ((0, 0, 0),), "durations": ()}, r"corners: need at least 2 points"),
        ({"corners": ((0, 0), (1, 1))}, r"corners must have shape \(n, 3\)"),
    ],
)
def test_case2_bad_arguments(kwargs, match):
    with pytest.raises(PathError, match=match):
        paths.case2(1e-3, **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"duration": 0.0}, r"^duration = 0\.0: expected a finite number > 0 \(s\)$"),
        ({"az": math.nan}, r"^az = nan: expected a finite number \(m\)$"),
        ({"x0": "left"}, r"^x0 = 'left': expected a finite number \(m\)$"),
    ],
)
def test_case1_bad_arguments(kwargs, match):
    with pytest.raises(PathError, match=match):
        paths.case1(1e-3, **kwargs)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", r"is empty; expected a header row t,x,y,z"),
        ("t,x,y\n0,0,0\n", r"line 1: header must be the columns t,x,y,z \(.*\); found 3 columns t, x, y$"),
        ("time,x,y,z\n0,0,0,0\n", r"line 1: header .* found 4 columns time, x, y, z$"),
        ("t,x,y,z\n0,0,0,0\n0.1,0,0\n", r"line 3: expected 4 fields \(t,x,y,z\), found 3"),
        ("t,x,y,z\n0,0,0,0\n0.1,0,0,0,5\n", r"line 3: expected 4 fields .* found 5"),
        ("t,x,y,z\n0,0,0,0\n0.1,0,abc,0\n", r"line 3, column 'y': 'abc' is not a number"),
        ("t,x,y,z\n0,0,0,0\n0.1,0,,0\n", r"line 3, column 'y': '' is not a number"),
        ("t,x,y,z\n0,0,0,0\n0.1,0,0,nan\n", r"line 3, column 'z': 'nan' is not finite"),
        ("t,x,y,z\n0,0,0,0\n0.1,inf,0,0\n", r"line 3, column 'x': 'inf' is not finite"),
        ("t,x,y,z\n0,0,0,0\n", r"need at least 2 data rows after the header, got 1"),
        ("t,x,y,z\n", r"need at least 2 data rows after the header, got 0"),
        (
            "t,x,y,z\n0,0,0,0\n0.1,0,0,0\n\n0.1,0,0,0\n",
            r"line 5: t must be strictly increasing, got 0\.1 after 0\.1 \(line 3\)",
        ),
        (
            "t,x,y,z\n0,0,0,0\n0.1,0,0,0\n0.2,0,0,0\n0.4,0,0,0\n",
            r"t is not uniformly spaced: step 0\.2 s from line 4 to line 5.*pass dt",
        ),
    ],
)
def test_from_csv_bad_content(tmp_path, text, match):
    with pytest.raises(PathError, match=match):
        paths.from_csv(write_text(tmp_path, text))


def test_from_csv_error_names_file(tmp_path):
    file = write_text(tmp_path, "t,x,y,z\n0,0,0,0\n0.1,0,zero,0\n")
    with pytest.raises(PathError, match="path.csv"):
        paths.from_csv(file)


def test_from_csv_missing_file(tmp_path):
    missing = tmp_path / "nowhere.csv"
    with pytest.raises(PathError, match=r"path file .*nowhere\.csv: not found"):
        paths.from_csv(missing)


def test_from_csv_accepts_blank_lines_and_spaces(tmp_path):
    file = write_text(tmp_path, "t, x, y, z\n\n0.0, 0, 0, 0.6\n0.1, 0.01, 0, 0.6\n\n")
    path = paths.from_csv(file)
    assert len(path) == 2
    np.testing.assert_allclose(path.position[-1], (0.01, 0.0, 0.6))


def test_the_old_name_path_still_works_and_says_it_moved():
    """``TipPath`` is the desired path; ``Path``, which shadowed :class:`pathlib.Path`, is gone from
    the module's names and still resolves, with a DeprecationWarning."""
    assert "Path" not in vars(paths) and "Path" not in dir(paths)
    with pytest.warns(DeprecationWarning, match="TipPath"):
        assert paths.Path is paths.TipPath
    with pytest.raises(AttributeError):
        paths.Pathh  # noqa: B018
