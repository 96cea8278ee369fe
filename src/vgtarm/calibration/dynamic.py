"""Dynamic identification: the inertial and friction parameters of a robot from its leg forces.

The inverse dynamics is linear in each body's ten *standard* parameters, taken about the body
frame's origin: the mass ``m``, the first moments ``m c`` (3) and the inertia about the origin
``I_O = I_C + m (|c|^2 1 - c c^T)`` (6: ``Ixx, Iyy, Izz, Ixy, Ixz, Iyz``), and in the viscous
coefficients (one per joint)::

    F = Y(q, qd, qdd) pi

:func:`regressor` builds ``Y`` from the robot's own compiled inverse dynamics: each column is the
difference of two valid robots' efforts (a reference of unit bodies and the same with one standard
parameter moved), which is exact up to round-off because ``F`` is linear in ``pi`` (the model is
written once, its derivatives by automatic differentiation: nothing is re-derived here).

Not every standard parameter moves the efforts (the planar platform of module 1 turns about one
axis only): :func:`base_parameters` finds the identifiable combinations by a QR decomposition with
column pivoting of a regressor stacked over random states, and names them. :func:`identify` fits
them by least squares (with their standard errors) and then finds the physically consistent
standard parameters closest to the data: each body's pseudo-inertia ``[[Sigma, h], [h^T, m]]``
(``Sigma = tr(I_O)/2 1 - I_O``, ``h = m c``) is written ``L L^T`` with ``L`` lower triangular and
a positive diagonal (the log-Cholesky parameterisation), so every candidate has a positive mass and
an inertia about its centre of mass that is positive definite and satisfies the triangle
inequalities; the viscous coefficients are bounded below by 0. What the data cannot determine is
held at the prior model's values by a weak pull (reported as such, never estimated).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numpy as np
import scipy.linalg
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..model.parameters import Body, RobotParameters
from ..model.robot import Robot
from ..model.stack import Stack

Array = NDArray[np.float64]

#: The ten standard parameters of one body, in the order of the regressor's columns.
STANDARD_NAMES: tuple[str, ...] = ("m", "mx", "my", "mz", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
#: Units of the standard parameters (then ``N s/m`` or ``N m s/rad`` for the viscous ones).
STANDARD_UNITS: tuple[str, ...] = ("kg", "kg m", "kg m", "kg m", *(("kg m^2",) * 6))
#: A column of the normalised stacked regressor whose pivot is below this (relative to the first)
#: is a combination of those before it.
RANK_TOLERANCE = 1e-8
#: Coefficients of a base combination below this are dropped from its name (not from its value).
NAME_TOLERANCE = 1e-9
#: Weight of the pull toward the prior model, relative to the columns' norms (what the data do not
#: determine takes the prior's values; what they do is moved by about this fraction of its error).
PRIOR_WEIGHT = 1e-3
#: Most evaluations of the consistent fit (it stops there when a body sits on the boundary of
#: consistency, which the log-Cholesky variables reach only at infinity; measured: the residual's
#: RMS is then within 0.1 % of where it goes).
FIT_EVALUATIONS = 200
#: Index of ``(i, j)`` of a symmetric 3x3 matrix in ``Ixx, Iyy, Izz, Ixy, Ixz, Iyz``.
_SYMMETRIC = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


# -- standard parameters --------------------------------------------------------------------------


def body_standard(body: Body) -> Array:
    """The ten standard parameters of ``body`` about its frame's origin, ``(10,)`` (module docstring)."""
    m, c = body.mass, np.array(body.com, dtype=float)
    inertia = body.inertia_matrix + m * (c @ c * np.eye(3) - np.outer(c, c))
    return np.array([m, *(m * c), *(inertia[i, j] for i, j in _SYMMETRIC)])


def body_from_standard(values: ArrayLike, name: str) -> Body:
    """The body (mass, centre of mass, inertia about it) of ten standard parameters; not checked here
    (a :class:`RobotParameters` or :class:`Stack` built with it checks it)."""
    v = np.asarray(values, dtype=float)
    m = float(v[0])
    c = v[1:4] / m
    inertia = np.zeros((3, 3))
    for k, (i, j) in enumerate(_SYMMETRIC):
        inertia[i, j] = inertia[j, i] = v[4 + k]
    inertia_c = inertia - m * (c @ c * np.eye(3) - np.outer(c, c))
    inertia_c = 0.5 * (inertia_c + inertia_c.T)
    return Body(
        name=name,
        mass=m,
        com=(float(c[0]), float(c[1]), float(c[2])),
        inertia=tuple(tuple(float(x) for x in row) for row in inertia_c),
    )


def standard_names(parameters: RobotParameters | Stack) -> tuple[str, ...]:
    """Names of the standard parameters: ``<body>.<parameter>`` for each body, then ``viscous.<joint>``."""
    bodies = _body_names(parameters)
    return (
        *(f"{body}.{name}" for body in bodies for name in STANDARD_NAMES),
        *(f"viscous.{joint}" for joint in parameters.joint_names),
    )


def standard_vector(parameters: RobotParameters | Stack) -> Array:
    """The standard parameters of a robot: ten per body, then the viscous coefficients, ``(10 b + n,)``."""
    values = [body_standard(body) for body in parameters.bodies]
    return np.concatenate([*values, np.asarray(parameters.viscous, dtype=float)])


def with_standard(parameters: RobotParameters | Stack, values: ArrayLike, *, name: str | None = None) -> Any:
    """``parameters`` with its bodies and viscous coefficients from standard ``values`` (geometry, limits
    and the rest unchanged). Raises :class:`~vgtarm.errors.ConfigError` for an invalid body."""
    v = np.asarray(values, dtype=float)
    names = _body_names(parameters)
    bodies = [body_from_standard(v[10 * k : 10 * k + 10], body) for k, body in enumerate(names)]
    viscous = [float(x) for x in v[10 * len(names) :]]
    title = parameters.name if name is None else name
    if isinstance(parameters, RobotParameters):
        return replace(parameters, name=title, bodies=tuple(bodies), viscous=tuple(viscous))  # type: ignore[arg-type]
    return _stack_with(parameters, bodies, viscous, title)


def _body_names(parameters: RobotParameters | Stack) -> tuple[str, ...]:
    if isinstance(parameters, Stack):
        return parameters.body_names
    return tuple(body.name for body in parameters.bodies)


def _stack_with(stack: Stack, bodies: list[Body], viscous: list[float], name: str) -> Stack:
    """``stack`` with its bodies (in the order of ``body_names``) and viscous coefficients replaced."""
    bodies_left, viscous_left = list(bodies), list(viscous)
    modules = []
    for module in stack.modules:
        platform = bodies_left.pop(0)
        legs = (viscous_left.pop(0), viscous_left.pop(0), viscous_left.pop(0))
        twist = module.twist
        if twist is not None:
            body = None if twist.body is None else bodies_left.pop(0)
            twist = replace(twist, viscous=viscous_left.pop(0), body=body)
        modules.append(replace(module, platform=platform, viscous=legs, twist=twist))
    return replace(stack, name=name, modules=tuple(modules), end_effector=bodies_left.pop(0))


# -- the regressor ---------------------------------------------------------------------------------

#: The unit reference body (standard parameters) the columns are differences from, and the step of
#: each parameter: every moved body stays valid (positive mass, inertia positive and triangular).
_REFERENCE = np.array([1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
_STEP = np.array([1.0, 0.1, 0.1, 0.1, 0.5, 0.5, 0.5, 0.1, 0.1, 0.1])


def regressor(robot: Robot, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike) -> Array:
    """The regressor ``Y`` with ``F = Y pi`` (``pi``: :func:`standard_vector`), ``(N, n, 10 b + n)``.

    ``q``, ``qd``, ``qdd`` are ``(N, n)`` (m, m/s, m/s^2; rad for the twists); no tip force. Each
    column is ``(F(pi_ref + step e_k) - F(pi_ref)) / step`` for a reference of unit bodies (module
    docstring), the robot's own compiled inverse dynamics evaluated ``10 b + n + 1`` times.
    """
    q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
    reference, moved, steps = _column_robots(robot)
    base = reference.inverse_dynamics(q, qd, qdd)
    columns = [(other.inverse_dynamics(q, qd, qdd) - base) / step for other, step in zip(moved, steps, strict=True)]
    return np.stack(columns, axis=-1)


@lru_cache(maxsize=8)
def _column_robots(robot: Robot) -> tuple[Robot, tuple[Robot, ...], Array]:
    """The reference robot of unit bodies and, per standard parameter, the robot with it moved by its
    step (sharing ``robot``'s compiled model), and the steps: built once per robot."""
    parameters = robot.parameters
    n_bodies = len(parameters.bodies)
    reference = np.concatenate([np.tile(_REFERENCE, n_bodies), np.zeros(robot.n_joints)])
    steps = np.concatenate([np.tile(_STEP, n_bodies), np.ones(robot.n_joints)])
    moved = []
    for k, step in enumerate(steps):
        values = reference.copy()
        values[k] += step
        moved.append(robot.with_parameters(with_standard(parameters, values)))
    return robot.with_parameters(with_standard(parameters, reference)), tuple(moved), steps


# -- base parameters -------------------------------------------------------------------------------


@dataclass(frozen=True)
class BaseParameters:
    """The identifiable combinations of the standard parameters: ``beta = combination @ pi``.

    Attributes:
        names: the standard parameters' names (:func:`standard_names`), ``(p,)``.
        independent: indices (in ``names``) of the standard parameter that leads each combination, ``(r,)``.
        combination: ``(r, p)``: row ``j`` is 1 at ``independent[j]``, the coefficients of the
            dependent parameters it absorbs, 0 elsewhere.
        labels: each combination written out (``platform2.m + 0.01 end_effector.Izz``).
        undetermined: standard parameters that move no effort at all (their column is zero).
        singular_values: of the column-normalised stacked base regressor (decreasing): its conditioning.
    """

    names: tuple[str, ...]
    independent: tuple[int, ...]
    combination: Array
    labels: tuple[str, ...]
    undetermined: tuple[str, ...]
    singular_values: Array

    @property
    def size(self) -> int:
        """Number of base parameters ``r``."""
        return len(self.independent)

    def of(self, standard: ArrayLike) -> Array:
        """The base parameters of standard parameters ``(p,)``, ``(r,)``."""
        return self.combination @ np.asarray(standard, dtype=float)

    def regressor(self, full: Array) -> Array:
        """The base regressor: the independent columns of a regressor ``(..., p)``, ``(..., r)``."""
        return full[..., list(self.independent)]


def random_states(robot: Robot, samples: int, *, seed: int = 0, margin: float = 0.005) -> tuple[Array, Array, Array]:
    """``samples`` states ``(q, qd, qdd)``, each ``(samples, n)``: ``q`` uniform inside the joint limits and
    assemblable with ``margin`` (m); rates and accelerations normal with the joints' ranges per second."""
    checks.whole("samples", samples, minimum=1)
    rng = np.random.default_rng(checks.seed("seed", seed))
    lower, upper = robot.joint_limits()
    chosen: list[Array] = []
    while sum(len(c) for c in chosen) < samples:
        q = rng.uniform(lower, upper, size=(4 * samples, robot.n_joints))
        chosen.append(q[robot.is_assemblable(q, margin)])
    q = np.concatenate(chosen)[:samples]
    span = upper - lower
    return q, rng.normal(size=q.shape) * span, rng.normal(size=q.shape) * span


def base_parameters(robot: Robot, *, samples: int = 200, seed: int = 0) -> BaseParameters:
    """The base parameters of ``robot`` from its regressor stacked over ``samples`` random states
    (:func:`random_states`): a QR decomposition with column pivoting of the column-normalised
    regressor, the rank from :data:`RANK_TOLERANCE`, each dependent column written in the
    independent ones (which are then put back in the order of the standard parameters)."""
    q, qd, qdd = random_states(robot, samples, seed=seed)
    stacked = regressor(robot, q, qd, qdd).reshape(-1, len(standard_names(robot.parameters)))
    names = standard_names(robot.parameters)
    norms = np.linalg.norm(stacked, axis=0)
    scale = norms.max()
    zero = norms <= RANK_TOLERANCE * scale
    live = np.flatnonzero(~zero)
    normalised = stacked[:, live] / norms[live]
    _, r_factor, pivots = scipy.linalg.qr(normalised, mode="economic", pivoting=True)
    diagonal = np.abs(np.diag(r_factor))
    rank = int(np.count_nonzero(diagonal > RANK_TOLERANCE * diagonal[0]))
    order = np.argsort(pivots[:rank])  # the independent columns in the standard order
    first, rest = pivots[:rank][order], pivots[rank:]
    coefficients = scipy.linalg.solve_triangular(r_factor[:rank, :rank], r_factor[:rank, rank:])[order]
    combination = np.zeros((rank, len(names)))
    combination[np.arange(rank), live[first]] = 1.0
    # unnormalised: column_dep = sum_j column_j K_j norms_dep / norms_j
    combination[:, live[rest]] = coefficients * norms[live[rest]] / norms[live[first]][:, None]
    labels = tuple(_label(names, row, int(lead)) for row, lead in zip(combination, live[first], strict=True))
    singular = scipy.linalg.svdvals(normalised[:, first])
    return BaseParameters(
        names=names,
        independent=tuple(int(i) for i in live[first]),
        combination=combination,
        labels=labels,
        undetermined=tuple(names[i] for i in np.flatnonzero(zero)),
        singular_values=singular,
    )


def _label(names: tuple[str, ...], row: Array, lead: int) -> str:
    """The combination ``row`` written out, its leading parameter ``lead`` first."""
    others = [int(i) for i in np.flatnonzero(np.abs(row) > NAME_TOLERANCE) if i != lead]
    text = names[lead]
    for i in others:
        c = float(row[i])
        size = abs(c)
        factor = "" if abs(size - 1.0) <= NAME_TOLERANCE else f"{size:.6g} "
        text += f" {'-' if c < 0 else '+'} {factor}{names[i]}"
    return text


# -- the measurements ------------------------------------------------------------------------------


def check_measurements(
    robot: Robot, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, forces: ArrayLike
) -> tuple[Array, ...]:
    """The measurements as ``(N, n)`` float arrays, or one :class:`~vgtarm.errors.InputError` line naming
    the first bad row (counted from 1): a value that is not finite, a joint outside its limits, a leg
    set that cannot be assembled."""
    arrays = []
    for label, value in (("q", q), ("qd", qd), ("qdd", qdd), ("forces", forces)):
        array = checks.number_array(label, value, shape=(None, robot.n_joints))
        arrays.append(np.asarray(array, dtype=float))
    rows = {len(a) for a in arrays}
    if len(rows) != 1:
        checks.refuse("measurements", [len(a) for a in arrays], "q, qd, qdd and forces with the same number of rows")
    for label, array in zip(("q", "qd", "qdd", "forces"), arrays, strict=True):
        bad = ~np.isfinite(array)
        if bad.any():
            row, joint = np.argwhere(bad)[0]
            name = robot.joint_names[joint]
            checks.refuse(f"row {row + 1}: {label}[{name}]", array[row, joint], "a finite number")
    lower, upper = robot.joint_limits()
    outside = (arrays[0] < lower) | (arrays[0] > upper)
    if outside.any():
        row, joint = np.argwhere(outside)[0]
        name, unit = robot.joint_names[joint], robot.joint_units[joint]
        expected = f"a value inside the joint limits [{lower[joint]:.6g}, {upper[joint]:.6g}] ({unit})"
        checks.refuse(f"row {row + 1}: q[{name}]", arrays[0][row, joint], expected)
    assembled = robot.is_assemblable(arrays[0])
    if not assembled.all():
        row = int(np.flatnonzero(~assembled)[0])
        checks.refuse(
            f"row {row + 1}: q", arrays[0][row].tolist(), "legs that can be assembled (triangle inequalities)"
        )
    return tuple(arrays)


# -- physically consistent parameters: the log-Cholesky map ---------------------------------------

_LOWER = np.tril_indices(4)
#: Positions in the flattened ``_LOWER`` entries of the diagonal (exponentiated) entries.
_DIAGONAL = np.flatnonzero(_LOWER[0] == _LOWER[1])


def _pseudo_to_standard(pseudo: Array) -> Array:
    """Standard parameters ``(10,)`` of a pseudo-inertia ``[[Sigma, h], [h^T, m]]`` (linear)."""
    sigma = pseudo[:3, :3]
    inertia = np.trace(sigma) * np.eye(3) - sigma
    return np.array([pseudo[3, 3], *pseudo[:3, 3], *(inertia[i, j] for i, j in _SYMMETRIC)])


def _standard_to_pseudo(values: Array) -> Array:
    inertia = np.zeros((3, 3))
    for k, (i, j) in enumerate(_SYMMETRIC):
        inertia[i, j] = inertia[j, i] = values[4 + k]
    pseudo = np.zeros((4, 4))
    pseudo[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    pseudo[:3, 3] = pseudo[3, :3] = values[1:4]
    pseudo[3, 3] = values[0]
    return pseudo


def _cholesky_factor(x: Array) -> Array:
    factor = np.zeros((4, 4))
    values = np.array(x, dtype=float)
    values[_DIAGONAL] = np.exp(values[_DIAGONAL])
    factor[_LOWER] = values
    return factor


def body_from_log_cholesky(x: ArrayLike, reference: ArrayLike | None = None) -> tuple[Array, Array]:
    """Standard parameters ``(10,)`` of the log-Cholesky variables ``x`` ``(10,)`` and their Jacobian ``(10, 10)``.

    The pseudo-inertia is ``(L0 M) (L0 M)^T`` with ``M`` lower triangular, ``exp`` of its diagonal
    variables, and ``L0`` the Cholesky factor of a ``reference`` body (``None``: the identity; ``x =
    0`` then gives the reference), so it is positive definite: a positive mass and a physically
    consistent inertia, for any ``x``. The reference scales the variables to the body's own size.
    """
    base = np.eye(4) if reference is None else np.linalg.cholesky(_standard_to_pseudo(np.asarray(reference, float)))
    inner = _cholesky_factor(np.asarray(x, dtype=float))
    factor = base @ inner
    values = _pseudo_to_standard(factor @ factor.T)
    jacobian = np.empty((10, 10))
    for k, (i, j) in enumerate(zip(*_LOWER, strict=True)):
        unit = np.zeros((4, 4))
        unit[i, j] = inner[i, j] if k in _DIAGONAL else 1.0
        moved = base @ unit
        jacobian[:, k] = _pseudo_to_standard(moved @ factor.T + factor @ moved.T)
    return values, jacobian


def log_cholesky_of(values: ArrayLike, reference: ArrayLike | None = None) -> Array:
    """The log-Cholesky variables ``(10,)`` of a physically consistent body's standard parameters
    (relative to ``reference``, as :func:`body_from_log_cholesky`)."""
    factor = np.linalg.cholesky(_standard_to_pseudo(np.asarray(values, dtype=float)))
    if reference is not None:
        base = np.linalg.cholesky(_standard_to_pseudo(np.asarray(reference, dtype=float)))
        factor = scipy.linalg.solve_triangular(base, factor, lower=True)
    x = np.array(factor[_LOWER], dtype=float)
    x[_DIAGONAL] = np.log(x[_DIAGONAL])
    return x


def nearest_consistent(values: ArrayLike, floor: float = 1e-3) -> Array:
    """Standard parameters ``(10,)`` made consistent: the pseudo-inertia's eigenvalues raised to at
    least ``floor`` times the largest (unchanged if already so)."""
    moments, vectors = np.linalg.eigh(_standard_to_pseudo(np.asarray(values, dtype=float)))
    top = max(float(moments[-1]), np.finfo(float).tiny)
    clipped = np.maximum(moments, floor * top)
    return _pseudo_to_standard((vectors * clipped) @ vectors.T)


def is_consistent(values: ArrayLike) -> bool:
    """Whether standard parameters ``(10,)`` are a physical body: a positive definite pseudo-inertia
    (a positive mass, an inertia about the centre of mass positive with its triangle inequalities)."""
    return bool(np.linalg.eigvalsh(_standard_to_pseudo(np.asarray(values, dtype=float)))[0] > 0.0)


# -- identification --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Identification:
    """The result of :func:`identify`.

    Attributes:
        base: the base parameters (:class:`BaseParameters`).
        least_squares: their ordinary least-squares estimate, ``(r,)``.
        standard_errors: its standard errors, ``(r,)``.
        noise: each joint's noise, the RMS of its residuals of a first ordinary fit, ``(n,)`` (N, N m).
        consistent: the base parameters of the physically consistent estimate, ``(r,)``.
        standard: the consistent estimate's standard parameters, ``(p,)`` (what the data leave
            undetermined: the prior's values).
        prior: the prior model's standard parameters, ``(p,)``.
        parameters: the identified robot (the prior's geometry, limits and actuators; the consistent
            bodies and viscous coefficients): a ``RobotParameters`` or a ``Stack``, usable as a
            controller's model.
        residual: the consistent estimate's force residuals ``F - Y pi``, ``(N, n)`` (N, N m).
        rms_least_squares, rms_consistent: RMS of the residuals of either estimate (N, N m).
        condition_number: of the column-normalised base regressor of the data.
        samples: rows of the data; success, message: whether the consistent fit converged, and why not.
    """

    base: BaseParameters
    least_squares: Array
    standard_errors: Array
    noise: Array
    consistent: Array
    standard: Array
    prior: Array
    parameters: Any
    residual: Array
    rms_least_squares: float
    rms_consistent: float
    condition_number: float
    samples: int
    success: bool
    message: str


def identify(
    robot: Robot,
    q: ArrayLike,
    qd: ArrayLike,
    qdd: ArrayLike,
    forces: ArrayLike,
    *,
    base: BaseParameters | None = None,
    name: str | None = None,
    seed: int = 0,
) -> Identification:
    """Identify the inertial and viscous parameters of ``robot`` from measured actuator ``forces`` along
    ``(q, qd, qdd)`` (each ``(N, n)``: m, m/s, m/s^2, N; rad and N m for the twists; no tip force).

    ``robot``'s parameters are the prior: its geometry is kept and its bodies give what the data
    cannot determine. ``base`` (default :func:`base_parameters` of ``robot`` with ``seed``) says which
    combinations are fitted. Refused (one :class:`~vgtarm.errors.InputError` line): a bad row
    (:func:`check_measurements`), fewer equations ``N n`` than base parameters plus one, data that
    do not excite every base parameter (naming one).
    """
    q, qd, qdd, forces = check_measurements(robot, q, qd, qdd, forces)
    base = base if base is not None else base_parameters(robot, seed=seed)
    samples, n = q.shape
    if samples * n <= base.size:
        checks.refuse(
            "samples", samples, f"more than {base.size // n} rows ({n} forces each) for {base.size} base parameters"
        )
    full = regressor(robot, q, qd, qdd).reshape(samples * n, -1)
    design, measured = base.regressor(full), forces.reshape(-1)
    _check_excited(design, base)
    solution = _weighted_least_squares(design, measured, n)
    estimate = solution.estimate
    residual = measured - design @ estimate
    prior = standard_vector(robot.parameters)
    scale = np.maximum(np.linalg.norm(full, axis=0), 1e-3 * np.linalg.norm(full, axis=0).max())
    weighted = solution.r_factor @ base.combination
    fit = _consistent_fit(weighted, solution.projected, prior, scale, len(robot.parameters.bodies))
    standard = fit.standard
    title = name if name is not None else f"{robot.parameters.name} (identified)"
    parameters = with_standard(robot.parameters, standard, name=title)
    final = measured - full @ standard
    normalised = design / np.linalg.norm(design, axis=0)
    return Identification(
        base=base,
        least_squares=estimate,
        standard_errors=solution.errors,
        noise=solution.noise,
        consistent=base.of(standard),
        standard=standard,
        prior=prior,
        parameters=parameters,
        residual=final.reshape(samples, n),
        rms_least_squares=float(np.sqrt(np.mean(residual**2))),
        rms_consistent=float(np.sqrt(np.mean(final**2))),
        condition_number=float(np.linalg.cond(normalised)),
        samples=samples,
        success=fit.success,
        message=fit.message,
    )


@dataclass(frozen=True)
class _LeastSquares:
    estimate: Array
    errors: Array
    noise: Array
    r_factor: Array
    projected: Array


def _weighted_least_squares(design: Array, measured: Array, n: int) -> _LeastSquares:
    """Least squares of ``design beta = measured`` (rows joint after joint of each sample) weighted by
    each joint's noise, estimated from a first unweighted fit (legs in N and twists in N m differ);
    the standard errors from the weighted residuals. ``r_factor`` and ``projected`` give the weighted
    residual's norm as ``|r_factor beta - projected|`` up to a constant."""
    size = design.shape[1]
    first = np.linalg.lstsq(design, measured, rcond=None)[0]
    per_joint = (measured - design @ first).reshape(-1, n)
    dof = max(per_joint.size - size, 1) / per_joint.size
    noise = np.sqrt(np.mean(per_joint**2, axis=0) / dof)
    floor = max(float(noise.max()) * 1e-6, np.finfo(float).tiny)
    weights = np.tile(1.0 / np.maximum(noise, floor), len(per_joint))
    q_factor, r_factor = np.linalg.qr(design * weights[:, None])
    projected = q_factor.T @ (measured * weights)
    estimate = scipy.linalg.solve_triangular(r_factor, projected)
    residual = (measured - design @ estimate) * weights
    scale = float(np.sqrt(residual @ residual / max(len(residual) - size, 1)))
    inverse_r = scipy.linalg.solve_triangular(r_factor, np.eye(size))
    errors = scale * np.sqrt(np.sum(inverse_r**2, axis=1))
    return _LeastSquares(estimate, errors, noise, r_factor, projected)


def _check_excited(design: Array, base: BaseParameters) -> None:
    """Refuse data whose base regressor is rank deficient, naming a base parameter they do not excite."""
    norms = np.linalg.norm(design, axis=0)
    if (norms == 0.0).any():
        checks.refuse(
            "data", base.labels[int(np.argmin(norms))], "data that move this base parameter (it has no effect)"
        )
    _, r_factor, pivots = scipy.linalg.qr(design / norms, mode="economic", pivoting=True)
    diagonal = np.abs(np.diag(r_factor))
    weak = np.flatnonzero(diagonal <= RANK_TOLERANCE * diagonal[0])
    if weak.size:
        label = base.labels[int(pivots[weak[0]])]
        checks.refuse(
            "data",
            label,
            f"data that excite every base parameter ({weak.size} of {base.size} are not: use an exciting trajectory)",
        )


@dataclass(frozen=True)
class _Fit:
    standard: Array
    success: bool
    message: str


def _consistent_fit(weighted: Array, target: Array, prior: Array, scale: Array, n_bodies: int) -> _Fit:
    """The physically consistent standard parameters minimising ``|weighted pi - target|^2`` plus the
    weak pull ``PRIOR_WEIGHT^2 |scale (pi - prior)|^2``: log-Cholesky bodies relative to the prior's,
    viscous >= 0. It starts from the least-squares fit nearest the prior (made consistent)."""
    n_body_values = 10 * n_bodies
    pull = PRIOR_WEIGHT * scale
    parts = [slice(10 * k, 10 * k + 10) for k in range(n_bodies)]

    def standard_of(x: Array) -> tuple[Array, Array]:
        values, jacobian = np.empty(len(x)), np.zeros((len(x), len(x)))
        for part in parts:
            values[part], jacobian[part, part] = body_from_log_cholesky(x[part], prior[part])
        values[n_body_values:] = x[n_body_values:]
        jacobian[n_body_values:, n_body_values:] = np.eye(len(x) - n_body_values)
        return values, jacobian

    def residual(x: Array) -> Array:
        values, _ = standard_of(x)
        return np.concatenate([weighted @ values - target, pull * (values - prior)])

    def jacobian(x: Array) -> Array:
        _, inner = standard_of(x)
        return np.vstack([weighted @ inner, pull[:, None] * inner])

    # the least-squares solution nearest the prior (in the pulled metric), made consistent
    augmented = np.vstack([weighted, np.diag(pull)])
    shift = np.linalg.lstsq(augmented, np.concatenate([target - weighted @ prior, np.zeros(len(prior))]), rcond=None)
    guess = prior + shift[0]
    start = np.concatenate(
        [*(log_cholesky_of(nearest_consistent(guess[part]), prior[part]) for part in parts), guess[n_body_values:]]
    )
    lower = np.concatenate([np.full(n_body_values, -np.inf), np.zeros(len(prior) - n_body_values)])
    start[n_body_values:] = np.maximum(start[n_body_values:], 0.0)
    solution = scipy.optimize.least_squares(
        residual,
        start,
        jac=jacobian,
        bounds=(lower, np.inf),
        x_scale="jac",
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
        max_nfev=FIT_EVALUATIONS,
    )
    values, _ = standard_of(solution.x)
    return _Fit(values, bool(solution.success), str(solution.message))


# -- simulated measurements ------------------------------------------------------------------------


def perturbed_parameters(
    parameters: RobotParameters | Stack, *, mass: float = 0.2, friction: float = 0.5, seed: int = 0
) -> Any:
    """A "true" robot for simulated identification: each body's mass and inertia times one factor
    uniform in ``[1 - mass, 1 + mass]`` (its centre of mass kept), each viscous coefficient times a
    factor uniform in ``[1 - friction, 1 + friction]``."""
    checks.number("mass", mass, minimum=0.0, below=1.0)
    checks.number("friction", friction, minimum=0.0, maximum=1.0)
    rng = np.random.default_rng(checks.seed("seed", seed))
    values = standard_vector(parameters)
    n_bodies = len(parameters.bodies)
    factors = rng.uniform(1.0 - mass, 1.0 + mass, size=n_bodies)
    values[: 10 * n_bodies] *= np.repeat(factors, 10)
    values[10 * n_bodies :] *= rng.uniform(1.0 - friction, 1.0 + friction, size=parameters.n_joints)
    return with_standard(parameters, values, name=f"{parameters.name} (perturbed, seed {seed})")


def simulated_forces(
    robot: Robot, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, *, noise: ArrayLike = 0.5, seed: int = 0
) -> Array:
    """The actuator forces of ``robot`` along ``(q, qd, qdd)`` plus white Gaussian noise of standard
    deviation ``noise`` (N for legs, N m for twists; one value, or one per joint), ``(N, n)``."""
    sigma = np.broadcast_to(checks.number_array("noise", noise), (robot.n_joints,))
    if not (np.isfinite(sigma) & (sigma >= 0)).all():
        checks.refuse("noise", np.asarray(noise).tolist(), "standard deviations >= 0 (N, N m)")
    rng = np.random.default_rng(checks.seed("seed", seed))
    forces = robot.inverse_dynamics(q, qd, qdd)
    return forces + sigma * rng.standard_normal(forces.shape)


#: Share of the samples :func:`holdout_check` predicts from a fit to the rest.
HOLDOUT_FRACTION = 0.3


def _rms_of(values: Array) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def holdout_check(
    robot: Robot, result: Identification, data: tuple[np.ndarray, ...], fraction: float = HOLDOUT_FRACTION
) -> dict[str, Any] | None:
    """Predict the last ``fraction`` of the samples from a least-squares fit of the base parameters
    (weighted by each joint's noise, as :func:`~vgtarm.calibration.dynamic.identify`) to the others:
    the RMS residual of the fit and of the prediction (N, N m), or ``None`` when the first part does
    not excite every base parameter (its base regressor is rank deficient)."""
    q, qd, qdd, forces = data
    samples, n = q.shape
    split = int(round((1.0 - fraction) * samples))
    design = result.base.regressor(regressor(robot, q, qd, qdd))  # (N, n, r)
    weights = 1.0 / np.maximum(result.noise, np.finfo(float).tiny)
    train = (design[:split] * weights[:, None]).reshape(-1, design.shape[2])
    norms = np.linalg.norm(train, axis=0)
    if not 0 < split < samples or not (norms > 0).all():
        return None
    if np.linalg.matrix_rank(train / norms, tol=RANK_TOLERANCE * np.linalg.norm(train / norms, 2)) < train.shape[1]:
        return None
    estimate = np.linalg.lstsq(train, (forces[:split] * weights).reshape(-1), rcond=None)[0]
    residual = forces - design @ estimate
    return {
        "fit_samples": split,
        "test_samples": samples - split,
        "rms_fit": _rms_of(residual[:split]),
        "rms_prediction": _rms_of(residual[split:]),
    }
