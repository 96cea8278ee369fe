"""The closed loop of force-controlled drilling and its result record (issue 38; see
``docs/drilling_control.md``): :func:`drilling_run` drives :class:`~.control.DrillingPlant` with
:class:`~.control.HybridController`, fed by the encoders and the momentum observer, stops and
retracts on the :class:`~.control.Detector`'s breakthrough, and returns a :class:`DrillingResult`
with its summary against the issue's targets and its figure. The loop here is NumPy's, the
reference; by default the same run is made in C (:mod:`.compiled`), held to it."""

from __future__ import annotations

import io
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import checks
from ..errors import AssemblyError, InputError
from ..markup import mpl_text
from ..model.robot import Robot
from . import compiled
from .bone import Bone, bone_from_dict, layer_weights
from .control import (
    DONE,
    DRILLING,
    END_HOLD,
    PHASES,
    RETRACTING,
    STOP_HOLD,
    STOPPING,
    TARE,
    Detector,
    DrillingPlant,
    DrillingSettings,
    DrillingSetup,
    HybridController,
    Sensing,
    arm_depth,
    check_settings,
    task_state,
    tool_wrench,
)

Array = NDArray[np.float64]

#: The issue's targets (thrust error RMS per layer (N), protrusion (m), detection delay (s),
#: lateral deviation (m), axis error (rad)).
TARGETS = {
    "thrust_error_rms": 0.5,
    "protrusion": 0.5e-3,
    "detection_delay": 0.020,
    "lateral_deviation": 0.05e-3,
    "axis_error": 1.0e-3,
}
#: The loops :func:`drilling_run` runs.
ENGINES = ("auto", "compiled", "numpy")
#: Time after full engagement in a layer before its thrust error counts (s).
ENGAGEMENT_WAIT = 0.05
#: Columns of :attr:`DrillingResult.series`.
SERIES = (
    "t",
    "depth",
    "feed",
    "thrust",
    "thrust_estimate",
    "set_point",
    "torque",
    "lateral_deviation",
    "axis_error",
    "phase",
    "detected_layer",
    "specific_thrust",
    "axial_push",
)


@dataclass(frozen=True)
class DrillingResult:
    """One drilling run: ``series`` (``(samples, len(SERIES))``, columns :data:`SERIES`, SI units;
    ``phase`` an index of :data:`~.control.PHASES`), the joint ``efforts`` ``(samples, n)``, the
    detector's ``events`` ``(t, kind, layer)``, the bone, the settings, ``success`` and ``reason``."""

    series: Array
    efforts: Array
    events: tuple[tuple[float, str, int], ...]
    bone: Bone
    settings: DrillingSettings
    success: bool
    reason: str
    fracture_time: float = math.nan  # when the far cortex's cap broke out (s; NaN: it did not)

    def column(self, name: str) -> Array:
        """The column ``name`` of :data:`SERIES`."""
        return self.series[:, SERIES.index(checks.choice("name", name, SERIES))]

    def summary(self) -> dict[str, Any]:
        """The run's measures against :data:`TARGETS` (see ``docs/drilling_control.md``)."""
        return summarise(self)

    def series_csv(self) -> str:
        """The series as CSV text: a header of :data:`SERIES`, then a line per sample with every
        double as it is (``%.17g``)."""
        stream = io.StringIO()
        stream.write(",".join(SERIES) + "\n")
        np.savetxt(stream, self.series, delimiter=",", fmt="%.17g")
        return stream.getvalue()

    def events_csv(self) -> str:
        """The detector's events as CSV text, ``t,kind,layer`` (the detector's own names: no user text)."""
        lines = ["t,kind,layer"] + [f"{t:.6g},{kind},{layer}" for t, kind, layer in self.events]
        return "\n".join(lines) + "\n"

    def figure(self, fig: Any = None) -> Any:
        """Thrust (true, estimate, set point), depth and the specific thrust against time with the
        detections and the true crossings marked; a :class:`matplotlib.figure.Figure`."""
        return drilling_figure(self, fig)


def _frame(robot: Robot, q0: Array) -> Array:
    """The target tool frame (columns ``e1``, ``e2``, axis): the tool frame at ``q0``."""
    _, rotation = robot.tool_frame(q0)
    return np.asarray(rotation, dtype=np.float64)


@dataclass
class _Run:
    """The mutable state of one run."""

    phase: int = TARE
    offset: float = 0.0
    tare: float = 0.0
    tare_n: int = 0
    stopped_at: float = math.inf
    retracted_at: float = math.inf
    previous_thrust: float = 0.0


def drilling_setup(
    robot: Robot,
    bone: Bone,
    settings: DrillingSettings | None = None,
    *,
    q0: Array | None = None,
    nominal: Bone | None = None,
) -> DrillingSetup:
    """The :class:`DrillingSetup` of :func:`drilling_run`'s arguments, each checked (one line
    naming the field otherwise); the exported controller (:mod:`vgtarm.export.drilling`) starts
    from the same."""
    q = np.array(robot.parameters.home if q0 is None else q0, dtype=np.float64)
    robot.check_assembly(q, where="q0")
    s = check_settings(robot, settings or DrillingSettings(), q)
    if not compiled.has_functions(robot):
        checks.refuse(
            "robot backend",
            getattr(robot.backend, "kind", type(robot.backend).__name__),
            "the symbolic model (drilling needs its bias accelerations and forward kinematics)",
        )
    frame = _frame(robot, q)
    entry = robot.tip_position(q) + s.gap * frame[:, 2]
    model = robot.with_parameters(robot.parameters.scaled(mass=s.model_mass))
    steps = np.array([s.encoder_resolution if u == "m" else s.twist_resolution for u in robot.joint_units])
    return DrillingSetup(robot, model, bone, nominal or bone, s, q, frame, entry, steps)


def drilling_run(
    robot: Robot,
    bone: Bone,
    settings: DrillingSettings | None = None,
    *,
    q0: Array | None = None,
    nominal: Bone | None = None,
    engine: str = "auto",
    plant: Callable[..., DrillingPlant] = DrillingPlant,
) -> DrillingResult:
    """Drill ``bone`` with ``robot`` (the plant; the controller's model is its parameters with the
    masses times ``settings.model_mass``) along the tool axis at ``q0`` (default the home
    configuration), starting at rest with the tip ``settings.gap`` before the entry surface.
    ``nominal`` is the bone the detector is told of (its layer count and feed exponent; default
    ``bone``). Stops at the breakthrough's detection, retracts ``retract_distance``, and ends;
    or ends at ``settings.duration`` (``success`` False).

    ``engine``: ``"compiled"`` (the loop in C, :mod:`.compiled`; 26 to 29 times faster, measured in
    ``docs/benchmarks.md``),
    ``"numpy"`` (this module's loop), or ``"auto"``: compiled where the robot's backend is the
    compiled symbolic library, NumPy otherwise.

    ``plant``: the class of the true robot drilling (called as :class:`~.control.DrillingPlant`
    is): another plant runs the NumPy loop (``engine`` ``"compiled"`` is then refused), as
    :func:`vgtarm.mujoco_bridge.drilling.mujoco_drilling_run` does with MuJoCo's dynamics."""
    checks.choice("engine", engine, ENGINES)
    setup = drilling_setup(robot, bone, settings, q0=q0, nominal=nominal)
    if plant is not DrillingPlant and engine == "compiled":
        checks.refuse("engine", engine, '"numpy" or "auto" with a plant of its own (the compiled loop has its own)')
    if plant is DrillingPlant and (engine == "compiled" or (engine == "auto" and compiled.available(robot))):
        return _compiled(setup)
    s, q, frame, entry, model, told = setup.settings, setup.q0.copy(), setup.frame, setup.entry, setup.model, setup.told
    truth = plant(robot, bone, entry, frame[:, 2], s.spindle_speed, s.tool_torque)
    keep_v = math.exp(-2.0 * math.pi * s.velocity_filter_hz * s.dt)
    sensing = Sensing(model, setup.steps, s.dt, keep_v, math.exp(-s.observer_gain * s.dt))
    exponent = float(told.coefficients[0, 1])  # the thrust's feed exponent of the first layer
    ctrl = HybridController(s, q.copy(), exponent, depth_ref=-s.gap)
    detector = Detector(s, len(told.layers), exponent, told.reference_feed, told.feed_floor, arm_depth(told, s))
    qd = np.zeros(robot.n_joints)
    qd0 = qd.copy()
    rows: list[list[float]] = []
    efforts: list[Array] = []
    run = _Run()
    reason = "stopped"
    for k in range(int(round(s.duration / s.dt)) + 1):
        t = k * s.dt
        try:
            row, F = _sample(t, q, qd, qd0, truth, sensing, ctrl, detector, run, frame, entry)
        except (AssemblyError, InputError) as error:
            reason = f"the run left the model at t = {t:.3f} s: {error}"
            break
        rows.append(row)
        efforts.append(F)
        if run.phase == DONE:
            break
        truth.cap.clock = t
        q, qd = truth.step(q, qd, F, s.dt, s.substeps)
    else:
        reason = f"no breakthrough detected within {s.duration:g} s"
    series = np.array(rows, dtype=np.float64).reshape(-1, len(SERIES))
    events = tuple(detector.events)
    success = run.phase == DONE
    reason = reason if not success else "done"
    return DrillingResult(series, np.array(efforts), events, bone, s, success, reason, truth.cap.broken_at)


def _compiled(setup: DrillingSetup) -> DrillingResult:
    """:func:`drilling_run` through the compiled loop."""
    if not compiled.available(setup.robot):
        checks.refuse("engine", "compiled", 'a robot with the compiled symbolic library (this one runs "numpy")')
    s = setup.settings
    run = compiled.compiled_run(setup)
    series, efforts, events, status = run.series, run.efforts, run.events, run.status
    success = status == compiled.STATUS["VGT_DONE"]
    if success:
        reason = "done"
    elif status == compiled.STATUS["VGT_ABOVE_THRESHOLD"]:
        reason = f"no breakthrough detected within {s.duration:g} s"
    else:
        t = float(series[-1, 0]) if len(series) else 0.0
        reason = f"the run left the model at t = {t:.3f} s (status {status})"
    return DrillingResult(series, efforts, events, setup.bone, s, success, reason, run.fracture_time)


def _sample(
    t: float,
    q: Array,
    qd: Array,
    qd0: Array,
    plant: DrillingPlant,
    sensing: Sensing,
    ctrl: HybridController,
    detector: Detector,
    run: _Run,
    frame: Array,
    entry: Array,
) -> tuple[list[float], Array]:
    """One control period: the truth, the measurement, the estimate, the phase, the effort."""
    s = ctrl.settings
    thrust, torque, _, _ = plant.forces(q, qd)
    depth, feed = plant.depth_feed(q, qd)
    qm, vm = sensing.measure(q, qd0)
    tau_hat = sensing.observe()
    ts = task_state(sensing.model, qm, vm, entry, frame)
    force, _ = tool_wrench(sensing.model, qm, tau_hat)
    observed = float(-(plant.axis @ force)) - run.offset
    estimate = run.previous_thrust if s.feedback == "sensor" else observed
    run.previous_thrust = thrust
    _advance(t, run, ctrl, detector, ts, estimate, observed)
    if run.phase == STOPPING and run.stopped_at == t:  # the bone is gone: so is its force from the estimate
        tau_hat = sensing.tau_hat = tau_hat + ts.J[4] * observed
    F, push = ctrl.effort(ts, vm, qm, tau_hat, estimate, run.phase, observed)
    actuators = sensing.model.actuators
    if actuators is not None:  # the controller clips to the peak forces (vgt_clip); the observer gets it
        F = np.minimum(np.maximum(F, -actuators.force), actuators.force)
    sensing.applied(F)
    true_axis = plant.robot.tool_axis(q)
    offset = plant.robot.tip_position(q) - entry
    lateral = float(np.linalg.norm(offset - (offset @ plant.axis) * plant.axis))
    angle = math.atan2(float(np.linalg.norm(np.cross(true_axis, plant.axis))), float(true_axis @ plant.axis))
    set_point = s.set_point if run.phase == DRILLING else 0.0
    row = [
        t,
        depth,
        feed,
        thrust,
        estimate,
        set_point,
        torque,
        lateral,
        angle,
        float(run.phase),
        float(detector.layer),
        detector.specific,
        push,
    ]
    return row, F


def _advance(
    t: float, run: _Run, ctrl: HybridController, detector: Detector, ts: Any, estimate: float, observed: float
) -> None:
    """The phase of this sample: tare (the offset of the observer's thrust ``observed``), drilling
    (the detector fed with the thrust fed back, ``estimate``), stopping, retracting, done."""
    s = ctrl.settings
    if run.phase == TARE:
        if t >= 0.5 * s.tare_time:
            run.tare += observed
            run.tare_n += 1
        if t >= s.tare_time:
            run.offset = run.tare / run.tare_n
            run.phase = DRILLING
            ctrl.depth_ref, ctrl.feed_ref = ts.depth, 0.0
        return
    if run.phase == DRILLING:
        if detector.update(t, estimate, ts.feed, ts.depth):
            run.phase, run.stopped_at = STOPPING, t
            ctrl.stop(ts.depth)
    elif run.phase == STOPPING and t >= run.stopped_at + STOP_HOLD:
        run.phase = RETRACTING
    elif run.phase == RETRACTING and ctrl.depth_ref <= ctrl.stop_depth - s.retract_distance + 1e-12:
        if not math.isfinite(run.retracted_at):
            run.retracted_at = t
        if t >= run.retracted_at + END_HOLD:
            run.phase = DONE


def _crossing(t: Array, x: Array, level: float) -> float:
    """First time ``x`` reaches ``level`` (s), NaN if never."""
    hit = np.nonzero(x >= level)[0]
    return float(t[hit[0]]) if hit.size else math.nan


def _layer_errors(result: DrillingResult) -> list[dict[str, float]]:
    """Per layer: the RMS of the true thrust's error to the set point while drilling with the point
    wholly in the layer, from :data:`ENGAGEMENT_WAIT` after its full engagement to the next
    interface (or the cap's breakout), and the share of those samples at the feed limit."""
    t, depth, thrust = result.column("t"), result.column("depth"), result.column("thrust")
    feed, phase = result.column("feed"), result.column("phase")
    edges, length = result.bone.boundaries, result.bone.point_length
    s = result.settings
    out = []
    for i in range(len(result.bone.layers)):
        start = _crossing(t, depth, edges[i] + length)
        inside = (depth >= edges[i] + length) & (depth <= edges[i + 1]) & (phase == DRILLING)
        inside &= t >= start + ENGAGEMENT_WAIT if math.isfinite(start) else False
        if math.isfinite(result.fracture_time):  # the cap out, the last layer cuts no more
            inside &= t < result.fracture_time
        error = thrust[inside] - s.set_point
        out.append(
            {
                "layer": float(i),
                "samples": float(inside.sum()),
                "thrust_error_rms": float(np.sqrt(np.mean(error**2))) if error.size else math.nan,
                "thrust_mean": float(np.mean(thrust[inside])) if error.size else math.nan,
                "at_feed_limit": float(np.mean(feed[inside] >= 0.98 * s.feed_limit)) if error.size else math.nan,
            }
        )
    return out


def summarise(result: DrillingResult) -> dict[str, Any]:
    """The measures of ``result``: per-layer thrust error, protrusion past the far surface (m),
    the breakthrough's true time (the tip crossing the far surface, or the cap breaking out if that
    came first) and the detection's delay after it (s), the delay after the true last layer's
    engagement fell below the detector's fraction (the estimator's and detector's own latency), the
    largest lateral deviation (m) and axis error (rad) from the tare to the end, each layer
    transition's true and detected times, the detections not preceded by a true crossing (false),
    and the largest joint efforts."""
    t, depth = result.column("t"), result.column("depth")
    bone, s = result.bone, result.settings
    true_break = _crossing(t, depth, bone.thickness)
    if math.isfinite(result.fracture_time):  # the cap broke out before the apex reached the surface
        true_break = min(true_break, result.fracture_time) if math.isfinite(true_break) else result.fracture_time
    weight, _ = layer_weights(bone, depth)
    last = weight[:, -1]
    past = depth > bone.thickness
    dropped = np.nonzero(past & (last < s.breakthrough_fraction))[0]
    truth_drop = float(t[dropped[0]]) if dropped.size else math.nan
    detected = [e for e in result.events if e[1] == "breakthrough"]
    t_detect = detected[0][0] if detected else math.nan
    # each detection belongs to the last interface the tip crossed before it (by time, not by the
    # detector's count, which a hidden transition puts off); a second one for that interface, or
    # one before any crossing, is false
    crossings = [_crossing(t, depth, float(edge)) for edge in bone.boundaries[1:-1]]
    matched: dict[int, tuple[float, str, int]] = {}
    used = set()
    for event in (e for e in result.events if e[1] in ("softer", "harder")):
        before = [i for i, c in enumerate(crossings) if math.isfinite(c) and c <= event[0]]
        if before and before[-1] not in matched:
            matched[before[-1]] = event
            used.add(event)
    transitions = [
        {"interface": i + 1, "true_time": c, "detected_time": matched[i][0] if i in matched else math.nan}
        for i, c in enumerate(crossings)
    ]
    false = [e for e in result.events if e[1] in ("softer", "harder") and e not in used]
    if detected and not (math.isfinite(true_break) and detected[0][0] >= true_break):
        false.append(detected[0])  # a breakthrough before the tip crossed the far surface: the hole unfinished
    errors = _layer_errors(result)
    rms = [e["thrust_error_rms"] for e in errors]
    return {
        "success": result.success,
        "reason": result.reason,
        "layers": errors,
        "thrust_error_rms_max": float(np.nanmax(rms)) if np.isfinite(rms).any() else math.nan,
        "protrusion": float(np.max(depth) - bone.thickness),
        "breakthrough_true_time": true_break,
        "cap_breakout_time": result.fracture_time,
        "breakthrough_detected_time": t_detect,
        "detection_delay": t_detect - true_break,
        "detection_delay_after_drop": t_detect - truth_drop,
        "lateral_deviation_max": float(np.max(result.column("lateral_deviation"))),
        "axis_error_max": float(np.max(result.column("axis_error"))),
        "transitions": transitions,
        "false_detections": len(false),
        "effort_max": np.max(np.abs(result.efforts), axis=0).tolist() if result.efforts.size else [],
        "targets": dict(TARGETS),
    }


def drilling_figure(result: DrillingResult, fig: Any = None) -> Any:
    """Thrust, depth and specific thrust of ``result`` against time, detections marked (dashed,
    red: breakthrough) and the true interface crossings (dotted); a new
    :class:`matplotlib.figure.Figure` (no pyplot) unless ``fig`` is given."""
    from matplotlib.figure import Figure

    fig = fig if fig is not None else Figure(figsize=(8.0, 7.0))
    axes = fig.subplots(3, 1, sharex=True)
    t = result.column("t")
    axes[0].plot(t, result.column("thrust"), label="thrust (true)")
    axes[0].plot(t, result.column("thrust_estimate"), label="estimate", alpha=0.6)
    axes[0].plot(t, result.column("set_point"), "k--", label="set point")
    axes[0].set_ylabel("thrust (N)")
    axes[1].plot(t, 1e3 * result.column("depth"), label="tip depth")
    for edge in result.bone.boundaries:
        axes[1].axhline(1e3 * edge, color="0.6", lw=0.8)
    axes[1].set_ylabel("depth (mm)")
    axes[2].plot(t, result.column("specific_thrust"), label="specific thrust")
    axes[2].set_ylabel("specific thrust (N)")
    axes[2].set_xlabel("time (s)")
    for edge in result.bone.boundaries[1:]:
        crossing = _crossing(t, result.column("depth"), float(edge))
        if math.isfinite(crossing):
            for ax in axes:
                ax.axvline(crossing, color="0.5", ls=":", lw=1.0)
    for time, kind, _ in result.events:
        for ax in axes:
            ax.axvline(time, color="r" if kind == "breakthrough" else "g", ls="--", lw=1.0)
    axes[0].legend(loc="upper right", fontsize="small")
    phase = PHASES[int(result.column("phase")[-1])]
    fig.suptitle(f"{mpl_text(result.bone.name)}: {result.settings.mode}, {phase}")  # the name is the user's
    return fig


def perturbed_bone(bone: Bone, seed: int, spread: float = 0.3) -> Bone:
    """``bone`` with each layer's thickness and density multiplied by an independent factor drawn
    uniformly in ``[1 - spread, 1 + spread]`` with the generator of ``seed`` (thicknesses first,
    then densities, layer by layer), rebuilt (and checked) through :func:`bone_from_dict`."""
    rng = np.random.default_rng(checks.seed("seed", seed))
    spread = checks.number("spread", spread, minimum=0.0, below=1.0)
    data = bone.to_dict()
    n = len(data["layers"])
    thickness = rng.uniform(1.0 - spread, 1.0 + spread, n)
    density = rng.uniform(1.0 - spread, 1.0 + spread, n)
    for layer, a, b in zip(data["layers"], thickness, density, strict=True):
        layer["thickness"] *= float(a)
        layer["density"] *= float(b)
    data["name"] = f"{bone.name} (seed {seed}, +-{100 * spread:g} %)"
    return bone_from_dict(data, source=f"perturbed {bone.name}")
