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

from .version import __version__ as __version__

if TYPE_CHECKING:  # the names as static type checkers and editors see them
    from . import (
        calibration,
        control,
        design,
        drilling,
        export,
        ga,
        ik,
        model,
        mujoco_bridge,
        paths,
        retiming,
        simulation,
        study,
        toolpaths,
    )
    from .app.library import run_study
    from .app.pictures.plotting import (
        comparison_figure,
        plot_efforts,
        plot_joint_errors,
        plot_path_3d,
        plot_tip_error,
        save_figure,
    )
    from .app.reports.reproduce import reproduce
    from .calibration import calibrate, exciting_trajectory, identify, plan_poses
    from .control import ComputedForceControl, Gains, SwitchingControl
    from .design import cartesian_stiffness, deflection, dexterity, workspace_volume
    from .drilling import DrillingSettings, drilling_run, load_bone
    from .errors import (
        AssemblyError,
        ConfigError,
        InputError,
        PathError,
        SimulationError,
        UnreachableError,
        VgtarmError,
    )
    from .experiment import PRESETS, Experiment
    from .experiment.cases import case_study, run_case
    from .export import export_controller, export_drilling
    from .ga import GAOptions
    from .ik import AxisPath, IKOptions, IKResult, OrientationPath, PointSolution, inverse_kinematics, solve_point
    from .model import (
        JOINT_NAMES,
        BiasAccelerations,
        ForwardKinematics,
        Robot,
        RobotParameters,
        load_parameters,
        load_robot,
    )
    from .mujoco_bridge import to_mjcf
    from .retiming import retime
    from .simulation import ExternalForce, JointReference, Scenario, SimulationResult, simulate
    from .simulation.limits_check import check_path
    from .study import Study, load_study

#: Where each public name lives: ``(module, name in that module)``, the module relative to this
#: package. The command line's capabilities are all here: a notebook needs nothing of ``vgtarm.app``.
_SOURCES: dict[str, tuple[str, str]] = {
    # errors
    **{
        name: ("errors", name)
        for name in (
            "AssemblyError",
            "ConfigError",
            "InputError",
            "PathError",
            "SimulationError",
            "UnreachableError",
            "VgtarmError",
        )
    },
    # the model
    **{
        name: ("model", name)
        for name in (
            "JOINT_NAMES",
            "BiasAccelerations",
            "ForwardKinematics",
            "Robot",
            "RobotParameters",
            "load_parameters",
            "load_robot",
        )
    },
    # inverse kinematics
    **{
        name: ("ik", name)
        for name in (
            "AxisPath",
            "IKOptions",
            "IKResult",
            "OrientationPath",
            "PointSolution",
            "inverse_kinematics",
            "solve_point",
        )
    },
    # controllers
    **{name: ("control", name) for name in ("ComputedForceControl", "Gains", "SwitchingControl")},
    "GAOptions": ("ga", "GAOptions"),
    # the closed loop
    **{
        name: ("simulation", name)
        for name in (
            "ExternalForce",
            "JointReference",
            "Scenario",
            "SimulationResult",
            "simulate",
        )
    },
    # actuators: a path checked against their limits, and its fastest timing under them
    "check_path": ("simulation.limits_check", "check_path"),
    "retime": ("retiming", "retime"),
    # the designer's and the calibrator's tools
    "workspace_volume": ("design", "workspace_volume"),
    "dexterity": ("design", "dexterity"),
    "cartesian_stiffness": ("design", "cartesian_stiffness"),
    "deflection": ("design", "deflection"),
    "calibrate": ("calibration", "calibrate"),
    "plan_poses": ("calibration", "plan_poses"),
    "identify": ("calibration", "identify"),
    "exciting_trajectory": ("calibration", "exciting_trajectory"),
    # bone drilling: the tool's thrust and torque through a layered bone
    "load_bone": ("drilling", "load_bone"),
    "DrillingSettings": ("drilling", "DrillingSettings"),
    "drilling_run": ("drilling", "drilling_run"),
    "export_drilling": ("export", "export_drilling"),
    # one run as a record (every option declared once), the presets
    "Experiment": ("experiment", "Experiment"),
    "PRESETS": ("experiment", "PRESETS"),
    # the paper's case studies, studies of many runs, the report
    "case_study": ("experiment.cases", "case_study"),
    "run_case": ("experiment.cases", "run_case"),
    "Study": ("study", "Study"),
    "load_study": ("study", "load_study"),
    "run_study": ("app.library", "run_study"),
    "reproduce": ("app.reports.reproduce", "reproduce"),
    # other engines and targets
    "to_mjcf": ("mujoco_bridge", "to_mjcf"),
    "export_controller": ("export", "export_controller"),
    # figures of runs and of comparisons (matplotlib; each takes ax=None and returns it)
    **{
        name: ("app.pictures.plotting", name)
        for name in (
            "comparison_figure",
            "plot_efforts",
            "plot_joint_errors",
            "plot_path_3d",
            "plot_tip_error",
            "save_figure",
        )
    },
}

#: Subpackages a user reaches by attribute (``vgtarm.paths.case1``), imported on first use.
_MODULES = (
    "calibration",
    "control",
    "design",
    "drilling",
    "export",
    "ga",
    "ik",
    "model",
    "mujoco_bridge",
    "paths",
    "retiming",
    "simulation",
    "study",
    "toolpaths",
)

__all__ = [
    "AssemblyError",
    "AxisPath",
    "BiasAccelerations",
    "ComputedForceControl",
    "ConfigError",
    "Experiment",
    "ExternalForce",
    "ForwardKinematics",
    "GAOptions",
    "Gains",
    "IKOptions",
    "IKResult",
    "InputError",
    "JOINT_NAMES",
    "JointReference",
    "OrientationPath",
    "PRESETS",
    "PathError",
    "PointSolution",
    "Robot",
    "RobotParameters",
    "Scenario",
    "SimulationError",
    "SimulationResult",
    "DrillingSettings",
    "Study",
    "SwitchingControl",
    "UnreachableError",
    "VgtarmError",
    "calibrate",
    "calibration",
    "cartesian_stiffness",
    "case_study",
    "check_path",
    "comparison_figure",
    "control",
    "deflection",
    "design",
    "dexterity",
    "drilling",
    "drilling_run",
    "exciting_trajectory",
    "export",
    "export_controller",
    "export_drilling",
    "ga",
    "identify",
    "ik",
    "inverse_kinematics",
    "load_bone",
    "load_parameters",
    "load_robot",
    "load_study",
    "model",
    "mujoco_bridge",
    "paths",
    "plan_poses",
    "plot_efforts",
    "plot_joint_errors",
    "plot_path_3d",
    "plot_tip_error",
    "reproduce",
    "retime",
    "retiming",
    "run_case",
    "run_study",
    "save_figure",
    "simulate",
    "simulation",
    "solve_point",
    "study",
    "to_mjcf",
    "toolpaths",
    "workspace_volume",
]


def __getattr__(name: str) -> Any:
    """A public name, or a subpackage (``vgtarm.model``), imported on first use."""
    source = _SOURCES.get(name)
    if source is not None:
        module, attribute = source
        value = getattr(importlib.import_module(f".{module}", __name__), attribute)
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
    """The public names only (not ``importlib`` or the typing helpers of this module)."""
    return sorted({"__version__", *__all__})
