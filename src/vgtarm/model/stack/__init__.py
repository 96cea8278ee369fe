"""Robots made of any stack of planar VGT modules: the description (:mod:`.description`), its
symbolic kinematics and dynamics for ``n`` joints (:mod:`.symbolic`) and their numerical
evaluation (:mod:`.model`).

The fixed 7-joint model (:mod:`vgtarm.model.symbolic`, the compiled backend and
:class:`~vgtarm.model.robot.Robot`) is unchanged; :func:`stack_from_parameters` describes it as
a stack whose model gives the same numbers.
"""

from .description import (
    Stack,
    StackModule,
    Twist,
    load_stack,
    parameters_to_toml,
    reference_stack,
    robot_to_toml,
    stack_from_dict,
    stack_from_parameters,
    stack_margins,
    stack_to_toml,
)
from .model import StackForwardKinematics, StackModel
from .symbolic import StackDynamics, StackKinematics, stack_dynamics, stack_kinematics

__all__ = [
    "Stack",
    "StackDynamics",
    "StackForwardKinematics",
    "StackKinematics",
    "StackModel",
    "StackModule",
    "Twist",
    "load_stack",
    "parameters_to_toml",
    "reference_stack",
    "robot_to_toml",
    "stack_dynamics",
    "stack_from_dict",
    "stack_from_parameters",
    "stack_kinematics",
    "stack_margins",
    "stack_to_toml",
]
