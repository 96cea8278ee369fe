"""Checks of what a simulation is given, before it runs: each refusal is one line naming the value.

- the reference must be the plant's: the plant's kinematics must put the tip of the reference
  joints on the reference's desired tip path (within :data:`REFERENCE_TIP_TOLERANCE`), otherwise
  a run reports small errors about a path the tool does not follow;
- the initial state must be a configuration of the plant (shape, finite, in the accepted range,
  assemblable): a bad one is a bad input, not a divergence;
- ``limit_tolerance`` must be a positive distance that keeps the run inside the accepted range;
- the controller's model must be a model of the plant: its total mass, inertia and friction
  within :data:`~vgtarm.model.factors.MODEL_FACTOR_RANGE` of the plant's (a ratio, named with its
  value and the range, never "not finite");
- every other argument of ``simulate`` must have the right type (one line, not a ``TypeError``);
  the scenario's own fields are checked by :class:`~vgtarm.simulation.scenario.Scenario`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..checks import number as check_number
from ..errors import InputError, VgtarmError, escape, shown
from ..model.factors import MODEL_FACTOR_RANGE
from ..model.parameters import RobotParameters
from ..model.robot import Robot
from ..model.sanity import (
    RANGE_REASONS,
    as_float,
    check_input,
    check_joint_range,
    real_array,
    user_finite,
)
from ..model.stack import Stack
from .reference import JointReference

Array = NDArray[np.float64]

#: Largest distance (m) between the plant's tip at the reference joints and the reference's
#: desired tip. Inverse kinematics verifies its samples to 1e-10 m, so anything above this
#: means the joints were solved for other kinematics (another robot).
REFERENCE_TIP_TOLERANCE = 1e-6


def reference_tip(plant: Robot, reference: JointReference) -> Array:
    """The plant's tip along the reference joints ``(N, 3)`` (m), checked against the reference.

    Raises :class:`InputError` if the reference joints are not configurations of the plant, or if
    the reference carries its desired tip path and the plant's tip strays more than
    :data:`REFERENCE_TIP_TOLERANCE` from it; the message names the robot it was solved for.
    """
    try:
        tip = plant.tip_position(reference.q)
    except VgtarmError as error:
        raise InputError(
            f"reference {escape(reference.name)!r} is not a motion of this plant: {error}{_robots(plant, reference)}"
        ) from None
    if reference.tip is None:
        return tip
    gap = np.linalg.norm(tip - np.asarray(reference.tip, dtype=float), axis=1)
    worst = int(np.argmax(gap))
    if gap[worst] > REFERENCE_TIP_TOLERANCE:
        raise InputError(
            f"reference {escape(reference.name)!r}: the plant's tip at its joints is {gap[worst] * 1e3:.3g} mm from "
            f"its desired tip at t = {float(reference.t[worst]):.6g} s (at most {REFERENCE_TIP_TOLERANCE:g} m "
            f"expected){_robots(plant, reference)}; solve the inverse kinematics on the plant's robot"
        )
    return tip


def _robots(plant: Robot, reference: JointReference) -> str:
    """``"; solved for robot 'A' (fingerprint), simulating robot 'B' (fingerprint)"``, where known."""
    here = f"robot {shown(plant.parameters.name)} ({plant.fingerprint})"
    if not reference.robot and not reference.robot_fingerprint:
        return f"; simulating {here}"
    there = f"robot {shown(reference.robot)} ({reference.robot_fingerprint or 'fingerprint unknown'})"
    return f"; solved for {there}, simulating {here}"


def initial_state(plant: Robot, reference: JointReference, state: Any) -> tuple[Array, Array]:
    """The run's initial ``(q0, qd0)`` ``(n,)`` each: rest at ``q_d(0)`` for ``None``, else ``state``
    checked as a configuration of the plant (:class:`InputError` / ``AssemblyError`` otherwise)."""
    n = reference.q.shape[1]
    if state is None:
        return np.asarray(reference.q[0], dtype=float), np.zeros(n)
    if isinstance(state, str | bytes) or not hasattr(state, "__len__") or len(state) != 2:
        raise InputError(f"initial_state = {shown(state)}: expected a pair (q0, qd0) of {n} joint values each")
    arrays = []
    for label, value in zip(("q0", "qd0"), state, strict=True):
        name = f"initial_state {label}"
        if isinstance(value, str | bytes):
            raise InputError(f"{name} = {shown(value)}: expected {n} numbers")
        try:
            shape = np.shape(value)
        except (TypeError, ValueError, RecursionError):  # ragged nesting
            raise InputError(f"{name} = {shown(value)}: expected {n} numbers") from None
        if shape != (n,):
            raise InputError(f"{name}: expected shape ({n},), got {shape}")
        raw = real_array(value, name, n, plant.joint_names)  # complex, None, booleans, text: one line each
        array = as_float(raw)
        if not np.isfinite(array).all():
            i = int(np.argwhere(~np.isfinite(array))[0][0])
            user = raw[i].item() if isinstance(raw[i], np.generic) and raw.dtype != np.longdouble else raw[i]
            if not user_finite(user):  # a whole number too large for a float is refused as out of range below
                raise InputError(f"{name}[{i}] = {shown(user)}: expected a finite number")
        arrays.append((array, raw))
    (q0, raw_q0), (qd0, raw_qd0) = arrays
    check_joint_range(q0, plant.parameters, plant.joint_range(), where="initial_state q0", raw=raw_q0)
    plant.check_assembly(q0, where="initial_state q0")
    units = tuple(f"{unit}/s" for unit in plant.joint_units)
    qd_range = plant.input_ranges()["qd"]
    check_input(qd0, "initial_state qd0", qd_range, plant.joint_names, units, raw=raw_qd0, explain=RANGE_REASONS["qd"])
    return q0, qd0


def limit_tolerance(plant: Robot, value: Any) -> float:
    """``value`` checked as the run's ``limit_tolerance`` (m, rad): finite, > 0, and small enough
    that a run stopped that far outside the limits is still inside the accepted joint range."""
    low, high = plant.joint_range()
    largest = float(min((plant.parameters.lower - low).min(), (high - plant.parameters.upper).min()))
    expected = (
        f"a distance in (0, {largest:.6g}] (m, rad) outside the joint limits at which a run is stopped (nan or inf"
        " would never stop a diverging run)"
    )
    return check_number("limit_tolerance", value, above=0, maximum=largest, expected=expected)


def arguments(plant: Any, controller_model: Any, metadata: Any, progress: Any) -> None:
    """Refuse, with one :class:`InputError` line, arguments of ``simulate`` of the wrong type (the
    scenario's fields are checked when the :class:`~vgtarm.simulation.Scenario` is built), and a
    controller model that is no model of the plant (:func:`model_of_plant`)."""
    if not isinstance(plant, Robot):
        raise InputError(f"plant = {shown(plant)}: expected a vgtarm.Robot (see vgtarm.load_robot)")
    if controller_model is not None:
        model_of_plant(plant, controller_model)
    if metadata is not None and not isinstance(metadata, Mapping):
        raise InputError(f"metadata = {shown(metadata)}: expected None or a mapping of summary entries")
    if progress is not None and not callable(progress):
        raise InputError(f"progress = {shown(progress)}: expected None or a callable progress(done, total)")


def gains(plant: Robot, Kp: Array) -> None:
    """Refuse, with one :class:`InputError` line, gains sized for another number of joints."""
    if Kp.shape != (plant.n_joints, plant.n_joints):
        raise InputError(
            f"the controller's gains are {Kp.shape[0]}x{Kp.shape[1]}, but robot {shown(plant.parameters.name)} has "
            f"{plant.n_joints} joints (give gains for its joints, e.g. ComputedForceControl.with_gains(kp, kv, "
            f"{plant.n_joints}))"
        )


def _totals(parameters: RobotParameters | Stack) -> dict[str, float]:
    """Total mass (kg), inertia (sum of the bodies' traces, kg m^2) and viscous friction of a robot."""
    bodies = parameters.bodies
    return {
        "mass": float(sum(body.mass for body in bodies)),
        "inertia": float(sum(np.trace(np.asarray(body.inertia, dtype=float)) for body in bodies)),
        "friction": float(np.sum(parameters.viscous)),
    }


def model_of_plant(
    plant: Robot | RobotParameters | Stack,
    controller_model: Robot | RobotParameters | Stack,
    name: str = "controller_model",
) -> None:
    """Refuse, with one :class:`InputError` line, a controller model whose total mass, inertia or
    friction is not within :data:`~vgtarm.model.factors.MODEL_FACTOR_RANGE` of the plant's (for
    example a model of a ten-thousandth of the plant's mass): the line names the ratio and the
    accepted range, after ``name``. The plant and the model: robots or their parameters (nothing
    is built)."""
    model = controller_model.parameters if isinstance(controller_model, Robot) else controller_model
    plant_parameters = plant.parameters if isinstance(plant, Robot) else plant
    low, high = MODEL_FACTOR_RANGE
    ours, theirs = _totals(plant_parameters), _totals(model)
    for quantity, value in theirs.items():
        reference = ours[quantity]
        if reference == 0.0:  # nothing to compare with (a robot without friction)
            continue
        ratio = value / reference
        if not low * (1 - 1e-9) <= ratio <= high * (1 + 1e-9):
            raise InputError(
                f"{name}: its {quantity} is {ratio:.3g} times the plant's (robot "
                f"{shown(plant_parameters.name)}); expected a ratio in [{low:g}, {high:g}] (a model off by more "
                "is no model of the plant)"
            )
