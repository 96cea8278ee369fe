"""The calibrator's tools: the geometric parameters identified from measured tool poses
(:mod:`.kinematic`: ``vgtarm calibrate``) and the inertial and friction parameters from leg forces
along an exciting trajectory (:mod:`.dynamic`, :mod:`.excitation`: ``vgtarm identify``).

Both work for the paper robot and any stack of modules, with the derivatives of the same model the
compiled library is generated from; what the data cannot determine is reported as such and keeps
its nominal value (docs/calibration.md, docs/identification.md).
"""

from .dynamic import (
    BaseParameters,
    Identification,
    base_parameters,
    identify,
    is_consistent,
    perturbed_parameters,
    regressor,
    simulated_forces,
)
from .excitation import ExcitingTrajectory, exciting_trajectory
from .kinematic import (
    Calibration,
    Identifiability,
    Measurements,
    PosePlan,
    calibrate,
    calibration_parameters,
    corrected_parameters,
    identifiability,
    perturbed_values,
    plan_poses,
    read_measurements,
    synthetic_measurements,
    write_robot_file,
)

__all__ = [
    "BaseParameters",
    "Calibration",
    "ExcitingTrajectory",
    "Identifiability",
    "Identification",
    "Measurements",
    "PosePlan",
    "base_parameters",
    "calibrate",
    "calibration_parameters",
    "corrected_parameters",
    "exciting_trajectory",
    "identifiability",
    "identify",
    "is_consistent",
    "perturbed_parameters",
    "perturbed_values",
    "plan_poses",
    "read_measurements",
    "regressor",
    "simulated_forces",
    "synthetic_measurements",
    "write_robot_file",
]
