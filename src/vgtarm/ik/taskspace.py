"""The task space a robot's tip can reach: all of space, a plane or a line (from its tip Jacobian).

The paper's robot moves its tip in three directions (its tip Jacobian has rank 3 everywhere off
singular poses), and the inverse kinematics constrains the three coordinates of the tip. A single
planar VGT module moves its tip in its operating plane only: the tip Jacobian has rank 2 and its
third row, in the plane's normal, is zero; constraining all three coordinates would give a
dependent equality row (no multiplier is unique, the KKT matrix is singular). Such a robot tracks
the path in the space it can reach instead: the task is the tip's coordinates along the
directions its Jacobian spans (``E (P(q) - P_d)`` with ``E`` ``(r, 3)`` orthonormal rows), and
the ``n - r`` remaining freedoms are spent on eq. 12 as for the paper's robot.

**Rule** (:func:`task_space`): the Jacobians ``J(q)`` ``(3, n)`` at the start pose, at home and
at 16 seeded assemblable poses inside the joint ranges are put side by side; their left singular
vectors with singular values above ``RANK_TOLERANCE`` times the largest give the rank ``r`` and
the directions. ``r = 3``: the full task (``None``; the caller never gets here for a rank-3
Jacobian at the start, so the paper's code path is untouched). ``r < 3``: the directions are made
canonical (the base axes projected on the subspace, largest first, orthonormalised; entries below
``SNAP`` set to zero), so a module in the ``u2-u3`` plane gets exactly ``(u2, u3)``; the tip points
of every sampled pose must lie on the plane (line) through the start tip, else the robot's tip
moves on a curved surface and is refused in one line. A start pose whose Jacobian has a lower rank
than the sampled ones is singular and refused too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, shown
from ..model.robot import Robot

Array = NDArray[np.float64]

#: Singular values below this fraction of the largest count as zero (rank of the stacked Jacobians).
RANK_TOLERANCE = 1e-9
#: Direction entries below this are set to zero (the plane of a module at 0 or 90 degrees is exact).
SNAP = 1e-12
#: Distance (m) a sampled tip may lie off the plane (line) through the start tip.
FLAT_TOLERANCE = 1e-9
#: Seeded poses sampled for the rank and the flatness, and their seed.
N_POSES, SEED = 16, 0
AXES = ("u1", "u2", "u3")


@dataclass(frozen=True, eq=False)
class TaskSpace:
    """The plane (``rank`` 2) or line (``rank`` 1) the tip moves in.

    Attributes:
        directions: ``(r, 3)`` orthonormal rows: the tip coordinates the task constrains.
        origin: ``(3,)`` a point of the plane or line (the tip at the start pose), m.
        label: what the task is, e.g. ``"tip (u2, u3) in its plane"``.
    """

    directions: Array
    origin: Array
    label: str

    @property
    def rank(self) -> int:
        """``r``: 2 for a plane, 1 for a line."""
        return int(self.directions.shape[0])

    def distance(self, points: Array) -> Array:
        """Distance ``(N,)`` of ``points`` ``(N, 3)`` from the plane or line (m)."""
        offset = np.asarray(points, dtype=float) - self.origin
        inside = (offset @ self.directions.T) @ self.directions
        return np.asarray(np.linalg.norm(offset - inside, axis=-1))

    def normal(self) -> Array:
        """The unit normal ``(3,)`` of a plane (rank 2), right-handed with its two directions."""
        if self.rank != 2:
            raise InputError(f"a normal needs a plane; this task space has rank {self.rank}")
        return np.asarray(np.cross(self.directions[0], self.directions[1]))


def _poses(robot: Robot, q_start: Array) -> Array:
    """The start pose, home and up to :data:`N_POSES` seeded assemblable poses inside the joint ranges."""
    p = robot.parameters
    rng = np.random.default_rng(SEED)
    inner = p.lower + (p.upper - p.lower) * rng.uniform(0.25, 0.75, size=(4 * N_POSES, p.lower.shape[0]))
    kept = inner[robot.is_assemblable(inner, 1e-3)][:N_POSES]
    return np.concatenate([q_start[None], p.home[None], kept])


def _label(directions: Array, what: str) -> str:
    names = []
    for d in directions:
        axis = np.flatnonzero(d)
        if axis.size == 1:
            names.append(AXES[int(axis[0])])
        else:
            names.append("(" + ", ".join(f"{v:.4g}" for v in d) + ")")
    if all(name in AXES for name in names):
        return f"tip ({', '.join(names)}) in its {what}" if len(names) > 1 else f"tip {names[0]} along its {what}"
    return f"tip along {' and '.join(names)} in its {what}"


def canonical(basis: Array) -> Array:
    """Orthonormal rows spanning the subspace of ``basis`` ``(r, 3)`` (orthonormal rows), built from
    the base axes projected on it, the longest projection first (ties: the lower axis), each row's
    entries below :data:`SNAP` set to zero and its largest entry positive; rows in axis order."""
    projector = basis.T @ basis
    order = sorted(range(3), key=lambda j: (-round(float(np.linalg.norm(projector[:, j])), 12), j))
    rows: list[Array] = []
    for j in order:
        v = projector[:, j].copy()
        for row in rows:
            v -= (v @ row) * row
        norm = float(np.linalg.norm(v))
        if norm <= 1e-6:
            continue
        v /= norm
        v[np.abs(v) < SNAP] = 0.0
        v /= np.linalg.norm(v)
        v *= np.sign(v[int(np.argmax(np.abs(v)))])
        rows.append(v)
        if len(rows) == basis.shape[0]:
            break
    rows.sort(key=lambda v: int(np.argmax(np.abs(v))))
    return np.asarray(rows)


def task_space(robot: Robot, q_start: Array) -> TaskSpace | None:
    """The plane or line the tip of ``robot`` moves in, or ``None`` when it moves in all of space.

    Raises:
        InputError: the start pose is singular (its tip Jacobian has a lower rank than elsewhere),
            the tip cannot move at all, or it moves on a curved surface (not a plane or a line).
    """
    name = shown(robot.parameters.name)
    poses = _poses(robot, np.asarray(q_start, dtype=float))
    jacobians = robot.tip_jacobian(poses)  # (K, 3, n)
    side_by_side = np.concatenate(list(jacobians), axis=1)  # (3, K n)
    u, s, _ = np.linalg.svd(side_by_side)
    rank = int(np.count_nonzero(s > RANK_TOLERANCE * s[0])) if s[0] > 0 else 0
    at_start = int(np.linalg.matrix_rank(jacobians[0], tol=RANK_TOLERANCE * max(s[0], 1e-300)))
    if rank == 3:
        if at_start < 3:
            raise InputError(
                f"robot {name}: the start pose {shown(np.round(poses[0], 9).tolist())} is singular (its tip Jacobian "
                f"has rank {at_start}, elsewhere 3); start from another pose (initial_guess)"
            )
        return None
    if rank == 0:
        raise InputError(f"robot {name}: its tip does not move (the tip Jacobian is zero); it has no task space")
    if at_start < rank:
        raise InputError(
            f"robot {name}: the start pose is singular (its tip Jacobian has rank {at_start}, elsewhere {rank}); "
            "start from another pose (initial_guess)"
        )
    what = "plane" if rank == 2 else "line"
    directions = canonical(u[:, :rank].T)
    tips = robot.tip_position(poses)
    space = TaskSpace(directions, tips[0].copy(), _label(directions, what))
    off = space.distance(tips)
    worst = int(np.argmax(off))
    if off[worst] > FLAT_TOLERANCE:
        raise InputError(
            f"robot {name}: its tip Jacobian has rank {rank} but its tip does not stay in one {what} (a sampled pose "
            f"puts it {off[worst]:.3g} m off the {what} through the start tip); inverse kinematics of a tip moving "
            "on a curved surface is not supported"
        )
    return space
