"""Closed-loop simulation: a plant, a controller with its own model, a reference, tool forces.

The plant is the model of :class:`~vgtarm.robot.Robot` driven by the actuator efforts and the
external tool force; the controller runs once per control period (the reference's sampling
period) with its own copy of the parameters, so it can be given a wrong model. Integrators:

- ``euler``: explicit Euler at the control period (the paper's choice);
- ``semi_implicit_euler``: velocity first, then position (symplectic, same cost);
- ``rk4``: classical Runge-Kutta with ``substeps`` steps per control period; the efforts and the
  disturbance are held over the period (zero-order hold), the cutting force follows the state.

With a C compiler the whole loop runs in compiled code (``csrc/closed_loop.c``); without one, in
NumPy (:mod:`vgtarm.simulation.python_loop`), with the same results.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any, ParamSpec, TypeVar

import numpy as np
from threadpoolctl import threadpool_limits

from ..control.cfc import ComputedForceControl
from ..control.gains import Gains
from ..control.scm import SwitchingControl
from ..errors import InputError, SimulationError, shown
from ..memory import check_memory
from ..model.closedloop import (
    ABOVE_THRESHOLD,
    DONE,
    FUNCTION_FAILED,
    NO_MEMORY,
    NOT_ASSEMBLABLE,
    NOT_FINITE,
    OUTSIDE_LIMITS,
    ClosedLoopDriver,
    CompiledGA,
    LoopArrays,
    LoopSettings,
)
from ..model.compiled import CompiledBackend
from ..model.parameters import RobotParameters
from ..model.robot import Robot
from ..model.stack import Stack
from . import checks
from .external import ExternalForce
from .python_loop import PythonLoop
from .reference import HasJointReference, JointReference
from .result import MODE_FIXED, MODE_GA, MODE_NOT_RUN, GAActivation, SimulationResult
from .sensing import DEFAULT_VELOCITY_FILTER_HZ, sensing_settings

#: Plants other than our own model, by name: ``factory(plant, controller_model)`` returns a loop
#: with the interface of :class:`PythonLoop`. Packages above this layer register themselves
#: (``import vgtarm.mujoco_bridge`` adds ``"mujoco"``), so the simulator never imports them.
PLANT_ENGINES: dict[str, Callable[[Robot, Robot], PythonLoop]] = {}


def register_plant_engine(name: str, factory: Callable[[Robot, Robot], PythonLoop]) -> None:
    """Make ``simulate(..., plant_engine=name)`` run its loop on the plant ``factory`` builds."""
    if not isinstance(name, str) or not name or name == "model":
        raise InputError(f"plant engine name {name!r}: expected a name other than 'model'")
    PLANT_ENGINES[name] = factory

#: Integrators by name.
INTEGRATORS: dict[str, str] = {
    "euler": "explicit Euler at the control period (the paper's)",
    "semi_implicit_euler": "semi-implicit (symplectic) Euler at the control period",
    "rk4": "classical Runge-Kutta, `substeps` steps per control period",
}

#: Most integration steps per control period: a step of dt / 1e6 (1 ns at the paper's 1 ms) is
#: far below any time scale of the robot; more only add round-off and hours of work.
MAX_SUBSTEPS = 1_000_000
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

Controller = ComputedForceControl | SwitchingControl
Progress = Callable[[int, int], None]


#: Whether the compiled GA runs inside the compiled loop (one call per chunk) rather than one call
#: per activation from Python; both give the same run bit for bit (a test compares them).
GA_IN_LOOP = True

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
    (:func:`vgtarm._entry.single_threaded_blas`).
    """

    @functools.wraps(function)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with threadpool_limits(limits=1, user_api="blas"):
            return function(*args, **kwargs)

    return wrapper


@_blas_on_one_thread
def simulate(
    plant: Robot,
    reference: HasJointReference,
    controller: Controller,
    *,
    controller_model: RobotParameters | Stack | Robot | None = None,
    external_force: ExternalForce | None = None,
    integrator: str = "euler",
    substeps: int = 1,
    seed: int = 0,
    initial_state: tuple[np.ndarray, np.ndarray] | None = None,
    limit_tolerance: float = 0.05,
    observer: str = "none",
    observer_gain: float | None = None,
    force_sensor: bool = False,
    encoder_resolution: float = 0.0,
    twist_resolution: float | None = None,
    velocity_noise: float = 0.0,
    velocity_filter_hz: float = DEFAULT_VELOCITY_FILTER_HZ,
    plant_engine: str = "model",
    transient_s: float = 0.2,
    metadata: Mapping[str, Any] | None = None,
    progress: Progress | None = None,
) -> SimulationResult:
    """Run ``controller`` on ``plant`` along ``reference`` and return the record of the run.

    Args:
        plant: the simulated robot (its parameters are the truth).
        reference: joint reference ``t``, ``q``, ``qd``, ``qdd`` (an IK result works).
        controller: :class:`ComputedForceControl` or :class:`SwitchingControl`.
        controller_model: the controller's parameters (default: the plant's, an exact model).
        external_force: tool force (default: none).
        integrator: a name of :data:`INTEGRATORS`; ``substeps`` integration steps per period.
        seed: seeds the disturbance and the genetic algorithm; the same seed gives the same run.
        initial_state: ``(q0, qd0)``; default: at rest at ``q_d(0)`` (the paper's start).
        limit_tolerance: distance (m, rad) outside a joint limit at which the run is stopped.
        plant_engine: ``"model"`` (our equations: the compiled loop or its NumPy twin) or a
            registered engine, such as ``"mujoco"`` after ``import vgtarm.mujoco_bridge``: the
            exported MJCF model stepped by MuJoCo (``vgtarm[mujoco]``).
        observer: ``"none"`` or ``"momentum"``: computed force control subtracts the estimate of a
            generalised-momentum disturbance observer with gain ``observer_gain`` (K_O, 1/s,
            default 0.5/dt; the estimate follows the external efforts as ``1 - exp(-K_O t)``; at
            most 1/dt; refused without the observer).
        force_sensor: instead, feed the tool force measured one period late forward through
            ``J_P^T`` (exclusive with ``observer``).
        encoder_resolution: encoder step of the legs (m); with it, or with ``velocity_noise``,
            the controller sees quantised joints and velocities from their differences, filtered
            at ``velocity_filter_hz`` (first order, default 100 Hz; the observer takes the
            unfiltered differences) with Gaussian noise of ``velocity_noise`` (m/s, rad/s) on each
            difference, seeded from ``seed``. ``twist_resolution`` (rad) defaults to a 20-bit
            encoder (2 pi / 2^20) when encoders are on.
        transient_s: length of the start transient excluded from the "after transient" figures.
        metadata: extra entries for the summary (case name, ...).
        progress: called as ``progress(samples_done, samples_total)`` now and then.

    Raises:
        SimulationError: the run diverged; ``error.result`` holds the samples up to then.
        InputError: a bad argument (the message names it).
    """
    checks.arguments(
        plant, controller_model, external_force, integrator, plant_engine, metadata, progress, transient_s
    )
    if plant_engine != "model" and plant_engine not in PLANT_ENGINES:
        raise InputError(
            f"plant_engine = {plant_engine!r}: expected 'model' or a registered engine {sorted(PLANT_ENGINES)}"
            " (the MuJoCo plant registers with `import vgtarm.mujoco_bridge`, pip install 'vgtarm[mujoco]')"
        )
    if integrator not in INTEGRATORS:
        raise InputError(f"integrator = {integrator!r}: expected one of {sorted(INTEGRATORS)}")
    if not (isinstance(substeps, int) and 1 <= substeps <= MAX_SUBSTEPS):
        raise InputError(f"substeps = {shown(substeps)}: expected a whole number from 1 to {MAX_SUBSTEPS:,}")
    if not isinstance(controller, ComputedForceControl | SwitchingControl):
        raise InputError(f"controller = {controller!r}: expected ComputedForceControl or SwitchingControl")
    checks.gains(plant, controller.gains.Kp)
    if not (isinstance(seed, int | np.integer) and seed >= 0):
        raise InputError(f"seed = {seed!r}: expected a whole number >= 0")
    ref = JointReference.of(reference)
    n, dt = len(ref.t), ref.dt
    per_sample = BYTES_PER_SAMPLE_SCM if isinstance(controller, SwitchingControl) else BYTES_PER_SAMPLE
    check_memory(n * per_sample, f"simulation of {n:,} reference samples", "simulate a shorter reference")
    sensing = sensing_settings(
        plant.joint_units,
        dt,
        observer,
        observer_gain,
        force_sensor,
        encoder_resolution,
        twist_resolution,
        velocity_noise,
        velocity_filter_hz,
    )
    external = external_force or ExternalForce.none()
    if isinstance(controller_model, Robot):
        model = controller_model
    else:
        model = plant.with_parameters(controller_model or plant.parameters)
    tip_d = checks.reference_tip(plant, ref)  # refuses another robot's reference, naming both
    dist_seed, ga_seed, sensor_seed = np.random.SeedSequence(int(seed)).spawn(3)
    disturbance = external.disturbance_samples(n, np.random.default_rng(dist_seed))
    ga_rng = np.random.default_rng(ga_seed)
    q0, qd0 = checks.initial_state(plant, ref, initial_state)
    noise = (
        np.random.default_rng(sensor_seed).normal(scale=sensing.velocity_noise, size=ref.q.shape)
        if sensing.velocity_noise > 0
        else None
    )
    arrays = loop_arrays(
        plant,
        model,
        ref,
        disturbance,
        initial_state=(np.asarray(q0, dtype=float), np.asarray(qd0, dtype=float)),
        tip_d=tip_d,
        resolution=sensing.resolution,
        velocity_noise=noise,
    )
    loop: ClosedLoopDriver | PythonLoop
    if plant_engine != "model":
        loop = PLANT_ENGINES[plant_engine](plant, model)
    elif isinstance(plant.backend, CompiledBackend) and isinstance(model.backend, CompiledBackend):
        loop = ClosedLoopDriver(plant.backend)
    else:
        loop = PythonLoop(plant, model)
    settings = LoopSettings(
        dt=dt,
        integrator=integrator,
        substeps=substeps,
        cutting=external.cutting,
        cutting_force=external.cutting_force,
        cutting_speed=external.cutting_speed,
        threshold=controller.threshold if isinstance(controller, SwitchingControl) else 0.0,
        limit_tolerance=checks.limit_tolerance(plant, limit_tolerance),
        observer=sensing.loop_observer,
        observer_gain=sensing.observer_gain,
        sensing=sensing.active,
        velocity_filter=sensing.velocity_filter,
    )
    mode = np.full(n, MODE_NOT_RUN, dtype=np.int8)
    activations: list[GAActivation] = []
    fixed = controller.gains
    unswitched = LoopSettings(**{**settings.__dict__, "threshold": 0.0})
    start = time.perf_counter()
    ga_time = 0.0
    compiled_ga: dict[str, CompiledGA] = {}
    k = 0
    status = DONE
    chunk = max(n // 100, 1) if progress else n
    # the compiled GA runs inside the compiled loop: one call per chunk, whatever the activations
    ga_in_loop = (
        GA_IN_LOOP
        and isinstance(controller, SwitchingControl)
        and isinstance(loop, ClosedLoopDriver)
        and controller.ga.stall_generations is None
    )
    switching_loop = loop if isinstance(loop, ClosedLoopDriver) else None
    if ga_in_loop:
        assert isinstance(controller, SwitchingControl) and switching_loop is not None
        ga = compiled_ga["ga"] = _compiled_ga(controller, switching_loop, model, arrays, dt)
        # one seed per activation, drawn as _tune draws them one by one (same numbers)
        ga.bind_switching(ga_rng.integers(0, 2**63, size=n, dtype=np.int64))
    while k < n and ga_in_loop:
        k_end = min(k + chunk, n)
        first = int(ga.switching.count)
        assert switching_loop is not None
        status, stop = switching_loop.simulate_switching(settings, unswitched, arrays, fixed.Kp, fixed.Kv, ga, k, k_end)
        assert status != ABOVE_THRESHOLD  # the records hold one activation per sample
        mode[k : k_end if status == DONE else stop] = MODE_FIXED
        records = ga.records(first, int(ga.switching.count))
        for i, sample in enumerate(records["sample"].tolist()):
            mode[sample] = MODE_GA
            ga_time += float(records["wall_time"][i])
            activations.append(
                GAActivation(
                    sample=sample,
                    time_s=float(ref.t[sample]),
                    generations=int(records["generations"][i]),
                    evaluations=int(records["evaluations"][i]),
                    best_fitness=float(records["best_cost"][i]),
                    fixed_gains_fitness=float(records["seeded_cost"][i]),
                    error_before_m=float(arrays.error[sample]),
                    error_after_m=float("nan"),  # filled below
                    wall_time_s=float(records["wall_time"][i]),
                )
            )
        if status != DONE:
            break
        k = k_end
        if progress:
            progress(k, n)
    while k < n and not ga_in_loop:
        k_end = min(k + chunk, n)
        status, stop = loop.simulate(settings, arrays, fixed.Kp, fixed.Kv, k, k_end)
        mode[k:stop] = MODE_FIXED
        if status == DONE:
            k = k_end
            if progress:
                progress(k, n)
            continue
        if status != ABOVE_THRESHOLD:
            break
        assert isinstance(controller, SwitchingControl)
        k = stop
        ga_start = time.perf_counter()
        gains, activation = _tune(controller, loop, model, arrays, k, dt, ga_rng, compiled_ga)
        sample = k
        status, stop = loop.simulate(unswitched, arrays, gains.Kp, gains.Kv, k, k + 1)
        mode[k] = MODE_GA
        k += 1
        elapsed = time.perf_counter() - ga_start
        ga_time += elapsed
        activations.append(
            GAActivation(
                sample=sample,
                time_s=float(ref.t[sample]),
                generations=activation[0],
                evaluations=activation[1],
                best_fitness=activation[2],
                fixed_gains_fitness=activation[3],
                error_before_m=float(arrays.error[sample]),
                error_after_m=float("nan"),  # the loop measures it at the next sample (filled below)
                wall_time_s=elapsed,
            )
        )
        if status != DONE:
            break
    wall = time.perf_counter() - start
    activations = [
        replace(a, error_after_m=float(arrays.error[a.sample + 1])) if a.sample + 1 < n else a for a in activations
    ]
    success = status in (DONE, ABOVE_THRESHOLD) and k >= n
    if success:
        message = "completed"
    else:
        failed_at = stop
        message = (
            f"diverged at t = {ref.t[min(failed_at, n - 1)]:.4f} s (sample {failed_at} of {n}): "
            f"{_FAILURES.get(status, f'status {status}')}{_where(plant, arrays, failed_at)}"
        )
        mode[failed_at:] = MODE_NOT_RUN
    info: dict[str, Any] = {
        "controller": controller.name,
        "external_force": external.active,
        "cutting_force": external.cutting,
        "disturbance": external.disturbance,
        "seed": int(seed),
        "dt_s": dt,
        "integrator": integrator,
        "substeps": substeps,
        "reference_rates": ref.rates,
        "transient_s": transient_s,
        "controller_model": model.parameters.name,
        "plant": plant.parameters.name,
        **({"joint_names": list(plant.joint_names)} if plant.is_stack else {}),
        "backend": plant.backend.kind,
        "plant_engine": plant_engine,
        **sensing.metadata(),
    }
    if isinstance(controller, SwitchingControl):
        info.update(
            threshold_m=controller.threshold,
            ga_horizon=controller.horizon,
            kp_bounds=list(controller.kp_bounds),
            kv_bounds=list(controller.kv_bounds),
        )
    info.update(dict(metadata or {}))
    result = SimulationResult(
        t=ref.t.copy(),
        tip_desired=tip_d,
        tip=_blank(arrays.tip, mode),
        tip_error=_blank(arrays.error, mode),
        q_desired=ref.q.copy(),
        qd_desired=ref.qd.copy(),
        q=_blank(arrays.q, mode),
        qd=_blank(arrays.qd, mode),
        effort=_blank(arrays.F, mode),
        f_ext=_blank(arrays.f_ext, mode),
        mode=mode,
        activations=tuple(activations),
        success=success,
        message=message,
        wall_time_s=wall,
        ga_time_s=ga_time,
        metadata=info,
        effort_estimate=_blank(arrays.tau_hat, mode) if sensing.loop_observer != "none" else None,
        tip_error_measured=_measured_tip_error(model, arrays, tip_d, mode) if sensing.active else None,
    )
    if not success:
        raise SimulationError(message, result)
    return result


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
) -> LoopArrays:
    """The arrays of one closed-loop run of ``plant`` under a controller with model ``model``.

    ``disturbance`` ``(N, 3)`` defaults to none, the initial state to rest at ``q_d(0)``,
    ``tip_d`` to the plant's tip along the reference; ``resolution`` and ``velocity_noise`` are
    the sensing arrays (none by default).
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
        q_min=plant.parameters.lower,
        q_max=plant.parameters.upper,
        q0=q0,
        qd0=qd0,
        resolution=resolution,
        velocity_noise=velocity_noise,
    )


def _tune(
    controller: SwitchingControl,
    loop: ClosedLoopDriver | PythonLoop,
    model: Robot,
    arrays: LoopArrays,
    k: int,
    dt: float,
    rng: np.random.Generator,
    compiled: dict[str, CompiledGA],
) -> tuple[Any, tuple[int, int, float, float]]:
    """Run the GA at sample ``k``; returns the gains and (generations, evaluations, best, fixed).

    With the compiled loop the whole activation runs in C (``csrc/ga.c``, bound once per run in
    ``compiled``); otherwise the NumPy GA (:func:`vgtarm.ga.minimize`) runs on the NumPy
    prediction. Each activation draws one 64-bit seed from ``rng``, so a seed gives the same run.
    """
    end = min(k + controller.horizon, arrays.n - 1)
    if end == k:  # the last sample: nothing left to predict, keep the fixed gains
        return controller.gains, (0, 0, 0.0, 0.0)
    if isinstance(loop, ClosedLoopDriver) and controller.ga.stall_generations is None:
        if "ga" not in compiled:
            compiled["ga"] = _compiled_ga(controller, loop, model, arrays, dt)
        seed = int(rng.integers(0, 2**63, dtype=np.int64))
        out = compiled["ga"].activate(k, arrays.q_meas[k], arrays.qd_meas[k], seed)
        Kp, Kv = controller.split(out.genes)
        return Gains.of(Kp, Kv), (out.generations, out.evaluations, out.best_cost, out.seeded_cost)
    window = slice(k, end + 1)
    inp = arrays.inputs

    predict = loop.ga_predictor(
        model.parameter_vector,
        dt,
        arrays.q_meas[k],
        arrays.qd_meas[k],
        inp["q_d"][window],
        inp["qd_d"][window],
        inp["qdd_d"][window],
        inp["tip_d"][window],
    )
    fixed_fitness = float(predict(controller.gains.Kp[None], controller.gains.Kv[None])[0])
    gains, result = controller.tune(predict, rng)
    return gains, (result.generations, result.n_evaluations, float(result.cost), fixed_fitness)


def _compiled_ga(
    controller: SwitchingControl, loop: ClosedLoopDriver, model: Robot, arrays: LoopArrays, dt: float
) -> CompiledGA:
    """The compiled GA of one run: the reference and the model's tip derivatives along it."""
    inp = arrays.inputs
    q_d = inp["q_d"]
    lower, upper = controller.bounds()
    options = controller.ga
    quadratic = controller.prediction == "quadratic"
    return CompiledGA(
        loop,
        dt=dt,
        lower=lower,
        upper=upper,
        initial_bits=controller.initial_bits(),
        n_bits=options.n_bits,
        population=options.population_size,
        generations=options.max_generations,
        elite=options.elite_count,
        p_crossover=options.crossover_probability,
        p_mutation=options.mutation_probability,
        horizon=controller.horizon,
        prediction=controller.prediction,
        exact_above=controller.exact_above,
        p_ctrl=model.parameter_vector,
        q_d=q_d,
        qd_d=inp["qd_d"],
        qdd_d=inp["qdd_d"],
        tip_d=inp["tip_d"],
        quadratic=quadratic,
    )


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
