"""The designer's tools for any robot file: the reachable and dexterous workspace (:mod:`.workspace`:
``vgtarm workspace``), manipulability, condition number and the distance of each module from its
flat-truss singularity (:mod:`.measures`), and the tool's Cartesian stiffness and deflection under
load with the leg stiffnesses of the ``[stiffness]`` table (:mod:`.stiffness`: ``vgtarm stiffness``),
and the posture stiffest along the tool's axis for a given tool pose (:mod:`.posture`: ``vgtarm drill
--posture stiffest``).
"""

from .measures import Dexterity, dexterity, joint_grid, module_distance
from .posture import StiffPosture, stiffest_posture
from .stiffness import CartesianStiffness, Deflection, Equilibrium, cartesian_stiffness, deflection, static_equilibrium
from .workspace import (
    MonteCarloVolume,
    ReachTest,
    Slice,
    WorkspaceVolume,
    monte_carlo_volume,
    plot_slices,
    plot_workspace_3d,
    workspace_slices,
    workspace_volume,
)

__all__ = [
    "CartesianStiffness",
    "Deflection",
    "Dexterity",
    "Equilibrium",
    "MonteCarloVolume",
    "ReachTest",
    "Slice",
    "StiffPosture",
    "WorkspaceVolume",
    "cartesian_stiffness",
    "deflection",
    "dexterity",
    "joint_grid",
    "module_distance",
    "monte_carlo_volume",
    "plot_slices",
    "plot_workspace_3d",
    "static_equilibrium",
    "stiffest_posture",
    "workspace_slices",
    "workspace_volume",
]
