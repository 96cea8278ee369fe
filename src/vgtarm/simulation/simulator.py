"""Closed-loop simulation: a plant, a controller with its own model, a reference, tool forces.

The plant is the model of :class:`~vgtarm.model.robot.Robot` driven by the actuator efforts and the
external tool force; the controller runs once per control period (the reference's sampling
period) with its own copy of the parameters, so it can be given a wrong model. Integrators:

- ``euler``: explicit Euler at the control period (the paper's choice);
- ``semi_implicit_euler``: velocity first, then position (symplectic, same cost);
- ``rk4``: classical Runge-Kutta with ``substeps`` steps per control period; the efforts and the
  disturbance are held over the period (zero-order hold), the cutting force follows the state.

With a C compiler the whole loop runs in compiled code (``csrc/closed_loop.c``); without one, in
NumPy (:mod:`vgtarm.simulation.python_loop`), with the same results.

The pieces: :class:`~.scenario.Scenario` says what the run is (validated once, stored whole in the
summary); :func:`prepare` checks it against the plant and the reference and builds the loop's
arrays (:class:`Run`); :func:`drive` advances the engine that :func:`~.engines.engine_for` picks,
chunk by chunk, and marks each sample's mode; :meth:`Run.result` turns the activations and the
arrays into the record of the run, in one place for every engine.
"""

from __future__ import annotations

import functools
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from dataclasses import replace as dataclass_replace
from typing import Any, ParamSpec, TypeVar

import numpy as np

from ..control.cfc import ComputedForceControl
from ..control.scm import SwitchingControl
from ..errors import InputError, SimulationError, shown
from ..machine import blas_on_one_thread
from ..memory import check_memory
from ..model.closedloop import (
    ABOVE_THRESHOLD,
    DONE,
    FUNCTION_FAILED,
    NO_MEMORY,
    NOT_ASSEMBLABLE,
    NOT_FINITE,
    OUTSIDE_LIMITS,
    LoopArrays,
    LoopSettings,
)
from ..model.robot import Robot
from . import checks
from .engines import PLANT_ENGINES, Job, RawActivation, check_plant_engine, engine_for, register_plant_engine
from .reference import HasJointReference, JointReference
from .result import MODE_FIXED, MODE_GA, MODE_NOT_RUN, GAActivation, SimulationResult
from .scenario import INTEGRATORS, MAX_SUBSTEPS, Scenario
from .sensing import Sensing, sensing_of

__all__ = [
    "INTEGRATORS",
    "MAX_SUBSTEPS",
    "PLANT_ENGINES",
    "Run",
    "Scenario",
    "drive",
    "loop_arrays",
    "prepare",
    "register_plant_engine",
    "simulate",
]

#: Peak memory of a run per reference sample (bytes), beyond the reference: the loop's arrays and
#: the result's copies (1.2 kB a sample measured with sensing and the observer) with a margin; the
#: switching method adds its tip Jacobians and Hessians along the reference (1.3 kB).
BYTES_PER_SAMPLE = 1_600
BYTES_PER_SAMPLE_SCM = 3_200

_FAILURES = {
    NOT_FINITE: "the state is no longer finite (NaN or infinity)",
    NOT_ASSEMBLABLE: "a leg set can no longer be assembled",
    OUTSIDE_LIMITS: "a joint is far outside its limits",
    FUNCTION_FAILED: "a model function failed",
    NO_MEMORY: "out of memory",
}

#: The ``status`` of a run that stopped, by the loop's status code.
_STATUS_NAMES = {
    NOT_FINITE: "not_finite",
    NOT_ASSEMBLABLE: "not_assemblable",
    OUTSIDE_LIMITS: "outside_limits",
    FUNCTION_FAILED: "function_failed",
    NO_MEMORY: "no_memory",
}

Controller = ComputedForceControl | SwitchingControl
Progress = Callable[[int, int], None]

_P = ParamSpec("_P")
_R = TypeVar("_R")


def _blas_on_one_thread(function: Callable[_P, _R]) -> Callable[_P, _R]:
    """Run ``function`` with NumPy's BLAS (OpenBLAS) limited to one thread (threadpoolctl).

    A run's matrices are tiny, so BLAS threads never help it; but once woken, OpenBLAS's threads
    spin for a while after each call, and on a small machine they take the cores that the compiled
    loop and the GA's threads need: on 2 cores, case 1 under switching control took 58 ms instead
    of 45 (median of 15), and a GA activation could wait for a spinning thread for milliseconds.
    Threads that a NumPy call woke before the run may still spin for a while; the ``vgtarm``
    command therefore also asks for one BLAS thread before NumPy loads
    (:func:`vgtarm._entry.single_threaded_blas`). The loaded libraries are looked up once per
    process (:func:`vgtarm.machine.blas_on_one_thread`), not at every run.
    """

    @functools.wraps(function)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with blas_on_one_thread():
            return function(*args, **kwargs)

    return wrapper


@_blas_on_one_thread
def simulate(
    plant: Robot,
    reference: HasJointReference,
    controller: Controller,
    scenario: Scenario | None = None,
    *,
    metadata: Mapping[str, Any] | None = None,
    progress: Progress | None = None,
    check: bool = True,
    **options: Any,
) -> SimulationResult:
    """Run ``controller`` on ``plant`` along ``reference`` and return the record of the run.

    Args:
        plant: the simulated robot (its parameters are the truth).
        reference: joint reference ``t``, ``q``, ``qd``, ``qdd`` (an IK result works).
        controller: :class:`ComputedForceControl` or :class:`SwitchingControl`.
        scenario: what the run is beside these (:class:`~vgtarm.simulation.Scenario`: the tool
            force, the controller's model, the integrator, the seed, the sensing and estimation, the
            feedforward); or give its fields as keywords (``options``), which build it. Each field,
            its unit, bounds and default are declared once, on :class:`~vgtarm.simulation.Scenario`.
        metadata: extra entries for the summary (case name, ...).
        progress: called as ``progress(samples_done, samples_total)`` now and then.
        check: raise when the run fails (the default); with False, a failed run is returned as it
            is, ``success`` False, its ``status`` and ``message`` saying what stopped it and its
            arrays up to then (as :func:`scipy.integrate.solve_ivp` does).

    Raises:
        SimulationError: the run diverged (with ``check``); ``error.result`` holds the samples up to then.
        InputError: a bad argument (the message names it).
    """
    if not isinstance(check, bool):
        raise InputError(f"check = {shown(check)}: expected True or False")
    scenario = Scenario.of(scenario, options)
    run = prepare(plant, reference, controller, scenario, metadata, progress)
    outcome = drive(run, progress)
    result = run.result(outcome, metadata)
    if check and not result.success:
        raise SimulationError(result.message, result)
    return result


@dataclass(frozen=True)
class Run:
    """A run ready to go: the validated inputs, the resolved sensing and the loop's arrays."""

    plant: Robot
    controller: Controller
    scenario: Scenario
    reference: JointReference
    sensing: Sensing
    tip_d: np.ndarray
    job: Job

    @property
    def n(self) -> int:
        return len(self.reference.t)

    def result(self, outcome: Outcome, metadata: Mapping[str, Any] | None) -> SimulationResult:
        """The record of the run: its arrays blanked where not run, the activations with the errors
        around them, and the summary's entries (the scenario stored whole)."""
        ref, arrays, mode = self.reference, self.job.arrays, outcome.mode
        n = self.n
        activations = tuple(
            GAActivation(
                sample=a.sample,
                time_s=float(ref.t[a.sample]),
                generations=a.generations,
                evaluations=a.evaluations,
                best_fitness=a.best_cost,
                fixed_gains_fitness=a.seeded_cost,
                error_before_m=float(arrays.error[a.sample]),
                error_after_m=float(arrays.error[a.sample + 1]) if a.sample + 1 < n else float("nan"),
                wall_time_s=a.wall_time_s,
            )
            for a in outcome.activations
        )
        if outcome.success:
            message = "completed"
        else:
            at = outcome.stop
            message = (
                f"diverged at t = {ref.t[min(at, n - 1)]:.4f} s (sample {at} of {n}): "
                f"{_FAILURES.get(outcome.status, f'status {outcome.status}')}{_where(self.plant, arrays, at)}"
            )
        return SimulationResult(
            t=ref.t.copy(),
            tip_desired=self.tip_d,
            tip=_blank(arrays.tip, mode),
            tip_error=_blank(arrays.error, mode),
            q_desired=ref.q.copy(),
            qd_desired=ref.qd.copy(),
            q=_blank(arrays.q, mode),
            qd=_blank(arrays.qd, mode),
            effort=_blank(arrays.F, mode),
            f_ext=_blank(arrays.f_ext, mode),
            mode=mode,
            activations=activations,
            success=outcome.success,
            status="completed" if outcome.success else _STATUS_NAMES.get(outcome.status, f"status_{outcome.status}"),
            message=message,
            wall_time_s=outcome.wall_time_s,
            ga_time_s=sum((a.wall_time_s for a in outcome.activations), 0.0),
            metadata={
                **self.metadata(),
                **self._drops(outcome),
                **actuator_figures(self.plant, arrays, mode, ref.dt),
                **dict(metadata or {}),
            },
            effort_estimate=_blank(arrays.tau_hat, mode) if self.sensing.loop_observer != "none" else None,
            tip_error_measured=(
                _measured_tip_error(self.job.model, arrays, self.tip_d, mode) if self.sensing.active else None
            ),
            robot=self.plant,
            reference=ref,
        )

    def _tool_task(self) -> dict[str, Any]:
        """The reference's tool task and entry point (none for the tip alone): the summary says which
        task the run tracked, and the pictures mark the entry point."""
        reference = self.reference
        if reference.task in ("position", ""):
            return {}
        entry = reference.entry_point
        return {"task": reference.task, **({} if entry is None else {"entry_point_m": [float(v) for v in entry]})}

    def _drops(self, outcome: Outcome) -> dict[str, Any]:
        """The safe variant's held gain sets dropped for the fixed gains because the error seen
        rose above its value at their switch (the summary's ``scm_hold_drops``)."""
        controller = self.controller
        if isinstance(controller, SwitchingControl) and controller.variant == "safe":
            return {"scm_hold_drops": len(outcome.drops)}
        return {}

    def metadata(self) -> dict[str, Any]:
        """The summary's entries that describe the run (before the caller's ``metadata``)."""
        plant, controller, scenario, external = self.plant, self.controller, self.scenario, self.scenario.external_force
        info: dict[str, Any] = {
            "controller": controller.name,
            "external_force": external.active,
            "cutting_force": external.cutting,
            "disturbance": external.disturbance,
            "seed": int(scenario.seed),
            "dt_s": self.reference.dt,
            "integrator": scenario.integrator,
            "substeps": scenario.substeps,
            "reference_rates": self.reference.rates,
            "reference": self.reference.name,
            **self._tool_task(),
            "transient_s": scenario.transient_s,
            "controller_model": self.job.model.parameters.name,
            "plant": plant.parameters.name,
            **({"joint_names": list(plant.joint_names)} if plant.is_stack else {}),
            "backend": plant.backend.kind,
            "plant_engine": scenario.plant_engine,
            **self.sensing.metadata(),
        }
        if isinstance(controller, SwitchingControl):
            info.update(
                threshold_m=controller.threshold,
                scm_variant=controller.variant,
                **(
                    {
                        "scm_model_error": controller.model_error,
                        "scm_stability_radius": controller.stability_radius,
                        "scm_hold": controller.hold_periods,
                        "scm_switch_on": "measured" if controller.measured_switching else "true",
                        "scm_watch_from": controller.watch_from,
                    }
                    if controller.variant == "safe"
                    else {}
                ),
                ga_horizon=controller.horizon,
                kp_bounds=list(controller.kp_bounds),
                kv_bounds=list(controller.kv_bounds),
            )
        info["scenario"] = scenario.record()
        return info


def prepare(
    plant: Robot,
    reference: HasJointReference,
    controller: Controller,
    scenario: Scenario,
    metadata: Mapping[str, Any] | None = None,
    progress: Progress | None = None,
) -> Run:
    """Check what a run is given against the plant and build its arrays (nothing runs yet)."""
    checks.arguments(plant, scenario.controller_model, metadata, progress)
    check_plant_engine(scenario.plant_engine)
    if not isinstance(controller, ComputedForceControl | SwitchingControl):
        raise InputError(f"controller = {controller!r}: expected ComputedForceControl or SwitchingControl")
    checks.gains(plant, controller.gains.Kp)
    ref = JointReference.of(reference)
    n, dt = len(ref.t), ref.dt
    per_sample = BYTES_PER_SAMPLE_SCM if isinstance(controller, SwitchingControl) else BYTES_PER_SAMPLE
    check_memory(n * per_sample, f"simulation of {n:,} reference samples", "simulate a shorter reference")
    sensing = _sensing(plant, dt, scenario)
    chosen = scenario.controller_model
    model = chosen if isinstance(chosen, Robot) else plant.with_parameters(chosen or plant.parameters)
    tip_d = checks.reference_tip(plant, ref)  # refuses another robot's reference, naming both
    dist_seed, ga_seed, sensor_seed = np.random.SeedSequence(int(scenario.seed)).spawn(3)
    arrays = _run_arrays(plant, model, ref, scenario, sensing, tip_d, dist_seed, sensor_seed)
    settings = _loop_settings(plant, controller, scenario, sensing, dt)
    _warn_stiff_lines(plant, np.asarray(arrays.q[0]), dt / max(scenario.substeps, 1), scenario.integrator)
    job = Job(
        settings=settings,
        unswitched=dataclass_replace(settings, threshold=0.0),
        arrays=arrays,
        gains=controller.gains,
        controller=controller,
        model=model,
        dt=dt,
        ga_rng=np.random.default_rng(ga_seed),
    )
    return Run(plant, controller, scenario, ref, sensing, tip_d, job)


def _sensing(plant: Robot, dt: float, scenario: Scenario) -> Sensing:
    """What the controller measures and estimates in ``scenario``, at the control period ``dt`` (s)."""
    return sensing_of(plant.joint_units, dt, scenario)


def _run_arrays(
    plant: Robot,
    model: Robot,
    ref: JointReference,
    scenario: Scenario,
    sensing: Sensing,
    tip_d: np.ndarray,
    dist_seed: np.random.SeedSequence,
    sensor_seed: np.random.SeedSequence,
) -> LoopArrays:
    """The loop's arrays: the reference, the disturbance drawn from ``dist_seed``, the initial state,
    the velocity noise drawn from ``sensor_seed`` and the expected tool force fed forward."""
    external = scenario.external_force
    disturbance = external.disturbance_samples(len(ref.t), np.random.default_rng(dist_seed))
    q0, qd0 = checks.initial_state(plant, ref, scenario.initial_state)
    noise = (
        np.random.default_rng(sensor_seed).normal(scale=sensing.velocity_noise, size=ref.q.shape)
        if sensing.velocity_noise > 0
        else None
    )
    expected = None
    if scenario.tool_force_feedforward:  # along the desired tip velocity J_P(q_d) qd_d of the controller's model
        expected = external.expected(model.tip_velocity(ref.q, ref.qd)[0], scenario.feedforward_speed)
    return loop_arrays(
        plant,
        model,
        ref,
        disturbance,
        initial_state=(np.asarray(q0, dtype=float), np.asarray(qd0, dtype=float)),
        tip_d=tip_d,
        resolution=sensing.resolution,
        velocity_noise=noise,
        tool_force_expected=expected,
    )


def _loop_settings(
    plant: Robot, controller: Controller, scenario: Scenario, sensing: Sensing, dt: float
) -> LoopSettings:
    """The settings of the compiled loop (``vgt_settings``) for ``controller`` in ``scenario``."""
    external = scenario.external_force
    return LoopSettings(
        dt=dt,
        integrator=scenario.integrator,
        substeps=scenario.substeps,
        cutting=external.cutting,
        cutting_force=external.cutting_force,
        cutting_speed=external.cutting_speed,
        threshold=controller.threshold if isinstance(controller, SwitchingControl) else 0.0,
        limit_tolerance=checks.limit_tolerance(plant, scenario.limit_tolerance),
        **sensing.loop_fields(),
        threshold_measured=isinstance(controller, SwitchingControl) and controller.measured_switching,
        tool_feedforward=bool(scenario.tool_force_feedforward),
        saturation=plant.actuators is not None,
    )


@dataclass(frozen=True)
class Outcome:
    """How a run ended: the loop's status, the sample where it stopped, each sample's mode, the
    activations in order and the wall time of the loop."""

    status: int
    stop: int
    success: bool
    mode: np.ndarray
    activations: tuple[RawActivation, ...]
    wall_time_s: float
    drops: tuple[int, ...] = ()  # samples where a held gain set was dropped for the fixed gains


def drive(run: Run, progress: Progress | None = None) -> Outcome:
    """Advance the run's engine chunk by chunk (one chunk without ``progress``, else a hundredth
    of the run between two calls of it), marking each sample's mode."""
    n = run.n
    mode = np.full(n, MODE_NOT_RUN, dtype=np.int8)
    found: list[RawActivation] = []
    drops: list[int] = []
    start = time.perf_counter()
    engine = engine_for(run.plant, run.scenario.plant_engine, run.job)
    chunk = max(n // 100, 1) if progress else n
    k, status, stop = 0, DONE, 0
    while k < n:
        k_end = min(k + chunk, n)
        step = engine.advance(k, k_end)
        status, stop = step.status, step.stop
        mode[k:stop] = MODE_FIXED
        for activation in step.activations:
            mode[activation.sample] = MODE_GA
        mode[list(step.held)] = MODE_GA  # a held set's samples: its gains, no GA run
        found.extend(step.activations)
        drops.extend(step.drops)
        if status != DONE:
            break
        k = k_end
        if progress:
            progress(k, n)
    wall = time.perf_counter() - start
    success = status in (DONE, ABOVE_THRESHOLD) and k >= n
    if not success:
        mode[stop:] = MODE_NOT_RUN
    return Outcome(status, stop, success, mode, tuple(found), wall, tuple(drops))


def loop_arrays(
    plant: Robot,
    model: Robot,
    reference: JointReference,
    disturbance: np.ndarray | None = None,
    *,
    initial_state: tuple[np.ndarray, np.ndarray] | None = None,
    tip_d: np.ndarray | None = None,
    resolution: np.ndarray | None = None,
    velocity_noise: np.ndarray | None = None,
    tool_force_expected: np.ndarray | None = None,
) -> LoopArrays:
    """The arrays of one closed-loop run of ``plant`` under a controller with model ``model``.

    ``disturbance`` ``(N, 3)`` defaults to none, the initial state to rest at ``q_d(0)``,
    ``tip_d`` to the plant's tip along the reference; ``resolution`` and ``velocity_noise`` are
    the sensing arrays (none by default); ``tool_force_expected`` ``(N, 3)`` the expected tool force
    the controller feeds forward (zeros by default; used with ``LoopSettings.tool_feedforward``).
    """
    n, n_joints = reference.q.shape
    q0, qd0 = initial_state if initial_state is not None else (reference.q[0], np.zeros(n_joints))
    G, h = plant.margin_form()
    return LoopArrays(
        q_d=reference.q,
        qd_d=reference.qd,
        qdd_d=reference.qdd,
        tip_d=plant.tip_position(reference.q) if tip_d is None else tip_d,
        disturbance=np.zeros((n, 3)) if disturbance is None else disturbance,
        p_plant=plant.parameter_vector,
        p_ctrl=model.parameter_vector,
        G=G,
        h=h,
        lower=plant.parameters.lower,
        upper=plant.parameters.upper,
        q0=q0,
        qd0=qd0,
        resolution=resolution,
        velocity_noise=velocity_noise,
        tool_force_expected=tool_force_expected,
        actuators=plant.actuators,
    )


#: The largest step ratio ``h F_s / (v_max m)`` each integrator takes stably on a force-speed line
#: (the stability limit of a damping ``-k v / m`` on the real axis: 2 for both Euler steps, about
#: 2.785 for RK4).
STABLE_STEP = {"euler": 2.0, "semi_implicit_euler": 2.0, "rk4": 2.785}


def _warn_stiff_lines(plant: Robot, q0: np.ndarray, h: float, integrator: str) -> None:
    """Warn when the actuators' force-speed lines are too stiff for the integration step: their
    back-EMF is a damping ``K = diag(F_s / v_max)`` on the joints, whose fastest mode decays at the
    largest eigenvalue ``lambda`` of ``M^-1 K``; an explicit step with ``h lambda`` beyond the
    integrator's limit chatters (the run is then a numerical artefact: more substeps fix it)."""
    actuators = plant.actuators
    if actuators is None or not actuators.force_speed.any():
        return
    with np.errstate(invalid="ignore", divide="ignore"):
        damping = np.where(actuators.force_speed, actuators.force / actuators.speed, 0.0)
    rates = np.linalg.eigvals(np.linalg.solve(plant.mass_matrix(q0), np.diag(damping))).real
    ratio = h * float(rates.max())
    limit = STABLE_STEP.get(integrator, 2.0)
    if ratio > limit:
        needed = int(np.ceil(ratio / limit * 1.05))
        warnings.warn(
            f"actuators: their force-speed lines (damping F_s / v_max up to {damping.max():.4g} N s/m) are too "
            f"stiff for {integrator} steps of {h:.3g} s: h lambda = {ratio:.3g} > {limit:g}, lambda the fastest "
            f"rate of M^-1 K; the run would chatter; use {needed} times the substeps, or a smaller dt",
            RuntimeWarning,
            stacklevel=4,  # the caller of simulate
        )


def actuator_figures(plant: Robot, arrays: LoopArrays, mode: np.ndarray, dt: float) -> dict[str, Any]:
    """Per joint with an actuator, at each sample: the force it delivers for the controller's effort
    at the joint's velocity (its force-speed line, where it holds); the summary's peak utilisation of
    the limit (at most 1) and the time spent at a limit (s: the samples where the effort asked was at
    or beyond the limit in its direction); none for a robot without actuators."""
    actuators = plant.actuators
    if actuators is None:
        return {}
    run = (mode != MODE_NOT_RUN) & np.isfinite(arrays.F).all(axis=1) & np.isfinite(arrays.qd).all(axis=1)
    F, v = arrays.F[run], arrays.qd[run]
    lower, upper = actuators.bounds(v)
    delivered = np.minimum(np.maximum(F, lower), upper)
    utilisation = actuators.utilisation(delivered, v)
    at_limit = ((F >= upper) | (F <= lower)) & actuators.limited
    names = [name for name, limited in zip(plant.joint_names, actuators.limited, strict=True) if limited]
    index = np.flatnonzero(actuators.limited)
    return {
        "actuator_peak_utilisation": {
            name: float(utilisation[:, i].max()) if len(F) else None for name, i in zip(names, index, strict=True)
        },
        "actuator_time_at_limit_s": {
            name: float(np.count_nonzero(at_limit[:, i]) * dt) for name, i in zip(names, index, strict=True)
        },
    }


def _blank(values: np.ndarray, mode: np.ndarray) -> np.ndarray:
    out = values.copy()
    out[mode == MODE_NOT_RUN] = np.nan
    return out


def _measured_tip_error(model: Robot, arrays: LoopArrays, tip_d: np.ndarray, mode: np.ndarray) -> np.ndarray:
    """The tip error the controller saw, ``|P(q_d) - P(q_meas)|`` (m), NaN where not run."""
    out = np.full(arrays.n, np.nan)
    run = (mode != MODE_NOT_RUN) & np.isfinite(arrays.q_meas).all(axis=1)
    if run.any():
        out[run] = np.linalg.norm(tip_d[run] - model.tip_position(arrays.q_meas[run]), axis=1)
    return out


def _where(plant: Robot, arrays: LoopArrays, k: int) -> str:
    q = arrays.q[min(k, arrays.n - 1)]
    if not np.isfinite(q).all():
        return ""
    lower, upper = plant.parameters.lower, plant.parameters.upper
    names = plant.joint_names
    outside = [f"{names[i]} = {q[i]:.4g}" for i in range(len(q)) if not lower[i] <= q[i] <= upper[i]]
    return f" ({', '.join(outside)})" if outside else ""
