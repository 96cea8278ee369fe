"""The simulated closed loop through the exported controller: vgtarm's plant, the export's C.

:class:`CompiledExport` compiles an exported folder (:func:`~.controller.export_controller`) into a
shared library together with ``harness/harness.c``, which includes the simulation's own
``closed_loop.c``: the plant is stepped by the very functions ``vgt_simulate`` uses (tool force,
integrator, divergence checks) while each period's efforts come from ``vgtc_step`` of the export.
:func:`simulate_exported` runs it on a plant and a reference with the options of
:func:`vgtarm.simulation.simulate` and returns the same record, so a test can hold the two runs to
each other sample by sample.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from cffi import FFI

from ..control.cfc import ComputedForceControl
from ..control.scm import SwitchingControl
from ..errors import InputError, SimulationError, shown
from ..fileio import read_text_limited
from ..model import interface
from ..model.closedloop import DONE, ClosedLoopDriver
from ..model.compiled import CompiledBackend, find_compiler
from ..model.robot import Robot
from ..simulation.engines import RawActivation
from ..simulation.reference import HasJointReference
from ..simulation.result import MODE_FIXED, MODE_GA, MODE_NOT_RUN, SimulationResult
from ..simulation.scenario import MODEL_ENGINE, Scenario
from ..simulation.simulator import Outcome, prepare
from .controller import ExportError, run_compiler, sensing_in_use
from .switching import switching_controller

#: Largest ``export.json`` of an export read (bytes): a few kilobytes.
SETTINGS_LIMIT = 2**20


def export_settings(folder: str | os.PathLike[str]) -> dict[str, Any]:
    """The settings of the export in ``folder`` (its ``export.json``), or one line saying why not:
    missing, not a regular file (a named pipe or a device is refused before it is opened), not
    JSON, or not an export's settings (a table with ``n_joints``)."""
    where = f"exported controller {shown(str(folder), 200)}"
    expected = "expected a folder written by vgtarm export controller"
    try:
        text = read_text_limited(Path(folder) / "export.json", SETTINGS_LIMIT, "export settings")
    except InputError as exc:
        raise InputError(f"{where}: no readable export.json ({exc}); {expected}") from None
    try:
        settings = json.loads(text)
    except (ValueError, RecursionError):
        raise InputError(f"{where}: export.json is not JSON; {expected}") from None
    if not isinstance(settings, dict) or not isinstance(settings.get("n_joints"), int):
        raise InputError(f"{where}: export.json holds no export's settings (no n_joints); {expected}")
    return settings


HARNESS = Path(__file__).resolve().parent / "harness" / "harness.c"
MODEL_CSRC = Path(__file__).resolve().parent.parent / "model" / "csrc"
#: The programs of an export (each has its own main): not part of the library.
PROGRAMS = ("replay.c", "rt_loop.c", "ga_timing.c")
#: Flags of the shared library: the compiled model library's (no contraction, no fast math).
LIBRARY_FLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off")

_CDEF = """
typedef struct vgtc_params_opaque vgtc_params;
typedef struct vgtc_context_opaque vgtc_context;
void vgtc_default_params(vgtc_params *params);
int vgtc_init(vgtc_context *ctx, const vgtc_params *params);
int vgtc_step(vgtc_context *ctx, double t, const double *q_meas, const double *qd_meas, const double *ref_row,
              const double *f_meas, double *efforts);
const double *vgtc_effort_estimate(const vgtc_context *ctx);
double vgtc_tip_error(const vgtc_context *ctx);
const char *vgtc_status_text(int status);
size_t vgtc_context_size(void);
size_t vgtc_params_size(void);
int vgtc_harness_run(const vgt_model *m, const vgt_settings *s, const vgt_run *r, vgtc_context *ctx,
                     const double *t, long k0, long k1, long *stop, int *controller_status);
"""
#: The switching harness's declarations (exports written with ``switching``).
_CDEF_SWITCHING = """
typedef struct vgtc_switching_opaque vgtc_switching;
typedef struct vgtc_ga_params_opaque vgtc_ga_params;
typedef struct vgtc_switching_params_opaque vgtc_switching_params;
void vgtc_ga_default_params(vgtc_ga_params *params);
void vgtc_switching_default_params(vgtc_switching_params *params);
int vgtc_switching_init(vgtc_switching *sw, const vgtc_params *control, const vgtc_ga_params *ga,
                        const vgtc_switching_params *params);
size_t vgtc_switching_size(void);
size_t vgtc_ga_params_size(void);
size_t vgtc_switching_params_size(void);
int vgtc_harness_run_switching(const vgt_model *m, const vgt_settings *s, const vgt_run *r, vgtc_switching *sw,
                               const double *t, const double *ref, const uint64_t *seeds, int true_error, long k0,
                               long k1, long *stop, int *controller_status, signed char *mode, long *count,
                               long *sample, long *generations, long *evaluations, double *best_cost,
                               double *seeded_cost, double *wall);
"""


class CompiledExport:
    """An exported folder compiled, with the simulation's harness, into a shared library.

    Attributes:
        folder: the export.
        settings: its ``export.json``.
        n_joints: its joint count.
    """

    def __init__(
        self,
        folder: str | os.PathLike[str],
        *,
        compiler: str | None = None,
        extra_flags: tuple[str, ...] = (),
    ) -> None:
        self.folder = Path(folder).absolute()
        self.settings: dict[str, Any] = export_settings(folder)
        self.n_joints = int(self.settings["n_joints"])
        chosen = compiler or find_compiler()
        if chosen is None:
            raise ExportError("no C compiler found (cc, gcc or clang, or $CC) to compile the exported controller")
        sources = [str(p) for p in sorted(self.folder.glob("*.c")) if p.name not in PROGRAMS]
        scratch = tempfile.mkdtemp(prefix="vgtc-harness-")
        try:
            library = Path(scratch) / "libvgtc_harness.so"
            # the export's folder first: its vgt_control.h is the copy the controller uses
            command = [chosen, *LIBRARY_FLAGS, *extra_flags, "-I", str(self.folder), "-I", str(MODEL_CSRC)]
            command += ["-o", str(library), *sources, str(HARNESS), "-lm"]
            run_compiler(command, "the exported controller with the simulation harness")
            self.ffi = FFI()
            self.ffi.include(interface.ffi())
            self.ffi.cdef(_CDEF)
            if self.settings.get("switching"):
                self.ffi.cdef(_CDEF_SWITCHING)
            self.lib: Any = self.ffi.dlopen(str(library))
        finally:
            shutil.rmtree(scratch, ignore_errors=True)  # the loaded library stays mapped

    def new_context(self) -> Any:
        """A context initialised with the export's own values (``vgtc_default_params``)."""
        owner = self.ffi.new("char[]", int(self.lib.vgtc_params_size()))  # a cast does not keep its owner
        params = self.ffi.cast("vgtc_params *", owner)
        self.lib.vgtc_default_params(params)
        buffer = self.ffi.new("char[]", int(self.lib.vgtc_context_size()))
        context = self.ffi.cast("vgtc_context *", buffer)
        status = self.lib.vgtc_init(context, params)
        if status != 0:
            raise ExportError(f"vgtc_init of {shown(str(self.folder), 200)}: {self._text(status)}")
        self._keep = buffer  # the context lives as long as the last one made
        return context

    def new_switching(self) -> Any:
        """Switching control initialised with the export's own values (controller, GA, threshold)."""
        ffi, lib = self.ffi, self.lib
        owners = [
            ffi.new("char[]", int(size()))
            for size in (lib.vgtc_params_size, lib.vgtc_ga_params_size, lib.vgtc_switching_params_size)
        ]
        control = ffi.cast("vgtc_params *", owners[0])
        ga = ffi.cast("vgtc_ga_params *", owners[1])
        params = ffi.cast("vgtc_switching_params *", owners[2])
        lib.vgtc_default_params(control)
        lib.vgtc_ga_default_params(ga)
        lib.vgtc_switching_default_params(params)
        buffer = ffi.new("char[]", int(lib.vgtc_switching_size()))
        switching = ffi.cast("vgtc_switching *", buffer)
        status = lib.vgtc_switching_init(switching, control, ga, params)
        if status != 0:
            raise ExportError(f"vgtc_switching_init of {shown(str(self.folder), 200)}: {self._text(status)}")
        self._keep = buffer
        return switching

    def _text(self, status: int) -> str:
        return str(self.ffi.string(self.lib.vgtc_status_text(status)).decode())


def _check_agrees(settings: Mapping[str, Any], run: Any, plant: Robot) -> None:
    """Refuse, in one line, a run whose options are not the ones the controller was exported with."""
    sensing, job = run.sensing, run.job
    wanted = {
        "dt_s": job.dt,
        **sensing_in_use(sensing),  # the entries of export.json the controller's arithmetic uses
        "controller_model_fingerprint": job.model.fingerprint,
        "n_joints": plant.n_joints,
    }
    for key, value in wanted.items():
        exported = settings.get(key, "difference" if key == "estimator" else None)  # (exports before the option)
        if exported != value:
            raise InputError(
                f"the exported controller has {key} = {shown(exported)}, the run {shown(value)}: "
                "export it with the run's options"
            )
    if sensing.velocity_noise > 0:
        raise InputError(
            f"velocity_noise = {sensing.velocity_noise!r}: the exported controller is closed without simulated "
            "velocity noise (expected 0)"
        )
    if run.scenario.plant_engine != MODEL_ENGINE:
        raise InputError(f"plant_engine = {run.scenario.plant_engine!r}: expected {MODEL_ENGINE!r}")


def _check_switching(exported: Mapping[str, Any], controller: SwitchingControl) -> None:
    """Refuse, in one line, a switching controller other than the exported one."""
    ga = controller.ga
    wanted = {
        "variant": controller.variant,
        "threshold_m": controller.threshold,
        "horizon": controller.horizon,
        "prediction": controller.prediction,
        "exact_above": controller.exact_above,
        "population": ga.population_size,
        "generations": ga.max_generations,
        "elite": ga.elite_count,
        "hold": controller.hold_periods,
        "switch_on": "measured" if controller.measured_switching else "true",
        "watch_from": int(getattr(controller, "watch_period", controller.hold_periods)),
    }
    for key, value in wanted.items():
        if exported.get(key) != value:
            raise InputError(
                f"the exported switching control has {key} = {shown(exported.get(key))}, the controller"
                f" {shown(value)}: export it with the run's controller"
            )


class _SwitchingOutputs:
    """What ``vgtc_harness_run_switching`` writes for a run of ``n`` samples: each sample's mode
    (0 fixed gains, 1 the GA's, 2 a held set dropped), the activations' records and costs, where the
    run stopped, the controller's refusal and the activations' count; :meth:`pointers` passes them."""

    def __init__(self, ffi: Any, n: int) -> None:
        self.ffi = ffi
        self.mode = np.zeros(n, dtype=np.int8)
        self.records = {name: np.zeros(n, dtype=np.int64) for name in ("sample", "generations", "evaluations")}
        self.costs = {name: np.zeros(n) for name in ("best_cost", "seeded_cost", "wall")}
        self.stop, self.refused, self.count = ffi.new("long *"), ffi.new("int *"), ffi.new("long *")

    def doubles(self, a: np.ndarray) -> Any:
        """``a``'s data as ``double *``."""
        return self.ffi.cast("double *", a.ctypes.data)

    def pointers(self) -> tuple[Any, ...]:
        """The harness's last ten arguments, from ``stop`` to ``wall``."""
        longs = [self.ffi.cast("long *", self.records[name].ctypes.data) for name in self.records]
        costs = [self.doubles(self.costs[name]) for name in self.costs]
        mode = self.ffi.cast("signed char *", self.mode.ctypes.data)
        return (self.stop, self.refused, mode, self.count, *longs, *costs)

    def activations(self) -> tuple[RawActivation, ...]:
        """The GA's activations, in order."""
        records, costs = self.records, self.costs
        return tuple(
            RawActivation(
                sample=int(records["sample"][i]),
                generations=int(records["generations"][i]),
                evaluations=int(records["evaluations"][i]),
                best_cost=float(costs["best_cost"][i]),
                seeded_cost=float(costs["seeded_cost"][i]),
                wall_time_s=float(costs["wall"][i]),
            )
            for i in range(int(self.count[0]))
        )


def _simulate_switching(
    compiled: CompiledExport, plant: Robot, run: Any, metadata: Mapping[str, Any] | None
) -> SimulationResult:
    """The run of :func:`simulate_exported` under the exported switching control."""
    job = run.job
    arrays = job.arrays
    n = int(arrays.n)
    # the GA's seeds: one per sample, drawn as the simulation's loop draws them
    seeds = np.ascontiguousarray(np.asarray(job.ga_rng.integers(0, 2**63, size=n, dtype=np.int64)).view(np.uint64))
    inp = arrays.inputs
    ref = np.ascontiguousarray(np.hstack([inp["q_d"], inp["qd_d"], inp["qdd_d"]]), dtype=np.float64)
    assert isinstance(plant.backend, CompiledBackend)  # checked by simulate_exported
    driver = ClosedLoopDriver(plant.backend)
    loop_settings = job.settings.struct(arrays.n_joints, arrays.n_margins)
    switching = compiled.new_switching()
    t = np.ascontiguousarray(run.reference.t, dtype=np.float64)
    out = _SwitchingOutputs(compiled.ffi, n)
    started = time.perf_counter()
    status = int(
        compiled.lib.vgtc_harness_run_switching(
            driver.model,
            loop_settings,
            arrays.struct,
            switching,
            out.doubles(t),
            out.doubles(ref),
            compiled.ffi.cast("uint64_t *", seeds.ctypes.data),
            int(not job.controller.measured_switching),
            0,
            n,
            *out.pointers(),
        )
    )
    wall = time.perf_counter() - started
    at = int(out.stop[0])
    mode = np.where(out.mode == 1, MODE_GA, MODE_FIXED).astype(np.int8)
    drops = tuple(np.flatnonzero(out.mode == 2).tolist())  # held sets dropped for the fixed gains
    success = status == DONE
    if not success:
        mode[at:] = MODE_NOT_RUN
    # the drops are recorded where the simulator's outcome keeps them (vgtarm with the drop rule)
    kept = {"drops": drops} if "drops" in {f.name for f in dataclasses.fields(Outcome)} else {}
    outcome = Outcome(status, at, success, mode, out.activations(), wall, **kept)
    return _finished(compiled, run, outcome, t, int(out.refused[0]), metadata)


def _simulate_fixed(
    compiled: CompiledExport, plant: Robot, run: Any, metadata: Mapping[str, Any] | None
) -> SimulationResult:
    """The run of :func:`simulate_exported` under the exported computed force control."""
    arrays = run.job.arrays
    assert isinstance(plant.backend, CompiledBackend)  # checked by simulate_exported
    driver = ClosedLoopDriver(plant.backend)
    loop_settings = run.job.settings.struct(arrays.n_joints, arrays.n_margins)
    context = compiled.new_context()
    t = np.ascontiguousarray(run.reference.t, dtype=np.float64)
    ffi = compiled.ffi
    stop, refused = ffi.new("long *"), ffi.new("int *")
    started = time.perf_counter()
    status = int(
        compiled.lib.vgtc_harness_run(
            driver.model,
            loop_settings,
            arrays.struct,
            context,
            ffi.cast("double *", t.ctypes.data),
            0,
            arrays.n,
            stop,
            refused,
        )
    )
    wall = time.perf_counter() - started
    at = int(stop[0])
    mode = np.full(arrays.n, MODE_FIXED, dtype=np.int8)
    success = status == DONE
    if not success:
        mode[at:] = MODE_NOT_RUN
    outcome = Outcome(status, at, success, mode, (), wall)
    return _finished(compiled, run, outcome, t, int(refused[0]), metadata)


def _finished(
    compiled: CompiledExport,
    run: Any,
    outcome: Outcome,
    t: np.ndarray,
    refused: int,
    metadata: Mapping[str, Any] | None,
) -> SimulationResult:
    """The record of a run closed through the export: its message says which sample the controller
    refused (``refused`` < 0: its status); :class:`~vgtarm.errors.SimulationError` with the record
    when the run did not reach its end."""
    extra = {"exported_controller": str(compiled.folder), **dict(metadata or {})}
    result = run.result(outcome, extra)
    if refused < 0:
        at = outcome.stop
        text = compiled._text(refused)
        result = dataclasses.replace(
            result, message=f"the exported controller refused sample {at} (t = {t[min(at, len(t) - 1)]:.4f} s): {text}"
        )
    if not outcome.success:
        raise SimulationError(result.message, result)
    return result


def simulate_exported(
    exported: CompiledExport | str | os.PathLike[str],
    plant: Robot,
    reference: HasJointReference,
    scenario: Scenario | None = None,
    *,
    metadata: Mapping[str, Any] | None = None,
    controller: SwitchingControl | None = None,
    **options: Any,
) -> SimulationResult:
    """Close vgtarm's simulated plant through the exported controller; the record of
    :func:`vgtarm.simulation.simulate` (``options`` are its scenario's).

    The plant is stepped by ``closed_loop.c`` itself; each period, ``vgtc_step`` gets the true
    joints (it rounds them to its encoder steps), the true velocity (with differenced velocities,
    only at the start), the tool force of the previous period (force sensor) and, with the
    scenario's ``tool_force_feedforward``, the expected tool force of the period
    (``vgtc_step_feedforward``, ``vgtc_switching_step_feedforward``). The run's options
    must be those the controller was exported with (dt, observer and gain, sensing, controller
    model; refused in one line otherwise); simulated velocity noise is not supported.

    An export with switching control runs ``vgtc_switching_step`` each period, with the GA's seeds
    that :func:`~vgtarm.simulation.simulate` draws for the same run, so the two runs are the same;
    ``controller`` is the :class:`~vgtarm.control.SwitchingControl` it was exported from (default:
    the one its variant names, around the exported gains), refused unless it agrees with the export.

    Raises:
        SimulationError: the run diverged or the controller refused a step (``.result`` keeps the
            samples up to then); InputError: options that differ from the export's.
    """
    compiled = exported if isinstance(exported, CompiledExport) else CompiledExport(exported)
    if not isinstance(plant, Robot) or not isinstance(plant.backend, CompiledBackend):
        raise InputError(f"plant = {shown(plant)}: expected a vgtarm.Robot with the compiled backend")
    scenario = Scenario.of(scenario, options)
    law = _exported_law(compiled.settings, controller, plant.n_joints)
    run = prepare(plant, reference, law, scenario, metadata)
    _check_agrees(compiled.settings, run, plant)
    if compiled.settings.get("switching"):
        return _simulate_switching(compiled, plant, run, metadata)
    return _simulate_fixed(compiled, plant, run, metadata)


def _exported_law(
    settings: Mapping[str, Any], controller: SwitchingControl | None, n: int
) -> ComputedForceControl | SwitchingControl:
    """The control law of an export's ``settings`` for ``n`` joints: its computed force control, or
    its switching control (``controller``, else the one its variant names around the exported
    gains), refused in one line unless it agrees with the export."""
    switching = settings.get("switching")
    if switching:
        law = switching_controller(
            controller or switching["variant"], np.array(settings["Kp"]), np.array(settings["Kv"]), n
        )
        _check_switching(switching, law)
        return law
    if controller is not None:
        raise InputError("controller: the export has no switching control (export it with switching=...)")
    return ComputedForceControl.with_gains(np.array(settings["Kp"]), np.array(settings["Kv"]), n)
