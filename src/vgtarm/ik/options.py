"""Options of an inverse-kinematics solve, validated where they enter (``**options`` of the API)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import checks
from ..errors import InputError
from ..model.parameters import N_JOINTS
from .effort import CRITERIA, DEFAULT_JOINT_LIMIT_WEIGHT, DEFAULT_TOOL_FORCE_SPEED
from .problem import DEFAULT_MARGIN

#: The fast solver's ``coarse_step`` on the paper's robot (m).
COARSE_STEP = 0.02
#: The paper robot's reach: the distance from the base to its tip at home (m). A robot that reaches
#: farther gets the case paths scaled by its reach over this (:func:`vgtarm.experiment.cases.path_placement`)
#: and a ``coarse_step`` scaled alike (:func:`default_coarse_step`).
PAPER_REACH = 0.66
#: Reaches within this of :data:`PAPER_REACH` (m) count as the paper robot's (the case paths' rule).
SAME_REACH = 1e-9
#: The options that are numbers > 0, with their units (``""``: a ratio, or a tolerance of mixed units).
_POSITIVE = {
    "margin": "m",
    "tol_primal": "",
    "tol_stationarity": "",
    "max_step": "m, rad",
    "coarse_step": "m",
    "reference_ftol": "",
    "accept_primal": "",
    "accept_stationarity": "",
    "joint_limit_weight": "",
    "tool_force_speed": "m/s",
}


def default_coarse_step(reach: float) -> float:
    """The fast solver's ``coarse_step`` (m) for a robot whose tip at home is ``reach`` (m) from the base.

    The case paths are scaled with the reach (a circle of 0.1 m radius on the paper's robot is one of
    2.35 m on a 50-module arm), so the coarse samples and the approach from the start pose are
    spaced in proportion: ``COARSE_STEP * reach / PAPER_REACH``, the same number of coarse samples
    on every robot. A robot that reaches no farther than the paper's keeps exactly ``COARSE_STEP``
    (the paper's robot, bit for bit, and the small stacks).
    """
    if not reach > PAPER_REACH + SAME_REACH:
        return COARSE_STEP
    return COARSE_STEP * reach / PAPER_REACH


@dataclass(frozen=True)
class NewtonSettings:
    """Stopping tests and safeguards of the Newton iteration.

    Attributes:
        tol_primal: Largest equality residual (m; rad-like for the orientation rows).
        tol_stationarity: Largest entry of the Lagrangian gradient (cost per m).
        tol_active: Hysteresis of the active-set rule (m / multiplier units).
        max_iterations: Newton steps per sample before it is declared failed.
        max_step: Largest change of any joint value in one step (m, rad).
    """

    tol_primal: float = 1e-12
    tol_stationarity: float = 1e-10
    tol_active: float = 1e-12
    max_iterations: int = 30
    max_step: float = 0.02


@dataclass(frozen=True)
class FastSettings:
    """Settings of the fast solver.

    Attributes:
        newton: Stopping tests and safeguards of the Newton iterations.
        coarse_step: Largest tip travel between consecutive coarse samples, and step of the
            continuation from the start pose (m; 0.1 m counts for one radian of rotation).
        top_count: Smallest number of samples of the coarsest level.
        retry_pieces: Intermediate path samples of the continuation that retries a failed sample.
    """

    newton: NewtonSettings = field(default_factory=NewtonSettings)
    coarse_step: float = COARSE_STEP
    top_count: int = 4
    retry_pieces: int = 8


@dataclass(frozen=True)
class Tolerances:
    """Acceptance thresholds of a verified sample."""

    primal: float = 1e-10
    stationarity: float = 1e-6
    feasibility: float = 1e-10
    multiplier: float = 1e-8
    curvature: float = 1e-10


@dataclass(frozen=True)
class IKOptions:
    """Every tunable of the solvers, with its default.

    Attributes:
        margin: Assembly margin (m): every triangle inequality holds with at least this slack.
        initial_guess: ``(n,)`` start pose of the continuation (default: the robot's home pose).
        tol_primal: Newton stopping test on the equality residual (m; rad-like for orientation).
        tol_stationarity: Newton stopping test on the Lagrangian gradient.
        max_iterations: Newton steps per sample before it counts as failed.
        max_step: Largest joint change in one Newton step (m, rad).
        coarse_step: Tip travel between consecutive coarse samples of the fast solver (m); by default
            (None) :func:`default_coarse_step` of the robot's reach: 0.02 m on the paper's robot.
        fallback: Re-solve samples that the fast solver could not verify with the reference solver.
        reference_ftol: SLSQP's ``ftol`` (reference solver).
        reference_maxiter: SLSQP's and IPOPT's iteration limit per sample.
        accept_primal: Largest equality residual of an accepted sample (m; rad-like).
        accept_stationarity: Largest Lagrangian gradient of a verified sample.
        criterion: The redundancy criterion: ``"joint_limits"`` (paper eq. 12, the default) or
            ``"effort"`` (the static actuator efforts, :mod:`vgtarm.ik.effort`).
        joint_limit_weight: Weight of eq. 12's cost in the effort criterion (> 0).
        tool_force: Magnitude ``F0`` (N, >= 0) of the expected cutting force along the path
            (effort criterion; 0: gravity alone).
        tool_force_speed: Speed (m/s, > 0) over which the expected tool force is smoothed.
    """

    margin: float = DEFAULT_MARGIN
    initial_guess: NDArray[np.float64] | None = None
    tol_primal: float = 1e-12
    tol_stationarity: float = 1e-10
    max_iterations: int = 30
    max_step: float = 0.02
    coarse_step: float | None = None
    fallback: bool = True
    reference_ftol: float = 1e-15
    reference_maxiter: int = 200
    accept_primal: float = 1e-10
    accept_stationarity: float = 1e-6
    criterion: str = "joint_limits"
    joint_limit_weight: float = DEFAULT_JOINT_LIMIT_WEIGHT
    tool_force: float = 0.0
    tool_force_speed: float = DEFAULT_TOOL_FORCE_SPEED

    @classmethod
    def from_keywords(cls, options: dict[str, Any], n_joints: int = N_JOINTS) -> IKOptions:
        """Build from keyword arguments for a robot of ``n_joints`` joints; unknown names and bad values
        raise :class:`InputError`."""
        valid = [f.name for f in fields(cls)]
        unknown = sorted(set(options) - set(valid))
        if unknown:
            raise InputError(f"unknown inverse-kinematics option {unknown[0]!r}; valid options are {', '.join(valid)}")
        values = dict(options)
        for name, unit in _POSITIVE.items():
            if name in values and not (name == "coarse_step" and values[name] is None):
                values[name] = checks.positive(name, values[name], unit)
        if "criterion" in values:
            checks.choice("criterion", values["criterion"], CRITERIA)
        if "tool_force" in values:
            values["tool_force"] = checks.number("tool_force", values["tool_force"], minimum=0, unit="N")
        if values.get("criterion", "joint_limits") == "joint_limits":
            given = sorted({"joint_limit_weight", "tool_force", "tool_force_speed"} & set(values))
            if given:
                raise InputError(f"{given[0]} applies to criterion='effort' only; criterion is 'joint_limits'")
        for name in ("max_iterations", "reference_maxiter"):
            if name in values:
                values[name] = checks.whole(name, values[name], 1)
        if "fallback" in values:
            checks.flag("fallback", values["fallback"])
        if values.get("initial_guess") is not None:
            values["initial_guess"] = checks.finite_array("initial_guess", values["initial_guess"], (n_joints,)).copy()
        return cls(**values)

    @property
    def newton(self) -> NewtonSettings:
        """The Newton settings these options imply."""
        return NewtonSettings(
            tol_primal=self.tol_primal,
            tol_stationarity=self.tol_stationarity,
            max_iterations=self.max_iterations,
            max_step=self.max_step,
        )

    @property
    def fast(self) -> FastSettings:
        """The fast solver's settings these options imply."""
        step = COARSE_STEP if self.coarse_step is None else self.coarse_step
        return FastSettings(newton=self.newton, coarse_step=step)

    @property
    def tolerances(self) -> Tolerances:
        """Acceptance thresholds of the per-sample verification."""
        return Tolerances(primal=self.accept_primal, stationarity=self.accept_stationarity)
