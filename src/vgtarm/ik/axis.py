"""Tool-axis targets: the tool's axis along a direction, the spin about it free (a 5-D task).

A drill needs its axis on a line and does not care how it spins about it: the task is the tip
point (3 equations) and the axis direction (2), leaving two of the paper robot's seven joints to
the cost (eq. 12 or the effort criterion) instead of one for the full pose.

**The equations.** With the tool axis ``u`` in the end-effector frame F3 (``robot.tool_rotation``'s
third column, :mod:`vgtarm.model.stack`), the axis in F0 is ``a(q) = C03(q) u``. The target
direction ``d`` is completed to a frame ``F = [w1 w2 d]`` (a rotation); the two equations are
``w1 . a(q) = 0`` and ``w2 . a(q) = 0``, regular wherever ``a`` is near ``d`` (unlike the x, y rows
of a pose residual with the spin held, which lose rank when the spin turns by half a turn). They
also hold at ``a = -d``: every solution's axis is checked to point along ``d``
(:func:`axis_error` is the true angle).

**Compiled functions.** The rows are linear in ``C03``, so the pose task's compiled functions
(``ik_pose*`` of :mod:`vgtarm.model.codegen.ik`, whose residual ``e = 0.5 vee(M^T C03 - C03^T M)`` is
linear in its input matrix ``M``) evaluate them: with ``M = F K B^T`` (``K`` below, ``B`` the tool
rotation), ``e = B e'`` and the first two rows of ``e'`` are the two equations, so the task rows are
``B[:, :2]^T e`` and the multipliers enter the pose functions as ``B[:, :2] lam``. Their time
derivatives assume ``dM/dt = [w] M``, true for ``M = F K B^T`` when ``w`` is ``F``'s angular velocity:
the exact rates of a moving axis follow from ``F``'s angular velocity and acceleration.

**The frame** ``F`` of a direction path ``d(t)`` (with ``d'``, ``d''``): ``w1`` is the unit part of a
fixed helper axis ``h`` orthogonal to ``d`` (``h`` the base axis least aligned with the path's
directions), ``w2 = d x w1``; its angular velocity and acceleration are
``w = 1/2 sum f_i x f_i'`` and ``a = 1/2 sum f_i x f_i''`` over its columns ``f_i``, in closed form.

**Entry point** (remote centre of motion): the tool's axis passes through a fixed point ``E`` while
the tip follows its path ``P_d(t)``. With the tip on its target, the axis is then
``d = (P_d - E) / |P_d - E|`` (the tool enters at ``E`` and advances to the tip): the entry-point
task is the axis task of that direction, whose derivatives follow from the path's velocity and
acceleration exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..checks import Error
from ..errors import InputError, shown

Array = NDArray[np.float64]

#: Largest ``| |d| - 1 |`` of an axis direction as given.
UNIT_TOLERANCE = 1e-9
#: Smallest distance (m) of a tip target from the entry point: the axis through both is undefined
#: when they meet, and its rates grow as the inverse of the distance.
ENTRY_CLEARANCE = 1e-3
#: The frame ``[d w1 w2]`` of the frame ``[w1 w2 d]`` (a cyclic permutation: a rotation), whose first
#: row of the axis rows is ``d . a``: the row of a cone's boundary.
AXIS_FIRST = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
#: ``K`` of the module docstring: ``F K`` has the columns ``[2 w2, -2 w1, 0]``.
_K = np.array([[0.0, -2.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


@dataclass(frozen=True, eq=False)
class AxisPath:
    """Desired direction of the tool's axis in F0 along a path.

    Attributes:
        direction: ``(3,)`` (held) or ``(N, 3)`` (one per sample) unit vectors.
        rate: ``(N, 3)`` its time derivative (1/s); needed by the exact rates of a changing axis
            (zero for a held one).
        acceleration: ``(N, 3)`` its second derivative (1/s^2), likewise.
    """

    direction: ArrayLike
    rate: ArrayLike | None = None
    acceleration: ArrayLike | None = None


@dataclass(frozen=True, eq=False)
class AxisTarget:
    """Validated per-sample arrays of an axis task.

    Attributes:
        direction, rate, acceleration: ``(N, 3)`` the target axis ``d`` and its derivatives.
        frame: ``(N, 3, 3)`` the rotations ``F = [w1 w2 d]``.
        angular_velocity, angular_acceleration: ``(N, 3)`` of ``F`` in F0.
        entry_point: ``(3,)`` the entry point the axis passes through, or None.
        cone: ``cos`` of a cone's half-angle whose boundary the axis is held on (one row
            ``d . a = cone``), or None for the axis itself.
    """

    direction: Array
    rate: Array
    acceleration: Array
    frame: Array
    angular_velocity: Array
    angular_acceleration: Array
    entry_point: Array | None = None
    cone: float | None = None

    def subset(self, n: int) -> AxisTarget:
        """The target of the first ``n`` samples."""
        return AxisTarget(
            self.direction[:n],
            self.rate[:n],
            self.acceleration[:n],
            self.frame[:n],
            self.angular_velocity[:n],
            self.angular_acceleration[:n],
            self.entry_point,
            self.cone,
        )


def _vectors(value: object, n: int, name: str, error: Error = InputError) -> Array:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise error(f"{name} = {shown(value)}: expected a vector [x, y, z] or one per sample ({n}, 3)") from None
    if array.shape not in ((3,), (n, 3)):
        raise error(f"{name} has shape {array.shape}: expected (3,) or ({n}, 3) for a path of {n} samples")
    if not np.isfinite(array).all():
        raise error(f"{name} = {shown(array.tolist())}: expected finite numbers")
    return np.broadcast_to(array, (n, 3)).copy()


def unit_directions(value: object, n: int, name: str = "axis", *, error: Error = InputError) -> Array:
    """``value`` as ``(n, 3)`` unit vectors, refused in one ``error`` line when a row's length is not 1
    within :data:`UNIT_TOLERANCE` (the message gives the normalised vector to use instead)."""
    d = _vectors(value, n, name, error)
    norm = np.linalg.norm(d, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > UNIT_TOLERANCE)
    if bad.size:
        i = int(bad[0])
        where = name if np.ndim(np.asarray(value)) == 1 else f"{name}[{i}]"
        if norm[i] == 0.0:
            raise error(f"{where} = {shown(d[i].tolist())}: expected a unit vector, got the zero vector")
        fixed = ", ".join(f"{v:.12g}" for v in d[i] / norm[i])
        raise error(
            f"{where} = {shown(d[i].tolist())}: expected a unit vector (length 1 within {UNIT_TOLERANCE:g}), its "
            f"length is {norm[i]:.9g}; normalised: [{fixed}]"
        )
    return d


def _helper(direction: Array) -> Array:
    """The base axis least aligned with any of the ``(N, 3)`` directions (the frame's helper ``h``)."""
    worst = np.abs(direction).max(axis=0)
    return np.eye(3)[int(np.argmin(worst))]


def unit_part(g: Array, gd: Array, gdd: Array) -> tuple[Array, Array, Array]:
    """``n = g / |g|`` and its first two time derivatives, row by row, from those of ``g``."""
    r = np.linalg.norm(g, axis=1, keepdims=True)
    n = g / r
    rd = (n * gd).sum(axis=1, keepdims=True)
    nd = (gd - rd * n) / r
    rdd = (nd * gd).sum(axis=1, keepdims=True) + (n * gdd).sum(axis=1, keepdims=True)
    ndd = (gdd - rdd * n - 2.0 * rd * nd) / r
    return n, nd, ndd


def frames(direction: Array, rate: Array, acceleration: Array) -> tuple[Array, Array, Array]:
    """The frames ``F = [w1 w2 d]`` ``(N, 3, 3)`` of unit directions ``d`` ``(N, 3)`` with derivatives
    ``d'``, ``d''``, and their angular velocity and acceleration ``(N, 3)`` (see the module docstring)."""
    h = _helper(direction)
    along = direction @ h
    rate_along = rate @ h
    g = h - along[:, None] * direction
    gd = -rate_along[:, None] * direction - along[:, None] * rate
    gdd = -(acceleration @ h)[:, None] * direction - 2.0 * rate_along[:, None] * rate - along[:, None] * acceleration
    w1, w1d, w1dd = unit_part(g, gd, gdd)
    w2 = np.cross(direction, w1)
    w2d = np.cross(rate, w1) + np.cross(direction, w1d)
    w2dd = np.cross(acceleration, w1) + 2.0 * np.cross(rate, w1d) + np.cross(direction, w1dd)
    columns = ((w1, w1d, w1dd), (w2, w2d, w2dd), (direction, rate, acceleration))
    omega = 0.5 * sum(np.cross(f, fd) for f, fd, _ in columns)
    alpha = 0.5 * sum(np.cross(f, fdd) for f, _, fdd in columns)
    return np.stack([w1, w2, direction], axis=2), np.asarray(omega), np.asarray(alpha)


def axis_target(axis: object, n: int, exact_rates: bool) -> AxisTarget:
    """Validate an ``axis`` argument (a direction ``(3,)``, one per sample ``(N, 3)`` or an
    :class:`AxisPath`) for a path of ``n`` samples."""
    spec = axis if isinstance(axis, AxisPath) else AxisPath(axis)  # type: ignore[arg-type]
    direction = unit_directions(spec.direction, n)
    constant = np.ndim(np.asarray(spec.direction, dtype=object)) == 1
    if spec.rate is None or spec.acceleration is None:
        if exact_rates and not constant:
            raise InputError(
                "exact rates of a changing axis need its rate and acceleration: pass vgtarm.ik.AxisPath(direction, "
                "rate, acceleration), or use rates='finite_difference'"
            )
    rate = np.zeros((n, 3)) if spec.rate is None else _vectors(spec.rate, n, "axis rate")
    acceleration = (
        np.zeros((n, 3)) if spec.acceleration is None else _vectors(spec.acceleration, n, "axis acceleration")
    )
    return AxisTarget(direction, rate, acceleration, *frames(direction, rate, acceleration))


def entry_point_target(
    point: object, position: Array, velocity: Array, acceleration: Array, name: str = "entry_point"
) -> AxisTarget:
    """The axis task of a tool whose axis passes through ``point`` while its tip follows ``position``
    ``(N, 3)`` (with its velocity and acceleration): ``d = (P_d - E) / |P_d - E|``; refusals name the
    argument ``name``."""
    n = position.shape[0]
    try:
        entry = np.array(point, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} = {shown(point)}: expected a point [x, y, z] (m)") from None
    if entry.shape != (3,) or not np.isfinite(entry).all():
        raise InputError(f"{name} = {shown(point)}: expected a point [x, y, z] of finite numbers (m)")
    offset = position - entry
    distance = np.linalg.norm(offset, axis=1)
    close = int(np.argmin(distance)) if n else 0
    if n and distance[close] < ENTRY_CLEARANCE:
        raise InputError(
            f"{name} = {shown(entry.tolist())}: the tip's path passes {distance[close]:.3g} m from it (sample "
            f"{close}); expected at least {ENTRY_CLEARANCE:g} m (the tool's axis through the entry point and the "
            "tip is undefined where they meet)"
        )
    direction, rate, accel = unit_part(offset, velocity, acceleration)
    return AxisTarget(direction, rate, accel, *frames(direction, rate, accel), entry_point=entry)


def cone_angle(value: object, name: str = "cone") -> float:
    """A cone's half-angle (rad) in ``(0, pi/2)``, refused in one line otherwise."""
    try:
        angle = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        angle = float("nan")
    if not 0.0 < angle < 0.5 * np.pi:
        raise InputError(
            f"{name} = {shown(value)}: expected a half-angle in (0, 90) degrees, given in rad (0 to {0.5 * np.pi:.6g})"
        )
    return angle


def tool_task_keywords(
    axis: object = None,
    cone: object = None,
    entry_point: object = None,
    *,
    names: tuple[str, str, str] = ("axis", "cone", "entry_point"),
) -> dict[str, Any]:
    """The inverse kinematics' keywords of a tool-axis task as a user writes it: ``axis`` a unit
    vector (``"x,y,z"`` or three numbers), ``cone`` its half-angle in degrees (with ``axis`` only),
    ``entry_point`` a point (``"x,y,z"`` or three numbers, m), not both ``axis`` and ``entry_point``;
    ``{}`` when none is given. ``cone`` is returned in rad, as :func:`vgtarm.inverse_kinematics`
    takes it. A refusal is one line naming ``names`` (the record's fields, or the command's flags)."""
    axis_name, cone_name, entry_name = names
    out: dict[str, Any] = {}
    if axis is not None:
        values = _written(axis_name, axis, "the direction of the tool's axis x,y,z, a unit vector")
        out["axis"] = unit_directions(values, 1, axis_name)[0]
    if entry_point is not None:
        out["entry_point"] = _written(entry_name, entry_point, "the entry point x,y,z in m")
    if cone is not None:
        if axis is None:
            raise InputError(f"{cone_name} {shown(cone)}: a cone needs its axis, {axis_name} X,Y,Z")
        degrees = checks.comma_numbers(cone_name, str(cone), 1, "the cone's half-angle in degrees, in (0, 90)")[0]
        if not 0.0 < degrees < 90.0:
            raise InputError(f"{cone_name} {shown(cone)}: expected a half-angle in (0, 90) degrees")
        out["cone"] = float(np.radians(degrees))
    if axis is not None and entry_point is not None:
        raise InputError(f"{axis_name} and {entry_name}: expected one of them (the entry point sets the axis)")
    return out


def _written(name: str, value: object, meaning: str) -> Array:
    """Three numbers written ``"x,y,z"`` or given as a sequence, refused in one line naming ``name``."""
    if isinstance(value, str):
        return checks.comma_numbers(name, value, 3, meaning)
    return checks.finite_array(name, value, (3,)).astype(float)


def compiled_target(frame: Array, tool: Array) -> Array:
    """The input matrices ``M = F K B^T`` ``(N, 9)``, row-major, of the pose functions for frames ``F``
    ``(N, 3, 3)`` and the tool rotation ``B`` ``(3, 3)``."""
    return np.asarray((frame @ (_K @ tool.T)).reshape(-1, 9))


def task_rows(tool: Array) -> Array:
    """``D = B[:, :2]^T`` ``(2, 3)``: the axis task's rows of the pose residual ``e``."""
    return np.ascontiguousarray(tool[:, :2].T)


def tool_axes(rotation: Array, tool: Array) -> Array:
    """The tool axes ``a = C03 u`` ``(N, 3)`` of end-effector rotations ``(N, 3, 3)``."""
    return np.asarray(rotation @ tool[:, 2])


def axis_error(axes: Array, direction: Array) -> Array:
    """Angle ``(N,)`` (rad) between tool axes and target directions ``(N, 3)``, accurate near zero and pi."""
    return np.asarray(np.arctan2(np.linalg.norm(np.cross(axes, direction), axis=1), (axes * direction).sum(axis=1)))


def entry_distance(tip: Array, axes: Array, entry: Array) -> Array:
    """Distance ``(N,)`` (m) of the entry point from the lines through the tips ``(N, 3)`` along the
    unit axes ``(N, 3)``."""
    return np.asarray(np.linalg.norm(np.cross(entry - tip, axes), axis=1))
