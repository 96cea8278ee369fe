"""Tool paths: a tip path with the tool's axis or its whole frame, and the builders of drilling and cutting.

A :class:`ToolPath` is a :class:`~vgtarm.paths.TipPath` (the tool's tip) with the desired tool axis
(:class:`~vgtarm.ik.AxisPath`, the spin free) or the desired tool frame (its rotation, angular
velocity and acceleration), all exact derivatives of one motion model, never finite differences.
``ToolPath.task(robot)`` gives the keywords of :func:`vgtarm.inverse_kinematics`.

- :func:`drilling`: approach (a straight line from a start point while the axis turns onto the
  drill's axis), plunge along the axis through the entry point to a depth at a constant feed rate,
  dwell, retract along the axis. The axis task: the drill's spin is free.
- :func:`cutting`: an arc (or a straight cut) of a given length on a plane, the blade's edge along
  the cut's tangent and its axis tilted by a held angle about the edge from the plane's inward
  normal. The tool frame is given in full (a blade's spin is not free), and it turns about the
  plane's normal at ``kappa * ds/dt``: its angular velocity and acceleration are exact.

Every motion along a line or an arc follows the same speed profile: from rest, the speed rises to
its cruise value along a quintic ``10 x^3 - 15 x^4 + 6 x^5`` of the ramp time (so the acceleration
is continuous and zero at both ends), holds, and falls again to rest. Units are SI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import checks
from .errors import PathError, shown
from .ik.axis import UNIT_TOLERANCE, AxisPath, unit_directions, unit_part
from .ik.pose import OrientationPath
from .paths import MIN_DT, TipPath

if TYPE_CHECKING:
    from .model.robot import Robot

Array = NDArray[np.float64]

#: Default ramp time of a motion's speed (s): from rest to the cruise speed.
RAMP = 0.2


@dataclass(frozen=True, eq=False)
class ToolPath:
    """A tip path with the desired tool axis or tool frame.

    Attributes:
        tip: the tool tip's path (:class:`~vgtarm.paths.TipPath`).
        axis: ``(N, 3)`` the desired tool axis (F0), its rate and acceleration, as an
            :class:`~vgtarm.ik.AxisPath`, or None when the whole frame is given.
        frame: ``(N, 3, 3)`` the desired tool frame in F0, its columns the tool frame's axes (``x`` the
            blade's edge, ``z`` the tool axis, ``y = z x x``), or None.
        angular_velocity, angular_acceleration: ``(N, 3)`` of ``frame`` (rad/s, rad/s^2), or None.
        phases: ``(name, start, end)`` times (s) of the path's phases, in order.
        entry_point: ``(3,)`` where the tool enters the work (m), or None.
    """

    tip: TipPath
    axis: AxisPath | None = None
    frame: Array | None = None
    angular_velocity: Array | None = None
    angular_acceleration: Array | None = None
    phases: tuple[tuple[str, float, float], ...] = ()
    entry_point: Array | None = None

    @property
    def name(self) -> str:
        """The tip path's name."""
        return self.tip.name

    def task(self, robot: Robot) -> dict[str, Any]:
        """The keywords of :func:`vgtarm.inverse_kinematics` for ``robot``: ``axis`` (the axis task), or
        ``pose`` (the end-effector frame ``C03 = F B^T`` of the tool frame ``F``, ``B`` the robot's
        tool rotation, with the same angular velocity and acceleration)."""
        if self.axis is not None:
            return {"axis": self.axis}
        assert self.frame is not None
        tool: Array = np.array(robot.tool_rotation, dtype=np.float64)
        rotation = self.frame @ tool.T
        return {"pose": OrientationPath(rotation, self.angular_velocity, self.angular_acceleration)}


@dataclass(frozen=True)
class _Motion:
    """Arc length ``s`` and its first three time derivatives ``(N,)`` of a motion along a line or arc."""

    s: Array
    v: Array
    a: Array
    j: Array


def _unit(name: str, value: object) -> Array:
    vector = checks.finite_array(name, value, (3,), error=PathError)
    return np.asarray(unit_directions(vector, 1, name, error=PathError)[0])


def _point(name: str, value: object) -> Array:
    return checks.finite_array(name, value, (3,), error=PathError).astype(float)


def _profile(distance: float, speed: float, ramp: float) -> tuple[float, float]:
    """The ramp time and the total time of a motion over ``distance`` at cruise ``speed``."""
    if distance <= 0.0:
        return 0.0, 0.0
    ramp = min(ramp, distance / speed)  # too short to cruise: ramp up then down
    return ramp, distance / speed + ramp


def _rest_to_cruise(tau: Array, speed: float, ramp: float) -> tuple[Array, Array, Array, Array]:
    """``s, ds/dt, d2s/dt2, d3s/dt3`` of the ramp from rest to ``speed`` over ``ramp`` seconds, at ``tau``."""
    x = np.clip(tau / ramp, 0.0, 1.0)
    s = speed * ramp * x**4 * (2.5 - 3 * x + x**2)
    v = speed * x**3 * (10 - 15 * x + 6 * x**2)
    a = speed * 30 * x**2 * (1 - x) ** 2 / ramp
    j = np.where(x < 1, speed * 60 * x * (1 - x) * (1 - 2 * x) / ramp**2, 0.0)
    return s, v, a, j


def _move(t: Array, distance: float, speed: float, ramp: float) -> _Motion:
    """The motion ``s(t)`` from rest at 0 to rest at ``distance`` (cruise ``speed``), ``t`` (s) from its start."""
    r, total = _profile(distance, speed, ramp)
    if total == 0.0:
        zero = np.zeros_like(t)
        return _Motion(zero, zero, zero, zero)
    cruise = distance / (total - r)
    s, v, a, j = _rest_to_cruise(t, cruise, r)
    middle = (t > r) & (t < total - r)
    s = np.where(middle, cruise * (r / 2 + t - r), s)
    v = np.where(middle, cruise, v)
    a, j = np.where(middle, 0.0, a), np.where(middle, 0.0, j)
    end = t >= total - r
    s_e, v_e, a_e, j_e = _rest_to_cruise(total - t, cruise, r)
    s, v = np.where(end, distance - s_e, s), np.where(end, v_e, v)
    a, j = np.where(end, -a_e, a), np.where(end, j_e, j)
    return _Motion(s, v, a, j)


def _times(duration: float, dt: float) -> Array:
    dt = checks.number("dt", dt, minimum=MIN_DT, unit="s", error=PathError)
    count = int(math.floor(duration / dt + 1e-9)) + 1
    return np.arange(count, dtype=np.float64) * dt


def _rotate(k: Array, angle: Array, v: Array) -> Array:
    """``v`` ``(3,)`` or ``(N, 3)`` turned about the unit ``k`` by ``angle`` ``(N,)`` (Rodrigues)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    v = np.broadcast_to(v, (angle.shape[0], 3))
    return np.asarray(v * c + np.cross(k, v) * s + (1 - c) * (v @ k)[:, None] * k)


def _turning(d0: Array, d: Array, angle: Array, speed: Array, acceleration: Array) -> tuple[Array, Array, Array]:
    """The unit vector ``d0`` turned towards ``d`` about their common normal by ``angle`` ``(N,)``, with
    its rate and acceleration for the angle's ``speed`` and ``acceleration``."""
    k = np.cross(d0, d) / np.linalg.norm(np.cross(d0, d))
    direction = _rotate(k, angle, d0)
    across = np.cross(k, direction)
    rate = speed[:, None] * across
    return direction, rate, acceleration[:, None] * across + speed[:, None] ** 2 * np.cross(k, across)


def _clock(spans: tuple[float, ...], dt: float) -> tuple[Array, Array, Array, Array, Array]:
    """The samples of motions lasting ``spans`` (s) one after the other: the times, each motion's start
    and end, each sample's motion (the last one's end included in it) and its time from that start."""
    ends = np.cumsum(spans)
    t = _times(float(ends[-1]), dt)
    starts = np.concatenate([[0.0], ends[:-1]])
    phase = np.minimum(np.searchsorted(ends, t, side="right"), len(spans) - 1)
    return t, starts, ends, phase, t - starts[phase]


def drilling(
    entry: ArrayLike,
    axis: ArrayLike,
    depth: float,
    *,
    feed: float = 2e-3,
    dwell: float = 0.5,
    clearance: float = 5e-3,
    start: ArrayLike | None = None,
    start_axis: ArrayLike | None = None,
    approach_speed: float = 0.02,
    ramp: float = RAMP,
    dt: float = 1e-3,
) -> ToolPath:
    """A drilling cycle: approach and align, plunge at the feed rate, dwell, retract along the axis.

    Args:
        entry: ``(3,)`` where the drill enters the work (m).
        axis: ``(3,)`` unit vector, the direction the drill advances (F0).
        depth: how deep past the entry point (m, > 0).
        feed: the plunge's feed rate (m/s, > 0); reached before the entry point.
        dwell: time at the bottom of the hole (s, >= 0).
        clearance: the plunge starts and the retract ends this far before the entry point, on the
            axis (m, > 0).
        start: ``(3,)`` where the approach starts (m); default: at the plunge's start (no approach).
        start_axis: ``(3,)`` unit tool axis at ``start``; default ``axis`` (it turns onto ``axis`` during
            the approach, about their common normal, with the approach's profile).
        approach_speed: cruise speed of the approach and the retract (m/s).
        ramp: ramp time of every motion's speed (s).
        dt: sampling period (s).

    Returns:
        A :class:`ToolPath` named ``"drilling"`` with the axis task (phases ``approach``, ``plunge``,
        ``dwell``, ``retract``).
    """
    e, d = _point("entry", entry), _unit("axis", axis)
    depth = checks.positive("depth", depth, "m", error=PathError)
    feed = checks.positive("feed", feed, "m/s", error=PathError)
    dwell = checks.number("dwell", dwell, minimum=0.0, unit="s", error=PathError)
    clearance = checks.positive("clearance", clearance, "m", error=PathError)
    approach_speed = checks.positive("approach_speed", approach_speed, "m/s", error=PathError)
    ramp = checks.positive("ramp", ramp, "s", error=PathError)
    above = e - clearance * d
    p0 = above if start is None else _point("start", start)
    d0 = d if start_axis is None else _unit("start_axis", start_axis)
    reach = float(np.linalg.norm(above - p0))
    turn = float(np.arctan2(np.linalg.norm(np.cross(d0, d)), d0 @ d))
    # the approach lasts as long as the longer of its travel and of its turn (0.1 m per radian)
    approach = max(reach, 0.1 * turn)
    spans = (
        _profile(approach, approach_speed, ramp)[1],
        _profile(clearance + depth, feed, ramp)[1],
        dwell,
        _profile(clearance + depth, approach_speed, ramp)[1],
    )
    t, starts, ends, phase, local = _clock(spans, dt)
    position, velocity, acceleration, jerk = (np.zeros((t.size, 3)) for _ in range(4))
    direction, rate, turning = np.tile(d, (t.size, 1)), np.zeros((t.size, 3)), np.zeros((t.size, 3))
    # approach: a straight line from p0 while the axis turns from d0 onto d, on one profile u in [0, 1]
    on = phase == 0
    if approach > 0:
        u = _move(local[on], approach, approach_speed, ramp)
        fraction = (u.s / approach, u.v / approach, u.a / approach, u.j / approach)
        position[on], velocity[on], acceleration[on], jerk[on] = (np.outer(f, above - p0) for f in fraction)
        position[on] += p0
        if turn > 0:
            direction[on], rate[on], turning[on] = _turning(d0, d, *(turn * f for f in fraction[:3]))
    # plunge, dwell, retract: along the axis from ``above``
    for index, speed, sign in ((1, feed, 1.0), (3, approach_speed, -1.0)):
        on = phase == index
        motion = _move(local[on], clearance + depth, speed, ramp)
        base = above if sign > 0 else e + depth * d
        position[on] = base + np.outer(sign * motion.s, d)
        velocity[on], acceleration[on], jerk[on] = (np.outer(sign * f, d) for f in (motion.v, motion.a, motion.j))
    position[phase == 2] = e + depth * d
    names = ("approach", "plunge", "dwell", "retract")
    phases = tuple((names[i], float(starts[i]), float(ends[i])) for i in range(4))
    tip = TipPath("drilling", t, position, velocity, acceleration, jerk)
    return ToolPath(tip, axis=AxisPath(direction, rate, turning), phases=phases, entry_point=e)


def cutting(
    start: ArrayLike,
    direction: ArrayLike,
    normal: ArrayLike,
    length: float,
    *,
    radius: float = math.inf,
    tilt: float = 0.0,
    speed: float = 0.01,
    ramp: float = RAMP,
    dt: float = 1e-3,
) -> ToolPath:
    """A cut of ``length`` on a plane: the blade's edge along the cut, its axis tilted by a held angle.

    Args:
        start: ``(3,)`` where the cut starts, on the plane (m).
        direction: ``(3,)`` unit, the cut's direction at its start (in the plane).
        normal: ``(3,)`` unit normal of the plane, pointing out of the work (towards the tool): the
            blade's axis points along ``-normal`` (into the work) when ``tilt`` is 0.
        length: the cut's length along its curve (m, > 0).
        radius: the radius of the arc (m); positive turns about ``normal`` counter-clockwise, negative
            clockwise, ``inf`` (the default) a straight cut.
        tilt: the blade's tilt about its edge from ``-normal`` (rad), held along the cut.
        speed: cruise cutting speed (m/s).
        ramp: ramp time of the speed (s).
        dt: sampling period (s).

    Returns:
        A :class:`ToolPath` named ``"cutting"`` with the whole tool frame: ``x`` the edge along the
        cut's tangent, ``z`` the blade's axis.
    """
    p0, t0, n = _point("start", start), _unit("direction", direction), _unit("normal", normal)
    if abs(float(t0 @ n)) > UNIT_TOLERANCE:
        raise PathError(
            f"direction = {shown(t0.tolist())} is not in the plane of normal = {shown(n.tolist())} "
            f"(direction . normal = {float(t0 @ n):.3g}); expected them perpendicular"
        )
    length = checks.positive("length", length, "m", error=PathError)
    straight = isinstance(radius, int | float) and math.isinf(radius) and radius > 0
    if not straight:
        radius = checks.number("radius", radius, unit="m", expected="a non-zero radius (m), or inf", error=PathError)
        if radius == 0:
            raise PathError("radius = 0: expected a non-zero radius (m), or inf for a straight cut")
    tilt = checks.number("tilt", tilt, minimum=-math.pi / 2, maximum=math.pi / 2, unit="rad", error=PathError)
    speed = checks.positive("speed", speed, "m/s", error=PathError)
    ramp = checks.positive("ramp", ramp, "s", error=PathError)
    kappa = 0.0 if straight else 1.0 / float(radius)
    t = _times(_profile(length, speed, ramp)[1], dt)
    m = _move(t, length, speed, ramp)
    side = np.cross(n, t0)
    angle = kappa * m.s
    tangent = _rotate(n, angle, t0)
    across = np.cross(n, tangent)
    position = p0 + (_sinc(angle) * m.s)[:, None] * t0 + (_versine(angle, kappa) * m.s)[:, None] * side
    v, a, j = m.v[:, None], m.a[:, None], m.j[:, None]
    velocity = v * tangent
    acceleration = a * tangent + kappa * v**2 * across
    jerk = j * tangent + 3 * kappa * v * a * across - kappa**2 * v**3 * tangent
    z0 = _rotate(t0, np.array([tilt]), -n)[0]
    frame0 = np.stack([t0, np.cross(z0, t0), z0], axis=1)
    frame = np.stack([_rotate(n, angle, frame0[:, i]) for i in range(3)], axis=2)
    tip = TipPath("cutting", t, position, velocity, acceleration, jerk)
    omega, alpha = np.outer(kappa * m.v, n), np.outer(kappa * m.a, n)
    phases = (("cut", 0.0, float(t[-1])),)
    return ToolPath(tip, frame=frame, angular_velocity=omega, angular_acceleration=alpha, phases=phases)


def _sinc(angle: Array) -> Array:
    """``sin(angle) / angle`` (1 at 0)."""
    return np.asarray(np.sinc(angle / np.pi))


def _versine(angle: Array, kappa: float) -> Array:
    """``(1 - cos(angle)) / angle`` (0 at 0): with ``angle = kappa s``, times ``s`` the offset across."""
    small = np.abs(angle) < 1e-4
    safe = np.where(small, 1.0, angle)
    return np.asarray(np.where(small, angle / 2 - angle**3 / 24, (1 - np.cos(safe)) / safe))


def _knots(times: ArrayLike, count: int, what: str) -> Array:
    knots = checks.finite_array("times", times, (None,), error=PathError).astype(float)
    if knots.shape != (count,) or count < 2:
        raise PathError(f"times has shape {knots.shape}: expected ({count},), one time per {what}, at least 2")
    if not (np.diff(knots) > 0).all():
        raise PathError(f"times = {shown(knots.tolist())}: expected strictly increasing times (s)")
    return knots


def _inside(tip: TipPath, knots: Array) -> None:
    if tip.t[0] < knots[0] - 1e-12 or tip.t[-1] > knots[-1] + 1e-12:
        raise PathError(
            f"the tip path's times {tip.t[0]:.6g} .. {tip.t[-1]:.6g} s leave the given times {knots[0]:.6g} .. "
            f"{knots[-1]:.6g} s: expected the tip path within them"
        )


def with_frames(tip: TipPath, times: ArrayLike, rotations: ArrayLike) -> ToolPath:
    """A tool path of ``tip`` whose tool frame passes through ``rotations`` ``(M, 3, 3)`` at ``times``
    ``(M,)`` (s): SciPy's C2 rotation spline (:class:`scipy.spatial.transform.RotationSpline`, its
    angular rate and acceleration continuous), sampled at the tip's times, with its angular velocity
    and acceleration in F0 (``R w_body``, ``R a_body``: exact)."""
    from scipy.spatial.transform import Rotation, RotationSpline

    matrices = checks.finite_array("rotations", rotations, (None, 3, 3), error=PathError).astype(float)
    knots = _knots(times, matrices.shape[0], "rotation")
    deviation = np.abs(matrices.transpose(0, 2, 1) @ matrices - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((deviation > 1e-9) | (np.linalg.det(matrices) <= 0))
    if bad.size:
        raise PathError(f"rotations[{int(bad[0])}] is not a rotation matrix (|R^T R - I| = {deviation[bad[0]]:.3g})")
    _inside(tip, knots)
    spline = RotationSpline(knots, Rotation.from_matrix(matrices))
    t = np.clip(tip.t, knots[0], knots[-1])
    frame = spline(t).as_matrix()
    omega = np.einsum("nij,nj->ni", frame, spline(t, 1))
    alpha = np.einsum("nij,nj->ni", frame, spline(t, 2))
    return ToolPath(tip, frame=frame, angular_velocity=omega, angular_acceleration=alpha)


def with_axes(tip: TipPath, times: ArrayLike, directions: ArrayLike) -> ToolPath:
    """A tool path of ``tip`` whose tool axis passes through the unit ``directions`` ``(M, 3)`` at
    ``times`` ``(M,)`` (s), the spin free: a C2 cubic spline of the vectors (zero rate at both ends),
    normalised, sampled at the tip's times with its exact rate and acceleration."""
    from scipy.interpolate import CubicSpline

    vectors = checks.finite_array("directions", directions, (None, 3), error=PathError).astype(float)
    knots = _knots(times, vectors.shape[0], "direction")
    vectors = unit_directions(vectors, vectors.shape[0], "directions", error=PathError)
    _inside(tip, knots)
    spline = CubicSpline(knots, vectors, bc_type="clamped")
    t = np.clip(tip.t, knots[0], knots[-1])
    g, gd, gdd = spline(t), spline(t, 1), spline(t, 2)
    if np.linalg.norm(g, axis=1).min() < 1e-6:
        raise PathError(
            "directions: the spline between two of them passes through zero (they turn by nearly half a turn)"
        )
    direction, rate, acceleration = unit_part(g, gd, gdd)
    return ToolPath(tip, axis=AxisPath(direction, rate, acceleration))
