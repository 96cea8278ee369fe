"""vgtarm: model, plan and control the 7-DOF redundant hybrid VGT manipulator.

Quick start::

    import vgtarm
    robot = vgtarm.load_robot()                 # the reference robot of the spec
    fk = robot.forward_kinematics(robot.parameters.home)
    fk.tip                                       # array([0., 0., 0.66])

The public names are loaded on first use (:pep:`562`), so that ``import vgtarm`` itself costs
nothing: the ``vgtarm`` command (:mod:`vgtarm._entry`) installs its Ctrl-C handling before NumPy
and CasADi are imported.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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

#: Where each public name lives.
_SOURCES = {
    **dict.fromkeys(
        (
            "AssemblyError",
            "ConfigError",
            "InputError",
            "PathError",
            "SimulationError",
            "UnreachableError",
            "VgtarmError",
        ),
        "errors",
    ),
    **dict.fromkeys(
        (
            "JOINT_NAMES",
            "BiasAccelerations",
            "ForwardKinematics",
            "Robot",
            "RobotParameters",
            "load_parameters",
            "load_robot",
        ),
        "model",
    ),
}

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


def __getattr__(name: str) -> Any:
    """A public name, or a subpackage (``vgtarm.model``), imported on first use."""
    source = _SOURCES.get(name)
    if source is not None:
        value = getattr(importlib.import_module(f".{source}", __name__), name)
        globals()[name] = value
        return value
    if not name.startswith("__"):
        try:
            return importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":  # the module exists but something it imports does not
                raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
