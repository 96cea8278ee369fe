"""Assemblability of the VGT modules' leg sets.

A module with base half-width ``b`` and platform half-width ``d`` can be assembled only if the
two triangles of its truss exist: ``(2b, v, p)`` (base edge, leg ``v``, diagonal ``p``) and
``(s, p, 2d)`` (leg ``s``, diagonal ``p``, platform edge). Each strict triangle inequality is a
*linear* function of the leg lengths, so the assemblable set is a polytope in joint space:
``margins = G q + h > 0``. This module is below the kinematics in the layer order; it depends on
NumPy only.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import AssemblyError

#: Names of the six triangle inequalities of one module, in the order of the margins.
TRIANGLE_INEQUALITIES: tuple[str, ...] = (
    "v + p > 2b",
    "2b + p > v",
    "2b + v > p",
    "s + p > 2d",
    "s + 2d > p",
    "p + 2d > s",
)


def linear_form(b: Sequence[float], d: Sequence[float]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return ``G`` (12, 7) and ``h`` (12,) such that the triangle margins are ``G q + h``.

    Rows 0-5 belong to module 1, rows 6-11 to module 2, each in the order of
    :data:`TRIANGLE_INEQUALITIES`. ``b`` and ``d`` are the half-widths of the two modules (m).
    """
    G = np.zeros((12, 7))
    h = np.zeros(12)
    for k in range(2):
        s, v, p = 3 * k, 3 * k + 1, 3 * k + 2
        rows = [
            ({v: 1.0, p: 1.0}, -2.0 * b[k]),
            ({p: 1.0, v: -1.0}, 2.0 * b[k]),
            ({v: 1.0, p: -1.0}, 2.0 * b[k]),
            ({s: 1.0, p: 1.0}, -2.0 * d[k]),
            ({s: 1.0, p: -1.0}, 2.0 * d[k]),
            ({p: 1.0, s: -1.0}, 2.0 * d[k]),
        ]
        for i, (coefficients, offset) in enumerate(rows):
            for j, c in coefficients.items():
                G[6 * k + i, j] = c
            h[6 * k + i] = offset
    return G, h


def triangle_margins(q: ArrayLike, b: Sequence[float], d: Sequence[float]) -> NDArray[np.float64]:
    """Margins of the twelve triangle inequalities, shape ``(..., 12)`` (m); all > 0 to assemble."""
    G, h = linear_form(b, d)
    return np.asarray(q, dtype=float) @ G.T + h


def check_assembly(q: ArrayLike, b: Sequence[float], d: Sequence[float], *, where: str = "") -> None:
    """Raise :class:`AssemblyError` if any configuration in ``q`` (..., 7) cannot be assembled.

    The message names the first failing configuration (its index in a batch), the module and the
    violated triangle inequality with the leg lengths involved.
    """
    G, h = linear_form(b, d)
    check_margins(q, G, h, ((0, 1, 2), (3, 4, 5)), b, d, where=where)


def check_margins(
    q: ArrayLike,
    G: NDArray[np.float64],
    h: NDArray[np.float64],
    legs: Sequence[tuple[int, int, int]],
    b: Sequence[float],
    d: Sequence[float],
    *,
    where: str = "",
) -> None:
    """As :func:`check_assembly` for any number of modules: ``G q + h`` ``(6 m, n)`` holds six rows
    per module in the order of :data:`TRIANGLE_INEQUALITIES`; ``legs[k]`` are the indices of module
    ``k``'s ``(s, v, p)`` in ``q`` ``(..., n)``; ``b``, ``d`` its half-widths (for the message)."""
    qa = np.asarray(q, dtype=float)
    margins = qa @ G.T + h
    bad = ~(margins > 0.0)
    if not bad.any():
        return
    rows = G.shape[0]
    flat_index = int(np.argmax(bad.reshape(-1, rows).any(axis=1)))
    row = int(np.argmax(bad.reshape(-1, rows)[flat_index]))
    module = row // 6 + 1
    qi = qa.reshape(-1, qa.shape[-1])[flat_index]
    s, v, p = (qi[i] for i in legs[module - 1])
    index = tuple(int(i) for i in np.unravel_index(flat_index, qa.shape[:-1]))
    location = "" if qa.ndim == 1 else f" (configuration {index})"
    prefix = f"{where}: " if where else ""
    raise AssemblyError(
        f"{prefix}module {module} cannot be assembled{location}: triangle inequality "
        f"'{TRIANGLE_INEQUALITIES[row % 6]}' fails with s={s:.6g} m, v={v:.6g} m, p={p:.6g} m, "
        f"b={b[module - 1]:.6g} m, d={d[module - 1]:.6g} m"
    )
