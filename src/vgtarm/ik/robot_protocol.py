"""What inverse kinematics needs from a robot (a structural type, so ``ik`` never imports ``robot``)."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..model.compiled import Backend
from ..model.parameters import RobotParameters


class HasRotation(Protocol):
    """A forward-kinematics record: only the end-effector orientation is used."""

    @property
    def rotation(self) -> NDArray[np.float64]:
        """``(..., 3, 3)`` orientation ``C03`` of the end-effector."""
        ...


class RobotLike(Protocol):
    """The parts of :class:`vgtarm.Robot` that inverse kinematics uses."""

    @property
    def parameters(self) -> RobotParameters:
        """Dimensions, joint limits and home pose."""
        ...

    @property
    def backend(self) -> Backend:
        """The compiled (or interpreted) model functions."""
        ...

    @property
    def parameter_vector(self) -> NDArray[np.float64]:
        """The flat parameter vector given to the compiled functions."""
        ...

    def tip_position(self, q: ArrayLike) -> NDArray[np.float64]:
        """Tip point ``(..., 3)`` (m)."""
        ...

    def forward_kinematics(self, q: ArrayLike) -> HasRotation:
        """Forward kinematics record with the end-effector orientation."""
        ...
