"""The reachable and dexterous workspace of the tool tip of any VGT robot: membership, volume, slices.

The **reachable workspace** is the set of tip points ``P(q)`` for ``q`` inside the joint limits and
assemblable; the **dexterous workspace** the subset reachable with the tool's axis
(:meth:`~vgtarm.model.robot.Robot.tool_axis`) inside a cone of half-angle ``cone`` (deg) about a
direction ``axis`` (default the base ``+z``, the axis at home). docs/workspace.md gives the methods
and the numbers measured on the shipped robots.

Three ideas carry everything:

- **A box chart of the feasible joints.** Per module the assemblable leg sets inside the limits are
  a polytope whose six triangle inequalities bound ``s`` and ``v`` by intervals that depend on ``p``
  alone. Writing ``p`` as a fraction of its feasible range and ``s``, ``v`` as fractions of their
  ``p``-dependent intervals (twists as fractions of their limits) maps the unit box ``[0, 1]^n``
  onto the feasible set (:class:`JointChart`): every point of the box assembles, and projecting on
  the feasible set becomes a clip.
- **Membership by bounded least squares.** ``x`` belongs to the workspace when
  ``min ||P(q(u)) - x||`` over the box is zero (with the cone, a hinge residual on the tool axis is
  added): a projected Levenberg-Marquardt iteration vectorised over many points
  (:class:`ReachTest`), started from the nearest tips of a seeded cloud of joint samples (a k-d
  tree), a few starts each. A point is inside when the residual falls below ``tol`` (m).
- **Volume by grown voxels.** Voxels hit by the tips of a dense joint sample are inside; voxels on
  the border of the hit set, and every neighbour of a voxel found partly inside, are measured by
  the membership of one point drawn in each of their ``refine^3`` sub-cells (stratified
  sampling), until no border is left unmeasured
  (:func:`workspace_volume`). :func:`monte_carlo_volume` is the independent estimate of the same
  set that checks it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from .. import checks
from ..errors import InputError, shown

Array = NDArray[np.float64]

#: Default half-angle of the dexterous workspace's cone (deg): the tool axis of the paper's robot is
#: within 19 deg of +z for half of the joint box (ASSUMPTION of this module; the issue is silent).
DEFAULT_CONE = 20.0
#: The assembly margin the chart keeps from every triangle inequality (m): the model is singular on
#: the margin itself (a flat triangle); 1e-8 m changes no volume measurably.
CHART_MARGIN = 1e-8
#: The chart keeps each truss triangle's angle this far from flat (rad): a fold is singular in the
#: model (a triangle inequality with zero margin); 3e-5 rad moves the tip some 10 um.
CHART_ANGLE = 3e-5
#: A point is in the workspace when its least-squares residual falls below this (m).
DEFAULT_TOL = 1e-7
#: A point whose first start leaves it farther than this fraction of the workspace's size (the
#: diagonal of the sample tips' box) is taken as outside without the other starts: on 20,000 points
#: of the paper robot's box this changed 1 answer and halved the time (docs/workspace.md).
FAR = 0.03
#: Below this many point-start pairs :meth:`ReachTest.solve` runs the remaining starts together.
SMALL_BATCH = 8192
#: Fewest Monte Carlo samples accepted (a smaller run says nothing at 1 %).
MIN_SAMPLES = 1000
#: Largest number of points, voxels or samples one call accepts (memory: a few hundred bytes each).
MAX_POINTS = 50_000_000


class NoVolumeError(InputError):
    """The robot's tool tip moves on a surface or a curve (a planar arm): its workspace has no volume."""


def check_volume(test: ReachTest) -> None:
    """Refuse a robot whose tip Jacobian has rank below 3 at every sampled configuration."""
    q = test.chart.joints(test.cloud_u[:2000])[0]
    sigma = np.linalg.svd(test.robot.tip_jacobian(q), compute_uv=False)
    if not np.any(sigma[:, -1] > 1e-9 * np.maximum(sigma[:, 0], 1e-300)):
        raise NoVolumeError(
            f"robot {shown(test.robot.parameters.name)}: its tool tip moves on a surface or a curve (the tip "
            "Jacobian has rank < 3 at every sampled configuration): the workspace has no volume"
        )


def check_cone(cone: object, axis: object) -> tuple[float, Array]:
    """The cone's half-angle (deg, in (0, 180]) and its unit direction, refused in one line if bad."""
    angle = checks.number("cone", cone, above=0.0, maximum=180.0, unit="deg")
    given = axis.tolist() if isinstance(axis, np.ndarray) else axis
    direction = np.asarray(checks.vector("axis", given, 3), dtype=float)
    norm = float(np.linalg.norm(direction))
    if not norm > 1e-12:
        checks.refuse("axis", axis, "a nonzero direction (3 numbers, not all zero)")
    return angle, direction / norm


class JointChart:
    """The unit box ``[0, 1]^n`` mapped onto the joints inside their limits that assemble.

    Module ``k`` with legs ``(s, v, p)`` and half-widths ``b``, ``d``: ``p = pl + u_p (ph - pl)``
    over the range of ``p`` where the module assembles inside its limits; then each of ``s`` and
    ``v`` through the angle ``eps`` its triangle, ``(s, p, 2d)`` or ``(v, p, 2b)``, opens opposite
    it: ``s^2 = (p - 2d)^2 + 8 p d sin^2(eps / 2)`` with ``eps = eps_lo + u_s (eps_hi - eps_lo)``,
    ``[eps_lo, eps_hi]`` the angles of the leg's limits clipped to ``[eta, pi - eta]`` (the
    triangle inequalities are ``0 < eps < pi``; ``eta`` = :data:`CHART_ANGLE`). A twist is
    ``lo + u (hi - lo)``. The angle makes the folds of the truss (a flat triangle, where a leg's
    length has a square-root singularity in the tip) regular points of the chart, so that the
    least squares of :class:`ReachTest` converge there too. The map is onto the feasible set but
    for an ``eta``-thin layer at the folds, piecewise smooth, and its Jacobian is sparse.
    """

    def __init__(self, robot: Any, eta: float = CHART_ANGLE) -> None:
        self.n = robot.n_joints
        lower, upper = robot.joint_limits()
        legs = np.array(robot.parameters.margin_legs(), dtype=int).reshape(-1, 3)
        self.s, self.v, self.p = legs[:, 0], legs[:, 1], legs[:, 2]
        self.lower, self.upper = lower, upper
        two_d = 2.0 * np.asarray(robot.parameters.d, dtype=float)
        two_b = 2.0 * np.asarray(robot.parameters.b, dtype=float)
        self.eta, self.two_d, self.two_b = eta, two_d, two_b
        e = CHART_MARGIN
        pl = np.max(
            [lower[self.p], lower[self.s] - two_d + e, two_d + e - upper[self.s]]
            + [lower[self.v] - two_b + e, two_b + e - upper[self.v], np.full(len(two_d), e)],
            axis=0,
        )
        ph = np.min([upper[self.p], upper[self.s] + two_d - e, upper[self.v] + two_b - e], axis=0)
        if np.any(pl >= ph):
            k = int(np.argmax(pl >= ph))
            raise InputError(
                f"robot {shown(robot.parameters.name)}: module {k + 1} cannot be assembled anywhere inside its "
                "joint limits (no leg set meets both triangle inequalities): no workspace"
            )
        self.pl, self.ph = pl, ph

    def _angle(self, p: Array, leg: Array, w: Array) -> tuple[Array, Array]:
        """The angle opposite a leg of length ``leg`` in the triangle ``(leg, p, w)`` clipped to
        ``[eta, pi - eta]``, and its derivative with respect to ``p`` (0 where clipped)."""
        c = (p * p + w * w - leg * leg) / (2.0 * p * w)
        eps = np.arccos(np.clip(c, -1.0, 1.0))
        inside = (eps > self.eta) & (eps < np.pi - self.eta)
        dc = (p * p - w * w + leg * leg) / (2.0 * p * p * w)
        slope = np.where(inside, -dc / np.sqrt(np.maximum(1.0 - c * c, 1e-300)), 0.0)
        return np.clip(eps, self.eta, np.pi - self.eta), slope

    def _leg(self, p: Array, u: Array, lo: Array, hi: Array, w: Array) -> tuple[Array, Array, Array]:
        """One leg at chart coordinate ``u`` given ``p``: its length, d(length)/dp at fixed ``u`` and
        d(length)/du."""
        lo_eps, lo_slope = self._angle(p, np.broadcast_to(lo, p.shape), w)
        hi_eps, hi_slope = self._angle(p, np.broadcast_to(hi, p.shape), w)
        span = np.maximum(hi_eps - lo_eps, 0.0)
        eps = lo_eps + u * span
        half = np.sin(0.5 * eps)
        length = np.sqrt((p - w) ** 2 + 4.0 * p * w * half * half)
        d_eps = p * w * np.sin(eps) / length
        d_p = (p - w * np.cos(eps)) / length + d_eps * np.where(span > 0, lo_slope + u * (hi_slope - lo_slope), 0.0)
        return length, d_p, d_eps * span

    def joints(self, u: Array) -> tuple[Array, Array]:
        """``q(u)`` ``(N, n)`` and the chart's Jacobian as the factors of :meth:`pull_back` ``(N, 5m)``."""
        u = np.clip(u, 0.0, 1.0)
        q = self.lower + u * (self.upper - self.lower)
        width = self.ph - self.pl
        p = self.pl + u[:, self.p] * width
        s, ds_dp, ds_du = self._leg(p, u[:, self.s], self.lower[self.s], self.upper[self.s], self.two_d)
        v, dv_dp, dv_du = self._leg(p, u[:, self.v], self.lower[self.v], self.upper[self.v], self.two_b)
        # the clip keeps a leg's limits exact against rounding in the square root
        q[:, self.p] = p
        q[:, self.s] = np.clip(s, self.lower[self.s], self.upper[self.s])
        q[:, self.v] = np.clip(v, self.lower[self.v], self.upper[self.v])
        factors = np.concatenate([width * np.ones_like(p), ds_du, dv_du, ds_dp * width, dv_dp * width], axis=1)
        return q, factors

    def pull_back(self, jq: Array, factors: Array) -> Array:
        """``jq @ dq/du`` for Jacobians ``jq`` ``(N, m, n)`` with respect to ``q``."""
        m = len(self.p)
        width, s_du, v_du, s_up, v_up = (factors[:, k * m : (k + 1) * m] for k in range(5))
        ju = jq * (self.upper - self.lower)[None, None, :]
        ju[:, :, self.p] = (
            jq[:, :, self.p] * width[:, None] + jq[:, :, self.s] * s_up[:, None] + jq[:, :, self.v] * v_up[:, None]
        )
        ju[:, :, self.s] = jq[:, :, self.s] * s_du[:, None]
        ju[:, :, self.v] = jq[:, :, self.v] * v_du[:, None]
        return ju

    def box(self, q: ArrayLike) -> Array:
        """The chart coordinates ``u`` ``(N, n)`` of feasible joints ``q`` ``(N, n)`` (clipped into the box)."""
        qa = np.atleast_2d(np.asarray(q, dtype=float))
        span = np.where(self.upper > self.lower, self.upper - self.lower, 1.0)
        u = (qa - self.lower) / span
        p = np.clip(qa[:, self.p], self.pl, self.ph)
        u[:, self.p] = (p - self.pl) / (self.ph - self.pl)
        for legs, w in ((self.s, self.two_d), (self.v, self.two_b)):
            lo_eps, _ = self._angle(p, np.broadcast_to(self.lower[legs], p.shape), w)
            hi_eps, _ = self._angle(p, np.broadcast_to(self.upper[legs], p.shape), w)
            eps, _ = self._angle(p, qa[:, legs], w)
            u[:, legs] = (eps - lo_eps) / np.where(hi_eps > lo_eps, hi_eps - lo_eps, 1.0)
        return np.clip(u, 0.0, 1.0)

    def sample(self, count: int, rng: np.random.Generator, faces: float = 0.0) -> tuple[Array, Array]:
        """``count`` chart points drawn uniformly in the box and their joints ``(count, n)`` each; with
        ``faces`` > 0 each coordinate is then put on the box's face 0 or 1 with that probability (the
        faces map onto the joint limits and the flat triangles, where the workspace's boundary lies)."""
        u = rng.random((count, self.n))
        if faces > 0:
            snap = rng.random((count, self.n)) < faces
            u[snap] = np.round(rng.random(int(snap.sum())))
        return u, self.joints(u)[0]


@dataclass(frozen=True)
class Solve:
    """Result of :meth:`ReachTest.solve` for ``N`` target points.

    Attributes:
        residual: ``(N,)`` the least residual found (m; with a cone, the hinge term included).
        q: ``(N, n)`` the joints that reach it.
        iterations: total Levenberg-Marquardt iterations over all points and starts (work counter).
    """

    residual: Array
    q: Array
    iterations: int


class ReachTest:
    """Membership of points in the reachable (``cone=180``) or dexterous workspace of ``robot``.

    ``cloud`` chart samples (seeded; a fraction ``faces`` of their coordinates on the box's faces)
    give the starts: each point is solved from the chart coordinates of ``starts`` of its ``pool``
    nearest sample tips, evenly spread in rank, one after the other until one reaches it; a point
    left farther than ``far`` (m; default :data:`FAR` of the workspace's size) by its first start
    is outside. Each solve is at most ``iterations`` Levenberg-Marquardt steps. ``tol`` (m) is the
    residual below which a point is inside. ``length`` (m) weighs the cone's hinge residual
    ``length * max(0, cos(cone) - axis . tool_axis)`` against the position's.
    """

    def __init__(
        self,
        robot: Any,
        *,
        cone: float = 180.0,
        axis: ArrayLike = (0.0, 0.0, 1.0),
        cloud: int = 20000,
        starts: int = 10,
        pool: int = 96,
        far: float | None = None,
        tol: float = DEFAULT_TOL,
        iterations: int = 60,
        seed: int = 0,
        faces: float = 0.25,
    ) -> None:
        self.cone, self.axis = check_cone(cone, axis)
        faces = checks.probability("faces", faces)
        cloud = checks.whole("cloud", cloud, minimum=100, maximum=MAX_POINTS)
        self.starts = checks.whole("starts", starts, minimum=1, maximum=64)
        self.pool = checks.whole("pool", pool, minimum=1, maximum=1024)
        self.tol = checks.number("tol", tol, above=0.0, unit="m")
        self.iterations = checks.whole("iterations", iterations, minimum=1, maximum=10_000)
        self.robot, self.chart = robot, JointChart(robot)
        self.cos_cone = math.cos(math.radians(self.cone))
        self.dexterous = self.cone < 180.0
        rng = np.random.default_rng(checks.seed("seed", seed))
        u, q = self.chart.sample(cloud, rng, faces=faces)
        tips = robot.tip_position(q)
        self.length = float(np.linalg.norm(tips.max(axis=0) - tips.min(axis=0))) or 1.0
        keep = self.in_cone(q) if self.dexterous else np.ones(len(q), dtype=bool)
        if keep.sum() < self.starts:  # too few samples in the cone: start from the closest axes
            keep = np.argsort(-(robot.tool_axis(q) @ self.axis))[: max(self.starts, 100)]
        self.cloud_u, self.cloud_tips = u[keep], tips[keep]
        self.tree = cKDTree(self.cloud_tips)
        self.far = FAR * self.length if far is None else checks.number("far", far, above=0.0, unit="m")

    def in_cone(self, q: Array) -> NDArray[np.bool_]:
        """Whether the tool axis at each configuration ``q`` ``(N, n)`` lies inside the cone."""
        if not self.dexterous:
            return np.ones(len(q), dtype=bool)
        return np.asarray(self.robot.tool_axis(q) @ self.axis >= self.cos_cone)

    def _residual(self, u: Array, x: Array) -> tuple[Array, Array, Array]:
        """Residuals ``(N, r)``, their Jacobian with respect to ``u`` ``(N, r, n)`` and ``q``."""
        q, factors = self.chart.joints(u)
        r = self.robot.tip_position(q) - x
        jq = self.robot.tip_jacobian(q)
        if self.dexterous:
            z = self.robot.tool_axis(q)
            gap = self.cos_cone - z @ self.axis
            on = gap > 0
            hinge = self.length * np.where(on, gap, 0.0)
            grad = -np.einsum("nkj,nk->nj", self.robot.angular_jacobian(q), np.cross(z, self.axis))
            row = self.length * grad * on[:, None]
            r = np.concatenate([r, hinge[:, None]], axis=1)
            jq = np.concatenate([jq, row[:, None, :]], axis=1)
        return r, self.chart.pull_back(jq, factors), q

    def _descend(self, u: Array, x: Array) -> tuple[Array, Array, Array, int]:
        """Projected Levenberg-Marquardt from ``u`` towards the targets ``x``: the least residual
        norms ``(N,)``, their ``u`` and ``q`` and the iterations spent (every point counted)."""
        r, ju, q = self._residual(u, x)
        f = np.einsum("nk,nk->n", r, r)
        lam = np.full(len(u), 1e-3)
        slow = np.zeros(len(u), dtype=int)
        live = np.sqrt(f) >= self.tol
        work = 0
        for _ in range(self.iterations):
            idx = np.flatnonzero(live)
            if not idx.size:
                break
            work += idx.size
            ui, ri, ji = u[idx], r[idx], ju[idx]
            g = np.einsum("nkj,nk->nj", ji, ri)
            free = ~(((ui <= 0.0) & (g > 0.0)) | ((ui >= 1.0) & (g < 0.0)))
            jf = ji * free[:, None, :]
            a = jf @ jf.transpose(0, 2, 1)
            scale = np.trace(a, axis1=1, axis2=2) / a.shape[1]
            scale = np.where(scale > 1e-200, scale, 1.0)  # every column frozen: jf = 0, the step is 0
            a += (lam[idx] * scale)[:, None, None] * np.eye(a.shape[1])
            step = -np.einsum("nkj,nk->nj", jf, np.linalg.solve(a, ri[:, :, None])[:, :, 0])
            step[~np.isfinite(step).all(axis=1)] = 0.0
            trial = np.clip(ui + step, 0.0, 1.0)
            rt, jt, qt = self._residual(trial, x[idx])
            ft = np.einsum("nk,nk->n", rt, rt)
            better = ft < f[idx]
            gain = np.where(better, (f[idx] - ft) / np.maximum(f[idx], 1e-300), 0.0)
            ok = idx[better]
            u[ok], r[ok], ju[ok], q[ok], f[ok] = trial[better], rt[better], jt[better], qt[better], ft[better]
            lam[idx] = np.where(better, np.maximum(lam[idx] / 3.0, 1e-9), lam[idx] * 4.0)
            slow[idx] = np.where(better, np.where(gain < 1e-6, slow[idx] + 1, 0), slow[idx])
            live[idx] = (np.sqrt(f[idx]) >= self.tol) & (lam[idx] < 1e10) & (slow[idx] < 4)
        return np.sqrt(f), u, q, work

    def solve(self, points: ArrayLike) -> Solve:
        """The least residual of each point ``(N, 3)`` (m) over the feasible joints, from up to
        ``starts`` starts each (the next start only for the points not yet reached); in chunks of
        a bounded memory (the Jacobians of a chunk take about 100 MB)."""
        x = checks.finite_array("points", points, shape=(None, 3))
        chunk = max(1000, 4_000_000 // self.n)
        if len(x) <= chunk:
            return self._solve(x)
        parts = [self._solve(x[i : i + chunk]) for i in range(0, len(x), chunk)]
        return Solve(
            np.concatenate([part.residual for part in parts]),
            np.concatenate([part.q for part in parts]),
            sum(part.iterations for part in parts),
        )

    def _solve(self, x: Array) -> Solve:
        """:meth:`solve` for one chunk of checked points ``(N, 3)``."""
        best = np.full(len(x), np.inf)
        q_best = np.zeros((len(x), self.n))
        if not len(x):
            return Solve(best, q_best, 0)
        pool = min(self.pool, len(self.cloud_tips))
        _, near = self.tree.query(x, k=pool)
        ranks = np.unique(np.round(np.linspace(0, pool - 1, min(self.starts, pool))).astype(int))
        near = np.asarray(near).reshape(len(x), pool)[:, ranks]
        k = len(ranks)
        todo = np.arange(len(x))
        work = 0
        j = 0
        while j < k and todo.size:
            # one start at a time for many points (the next only for those not reached yet); the
            # remaining starts at once for few (the iterations' fixed costs dominate there): the
            # same points are reached either way
            together = 1 if j == 0 or todo.size * (k - j) > SMALL_BATCH else k - j
            rows = np.repeat(todo, together)
            starts = near[todo, j : j + together].ravel()
            res, _, q, spent = self._descend(self.cloud_u[starts].copy(), x[rows])
            work += spent
            order = np.lexsort((res, rows))  # by point, then by residual: the first of each point is its best
            first = order[np.r_[True, rows[order][1:] != rows[order][:-1]]]
            better = res[first] < best[rows[first]]
            best[rows[first][better]], q_best[rows[first][better]] = res[first][better], q[first][better]
            todo = todo[(best[todo] >= self.tol) & (best[todo] < self.far)]
            j += together
        return Solve(best, q_best, work)

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.chart.n)

    def contains(self, points: ArrayLike) -> NDArray[np.bool_]:
        """Whether each point ``(N, 3)`` (m) is in the workspace (the residual below ``tol``)."""
        return np.asarray(self.solve(points).residual < self.tol)


# -- the bounding box ------------------------------------------------------------------------------


def _extreme(test: ReachTest, direction: Array, rounds: int = 200) -> float:
    """The largest ``direction . P(q)`` over the feasible joints (m): projected gradient ascent in
    the chart from the 16 best cloud samples, a backtracking step each round."""
    robot, chart = test.robot, test.chart
    scores = test.cloud_tips @ direction
    u = test.cloud_u[np.argsort(-scores)[:16]].copy()
    q, factors = chart.joints(u)
    value = robot.tip_position(q) @ direction
    step = np.full(len(u), 0.1)
    for _ in range(rounds):
        g = np.einsum("nkj,k->nj", chart.pull_back(robot.tip_jacobian(q), factors), direction)
        trial = np.clip(u + step[:, None] * g / (np.linalg.norm(g, axis=1, keepdims=True) + 1e-300), 0, 1)
        qt, ft = chart.joints(trial)
        vt = robot.tip_position(qt) @ direction
        up = vt > value
        u[up], q[up], factors[up], value[up] = trial[up], qt[up], ft[up], vt[up]
        step = np.where(up, np.minimum(step * 1.5, 0.5), step * 0.5)
        if step.max() < 1e-10:
            break
    return float(value.max())


def reach_bounds(test: ReachTest) -> tuple[Array, Array]:
    """The bounding box ``(lower, upper)`` ``(3,)`` each (m) of the reachable workspace: the
    extremes of each coordinate of the tip over the feasible joints (:func:`_extreme`)."""
    upper = np.array([_extreme(test, e) for e in np.eye(3)])
    lower = -np.array([_extreme(test, -e) for e in np.eye(3)])
    return lower, upper


# -- volume ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class WorkspaceVolume:
    """The volume of a workspace by grown voxels (:func:`workspace_volume`).

    Attributes:
        volume: the volume (m^3).
        cone: the cone's half-angle (deg; 180: the reachable workspace), axis its direction.
        voxel: the voxel edge (m); refine: points per voxel edge in a measured voxel.
        origin: ``(3,)`` the corner of the grid (m); shape: ``(3,)`` voxels per axis.
        inside: voxels counted whole without a test; measured: voxels measured point by point.
        tests: membership tests spent; seconds: wall time of the computation (s).
        boundary: ``(B, 3)`` points inside measured voxels that have a neighbour point outside (m):
            the workspace's boundary surface, for the figures.
        cloud: ``(C, 3)`` tips of joint samples in the workspace (m), for the figures.
        lower, upper: ``(3,)`` the reachable workspace's bounding box (m).
    """

    volume: float
    cone: float
    axis: Array
    voxel: float
    refine: int
    origin: Array
    shape: tuple[int, int, int]
    inside: int
    measured: int
    tests: int
    seconds: float
    boundary: Array = field(repr=False)
    cloud: Array = field(repr=False)
    lower: Array = field(repr=False)
    upper: Array = field(repr=False)


def _neighbours(index: NDArray[np.int64], shape: tuple[int, int, int]) -> NDArray[np.int64]:
    """The flat indices of the 26 neighbours (inside the grid) of the flat voxel indices ``index``."""
    ijk = np.stack(np.unravel_index(index, shape), axis=1)
    offsets = np.array(
        [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1) if (a, b, c) != (0, 0, 0)]
    )
    around = (ijk[:, None, :] + offsets[None]).reshape(-1, 3)
    ok = ((around >= 0) & (around < np.array(shape))).all(axis=1)
    return np.unique(np.ravel_multi_index(around[ok].T, shape))


Grid = tuple[Array, float, tuple[int, int, int]]


def _measure(test: ReachTest, index: NDArray[np.int64], grid: Grid, refine: int, rng: np.random.Generator):
    """The least residuals (m) of one point in each of the ``refine^3`` sub-cells of each voxel
    ``index`` ``(V, refine^3)``, drawn uniformly in its sub-cell (stratified sampling: unbiased
    whatever the boundary, where sub-cell centres would count a wall parallel to the grid a quarter
    of a sub-cell off), and the points ``(V, refine^3, 3)`` (m)."""
    origin, h, shape = grid
    ijk = np.stack(np.unravel_index(index, shape), axis=1).astype(float)
    cells = np.arange(refine, dtype=float)
    corners = np.stack(np.meshgrid(cells, cells, cells, indexing="ij"), axis=-1).reshape(-1, 3)
    offsets = (corners[None] + rng.random((len(index), len(corners), 3))) / refine
    points = origin + h * (ijk[:, None, :] + offsets)
    residual = test.solve(points.reshape(-1, 3)).residual.reshape(len(index), -1)
    return residual, points


def _grid(test: ReachTest, voxel: float | None) -> tuple[Array, float, tuple[int, int, int], Array, Array]:
    """The voxel grid over the reachable workspace's box, one voxel wider each side: its corner
    (m), edge (m), shape, and the box (m)."""
    lower, upper = reach_bounds(test)
    extent = float((upper - lower).max())
    h = extent / 40.0 if voxel is None else checks.number("voxel", voxel, above=0.0, unit="m")
    counts = np.ceil((upper - lower) / h).astype(int) + 2
    if float(np.prod(counts.astype(float))) > MAX_POINTS:
        checks.refuse("voxel", voxel, f"a voxel edge giving at most {MAX_POINTS:,} voxels (m)")
    return lower - h, h, (int(counts[0]), int(counts[1]), int(counts[2])), lower, upper


def _hits(
    test: ReachTest, grid: tuple[Array, float, tuple[int, int, int]], samples: int, seed: int
) -> NDArray[np.bool_]:
    """The voxels ``(V,)`` (flat) hit by the tips of ``samples`` seeded joint samples in the cone."""
    origin, h, shape = grid
    rng = np.random.default_rng(seed)
    hit = np.zeros(shape, dtype=bool)
    for start in range(0, samples, 100_000):
        _, q = test.chart.sample(min(100_000, samples - start), rng, faces=0.1)
        tips = test.robot.tip_position(q[test.in_cone(q)])
        ijk = np.clip(np.floor((tips - origin) / h).astype(int), 0, np.array(shape) - 1)
        hit[tuple(ijk.T)] = True
    return hit.ravel()


def _grow(
    test: ReachTest, grid: Grid, hit: NDArray[np.bool_], refine: int, rng: np.random.Generator
) -> tuple[Array, NDArray[np.bool_], int, Array]:
    """Measure the voxels on the border of the hit set, then every neighbour of a measured voxel
    that is partly inside (or unhit and inside, or within two voxel edges of the workspace), until
    none is left: the fraction inside of each voxel ``(V,)``, which were measured, the tests spent
    and the boundary points ``(B, 3)`` (m)."""
    _, h, shape = grid
    border = np.zeros(hit.size, dtype=bool)
    near = _neighbours(np.flatnonzero(hit), shape)
    border[near[~hit[near]]] = True  # unhit voxels next to a hit one
    around = _neighbours(np.flatnonzero(border), shape)
    border[around[hit[around]]] = True  # hit voxels next to an unhit one
    fraction = np.zeros(hit.size)
    done = np.zeros(hit.size, dtype=bool)
    todo = np.flatnonzero(border)
    boundary: list[Array] = []
    tests = 0
    while todo.size:
        residual, points = _measure(test, todo, grid, refine, rng)
        inside = residual < test.tol
        tests += inside.size
        done[todo] = True
        fraction[todo] = inside.mean(axis=1)
        # a neighbour may hold a sliver no sub-cell point of this voxel reaches: grow also from a
        # voxel whose nearest point is within two voxel edges of the workspace
        partial = todo[(residual.min(axis=1) < 2.0 * h) & ((fraction[todo] < 1) | ~hit[todo])]
        mixed = inside.any(axis=1) & ~inside.all(axis=1)
        boundary.append(points[mixed][inside[mixed]])
        grown = _neighbours(partial, shape) if partial.size else np.zeros(0, dtype=np.int64)
        todo = grown[~done[grown]]
    return fraction, done, tests, np.concatenate(boundary) if boundary else np.zeros((0, 3))


def workspace_volume(
    robot: Any,
    *,
    cone: float = 180.0,
    axis: ArrayLike = (0.0, 0.0, 1.0),
    voxel: float | None = None,
    refine: int = 2,
    samples: int = 1_000_000,
    seed: int = 0,
    test: ReachTest | None = None,
) -> WorkspaceVolume:
    """The volume of the reachable (``cone=180``) or dexterous workspace (m^3) by grown voxels.

    ``voxel`` (m; default 1/40 of the bounding box's longest side) is the grid's edge; ``samples``
    joint samples (seeded) mark the voxels their tips hit; voxels hit whose 26 neighbours are all
    hit count whole; every other voxel next to a hit one is measured by the membership of its
    ``refine^3`` sub-cells, one point drawn in each (:class:`ReachTest`, ``test`` if given), and the
    measurement grows into the neighbours of every voxel measured partly inside until none is left
    (:func:`_grow`).
    """
    started = time.perf_counter()
    test = test or ReachTest(robot, cone=cone, axis=axis, seed=seed)
    check_volume(test)
    refine = checks.whole("refine", refine, minimum=1, maximum=8)
    samples = checks.whole("samples", samples, minimum=MIN_SAMPLES, maximum=MAX_POINTS)
    origin, h, shape, lower, upper = _grid(test, voxel)
    seed = checks.seed("seed", seed)
    hit = _hits(test, (origin, h, shape), samples, seed)
    rng = np.random.default_rng([seed, 1])
    fraction, done, tests, boundary = _grow(test, (origin, h, shape), hit, refine, rng)
    whole = hit & ~done
    return WorkspaceVolume(
        volume=h**3 * (int(whole.sum()) + float(fraction[done].sum())),
        cone=test.cone,
        axis=test.axis,
        voxel=h,
        refine=refine,
        origin=origin,
        shape=shape,
        inside=int(whole.sum()),
        measured=int(done.sum()),
        tests=tests,
        seconds=time.perf_counter() - started,
        boundary=boundary,
        cloud=test.cloud_tips[:20000],
        lower=lower,
        upper=upper,
    )


@dataclass(frozen=True)
class MonteCarloVolume:
    """A Monte Carlo estimate of a workspace's volume (:func:`monte_carlo_volume`).

    Attributes:
        volume: the estimate (m^3); standard_error: its standard error (m^3).
        samples: points drawn; hits: points found inside; box_volume: the box's volume (m^3).
        lower, upper: ``(3,)`` the box the points were drawn in (m); seed: the seed.
        seconds: wall time (s).
    """

    volume: float
    standard_error: float
    samples: int
    hits: int
    box_volume: float
    lower: Array
    upper: Array
    seed: int
    seconds: float


def monte_carlo_volume(
    robot: Any,
    samples: int,
    seed: int,
    *,
    cone: float = 180.0,
    axis: ArrayLike = (0.0, 0.0, 1.0),
    test: ReachTest | None = None,
    batch: int = 50_000,
) -> MonteCarloVolume:
    """The workspace's volume by Monte Carlo (m^3): ``samples`` points drawn uniformly (seeded) in
    the bounding box of the reachable workspace (:func:`reach_bounds`, widened by 1 %), each tested
    for membership (:class:`ReachTest`); the standard error is ``V_box sqrt(f (1 - f) / samples)``."""
    started = time.perf_counter()
    samples = checks.whole("samples", samples, minimum=MIN_SAMPLES, maximum=MAX_POINTS)
    seed = checks.seed("seed", seed)
    test = test or ReachTest(robot, cone=cone, axis=axis, seed=seed)
    check_volume(test)
    lower, upper = reach_bounds(test)
    pad = 0.01 * (upper - lower)
    lower, upper = lower - pad, upper + pad
    rng = np.random.default_rng(seed)
    hits = 0
    for start in range(0, samples, batch):
        points = rng.uniform(lower, upper, size=(min(batch, samples - start), 3))
        hits += int(test.contains(points).sum())
    box = float(np.prod(upper - lower))
    f = hits / samples
    return MonteCarloVolume(
        volume=box * f,
        standard_error=box * math.sqrt(f * (1 - f) / samples),
        samples=samples,
        hits=hits,
        box_volume=box,
        lower=lower,
        upper=upper,
        seed=seed,
        seconds=time.perf_counter() - started,
    )


# -- slices ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Slice:
    """The workspace's boundary in the horizontal plane at height ``z`` (:func:`workspace_slices`).

    Attributes:
        z: the height (m).
        loops: closed boundary curves, each ``(K, 2)`` ``(x, y)`` points (m), the last equal to the
            first; outer curves and holes alike.
        area: the area inside (m^2): the loops' signed shoelace areas summed (holes subtract).
        grid_area: the same area counted on the membership grid the loops were traced on (m^2).
    """

    z: float
    loops: tuple[Array, ...]
    area: float
    grid_area: float


def _crossings(vertices: Array, xs: Array, ys: Array, inside: NDArray[np.bool_]) -> tuple[Array, Array]:
    """For contour vertices at the midpoints of grid edges, the edge's inside and outside ends."""
    h = np.array([xs[1] - xs[0], ys[1] - ys[0]])
    cell = (vertices - np.array([xs[0], ys[0]])) / h
    on_x = np.abs(cell[:, 0] - np.round(cell[:, 0])) < 0.25  # on a grid column: the edge runs along y
    i0 = np.where(on_x, np.round(cell[:, 0]), np.floor(cell[:, 0])).astype(int)
    j0 = np.where(on_x, np.floor(cell[:, 1]), np.round(cell[:, 1])).astype(int)
    i1, j1 = i0 + ~on_x, j0 + on_x
    i0, i1 = np.clip(i0, 0, len(xs) - 1), np.clip(i1, 0, len(xs) - 1)
    j0, j1 = np.clip(j0, 0, len(ys) - 1), np.clip(j1, 0, len(ys) - 1)
    a = np.stack([xs[i0], ys[j0]], axis=1)
    b = np.stack([xs[i1], ys[j1]], axis=1)
    a_in = inside[j0, i0]
    return np.where(a_in[:, None], a, b), np.where(a_in[:, None], b, a)


def _bisect(test: ReachTest, inner: Array, outer: Array, steps: int) -> Array:
    """Points ``(K, 3)`` moved onto the boundary between ``inner`` (inside) and ``outer`` (outside)
    points by ``steps`` bisections of each segment, all segments at once."""
    for _ in range(steps):
        middle = 0.5 * (inner + outer)
        found = test.contains(middle)[:, None]
        inner, outer = np.where(found, middle, inner), np.where(found, outer, middle)
    return np.asarray(0.5 * (inner + outer))


def _loops(inside: NDArray[np.bool_], xs: Array, ys: Array) -> list[Array]:
    """Marching-squares curves at 1/2 of one membership grid ``(len(ys), len(xs))``, ``(K, 2)`` each."""
    import contourpy

    generator = contourpy.contour_generator(xs, ys, inside.astype(float), line_type=contourpy.LineType.Separate)
    return [np.asarray(line, dtype=float) for line in generator.lines(0.5)]


def _area(loops: tuple[Array, ...]) -> float:
    """The area inside closed curves (m^2): their signed shoelace areas summed, holes subtracting."""
    signed = sum(0.5 * float(np.sum(x[:-1] * y[1:] - x[1:] * y[:-1])) for x, y in (loop.T for loop in loops))
    return abs(signed)


def workspace_slices(
    test: ReachTest,
    heights: ArrayLike,
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    resolution: int = 48,
    bisections: int = 8,
) -> tuple[Slice, ...]:
    """The workspace's boundary curves at each height ``z`` (m) of ``heights``: membership on a
    ``resolution`` x ``resolution`` grid over the box ``lower``-``upper`` (m, its x and y; one cell
    wider each side so that every curve closes), traced at 1/2 (marching squares) and each point
    moved onto the boundary by ``bisections`` bisections along its grid edge (to 2^-bisections of
    a cell). Every height is solved in the same batches."""
    zs = checks.finite_array("heights", heights, shape=(None,))
    resolution = checks.whole("resolution", resolution, minimum=4, maximum=2000)
    bisections = checks.whole("bisections", bisections, minimum=0, maximum=50)
    lo = checks.finite_array("lower", lower, shape=(3,))
    hi = checks.finite_array("upper", upper, shape=(3,))
    if not np.all(hi > lo):
        checks.refuse("upper", hi.tolist(), f"a box corner above lower = {lo.tolist()} on every axis (m)")
    h = (hi[:2] - lo[:2]) / (resolution - 1)
    xs = np.linspace(lo[0] - h[0], hi[0] + h[0], resolution + 2)
    ys = np.linspace(lo[1] - h[1], hi[1] + h[1], resolution + 2)
    gx, gy = np.meshgrid(xs, ys)
    plane = np.column_stack([gx.ravel(), gy.ravel()])
    points = np.concatenate([np.column_stack([plane, np.full(len(plane), z)]) for z in zs])
    inside = test.contains(points).reshape(len(zs), *gx.shape)
    lines = [_loops(inside[k], xs, ys) for k in range(len(zs))]
    ends = [_crossings(np.concatenate(found), xs, ys, inside[k]) if found else None for k, found in enumerate(lines)]
    segments = [(e, z) for e, z in zip(ends, zs, strict=True) if e is not None]
    inner, outer = (
        np.concatenate([np.column_stack([e[i], np.full(len(e[i]), z)]) for e, z in segments])
        if segments
        else np.zeros((0, 3))
        for i in (0, 1)
    )
    refined = _bisect(test, inner, outer, bisections)[:, :2] if len(inner) else np.zeros((0, 2))
    sizes = [len(line) for found in lines for line in found]
    pieces = iter(np.split(refined, np.cumsum(sizes)[:-1]) if sizes else [])
    cell = float(h[0] * h[1])
    slices = []
    for k, z in enumerate(zs):
        loops = tuple(_closed(next(pieces)) for _ in lines[k])
        slices.append(Slice(z=float(z), loops=loops, area=_area(loops), grid_area=cell * int(inside[k].sum())))
    return tuple(slices)


def _closed(loop: Array) -> Array:
    """A curve ``(K, 2)`` with its first point repeated at its end (unless it is already)."""
    return loop if np.array_equal(loop[0], loop[-1]) else np.vstack([loop, loop[:1]])


def default_heights(lower: ArrayLike, upper: ArrayLike, count: int = 6) -> Array:
    """``count`` heights (m) at the middles of equal layers between the box's bottom and top."""
    lo, hi = float(np.asarray(lower)[2]), float(np.asarray(upper)[2])
    return np.asarray(lo + (np.arange(count) + 0.5) / count * (hi - lo))


def slices_csv(sets: dict[str, tuple[Slice, ...]]) -> str:
    """The slices of each named set as CSV rows ``set,z,loop,x,y`` (m), one row per boundary point."""
    rows = ["set,z,loop,x,y"]
    for name, slices in sets.items():
        for piece in slices:
            for k, loop in enumerate(piece.loops):
                rows += [f"{name},{piece.z:.9g},{k},{x:.9g},{y:.9g}" for x, y in loop]
    return "\n".join(rows) + "\n"


# -- figures ---------------------------------------------------------------------------------------


def plot_slices(sets: dict[str, tuple[Slice, ...]], fig: Any = None) -> Any:
    """A figure of the slices: one panel per height, each named set's boundary curves in its own
    style (the first solid, the next dashed). Returns the figure; never shows it."""
    from matplotlib.figure import Figure

    first = next(iter(sets.values()))
    count = len(first)
    cols = min(3, max(count, 1))
    rows = max(1, math.ceil(count / cols))
    fig = fig or Figure(figsize=(4.2 * cols, 3.9 * rows))
    styles = ("-", "--", ":", "-.")
    colours = ("tab:blue", "tab:red", "tab:green", "tab:purple")
    for k in range(count):
        ax = fig.add_subplot(rows, cols, k + 1)
        for j, (name, slices) in enumerate(sets.items()):
            piece = slices[k]
            for i, loop in enumerate(piece.loops):
                label = f"{name} ({1e4 * piece.area:.0f} cm^2)" if i == 0 else None
                ax.plot(loop[:, 0], loop[:, 1], styles[j % 4], color=colours[j % 4], lw=1.2, label=label)
        ax.set_title(f"z = {first[k].z:.3f} m")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return fig


def plot_workspace_3d(
    volumes: dict[str, WorkspaceVolume], sets: dict[str, tuple[Slice, ...]] | None = None, fig: Any = None
) -> Any:
    """A 3-D figure per named workspace: its boundary points (coloured by height) and, if given, its
    slices' curves at their heights. Returns the figure; never shows it."""
    from matplotlib.figure import Figure

    fig = fig or Figure(figsize=(6.0 * len(volumes), 5.5))
    rng = np.random.default_rng(0)  # only thins the points drawn
    for k, (name, result) in enumerate(volumes.items()):
        ax = fig.add_subplot(1, len(volumes), k + 1, projection="3d")
        points = result.boundary
        if len(points) > 6000:
            points = points[rng.choice(len(points), 6000, replace=False)]
        if len(points):
            ax.scatter(points[:, 0], points[:, 1], points[:, 2], c=points[:, 2], s=1.5, cmap="viridis", alpha=0.5)
        for piece in (sets or {}).get(name, ()):
            for loop in piece.loops:
                ax.plot(loop[:, 0], loop[:, 1], np.full(len(loop), piece.z), color="k", lw=0.8)
        ax.set_title(f"{name}: {1e3 * result.volume:.2f} litres")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        span = np.maximum(result.upper - result.lower, 1e-9)
        ax.set_box_aspect(tuple(span / span.max()))
    fig.tight_layout()
    return fig
