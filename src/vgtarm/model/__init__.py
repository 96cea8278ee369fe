"""The model layer: parameters, assembly, the symbolic definition, code generation, the compiled
and interpreted backends, the C drivers and the :class:`Robot`.

It imports nothing above it (no ``ik``, ``paths``, ``control``, ``simulation`` or ``app``), so
``import vgtarm.model`` loads neither inverse kinematics nor ``scipy.optimize``.
"""

from .parameters import JOINT_NAMES, N_JOINTS, RobotParameters, load_parameters
from .robot import BiasAccelerations, ForwardKinematics, Robot, load_robot

__all__ = [
    "JOINT_NAMES",
    "N_JOINTS",
    "BiasAccelerations",
    "ForwardKinematics",
    "Robot",
    "RobotParameters",
    "load_parameters",
    "load_robot",
]
