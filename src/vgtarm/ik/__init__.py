"""Redundancy-resolving inverse kinematics along desired tip paths (paper Section IV, eq. 12).

For each sample of a desired tip path the joint vector minimises the joint-limit cost ``Phi``
subject to the tip point (optionally the full pose, the tool's axis or an entry point the axis
passes through), the joint limits and assemblability with a
margin; the joint rates and accelerations of the reference follow exactly from the optimality
conditions. See ``docs/ik.md``.

Public API: :func:`inverse_kinematics` (also ``Robot.inverse_kinematics``), :func:`solve_point`
(one tip point, a :class:`PointSolution` record), the records
:class:`IKResult` and :class:`IKSamples`, :class:`OrientationPath`, :class:`AxisPath` (a tool
axis along a direction, the spin free; :mod:`vgtarm.ik.axis`), :class:`IKOptions`, the
solver interface and registry (:class:`Solver`, :class:`SolverResult`, :func:`register_solver`,
:data:`SOLVERS`, :func:`solver_names`) and :func:`write_csv`.
"""

from .axis import AxisPath
from .options import IKOptions
from .point import PointSolution, solve_point
from .pose import OrientationPath
from .records import CSV_COLUMNS, IKResult, IKSamples, write_csv
from .solve import (
    ALIASES,
    SOLVERS,
    Solver,
    SolverResult,
    in_place,
    inverse_kinematics,
    register_solver,
    solver_names,
    unregister_solver,
)

__all__ = [
    "ALIASES",
    "CSV_COLUMNS",
    "AxisPath",
    "SOLVERS",
    "IKOptions",
    "IKResult",
    "IKSamples",
    "OrientationPath",
    "PointSolution",
    "Solver",
    "SolverResult",
    "in_place",
    "inverse_kinematics",
    "register_solver",
    "solve_point",
    "solver_names",
    "unregister_solver",
    "write_csv",
]
