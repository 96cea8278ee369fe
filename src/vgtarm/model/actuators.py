"""Actuators: each joint's peak force, no-load speed, acceleration limit and force-speed line.

A robot file may give its actuators in an ``[actuators]`` table (both file formats)::

    [actuators]
    legs = { force = 60.0, speed = 0.05 }             # every leg: peak force (N), no-load speed (m/s)
    twists = { force = 2.0, speed = 3.0 }             # every twist joint (N m, rad/s)
    p1 = { force = 90.0, acceleration = 1.5, force_speed = true }   # one joint: overrides its group

A joint's entry takes the keys of its group (``legs`` or ``twists``) and replaces those it names.
Every actuator has a ``force`` (its peak or stall force, N, or N m for a twist) and a ``speed`` (its
no-load speed, m/s or rad/s), both > 0; ``acceleration`` (m/s^2, rad/s^2) is optional, a limit for
planning (:func:`vgtarm.retime`, ``vgtarm check path``); ``force_speed = true`` adds the
force-speed line of a motor and lead screw. A joint that neither its group nor its own entry
covers has no actuator limits. A file without the table has none (every run of the paper is as
before).

**The limits.** Without the line an actuator delivers ``|F| <= force`` at any speed; its ``speed`` is
a limit for planning, which the plant does not enforce. With the line it is a DC motor whose
voltage is bounded: a current (force) limit ``|F| <= F_s`` and a back-EMF that takes force away in
the direction of motion, ``F sign(v) <= F_s (1 - |v| / v_max)``, so it cannot drive past its
no-load speed ``v_max``. Braking (a force against the motion) keeps the full ``F_s``: the
physics of the motor, and the issue's symmetric ``|F| <= F_s (1 - |v|/v_max)`` in the motoring
quadrants, where it binds (see ``docs/conventions.md``). So at a velocity ``v`` the force lies in

    [-F_s min(1, 1 + v / v_max), F_s min(1, 1 - v / v_max)]   (each end clipped to [-F_s, F_s])

which :meth:`Actuators.bounds` gives and :meth:`Actuators.saturate` clips to.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..errors import ConfigError, cut

#: Largest peak force (N, N m) and speed (m/s, rad/s) and acceleration accepted: far beyond any
#: actuator, they keep every product of the limits finite.
MAX_FORCE = 1e9
MAX_SPEED = 1e6
MAX_ACCELERATION = 1e9
#: The group of a joint's kind: a leg (m) or a twist (rad).
GROUPS = ("legs", "twists")
_KEYS = ("force", "speed", "acceleration", "force_speed")
_SOURCE_LENGTH = 200

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Actuator:
    """One joint's actuator: ``force`` (N, N m), ``speed`` (m/s, rad/s), ``acceleration`` (m/s^2,
    rad/s^2; ``inf``: none) and whether the force-speed line holds (``force_speed``)."""

    force: float
    speed: float
    acceleration: float = math.inf
    force_speed: bool = False


@dataclass(frozen=True)
class Actuators:
    """The actuators of a robot's joints, in the order of ``q`` (``None``: a joint without limits).

    ``names`` are the joint names (for messages); the arrays have ``inf`` (no limit) where a joint
    has no actuator, and ``force_speed`` is false there."""

    names: tuple[str, ...]
    joints: tuple[Actuator | None, ...]
    #: Per joint, the table of the file its force came from (``legs``, ``twists`` or its own name):
    #: what a refusal names. Empty: the joint names.
    origins: tuple[str, ...] = field(default=(), compare=False)

    def __post_init__(self) -> None:
        if len(self.names) != len(self.joints):
            raise ConfigError(f"actuators: {len(self.joints)} entries for {len(self.names)} joints")
        if not all(a is None or isinstance(a, Actuator) for a in self.joints):
            raise ConfigError(f"actuators: expected an Actuator or None per joint, got {self.joints!r:.200}")

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    def _array(self, name: str, default: float) -> Array:
        values = [default if a is None else float(getattr(a, name)) for a in self.joints]
        array = np.array(values, dtype=float)
        array.flags.writeable = False
        return array

    @property
    def force(self) -> Array:
        """Peak force of each joint, ``(n,)`` (``inf``: none)."""
        return self._array("force", math.inf)

    @property
    def speed(self) -> Array:
        """No-load speed of each joint, ``(n,)`` (``inf``: none)."""
        return self._array("speed", math.inf)

    @property
    def acceleration(self) -> Array:
        """Acceleration limit of each joint, ``(n,)`` (``inf``: none)."""
        return self._array("acceleration", math.inf)

    @property
    def force_speed(self) -> NDArray[np.bool_]:
        """Whether each joint's force-speed line holds, ``(n,)``."""
        return np.array([a is not None and a.force_speed for a in self.joints], dtype=bool)

    @property
    def limited(self) -> NDArray[np.bool_]:
        """Whether each joint has an actuator, ``(n,)``."""
        return np.array([a is not None for a in self.joints], dtype=bool)

    def bounds(self, qd: ArrayLike) -> tuple[Array, Array]:
        """The lowest and highest force each actuator can give at the joint velocities ``qd``
        ``(..., n)``: ``(lower, upper)``, each ``(..., n)`` (see the module docstring)."""
        return effort_bounds(self.force, self.speed, self.force_speed, np.asarray(qd, dtype=float))

    def saturate(self, F: ArrayLike, qd: ArrayLike) -> Array:
        """The forces ``F`` ``(..., n)`` clipped to what the actuators give at ``qd``."""
        lower, upper = self.bounds(qd)
        return np.minimum(np.maximum(np.asarray(F, dtype=float), lower), upper)

    def utilisation(self, F: ArrayLike, qd: ArrayLike) -> Array:
        """How much of its limit each effort ``F`` ``(..., n)`` uses at ``qd``: ``|F|`` over the limit in
        its own direction, and past a limit ``1 +`` the excess over the peak force; so it is at most 1
        exactly when ``F`` is within the bounds (0 for a joint without an actuator)."""
        Fa = np.asarray(F, dtype=float)
        lower, upper = self.bounds(qd)
        limit = np.where(Fa >= 0.0, upper, -lower)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(limit > 0.0, np.abs(Fa) / limit, np.where(Fa == 0.0, 0.0, np.inf))
            excess = np.maximum(lower - Fa, Fa - upper) / self.force
        outside = (Fa < lower) | (Fa > upper)  # beyond the no-load speed the bounds need not hold 0
        ratio = np.where(outside, np.maximum(ratio, 1.0 + excess), ratio)
        return np.where(self.limited, ratio, 0.0)

    def entries(self) -> dict[str, dict[str, Any]]:
        """The actuators as the ``[actuators]`` table of a robot file, one entry per joint."""
        table: dict[str, dict[str, Any]] = {}
        for name, a in zip(self.names, self.joints, strict=True):
            if a is None:
                continue
            entry: dict[str, Any] = {"force": a.force, "speed": a.speed}
            if math.isfinite(a.acceleration):
                entry["acceleration"] = a.acceleration
            if a.force_speed:
                entry["force_speed"] = True
            table[name] = entry
        return table


def effort_bounds(force: Array, speed: Array, line: ArrayLike, v: Array) -> tuple[Array, Array]:
    """``(lower, upper)`` force bounds at the joint velocities ``v`` ``(..., n)`` of actuators of peak
    ``force``, no-load ``speed`` and force-speed ``line`` (nonzero: it holds), each ``(n,)``: the
    arithmetic of ``vgt_saturate`` (``vgt_control.h``), operation for operation, so the NumPy loop
    and the compiled one clip to the same bits."""
    on = np.asarray(line) != 0
    with np.errstate(invalid="ignore"):  # inf * 0 where a joint has no actuator: not selected below
        upper = np.where(on, np.maximum(force * np.minimum(1.0, 1.0 - v / speed), -force), force)
        lower = np.where(on, np.minimum(-force * np.minimum(1.0, 1.0 + v / speed), force), -force)
    return lower, upper


def _group(name: str) -> str:
    return "twists" if name.startswith("psi") else "legs"


def _units(name: str) -> tuple[str, str, str]:
    return ("N m", "rad/s", "rad/s^2") if name.startswith("psi") else ("N", "m/s", "m/s^2")


def read_actuators(table: object, names: Sequence[str], source: str) -> Actuators:
    """The ``[actuators]`` table of a robot file whose joints are ``names``; every bad entry is
    refused with one :class:`ConfigError` line naming the field (``actuators.p1.force``)."""
    where = f"{cut(str(source), _SOURCE_LENGTH)}: field 'actuators"
    if not isinstance(table, Mapping):
        checks.refuse(f"{where}'", table, "a table of joints and groups (legs, twists)", ConfigError)
    known = set(GROUPS) | set(names)
    for key in table:
        if key not in known:
            raise ConfigError(
                f"{cut(str(source), _SOURCE_LENGTH)}: unknown key 'actuators.{cut(str(key))}'; expected a "
                f"joint ({', '.join(names[:8])}{', ...' if len(names) > 8 else ''}) or a group (legs, twists)"
            )
    for key, entry in table.items():
        if not isinstance(entry, Mapping):
            checks.refuse(f"{where}.{key}'", entry, f"a table with keys {', '.join(_KEYS)}", ConfigError)
        for field_name in entry:
            if field_name not in _KEYS:
                raise ConfigError(
                    f"{cut(str(source), _SOURCE_LENGTH)}: unknown key 'actuators.{key}.{cut(str(field_name))}'; "
                    f"expected one of {list(_KEYS)}"
                )
    joints: list[Actuator | None] = []
    origins: list[str] = []
    for name in names:
        group = _group(name)
        merged = {**table.get(group, {}), **table.get(name, {})}
        own = table.get(name, {})
        origins.append(name if "force" in own or group not in table else group)
        if not merged:
            joints.append(None)
            continue
        joints.append(_actuator(merged, name, group, own, where))
    return Actuators(names=tuple(names), joints=tuple(joints), origins=tuple(origins))


def _actuator(entry: Mapping[str, Any], name: str, group: str, own: Mapping[str, Any], where: str) -> Actuator:
    """One joint's actuator from its merged entry (its group's keys, then its ``own``); a refusal
    names the table each value came from."""
    force_unit, speed_unit, acceleration_unit = _units(name)

    def given(key: str) -> str:
        """The field of ``key``, with the joint when it comes from the group (its first joint)."""
        return f"{name}.{key}'" if key in own else f"{group}.{key}' (joint {name})"

    for key in ("force", "speed"):
        if key not in entry:
            raise ConfigError(
                f"{where.split(': field')[0]}: missing key 'actuators.{name}.{key}' "
                f"(joint {name} needs a force and a speed, in its own entry or its group's, {group})"
            )
    force = checks.number(
        f"{where}.{given('force')}",
        entry["force"],
        above=0,
        maximum=MAX_FORCE,
        unit=force_unit,
        error=ConfigError,
    )
    speed = checks.number(
        f"{where}.{given('speed')}",
        entry["speed"],
        above=0,
        maximum=MAX_SPEED,
        unit=speed_unit,
        error=ConfigError,
    )
    acceleration = math.inf
    if "acceleration" in entry:
        acceleration = checks.number(
            f"{where}.{given('acceleration')}",
            entry["acceleration"],
            above=0,
            maximum=MAX_ACCELERATION,
            unit=acceleration_unit,
            error=ConfigError,
        )
    line = checks.flag(f"{where}.{given('force_speed')}", entry.get("force_speed", False), error=ConfigError)
    return Actuator(force=force, speed=speed, acceleration=acceleration, force_speed=line)


def check_holding(actuators: Actuators, holding: Array, source: str) -> None:
    """Refuse an actuator weaker than the force ``holding`` ``(n,)`` that keeps the robot still at
    home (gravity): one line naming the joint's field."""
    origins = actuators.origins or actuators.names
    for name, given, a, need in zip(actuators.names, origins, actuators.joints, holding, strict=True):
        if a is not None and a.force < abs(float(need)):
            unit = _units(name)[0]
            checks.refuse(
                f"{cut(str(source), _SOURCE_LENGTH)}: field 'actuators.{given}.force'",
                a.force,
                f"at least {abs(float(need)):.6g} {unit}, the force that holds the robot still at home "
                f"(joint {name}; its group's value or its own)",
                ConfigError,
            )


__all__ = ["Actuator", "Actuators", "check_holding", "read_actuators"]
