"""Force-controlled drilling: the plant with the drill's thrust, the encoders and momentum observer,
the hybrid force/position controller in the tool frame, and the layer and breakthrough detector
(issue 38, deliverables 2 and 3; ``docs/drilling_control.md``). The closed loop that runs them is
:func:`vgtarm.drilling.loop.drilling_run`.

Frames and signs: ``axis`` is the unit drilling direction in F0 (the tool's axis at the start),
``entry`` the bone's entry point; the tip depth is ``axis . (tip - entry)`` (m) and the feed its
rate (m/s). The bone pushes the tip with ``-thrust * axis`` and turns the end-effector with the
moment ``-torque * axis`` (the spindle housing takes the reaction of the cutting torque).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from .. import checks
from ..model.robot import Robot
from .bone import Bone, cap_thickness, drilling_forces_at

Array = NDArray[np.float64]

#: Explicit force control (PI on the thrust error into the axial force) or admittance (the axial
#: reference moved by the thrust error, tracked by a position loop).
MODES = ("explicit", "admittance")
#: The thrust fed back: the momentum observer's estimate mapped to the tool, or a tip force sensor.
FEEDBACKS = ("observer", "sensor")
#: Phases of a run, as recorded in :attr:`DrillingResult.phase`.
PHASES = ("tare", "drilling", "stopping", "retracting", "done")
TARE, DRILLING, STOPPING, RETRACTING, DONE = range(len(PHASES))
#: Hold after the stop before retracting, and after the retract before the run ends (s).
STOP_HOLD = 0.05
END_HOLD = 0.1


@dataclass(frozen=True)
class DrillingSettings:
    """A drilling run's settings, SI units (m, s, N, rad/s). See ``docs/drilling_control.md`` for
    each choice; :func:`check_settings` validates them against a robot."""

    set_point: float = 20.0  # thrust (N)
    feed_limit: float = 1.0e-3  # the feed is never faster (m/s)
    spindle_speed: float = 1000.0 * 2.0 * math.pi / 60.0  # 1000 rpm (rad/s)
    mode: str = "admittance"
    feedback: str = "observer"
    dt: float = 1.0e-3  # control period (s)
    substeps: int = 4  # plant steps per control period
    gap: float = 0.5e-3  # tip to entry surface at the start, along the axis (m)
    tare_time: float = 0.06  # hold at the start; the estimate's offset is its mean over the last half (s)
    encoder_resolution: float = 1.0e-6  # legs (m)
    twist_resolution: float = 2.0 * math.pi / 2**20  # twist (rad)
    velocity_filter_hz: float = 100.0
    observer_gain: float = 100.0  # K_O (1/s)
    model_mass: float = 1.1  # the controller's model: masses x this factor
    hold_frequency: float = 8.0  # lateral and angle position loops: natural frequency (Hz)
    axial_frequency: float = 20.0  # axial position loop (admittance, stop, retract): natural frequency (Hz)
    null_frequency: float = 2.0  # null-space posture loop (Hz)
    force_gain: float = 0.3  # explicit: proportional gain on the thrust error (N/N)
    force_rate: float = 40.0  # explicit: integral gain (1/s)
    feed_lead: float = 0.02  # the axial reference stays within this much feed (s) of the tip while drilling
    admittance_mass: float = 2000.0  # admittance: least virtual mass along the axis (kg)
    admittance_time: float = 0.15  # admittance: the force loop's time constant on the cut's damping (s)
    admittance_share: float = 0.5  # admittance: share of the thrust error the feed corrects at once
    estimate_time: float = 0.005  # detector: time constant of the thrust estimate's filter (s)
    feed_time: float = 0.03  # detector: time constant of the feed's filter (s)
    layer_change: float = 0.2  # detector: relative change of the specific thrust that marks a layer
    layer_samples: int = 20  # detector: samples the change must last
    breakthrough_fraction: float = 0.9  # detector: specific thrust below this share of its peak
    breakthrough_samples: int = 5  # detector: samples the drop must last
    settle_time: float = 0.1  # detector: time after a detection before the level is tracked again (s)
    arm_margin: float = 0.3  # detector: the breakthrough is armed by depth this share short of the last layer's start
    retract_distance: float = 1.0e-3  # (m)
    retract_speed: float = 2.0e-3  # (m/s)
    duration: float = 40.0  # longest run (s)
    tool_torque: bool = True  # the cutting torque on the end-effector


def check_settings(robot: Robot, settings: DrillingSettings, q: Array | None = None) -> DrillingSettings:
    """``settings`` checked; one :class:`~vgtarm.errors.InputError` line naming the field otherwise.

    With actuators (a robot file's ``[actuators]``), a set point whose holding effort at ``q``
    (default the home configuration: ``J_P^T axis set_point`` plus gravity) exceeds a peak force is
    refused."""
    s = settings
    checks.positive("set_point", s.set_point, "N")
    checks.positive("feed_limit", s.feed_limit, "m/s", maximum=0.1)
    checks.positive("spindle_speed", s.spindle_speed, "rad/s", maximum=1e4)
    checks.choice("mode", s.mode, MODES)
    checks.choice("feedback", s.feedback, FEEDBACKS)
    checks.positive("dt", s.dt, "s", maximum=0.01)
    checks.whole("substeps", s.substeps, minimum=1, maximum=1000)
    checks.number("gap", s.gap, minimum=0.0, maximum=0.01, unit="m")
    checks.number("tare_time", s.tare_time, minimum=4 * s.dt, maximum=10.0, unit="s")
    checks.number("encoder_resolution", s.encoder_resolution, minimum=0.0, maximum=1e-2, unit="m")
    checks.number("twist_resolution", s.twist_resolution, minimum=0.0, maximum=0.1, unit="rad")
    checks.positive("velocity_filter_hz", s.velocity_filter_hz, "Hz")
    checks.positive("observer_gain", s.observer_gain, "1/s", maximum=1.0 / s.dt)
    for name in (
        "hold_frequency",
        "axial_frequency",
        "null_frequency",
        "force_rate",
        "feed_lead",
        "admittance_mass",
        "admittance_time",
    ):
        checks.positive(name, getattr(s, name))
    checks.number("force_gain", s.force_gain, minimum=0.0, maximum=10.0)
    checks.number("admittance_share", s.admittance_share, minimum=0.0, maximum=1.0)
    for name in ("estimate_time", "feed_time", "settle_time", "retract_distance", "retract_speed", "duration"):
        checks.positive(name, getattr(s, name))
    checks.number("layer_change", s.layer_change, above=0.0, below=1.0)
    checks.number("breakthrough_fraction", s.breakthrough_fraction, above=0.0, below=1.0)
    checks.number("arm_margin", s.arm_margin, minimum=0.0, below=1.0)
    checks.whole("layer_samples", s.layer_samples, minimum=1)
    checks.whole("breakthrough_samples", s.breakthrough_samples, minimum=1)
    checks.flag("tool_torque", s.tool_torque)
    _check_actuators(robot, s.set_point, robot.parameters.home if q is None else q)
    return s


def _check_actuators(robot: Robot, set_point: float, q: Array) -> None:
    """Refuse a set point the actuators cannot hold at ``q``."""
    actuators = robot.actuators
    if actuators is None:
        return
    axis = robot.tool_axis(q)
    holding = robot.bias_forces(q, np.zeros(robot.n_joints)) + robot.tip_jacobian(q).T @ axis * set_point
    over = np.abs(holding) > actuators.force
    if over.any():
        i = int(np.argmax(over))
        checks.refuse(
            "set_point",
            set_point,
            f"a thrust the actuators hold (joint {robot.joint_names[i]} would need {abs(holding[i]):.4g} "
            f"against its peak {actuators.force[i]:.4g})",
        )


@dataclass(frozen=True)
class DrillingSetup:
    """What a drilling run starts from, checked (:func:`~.loop.drilling_setup`): the plant ``robot``, the
    controller's ``model``, the ``bone`` drilled and the one the detector is ``told`` of, the
    ``settings``, the start ``q0``, the target tool ``frame`` (columns ``e1``, ``e2``, the axis),
    the ``entry`` point (m, F0) and the encoder ``steps`` of each joint."""

    robot: Robot
    model: Robot
    bone: Bone
    told: Bone
    settings: DrillingSettings
    q0: Array
    frame: Array
    entry: Array
    steps: Array


def arm_depth(told: Bone, settings: DrillingSettings) -> tuple[float, float]:
    """The depths (m) past which the detector arms the breakthrough although its layer count says
    it is not in the last layer yet: ``(early, late)``, the told bone's last layer's start less and
    plus ``arm_margin`` of it. Early when the count is behind by two or more (a transition was
    missed for sure: no bone within the margin has its last layer start later), late when it is
    behind by one (the last transition itself was missed)."""
    start = float(told.boundaries[-2])
    return start * (1.0 - settings.arm_margin), start * (1.0 + settings.arm_margin)


# -- the plant ------------------------------------------------------------------------------------


@dataclass
class CapState:
    """Whether the far cortex's cap has broken out, and when (s; NaN: not yet); ``clock`` is the
    time of the control period the plant is stepping (s), set by the loop."""

    broken_at: float = math.nan
    clock: float = 0.0


@dataclass(frozen=True)
class DrillingPlant:
    """The true robot drilling ``bone`` along ``axis`` (unit, F0) from ``entry`` (m, F0) at
    ``spindle_speed`` (rad/s). With the bone's ``cap_strength`` the cap ahead of the apex breaks
    out once thinner than :func:`~.bone.cap_thickness` under the thrust (checked at each plant
    step), and the last layer cuts no more (``cap``)."""

    robot: Robot
    bone: Bone
    entry: Array
    axis: Array
    spindle_speed: float
    tool_torque: bool = True
    cap: CapState = field(default_factory=CapState)

    @cached_property
    def _capless(self) -> Bone:
        """The bone without its last layer: what still cuts once the cap is out."""
        return dataclasses.replace(self.bone, layers=self.bone.layers[:-1])

    def _check_cap(self, q: Array, qd: Array, t: float) -> None:
        """Break the cap at time ``t`` (s) if the bone left ahead of the apex is thinner than
        :func:`~.bone.cap_thickness` under the thrust at ``(q, qd)``."""
        bone = self.bone
        if bone.cap_strength is None or not math.isnan(self.cap.broken_at):
            return
        depth, _ = self.depth_feed(q, qd)
        if depth > float(bone.boundaries[-2]) and bone.thickness - depth < cap_thickness(bone, self.forces(q, qd)[0]):
            self.cap.broken_at = t

    def depth_feed(self, q: Array, qd: Array) -> tuple[float, float]:
        """Tip depth past the entry surface along the axis (m) and the feed (m/s)."""
        tip = self.robot.tip_position(q)
        velocity, _ = self.robot.tip_velocity(q, qd)
        return float(self.axis @ (tip - self.entry)), float(self.axis @ velocity)

    def forces(self, q: Array, qd: Array) -> tuple[float, float, float, float]:
        """The drill's ``(thrust, torque, d thrust / d depth, d thrust / d feed)`` at ``(q, qd)``."""
        depth, feed = self.depth_feed(q, qd)
        bone = self.bone if math.isnan(self.cap.broken_at) else self._capless
        return drilling_forces_at(bone, depth, feed, self.spindle_speed)

    def tip_force(self, q: Array, qd: Array) -> Array:
        """The bone's force on the tip (N, F0): ``-thrust * axis``."""
        return -self.forces(q, qd)[0] * self.axis

    def acceleration(self, q: Array, qd: Array, F: Array, h: float) -> tuple[Array, float]:
        """Joint accelerations under the efforts ``F`` with the thrust taken semi-implicitly over a
        step ``h`` (s): the cut is a stiff damper (``d thrust / d feed`` up to 1e5 N s/m), so
        ``(M + h b j j^T) qdd = F - C - j thrust - J_w^T axis torque`` with ``j = J_P^T axis``,
        ``b = d thrust / d feed``. ``h = 0`` gives :meth:`Robot.forward_dynamics` exactly. With
        actuators (the robot file's ``[actuators]``) ``F`` is first what they deliver at ``qd``
        (:meth:`~vgtarm.model.actuators.Actuators.saturate`). Also returns the thrust at ``(q, qd)`` (N)."""
        r = self.robot
        if r.actuators is not None:  # what the actuators deliver at this velocity (vgt_saturate)
            F = r.actuators.saturate(F, qd)
        thrust, torque, _, damping = self.forces(q, qd)
        j = r.tip_jacobian(q).T @ self.axis
        rhs = F - r.bias_forces(q, qd) - j * thrust
        if self.tool_torque:
            rhs = rhs - r.angular_jacobian(q).T @ self.axis * torque
        A = r.mass_matrix(q) + (h * damping) * np.outer(j, j)
        return np.asarray(np.linalg.solve(A, rhs), dtype=np.float64), thrust

    def step(self, q: Array, qd: Array, F: Array, dt: float, substeps: int) -> tuple[Array, Array]:
        """The state after ``dt`` (s) under the constant efforts ``F``: ``substeps`` steps of
        semi-implicit Euler (velocity first) with the semi-implicit thrust."""
        h = dt / substeps
        for i in range(substeps):
            self._check_cap(q, qd, self.cap.clock + i * h)
            qdd, _ = self.acceleration(q, qd, F, h)
            qd = qd + h * qdd
            q = q + h * qd
        return q, qd


# -- sensing --------------------------------------------------------------------------------------


def quantise(q: Array, step: Array) -> Array:
    """Encoder readings of ``q`` with the steps ``step`` (0: exact), as ``vgt_quantise``."""
    safe = np.where(step > 0, step, 1.0)
    return np.where(step > 0, step * np.floor(q / safe + 0.5), q)


@dataclass
class Sensing:
    """Encoders, the filtered velocity and the momentum observer (the formulas of the main loop,
    ``python_loop.py`` and ``vgt_control.h``: differenced velocities over two periods, the mean
    effort of the two, the first-order filter ``keep = exp(-K_O dt)``)."""

    model: Robot
    steps: Array
    dt: float
    velocity_weight: float
    keep: float
    q_meas: list[Array] = field(default_factory=list)
    F: list[Array] = field(default_factory=list)
    v_filtered: Array | None = None
    v_raw: list[Array] = field(default_factory=list)
    tau_hat: Array | None = None

    def measure(self, q: Array, qd0: Array) -> tuple[Array, Array]:
        """The encoder reading and the filtered velocity of this sample (``qd0``: the known start)."""
        qm = quantise(q, self.steps)
        if not self.q_meas:
            raw = qd0.copy()
            self.v_filtered = raw.copy()
        else:
            raw = (qm - self.q_meas[-1]) / self.dt
            assert self.v_filtered is not None
            self.v_filtered = self.velocity_weight * self.v_filtered + (1.0 - self.velocity_weight) * raw
        self.q_meas = [*self.q_meas[-2:], qm]
        self.v_raw = [*self.v_raw[-1:], raw]
        return qm, self.v_filtered

    def observe(self) -> Array:
        """The estimated external joint efforts ``J^T f_ext`` of this sample (zero for 2 samples)."""
        n = self.steps.shape[0]
        if self.tau_hat is None or len(self.q_meas) < 3 or len(self.F) < 2:
            self.tau_hat = np.zeros(n) if self.tau_hat is None else self.tau_hat
            return self.tau_hat
        va, vb = self.v_raw
        applied = 0.5 * (self.F[-2] + self.F[-1])
        raw = self.model.inverse_dynamics(self.q_meas[-3], va, (vb - va) / self.dt) - applied
        self.tau_hat = self.keep * self.tau_hat + (1.0 - self.keep) * raw
        return self.tau_hat

    def applied(self, F: Array) -> None:
        """Record the effort of this sample."""
        self.F = [*self.F[-1:], F]


def tool_wrench(model: Robot, q: Array, tau: Array) -> tuple[Array, Array]:
    """The force (N) and moment (N m) at the tip, F0, whose joint efforts are ``tau``: the least
    squares solution of ``[J_P; J_w]^T w = tau`` (exact for an effort of an external wrench)."""
    Jx = np.vstack([model.tip_jacobian(q), model.angular_jacobian(q)])
    w = np.asarray(np.linalg.lstsq(Jx.T, tau, rcond=None)[0], dtype=np.float64)
    return w[:3], w[3:]


# -- the controller -------------------------------------------------------------------------------


@dataclass(frozen=True)
class TaskState:
    """The tool-frame task at the measured state: the task Jacobian ``(5, n)`` (rows: lateral
    ``e1``, ``e2`` of the tip, angular velocity about ``e1``, ``e2``, feed along the axis), its
    ``Jdot qd`` ``(5,)``, the errors of the four held coordinates (m, m, rad, rad), the depth (m)
    and feed (m/s), and the model's mass matrix and bias forces."""

    J: Array
    Jdot_qd: Array
    held_error: Array
    held_rate: Array
    depth: float
    feed: float
    M: Array
    C: Array


def task_state(model: Robot, q: Array, qd: Array, entry: Array, frame: Array) -> TaskState:
    """:class:`TaskState` of ``model`` at ``(q, qd)`` for the target tool frame ``frame`` (columns
    ``e1``, ``e2``, ``axis``) through ``entry``."""
    e1, e2, axis = frame.T
    JP, Jw = model.tip_jacobian(q), model.angular_jacobian(q)
    bias = model.bias_accelerations(q, qd)
    J = np.vstack([e1 @ JP, e2 @ JP, e1 @ Jw, e2 @ Jw, axis @ JP])
    Jdot_qd = np.array([e1 @ bias.tip, e2 @ bias.tip, e1 @ bias.angular, e2 @ bias.angular, axis @ bias.tip])
    offset = model.tip_position(q) - entry
    turn = np.cross(model.tool_axis(q), axis)  # the rotation that brings the axis back (rad)
    held_error = np.array([e1 @ offset, e2 @ offset, -(e1 @ turn), -(e2 @ turn)])
    rate = J @ qd
    return TaskState(
        J,
        Jdot_qd,
        held_error,
        rate[:4],
        float(axis @ offset),
        float(rate[4]),
        model.mass_matrix(q),
        model.bias_forces(q, qd),
    )


@dataclass
class HybridController:
    """Hybrid force/position control in the tool frame at one period ``dt``: task-space computed
    force (the model's ``Lambda``) holding the tip on the axis line and the axis in angle (PD), the
    thrust regulated along the axis (``mode``), the null space held at the start posture, the
    observer's estimate cancelled as in the main loop. See ``docs/drilling_control.md``."""

    settings: DrillingSettings
    q_centre: Array
    exponent: float = 0.6  # the cutting law's feed exponent (the cut's damping a F / v)
    depth_ref: float = 0.0
    feed_ref: float = 0.0
    integral: float = 0.0
    stop_depth: float = 0.0
    limited: bool = True  # explicit: at the feed limit (the approach starts there)
    feed_f: float = 0.0  # explicit: the measured feed filtered (m/s)

    def effort(
        self, ts: TaskState, qd: Array, q: Array, tau_hat: Array, thrust: float, phase: int, cancelled: float
    ) -> tuple[Array, float]:
        """The joint efforts and the axial push commanded (N) at this sample; ``thrust`` is the
        thrust fed back (N, tared: the observer's or the sensor's), ``cancelled`` the observer's
        tared thrust, which cancelling ``tau_hat`` pushes with."""
        s = self.settings
        Minv = np.linalg.inv(ts.M)
        Lam = np.asarray(np.linalg.inv(ts.J @ Minv @ ts.J.T), dtype=np.float64)
        wn = 2.0 * math.pi * s.hold_frequency
        acc = np.zeros(5)
        acc[:4] = -wn * wn * ts.held_error - 2.0 * wn * ts.held_rate
        axial_force = 0.0
        explicit = phase == DRILLING and s.mode == "explicit"
        if explicit and not self._feed_limited(ts, thrust):
            axial_force = self._explicit(thrust, cancelled)
        else:
            if not explicit:
                self._reference(ts, thrust, phase)
            wa = 2.0 * math.pi * s.axial_frequency
            acc[4] = wa * wa * (self.depth_ref - ts.depth) + 2.0 * wa * (self.feed_ref - ts.feed)
        Ft = Lam @ (acc - ts.Jdot_qd)
        Ft[4] += axial_force
        Jbar = Minv @ ts.J.T @ Lam
        wp = 2.0 * math.pi * s.null_frequency
        posture = ts.M @ (wp * wp * (self.q_centre - q) - 2.0 * wp * qd)
        null = posture - ts.J.T @ (Jbar.T @ posture)
        return ts.J.T @ Ft + ts.C - tau_hat + null, axial_force

    def _explicit(self, thrust: float, cancelled: float) -> float:
        """Explicit force control: the axial force beyond the cancelled estimate ``cancelled`` (N),
        so that the net push is the PI on the error of the thrust fed back."""
        s = self.settings
        error = s.set_point - thrust
        self.integral += s.force_rate * error * s.dt
        return s.set_point + s.force_gain * error + self.integral - cancelled

    def _feed_limited(self, ts: TaskState, thrust: float) -> bool:
        """Explicit mode's feed limit: from the start, and whenever the measured feed (filtered
        over ``feed_time``) passes the limit by 5 % or reaches it with the thrust 5 % short of the
        set point, the axis goes to the position loop on a reference advancing at the limit (as the
        admittance's); back to force control, without a bump, once the thrust passes the set point."""
        s = self.settings
        b = math.exp(-s.dt / s.feed_time)
        self.feed_f = b * self.feed_f + (1.0 - b) * ts.feed
        short = thrust < 0.95 * s.set_point
        if not self.limited and (self.feed_f >= 1.05 * s.feed_limit or (short and self.feed_f >= s.feed_limit)):
            self.limited = True
            self.depth_ref, self.feed_ref = ts.depth, s.feed_limit
        elif self.limited and thrust >= s.set_point:
            self.limited = False
            self.integral = -(1.0 + s.force_gain) * (s.set_point - thrust)  # the same push as now
        if self.limited:
            self.depth_ref += s.dt * s.feed_limit
            lead = s.feed_limit * s.feed_lead
            self.depth_ref = min(max(self.depth_ref, ts.depth - lead), ts.depth + lead)
        return self.limited

    def _reference(self, ts: TaskState, thrust: float, phase: int) -> None:
        """The axial reference (depth, feed) of this sample: admittance while drilling, held at
        the tare, stopped then moved back when stopping and retracting."""
        s = self.settings
        if phase == DRILLING:  # admittance: virtual mass pushed by the thrust error, feed in [0, limit]
            damping = self.exponent * max(thrust, 0.0) / max(self.feed_ref, 0.05 * s.feed_limit)
            mass = max(s.admittance_mass, s.admittance_time * damping)
            error = s.set_point - thrust
            self.integral = min(max(self.integral + s.dt * error / mass, 0.0), s.feed_limit)
            direct = s.admittance_share * error / max(damping, s.admittance_mass / s.admittance_time)
            self.feed_ref = min(max(self.integral + direct, 0.0), s.feed_limit)
        elif phase == RETRACTING:
            self.feed_ref = -s.retract_speed
        else:
            self.feed_ref = 0.0
        if phase == RETRACTING and self.depth_ref <= self.stop_depth - s.retract_distance:
            self.feed_ref = 0.0
        self.depth_ref += s.dt * self.feed_ref
        if phase == DRILLING:  # the reference never runs away from the tip (no wind-up in the cut)
            lead = s.feed_limit * s.feed_lead
            self.depth_ref = min(max(self.depth_ref, ts.depth - lead), ts.depth + lead)

    def stop(self, depth: float) -> None:
        """Stop the feed at ``depth`` (m): the axial reference held there."""
        self.depth_ref, self.feed_ref, self.stop_depth = depth, 0.0, depth


# -- detection ------------------------------------------------------------------------------------


@dataclass
class Detector:
    """Layer transitions and breakthrough from the thrust estimate (docs/drilling_control.md).

    The signal is the specific thrust ``c = thrust_f / g(feed_f)``: the estimate and the feed
    filtered (first order), divided by the feed's factor of the cutting law ``(v / v_ref)^a``, so
    that a change of the feed the force loop makes is not taken for a change of the bone. A layer
    transition is ``c`` off its layer's level by more than ``layer_change`` for ``layer_samples``
    samples; the breakthrough is ``c`` below ``breakthrough_fraction`` of its peak in the last
    layer for ``breakthrough_samples`` samples. ``n_layers`` and the feed exponent come from the
    bone the controller is told of (the nominal file). A transition that the contrast of a
    perturbed bone hides would leave the breakthrough unarmed: past the depths of :func:`arm_depth`
    the detector arms it anyway (an ``armed`` event), the level tracked from there."""

    settings: DrillingSettings
    n_layers: int
    exponent: float
    reference_feed: float
    feed_floor: float
    arm_depth: tuple[float, float] = (math.inf, math.inf)  # (early, late) depths arming it (m), see arm_depth
    thrust_f: float = 0.0
    feed_f: float = 0.0
    specific: float = 0.0
    level: float = 0.0
    count: int = 0
    layer: int = -1  # detected layer: -1 before contact
    softer: bool = False  # the detected layer is softer than the one before
    started: bool = False  # a sample taken (the feed's filter starts at the first feed)
    quiet_until: float = 0.0
    events: list[tuple[float, str, int]] = field(default_factory=list)

    def update(self, t: float, thrust: float, feed: float, depth: float = -math.inf) -> bool:
        """Take the sample at time ``t`` (s) with the measured ``depth`` (m); True when the
        breakthrough is detected now."""
        s = self.settings
        a = math.exp(-s.dt / s.estimate_time)
        b = math.exp(-s.dt / s.feed_time)
        self.thrust_f = a * self.thrust_f + (1.0 - a) * thrust
        self.feed_f = b * self.feed_f + (1.0 - b) * feed if self.started else feed
        self.started = True
        g = (max(self.feed_f, self.feed_floor) / self.reference_feed) ** self.exponent
        self.specific = c = self.thrust_f / g
        if self.layer < 0:  # contact: the filtered thrust past a quarter of the set point
            if self.thrust_f > 0.25 * s.set_point:
                self._event(t, "contact", 0, c)
            return False
        early, late = self.arm_depth
        behind = self.n_layers - 1 - self.layer  # a transition the bone's contrast hid: armed by depth
        if (behind >= 2 and depth >= early) or (behind == 1 and depth >= late):
            self._event(t, "armed", self.n_layers - 1, c)
            self.quiet_until = t  # the level is tracked from now
        # the level: the peak since entering a harder layer, the trough since entering a softer one
        self.level = min(self.level, c) if self.softer else max(self.level, c)
        if t < self.quiet_until:
            return False
        if self.layer == self.n_layers - 1:
            drop = c < s.breakthrough_fraction * self.level
            self.count = self.count + 1 if drop else 0
            if self.count >= s.breakthrough_samples:
                self._event(t, "breakthrough", self.n_layers, c)
                return True
            return False
        if self.softer:
            changed = c > (1.0 + s.layer_change) * self.level
        else:
            changed = c < (1.0 - s.layer_change) * self.level
        self.count = self.count + 1 if changed else 0
        if self.count >= s.layer_samples:
            self._event(t, "harder" if self.softer else "softer", self.layer + 1, c)
        return False

    def _event(self, t: float, kind: str, layer: int, c: float) -> None:
        self.events.append((t, kind, layer))
        self.layer, self.count, self.level = layer, 0, c
        self.softer = kind == "softer"
        self.quiet_until = t + self.settings.settle_time
