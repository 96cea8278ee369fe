"""Time-optimal retiming of a geometric joint path under the actuators' limits, viscous friction exact.

The joints follow the geometry of a reference, ``q(s)`` with the path parameter ``s`` its own time
(so ``q' = qd``, ``q'' = qdd`` of the reference), at a new pace ``s(t)``: ``sdot = y``,
``sddot = u``. Along the path the joint forces are

    tau = a(s) u + b(s) y^2 + c(s) + d(s) y,

``a = M q'``, ``b = M q'' + (velocity products at q')``, ``c`` gravity and the tool force, and
``d = diag(viscous) q'`` the viscous friction: first order in ``y``. Per joint the limits are the
actuator's force bounds at the joint velocity ``q' y`` (with the force-speed line where set, itself
linear in ``y``), the speed ``|q' y| <= speed`` and the acceleration ``|q' u + q'' y^2| <=
acceleration``. In ``(u, x = y^2)`` a first-order term is ``sqrt(x)``: TOPP-RA (toppra), linear in
``(u, x)``, cannot hold friction exactly; here each constraint is a quadratic in ``y`` and every
bound is the root of a quadratic.

**The method** (TOPP-RA's, on a grid of ``s``, ``u`` constant per interval, ``x_{i+1} = x_i +
2 Delta_i u_i``, the constraints at the grid points): every constraint reads ``u <= P(y)`` or
``u >= P(y)`` with ``P`` a quadratic in ``y`` (or, where the path's ``a`` is zero, ``0 <= D(y)``).
The limit curve is the largest ``y`` up to which every upper ``P`` stays above every lower one
(the first root where their difference turns negative), the speed bound and ``x_{i+1} >= 0``
allow; the controllable set's upper end at stage ``i`` is the largest ``y`` below it from which
the hardest braking, ``y^2 + 2 Delta max(lower P(y))``, stays under the next stage's upper end
(again first roots of quadratics), and the profile is TOPP-RA's greedy forward pass: the largest
``u`` that keeps ``x_{i+1}`` controllable. Every point of the path must be one the actuators can
hold at rest (checked), so ``0`` is controllable everywhere and every set is ``[0, upper end]``:
from rest, the sets are exact, an island of feasible speeds above a gap is not used (none exists
without friction, where the sets are convex, as toppra's). The duration of a profile is
``sum 2 Delta_i / (y_i + y_{i+1})``, toppra's ``ParametrizeConstAccel``.

**The discretisation.** A grid point's constraints hold one interval's ``u``: the one after it
(``scheme="departure"``, TOPP-RA's collocation and toppra's default; without friction the same
profile as toppra's, to its solver's tolerance) or the one before it (``"arrival"``: the same
passes on the reversed path, where the controllable sets become the sets reachable from the
start); ``"interval"`` (the default) is ``"arrival"`` with the constraints of the interval's start
point added, at the arrival speed. The first is explicit in the speed: where a limit falls steeply
with the speed (a force-speed line) it overshoots to speeds where only hard braking is left and the
profile chatters down to rest and back; the others are implicit and do not. Either way the limits
hold at the grid points as the scheme states them, exactly; between the points a joint can pass its
bound by an amount of order the grid's step, more where the path's ``q'`` vanishes (its ends, a
corner where it stops) and ``a`` with it: there a point's constraint lets a huge ``u`` through that
the interval's other end would not (toppra's profiles too; ``"interval"`` catches the geometric
part; measured in ``benchmarks/bench_retime.py``). So :func:`retime` by default solves under limits
:data:`MARGIN` tighter and halves the intervals where the timing, resampled every ``dt``, passes one
of the actuators' own limits, until none does (``refine`` rounds at most).

The tool force is ``tool_force`` (N) against the motion, along the tip path's tangent
``J_P q' / |J_P q'|`` at every point (where the path rests, the nearest tangent): of constant
magnitude, at rest too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from . import checks
from .errors import InputError, PathError
from .model.actuators import Actuator, Actuators
from .paths import MIN_DT
from .simulation.reference import JointReference

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from .model.robot import Robot

Array = NDArray[np.float64]

#: Largest path speed ``sdot`` considered (per second of the reference's time): where the path's
#: joints do not move nothing else bounds it.
SPEED_CAP = 1e6
#: Coefficient standing for "no bound" in a quadratic (finite, so that no ``inf - inf`` appears).
_BIG = 1e150
#: A constraint's ``a`` below this fraction of its largest magnitude is taken as zero (a pure
#: bound on the speed).
_ZERO_A = 1e-12
#: Default number of grid points.
DEFAULT_GRID = 400
#: Largest number of grid points.
MAX_GRID = 1_000_000
#: The discretisations (:func:`solve`): the interval whose ``u`` a grid point's constraints hold.
SCHEMES = ("interval", "arrival", "departure")
#: Rounds of grid refinement by default (:func:`retime`), and the most accepted.
DEFAULT_REFINE = 20
MAX_REFINE = 60
#: With refinement the timing is solved under limits this fraction tighter (each peak force, speed
#: and acceleration times ``1 - MARGIN``), and the grid refined until the 1 ms resampling is within
#: the actuators' own limits: the margin absorbs what is left between grid points. Measured on case
#: 1 and 2 under 60 N / 0.05 m/s legs (400 points): without refinement the excess is 1.8 N and 34 N;
#: refined with 1e-3 of margin, none, for about 530 and 460 points (0.1 s) and a timing 0.1 % longer.
MARGIN = 1e-3
#: Most samples :meth:`Retimed.reference` builds.
MAX_SAMPLES = 10_000_000

__all__ = [
    "DEFAULT_GRID",
    "SCHEMES",
    "Geometry",
    "GridMotion",
    "PathDynamics",
    "Profile",
    "Retimed",
    "collocated",
    "force_excess",
    "path_dynamics",
    "retime",
    "solve",
    "tool_forces",
]


@dataclass(frozen=True, eq=False)
class PathDynamics:
    """The path and its dynamics at the grid ``s`` ``(K,)``: ``q``, ``qs = q'``, ``qss = q''`` and
    ``tau = a u + b y^2 + c + d y`` (``a``, ``b``, ``c``, ``d``), each ``(K, n)`` (SI per joint)."""

    s: Array
    q: Array
    qs: Array
    qss: Array
    a: Array
    b: Array
    c: Array
    d: Array


@dataclass(frozen=True, eq=False)
class Profile:
    """The solution on the grid ``s`` ``(K,)``: ``limit`` the limit curve ``sdot_max`` ``(K,)``,
    ``speed`` the joints' speed limits as a bound on ``sdot`` ``(K,)``, ``controllable`` the upper
    end of the controllable set (as ``sdot``) ``(K,)``, ``x = sdot^2`` ``(K,)`` and ``u = sddot``
    ``(K-1,)``; ``slow_stages`` how many stages of the backward pass needed roots (the others sat
    on the limit curve)."""

    s: Array
    limit: Array
    speed: Array
    controllable: Array
    x: Array
    u: Array
    slow_stages: int

    def intervals(self) -> Array:
        """Time of each interval ``(K-1,)`` (s): ``2 Delta_i / (y_i + y_{i+1})``, constant ``sddot``."""
        y = np.sqrt(self.x)
        with np.errstate(divide="ignore"):
            return np.asarray(2.0 * np.diff(self.s) / (y[1:] + y[:-1]))

    @property
    def duration(self) -> float:
        """The profile's duration (s)."""
        return float(np.sum(self.intervals()))


def _first_crossing(A: Array, B: Array, C: Array) -> Array:
    """The first ``y >= 0`` where ``A y^2 + B y + C`` turns negative, given it is ``>= 0`` at 0
    (``C`` below 0 is taken as 0); ``inf`` where it never does. The root where the derivative is
    negative, ``(-B - sqrt(B^2 - 4AC)) / 2A``, written without cancellation."""
    C = np.maximum(C, 0.0)
    disc = B * B - 4.0 * A * C
    root = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(B < 0.0, 2.0 * C / (root - B), (-B - root) / (2.0 * A))
    never = (disc < 0.0) | ((disc == 0.0) & (A > 0.0)) | np.isnan(r) | (r < 0.0)
    return np.where(never, np.inf, r)


def _constraint_rows(path: PathDynamics, actuators: Actuators) -> list[tuple[Array, ...]]:
    """Per kind of limit, the two rows ``(alpha, beta, gamma, delta)`` of ``alpha u + beta y^2 +
    gamma y + delta <= 0`` (upper, lower; the lower's ``alpha`` is the upper's negated) and the
    joints it holds for ``(K, n)`` each."""
    force, speed, accel = actuators.force, actuators.speed, actuators.acceleration
    line = actuators.force_speed
    has_force = np.broadcast_to(np.isfinite(force), path.a.shape)
    F = np.where(np.isfinite(force), force, 0.0)
    v = np.where(np.isfinite(speed), speed, 1.0)
    qs = path.qs
    push = np.where(line & (qs > 0.0), F * qs / v, 0.0)  # the line's loss, motoring forward
    pull = np.where(line & (qs < 0.0), -F * qs / v, 0.0)  # ... backward
    force_rows = (path.a, path.b, path.d + push, path.c - F, -path.b, -path.d + pull, -path.c - F, has_force)
    has_accel = np.broadcast_to(np.isfinite(accel), qs.shape)
    A = np.where(np.isfinite(accel), accel, 0.0)
    zero = np.zeros_like(qs)
    accel_rows = (qs, path.qss, zero, zero - A, -path.qss, zero, zero - A, has_accel)
    return [force_rows, accel_rows] if has_accel.any() else [force_rows]


def _quadratics(path: PathDynamics, actuators: Actuators) -> tuple[Array, Array, Array]:
    """The constraints as quadratics in ``y``: upper bounds ``P_up`` and lower bounds ``P_lo`` on
    ``u`` ``(K, J, 3)`` (no bound: ``+-_BIG``) and pure bounds ``D >= 0`` ``(K, 2J, 3)``; the
    coefficients of ``y^2``, ``y``, 1 on the last axis."""
    ups, los, pures = [], [], []
    none = np.array([0.0, 0.0, _BIG])
    for alpha, b1, g1, d1, b2, g2, d2, active in _constraint_rows(path, actuators):
        scale = np.max(np.abs(alpha), axis=0, initial=0.0)
        pos = active & (alpha > _ZERO_A * scale)
        neg = active & (alpha < -_ZERO_A * scale)
        pure = active & ~(pos | neg)
        one = np.stack([b1, g1, d1], axis=-1)
        two = np.stack([b2, g2, d2], axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            p1 = -one / alpha[..., None]
            p2 = two / alpha[..., None]  # the second row's alpha is -alpha
        ups.append(np.where(pos[..., None], p1, np.where(neg[..., None], p2, none)))
        los.append(np.where(pos[..., None], p2, np.where(neg[..., None], p1, -none)))
        pures += [np.where(pure[..., None], -one, none), np.where(pure[..., None], -two, none)]
    return np.concatenate(ups, axis=1), np.concatenate(los, axis=1), np.concatenate(pures, axis=1)


def _speed_bound(path: PathDynamics, actuators: Actuators) -> Array:
    """The joints' speed limits as a bound on ``sdot`` ``(K,)``, at most :data:`SPEED_CAP`."""
    speed = actuators.speed
    moving = (np.abs(path.qs) > 0.0) & np.isfinite(speed)
    with np.errstate(divide="ignore"):
        bound = np.where(moving, speed / np.abs(path.qs), np.inf)
    return np.minimum(bound.min(axis=1, initial=np.inf), SPEED_CAP)


def _limit_curve(up: Array, lo: Array, pure: Array, speed: Array, delta: Array) -> Array:
    """The largest ``sdot`` ``(K,)`` up to which, from rest, some ``u`` meets every constraint and
    keeps ``x_{i+1} >= 0`` (``delta`` ``(K,)`` the interval after each point, 0 at the last)."""
    K = len(up)
    first = np.minimum(speed, _first_crossing(pure[..., 0], pure[..., 1], pure[..., 2]).min(axis=1))
    twice = 2.0 * delta[:, None]
    # y^2 + 2 delta P_up(y) >= 0: the next x is not negative (no next point at the last)
    ahead = _first_crossing(
        1.0 + twice * up[..., 0], twice * up[..., 1], twice * up[..., 2] + (delta == 0.0)[:, None] * _BIG
    )
    first = np.minimum(first, ahead.min(axis=1))
    A, B, C = ((up[..., k][:, :, None] - lo[..., k][:, None, :]).reshape(K, -1) for k in range(3))
    return np.asarray(np.minimum(first, _first_crossing(A, B, C).min(axis=1)))


def _hardest_braking(lo: Array, limit: Array, delta: Array) -> Array:
    """Per stage, the largest ``y^2 + 2 delta P_lo(y)`` over ``y`` in ``[0, limit]`` ``(K,)``: the
    next ``x`` the hardest braking reaches at worst (at the ends or the vertex of each quadratic)."""
    A = 1.0 + 2.0 * delta[:, None] * lo[..., 0]
    B = 2.0 * delta[:, None] * lo[..., 1]
    C = 2.0 * delta[:, None] * lo[..., 2]
    top = limit[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.clip(np.where(A < 0.0, -B / (2.0 * A), 0.0), 0.0, top)
    values = [A * y * y + B * y + C for y in (np.zeros_like(top), top, vertex)]
    return np.max(np.maximum(np.maximum(values[0], values[1]), values[2]), axis=1)


def _backward(lo: Array, limit: Array, delta: Array) -> tuple[Array, int]:
    """The controllable sets' upper ends ``x`` ``(K,)`` from rest at the end, and how many stages
    needed roots (the others: the whole limit is controllable)."""
    K = len(limit)
    worst = _hardest_braking(lo, limit, delta)
    A = -1.0 - 2.0 * delta[:, None] * lo[..., 0]  # H - y^2 - 2 delta P_lo(y) >= 0
    B = -2.0 * delta[:, None] * lo[..., 1]
    C = -2.0 * delta[:, None] * lo[..., 2]
    top = np.zeros(K)
    slow = 0
    limits = limit.tolist()
    worsts = worst.tolist()
    for i in range(K - 2, -1, -1):
        H = top[i + 1]
        if worsts[i] <= H:
            y = limits[i]
        else:
            slow += 1
            y = min(limits[i], float(_first_crossing(A[i], B[i], C[i] + H).min()))
        top[i] = y * y
    return top, slow


def _forward(up: Array, top: Array, delta: Array) -> tuple[Array, Array]:
    """TOPP-RA's greedy pass from rest: per stage the largest ``u`` that keeps ``x_{i+1}`` in the
    next controllable set; ``x`` ``(K,)`` and ``u`` ``(K-1,)``."""
    K = len(top)
    x = np.zeros(K)
    u = np.zeros(K - 1)
    rows = np.ascontiguousarray(up)
    tops = top.tolist()
    deltas = delta.tolist()
    point = np.ones(3)
    xi = 0.0
    for i in range(K - 1):
        point[0] = xi
        point[1] = math.sqrt(xi)
        most = float(np.dot(rows[i], point).min())
        step = 2.0 * deltas[i]
        nxt = min(tops[i + 1], max(0.0, xi + step * min(most, (tops[i + 1] - xi) / step)))
        u[i] = (nxt - xi) / step
        x[i + 1] = xi = nxt
    return x, u


def solve(path: PathDynamics, actuators: Actuators, scheme: str = "interval") -> Profile:
    """The fastest profile along ``path`` from rest to rest under ``actuators`` (see the module
    docstring); :class:`PathError` if a point of the path cannot be held at rest.

    ``scheme`` says which interval's ``u`` each grid point's constraints hold: ``"departure"`` the
    one after it (TOPP-RA's collocation, toppra's default), ``"arrival"`` the one before it: the
    same problem with the path reversed and ``u`` negated, solved by the same passes;
    ``"interval"``: the one before it, and the previous point's constraints too at this speed."""
    checks.choice("scheme", scheme, SCHEMES)
    _check_rest(path, actuators)
    delta = np.append(np.diff(path.s), 0.0)
    up, lo, pure = _quadratics(path, actuators)
    speed = _speed_bound(path, actuators)
    if scheme == "interval":  # also the dynamics of the interval's start, at the arrival speed
        up, lo, pure = (np.concatenate([z, np.concatenate([z[:1], z[:-1]])], axis=1) for z in (up, lo, pure))
    if scheme != "departure":  # stage k is point K-1-k; x_{k+1} = x_k + 2 delta w with w = -u
        up, lo, pure, speed = -lo[::-1], -up[::-1], pure[::-1], speed[::-1]
        delta = np.append(delta[:-1][::-1], 0.0)
    limit = _limit_curve(up, lo, pure, speed, delta)
    top, slow = _backward(lo, limit, delta)
    x, u = _forward(up, top, delta)
    if scheme != "departure":
        limit, speed, top, x, u = limit[::-1], speed[::-1], top[::-1], x[::-1], -u[::-1]
    return Profile(s=path.s, limit=limit, speed=speed, controllable=np.sqrt(top), x=x, u=u, slow_stages=slow)


def _check_rest(path: PathDynamics, actuators: Actuators) -> None:
    """Refuse a path with a point the actuators cannot hold at rest (gravity and the tool force,
    ``|c| <= force``): the retiming starts every controllable set at rest."""
    excess = np.abs(path.c) - actuators.force
    if (excess <= 0.0).all():
        return
    k, j = np.unravel_index(int(np.argmax(excess)), excess.shape)
    raise PathError(
        f"path: joint {actuators.names[j]} needs {abs(path.c[k, j]):.6g} to hold the path at rest at "
        f"s = {path.s[k]:.6g} s, more than its peak force {actuators.force[j]:.6g}"
    )


# -- the path of a reference ------------------------------------------------------------------------


def _hermite(t: Array, y: Array, dy: Array, s: Array) -> Array:
    """The cubic Hermite interpolant of ``y`` ``(N, k)`` with derivatives ``dy`` at the knots ``t``
    ``(N,)``, at ``s`` ``(m,)`` inside ``[t_0, t_N]``: ``(m, k)``."""
    i = np.clip(np.searchsorted(t, s, side="right") - 1, 0, len(t) - 2)
    h = (t[i + 1] - t[i])[:, None]
    w = (s - t[i])[:, None] / h
    w2 = w * w
    w3 = w2 * w
    return np.asarray(
        (2 * w3 - 3 * w2 + 1) * y[i]
        + (w3 - 2 * w2 + w) * h * dy[i]
        + (3 * w2 - 2 * w3) * y[i + 1]
        + (w3 - w2) * h * dy[i + 1]
    )


@dataclass(frozen=True, eq=False)
class Geometry:
    """The geometric path of a reference, ``s`` its time: ``q`` by cubic Hermite with ``q' = qd``,
    ``q'`` by cubic Hermite with ``q'' = qdd``, ``q''`` linear in ``qdd``; ``tip`` ``(N, 3)`` the
    reference's desired tip (m), or None."""

    t: Array
    q: Array
    qd: Array
    qdd: Array
    tip: Array | None = None

    def __call__(self, s: Array) -> tuple[Array, Array, Array]:
        """``q``, ``q'``, ``q''`` at ``s`` ``(m,)``, each ``(m, n)``."""
        s = np.clip(s, self.t[0], self.t[-1])
        i = np.clip(np.searchsorted(self.t, s, side="right") - 1, 0, len(self.t) - 2)
        w = ((s - self.t[i]) / (self.t[i + 1] - self.t[i]))[:, None]
        qss = (1.0 - w) * self.qdd[i] + w * self.qdd[i + 1]
        return _hermite(self.t, self.q, self.qd, s), _hermite(self.t, self.qd, self.qdd, s), qss

    def tip_at(self, s: Array, robot: Robot) -> Array | None:
        """The desired tip at ``s`` ``(m, 3)`` by cubic Hermite with ``dP/ds = J_P q'`` of ``robot``, or None."""
        if self.tip is None:
            return None
        tip_s = robot.tip_velocity(self.q, self.qd)[0]
        return _hermite(self.t, self.tip, tip_s, np.clip(s, self.t[0], self.t[-1]))


def _tangent(robot: Robot, q: Array, qs: Array) -> tuple[Array, Array]:
    """The tip path's unit tangent ``J_P q' / |J_P q'|`` ``(m, 3)`` (where it rests: the nearest
    tangent; none at all: zero) and ``J_P`` ``(m, 3, n)``."""
    J = robot.tip_jacobian(q)
    v = np.einsum("kij,kj->ki", J, qs)
    norm = np.linalg.norm(v, axis=1)
    moving = norm > 1e-12 * max(float(norm.max(initial=0.0)), 1e-300)
    if not moving.any():
        return np.zeros_like(v), J
    index = np.arange(len(v))
    before = np.maximum.accumulate(np.where(moving, index, -1))
    after = np.minimum.accumulate(np.where(moving, index, len(v))[::-1])[::-1]
    near = np.where(before < 0, after, np.where((after < len(v)) & (after - index < index - before), after, before))
    return v[near] / norm[near][:, None], J


def tool_forces(robot: Robot, q: Array, qs: Array, tool_force: float) -> Array:
    """The joint forces ``-J_P^T f`` ``(m, n)`` that hold the tool force ``f`` of ``tool_force`` (N)
    against the motion along the tip path's tangent (see :func:`_tangent`)."""
    if tool_force == 0.0:
        return np.zeros_like(qs)
    tangent, J = _tangent(robot, q, qs)
    return np.asarray(tool_force * np.einsum("kij,ki->kj", J, tangent))


def path_dynamics(
    robot: Robot, geometry: Geometry, s: Array, *, tool_force: float = 0.0, friction: bool = True
) -> PathDynamics:
    """The path's ``a``, ``b``, ``c``, ``d`` at the grid ``s`` ``(K,)`` from one batched call of
    ``robot.inverse_dynamics``; friction separated exactly (``d = (ID(q, q', 0) - ID(q, -q', 0)) / 2``,
    the velocity products being even in ``q'``), zero with ``friction`` False."""
    q, qs, qss = geometry(s)
    zero = np.zeros_like(q)
    F = robot.inverse_dynamics(np.stack([q] * 4), np.stack([zero, zero, qs, -qs]), np.stack([zero, qs, qss, qss]))
    gravity, with_a, ahead, behind = F
    d = 0.5 * (ahead - behind)
    b = 0.5 * (ahead + behind) - gravity
    c = gravity + tool_forces(robot, q, qs, tool_force)
    return PathDynamics(s=s, q=q, qs=qs, qss=qss, a=with_a - gravity, b=b, c=c, d=d if friction else np.zeros_like(d))


# -- the result --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Retimed:
    """The fastest timing of a reference's path: ``profile`` on the grid (``s``, ``x = sdot^2``,
    ``u = sddot``, the limit curve, the controllable set), ``duration`` (s), ``t`` the grid's
    times ``(K,)`` (s), the path's ``dynamics`` at the grid, and what :meth:`reference` resamples:
    the ``geometry``, the ``robot``, its ``actuators``, ``tool_force`` (N), ``friction`` (whether
    the profile holds it), ``dt`` (s) the default period, ``source`` the reference's record and
    the ``scheme`` of :func:`solve`."""

    profile: Profile
    dynamics: PathDynamics
    geometry: Geometry
    robot: Robot
    actuators: Actuators
    tool_force: float
    friction: bool
    dt: float
    source: JointReference
    scheme: str = "interval"

    @property
    def s(self) -> Array:
        """The grid of the path parameter ``(K,)`` (the reference's time, s)."""
        return self.profile.s

    @property
    def x(self) -> Array:
        """``sdot^2`` at the grid ``(K,)``."""
        return self.profile.x

    @property
    def u(self) -> Array:
        """``sddot`` on each interval ``(K-1,)``."""
        return self.profile.u

    @property
    def t(self) -> Array:
        """The time of each grid point ``(K,)`` (s)."""
        return np.concatenate([[0.0], np.cumsum(self.profile.intervals())])

    @property
    def duration(self) -> float:
        """The retimed path's duration (s)."""
        return self.profile.duration

    def timing(self, t: Array) -> tuple[Array, Array, Array]:
        """``s``, ``sdot``, ``sddot`` at the times ``t`` ``(m,)`` (s); at rest at the end after the duration."""
        grid = self.t
        y = np.sqrt(self.x)
        i = np.clip(np.searchsorted(grid, t, side="right") - 1, 0, len(grid) - 2)
        tau = np.clip(t - grid[i], 0.0, np.diff(grid)[i])
        u = self.u[i]
        s = np.minimum(self.s[i] + y[i] * tau + 0.5 * u * tau * tau, self.s[-1])
        done = t >= grid[-1]
        return np.where(done, self.s[-1], s), np.where(done, 0.0, y[i] + u * tau), np.where(done, 0.0, u)

    def collocated(self) -> GridMotion:
        """The motion at the grid points as the solver constrains it (collocation): ``q(s_i)``,
        ``qd = q' y_i``, ``qdd = q' u + q'' x_i`` with ``u`` of the interval the scheme says (0 where
        there is none: the first point of ``"arrival"``, the last of ``"departure"``)."""
        u = np.append(self.u, 0.0) if self.scheme == "departure" else np.insert(self.u, 0, 0.0)
        return collocated(self.geometry, self.s, self.x, u)

    def sampled(self, dt: float | None = None) -> tuple[Array, Array, Array, Array, Array]:
        """The retimed joints every ``dt`` s (default :attr:`dt`) from 0 past the duration (then at
        rest): ``t``, ``s(t)``, ``q``, ``qd = q' sdot`` and ``qdd = q' sddot + q'' sdot^2``."""
        step = self.dt if dt is None else checks.number("dt", dt, minimum=MIN_DT, unit="s")
        count = int(math.ceil(self.duration / step - 1e-9)) + 1
        if count > MAX_SAMPLES:
            checks.refuse("dt", step, f"a period giving at most {MAX_SAMPLES:,} samples over {self.duration:.6g} s (s)")
        t = np.arange(count, dtype=np.float64) * step
        s, sd, sdd = self.timing(t)
        q, qs, qss = self.geometry(s)
        return t, s, q, qs * sd[:, None], qs * sdd[:, None] + qss * (sd * sd)[:, None]

    def reference(self, dt: float | None = None) -> JointReference:
        """The retimed joints of :meth:`sampled` as a reference, with the source's tip path (cubic
        Hermite in ``s``), robot and task."""
        t, s, q, qd, qdd = self.sampled(dt)
        src = self.source
        return JointReference(
            t=t,
            q=q,
            qd=qd,
            qdd=qdd,
            rates="exact",
            name=f"{src.name} (retimed)",
            tip=self.geometry.tip_at(s, self.robot),
            robot=src.robot,
            robot_fingerprint=src.robot_fingerprint,
            task=src.task,
            entry_point=src.entry_point,
        )

    def figure(self, dt: float | None = None) -> Figure:
        """The phase plane (the limit curve, the controllable set's upper end, the profile ``sdot(s)``)
        and each joint's force utilisation along the retimed reference (sampled every ``dt`` s)."""
        from matplotlib.figure import Figure  # noqa: PLC0415 (matplotlib only for figures)

        fig = Figure(figsize=(9.0, 7.0), layout="constrained")
        top, bottom = fig.subplots(2, 1)
        p = self.profile
        top.plot(p.s, np.minimum(p.limit, 1.5 * max(float(p.controllable.max()), 1e-9)), label="limit curve")
        kind = "controllable set" if self.scheme == "departure" else "reachable from rest"
        top.plot(p.s, p.controllable, "--", label=f"{kind} (upper end)")
        top.plot(p.s, np.sqrt(p.x), label=f"profile ({self.duration:.4g} s)")
        top.set(xlabel="s (reference time, s)", ylabel="sdot", title="phase plane")
        top.legend(loc="best")
        ref = self.reference(dt)
        F = self.robot.inverse_dynamics(ref.q, ref.qd, ref.qdd) + _tool_along(self.robot, ref, self.tool_force)
        share = self.actuators.utilisation(F, ref.qd)
        for j, name in enumerate(self.actuators.names):
            if self.actuators.limited[j]:
                bottom.plot(ref.t, share[:, j], label=name)
        bottom.axhline(1.0, color="k", lw=0.8)
        bottom.set(xlabel="t (s)", ylabel="|F| / limit", title="force utilisation (with friction)")
        bottom.legend(loc="best", ncol=4)
        return fig


@dataclass(frozen=True, eq=False)
class GridMotion:
    """Joint positions, velocities and accelerations ``(K, n)`` at the grid points."""

    q: Array
    qd: Array
    qdd: Array


def collocated(geometry: Geometry, s: Array, x: Array, u: Array) -> GridMotion:
    """The joints at the grid ``s`` ``(K,)`` of a profile ``x = sdot^2`` and ``u = sddot`` ``(K,)``
    (the acceleration each grid point's constraints hold: of the interval after it)."""
    q, qs, qss = geometry(s)
    y = np.sqrt(x)
    return GridMotion(q=q, qd=qs * y[:, None], qdd=qs * u[:, None] + qss * x[:, None])


def _tool_along(robot: Robot, reference: Any, tool_force: float) -> Array:
    """The tool force's joint forces along a timed reference (the tangent of its ``qd``)."""
    return tool_forces(robot, np.asarray(reference.q, dtype=float), np.asarray(reference.qd, dtype=float), tool_force)


def force_excess(robot: Robot, reference: Any, actuators: Actuators, tool_force: float = 0.0) -> Array:
    """Each joint's worst excess of its force bounds along a timed ``reference`` (``t``, ``q``,
    ``qd``, ``qdd``) ``(n,)`` (N, N m): ``max_t max(F - upper, lower - F)`` with ``F`` from
    ``robot.inverse_dynamics`` (its friction included) and the tool force against the motion;
    ``<= 0`` within the bounds, ``-inf`` for a joint without an actuator. (A check of retimed
    references for the tests and the benchmark, not the path checker.)"""
    q = np.asarray(reference.q, dtype=float)
    qd = np.asarray(reference.qd, dtype=float)
    F = robot.inverse_dynamics(q, qd, np.asarray(reference.qdd, dtype=float)) + tool_forces(robot, q, qd, tool_force)
    lower, upper = actuators.bounds(qd)
    excess = np.max(np.maximum(F - upper, lower - F), axis=0)
    return np.asarray(np.where(actuators.limited, excess, -np.inf))


# -- the entry point ---------------------------------------------------------------------------------


def retime(
    robot: Robot,
    reference: Any,
    *,
    actuators: Actuators | None = None,
    dt: float | None = None,
    grid: int = DEFAULT_GRID,
    tool_force: float = 0.0,
    friction: bool = True,
    scheme: str = "interval",
    refine: int = DEFAULT_REFINE,
) -> Retimed:
    """The fastest timing of ``reference``'s geometric path (an IK result or a
    :class:`~vgtarm.simulation.JointReference`), from rest to rest, under the ``actuators``'
    force bounds (force-speed lines included), speeds and accelerations, viscous friction exact.

    Args:
        robot: the robot (its dynamics and friction).
        reference: ``t``, ``q``, ``qd``, ``qdd``: the path, ``s`` its time.
        actuators: the limits (default: the robot's).
        dt: the default period of :meth:`Retimed.reference` (s; default the reference's).
        grid: the number of grid points of ``s`` (uniform), at least 2.
        tool_force: a force on the tool against the motion (N), of constant magnitude.
        friction: whether the timing holds the friction (False: ignored, as toppra must).
        scheme: which interval's ``sddot`` each grid point's constraints hold (:func:`solve`):
            ``"interval"`` (the one before it, with the previous point's constraints too),
            ``"arrival"`` (the one before it: implicit in the speed, stable where the limits fall
            steeply with the speed, as on a force-speed line) or ``"departure"`` (the one after
            it: toppra's collocation, whose profile chatters there).
        refine: rounds of grid refinement: the limits hold at the grid points, and between them a
            joint may exceed its force, speed or acceleration bound by an amount of the order of the
            grid's step (more where ``q'`` vanishes); each round resamples the timed path every
            ``dt`` s and halves every interval where a bound is exceeded, then solves again; the
            timing is solved under limits :data:`MARGIN` tighter, which absorb what is left between
            grid points (0: the uniform grid and the limits as given, as toppra's).

    Raises:
        InputError: a bad argument (the message names it).
        PathError: a point of the path the actuators cannot hold at rest.
    """
    source, limits = _inputs(robot, reference, actuators)
    points = checks.whole("grid", grid, 2, MAX_GRID)
    force = checks.number("tool_force", tool_force, minimum=0, unit="N")
    with_friction = checks.flag("friction", friction)
    period = source.dt if dt is None else checks.number("dt", dt, minimum=MIN_DT, unit="s")
    rounds = checks.whole("refine", refine, 0, MAX_REFINE)
    geometry = Geometry(t=source.t, q=source.q, qd=source.qd, qdd=source.qdd, tip=source.tip)
    chosen = checks.choice("scheme", scheme, SCHEMES)
    s = np.linspace(source.t[0], source.t[-1], points)
    tighter = limits if rounds == 0 else _tightened(limits, 1.0 - MARGIN)
    for done in range(rounds + 1):
        dynamics = path_dynamics(robot, geometry, s, tool_force=force, friction=with_friction)
        profile = solve(dynamics, tighter, chosen)
        if not np.isfinite(profile.duration):
            raise PathError(
                f"path: the actuators cannot move it (the limit curve is zero at s = {_stuck(profile):.6g} s)"
            )
        timed = Retimed(profile, dynamics, geometry, robot, limits, force, with_friction, period, source, chosen)
        over = _exceeded_intervals(timed) if done < rounds else np.zeros(0, dtype=np.intp)
        if not over.size:
            return timed
        s = np.sort(np.concatenate([s, 0.5 * (s[over] + s[over + 1])]))
    return timed


def _exceeded_intervals(timed: Retimed) -> NDArray[np.intp]:
    """The grid intervals in which the timed path, sampled every ``timed.dt`` s, exceeds one of the
    actuators' own force, speed or acceleration bounds (friction and the tool force as the timing
    holds them; beyond round-off, 1e-12 of the bound)."""
    _, s_t, q, qd, qdd = timed.sampled()  # the samples of Retimed.reference, without its tip path
    robot, limits = timed.robot, timed.actuators
    F = robot.inverse_dynamics(q, qd, qdd) + tool_forces(robot, q, qd, timed.tool_force)
    if not timed.friction:  # the timing ignores the friction: so does its check
        F = F - np.asarray(robot.parameters.viscous, dtype=float) * qd
    lower, upper = limits.bounds(qd)
    round_off = 1e-12
    with np.errstate(invalid="ignore"):  # inf - inf where a joint has no limit: not exceeded
        force = np.maximum(F - upper, lower - F) > round_off * limits.force
        speed = np.abs(qd) > (1.0 + round_off) * limits.speed
        acceleration = np.abs(qdd) > (1.0 + round_off) * limits.acceleration
    bad = (force | speed | acceleration).any(axis=1)
    if not bad.any():
        return np.zeros(0, dtype=np.intp)
    s_bad = s_t[bad]
    grid = timed.s
    return np.unique(np.clip(np.searchsorted(grid, s_bad, side="right") - 1, 0, len(grid) - 2))


def _tightened(actuators: Actuators, factor: float) -> Actuators:
    """``actuators`` with every peak force, speed and acceleration times ``factor`` (the same lines)."""
    joints = tuple(
        None if a is None else Actuator(a.force * factor, a.speed * factor, a.acceleration * factor, a.force_speed)
        for a in actuators.joints
    )
    return Actuators(names=actuators.names, joints=joints, origins=actuators.origins)


def _stuck(profile: Profile) -> float:
    """Where the profile cannot move: the first grid point after the start with ``sdot = 0``."""
    y = np.sqrt(profile.x[1:-1])
    return float(profile.s[1 + int(np.argmin(y))]) if len(y) else float(profile.s[0])


def _inputs(robot: Robot, reference: Any, actuators: Actuators | None) -> tuple[JointReference, Actuators]:
    """The reference as a :class:`JointReference` and the actuators, checked."""

    t = getattr(reference, "t", None)
    if t is None or np.ndim(t) != 1 or np.shape(t)[0] < 2:
        checks.refuse("reference.t", np.shape(t) if t is not None else None, "times of at least 2 samples (s)")
    source = JointReference.of(reference)
    if source.q.shape[1] != robot.n_joints:
        checks.refuse("reference.q", source.q.shape, f"({len(source.t)}, {robot.n_joints}): the robot's joints")
    limits = robot.actuators if actuators is None else actuators
    if limits is None:
        raise InputError(
            "actuators = None: expected Actuators of the robot's joints (the robot has none: give actuators=)"
        )
    if not isinstance(limits, Actuators) or limits.n_joints != robot.n_joints:
        checks.refuse("actuators", limits, f"Actuators of the robot's {robot.n_joints} joints")
    return source, limits
