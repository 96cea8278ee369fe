"""Dexterity of any VGT robot along joint configurations: manipulability, condition number and each
module's distance from its flat-truss singularity.

All three are evaluated on arrays of configurations ``q`` ``(N, n)``: a grid (:func:`joint_grid`),
a run's joint trajectory, the samples of a workspace.

- **Manipulability** ``w = sqrt(det(J J^T))`` of the tip Jacobian ``J = dP/dq`` ``(3, n)`` (m^3
  per joint unit cubed: leg rates in m/s and twist rates in rad/s mix as the model's ``q`` does);
  the volume of the tip's velocity ellipsoid for unit joint rates (Yoshikawa).
- **Condition number** ``sigma_max / sigma_min`` of the same ``J`` (3.06 at the reference robot's
  home): 1 for an isotropic tip, infinite where the tip loses a direction.
- **Distance from the flat-truss singularity** of module ``k``: its closure (the passive joints
  ``B'`` and ``A'`` from the legs, docs/conventions.md) solves two triangles, ``(2b, v, p)`` for
  ``B'`` and ``(s, p, 2d)`` for ``A'``. The Jacobian of the closure equations
  ``|B' - A| = p, |B' - B| = v, |A' - A| = s, |A' - B'| = 2d`` with respect to ``(B', A')`` is
  block triangular with unit rows; its determinant is ``sin(phi_B') sin(phi_A')``, the sines of
  the angles the two constraints meet at in each triangle (at ``B'`` between the diagonal and
  leg ``v``, at ``A'`` between leg ``s`` and the platform edge). It loses rank exactly when a
  triangle folds flat: the platform onto the base line, or the top joint onto the diagonal, which
  is also where a triangle inequality (assembly) fails. The dimensionless distance is
  ``min(sin phi_B', sin phi_A')`` in ``[0, 1]``: 1 with both constraints at right angles, 0 on the
  singularity, and ``1 / distance`` bounds how much the passive joints amplify a leg error.
  From Heron's formula, ``sin phi_B' = sqrt((v+p+2b)(v+p-2b)(2b+p-v)(2b+v-p)) / (2 p v)`` and
  ``sin phi_A' = sqrt((s+p+2d)(s+p-2d)(s+2d-p)(p+2d-s)) / (4 s d)``: the products of the
  assembly margins (:func:`vgtarm.model.assembly.triangle_margins`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..errors import InputError, shown

Array = NDArray[np.float64]

#: Most configurations :func:`joint_grid` builds.
MAX_GRID = 5_000_000


@dataclass(frozen=True)
class Dexterity:
    """Dexterity measures of ``N`` configurations (:func:`dexterity`).

    Attributes:
        q: ``(N, n)`` the configurations (m, rad).
        manipulability: ``(N,)`` ``sqrt(det(J J^T))`` of the tip Jacobian.
        condition: ``(N,)`` its condition number ``sigma_max / sigma_min`` (inf where rank < 3).
        singular_values: ``(N, 3)`` its singular values, largest first.
        module_distance: ``(N, m)`` each module's distance from its flat-truss singularity (0 to 1).
        module_names: the modules' names, ``module1``, ``module2``, ...
    """

    q: Array
    manipulability: Array
    condition: Array
    singular_values: Array
    module_distance: Array
    module_names: tuple[str, ...]

    @property
    def truss_distance(self) -> Array:
        """``(N,)`` the smallest module distance of each configuration (the arm's nearest fold)."""
        return np.asarray(self.module_distance.min(axis=1))


def _configurations(robot: object, q: ArrayLike) -> Array:
    """``q`` as a checked ``(N, n)`` float array of assemblable configurations."""
    n = robot.n_joints  # type: ignore[attr-defined]
    qa = checks.finite_array("q", q)
    if qa.ndim == 1:
        qa = qa[None, :]
    if qa.ndim != 2 or qa.shape[1] != n:
        raise InputError(f"q: expected shape (N, {n}) (or ({n},)), got {qa.shape}")
    robot.check_assembly(qa, where="q")  # type: ignore[attr-defined]
    return qa


def triangle_sines(robot: object, q: ArrayLike) -> tuple[Array, Array]:
    """``sin phi_B'`` and ``sin phi_A'`` of each module, ``(N, m)`` each (module docstring)."""
    qa = np.atleast_2d(np.asarray(q, dtype=float))
    parameters = robot.parameters  # type: ignore[attr-defined]
    legs = np.array(parameters.margin_legs(), dtype=int).reshape(-1, 3)
    two_b, two_d = 2.0 * np.asarray(parameters.b), 2.0 * np.asarray(parameters.d)
    s, v, p = qa[:, legs[:, 0]], qa[:, legs[:, 1]], qa[:, legs[:, 2]]
    heron_b = (v + p + two_b) * (v + p - two_b) * (two_b + p - v) * (two_b + v - p)
    heron_a = (s + p + two_d) * (s + p - two_d) * (s + two_d - p) * (p + two_d - s)
    sin_b = np.sqrt(np.maximum(heron_b, 0.0)) / (2.0 * p * v)
    sin_a = np.sqrt(np.maximum(heron_a, 0.0)) / (2.0 * s * two_d)
    return np.minimum(sin_b, 1.0), np.minimum(sin_a, 1.0)


def module_distance(robot: object, q: ArrayLike) -> Array:
    """Each module's distance from its flat-truss singularity, ``(N, m)`` in ``[0, 1]``:
    ``min(sin phi_B', sin phi_A')`` (module docstring), for assemblable ``q`` ``(N, n)``."""
    sin_b, sin_a = triangle_sines(robot, _configurations(robot, q))
    return np.minimum(sin_b, sin_a)


def dexterity(robot: object, q: ArrayLike) -> Dexterity:
    """Manipulability, condition number and module distances at each configuration ``q`` ``(N, n)``
    (a single ``(n,)`` configuration gives ``N = 1``); refused if ``q`` cannot be assembled."""
    qa = _configurations(robot, q)
    jac = robot.tip_jacobian(qa)  # type: ignore[attr-defined]
    sigma = np.linalg.svd(jac, compute_uv=False)
    with np.errstate(divide="ignore"):
        condition = np.where(sigma[:, -1] > 0, sigma[:, 0] / sigma[:, -1], np.inf)
    manipulability = np.sqrt(np.maximum(np.linalg.det(jac @ jac.transpose(0, 2, 1)), 0.0))
    sin_b, sin_a = triangle_sines(robot, qa)
    m = sin_b.shape[1]
    return Dexterity(
        q=qa,
        manipulability=manipulability,
        condition=condition,
        singular_values=sigma,
        module_distance=np.minimum(sin_b, sin_a),
        module_names=tuple(f"module{k + 1}" for k in range(m)),
    )


def joint_grid(robot: object, counts: Mapping[str, int], *, margin: float = 0.0) -> Array:
    """A tensor grid of configurations ``(N, n)``: each joint named in ``counts`` takes that many
    evenly spaced values between its limits, every other joint its home value; only the
    configurations that assemble (with ``margin``, m) are kept, in C order of the grid."""
    names = tuple(robot.joint_names)  # type: ignore[attr-defined]
    if not isinstance(counts, Mapping) or not counts:
        checks.refuse("counts", counts, f"a mapping of joint names to numbers of values, joints {list(names)}")
    lower, upper = robot.joint_limits()  # type: ignore[attr-defined]
    axes: list[Array] = []
    for name, count in counts.items():
        if name not in names:
            checks.refuse("counts", name, f"a joint name, one of {list(names)}")
        k = checks.whole(f"counts[{name!r}]", count, minimum=1, maximum=MAX_GRID)
        i = names.index(name)
        axes.append(np.linspace(lower[i], upper[i], k))
    if int(np.prod([len(a) for a in axes])) > MAX_GRID:
        checks.refuse("counts", dict(counts), f"at most {MAX_GRID:,} configurations in all")
    home: Array = np.array(robot.parameters.home, dtype=np.float64)  # type: ignore[attr-defined]
    mesh = np.meshgrid(*axes, indexing="ij")
    q = np.tile(home, (mesh[0].size, 1))
    for name, values in zip(counts, mesh, strict=True):
        q[:, names.index(name)] = values.ravel()
    keep = robot.is_assemblable(q, margin=margin)  # type: ignore[attr-defined]
    if not keep.any():
        raise InputError(f"counts = {shown(dict(counts))}: no configuration of the grid can be assembled")
    return np.asarray(q[keep])
