"""The paper's two case studies (Section VI) with the spec's numbers, and what the paper reports.

All values come from ``shared/spec/mechanism.md``: the paper gives the shapes of the paths and
the gains, the spec fixes the path parameters (assumptions) and the GA bounds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import paths
from ..control import ComputedForceControl, SwitchingControl
from ..errors import InputError, shown
from ..ga import GAOptions
from ..model.parameters import RobotParameters
from ..model.robot import Robot
from ..simulation import ExternalForce, JointReference, SimulationResult, simulate

CONTROLLERS = ("cfc", "scm")


@dataclass(frozen=True)
class CaseStudy:
    """One of the paper's case studies: the path, the fixed gains and the GA's element bounds."""

    number: int
    title: str
    path_factory: Callable[[float], paths.Path] = field(repr=False)
    kp: float
    kv: float
    kp_bounds: tuple[float, float]
    kv_bounds: tuple[float, float]
    threshold: float = 2e-4
    external_force: ExternalForce = field(default_factory=ExternalForce)

    def path(self, dt: float = 1e-3) -> paths.Path:
        """The desired tip path sampled at ``dt`` (s)."""
        return self.path_factory(dt)

    def controller(
        self, name: str, *, horizon: int = 20, ga: GAOptions | None = None
    ) -> ComputedForceControl | SwitchingControl:
        """``"cfc"``: computed force control with the case's gains; ``"scm"``: the switching method."""
        if name == "cfc":
            return ComputedForceControl.with_gains(self.kp, self.kv)
        if name == "scm":
            return SwitchingControl.with_gains(
                self.kp,
                self.kv,
                threshold=self.threshold,
                kp_bounds=self.kp_bounds,
                kv_bounds=self.kv_bounds,
                horizon=horizon,
                ga=ga or GAOptions(),
            )
        raise InputError(f"controller = {name!r}: expected one of {list(CONTROLLERS)}")


CASES: dict[int, CaseStudy] = {
    1: CaseStudy(
        number=1,
        title="closed curve (eq. 22)",
        path_factory=lambda dt: paths.case1(dt),
        kp=5000.0,
        kv=300.0,
        kp_bounds=(0.0, 5000.0),
        kv_bounds=(0.0, 300.0),
    ),
    2: CaseStudy(
        number=2,
        title="two spatial lines (eq. 23)",
        path_factory=lambda dt: paths.case2(dt),
        kp=15000.0,
        kv=600.0,
        kp_bounds=(0.0, 15000.0),
        kv_bounds=(0.0, 600.0),
    ),
}


@dataclass(frozen=True)
class PaperFigure:
    """A maximum tip error the paper reports: ``value`` (m) and whether it is exact or a bound."""

    value_m: float
    relation: str  # "=" (reported maximum) or "<" (the paper says the error stays below it)
    text: str


#: Maximum tip errors reported by the paper, by (case, controller, external force).
PAPER_RESULTS: dict[tuple[int, str, bool], PaperFigure] = {
    (1, "cfc", False): PaperFigure(0.53e-3, "=", "0.53 mm (errors below 0.2 mm after the start)"),
    (1, "scm", False): PaperFigure(0.48e-3, "=", "0.48 mm"),
    (2, "cfc", False): PaperFigure(0.31e-3, "=", "0.31 mm"),
    (2, "cfc", True): PaperFigure(0.68e-3, "=", "0.68 mm"),
    (2, "scm", False): PaperFigure(0.2e-3, "<", "kept below 0.2 mm"),
    (2, "scm", True): PaperFigure(0.4e-3, "<", "kept below 0.4 mm"),
}


def case_study(number: int) -> CaseStudy:
    """Case study 1 or 2."""
    if number not in CASES:
        raise InputError(f"case = {number!r}: expected one of {sorted(CASES)}")
    return CASES[number]


def joint_reference(
    robot: Robot,
    number: int,
    *,
    dt: float = 1e-3,
    rates: str = "exact",
    solver: str = "fast",
    duration: float | None = None,
) -> JointReference:
    """The case's joint reference from the redundancy-resolving inverse kinematics; with
    ``duration`` (s) only its first ``duration`` seconds (:func:`truncate_reference`)."""
    ik = robot.inverse_kinematics(case_study(number).path(dt), solver=solver, rates=rates)
    reference = JointReference.of(ik, name=f"case {number}")
    return reference if duration is None else truncate_reference(reference, duration)


def truncate_reference(reference: JointReference, duration: float) -> JointReference:
    """The samples of ``reference`` with ``t - t[0] <= duration`` (s), at least two.

    The reference of the whole path is computed first and then cut, so a run on the first
    ``duration`` seconds follows exactly the start of the full run's reference.
    """
    if isinstance(duration, bool) or not isinstance(duration, int | float | np.integer | np.floating):
        raise InputError(f"duration = {shown(duration)}: expected a time > 0 (s)")
    if not (np.isfinite(duration) and duration > 0):
        raise InputError(f"duration = {duration!r}: expected a time > 0 (s)")
    t = reference.t
    n = max(2, int(np.count_nonzero(t - t[0] <= duration + 1e-6 * reference.dt)))
    return reference.head(n)


def run_case(
    robot: Robot,
    number: int,
    *,
    controller: str = "cfc",
    external_force: bool = False,
    integrator: str = "euler",
    substeps: int = 1,
    seed: int = 0,
    rates: str = "exact",
    dt: float = 1e-3,
    horizon: int = 20,
    ga: GAOptions | None = None,
    controller_model: RobotParameters | None = None,
    reference: JointReference | None = None,
    progress: Callable[[int, int], None] | None = None,
    **options: Any,
) -> SimulationResult:
    """Run one case study; the robot starts at rest at ``q_d(0)`` (the paper's start).

    ``reference`` reuses a joint reference computed before (it must match ``dt`` and ``rates``);
    ``options`` go to :func:`vgtarm.simulation.simulate` (observer, force sensor, sensing, ...).
    """
    case = case_study(number)
    ref = reference if reference is not None else joint_reference(robot, number, dt=dt, rates=rates)
    metadata: dict[str, Any] = {"case": number, "case_title": case.title}
    return simulate(
        robot,
        ref,
        case.controller(controller, horizon=horizon, ga=ga),
        controller_model=controller_model,
        external_force=case.external_force if external_force else None,
        integrator=integrator,
        substeps=substeps,
        seed=seed,
        metadata=metadata,
        progress=progress,
        **options,
    )
