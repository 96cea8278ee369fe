"""The accepted range of joint values: a generous widening of the joint limits.

The model's formulas are defined far beyond the joint limits, but values far beyond them are
never a real configuration: with legs of 1e20 m the tip lands 6 km away, with 1e300 m every
product overflows to NaN, and a twist of 1e20 rad has lost every digit of its angle. The public
methods of :class:`~vgtarm.model.robot.Robot` therefore refuse joint values outside

- lengths (joints in metres): ``[max(0, q_min - w), q_max + w]`` with
  ``w = SANE_WIDENING * (q_max - q_min)``;
- angles (joints in radians): ``[q_min - t, q_max + t]`` with ``t = SANE_TURNS`` full turns.

For the reference robot that is legs in ``[0, 1.76]`` m (limits 0.22..0.36 m; ``[0, 2.06]`` m for
the diagonals, limits 0.30..0.46 m) and a twist within about +-6286 rad. The twist gets turns
rather than spans because it is a revolute joint that can spin freely (a free motion of the
model winds it up by tens of radians; its angle keeps 1e-12 rad resolution at 6000 rad).
Everything a controller or a solver legitimately visits (limits overshot by millimetres, a run
stopped ``limit_tolerance`` outside) lies far inside.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, shown
from .parameters import RobotParameters

if TYPE_CHECKING:
    from .stack.description import Stack

Array = NDArray[np.float64]

#: Width of the accepted band on each side of a length's limits, in multiples of its span.
SANE_WIDENING = 10.0
#: Width of the accepted band on each side of an angle's limits, in full turns.
SANE_TURNS = 1000.0


def sane_range(parameters: RobotParameters | Stack) -> tuple[Array, Array]:
    """Lowest and highest accepted value of each joint, ``(n,)`` each (m, rad)."""
    lower, upper = parameters.lower, parameters.upper
    lengths = np.array([unit == "m" for unit in parameters.joint_units[: len(lower)]])
    width = np.where(lengths, SANE_WIDENING * (upper - lower), SANE_TURNS * 2.0 * np.pi)
    low = lower - width
    low[lengths] = np.maximum(low[lengths], 0.0)
    return low, upper + width


def check_joint_range(
    q: Array, parameters: RobotParameters | Stack, bounds: tuple[Array, Array], *, where: str = "q"
) -> None:
    """Raise :class:`InputError` if a joint value of ``q`` ``(..., n)`` lies outside ``bounds``
    (``sane_range(parameters)``, passed in so callers can keep it).

    The message names the first offending joint (paper name), its value, the accepted range, the
    joint's limits and, for a batch, the configuration's index.
    """
    low, high = bounds
    outside = (q < low) | (q > high)
    if not outside.any():
        return
    index = tuple(int(i) for i in np.argwhere(outside)[0])
    joint = index[-1]
    names, units = parameters.joint_names, parameters.joint_units
    name = names[joint] if joint < len(names) else f"joint {joint}"
    unit = units[joint] if joint < len(units) else ""
    location = f" (configuration {index[:-1]})" if len(index) > 1 else ""
    raise InputError(
        f"{where}: {name} = {shown(float(q[index]))} {unit}{location} is outside the accepted range "
        f"[{low[joint]:.6g}, {high[joint]:.6g}] {unit}, far beyond its limits "
        f"[{parameters.q_min[joint]:.6g}, {parameters.q_max[joint]:.6g}] (not a configuration of this robot)"
    )
