"""The switching control method (paper Section V-C).

While the tip position error ``|P(q_d) - P(q)|`` exceeds a threshold, the full 7x7 gain
matrices ``Kp`` and ``Kv`` of computed force control are chosen by the paper's genetic
algorithm (:mod:`vgtarm.ga`); otherwise the fixed gains are used.

**The fitness.** The paper minimises "the Euclidean norm of the trajectory errors" without
saying over what. A one-step prediction cannot serve: with explicit Euler,
``q_{k+1} = q_k + dt qd_k`` does not depend on the gains at all. vgtarm therefore predicts the
tip over a *horizon* of ``H`` control periods (default 20, i.e. 20 ms at 1 ms) under the
controller's model and takes ``sqrt(sum_{j=1..H} |P(q_d,k+j) - P(q^_k+j)|^2)``. Under its own
model, computed force control cancels ``M^`` and ``C^`` exactly, so the predicted joints obey
``qdd = qdd_d + Kp e + Kv e_dot``; they are advanced with explicit Euler and mapped to the tip
with the exact forward kinematics. The gains first act on the tip at ``j = 2``; the horizon sets
how far ahead the GA looks (see the tests and the report for its effect).

**Seeding.** The first population holds the fixed gains (exactly representable: the diagonal
at the upper bound, the rest at the lower bound) and random individuals; with elitism the GA's
choice is therefore never predicted to be worse than the fixed gains.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..errors import InputError, shown
from ..ga import GAOptions, GAResult, decode, encode, minimize
from ..model.actuators import Actuators
from ..model.closedloop import PREDICTIONS
from ..model.parameters import N_JOINTS
from ..model.robot import Robot
from .gains import Gains, check_within
from .law import commanded_acceleration
from .safety import DAMPING_STEPS, admitted_interval, damping_table

Array = NDArray[np.float64]

#: Longest GA prediction horizon, in control periods (10 s at 1 ms; the GA's work grows with it).
MAX_HORIZON = 10_000

#: Variants of the method: the paper's, and the safe one whose gains are admitted first.
VARIANTS = ("paper", "safe")

#: The safe variant's damping: tuned by the GA on a grid (default) or held at the fixed gains'.
DAMPINGS = ("tuned", "fixed")

#: The tip errors the safe variant's threshold may be tested on.
SWITCH_ON = ("measured", "true")

#: Prediction of the tip error of candidate gains: ``(Kp (P, 7, 7), Kv (P, 7, 7)) -> (P,)``.
Predictor = Callable[[Array, Array], Array]


@dataclass(frozen=True)
class SwitchingControl:
    """Computed force control whose gains are retuned by the GA while the error is large.

    Attributes:
        fixed: the gains used while the tip error is at most ``threshold``; every element within
            ``kp_bounds`` / ``kv_bounds`` (the GA could not return to them otherwise).
        threshold: tip position error (m) above which the GA chooses the gains (paper: 0.2 mm).
        kp_bounds, kv_bounds: bounds of every element of ``Kp`` and ``Kv`` (paper: [0, 5000]
            and [0, 300] in case 1; [0, 15000] and [0, 600] in case 2).
        ga: the genetic algorithm's options (paper Appendix B by default).
        horizon: prediction horizon of the fitness, in control periods (1 .. :data:`MAX_HORIZON`).
        seed_fixed_gains: put the fixed gains into the first population.
        prediction: how the compiled GA maps the predicted joint errors to the tip:
            ``"quadratic"`` (default: tip Jacobian and Hessian at the reference), ``"linear"``
            (Jacobian only) or ``"exact"`` (forward kinematics of every predicted step, as the
            NumPy GA always does). See ``docs/control.md`` for how far apart they are.
        exact_above: with ``"linear"``/``"quadratic"``, a candidate whose predicted joint-error
            norm exceeds this (m, rad) is predicted exactly instead (0: never).
        variant: ``"paper"`` (the paper's GA over full 7x7 matrices, bit for bit as before) or
            ``"safe"``: ``Kp`` symmetrised and ``Kv`` held at the fixed damping, a candidate admitted
            only when the discrete loop it closes (hold, velocity filter, model error up to
            ``model_error``) has every pole inside ``stability_radius``, and a tuned set not
            predicted to lower the error below the fixed gains' dropped for them
            (:mod:`vgtarm.control.safety`, ``docs/control.md``); a held set whose seen error rises
            is dropped (``watch_from``). ``"safe"`` is the default, as in ``vgtarm simulate`` and
            the studies; the paper's runs and figures ask for ``"paper"`` by name.
        model_error: safe variant: bound of the controller model's relative mass error (0.1: the
            model's mass within 10 % of the plant's).
        stability_radius: safe variant: every pole of the admitted loop lies inside this circle.
        damping: safe variant: ``"tuned"`` (default): ``Kv = kv I`` with ``kv`` the GA's mean ``Kv``
            diagonal snapped to a grid of :data:`~vgtarm.control.safety.DAMPING_STEPS` steps up to
            the fixed damping (beyond it as far as ``kv_bounds`` reach), each grid point with its
            own admitted interval of ``Kp`` eigenvalues; ``"fixed"``: ``Kv`` held at the fixed
            damping (the first safe variant).
        stiffness_box: safe variant: the GA searches ``Kp`` elements in ``[kp_bounds[0],
            stiffness_box * kp_bounds[1]]`` (a whole number; the fixed gains must stay exactly
            representable by the GA's codes, e.g. 1, 3, 5, 15 with 8-bit genes on the bound);
            stability is the admission's business, the box only says where to search.
        hold: safe variant: control periods an admitted gain set controls from its activation's
            sample, whatever the error meanwhile (1 .. ``horizon``; ``None``: half the horizon,
            10 periods at the default 20: in case 2 with the tool force and 1 um encoders the whole
            horizon gave outliers of 0.35-0.39 mm where half gave 0.26-0.27 mm). Its loop is
            certified for frozen gains, so holding it is covered; a set dropped for the fixed
            gains controls its sample only.
        switch_on: safe variant: the tip error the threshold is tested on: ``"measured"`` (the
            controller model's tip at the measured joints, what a real controller has; ``None``
            means this) or ``"true"`` (the plant's, as the paper's variant).
        watch_from: safe variant: a held set is dropped for the fixed gains at the first held
            period, from this one on, whose seen error (the one the threshold is tested on)
            exceeds the error seen at its activation (the activation's sample is period 0; that
            period and the later ones then run with the fixed gains until the threshold calls the
            GA again). Default 2: the first period whose joints the set's efforts have moved (with
            the paper's explicit Euler the joints at period 1 do not depend on them); ``None``:
            held sets are never dropped during their hold. See :func:`dropped_at`.

    In the paper's variant the GA runs at every control period whose error exceeds the threshold,
    on the true error. Holding its gains for several periods is not offered there: gains tuned
    over a short horizon can destabilise the loop when held (in case 2 with the tool force,
    holding them 10 periods gave peak forces of 1.6 kN, 25 periods 26 kN); the safe variant's
    admitted sets are certified for frozen gains.
    """

    fixed: Gains
    threshold: float = 2e-4
    kp_bounds: tuple[float, float] = (0.0, 5000.0)
    kv_bounds: tuple[float, float] = (0.0, 300.0)
    ga: GAOptions = field(default_factory=GAOptions)
    horizon: int = 20
    seed_fixed_gains: bool = True
    prediction: str = "quadratic"
    exact_above: float = 3e-3
    variant: str = "safe"
    model_error: float = 0.1
    stability_radius: float = 0.99
    damping: str = "tuned"
    stiffness_box: int = 5
    hold: int | None = None
    switch_on: str | None = None
    watch_from: int | None = 2
    name: str = "scm"

    def __post_init__(self) -> None:
        if not isinstance(self.fixed, Gains):
            raise InputError(f"fixed = {shown(self.fixed)}: expected Gains (use SwitchingControl.with_gains)")
        checks.positive("threshold", self.threshold, "m")
        checks.interval("kp_bounds", self.kp_bounds, unit="1/s^2")
        checks.interval("kv_bounds", self.kv_bounds, unit="1/s")
        check_within(self.fixed, self.kp_bounds, self.kv_bounds)
        if not isinstance(self.ga, GAOptions):
            raise InputError(f"ga = {shown(self.ga)}: expected a vgtarm.ga.GAOptions")
        checks.whole("horizon", self.horizon, 1, MAX_HORIZON, unit="control periods")
        checks.number("exact_above", self.exact_above, minimum=0, unit="m, rad; 0 = never")
        checks.choice("prediction", self.prediction, PREDICTIONS)
        checks.choice("variant", self.variant, VARIANTS)
        checks.number("model_error", self.model_error, minimum=0, below=1)
        checks.number("stability_radius", self.stability_radius, above=0, below=1)
        checks.choice("damping", self.damping, DAMPINGS)
        checks.whole("stiffness_box", self.stiffness_box, 1, 100)
        if self.hold is not None:
            expected = f"a whole number of control periods from 1 to {self.horizon} (the horizon) or None"
            checks.whole("hold", self.hold, 1, self.horizon, expected=expected)
        if self.watch_from is not None:
            expected = (
                f"a whole number of control periods from 1 to {MAX_HORIZON:,} (from the hold on: never) or None"
                " (never drop a held set)"
            )
            checks.whole("watch_from", self.watch_from, 1, MAX_HORIZON, expected=expected)
        checks.choice("switch_on", self.switch_on, (*SWITCH_ON, None))
        if self.variant == "paper" and (self.hold not in (None, 1) or self.switch_on not in (None, "true")):
            raise InputError(
                f"hold = {shown(self.hold)}, switch_on = {shown(self.switch_on)}: the paper's variant holds a"
                ' gain set for its sample only and switches on the true error (expected None, 1 and "true")'
            )
        if self.variant == "safe":
            self._check_safe()

    @property
    def hold_periods(self) -> int:
        """Periods an admitted gain set controls from its activation (the paper's variant: 1)."""
        if self.variant != "safe":
            return 1
        return int(max(self.horizon // 2, 1) if self.hold is None else self.hold)

    @property
    def watch_period(self) -> int:
        """The first held period whose seen error may drop the set (``hold_periods``: none)."""
        hold = self.hold_periods
        return hold if self.watch_from is None else min(int(self.watch_from), hold)

    @property
    def measured_switching(self) -> bool:
        """Whether the threshold is tested on the measured tip error (the paper's variant: no)."""
        return self.variant == "safe" and self.switch_on != "true"

    def _check_safe(self) -> None:
        """The safe variant's structure: the fixed ``Kv`` is a multiple of the identity (the
        damping every candidate gets), the fixed ``Kp`` symmetric, the fixed gains seeded and a
        compiled-GA prediction (the admission lives in ``csrc/ga.c``)."""
        Kp, Kv = self.fixed.Kp, self.fixed.Kv
        if not np.array_equal(Kv, Kv[0, 0] * np.eye(len(Kv))) or not Kv[0, 0] > 0:
            raise InputError(
                f"fixed Kv = {shown(Kv.tolist())}: the safe variant expects a positive multiple of the identity"
            )
        if not np.array_equal(Kp, Kp.T):
            raise InputError(f"fixed Kp = {shown(Kp.tolist())}: the safe variant expects a symmetric matrix")
        if not self.seed_fixed_gains:
            raise InputError("seed_fixed_gains = False: the safe variant falls back to the seeded fixed gains")
        if self.prediction == "exact":
            raise InputError('prediction = "exact": the safe variant runs with "linear" or "quadratic"')
        lower, upper = self.bounds()
        fixed = np.concatenate([Kp.ravel(), Kv.ravel()])
        if not np.array_equal(decode(self.initial_bits(), lower, upper, self.ga.n_bits)[0], fixed):
            raise InputError(
                f"stiffness_box = {self.stiffness_box}: the fixed gains are not exactly representable by"
                f" {self.ga.n_bits}-bit genes in [{lower[0]:g}, {upper[0]:g}]; expected a box whose codes hit them"
            )
        if self.ga.stall_generations is not None:
            raise InputError(
                f"ga.stall_generations = {self.ga.stall_generations}: the safe variant runs in the compiled GA,"
                " expected None"
            )

    def admitted_interval(self, dt: float, velocity_filter: float | None) -> tuple[float, float]:
        """The safe variant's interval of admitted eigenvalues of ``Kp`` (1/s^2) for a loop of
        period ``dt`` with velocities filtered by ``velocity_filter`` (``None``: measured)."""
        kv = float(self.fixed.Kv[0, 0])
        return admitted_interval(kv, dt, velocity_filter, self.model_error, self.stability_radius)

    def damping_table(
        self, dt: float, velocity_filter: float | None
    ) -> tuple[float, tuple[float, ...], tuple[float, ...]] | None:
        """The tuned safe variant's damping grid: ``(step, lo, hi)`` (``kv_j = j step``, its interval
        ``[lo[j], hi[j]]``, NaN where none); ``None`` for a held damping."""
        if self.damping != "tuned":
            return None
        kv = float(self.fixed.Kv[0, 0])
        step = kv / DAMPING_STEPS
        count = int(np.floor(self.kv_bounds[1] / step + 1e-9)) + 1
        lo, hi = damping_table(step, count, dt, velocity_filter, self.model_error, self.stability_radius)
        return step, lo, hi

    @classmethod
    def with_gains(
        cls, Kp: ArrayLike, Kv: ArrayLike, n_joints: int = N_JOINTS, **options: object
    ) -> SwitchingControl:
        """Switching control of a robot with ``n_joints`` joints (default the paper's 7) around fixed
        gains from scalars (times the identity), diagonals or matrices; the GA has ``2 n^2`` genes."""
        return cls(Gains.of(Kp, Kv, n_joints), **options)  # type: ignore[arg-type]

    @property
    def gains(self) -> Gains:
        """The fixed gains (used below the threshold)."""
        return self.fixed

    def bounds(self) -> tuple[Array, Array]:
        """Lower and upper bounds of the ``2 n^2`` genes: ``Kp`` row by row, then ``Kv``."""
        nn = self.fixed.Kp.size
        kp_top = self.kp_bounds[1] * (self.stiffness_box if self.variant == "safe" else 1)
        lower = np.concatenate([np.full(nn, self.kp_bounds[0]), np.full(nn, self.kv_bounds[0])])
        upper = np.concatenate([np.full(nn, kp_top), np.full(nn, self.kv_bounds[1])])
        return lower, upper

    @staticmethod
    def split(genes: Array) -> tuple[Array, Array]:
        """Genes ``(P, 2 n^2)`` to ``Kp`` and ``Kv`` ``(P, n, n)``."""
        genes = np.asarray(genes, dtype=float)
        nn = genes.shape[-1] // 2
        n = int(round(nn**0.5))
        shape = genes.shape[:-1] + (n, n)
        return genes[..., :nn].reshape(shape), genes[..., nn:].reshape(shape)

    def initial_bits(self) -> NDArray[np.uint8]:
        """``(k, n_genes * n_bits)`` codes of the individuals that seed the first population."""
        lower, upper = self.bounds()
        if not self.seed_fixed_gains:
            return np.zeros((0, len(lower) * self.ga.n_bits), dtype=np.uint8)
        fixed = np.concatenate([self.fixed.Kp.ravel(), self.fixed.Kv.ravel()])[None, :]
        return encode(fixed, lower, upper, self.ga.n_bits)

    def tune(self, predict: Predictor, rng: np.random.Generator) -> tuple[Gains, GAResult]:
        """Run the GA on the predicted tip error; returns the chosen gains and the GA's record."""
        lower, upper = self.bounds()

        def cost(genes: Array) -> Array:
            Kp, Kv = self.split(genes)
            return predict(Kp, Kv)

        initial = None
        if self.seed_fixed_gains:
            initial = np.concatenate([self.fixed.Kp.ravel(), self.fixed.Kv.ravel()])[None, :]
        result = minimize(cost, lower, upper, options=self.ga, seed=rng, initial=initial)
        Kp, Kv = self.split(result.x)
        return Gains.of(Kp, Kv), result


def dropped_at(seen: ArrayLike, activation: int, hold: int, watch_from: int) -> int | None:
    """The drop rule of a held gain set, written out: the sample where the set activated at sample
    ``activation`` and held ``hold`` periods is dropped for the fixed gains, given the error the
    controller saw at each sample (``seen``, as the threshold is tested on), or ``None`` when it
    controls its whole hold. It is dropped at the first period ``j`` in ``[watch_from, hold)`` whose
    seen error exceeds the one at the activation (``seen[activation + j] > seen[activation]``).
    The compiled loop (``csrc/ga.c``) and the per-activation loop (``engines.py``) decide as this
    function does; the tests hold them to it on recorded runs."""
    errors = np.asarray(seen, dtype=float)
    for j in range(max(watch_from, 1), hold):
        k = activation + j
        if k >= len(errors):
            return None
        if errors[k] > errors[activation]:
            return k
    return None


def predict_tip_error(
    model: Robot,
    dt: float,
    q0: ArrayLike,
    qd0: ArrayLike,
    q_d: ArrayLike,
    qd_d: ArrayLike,
    qdd_d: ArrayLike,
    tip_d: ArrayLike,
    Kp: ArrayLike,
    Kv: ArrayLike,
    actuators: Actuators | None = None,
) -> Array:
    """NumPy reference of the GA's fitness (the compiled ``vgt_ga_fitness_limited`` computes the same).

    ``q0``, ``qd0`` (n,): the state at sample k; ``q_d``, ``qd_d``, ``qdd_d`` (H+1, n) and
    ``tip_d`` (H+1, 3): the reference at samples k .. k+H; ``Kp``, ``Kv`` (P, n, n). Returns the
    predicted tip-error norm of each candidate, (P,); +inf where the prediction leaves the set of
    assemblable configurations (or, absurdly far, the accepted joint range of ``Robot.joint_range``).

    Under its own model computed force control gives ``qdd = qdd_d + Kp e + Kv e_dot``; with
    ``actuators`` its effort ``M a + C`` is first clipped to what they deliver at the predicted
    velocity (:meth:`Actuators.saturate`: the peak forces and the force-speed lines), and the joints
    follow the model's forward dynamics under the clipped effort.
    """
    Kp_a, Kv_a = np.asarray(Kp, dtype=float), np.asarray(Kv, dtype=float)
    refs = [np.asarray(a, dtype=float) for a in (q_d, qd_d, qdd_d, tip_d)]
    n_cand = len(Kp_a)
    q = np.tile(np.asarray(q0, dtype=float), (n_cand, 1))
    qd = np.tile(np.asarray(qd0, dtype=float), (n_cand, 1))
    total = np.zeros(n_cand)
    alive = np.ones(n_cand, dtype=bool)
    for j in range(len(refs[0]) - 1):
        e = refs[0][j] - q
        e_dot = refs[1][j] - qd
        a = commanded_acceleration(refs[2][j], e, e_dot, Kp_a, Kv_a)
        if actuators is not None:
            a = _limited_acceleration(model, actuators, q, qd, a, alive)
        q = q + dt * qd
        qd = qd + dt * a
        finite = np.where(np.isfinite(q), q, 0.0)
        alive &= np.isfinite(q).all(axis=1) & model.is_assemblable(finite) & model.in_joint_range(finite)
        safe = np.where(alive[:, None], q, model.parameters.home)
        total += ((refs[3][j + 1] - model.tip_position(safe)) ** 2).sum(axis=1)
    return np.where(alive, np.sqrt(total), np.inf)


def _limited_acceleration(model: Robot, actuators: Actuators, q: Array, qd: Array, a: Array, alive: Array) -> Array:
    """The model's acceleration under the effort ``M a + C`` of computed force control clipped by
    ``actuators`` at ``qd`` (candidates no longer ``alive`` keep ``a``: their cost is infinite)."""
    out = a.copy()
    if alive.any():
        qa, qda = q[alive], qd[alive]
        F = (model.mass_matrix(qa) @ a[alive][..., None])[..., 0] + model.bias_forces(qa, qda)
        out[alive] = model.forward_dynamics(qa, qda, actuators.saturate(F, qda))
    return out
