"""vgtarm: model, plan and control the 7-DOF redundant hybrid VGT manipulator.

Quick start::

    import vgtarm
    robot = vgtarm.load_robot()                 # the reference robot of the spec
    fk = robot.forward_kinematics(robot.parameters.home)
    fk.tip                                       # array([0., 0., 0.66])
"""

from .errors import (
    AssemblyError,
    ConfigError,
    InputError,
    PathError,
    SimulationError,
    UnreachableError,
    VgtarmError,
)
from .model import (
    JOINT_NAMES,
    BiasAccelerations,
    ForwardKinematics,
    Robot,
    RobotParameters,
    load_parameters,
    load_robot,
)

__version__ = "0.1.0"

__all__ = [
    "JOINT_NAMES",
    "AssemblyError",
    "BiasAccelerations",
    "ConfigError",
    "ForwardKinematics",
    "InputError",
    "PathError",
    "Robot",
    "RobotParameters",
    "SimulationError",
    "UnreachableError",
    "VgtarmError",
    "load_parameters",
    "load_robot",
]
