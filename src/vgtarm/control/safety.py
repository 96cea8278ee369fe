"""Admission of switching-control gains: the discrete loop the controller really closes.

The safe variant of switching control (``SwitchingControl(variant="safe")``) lets the GA apply a
candidate ``(Kp, Kv)`` only when the closed loop it makes is stable with margin, judged on what
the controller has: a control period ``dt`` with the effort held over it, velocities from
encoder differences through the first-order filter of weight ``a`` (``a = exp(-2 pi f dt)``), and
a controller model whose mass is off by at most ``model_error`` (relative). Linearised at the
current state, computed force control leaves on each error coordinate

    e_{k+1} = e_k + dt ed_k - h u_k,   ed_{k+1} = ed_k - dt u_k,
    w_k = a w_{k-1} + (1 - a) (e_k - e_{k-1}) / dt   (perfect sensing: w_k = ed_k),
    u_k = gamma (Kp e_k + Kv w_k),     gamma = M^-1 M^ in [1 - model_error, 1 + model_error],

with ``h = dt^2 / 2`` for a plant that integrates exactly over the period and ``h = 0`` for the
paper's explicit Euler; the state ``(e, ed, e_{k-1}, w_{k-1})`` has the matrix of
:func:`loop_matrix`. The safe variant uses ``Kv = kv I`` and a symmetric ``Kp``: the two share
their eigenvectors, so the ``4n`` loop splits into one scalar loop per eigenvalue ``lambda`` of
``Kp`` with gains ``(lambda, kv)``. :func:`admitted_interval` finds the interval of ``lambda``
whose scalar loops have every pole inside the circle of radius ``radius`` (< 1) for both holds and
every ``gamma`` of a grid over the bound; the compiled GA admits a candidate iff the eigenvalues
of its ``Kp`` lie in it (two Cholesky factorisations, ``csrc/ga.c``).

When the GA tunes the damping too, ``Kv = kv I`` with ``kv`` on a grid ``j * step``: the pairs
``(lambda, kv)`` are tested the same way, with one interval per grid point
(:func:`damping_table`, vectorised over ``lambda``; the compiled GA snaps a candidate's damping to
the grid point nearest to the mean of its ``Kv`` diagonal and looks its interval up).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from functools import lru_cache
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..errors import InputError
from ..model.compiled import cache_dir

Array = NDArray[np.float64]

#: Model errors (``gamma``) checked across the bound: this many evenly spaced values.
GAMMA_POINTS = 21
#: Eigenvalues of ``Kp`` scanned for the admitted interval (1/s^2), log-spaced, before bisection.
SCAN = (1.0, 1e8, 801)


def loop_matrix(
    Kp: ArrayLike,
    Kv: ArrayLike,
    dt: float,
    velocity_filter: float | None,
    gamma: float = 1.0,
    *,
    exact_hold: bool = True,
) -> Array:
    """Matrix of the linearised discrete error loop (see the module's docstring).

    ``Kp``, ``Kv`` (n, n); ``velocity_filter``: the filter weight ``a`` in [0, 1) of velocities
    differenced from encoders, or ``None`` for measured velocities (perfect sensing). Returns
    ``(4n, 4n)`` for the state ``(e, ed, e_prev, w_prev)``, or ``(2n, 2n)`` for ``(e, ed)``.
    """
    kp, kv = np.atleast_2d(np.asarray(Kp, dtype=float)), np.atleast_2d(np.asarray(Kv, dtype=float))
    n = kp.shape[0]
    eye, zero = np.eye(n), np.zeros((n, n))
    h = dt * dt / 2.0 if exact_hold else 0.0
    if velocity_filter is None:
        up, uv = gamma * kp, gamma * kv
        return np.block([[eye - h * up, dt * eye - h * uv], [-dt * up, eye - dt * uv]])
    a = float(velocity_filter)
    c = (1.0 - a) / dt
    ue, uprev, uw = gamma * (kp + c * kv), -gamma * c * kv, gamma * a * kv
    return np.block(
        [
            [eye - h * ue, dt * eye, -h * uprev, -h * uw],
            [-dt * ue, eye, -dt * uprev, -dt * uw],
            [eye, zero, zero, zero],
            [c * eye, zero, -c * eye, a * eye],
        ]
    )


def spectral_radius(
    Kp: ArrayLike, Kv: ArrayLike, dt: float, velocity_filter: float | None, model_error: float = 0.0
) -> float:
    """Largest pole modulus of :func:`loop_matrix` over both holds and ``gamma`` across the bound."""
    worst = 0.0
    for gamma in np.linspace(1.0 - model_error, 1.0 + model_error, GAMMA_POINTS if model_error > 0 else 1):
        for exact in (True, False):
            poles = np.linalg.eigvals(loop_matrix(Kp, Kv, dt, velocity_filter, float(gamma), exact_hold=exact))
            worst = max(worst, float(np.max(np.abs(poles))))
    return worst


@lru_cache(maxsize=64)
def admitted_interval(
    kv: float, dt: float, velocity_filter: float | None, model_error: float, radius: float
) -> tuple[float, float]:
    """Interval ``(lo, hi)`` (1/s^2) of the eigenvalues of ``Kp`` whose scalar loops with damping
    ``kv`` have every pole inside ``radius`` for every model error within ``model_error``.

    Raises:
        InputError: no eigenvalue is admitted, or the admitted set is not one interval.
    """
    checks.positive("kv", kv, "1/s")
    checks.number("radius", radius, above=0, below=1)
    checks.number("model_error", model_error, minimum=0, below=1)

    def inside(lams: Array) -> NDArray[np.bool_]:  # the scalar loops of all of them at once (batched eigenvalues)
        return _scalar_radii(lams, kv, dt, velocity_filter, model_error) < radius

    grid = np.geomspace(*SCAN[:2], int(SCAN[2]))
    where = np.flatnonzero(inside(grid))
    if where.size == 0:
        raise InputError(
            f"kv = {kv:g}: no Kp eigenvalue gives poles inside radius {radius:g} with dt = {dt:g} s and a model"
            f" error up to {model_error:g}; expected a damping that the loop can hold"
        )
    if np.any(np.diff(where) != 1):
        raise InputError(f"kv = {kv:g}: the admitted Kp eigenvalues are not one interval; refusing the safe variant")

    # both edges bisected together (60 halvings of the log-interval); an edge at the scan's end stays
    good = np.array([grid[where[0]], grid[where[-1]]])
    bad = np.array([grid[max(where[0] - 1, 0)], grid[min(where[-1] + 1, len(grid) - 1)]])
    for _ in range(60):
        mid = np.sqrt(good * bad)
        inner = inside(mid)
        good, bad = np.where(inner, mid, good), np.where(inner, bad, mid)
    return float(good[0]), float(good[1])


def _scalar_radii(
    lams: Array, kv: float | Array, dt: float, velocity_filter: float | None, model_error: float
) -> Array:
    """:func:`spectral_radius` of the scalar loops ``(lambda, kv)`` for every ``lambda`` of ``lams`` at
    once (the same grid of ``gamma`` and both holds; batched eigenvalues of the 4x4 or 2x2 loops);
    ``kv`` one damping or one per ``lambda``."""
    lam = np.asarray(lams, dtype=float)
    kv = np.asarray(kv, dtype=float)
    gammas = np.linspace(1.0 - model_error, 1.0 + model_error, GAMMA_POINTS if model_error > 0 else 1)
    g = gammas[:, None, None]
    h = np.array([dt * dt / 2.0, 0.0])[None, :, None]
    shape = (len(gammas), 2, len(lam))
    lp = np.broadcast_to(g * lam[None, None, :], shape)
    one, zero = np.ones(shape), np.zeros(shape)
    hb = np.broadcast_to(h, shape)
    if velocity_filter is None:
        uv = np.broadcast_to(g * kv, shape)
        rows = [[one - hb * lp, dt - hb * uv], [-dt * lp, one - dt * uv]]
    else:
        a = float(velocity_filter)
        c = (1.0 - a) / dt
        ue = lp + np.broadcast_to(g * c * kv, shape)
        uprev = np.broadcast_to(-g * c * kv, shape)
        uw = np.broadcast_to(g * a * kv, shape)
        rows = [
            [one - hb * ue, dt * one, -hb * uprev, -hb * uw],
            [-dt * ue, one, -dt * uprev, -dt * uw],
            [one, zero, zero, zero],
            [c * one, zero, -c * one, a * one],
        ]
    mats = np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)
    radii = np.abs(np.linalg.eigvals(mats)).max(axis=-1)
    return np.asarray(radii.max(axis=(0, 1)), dtype=float)


#: The damping grid of the tuned safe variant: this many steps between 0 and the fixed damping.
DAMPING_STEPS = 30
#: Scan of the tuned variant's table: eigenvalues of ``Kp`` (1/s^2), log-spaced, and bisection steps.
TABLE_SCAN = (10.0, 1e7, 241, 40)


@lru_cache(maxsize=16)
def damping_table(
    step: float, count: int, dt: float, velocity_filter: float | None, model_error: float, radius: float
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Admitted intervals of the eigenvalues of ``Kp`` for the dampings ``kv_j = j step``,
    ``j = 0 .. count - 1``: ``(lo, hi)`` tuples, NaN where no eigenvalue (or no single interval of
    them) has every pole of the scalar loop inside ``radius`` for every model error in the bound.
    The edges are bisected to 2^-40 relative and then moved inwards by 1e-9 relative.

    About 420,000 eigenvalue problems (1-5 s, the safe variant's set-up before its first run in a
    process): the table is kept in the cache folder of the compiled libraries
    (``safety-table-<key>.json``, the key hashing the arguments and this module's source), so a new
    process reads it instead; an unreadable or unwritable file is recomputed or left alone.
    """
    args = (step, count, dt, velocity_filter, model_error, radius)
    path = _table_file(args)
    if path is not None:
        try:
            stored = json.loads(path.read_text(encoding="utf-8"))
            los, his = (tuple(float(x) for x in stored[name]) for name in ("lo", "hi"))
            if len(los) == len(his) == count:
                return los, his
        except (OSError, ValueError, KeyError, TypeError):
            pass
    table = _damping_table(*args)
    if path is not None:
        with contextlib.suppress(OSError):
            path.parent.mkdir(parents=True, exist_ok=True)
            temporary = path.with_name(f".{path.name}.{os.getpid()}")
            temporary.write_text(json.dumps({"lo": table[0], "hi": table[1]}), encoding="utf-8")
            os.replace(temporary, path)  # atomic: a reader sees the whole table or none
    return table


def _table_file(args: tuple[object, ...]) -> Path | None:
    """The cache file of :func:`damping_table` for ``args`` (``None``: no usable cache folder)."""
    try:
        folder = cache_dir()
    except RuntimeError:  # Path.home() without a home folder
        return None
    digest = hashlib.sha256(Path(__file__).read_bytes() + repr(args).encode()).hexdigest()[:24]
    return folder / f"safety-table-{digest}.json"


def _damping_table(
    step: float, count: int, dt: float, velocity_filter: float | None, model_error: float, radius: float
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    checks.positive("step", step, "1/s")
    checks.whole("count", count, 1, 10_000)
    checks.number("radius", radius, above=0, below=1)
    checks.number("model_error", model_error, minimum=0, below=1)
    grid = np.geomspace(TABLE_SCAN[0], TABLE_SCAN[1], int(TABLE_SCAN[2]))
    kvs = np.arange(count) * step
    # every grid point of every damping in one batch, then all the edges bisected together: each
    # scalar loop's eigenvalues are those of its own matrix, so the table is that of one damping at
    # a time, in a fraction of the time (the safe variant's set-up before a run)
    flags = _scalar_radii(np.tile(grid, count), np.repeat(kvs, len(grid)), dt, velocity_filter, model_error) < radius
    flags = flags.reshape(count, len(grid))
    rows, goods, bads = [], [], []
    for j in range(count):
        where = np.flatnonzero(flags[j])
        if where.size == 0 or np.any(np.diff(where) != 1) or where[0] == 0 or where[-1] == len(grid) - 1:
            continue
        rows.append(j)
        goods += [grid[where[0]], grid[where[-1]]]
        bads += [grid[where[0] - 1], grid[where[-1] + 1]]
    los, his = [float("nan")] * count, [float("nan")] * count
    if rows:
        good, bad, kv = np.array(goods), np.array(bads), np.repeat(kvs[rows], 2)
        for _ in range(int(TABLE_SCAN[3])):
            mid = np.sqrt(good * bad)
            inside = _scalar_radii(mid, kv, dt, velocity_filter, model_error) < radius
            good, bad = np.where(inside, mid, good), np.where(inside, bad, mid)
        for i, j in enumerate(rows):
            los[j] = float(good[2 * i] * (1 + 1e-9))
            his[j] = float(good[2 * i + 1] * (1 - 1e-9))
    return tuple(los), tuple(his)
