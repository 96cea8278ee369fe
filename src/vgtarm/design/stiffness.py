"""Cartesian stiffness of the tool and its deflection under a tool wrench, from the joints' stiffness.

Each actuated joint is a spring (its ``[stiffness]`` in the robot file, N/m for a leg, N m/rad for a
twist: :class:`~vgtarm.model.parameters.JointStiffness`) about its commanded value ``q0``; the
passive joints follow by the closed-form forward kinematics, so the model's coordinates are the
``n`` actuated joints alone. A wrench ``w = (f, m)`` on the tool (force ``f`` (N) at the tool point
and moment ``m`` (N m), both in F0) holds the arm at rest where

    r(q) = K (q - q0) + g(q) - J(q)^T w = 0

with ``K = diag(k)``, ``g(q)`` the joint efforts of the bodies' weight (``dV/dq``, ``V`` the potential
energy) and ``J = [J_P; J_W]`` ``(6, n)``: the Jacobian of the tool point and the angular Jacobian of
the end-effector (F0 components). Its derivative is the tangent stiffness of the joints

    K_t = K + K_w + K_g,   K_w = dg/dq = d^2 V/dq^2,   K_g = -d(J^T w)/dq  (w held fixed)

(``K_g``: the geometric, load-dependent term of the tool wrench; ``K_w`` the same of the weight). A
small change of the wrench ``dw`` moves the joints by ``K_t dq = J^T dw`` and the tool by ``J dq``:
the Cartesian compliance is ``C = J K_t^-1 J^T`` ``(6, 6)``, its upper-left block ``(3, 3)`` the
translational compliance of the tool point, and the Cartesian stiffness their inverse where they
are invertible (``n >= 6`` with ``J`` of full rank for the pose; a planar module's tool point is
rigid across its plane and has none).

Every derivative comes from the one symbolic definition of the model (:mod:`vgtarm.model.definition`)
by CasADi's automatic differentiation: one function per structure, the parameters at run time.
:func:`deflection` solves the exact equilibrium by Newton's method, with the wrench and without it
(gravity on in both), and gives the tool's displacement between the two beside the linearised one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..errors import InputError, shown
from ..model.definition import Definition, PaperDefinition
from ..model.robot import Robot
from ..model.symbolic import SX, angular_velocity, unpack_parameters

Array = NDArray[np.float64]

#: Relative size under which a principal compliance counts as zero (a rigid direction: infinite
#: stiffness) and a compliance matrix as singular (no stiffness matrix).
RIGID = 1e-12
#: Default tolerance of the equilibrium: the residual force, relative to the largest force in it.
TOLERANCE = 1e-12
#: Most Newton iterations of an equilibrium.
MAX_ITERATIONS = 50


@dataclass(frozen=True)
class CartesianStiffness:
    """The stiffness of the tool at one configuration under one wrench (see the module docstring).

    Attributes (``n`` joints; units N/m, N m/rad and m/N, rad/(N m)):
        q: ``(n,)`` the configuration.
        wrench: ``(6,)`` the tool wrench ``(f, m)`` the geometric term is taken under (F0).
        jacobian: ``(6, n)`` ``J = [J_P; J_W]``.
        joint: ``(n, n)`` ``K = diag(k)``, the joints' springs.
        geometric: ``(n, n)`` ``K_g = -d(J^T w)/dq``.
        weight: ``(n, n)`` ``K_w = dg/dq`` of the bodies' weight (zero with ``gravity=False``).
        tangent: ``(n, n)`` ``K + K_w + K_g``.
        compliance: ``(6, 6)`` ``J tangent^-1 J^T``.
        stiffness: ``(6, 6)`` its inverse, or ``None`` where it is singular.
        translational_compliance: ``(3, 3)`` the upper-left block of ``compliance`` (m/N).
        translational_stiffness: ``(3, 3)`` its inverse, or ``None`` where it is singular (N/m).
        principal_stiffness: ``(3,)`` the stiffness along each principal direction, ascending
            (N/m; ``inf``: a rigid direction); the eigenvalues of the symmetric part of the
            translational compliance, inverted.
        principal_directions: ``(3, 3)`` the principal directions (columns, unit, F0).
    """

    q: Array
    wrench: Array
    jacobian: Array
    joint: Array
    geometric: Array
    weight: Array
    tangent: Array
    compliance: Array
    stiffness: Array | None
    translational_compliance: Array
    translational_stiffness: Array | None
    principal_stiffness: Array
    principal_directions: Array

    def linear_deflection(self, wrench: ArrayLike) -> Array:
        """The tool's linearised displacement and rotation ``(6,)`` (m, rad) under a change of the
        tool wrench ``wrench`` ((3,) force or (6,) force and moment, F0): ``compliance @ w``."""
        return np.asarray(self.compliance @ as_wrench(wrench))


@dataclass(frozen=True)
class Equilibrium:
    """The static equilibrium of :func:`static_equilibrium`: the joints ``q`` ``(n,)``, whether Newton
    converged (``success``, ``reason``), its ``iterations`` and the final ``residual`` (the largest
    joint force left, N or N m)."""

    q: Array
    success: bool
    reason: str
    iterations: int
    residual: float


@dataclass(frozen=True)
class Deflection:
    """The tool's deflection under a wrench (:func:`deflection`).

    Attributes:
        q_command: ``(n,)`` the commanded joints (the springs' rest values).
        wrench: ``(6,)`` the tool wrench (N, N m; F0).
        unloaded, loaded: the equilibria without and with the wrench (gravity on in both when
            ``gravity``).
        displacement: ``(3,)`` the tool point's exact displacement between them (m, F0).
        rotation: ``(3,)`` the end-effector's exact rotation between them, a rotation vector (rad, F0).
        linear: ``(6,)`` the linearised displacement and rotation ``C w`` at the unloaded equilibrium.
        stiffness: the :class:`CartesianStiffness` at the unloaded equilibrium (zero wrench).
        success: both equilibria converged.
    """

    q_command: Array
    wrench: Array
    unloaded: Equilibrium
    loaded: Equilibrium
    displacement: Array
    rotation: Array
    linear: Array
    stiffness: CartesianStiffness

    @property
    def success(self) -> bool:
        return self.unloaded.success and self.loaded.success


# -- the symbolic terms ---------------------------------------------------------------------------


def _potential(definition: Definition, q: SX, p: SX, coms: tuple[SX, ...]) -> SX:
    """The bodies' potential energy ``-sum m g . c`` (J), masses and gravity from ``p``."""
    if isinstance(definition, PaperDefinition):
        par = unpack_parameters(p)
        masses = [body.mass for body in par.bodies]
        gravity = par.gravity
    else:
        from ..model.stack.symbolic import unpack_stack_parameters

        spar = unpack_stack_parameters(definition.stack, p)
        masses = []
        for k, platform in enumerate(spar.platforms):
            masses.append(platform.mass)
            twist = spar.twist_bodies[k]
            if twist is not None:
                masses.append(twist.mass)
        masses.append(spar.end_effector.mass)
        gravity = spar.gravity
    if len(masses) != len(coms):
        raise RuntimeError(f"{len(masses)} masses for {len(coms)} bodies")  # a broken definition
    return -sum((m * ca.dot(gravity, c) for m, c in zip(masses, coms, strict=True)), SX(0))


@lru_cache(maxsize=8)
def _terms(definition: Definition) -> Any:
    """``(q, p, w) -> (tip, C03, J, g, K_w, K_g)``: one CasADi function per structure of the model."""
    n, n_p = definition.n_joints, definition.n_parameters
    q, qd, p, w = SX.sym("q", n), SX.sym("qd", n), SX.sym("p", n_p), SX.sym("w", 6)
    kin = definition.kinematics(q, p)
    J = ca.vertcat(ca.jacobian(kin.tip, q), ca.jacobian(angular_velocity(kin.C03, q, qd), qd))
    g = ca.gradient(_potential(definition, q, p, kin.body_com), q)
    outputs = [kin.tip, kin.C03, J, g, ca.jacobian(g, q), -ca.jacobian(J.T @ w, q)]
    names = ["tip", "C03", "J", "g", "K_w", "K_g"]
    return ca.Function("stiffness_terms", [q, p, w], outputs, ["q", "p", "w"], names)


@dataclass(frozen=True)
class _Terms:
    tip: Array
    rotation: Array
    J: Array
    g: Array
    K_w: Array
    K_g: Array


def _evaluate(robot: Robot, q: Array, w: Array) -> _Terms:
    out = _terms(robot.definition)(q, robot.parameter_vector, w)
    tip, rotation, J, g, K_w, K_g = (np.array(x, dtype=float) for x in out)
    return _Terms(tip.ravel(), rotation, J, g.ravel(), K_w, K_g)


# -- arguments ------------------------------------------------------------------------------------


def as_wrench(wrench: ArrayLike | None, name: str = "wrench") -> Array:
    """A tool wrench as ``(6,)``: ``None`` is zero, a force ``(3,)`` (N) has no moment, ``(6,)`` is
    ``(f, m)`` (N, N m); every element finite."""
    if wrench is None:
        return np.zeros(6)
    w = checks.finite_array(name, wrench)
    if w.shape not in ((3,), (6,)):
        checks.refuse(f"{name}.shape", w.shape, "(3,) a force (N) or (6,) a force and a moment (N, N m)")
    return np.concatenate([w, np.zeros(6 - len(w))])


def joint_stiffness(robot: Robot, stiffness: ArrayLike | None = None) -> Array:
    """The joints' stiffness ``(n,)`` (N/m, N m/rad): ``stiffness`` if given, else the robot file's
    ``[stiffness]`` table; a robot without one and no ``stiffness`` is refused."""
    if not isinstance(robot, Robot):
        raise InputError(f"robot = {shown(robot)}: expected a vgtarm.Robot (see vgtarm.load_robot)")
    if stiffness is None:
        table = getattr(robot.parameters, "stiffness", None)
        if table is None:
            raise InputError(
                f"robot {shown(robot.parameters.name)} has no [stiffness] table: give stiffness= (one value per "
                "joint, N/m and N m/rad) or load a robot file with one (examples/paper_robot_compliant.toml)"
            )
        return np.array(table.values, dtype=float)
    k = checks.finite_array("stiffness", stiffness, (robot.n_joints,))
    if not (k > 0).all():
        i = int(np.argmin(k > 0))
        checks.refuse(f"stiffness[{i}] ({robot.joint_names[i]})", float(k[i]), "a stiffness > 0 (N/m, N m/rad)")
    return k.copy()


def _configuration(robot: Robot, q: ArrayLike, name: str) -> Array:
    qa = checks.finite_array(name, q, (robot.n_joints,))
    robot.check_assembly(qa, where=name)
    return qa.copy()


# -- stiffness ------------------------------------------------------------------------------------


def cartesian_stiffness(
    robot: Robot,
    q: ArrayLike,
    wrench: ArrayLike | None = None,
    *,
    gravity: bool = True,
    stiffness: ArrayLike | None = None,
) -> CartesianStiffness:
    """The tool's compliance and stiffness at the configuration ``q`` ``(n,)`` under the tool wrench
    ``wrench`` ((3,) force or (6,) force and moment at the tool point, F0; default none), with the
    geometric term of that wrench and (``gravity``, default on) of the bodies' weight; the joints'
    springs are the robot file's ``[stiffness]`` or ``stiffness`` ``(n,)``."""
    k = joint_stiffness(robot, stiffness)
    qa = _configuration(robot, q, "q")
    w = as_wrench(wrench)
    checks.flag("gravity", gravity)
    return _stiffness(robot, qa, w, k, gravity, _evaluate(robot, qa, w))


def _inverse(matrix: Array) -> Array | None:
    """The inverse of a compliance matrix, or ``None`` where it is singular (relative :data:`RIGID`)."""
    values = np.linalg.svd(matrix, compute_uv=False)
    if values[-1] <= RIGID * max(values[0], 1e-300):
        return None
    return np.asarray(np.linalg.inv(matrix))


def _stiffness(robot: Robot, q: Array, w: Array, k: Array, gravity: bool, terms: _Terms) -> CartesianStiffness:
    K = np.diag(k)
    K_w = terms.K_w if gravity else np.zeros_like(K)
    tangent = K + K_w + terms.K_g
    J = terms.J
    compliance = J @ np.linalg.solve(tangent, J.T)
    translational = compliance[:3, :3]
    values, vectors = np.linalg.eigh(0.5 * (translational + translational.T))
    order = np.argsort(values)[::-1]  # most compliant first: the stiffness ascending
    values, vectors = values[order], vectors[:, order]
    rigid = values <= RIGID * max(float(np.abs(values).max()), 1e-300)
    with np.errstate(divide="ignore"):
        principal = np.where(rigid, np.inf, 1.0 / np.where(rigid, 1.0, values))
    return CartesianStiffness(
        q=q,
        wrench=w,
        jacobian=J,
        joint=K,
        geometric=terms.K_g,
        weight=K_w,
        tangent=tangent,
        compliance=compliance,
        stiffness=_inverse(compliance),
        translational_compliance=translational,
        translational_stiffness=_inverse(translational),
        principal_stiffness=principal,
        principal_directions=vectors,
    )


# -- equilibrium and deflection -------------------------------------------------------------------


def static_equilibrium(
    robot: Robot,
    q_command: ArrayLike,
    wrench: ArrayLike | None = None,
    *,
    gravity: bool = True,
    stiffness: ArrayLike | None = None,
    tolerance: float = TOLERANCE,
    max_iterations: int = MAX_ITERATIONS,
) -> Equilibrium:
    """The joints ``q`` at rest with springs about ``q_command`` ``(n,)`` under the tool wrench (and
    the weight, with ``gravity``): ``K (q - q0) + g(q) - J(q)^T w = 0`` solved by Newton's method
    with the exact tangent ``K + K_w + K_g``, from ``q_command``; a step that leaves the assemblable
    set or raises the residual is halved. Converged when the largest joint force left is at most
    ``tolerance`` times the largest force in the balance."""
    k = joint_stiffness(robot, stiffness)
    q0 = _configuration(robot, q_command, "q_command")
    checks.flag("gravity", gravity)
    checks.number("tolerance", tolerance, above=0, maximum=1)
    checks.whole("max_iterations", max_iterations, 1, 10_000)
    return _equilibrium(robot, q0, as_wrench(wrench), k, gravity, tolerance, max_iterations)


def _balance(robot: Robot, q: Array, q0: Array, w: Array, k: Array, gravity: bool) -> tuple[Array, float, _Terms]:
    """The residual ``r(q)`` ``(n,)``, the scale of its forces and the terms at ``q``."""
    terms = _evaluate(robot, q, w)
    spring = k * (q - q0)
    weight = terms.g if gravity else np.zeros_like(q)
    load = terms.J.T @ w
    scale = max(float(np.abs(spring).max()), float(np.abs(weight).max()), float(np.abs(load).max()), 1e-300)
    return spring + weight - load, scale, terms


def _equilibrium(
    robot: Robot, q0: Array, w: Array, k: Array, gravity: bool, tolerance: float, max_iterations: int
) -> Equilibrium:
    q = q0.copy()
    r, scale, terms = _balance(robot, q, q0, w, k, gravity)
    for iteration in range(max_iterations + 1):
        size = float(np.abs(r).max())
        if size <= tolerance * scale:
            return Equilibrium(q, True, "converged", iteration, size)
        if iteration == max_iterations:
            break
        tangent = np.diag(k) + (terms.K_w if gravity else 0.0) + terms.K_g
        step = -np.linalg.solve(tangent, r)
        for _ in range(40):  # halve a step that leaves the assemblable set or does not reduce r
            trial = q + step
            if bool(robot.is_assemblable(trial)):
                r_new, scale_new, terms_new = _balance(robot, trial, q0, w, k, gravity)
                if float(np.abs(r_new).max()) < size or np.abs(step).max() <= 1e-15 * (1.0 + np.abs(q).max()):
                    break
            step = 0.5 * step
        else:
            return Equilibrium(q, False, "no step reduces the residual", iteration, size)
        q, r, scale, terms = trial, r_new, scale_new, terms_new
    return Equilibrium(q, False, f"not converged in {max_iterations} iterations", max_iterations, size)


def rotation_vector(rotation: Array) -> Array:
    """The rotation vector ``(3,)`` (rad) of a rotation matrix ``(3, 3)`` (angle below pi)."""
    axis = 0.5 * np.array(
        [rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]]
    )
    sine = float(np.linalg.norm(axis))
    angle = math.atan2(sine, 0.5 * (float(np.trace(rotation)) - 1.0))
    return axis * (angle / sine if sine > 1e-300 else 1.0)


def deflection(
    robot: Robot,
    q_command: ArrayLike,
    wrench: ArrayLike,
    *,
    gravity: bool = True,
    stiffness: ArrayLike | None = None,
    tolerance: float = TOLERANCE,
    max_iterations: int = MAX_ITERATIONS,
) -> Deflection:
    """The tool's deflection under ``wrench`` ((3,) force or (6,) force and moment, F0) of the arm
    whose springs hold it about ``q_command`` ``(n,)``: the exact one, the equilibrium with the
    wrench minus the one without it (gravity on in both, with ``gravity``), and the linearised
    one, ``C w`` with the compliance at the unloaded equilibrium (:func:`cartesian_stiffness`)."""
    k = joint_stiffness(robot, stiffness)
    q0 = _configuration(robot, q_command, "q_command")
    w = as_wrench(wrench)
    checks.flag("gravity", gravity)
    checks.number("tolerance", tolerance, above=0, maximum=1)
    checks.whole("max_iterations", max_iterations, 1, 10_000)
    unloaded = _equilibrium(robot, q0, np.zeros(6), k, gravity, tolerance, max_iterations)
    loaded = _equilibrium(robot, q0, w, k, gravity, tolerance, max_iterations)
    before = _evaluate(robot, unloaded.q, np.zeros(6))
    after = _evaluate(robot, loaded.q, w)
    at_rest = _stiffness(robot, unloaded.q, np.zeros(6), k, gravity, before)
    return Deflection(
        q_command=q0,
        wrench=w,
        unloaded=unloaded,
        loaded=loaded,
        displacement=after.tip - before.tip,
        rotation=rotation_vector(after.rotation @ before.rotation.T),
        linear=at_rest.compliance @ w,
        stiffness=at_rest,
    )


__all__ = [
    "CartesianStiffness",
    "Deflection",
    "Equilibrium",
    "as_wrench",
    "cartesian_stiffness",
    "deflection",
    "joint_stiffness",
    "rotation_vector",
    "static_equilibrium",
]
