"""What the controller knows: the disturbance observer or force sensor, and realistic sensing.

Validated here once, from the arguments of :func:`vgtarm.simulation.simulate`; the loops
(``closed_loop.c`` and its NumPy twin) do the computation. See ``docs/control.md``, section
"Disturbance observer, force sensor and realistic sensing", for the formulas and how to choose
the gain.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import checks
from ..errors import InputError, shown
from ..model.parameters import JOINT_UNITS

#: Default gain of the momentum observer as K_O dt: half the largest admissible, 500 1/s at 1 ms
#: (a 2 ms time constant; measured choice in docs/control.md).
DEFAULT_OBSERVER_GAIN_DT = 0.5
#: Default cut-off of the controller's first-order filter of differenced velocities (Hz).
DEFAULT_VELOCITY_FILTER_HZ = 100.0
#: Encoder step of revolute joints when encoders are on and none is given: 20 bits a turn.
DEFAULT_TWIST_RESOLUTION = 2.0 * math.pi / 2**20
#: Coarsest encoder steps accepted: a leg encoder of 1 cm and a twist encoder of 0.1 rad (64 counts
#: a turn). Coarser steps are mistakes (a value meant in mm or um given in m), not sensors: at the
#: extreme they measure every leg as zero.
MAX_LEG_RESOLUTION = 1e-2
MAX_TWIST_RESOLUTION = 0.1
#: Largest velocity noise accepted (m/s, rad/s, standard deviation of each differenced velocity):
#: a thousand times what a 1 um encoder differenced at 1 ms gives (1 mm/s); more is a unit mistake.
MAX_VELOCITY_NOISE = 1.0
#: Observers by name.
OBSERVERS = ("none", "momentum")
#: Velocity (and, with the momentum observer, disturbance) estimators by name: encoder differences
#: through the first-order filter (the default), or the model-based Kalman filter.
ESTIMATORS = ("difference", "kalman")
#: Default bandwidth of the Kalman estimator (Hz; measured choice in docs/control.md).
DEFAULT_ESTIMATOR_BANDWIDTH_HZ = 60.0


def kalman_gains(dt: float, bandwidth_hz: float) -> tuple[float, float, float]:
    """Steady-state gains (position, velocity, disturbance) of the estimator's Kalman filter.

    Each joint's state is its position, velocity and an acceleration disturbance that drifts as a
    random walk; the encoder reads the position with the quantisation noise of its step. Only the
    ratio of the process noise to the measurement noise sets the gains, and it is given through the
    bandwidth: ratio ``(2 pi f dt)^6``, whose filter has its three poles near ``2 pi f`` (a
    third-order filter of the encoder positions), so every joint gets the same gains whatever its
    step. From the discrete algebraic Riccati equation (SciPy)."""
    from scipy.linalg import solve_discrete_are

    # in units of the period (state q, v dt, d dt^2) and of the measurement noise
    A = np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
    H = np.array([[1.0, 0.0, 0.0]])
    Q = np.diag([0.0, 0.0, (2.0 * math.pi * bandwidth_hz * dt) ** 6])
    P = solve_discrete_are(A.T, H.T, Q, np.array([[1.0]]))
    L = P @ H.T / (H @ P @ H.T + 1.0)
    return float(L[0, 0]), float(L[1, 0]) / dt, float(L[2, 0]) / (dt * dt)


@dataclass(frozen=True)
class Sensing:
    """The validated observer and sensing settings of one run."""

    observer: str
    observer_gain: float
    force_sensor: bool
    resolution: NDArray[np.float64]
    velocity_noise: float
    velocity_filter_hz: float
    velocity_filter: float
    units: tuple[str, ...] = JOINT_UNITS
    estimator: str = "difference"
    estimator_bandwidth_hz: float = 0.0
    kalman_gain: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def active(self) -> bool:
        """Whether the controller sees measured rather than true joint states."""
        return bool(np.any(self.resolution > 0) or self.velocity_noise > 0)

    @property
    def loop_observer(self) -> str:
        """The loop's observer code name (``vgt_observer``): none, momentum or force."""
        return "force" if self.force_sensor else self.observer

    def loop_fields(self) -> dict[str, Any]:
        """These settings as the compiled loop's settings name them (``LoopSettings``' fields)."""
        return {
            "observer": self.loop_observer,
            "observer_gain": self.observer_gain,
            "sensing": self.active,
            "velocity_filter": self.velocity_filter,
            "estimator": self.estimator,
            "kalman_gain": self.kalman_gain,
        }

    def metadata(self) -> dict[str, object]:
        """Summary entries of these settings."""
        legs = [float(r) for r, unit in zip(self.resolution, self.units, strict=False) if unit == "m"]
        twists = [float(r) for r, unit in zip(self.resolution, self.units, strict=False) if unit == "rad"]
        return {
            "observer": self.observer,
            "observer_gain_per_s": self.observer_gain if self.observer != "none" else None,
            "force_sensor": self.force_sensor,
            "sensing": self.active,
            "encoder_resolution_m": legs[0] if legs else 0.0,
            "twist_resolution_rad": twists[0] if twists else 0.0,
            "velocity_noise": self.velocity_noise,
            "velocity_filter_hz": self.velocity_filter_hz if self.active and self.estimator == "difference" else None,
            **(
                {"estimator": self.estimator, "estimator_bandwidth_hz": self.estimator_bandwidth_hz}
                if self.estimator != "difference"
                else {}
            ),
        }


def _observer_gain(observer: str, observer_gain: float | None, dt: float) -> float:
    """K_O (1/s) of the momentum observer: positive and at most 1/dt (default 0.5/dt); 0 without it."""
    if observer != "momentum":
        if observer_gain is not None:
            raise InputError(f"observer_gain = {observer_gain!r}: only used with observer = 'momentum'")
        return 0.0
    if observer_gain is None:
        observer_gain = DEFAULT_OBSERVER_GAIN_DT / dt
    gain = checks.positive("observer_gain", observer_gain, "1/s")
    if gain * dt > 1.0:
        expected = f"at most 1/dt = {1.0 / dt:g} 1/s (the estimate's time constant must be at least one control period)"
        checks.refuse("observer_gain", observer_gain, expected)
    return gain


def check_twist_resolution(units: tuple[str, ...], twist_resolution: object, name: str = "twist_resolution") -> None:
    """Refuse, in one line naming ``name`` (an argument, or a command-line option ``--...``), a twist
    encoder's resolution given for a robot without a twist joint (``units``: its joint units, none
    ``rad``), where it would be ignored without a word."""
    if twist_resolution is not None and "rad" not in units:
        given = f"{name} {shown(twist_resolution)}" if name.startswith("--") else f"{name} = {shown(twist_resolution)}"
        raise InputError(
            f"{given}: the robot has no twist joint (its {len(units)} joints are legs, in m); expected "
            + ("no twist encoder (leave the option out)" if name.startswith("--") else "None")
        )


def sensing_settings(
    units: tuple[str, ...],
    dt: float,
    observer: str,
    observer_gain: float | None,
    force_sensor: bool,
    encoder_resolution: float,
    twist_resolution: float | None,
    velocity_noise: float,
    velocity_filter_hz: float,
    estimator: str = "difference",
    estimator_bandwidth_hz: float | None = None,
) -> Sensing:
    """Validate the observer and sensing arguments of a run with control period ``dt``.

    ``units`` are the robot's joint units (``m``: a leg, whose encoder has ``encoder_resolution``;
    ``rad``: a twist, ``twist_resolution``, refused on a robot without a twist)."""
    checks.choice("observer", observer, OBSERVERS)
    checks.flag("force_sensor", force_sensor)
    if force_sensor and observer != "none":
        raise InputError(f"force_sensor = True with observer = {observer!r}: choose one way to cancel the tool force")
    gain = _observer_gain(observer, observer_gain, dt)
    legs = checks.number("encoder_resolution", encoder_resolution, minimum=0, unit="m")
    check_twist_resolution(units, twist_resolution)
    twist = DEFAULT_TWIST_RESOLUTION if twist_resolution is None and legs > 0 else twist_resolution or 0.0
    twist = checks.number("twist_resolution", twist, minimum=0, unit="rad")
    for label, step, largest, unit in (
        ("encoder_resolution", legs, MAX_LEG_RESOLUTION, "m"),
        ("twist_resolution", twist, MAX_TWIST_RESOLUTION, "rad"),
    ):
        if step > largest:
            checks.refuse(label, step, f"an encoder step of at most {largest:g} {unit}")
    noise = checks.number("velocity_noise", velocity_noise, minimum=0, unit="m/s, rad/s")
    if noise > MAX_VELOCITY_NOISE:
        expected = f"a standard deviation of at most {MAX_VELOCITY_NOISE:g} (m/s, rad/s) on each differenced velocity"
        checks.refuse("velocity_noise", velocity_noise, expected)
    cutoff = checks.positive("velocity_filter_hz", velocity_filter_hz, "Hz")
    resolution = np.array([legs if unit == "m" else twist for unit in units])
    bandwidth, gains = _estimator(estimator, estimator_bandwidth_hz, dt, resolution, noise)
    return Sensing(
        observer=observer,
        observer_gain=gain,
        force_sensor=bool(force_sensor),
        resolution=resolution,
        velocity_noise=noise,
        velocity_filter_hz=cutoff,
        velocity_filter=math.exp(-2.0 * math.pi * cutoff * dt),
        units=tuple(units),
        estimator=estimator,
        estimator_bandwidth_hz=bandwidth,
        kalman_gain=gains,
    )


#: The options a run's sensing is made of (:func:`sensing_settings`' arguments after the units and
#: the period), read by name from a record by :func:`sensing_of`.
SENSING_OPTIONS = tuple(inspect.signature(sensing_settings).parameters)[2:]


def sensing_of(units: tuple[str, ...], dt: float, record: object) -> Sensing:
    """:func:`sensing_settings` with each of :data:`SENSING_OPTIONS` read from ``record`` (a
    :class:`~vgtarm.simulation.Scenario`, or any record that names them alike)."""
    return sensing_settings(units, dt, **{name: getattr(record, name) for name in SENSING_OPTIONS})


def _estimator(
    estimator: str, bandwidth_hz: float | None, dt: float, resolution: NDArray[np.float64], noise: float
) -> tuple[float, tuple[float, float, float]]:
    """The Kalman estimator's bandwidth (Hz) and gains; 0 and zeros with the differences."""
    checks.choice("estimator", estimator, ESTIMATORS)
    if estimator == "difference":
        if bandwidth_hz is not None:
            raise InputError(f"estimator_bandwidth_hz = {bandwidth_hz!r}: only used with estimator = 'kalman'")
        return 0.0, (0.0, 0.0, 0.0)
    if not np.all(resolution > 0):
        raise InputError(
            "estimator = 'kalman' without encoders: expected encoder_resolution > 0 (the filter "
            "estimates the state from encoder counts)"
        )
    if noise > 0:
        raise InputError(
            f"velocity_noise = {noise!r} with estimator = 'kalman': expected 0 (the estimator reads "
            "positions, not differenced velocities)"
        )
    bandwidth = DEFAULT_ESTIMATOR_BANDWIDTH_HZ if bandwidth_hz is None else bandwidth_hz
    bandwidth = checks.positive("estimator_bandwidth_hz", bandwidth, "Hz")
    if bandwidth * dt > 0.25:
        expected = f"at most 0.25/dt = {0.25 / dt:g} Hz (a quarter of the sampling rate)"
        checks.refuse("estimator_bandwidth_hz", bandwidth, expected)
    return bandwidth, kalman_gains(dt, bandwidth)
