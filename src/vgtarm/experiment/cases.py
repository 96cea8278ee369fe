"""The paper's two case studies (Section VI) with the spec's numbers, and what the paper reports.

All values come from ``docs/conventions.md``: the paper gives the shapes of the paths and
the gains, the spec fixes the path parameters (assumptions) and the GA bounds.

**On a robot other than the paper's** (a stack of modules, issue 13) the case paths are moved and
scaled to it (:func:`path_placement`): a path point ``x`` becomes ``c + s (x - c0)``, where ``c0 =
(0, 0, 0.66) m`` is the paper robot's home tip (the centre of case 1), ``c`` the robot's home tip
and ``s = reach / 0.66 m`` with the robot's **reach** defined as the distance from the base origin
(F0) to its tip at home, ``|P(q_home)|`` (0.66 m for the paper's robot). Velocities and
accelerations scale by ``s`` too (same timing). A robot whose home tip lies within 1e-9 m of
``c0`` (the paper's robot, or a copy of it as a stack) gets the paths unchanged. The summary of a
run records the centre and the scale (``path_centre_m``, ``path_scale``).

**A robot whose tip moves in a plane** (a single planar module; :mod:`vgtarm.ik.taskspace`) tracks
the tip's two coordinates in that plane, so a case path is also turned into it: the moved and
scaled displacement ``s (x - c0)`` is turned by the smallest rotation that takes the normal of the
path's own best-fitting plane (the least principal direction of its points, entries below 1e-6 set
to zero; for case 2 the plane of its three corners, for case 1 the horizontal plane of its circle)
onto the robot's plane
normal, then projected on the robot's plane (what is left out of the path's plane, case 1's
+-15 mm wave in height before scaling, is dropped). Velocities and accelerations follow by the
same linear map: the same timing, the same shape where the path is planar. On a robot whose tip
moves on a line the displacement is projected on the line. The summary records the task
(``ik_task``, e.g. ``"tip (u2, u3) in its plane"``) and the robot plane's normal
(``path_plane_normal``).

The case gains are scalars: each case's ``Kp`` and ``Kv`` apply to every joint of the robot
(``Kp I``, ``Kv I`` of its size), as the paper's 7x7 diagonal gains do: legs and twists alike.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import checks, paths
from ..control import ComputedForceControl, SwitchingControl
from ..errors import InputError, shown
from ..ga import GAOptions
from ..ik.taskspace import TaskSpace, task_space
from ..model.parameters import N_JOINTS, RobotParameters
from ..model.robot import Robot
from ..model.stack import Stack
from ..simulation import ExternalForce, JointReference, SimulationResult, simulate

CONTROLLERS = ("cfc", "scm")


@dataclass(frozen=True)
class CaseStudy:
    """One of the paper's case studies: the path, the fixed gains and the GA's element bounds."""

    number: int
    title: str
    path_factory: Callable[[float], paths.TipPath] = field(repr=False)
    kp: float | tuple[float, ...]
    kv: float | tuple[float, ...]
    kp_bounds: tuple[float, float]
    kv_bounds: tuple[float, float]
    threshold: float = 2e-4
    external_force: ExternalForce = field(default_factory=ExternalForce)

    def path(self, dt: float = 1e-3) -> paths.TipPath:
        """The desired tip path sampled at ``dt`` (s)."""
        return self.path_factory(dt)

    def with_gains(self, kp: float | tuple[float, ...] | None, kv: float | tuple[float, ...] | None) -> CaseStudy:
        """The case with a user's gains (one value for every joint, or one per joint; None keeps the
        case's); the GA's upper bounds grow to the largest gain when it exceeds them."""
        kp = self.kp if kp is None else kp
        kv = self.kv if kv is None else kv
        return replace(
            self,
            kp=kp,
            kv=kv,
            kp_bounds=(self.kp_bounds[0], max(self.kp_bounds[1], float(np.max(kp)))),
            kv_bounds=(self.kv_bounds[0], max(self.kv_bounds[1], float(np.max(kv)))),
        )

    def controller(
        self,
        name: str,
        *,
        horizon: int = 20,
        ga: GAOptions | None = None,
        n_joints: int = N_JOINTS,
        variant: str = "safe",
        **scm_options: Any,
    ) -> ComputedForceControl | SwitchingControl:
        """``"cfc"``: computed force control with the case's gains (the same on each of the robot's
        ``n_joints`` joints); ``"scm"``: the switching method around the same gains, with ``2 n_joints^2``
        genes, in its ``variant`` (``"safe"``, the default, or ``"paper"``, the reproduction's) and
        with ``scm_options`` (``hold``, ``switch_on``, ... of :class:`SwitchingControl`)."""
        if name == "cfc":
            if scm_options:
                raise InputError(f"{', '.join(sorted(scm_options))}: options of the switching method, not of cfc")
            return ComputedForceControl.with_gains(self.kp, self.kv, n_joints)
        if name == "scm":
            return SwitchingControl.with_gains(
                self.kp,
                self.kv,
                n_joints,
                threshold=self.threshold,
                kp_bounds=self.kp_bounds,
                kv_bounds=self.kv_bounds,
                horizon=horizon,
                ga=ga or GAOptions(),
                variant=variant,
                **scm_options,
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


#: Home tip of the paper's robot (m): the centre of case 1, around which both case paths are laid.
PAPER_HOME_TIP = (0.0, 0.0, 0.66)
#: A robot whose home tip is this close (m) to :data:`PAPER_HOME_TIP` gets the case paths unchanged.
SAME_TIP_TOLERANCE = 1e-9


#: Entries of a path's fitted plane normal below this are set to zero: the sampling of a path that is
#: not a whole number of periods (case 1) tilts the fitted normal of its horizontal circle by ~1e-8 rad.
NORMAL_SNAP = 1e-6


@dataclass(frozen=True)
class PathPlacement:
    """Where the case paths go on a robot: ``x -> centre + scale (x - PAPER_HOME_TIP)``.

    ``centre`` (m) is the robot's home tip; ``scale`` its reach over the paper robot's (module
    docstring); ``reach`` (m) the distance from the base origin to its home tip. ``space`` is the
    plane or line the tip of a robot moves in when it does not move in all of space (the path is
    then turned into it, module docstring), else None.
    """

    centre: tuple[float, float, float]
    scale: float
    reach: float
    space: TaskSpace | None = None

    def apply(self, path: paths.TipPath) -> paths.TipPath:
        """The path moved and scaled (timing unchanged); turned into the robot's plane or line if it has one."""
        c0, c = np.array(PAPER_HOME_TIP), np.array(self.centre)
        if self.space is None:
            return paths.TipPath(
                path.name,
                path.t,
                c + self.scale * (path.position - c0),
                self.scale * path.velocity,
                self.scale * path.acceleration,
                None if path.jerk is None else self.scale * path.jerk,
            )
        M = self.scale * self.turn(path)
        return paths.TipPath(
            path.name,
            path.t,
            c + (path.position - c0) @ M.T,
            path.velocity @ M.T,
            path.acceleration @ M.T,
            None if path.jerk is None else path.jerk @ M.T,
        )

    def turn(self, path: paths.TipPath) -> NDArray[np.float64]:
        """The linear map ``(3, 3)`` that takes ``path``'s displacements into the robot's plane or line
        (before scaling): the smallest rotation of the path's plane normal onto the robot's, then the
        projection on the robot's plane (module docstring); the projection alone for a line, or for a
        path that is itself a line or a point."""
        assert self.space is not None
        E = self.space.directions
        projection = E.T @ E
        if self.space.rank != 2:
            return np.asarray(projection)
        spread = path.position - path.position.mean(axis=0)
        _, s, vt = np.linalg.svd(spread, full_matrices=False)
        if s.shape[0] < 3 or not s[1] > 1e-9 * s[0]:
            return np.asarray(projection)
        target = self.space.normal()
        normal = np.where(np.abs(vt[2]) < NORMAL_SNAP, 0.0, vt[2])
        normal /= np.linalg.norm(normal)
        if normal @ target < 0:
            normal = -normal
        cosine = float(normal @ target)
        k = np.cross(normal, target)
        cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        rotation = cosine * np.eye(3) + cross + np.outer(k, k) / (1.0 + cosine)
        return np.asarray(projection @ rotation)

    def metadata(self) -> dict[str, Any]:
        """The summary entries of the placement."""
        entries: dict[str, Any] = {
            "path_centre_m": list(self.centre),
            "path_scale": self.scale,
            "path_reach_m": self.reach,
        }
        if self.space is not None:
            entries["ik_task"] = self.space.label
            if self.space.rank == 2:
                entries["path_plane_normal"] = self.space.normal().tolist()
        return entries


def reduced_space(robot: Robot) -> TaskSpace | None:
    """The plane or line the tip of ``robot`` moves in from home (:func:`vgtarm.ik.taskspace.task_space`),
    or None when it moves in all of space (the paper's robot is never asked)."""
    home = robot.parameters.home
    if not robot.is_stack or np.linalg.matrix_rank(robot.tip_jacobian(home), tol=1e-9) == 3:
        return None
    return task_space(robot, home)


def task_metadata(robot: Robot) -> dict[str, Any]:
    """``{"ik_task": ...}`` for a robot whose tip moves in a plane or a line, else nothing (the
    paper's runs stay as they were)."""
    space = reduced_space(robot)
    return {} if space is None else {"ik_task": space.label}


def path_placement(robot: Robot) -> PathPlacement | None:
    """How the case paths are placed on ``robot``; ``None`` for the paper's robot (home tip within
    :data:`SAME_TIP_TOLERANCE` of :data:`PAPER_HOME_TIP`: the paths are used as they are)."""
    tip = robot.tip_position(robot.parameters.home)
    space = reduced_space(robot)
    if space is None and float(np.linalg.norm(tip - np.array(PAPER_HOME_TIP))) <= SAME_TIP_TOLERANCE:
        return None
    reach = float(np.linalg.norm(tip))
    if not reach > 0.0:
        raise InputError(f"robot {shown(robot.parameters.name)}: its tip at home is at the base origin (no reach)")
    scale = reach / float(np.linalg.norm(PAPER_HOME_TIP))
    return PathPlacement((float(tip[0]), float(tip[1]), float(tip[2])), scale, reach, space)


def case_path(robot: Robot, number: int, dt: float = 1e-3) -> paths.TipPath:
    """The desired tip path of case ``number`` placed on ``robot`` (:func:`path_placement`)."""
    path = case_study(number).path(dt)
    placement = path_placement(robot)
    return path if placement is None else placement.apply(path)


def joint_reference(
    robot: Robot,
    number: int,
    *,
    dt: float = 1e-3,
    rates: str = "exact",
    solver: str = "fast",
    duration: float | None = None,
    **ik_options: Any,
) -> JointReference:
    """The case's joint reference from the redundancy-resolving inverse kinematics; with
    ``duration`` (s) only its first ``duration`` seconds (:func:`truncate_reference`). ``ik_options``
    go to the inverse kinematics (``criterion="effort"``, ``tool_force``, ...)."""
    ik = robot.inverse_kinematics(case_path(robot, number, dt), solver=solver, rates=rates, **ik_options)
    reference = JointReference.of(ik, name=f"case {number}")
    return reference if duration is None else truncate_reference(reference, duration)


def truncate_reference(reference: JointReference, duration: float) -> JointReference:
    """The samples of ``reference`` with ``t - t[0] <= duration`` (s), at least two.

    The reference of the whole path is computed first and then cut, so a run on the first
    ``duration`` seconds follows exactly the start of the full run's reference.
    """
    checks.positive("duration", duration, "s")
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
    controller_model: RobotParameters | Stack | None = None,
    reference: JointReference | None = None,
    progress: Callable[[int, int], None] | None = None,
    scm_variant: str = "safe",
    scm_options: Mapping[str, Any] | None = None,
    kp: float | tuple[float, ...] | None = None,
    kv: float | tuple[float, ...] | None = None,
    **options: Any,
) -> SimulationResult:
    """Run one case study; the robot starts at rest at ``q_d(0)`` (the paper's start).

    ``kp``, ``kv``: gains other than the case's (one value for every joint, or one per joint),
    recorded in the summary.

    ``scm_variant``: the switching method's variant (``"safe"``, the default: gains admitted on
    the discrete loop first; ``"paper"``: the paper's, as the reproduction runs it);
    ``scm_options``: further options of :class:`SwitchingControl` (``hold``, ``switch_on``).

    ``reference`` reuses a joint reference computed before (it must match ``dt`` and ``rates``);
    ``options`` go to :func:`vgtarm.simulation.simulate` (observer, force sensor, sensing, ...).
    """
    case = case_study(number).with_gains(kp, kv)
    ref = reference if reference is not None else joint_reference(robot, number, dt=dt, rates=rates)
    metadata: dict[str, Any] = {"case": number, "case_title": case.title}
    placement = path_placement(robot)
    if placement is not None:
        metadata.update(placement.metadata())
    if kp is not None or kv is not None:  # recorded only when given: the paper's runs stay as they were
        metadata.update(_gain_metadata(case, robot.n_joints))
    options = {"integrator": integrator, "substeps": substeps, "seed": seed, "progress": progress, **options}
    scm = (scm_variant, dict(scm_options or {}))
    return _run(robot, case, ref, metadata, controller, external_force, horizon, ga, scm, controller_model, options)


#: The gains of a run on a user's path unless given: case 1's (as a study's path file).
PATH_GAINS_CASE = 1


def run_path(
    robot: Robot,
    path: paths.TipPath,
    *,
    controller: str = "cfc",
    external_force: bool = False,
    kp: float | tuple[float, ...] | None = None,
    kv: float | tuple[float, ...] | None = None,
    rates: str = "exact",
    horizon: int = 20,
    ga: GAOptions | None = None,
    controller_model: RobotParameters | Stack | None = None,
    reference: JointReference | None = None,
    scm_variant: str = "safe",
    scm_options: Mapping[str, Any] | None = None,
    metadata: dict[str, Any] | None = None,
    **options: Any,
) -> SimulationResult:
    """Run a user's desired tip ``path`` (its own sampling period) as a case is run: from rest at
    ``q_d(0)``, with ``kp``, ``kv`` (one value for every joint or one per joint; default case
    :data:`PATH_GAINS_CASE`'s, whose GA bounds and tool force apply too).

    ``reference`` reuses a joint reference of the path computed before; ``metadata`` is added to
    the summary (the path file's name, ...); ``options`` go to :func:`vgtarm.simulation.simulate`.
    """
    case = replace(case_study(PATH_GAINS_CASE), number=0, title=path.name).with_gains(kp, kv)
    ref = (
        reference
        if reference is not None
        else JointReference.of(robot.inverse_kinematics(path, rates=rates), path.name)
    )
    info: dict[str, Any] = {
        "path": path.name,
        **_gain_metadata(case, robot.n_joints),
        **task_metadata(robot),
        **(metadata or {}),
    }
    scm = (scm_variant, dict(scm_options or {}))
    return _run(robot, case, ref, info, controller, external_force, horizon, ga, scm, controller_model, options)


def _gain_metadata(case: CaseStudy, n_joints: int) -> dict[str, Any]:
    """The summary's ``kp`` and ``kv``: one value per joint, so the run can be repeated."""
    return {
        "kp": np.broadcast_to(np.asarray(case.kp, dtype=float), (n_joints,)).tolist(),
        "kv": np.broadcast_to(np.asarray(case.kv, dtype=float), (n_joints,)).tolist(),
    }


def _run(
    robot: Robot,
    case: CaseStudy,
    reference: JointReference,
    metadata: dict[str, Any],
    controller: str,
    external_force: bool,
    horizon: int,
    ga: GAOptions | None,
    scm: tuple[str, dict[str, Any]],
    controller_model: RobotParameters | Stack | None,
    options: dict[str, Any],
) -> SimulationResult:
    return simulate(
        robot,
        reference,
        case.controller(controller, horizon=horizon, ga=ga, n_joints=robot.n_joints, variant=scm[0], **scm[1]),
        controller_model=controller_model,
        external_force=case.external_force if external_force else None,
        metadata=metadata,
        **options,
    )
