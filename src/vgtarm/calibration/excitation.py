"""An exciting trajectory for dynamic identification: a finite Fourier series per joint.

Each joint follows ``q_i(t) = c_i + sum_l (a_il sin(l w t) + b_il cos(l w t))``, ``w = 2 pi / T``,
periodic (the data of several periods can be averaged). The centre ``c`` is the configuration
deepest inside the joint limits and the modules' triangle inequalities (a linear programme: both
are linear in ``q``). Any coefficients are made feasible by scaling: each joint's oscillation is
scaled to its limits, its speed and acceleration limits, then all together to the triangle
margins (linear in ``q`` too, so the largest admissible factor is exact on the samples). The
coefficients are chosen for the condition number of the column-normalised base regressor along the
trajectory by a seeded (1+1) evolution strategy: the constraints hold at every candidate, so the
search needs no penalty.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from .. import checks
from ..errors import InputError
from ..machine import blas_on_one_thread
from ..model.robot import Robot
from .dynamic import BaseParameters, base_parameters, regressor

Array = NDArray[np.float64]

#: Default limits where the robot file gives no actuators: speed, in joint spans per second, and
#: acceleration, in spans per second squared.
SPEED_SPANS = 1.0
ACCELERATION_SPANS = 10.0
#: Fraction of the joint spans kept clear of the limits, and of the triangle margins at the centre.
LIMIT_MARGIN = 0.02
#: Samples per period the search evaluates the condition number on.
SEARCH_SAMPLES = 100


@dataclass(frozen=True)
class ExcitingTrajectory:
    """A periodic exciting trajectory sampled at ``dt``.

    Attributes:
        t: ``(N,)`` times over one period (s); q, qd, qdd: ``(N, n)`` (m, m/s, m/s^2; rad for twists).
        centre: ``(n,)`` the centre configuration; sine, cosine: ``(n, L)`` the scaled coefficients.
        period: ``T`` (s); condition_number: of the column-normalised base regressor on ``t``;
        evaluations: condition numbers computed by the search; seed: of the search.
        joint_names: the robot's joints.
    """

    t: Array
    q: Array
    qd: Array
    qdd: Array
    centre: Array
    sine: Array
    cosine: Array
    period: float
    condition_number: float
    evaluations: int
    seed: int
    joint_names: tuple[str, ...]

    def csv_text(self) -> str:
        """``t``, then ``q``, ``qd`` and ``qdd`` of each joint (``s1``, ``s1_d``, ``s1_dd``...), one row per sample."""
        names = self.joint_names
        header = ["t", *names, *(f"{n}_d" for n in names), *(f"{n}_dd" for n in names)]
        stream = io.StringIO()
        stream.write(",".join(header) + "\n")
        np.savetxt(stream, np.column_stack([self.t, self.q, self.qd, self.qdd]), delimiter=",", fmt="%.17g")
        return stream.getvalue()


def centre_configuration(robot: Robot) -> Array:
    """The configuration deepest inside the joint limits and triangle inequalities, ``(n,)``: it
    maximises the least of the joints' distances to their limits (in spans) and the margins' (in
    metres over the row's norm), by a linear programme."""
    lower, upper = robot.joint_limits()
    span = upper - lower
    G, h = robot.margin_form()
    n = robot.n_joints
    eye = np.eye(n)
    # variables (q, s): maximise s subject to (q - lower) >= s span, (upper - q) >= s span, G q + h >= s |G|
    rows = np.block(
        [
            [-eye, span[:, None]],
            [eye, span[:, None]],
            [-G, np.linalg.norm(G, axis=1)[:, None]],
        ]
    )
    bounds = np.concatenate([-lower, upper, h])
    cost = np.zeros(n + 1)
    cost[-1] = -1.0
    solution = scipy.optimize.linprog(cost, A_ub=rows, b_ub=bounds, bounds=[(None, None)] * (n + 1))
    if not solution.success or solution.x[-1] <= 0.0:
        raise InputError(f"robot {robot.parameters.name!r}: no configuration is inside its limits and assemblable")
    centre = np.asarray(solution.x[:n], dtype=float)
    free = ~np.any(G != 0.0, axis=0)  # joints no margin involves (twists): the middle of their range
    centre[free] = 0.5 * (lower[free] + upper[free])
    return centre


def _basis(t: Array, period: float, harmonics: int) -> tuple[Array, Array, Array, Array, Array, Array]:
    """``sin``, ``cos`` of ``l w t`` and their first and second time derivatives, each ``(N, L)``."""
    w = 2.0 * np.pi / period * np.arange(1, harmonics + 1)
    angle = np.outer(t, w)
    s: Array = np.sin(angle)
    c: Array = np.cos(angle)
    return s, c, w * c, -w * s, -(w**2) * s, -(w**2) * c


def _limits(robot: Robot, speed: float, acceleration: float) -> tuple[Array, Array]:
    lower, upper = robot.joint_limits()
    span = upper - lower
    vmax, amax = speed * span, acceleration * span
    actuators = robot.actuators
    if actuators is not None:
        vmax = np.minimum(vmax, actuators.speed)  # inf where a joint has no actuator entry
        amax = np.minimum(amax, actuators.acceleration)
    return vmax, amax


@dataclass(frozen=True)
class _Problem:
    robot: Robot
    centre: Array
    period: float
    harmonics: int
    vmax: Array
    amax: Array
    base: BaseParameters

    def states(self, x: Array, t: Array) -> tuple[Array, Array, Array, Array, Array]:
        """``q, qd, qdd`` on ``t`` of the coefficients ``x`` (flattened sine then cosine) scaled to the
        limits, and the scaled ``sine``, ``cosine`` coefficients ``(n, L)``."""
        n, L = self.robot.n_joints, self.harmonics
        a, b = x[: n * L].reshape(n, L), x[n * L :].reshape(n, L)
        s, c, ds, dc, dds, ddc = _basis(t, self.period, L)
        d, dd, ddd = s @ a.T + c @ b.T, ds @ a.T + dc @ b.T, dds @ a.T + ddc @ b.T
        lower, upper = self.robot.joint_limits()
        room = LIMIT_MARGIN * (upper - lower)
        with np.errstate(divide="ignore"):
            factor = np.min(
                [
                    (upper - room - self.centre) / np.maximum(d.max(axis=0), 0.0),
                    (self.centre - lower - room) / np.maximum(-d.min(axis=0), 0.0),
                    self.vmax / np.abs(dd).max(axis=0),
                    self.amax / np.abs(ddd).max(axis=0),
                ],
                axis=0,
            )
        factor = np.where(np.isfinite(factor), factor, 0.0)
        G, h = self.robot.margin_form()
        slack = G @ self.centre + h
        push = -(d * factor) @ G.T  # how far each margin row falls below its centre value
        worst = push.max(axis=0)
        allowed = (1.0 - LIMIT_MARGIN) * slack
        overall = float(np.min(np.where(worst > 0, allowed / np.where(worst > 0, worst, 1.0), np.inf), initial=1.0))
        factor = factor * min(1.0, overall)
        return (
            self.centre + d * factor,
            dd * factor,
            ddd * factor,
            a * factor[:, None],
            b * factor[:, None],
        )

    def condition(self, x: Array, t: Array) -> float:
        q, qd, qdd, _, _ = self.states(x, t)
        full = regressor(self.robot, q, qd, qdd).reshape(-1, len(self.base.names))
        design = self.base.regressor(full)
        norms = np.linalg.norm(design, axis=0)
        if not (norms > 0).all():
            return float("inf")
        with blas_on_one_thread():
            return float(np.linalg.cond(design / norms))


def exciting_trajectory(
    robot: Robot,
    *,
    period: float = 5.0,
    harmonics: int = 5,
    dt: float = 0.002,
    evaluations: int = 200,
    speed: float = SPEED_SPANS,
    acceleration: float = ACCELERATION_SPANS,
    base: BaseParameters | None = None,
    seed: int = 0,
) -> ExcitingTrajectory:
    """An exciting trajectory of ``robot`` (module docstring): ``harmonics`` per joint over ``period``
    (s), sampled at ``dt`` (s), its coefficients searched over ``evaluations`` condition numbers from
    ``seed``. Speeds stay within ``speed`` joint spans per second and accelerations within
    ``acceleration`` spans per second squared (and the robot file's actuator speeds and accelerations
    where it has them); positions within the limits less 2 % of the span, margins above 2 % of
    the centre's."""
    period = checks.positive("period", period, "s")
    harmonics = checks.whole("harmonics", harmonics, 1, 50)
    dt = checks.positive("dt", dt, "s", maximum=period / 4)
    evaluations = checks.whole("evaluations", evaluations, 1, 100000)
    speed = checks.positive("speed", speed, "spans/s")
    acceleration = checks.positive("acceleration", acceleration, "spans/s^2")
    rng = np.random.default_rng(checks.seed("seed", seed))
    base = base if base is not None else base_parameters(robot, seed=seed)
    vmax, amax = _limits(robot, speed, acceleration)
    problem = _Problem(robot, centre_configuration(robot), period, harmonics, vmax, amax, base)
    search_t = np.linspace(0.0, period, SEARCH_SAMPLES, endpoint=False)
    decay = np.tile(1.0 / np.arange(1, harmonics + 1), 2 * robot.n_joints)
    x = rng.standard_normal(decay.size) * decay
    best, step = problem.condition(x, search_t), 0.5
    for _ in range(evaluations - 1):
        trial = x + step * rng.standard_normal(x.size) * decay
        value = problem.condition(trial, search_t)
        if value < best:
            x, best, step = trial, value, step * 1.5
        else:
            step *= 0.9
    t = np.arange(0.0, period, dt)
    q, qd, qdd, sine, cosine = problem.states(x, t)
    return ExcitingTrajectory(
        t=t,
        q=q,
        qd=qd,
        qdd=qdd,
        centre=problem.centre,
        sine=sine,
        cosine=cosine,
        period=period,
        condition_number=problem.condition(x, t),
        evaluations=evaluations,
        seed=seed,
        joint_names=robot.joint_names,
    )
