"""Short closed-loop runs for the tests of the pictures, the animation and the page (seconds, not minutes)."""

from __future__ import annotations

import vgtarm
from vgtarm import paths
from vgtarm.experiment.cases import case_study
from vgtarm.simulation import SimulationResult, simulate

#: Length of the short runs (s): case 1's path cut after its start transient.
SHORT_RUN_S = 0.3


def short_case1_run(robot: vgtarm.Robot, controller: str = "cfc", duration: float = SHORT_RUN_S) -> SimulationResult:
    """Case 1's reference cut to ``duration`` and run with ``controller`` (cfc or scm), through the public API."""
    case = case_study(1)
    reference = robot.inverse_kinematics(paths.case1(1e-3, duration=duration))
    return simulate(
        robot,
        reference,
        case.controller(controller, variant="paper"),
        seed=0,
        metadata={"case": 1, "case_title": case.title},
    )
