"""The loops that advance a run, one small class per engine behind one interface.

Every engine answers :meth:`Engine.advance`: run the samples ``k .. k_end - 1`` (or until the run
fails) and say how it ended and which GA activations it made on the way. The simulator calls it
chunk by chunk and does all the bookkeeping once (:mod:`.activations`); an engine only steps.

- :class:`CompiledLoop`: our equations in the compiled loop (``csrc/closed_loop.c``), at fixed
  gains; under switching control the loop stops where the tip error crosses the threshold, the
  GA tunes the gains from Python (one compiled activation, or the NumPy GA for options the
  compiled one lacks) and the loop runs that sample with them.
- :class:`CompiledSwitchingLoop`: the same loop with the compiled GA inside it, one call per
  chunk whatever the activations (the default for switching control with a compiler).
- :class:`NumpyLoop`: our equations in NumPy (:mod:`.python_loop`), without a compiler.
- :class:`RegisteredLoop`: a plant other than our equations, registered by name
  (``import vgtarm.mujoco_bridge`` registers ``"mujoco"``); it steps like :class:`NumpyLoop`.

All of them give the same run bit for bit where their arithmetic is the same (tested).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from ..control.gains import Gains
from ..control.scm import SwitchingControl
from ..errors import InputError
from ..model.closedloop import ABOVE_THRESHOLD, DONE, ClosedLoopDriver, CompiledGA, LoopArrays, LoopSettings
from ..model.compiled import CompiledBackend
from ..model.robot import Robot
from .python_loop import PythonLoop
from .scenario import MODEL_ENGINE

#: Plants other than our own model, by name: ``factory(plant, controller_model)`` returns a loop
#: with the interface of :class:`PythonLoop`. Packages above this layer register themselves
#: (``import vgtarm.mujoco_bridge`` adds ``"mujoco"``), so the simulator never imports them.
PLANT_ENGINES: dict[str, Callable[[Robot, Robot], PythonLoop]] = {}


def register_plant_engine(name: str, factory: Callable[[Robot, Robot], PythonLoop]) -> None:
    """Make ``simulate(..., plant_engine=name)`` run its loop on the plant ``factory`` builds."""
    if not isinstance(name, str) or not name or name == MODEL_ENGINE:
        raise InputError(f"plant engine name {name!r}: expected a name other than {MODEL_ENGINE!r}")
    PLANT_ENGINES[name] = factory


def check_plant_engine(name: str) -> None:
    """Refuse, in one line, a plant engine that is neither ours nor registered."""
    if name != MODEL_ENGINE and name not in PLANT_ENGINES:
        raise InputError(
            f"plant_engine = {name!r}: expected {MODEL_ENGINE!r} or a registered engine {sorted(PLANT_ENGINES)}"
            " (the MuJoCo plant registers with `import vgtarm.mujoco_bridge`, pip install 'vgtarm[mujoco]')"
        )


#: Whether the compiled GA runs inside the compiled loop (one call per chunk) rather than one call
#: per activation from Python; both give the same run bit for bit (a test compares them).
GA_IN_LOOP = True


@dataclass(frozen=True)
class RawActivation:
    """One GA activation as an engine reports it (the simulator adds the errors around it)."""

    sample: int
    generations: int
    evaluations: int
    best_cost: float
    seeded_cost: float
    wall_time_s: float


@dataclass(frozen=True)
class Advance:
    """How :meth:`Engine.advance` ended: the loop's status code, the sample where it stopped
    (``k_end`` when done), and the activations made on the way, in order."""

    status: int
    stop: int
    activations: tuple[RawActivation, ...] = ()
    held: tuple[int, ...] = ()  # samples controlled by a held gain set (safe variant), no GA run
    drops: tuple[int, ...] = ()  # samples where a held set was dropped for the fixed gains (its error rose)


@dataclass(frozen=True)
class Job:
    """What every engine steps on: the validated loop settings (``unswitched``: the same with the
    threshold off, for the sample run with tuned gains), the run's arrays, the fixed gains, the
    controller and its model, the control period and the generator of the GA's seeds."""

    settings: LoopSettings
    unswitched: LoopSettings
    arrays: LoopArrays
    gains: Gains
    controller: Any
    model: Robot
    dt: float
    ga_rng: np.random.Generator


class Engine(Protocol):
    """The one interface of the loops: run samples ``k .. k_end - 1`` or until the run fails."""

    def advance(self, k: int, k_end: int) -> Advance: ...


class _SteppedLoop:
    """An engine over a loop with ``simulate`` and ``ga_predictor`` (:class:`PythonLoop`'s
    interface, which :class:`ClosedLoopDriver` shares): fixed gains until the threshold, then one
    GA activation tuned from Python and one sample with its gains."""

    def __init__(self, loop: ClosedLoopDriver | PythonLoop, job: Job) -> None:
        self.loop = loop
        self.job = job
        self._compiled_ga: CompiledGA | None = None
        self._admitted = False  # the last activation's set was admitted (the safe variant, compiled)
        self._hold_left = 0  # samples the last admitted set still controls (as csrc/ga.c holds it)
        self._held: Gains | None = None
        self._watch: LoopSettings | None = None  # the held set's settings: dropped above the error at its switch

    def advance(self, k: int, k_end: int) -> Advance:
        job = self.job
        found: list[RawActivation] = []
        held: list[int] = []
        drops: list[int] = []

        def made(status: int, stop: int) -> Advance:
            return Advance(status, stop, tuple(found), tuple(held), tuple(drops))

        while True:
            if self._hold_left > 0 and self._held is not None and self._watch is not None:
                end = min(k + self._hold_left, k_end)
                period = job.controller.hold_periods - self._hold_left  # of sample k, from the activation's
                watch = self._watch
                if period < job.controller.watch_period:  # before the gains can act on the error: not watched
                    watch, end = job.unswitched, min(end, k + job.controller.watch_period - period)
                status, after = self.loop.simulate(watch, job.arrays, self._held.Kp, self._held.Kv, k, end)
                done = end if status == DONE else min(after, end)
                held.extend(range(k, done))
                self._hold_left -= end - k
                if status == ABOVE_THRESHOLD:  # the seen error rose above its value at the switch
                    self._hold_left, self._held, self._watch = 0, None, None
                    drops.append(after)
                    status, stop = self.loop.simulate(
                        job.unswitched, job.arrays, job.gains.Kp, job.gains.Kv, after, after + 1
                    )
                    if status != DONE:
                        return made(status, stop)
                    k = after + 1
                    if k >= k_end:
                        return made(DONE, k_end)
                    continue
                if status != DONE:
                    return made(status, after)
                k = end
                if k >= k_end:
                    return made(DONE, k_end)
                continue
            status, stop = self.loop.simulate(job.settings, job.arrays, job.gains.Kp, job.gains.Kv, k, k_end)
            if status != ABOVE_THRESHOLD:
                return made(status, k_end if status == DONE else stop)
            started = time.perf_counter()
            self._admitted = False
            gains, activation = self._tune(stop)
            status, after = self.loop.simulate(job.unswitched, job.arrays, gains.Kp, gains.Kv, stop, stop + 1)
            found.append(RawActivation(stop, *activation, time.perf_counter() - started))
            if self._admitted and job.controller.hold_periods > 1:
                self._hold_left, self._held = job.controller.hold_periods - 1, gains
                # held while the error seen stays at or below the one seen at this switch
                self._watch = replace(job.unswitched, threshold=float(job.arrays.seen[stop]))
            if status != DONE:
                return made(status, after)
            k = stop + 1
            if k >= k_end:
                return made(DONE, k_end)

    def _tune(self, k: int) -> tuple[Gains, tuple[int, int, float, float]]:
        """Run the GA at sample ``k``; returns the gains and (generations, evaluations, best, fixed).

        With the compiled loop the whole activation runs in C (``csrc/ga.c``, bound once per run);
        otherwise the NumPy GA (:func:`vgtarm.ga.minimize`) runs on the NumPy prediction. Each
        activation draws one 64-bit seed from the run's generator, so a seed gives the same run.
        """
        job = self.job
        controller: SwitchingControl = job.controller
        arrays = job.arrays
        end = min(k + controller.horizon, arrays.n - 1)
        if end == k:  # the last sample: nothing left to predict, keep the fixed gains
            return controller.gains, (0, 0, 0.0, 0.0)
        if isinstance(self.loop, ClosedLoopDriver) and controller.ga.stall_generations is None:
            if self._compiled_ga is None:
                self._compiled_ga = compiled_ga(controller, self.loop, job.model, arrays, job.dt, job.settings)
            seed = int(job.ga_rng.integers(0, 2**63, dtype=np.int64))
            out = self._compiled_ga.activate(k, arrays.q_meas[k], arrays.qd_meas[k], seed)
            self._admitted = controller.variant == "safe" and not out.dropped
            Kp, Kv = controller.split(out.genes)
            return Gains.of(Kp, Kv), (out.generations, out.evaluations, out.best_cost, out.seeded_cost)
        if controller.variant == "safe":
            raise InputError('variant = "safe": switching control\'s safe variant needs the compiled GA (a C compiler)')
        window = slice(k, end + 1)
        inp = arrays.inputs
        predict = self.loop.ga_predictor(
            job.model.parameter_vector,
            job.dt,
            arrays.q_meas[k],
            arrays.qd_meas[k],
            inp["q_d"][window],
            inp["qd_d"][window],
            inp["qdd_d"][window],
            inp["tip_d"][window],
            actuators=_limits(job.settings, inp),
        )
        fixed_fitness = float(predict(controller.gains.Kp[None], controller.gains.Kv[None])[0])
        gains, result = controller.tune(predict, job.ga_rng)
        return gains, (result.generations, result.n_evaluations, float(result.cost), fixed_fitness)


class CompiledLoop(_SteppedLoop):
    """Our equations in the compiled loop; the GA, if any, called from Python per activation."""

    def __init__(self, plant: Robot, job: Job) -> None:
        assert _looped(plant)
        super().__init__(ClosedLoopDriver(plant.backend), job)  # type: ignore[arg-type]


class NumpyLoop(_SteppedLoop):
    """Our equations in NumPy (no compiler), with the NumPy GA."""

    def __init__(self, plant: Robot, job: Job) -> None:
        super().__init__(PythonLoop(plant, job.model), job)


class RegisteredLoop(_SteppedLoop):
    """A registered plant engine (such as MuJoCo), stepped as :class:`NumpyLoop` steps."""

    def __init__(self, name: str, plant: Robot, job: Job) -> None:
        super().__init__(PLANT_ENGINES[name](plant, job.model), job)


class CompiledSwitchingLoop:
    """Our equations in the compiled loop with the compiled GA inside it: one call per chunk."""

    def __init__(self, plant: Robot, job: Job) -> None:
        self.job = job
        assert _looped(plant)
        self.loop = ClosedLoopDriver(plant.backend)  # type: ignore[arg-type]
        self.ga = compiled_ga(job.controller, self.loop, job.model, job.arrays, job.dt, job.settings)
        # one seed per sample, drawn as the stepped loop draws them one by one (the same numbers)
        seeds = np.asarray(job.ga_rng.integers(0, 2**63, size=int(job.arrays.n), dtype=np.int64))
        self.ga.bind_switching(seeds, hold=job.controller.hold_periods, watch_from=job.controller.watch_period)

    def advance(self, k: int, k_end: int) -> Advance:
        job = self.job
        first = int(self.ga.switching.count)
        status, stop = self.loop.simulate_switching(
            job.settings, job.unswitched, job.arrays, job.gains.Kp, job.gains.Kv, self.ga, k, k_end
        )
        assert status != ABOVE_THRESHOLD  # the records hold one activation per sample
        records = self.ga.records(first, int(self.ga.switching.count))
        end = k_end if status == DONE else stop
        held = tuple((np.flatnonzero(self.ga.held[k:end] == 1) + k).tolist())
        drops = tuple((np.flatnonzero(self.ga.held[k:end] == 2) + k).tolist())
        found = tuple(
            RawActivation(
                sample=int(sample),
                generations=int(records["generations"][i]),
                evaluations=int(records["evaluations"][i]),
                best_cost=float(records["best_cost"][i]),
                seeded_cost=float(records["seeded_cost"][i]),
                wall_time_s=float(records["wall_time"][i]),
            )
            for i, sample in enumerate(records["sample"].tolist())
        )
        return Advance(status, k_end if status == DONE else stop, found, held, drops)


def _looped(robot: Robot) -> bool:
    """Whether ``robot``'s backend runs the compiled closed loop (a compiled symbolic library, or the
    recursive model's library with its adapters)."""
    return isinstance(robot.backend, CompiledBackend) or bool(getattr(robot.backend, "closed_loop", False))


def engine_for(plant: Robot, plant_engine: str, job: Job) -> Engine:
    """The engine of a run: a registered plant's, else the compiled loop (with the GA inside it
    under switching control) when both models are compiled, else the NumPy loop."""
    if plant_engine != MODEL_ENGINE:
        return RegisteredLoop(plant_engine, plant, job)
    if not (_looped(plant) and _looped(job.model)):
        return NumpyLoop(plant, job)
    switching = isinstance(job.controller, SwitchingControl)
    if switching and GA_IN_LOOP and job.controller.ga.stall_generations is None:
        return CompiledSwitchingLoop(plant, job)
    return CompiledLoop(plant, job)


def _limits(
    settings: LoopSettings | None, inputs: dict[str, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The actuators the GA's prediction clips to: with saturation, the run's own (its controller
    clips to them and its plant delivers through them); ``None`` without."""
    if settings is None or not settings.saturation:
        return None
    return inputs["force_limit"], inputs["speed_limit"], inputs["force_speed"]


def compiled_ga(
    controller: SwitchingControl,
    loop: ClosedLoopDriver,
    model: Robot,
    arrays: LoopArrays,
    dt: float,
    settings: LoopSettings | None = None,
) -> CompiledGA:
    """The compiled GA of one run: the reference and the model's tip derivatives along it. The
    safe variant admits gains on the loop of ``settings`` (its sensing and velocity filter;
    ``None``: perfect sensing)."""
    inp = arrays.inputs
    safe = None
    damping = None
    if controller.variant == "safe":
        sensing = settings is not None and settings.sensing
        lo, hi = controller.admitted_interval(dt, settings.velocity_filter if settings and sensing else None)
        eig = np.linalg.eigvalsh(controller.fixed.Kp)
        if not (lo <= eig[0] and eig[-1] <= hi):
            raise InputError(
                f"fixed Kp eigenvalues [{eig[0]:g}, {eig[-1]:g}]: the safe variant expects them in the admitted"
                f" interval [{lo:g}, {hi:g}] (stability_radius {controller.stability_radius:g})"
            )
        safe = (float(controller.fixed.Kv[0, 0]), lo, hi)
        damping = controller.damping_table(dt, settings.velocity_filter if settings and sensing else None)
    return CompiledGA(
        loop,
        controller,
        dt=dt,
        p_ctrl=model.parameter_vector,
        reference=inp,
        safe=safe,
        damping=damping,
        actuators=_limits(settings, inp),
        # the safe variant's GA runs at about 6 % of the samples (its sets are held): a second thread
        # would save under 0.1 s a run, one stall of it on a busy machine costs 0.1-0.6 s; so one
        # thread unless $VGTARM_THREADS asks (the run is the same bit for bit with any count)
        threads=1 if controller.variant == "safe" and not os.environ.get("VGTARM_THREADS", "").strip() else None,
    )
