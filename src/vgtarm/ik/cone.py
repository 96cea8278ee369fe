"""The tool's axis within a cone about a direction: an inequality, the spin free.

``d . a(q) >= cos(beta)`` with the tool axis ``a(q)``, the cone's axis ``d`` and half-angle ``beta``.
The active set of this one nonlinear inequality is found sample by sample:

1. The tip alone (the position task) is solved along the whole path. Where its optimum's axis is
   inside the cone it is the cone problem's optimum too (a feasible optimum of a larger feasible
   set), with the inequality's multiplier zero.
2. Each run of consecutive samples whose axis leaves the cone is solved again with the inequality
   active: the axis task's machinery with one row, ``d . a(q) = cos(beta)`` (:mod:`vgtarm.ik.axis`),
   started from the first step's joints. Its multiplier ``lam`` of that row must be ``<= 0`` (the
   inequality's ``nu = -lam >= 0``).
3. Where it is not, the boundary pulls the axis out of the cone: the inequality is released, and the
   tip alone is solved again from the boundary's joints. The position task has other optima than
   the one step 1 followed (one with its axis 28 degrees off the cone's, another inside it, on a
   seeded target of the tests); an optimum reached so whose axis is inside the cone is the cone
   problem's. A sample where neither holds fails its check.

The rates are exact for each sample's active set (the position task's, or the boundary's), as for
the joint limits; where the inequality becomes active along the path the true rates jump.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..paths import TipPath
from .axis import AxisPath, AxisTarget, axis_error, axis_target
from .records import IKResult, IKSamples

Array = NDArray[np.float64]
#: Largest positive multiplier of the boundary's row still read as ``nu >= 0`` (a rounding of zero).
SIGN_TOLERANCE = 1e-9

#: ``solve(path, axis_keywords, initial_guess)``: the inverse kinematics of the caller's settings.
Solve = Callable[[TipPath, dict[str, Any], Array | None], IKResult]


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """``[start, end)`` of each run of True in ``mask``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _piece(path: TipPath, target: AxisTarget, a: int, b: int) -> tuple[TipPath, AxisPath]:
    """Samples ``[a, b)`` of the path and of the cone's axis (at least two: a lone sample takes a neighbour)."""
    if b - a < 2:
        a, b = (a, a + 2) if a + 2 <= len(path) else (b - 2, b)
    cut = slice(a, b)
    jerk = None if path.jerk is None else path.jerk[cut]
    piece = TipPath(path.name, path.t[cut], path.position[cut], path.velocity[cut], path.acceleration[cut], jerk)
    return piece, AxisPath(target.direction[cut], target.rate[cut], target.acceleration[cut])


class _Merged:
    """The cone's reference, assembled from the solves of its pieces: ``q``, ``qd``, ``qdd`` ``(N, n)``,
    the record's arrays by name (``multipliers`` with the cone's row) and the work counters."""

    def __init__(self, q: Array, qd: Array, qdd: Array, fields: dict[str, Any], work: dict[str, float]) -> None:
        self.q, self.qd, self.qdd, self.fields, self.work = q, qd, qdd, fields, work

    def take(self, result: IKResult, a: int, b: int, start: int, only: NDArray[np.intp] | None = None) -> None:
        """Rows ``[a, b)`` (or the rows ``only`` among them) from ``result``, a solve of the samples
        from ``start`` on; a position task's multipliers get the cone's row, zero."""
        rows = np.arange(a, b) if only is None else only
        source = rows - start
        for array, values in ((self.q, result.q), (self.qd, result.qd), (self.qdd, result.qdd)):
            array[rows] = values[source]
        for key, value in vars(result.samples).items():
            if not isinstance(value, np.ndarray) or key not in self.fields or key == "orientation_error":
                continue
            if key == "multipliers" and value.shape[1] < self.fields[key].shape[1]:
                value = np.concatenate([value, np.zeros((value.shape[0], 1))], axis=1)
            self.fields[key][rows] = value[source]
        self.work = {key: self.work.get(key, 0) + value for key, value in result.work.items()}


def within_cone(robot: Any, path: TipPath, axis: object, half_angle: float, exact: bool, solve: Solve) -> IKResult:
    """The joint reference of ``path`` with the tool's axis within ``half_angle`` (rad) of ``axis``
    (see the module docstring); ``solve`` runs the caller's inverse kinematics."""
    started = time.perf_counter()
    target = axis_target(axis, len(path), exact)
    bound = float(np.cos(half_angle))
    free = solve(path, {}, None)
    along = (robot.tool_axis(np.nan_to_num(free.q)) * target.direction).sum(axis=1)
    outside = np.isfinite(free.q).all(axis=1) & (along < bound)
    q, qd, qdd = free.q.copy(), free.qd.copy(), free.qdd.copy()
    fields: dict[str, Any] = {
        key: (value.copy() if isinstance(value, np.ndarray) else value) for key, value in vars(free.samples).items()
    }
    fields["multipliers"] = np.concatenate([free.samples.multipliers, np.zeros((len(path), 1))], axis=1)
    work = dict(free.work)
    merged = _Merged(q, qd, qdd, fields, work)
    for a, b in _runs(outside):
        piece, cone_axis = _piece(path, target, a, b)
        start = int(np.searchsorted(path.t, piece.t[0]))
        held = solve(piece, {"axis": cone_axis, "boundary": bound}, free.q[start])
        merged.take(held, a, b, start)
        pulled = held.samples.multipliers[a - start : b - start, 3] > SIGN_TOLERANCE
        fields["success"][a:b] &= ~pulled
        for c, e in _runs(pulled):
            piece, _ = _piece(path, target, a + c, a + e)
            first = int(np.searchsorted(path.t, piece.t[0]))
            released = solve(piece, {}, held.q[first - start])
            rows = slice(a + c - first, a + e - first)
            inside = (robot.tool_axis(released.q[rows]) * target.direction[a + c : a + e]).sum(axis=1) >= bound
            kept = np.flatnonzero(inside & released.samples.success[rows]) + a + c
            merged.take(released, a + c, a + e, first, kept)
    work = merged.work
    fields["orientation_error"] = axis_error(robot.tool_axis(np.nan_to_num(q)), target.direction)
    samples = IKSamples(**fields)
    for value in vars(samples).values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    for array in (q, qd, qdd):
        array.flags.writeable = False
    failed = np.flatnonzero(~samples.success)
    on_boundary = int(np.count_nonzero(samples.orientation_error >= half_angle - 1e-9))
    degrees = f"{np.degrees(half_angle):.6g} degrees"
    message = (
        f"all {len(path)} samples solved and verified ({on_boundary} on the cone's boundary)"
        if free.success and not failed.size
        else free.message
        if not free.success
        else f"{failed.size} of {len(path)} samples failed the optimality check within the cone (first: sample "
        f"{int(failed[0])} at t = {path.t[int(failed[0])]:.6g} s)"
    )
    return replace(
        free,
        q=q,
        qd=qd,
        qdd=qdd,
        samples=samples,
        task="axis cone",
        task_space=f"tip (u1, u2, u3) and tool axis within {degrees} of a direction",
        axis=target.direction,
        success=bool(free.success and not failed.size),
        status="completed" if free.success and not failed.size else free.status if not free.success else "unverified",
        message=message,
        work=work,
        wall_time_s=time.perf_counter() - started,
    )
