"""What a run is, beside its plant, reference and controller: one frozen, validated record.

:class:`Scenario` holds every option of :func:`vgtarm.simulation.simulate` that describes the
run (the tool force, the controller's model, sensing and the observer, the integrator and its
substeps, the plant engine, the seed, the start transient). It is checked once when built, and
stored whole in the run's ``summary.json`` (key ``scenario``, :meth:`Scenario.record`), so a run
says exactly what it was. Options that need the plant or the reference (the observer's default
gain needs the control period, the encoder steps the robot's joint units, the initial state and
the limit tolerance the robot's joint range) are resolved with them in the simulator.

A new option is one field here, declared with :func:`vgtarm.option.option` (its kind, default,
bounds, unit and help: checked when the record is built), and its use in the simulator; the
command line's flag (``vgtarm simulate``), the study file's parameter and the presets' key follow
from the declaration. A check that needs two options or the plant stays in
:meth:`Scenario.__post_init__` or where it meets the plant.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ..errors import InputError, shown
from ..ga import MAX_SEED
from ..model.parameters import RobotParameters
from ..model.robot import Robot
from ..model.stack import Stack
from ..option import ID_ALWAYS, Option, check_declared, declared, option
from .external import DEFAULT_FEEDFORWARD_SPEED, ExternalForce
from .sensing import (
    DEFAULT_ESTIMATOR_BANDWIDTH_HZ,
    DEFAULT_OBSERVER_GAIN_DT,
    DEFAULT_VELOCITY_FILTER_HZ,
    ESTIMATORS,
    MAX_LEG_RESOLUTION,
    MAX_TWIST_RESOLUTION,
    MAX_VELOCITY_NOISE,
    OBSERVERS,
)

#: Integrators by name.
INTEGRATORS: dict[str, str] = {
    "euler": "explicit Euler at the control period (the paper's)",
    "semi_implicit_euler": "semi-implicit (symplectic) Euler at the control period",
    "rk4": "classical Runge-Kutta, `substeps` steps per control period",
}
#: Most integration steps per control period: a step of dt / 1e6 (1 ns at the paper's 1 ms) is
#: far below any time scale of the robot; more only add round-off and hours of work.
MAX_SUBSTEPS = 1_000_000
#: The plant engine of our own equations (the compiled loop, or its NumPy twin without a compiler).
MODEL_ENGINE = "model"


@dataclass(frozen=True)
class Scenario:
    """The options of one closed-loop run (:func:`vgtarm.simulation.simulate` takes it, or its fields
    as keywords). Each option is declared on its field (:func:`vgtarm.option.option`: kind,
    default, bounds with the unit, help), checked here when the record is built.

    Attributes:
        external_force: the tool force (default: none).
        controller_model: the controller's parameters (default: the plant's, an exact model).
        integrator, substeps: a name of :data:`INTEGRATORS`; integration steps per control period.
        seed: seeds the disturbance, the sensor noise and the genetic algorithm; the same seed gives
            the same run.
        initial_state: ``(q0, qd0)``; default: at rest at ``q_d(0)`` (the paper's start).
        limit_tolerance: distance (m, rad) outside a joint limit at which the run is stopped.
        plant_engine: ``"model"`` (our equations: the compiled loop or its NumPy twin) or a
            registered engine, such as ``"mujoco"`` after ``import vgtarm.mujoco_bridge``: the
            exported MJCF model stepped by MuJoCo (``vgtarm[mujoco]``).
        observer, observer_gain: ``"none"`` or ``"momentum"``: computed force control subtracts the
            estimate of a generalised-momentum disturbance observer with gain K_O (1/s, default
            0.5/dt; the estimate follows the external efforts as ``1 - exp(-K_O t)``; at most 1/dt;
            refused without the observer).
        force_sensor: instead, feed the tool force measured one period late forward through
            ``J_P^T`` (exclusive with ``observer``).
        encoder_resolution, twist_resolution, velocity_noise, velocity_filter_hz: encoder step of
            the legs (m); with it, or with ``velocity_noise``, the controller sees quantised joints
            and velocities from their differences, filtered at ``velocity_filter_hz`` (first order,
            default 100 Hz; the observer takes the unfiltered differences) with Gaussian noise of
            ``velocity_noise`` (m/s, rad/s) on each difference, seeded from ``seed``.
            ``twist_resolution`` (rad) defaults to a 20-bit encoder (2 pi / 2^20) when encoders are
            on.
        estimator, estimator_bandwidth_hz: ``"difference"`` (differenced, filtered encoder counts,
            the default) or ``"kalman"`` (a Kalman filter on the encoder positions with the
            controller model as its process model, tuned by the bandwidth, default 60 Hz; needs
            encoders; docs/control.md).
        transient_s: start transient excluded from the "after transient" figures (s).
        tool_force_feedforward, tool_force_speed: feed the expected cutting force
            (``ExternalForce.expected`` along the reference's tip velocity, smoothed over
            ``tool_force_speed`` m/s, default :data:`~.external.DEFAULT_FEEDFORWARD_SPEED`) forward
            through ``J_P^T``; the observer and the Kalman estimator then estimate only the rest
            (needs the cutting force; exclusive with ``force_sensor``; docs/control.md).
    """

    external_force: ExternalForce = field(default_factory=ExternalForce.none)
    controller_model: RobotParameters | Stack | Robot | None = None
    integrator: str = option(
        "euler",
        str,
        f"one of {sorted(INTEGRATORS)}",
        choices=tuple(sorted(INTEGRATORS)),
        help="plant integrator (default: euler, the paper's)",
        in_id=ID_ALWAYS,
    )
    substeps: int = option(
        1,
        int,
        f"a whole number from 1 to {MAX_SUBSTEPS:,} (steps per control period)",
        low=1,
        high=MAX_SUBSTEPS,
        help=f"integration steps per control period (1 to {MAX_SUBSTEPS:,})",
        in_id=ID_ALWAYS,
    )
    seed: int = option(
        0,
        int,
        f"a whole number from 0 to 2**63 - 1 = {MAX_SEED}",
        low=0,
        high=MAX_SEED,
        help="seed of the disturbance and the GA (default 0; 0 to 2**63 - 1)",
        study=False,  # a study gives its seeds apart (``seeds``)
    )
    initial_state: tuple[Any, Any] | None = None
    limit_tolerance: float = option(
        0.05,
        float,
        "a distance > 0 (m, rad), at most a tenth of the smallest joint range",
        low=0.0,
        strict=True,
        flag="",
        deferred=True,  # the bound is the robot's: checked where the run meets the plant
    )
    observer: str = option(
        "none",
        str,
        f"one of {list(OBSERVERS)}",
        choices=OBSERVERS,
        help="momentum: cancel the external efforts estimated by a generalised-momentum observer",
    )
    observer_gain: float | None = option(
        None,
        float,
        "a finite number > 0 (1/s), at most 1/dt",
        low=0.0,
        strict=True,
        metavar="K",
        needs=("observer", "momentum"),
        help=f"with --observer momentum: its gain K_O in 1/s (default {DEFAULT_OBSERVER_GAIN_DT:g}/dt; at most 1/dt)",
    )
    force_sensor: bool = option(
        False, bool, "True or False", help="feed the tool force measured one period late forward"
    )
    encoder_resolution: float = option(
        0.0,
        float,
        f"an encoder step >= 0 (m), at most {MAX_LEG_RESOLUTION:g} m",
        low=0.0,
        metavar="R",
        help="encoder step of the legs in m (e.g. 1e-6); the twist gets a 20-bit encoder",
    )
    twist_resolution: float | None = option(
        None,
        float,
        f"an encoder step > 0 (rad), at most {MAX_TWIST_RESOLUTION:g} rad",
        low=0.0,
        flag="",  # vgtarm simulate gives the twist a 20-bit encoder; vgtarm export controller takes it
        metavar="RAD",
        help="encoder step of the twist in rad (default with --encoder-resolution: a 20-bit encoder)",
    )
    velocity_noise: float = option(
        0.0,
        float,
        f"a standard deviation >= 0 (m/s, rad/s), at most {MAX_VELOCITY_NOISE:g}",
        low=0.0,
        metavar="S",
        help="standard deviation of Gaussian noise on each differenced velocity (m/s, rad/s)",
    )
    velocity_filter_hz: float = option(
        DEFAULT_VELOCITY_FILTER_HZ,
        float,
        "a cut-off > 0 (Hz)",
        low=0.0,
        strict=True,
        flag="--velocity-filter",
        metavar="HZ",
        help=f"cut-off of the velocity filter with sensing (default {DEFAULT_VELOCITY_FILTER_HZ:g} Hz)",
    )
    plant_engine: str = option(
        MODEL_ENGINE,
        str,
        "a name of a plant engine ('model', 'mujoco' or one registered)",
        flag="--plant",
        metavar="{model,mujoco}",
        help="what integrates the robot: our model (default) or MuJoCo on the exported MJCF (vgtarm[mujoco])",
    )
    transient_s: float = option(0.2, float, "a duration >= 0 (s)", low=0.0, flag="")
    estimator: str = option(
        "difference",
        str,
        f"one of {list(ESTIMATORS)}",
        choices=ESTIMATORS,
        help="with encoders: velocities from differences through the filter (default), or a Kalman filter "
        "with the controller model's dynamics (and, with the observer, the disturbance) as its process model",
    )
    estimator_bandwidth_hz: float | None = option(
        None,
        float,
        "a finite number > 0 (Hz), at most 0.25/dt",
        low=0.0,
        strict=True,
        flag="--estimator-bandwidth",
        metavar="HZ",
        needs=("estimator", "kalman"),
        help=f"--estimator kalman: its bandwidth (default {DEFAULT_ESTIMATOR_BANDWIDTH_HZ:g} Hz, at most 1/(4 dt))",
    )
    tool_force_feedforward: bool = option(
        False,
        bool,
        "True or False",
        flag="--tool-feedforward",
        help="with --external-force: feed the expected cutting force (its model along the reference's tip "
        "velocity) forward through J_P^T; the observer and the Kalman estimator estimate the rest",
    )
    tool_force_speed: float | None = option(
        None,
        float,
        "a speed > 0 (m/s)",
        low=0.0,
        strict=True,
        metavar="V",
        needs=("tool_force_feedforward", True),
        help="--tool-feedforward: speed in m/s over which the expected force is smoothed where the tool starts, "
        f"turns or stops (default {DEFAULT_FEEDFORWARD_SPEED:g})",
    )

    def __post_init__(self) -> None:
        if self.external_force is None:  # the keyword form's default
            object.__setattr__(self, "external_force", ExternalForce.none())
        if not isinstance(self.external_force, ExternalForce):
            raise InputError(
                f"external_force = {shown(self.external_force)}: expected None or a vgtarm.simulation.ExternalForce"
            )
        if self.controller_model is not None and not isinstance(self.controller_model, Robot | RobotParameters | Stack):
            raise InputError(
                f"controller_model = {shown(self.controller_model)}: expected None, a Robot, RobotParameters or a Stack"
            )
        check_declared(self)  # each option's kind, bounds and choices (vgtarm.option)
        self._check_feedforward()

    def _check_feedforward(self) -> None:
        feedforward, speed = self.tool_force_feedforward, self.tool_force_speed
        if speed is not None and not feedforward:
            raise InputError(
                f"tool_force_speed = {shown(speed)} without tool_force_feedforward: it smooths the force fed forward"
            )
        if not feedforward:
            return
        if not self.external_force.cutting:
            raise InputError(
                "tool_force_feedforward = True without the cutting force: it feeds the expected cutting force "
                "forward (external_force with cutting=True)"
            )
        if self.force_sensor:
            raise InputError(
                "tool_force_feedforward = True with force_sensor = True: the sensor feeds the whole measured "
                "tool force forward already; choose one"
            )

    @property
    def feedforward_speed(self) -> float:
        """The smoothing speed of the expected tool force fed forward (m/s): given or the default."""
        return DEFAULT_FEEDFORWARD_SPEED if self.tool_force_speed is None else float(self.tool_force_speed)

    @classmethod
    def of(cls, scenario: Scenario | None, options: Mapping[str, Any]) -> Scenario:
        """``scenario``, or the one the keyword ``options`` describe (not both).

        An unknown keyword is refused with the list of the valid ones.
        """
        if scenario is not None:
            if not isinstance(scenario, Scenario):
                raise InputError(f"scenario = {shown(scenario)}: expected None or a vgtarm.simulation.Scenario")
            if options:
                raise InputError(
                    f"simulate got a scenario and the options {sorted(options)}: give the options in the "
                    "scenario (dataclasses.replace(scenario, ...)) or as keywords, not both"
                )
            return scenario
        unknown = sorted(set(options) - set(cls.option_names()))
        if unknown:
            raise InputError(
                f"simulate got the unknown option {unknown[0]!r}: expected one of {list(cls.option_names())}"
                " (or metadata, progress)"
            )
        return cls(**options)

    @classmethod
    def options(cls) -> dict[str, Option]:
        """The scalar options of a run, declared once (:mod:`vgtarm.option`), by name, in order."""
        return declared(cls)

    @classmethod
    def option_names(cls) -> tuple[str, ...]:
        """The names of the options, in their order."""
        return tuple(f.name for f in fields(cls))

    def replace(self, **changes: Any) -> Scenario:
        """A copy with ``changes`` (validated again)."""
        return dataclasses.replace(self, **changes)

    def record(self) -> dict[str, Any]:
        """The scenario as JSON values, as stored in ``summary.json``: the tool force's fields, the
        controller model's name (``None``: the plant's), the initial state as lists, and with the
        feedforward the smoothing speed it used."""
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "external_force":
                value = {key: _plain(v) for key, v in dataclasses.asdict(value).items()}
            elif f.name == "controller_model":
                value = None if value is None else _model_name(value)
            elif f.name == "tool_force_speed" and self.tool_force_feedforward:
                value = self.feedforward_speed  # the speed used, not "the default", which has changed before
            else:
                value = _plain(value)
            out[f.name] = value
        return out

    @classmethod
    def from_record(
        cls, record: Mapping[str, Any], controller_model: RobotParameters | Stack | Robot | None = None
    ) -> Scenario:
        """The scenario a :meth:`record` describes (as read from a run's ``summary.json``), to run
        it again. The record keeps only the controller model's name: pass the model itself as
        ``controller_model`` (``None``: the plant's own). An unknown field is refused in one line."""
        if not isinstance(record, Mapping):
            raise InputError(f"scenario record = {shown(record)}: expected a mapping of scenario fields")
        unknown = sorted(set(record) - set(cls.option_names()))
        if unknown:
            raise InputError(f"scenario record field {unknown[0]!r}: expected one of {list(cls.option_names())}")
        values = {key: value for key, value in record.items() if key != "controller_model"}
        force = values.get("external_force")
        if isinstance(force, Mapping):
            fixed: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in force.items()}
            try:
                values["external_force"] = ExternalForce(**fixed)
            except TypeError as exc:
                raise InputError(f"scenario record field 'external_force' = {shown(force)}: {exc}") from None
        state = values.get("initial_state")
        if isinstance(state, list):
            values["initial_state"] = tuple(np.asarray(part, dtype=float) for part in state)
        return cls(**values, controller_model=controller_model)


def senses(values: Mapping[str, Any]) -> bool:
    """Whether the options ``values`` (by name, as a Scenario's fields) give the controller
    measured rather than true joint states: encoders on the legs or noise on the velocities. The
    velocity filter applies only then (:attr:`~.sensing.Sensing.active` of the resolved run)."""
    return bool(values.get("encoder_resolution") or values.get("velocity_noise"))


def _model_name(model: RobotParameters | Stack | Robot) -> str:
    return str(model.parameters.name if isinstance(model, Robot) else model.name)


def _plain(value: Any) -> Any:
    """``value`` as JSON values (tuples and arrays as lists, NumPy scalars as Python's)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value
