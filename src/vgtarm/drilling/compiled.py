"""The compiled drilling loop (``model/csrc/drill_loop.c`` with the controller of
``model/csrc/vgt_drill_control.h``): the NumPy loop of :mod:`.loop` in C, called once per run.

It runs on the symbolic (CasADi) library of the robot, which has every function the loop calls
(tip, velocity, Jacobians, forward kinematics, bias accelerations, mass matrix, bias forces,
inverse dynamics); :func:`available` says whether a robot has it. The controller's arithmetic is
the NumPy loop's step for step, with the linear algebra done by Cholesky factors where NumPy
inverts or takes a least-squares solution, so the two agree to rounding, not bit for bit
(``tests/test_drilling_compiled.py``: exact sensing to 1e-9 of the path; with encoders, where one
rounding can move a reading by a step, on every measure of the summary).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import VgtarmError
from ..model.backends import CompiledBackend
from ..model.interface import enum, ffi
from ..model.robot import Robot
from .bone import CAP_FACTOR
from .control import END_HOLD, STOP_HOLD, DrillingSetup, arm_depth

Array = NDArray[np.float64]

#: The generated functions of ``vgt_drill_model``, by field (the symbolic library's names).
FUNCTIONS = ("tip", "velocity", "jac", "fk", "bias_acc", "mass", "bias_forces", "id")
#: The event kinds of ``vgt_drill_run.events`` (enum ``vgt_drill_event`` of ``vgtarm.h``), in code order.
EVENT_KINDS = tuple(
    name.removeprefix("VGT_DRILL_").lower() for name, _ in sorted(enum("vgt_drill_event").items(), key=lambda x: x[1])
)
#: Longest list of events a run keeps (contact, each interface, the breakthrough, spares).
MAX_EVENTS = 64
_STATUS = enum("vgt_status")


@dataclass(frozen=True)
class CompiledRun:
    """What one compiled run wrote: the series ``(samples, 13)`` (:data:`.loop.SERIES`), the
    efforts ``(samples, n)``, the detector's events ``(t, kind, layer)``, the status
    (``vgt_status``) and, when asked for, the encoder readings ``(samples, n)``."""

    series: Array
    efforts: Array
    events: tuple[tuple[float, str, int], ...]
    status: int
    readings: Array | None = None
    fracture_time: float = math.nan


def available(robot: Robot) -> bool:
    """Whether ``robot``'s backend is a compiled symbolic library (the loop's functions in C)."""
    return isinstance(robot.backend, CompiledBackend)


def has_functions(robot: Robot) -> bool:
    """Whether ``robot``'s backend evaluates every function the drilling loops call (the recursive
    model of large stacks has no bias accelerations or forward kinematics in its library)."""
    try:
        for name in FUNCTIONS:
            robot.backend.signature(name)
    except KeyError:
        return False
    return True


def _model(backend: CompiledBackend) -> Any:
    return ffi().new(
        "vgt_drill_model *",
        {
            **{name: backend.call(name) for name in FUNCTIONS},
            "n_fk_outputs": len(backend.signature("fk").nnz_out),
            "n_bias_outputs": len(backend.signature("bias_acc").nnz_out),
        },
    )


def settings_fields(setup: DrillingSetup) -> dict[str, float | int]:
    """The fields of ``vgt_drill_settings`` for ``setup`` (its settings, checked, and the bone the
    controller is told of), by name: the compiled loop's structure and the export's defaults."""
    s, told = setup.settings, setup.told
    fields: dict[str, float | int] = {
        name: getattr(s, name)
        for name in (
            "dt",
            "substeps",
            "set_point",
            "feed_limit",
            "spindle_speed",
            "tare_time",
            "hold_frequency",
            "axial_frequency",
            "null_frequency",
            "force_gain",
            "force_rate",
            "feed_lead",
            "admittance_mass",
            "admittance_time",
            "admittance_share",
            "estimate_time",
            "feed_time",
            "layer_change",
            "layer_samples",
            "breakthrough_fraction",
            "breakthrough_samples",
            "settle_time",
            "retract_distance",
            "retract_speed",
            "gap",
        )
    }
    fields.update(
        n_joints=setup.robot.n_joints,
        mode=0 if s.mode == "explicit" else 1,
        feedback=1 if s.feedback == "sensor" else 0,
        velocity_keep=math.exp(-2.0 * math.pi * s.velocity_filter_hz * s.dt),
        observer_keep=math.exp(-s.observer_gain * s.dt),
        stop_hold=STOP_HOLD,
        end_hold=END_HOLD,
        max_samples=int(round(s.duration / s.dt)) + 1,
        tool_torque=int(s.tool_torque),
        exponent=float(told.coefficients[0, 1]),
        told_layers=len(told.layers),
        told_feed_ref=told.reference_feed,
        told_feed_floor=told.feed_floor,
        arm_depth=arm_depth(told, s)[0],
        arm_depth_late=arm_depth(told, s)[1],
    )
    return fields


def _ptr(array: Array) -> Any:
    return ffi().cast("double *", array.ctypes.data)


def compiled_run(setup: DrillingSetup, *, readings: bool = False) -> CompiledRun:
    """One run in C of ``setup`` (:func:`.loop.drilling_setup`; see :class:`CompiledRun`);
    ``readings``: keep the encoder readings."""
    robot, model, bone = setup.robot, setup.model, setup.bone
    q0, entry, frame, steps = setup.q0, setup.entry, setup.frame, setup.steps
    backend = robot.backend
    if not isinstance(backend, CompiledBackend):
        raise VgtarmError("the compiled drilling loop needs the robot's compiled symbolic library")
    n = robot.n_joints
    fields = settings_fields(setup)
    max_samples = int(fields["max_samples"])
    arrays = {
        "q0": np.ascontiguousarray(q0, dtype=np.float64),
        "p_plant": np.ascontiguousarray(robot.parameter_vector, dtype=np.float64),
        "p_ctrl": np.ascontiguousarray(model.parameter_vector, dtype=np.float64),
        "steps": np.ascontiguousarray(steps, dtype=np.float64),
        "entry": np.ascontiguousarray(entry, dtype=np.float64),
        "frame": np.ascontiguousarray(frame, dtype=np.float64),
        "tool_axis": np.ascontiguousarray(robot.tool_rotation[:, 2], dtype=np.float64),
        "series": np.zeros((max_samples, 13)),
        "efforts": np.zeros((max_samples, n)),
        "events": np.zeros((MAX_EVENTS, 3)),
    }
    if readings:
        arrays["q_meas"] = np.zeros((max_samples, n))
    boundaries = np.ascontiguousarray(bone.boundaries, dtype=np.float64)
    coefficients = np.ascontiguousarray(bone.coefficients, dtype=np.float64)
    c_bone = ffi().new(
        "vgt_drill_bone *",
        {
            "n_layers": len(bone.layers),
            "boundaries": _ptr(boundaries),
            "coefficients": _ptr(coefficients),
            "point_length": bone.point_length,
            "chisel_length": bone.chisel_length,
            "chisel_share": bone.chisel_share,
            "feed_ref": bone.reference_feed,
            "speed_ref": bone.reference_speed,
            "feed_floor": bone.feed_floor,
            "cap_strength": 0.0 if bone.cap_strength is None else bone.cap_strength,
            "cap_factor": CAP_FACTOR,
        },
    )
    c_settings = ffi().new("vgt_drill_settings *", fields)
    limits = {}
    if robot.actuators is not None:  # the controller clips to them, the plant delivers through them
        act = robot.actuators
        limits = {"force_limit": act.force, "speed_limit": act.speed, "force_speed": act.force_speed.astype(float)}
        limits = {k: np.ascontiguousarray(v, dtype=np.float64) for k, v in limits.items()}
        c_settings.force_limit = _ptr(limits["force_limit"])
    pointers = {name: _ptr(a) for name, a in {**arrays, **limits}.items() if name != "force_limit"}
    run = ffi().new("vgt_drill_run *", pointers)
    run.max_events = MAX_EVENTS
    status = backend.library.vgt_drill_simulate(_model(backend), c_settings, c_bone, run)
    k, e = int(run.n_samples), int(run.n_events)
    events = tuple((float(t), EVENT_KINDS[int(kind)], int(layer)) for t, kind, layer in arrays["events"][:e])
    kept = arrays["q_meas"][:k].copy() if readings else None
    series, efforts = arrays["series"][:k].copy(), arrays["efforts"][:k].copy()
    return CompiledRun(series, efforts, events, int(status), kept, float(run.fracture_time))


#: ``vgt_status`` codes by name, for the loop's reasons.
STATUS = _STATUS
