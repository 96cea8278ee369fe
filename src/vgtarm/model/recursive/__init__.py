"""The recursive model of any stack of VGT modules: O(n) per sample, nothing compiled per arm.

A module is a three-degree-of-freedom joint (:mod:`.joint`: its pose, motion subspace and bias,
derived once by automatic differentiation of the one module solution and generated to C), a
twist stage a revolute joint; the C loops of ``csrc/vgt_rec.c`` run Featherstone's algorithms
over the chain (forward kinematics and Jacobians, composite rigid bodies for ``M``, recursive
Newton-Euler for inverse dynamics and ``C``, articulated bodies for forward dynamics), the arm
being data (:class:`RecursiveModel`). One library (:mod:`.library`) serves every arm.
:func:`vgtarm.model.robot.recursive_robot` (or ``load_robot(path, model="recursive")``) gives a
:class:`~vgtarm.model.robot.Robot` on it (:mod:`.backend`).
"""

from .backend import RecursiveBackend, stack_from_vector
from .model import RecursiveModel, spatial_inertia

__all__ = ["RecursiveBackend", "RecursiveModel", "spatial_inertia", "stack_from_vector"]
