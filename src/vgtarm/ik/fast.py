"""The fast trajectory solver: warm-started along the path, coarse to fine, batched over samples.

1. **Coarse samples, in order.** A few samples (every ``8^J``-th, refined so that consecutive
   ones are at most ``coarse_step`` apart along the path) are solved as sequential warm-started
   continuation would (each Newton solve starts from the previous sample's solution; the first
   is reached from the start pose, home or the user's guess, by continuation along a straight
   line, and a rotation arc for the pose task). :func:`vgtarm.ik.newton.solve_in_order` computes that chain
   with two batched runs and checks it.
2. **Levels.** Every ``8^(J-1)``-th sample, then every ``8^(J-2)``-th, ..., then all samples:
   each level starts from the quintic Hermite interpolation of the samples solved so far (with
   their exact joint rates and accelerations, and those of the multipliers, from
   :mod:`vgtarm.ik.rates`), and all its new samples go through one batched active-set Newton
   iteration (:mod:`vgtarm.ik.newton`). At the finest level the interpolation error is usually
   below the tolerances, so most samples pass the optimality test at the first evaluation and
   need no Newton step at all.
3. A sample that does not converge is retried by sequential continuation over the path samples
   from its nearest solved neighbour; what still fails is left unconverged for the caller (which
   re-solves it with the reference solver, or reports it unreachable).

Coarse-to-fine sample sets of a path and quintic Hermite interpolation between solved samples.

The fast solver solves a few samples sequentially, then every ``8^j``-th sample, ..., then all
of them; each level starts from the quintic Hermite interpolation of the solved samples (values,
exact first and second derivatives), whose error falls as the sixth power of the spacing, so
most samples of the finest level already satisfy the optimality conditions before any Newton step.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation, Slerp

from .. import progress
from . import newton, rates
from .options import FastSettings
from .problem import BatchState, IKProblem, Task

Array = NDArray[np.float64]
Index = NDArray[np.intp]

METHOD = "newton"


def _rest_start(q: Array, m: int, n_inequalities: int) -> dict[str, Array]:
    return {"q": q, "lam": np.zeros(m), "mu": np.zeros(n_inequalities), "active": np.zeros(n_inequalities, bool)}


def _sample_start(state: BatchState, i: int) -> dict[str, Array]:
    return {name: getattr(state, name)[i].copy() for name in ("q", "lam", "mu", "active")}


def approach(problem: IKProblem, task: Task, state: BatchState, i: int, q_start: Array, settings: FastSettings) -> bool:
    """Solve sample ``i`` from ``q_start`` by continuation along a line (and rotation arc) to its target."""
    tip, rotation = task.forward_frame(q_start[None])
    target = task.position[i]
    distance = float(np.linalg.norm(target - tip[0]))
    angle = 0.0
    ends = None
    if task.rotation is not None:
        ends = Rotation.from_matrix(np.stack([rotation[0].reshape(3, 3), task.rotation[i].reshape(3, 3)]))
        angle = float((ends[0].inv() * ends[1]).magnitude())
    pieces = max(1, math.ceil(max(distance, 0.1 * angle) / settings.coarse_step))
    s = np.arange(1, pieces + 1) / pieces
    points = tip[0] + s[:, None] * (target - tip[0])
    points[-1] = target
    rotations = None
    if task.rotation is not None and ends is not None:
        rotations = Slerp([0.0, 1.0], ends)(s).as_matrix().reshape(pieces, 9)
        rotations[-1] = task.rotation[i]
    line = task.with_targets(points, rotations, like=i)
    sub = BatchState.empty(pieces, task.m, state.mu.shape[1], state.q.shape[1], state.g is not None)
    start = _rest_start(q_start, task.m, state.mu.shape[1])
    newton.solve_in_order(problem, line, sub, np.arange(pieces, dtype=np.intp), start, settings.newton)
    state.iterations[i] += int(sub.iterations.sum())
    ok = bool(sub.converged[-1])
    if ok:
        for name in ("q", "lam", "mu", "active", "residual", "J", "H", "g"):
            if getattr(sub, name) is not None:
                getattr(state, name)[i] = getattr(sub, name)[-1]
    state.converged[i] = ok
    return ok


def chain(problem: IKProblem, task: Task, state: BatchState, a: int, b: int, settings: FastSettings) -> bool:
    """Solve sample ``b`` by sequential continuation over path samples from the solved sample ``a``."""
    steps = np.unique(np.linspace(a, b, settings.retry_pieces + 1).round().astype(np.intp))
    steps = steps[steps != a]
    start = _sample_start(state, a)
    newton.solve_in_order(problem, task, state, steps, start, settings.newton, with_rates=True)
    return bool(state.converged[b])


def _start_level(problem: IKProblem, task: Task, state: BatchState, new: Index) -> None:
    """Initial guesses of the samples ``new`` from the solved samples (quintic Hermite in time).

    Joints and equality multipliers are interpolated with their exact first and second
    derivatives; inequality multipliers linearly (they are kinked where the active set changes).
    """
    nj = problem.n
    known = np.flatnonzero(state.converged & state.rates_ready)
    if known.size < 2:
        nearest = known[0] if known.size else 0
        for name in ("q", "lam", "mu", "active"):
            getattr(state, name)[new] = getattr(state, name)[nearest]
        return
    tk, t = task.t[known], task.t[new]
    both = quintic_hermite(
        tk,
        np.concatenate([state.q[known], state.lam[known]], axis=1),
        np.concatenate([state.qd[known], state.lam_d[known]], axis=1),
        np.concatenate([state.qdd[known], state.lam_dd[known]], axis=1),
        t,
    )
    q = both[:, :nj]
    bad = ~problem.assemblable(q, 0.5 * problem.margin)
    if bad.any():
        q[bad] = linear(tk, state.q[known], t[bad])
    state.q[new], state.lam[new] = q, both[:, nj:]
    known_mu = state.mu[known]
    if known_mu.any():
        mu = np.maximum(linear(tk, known_mu, t), 0.0)
        state.mu[new], state.active[new] = mu, mu > 0
    else:
        state.mu[new], state.active[new] = 0.0, False


def _rescue(problem: IKProblem, task: Task, state: BatchState, failed: Index, settings: FastSettings) -> None:
    """Retry failed samples by continuation from their nearest solved neighbour on the left (else right).

    Once a continuation from a solved sample on the left fails, the failed samples after it that
    would start from the same sample are left to the caller (the reference solver, or the report
    of the first sample out of reach): a stretch of the path out of reach would otherwise cost a
    full continuation of Newton iterations per sample (measured: 126 samples of a path half out of
    reach took 22 s, 21 of them here).
    """
    abandoned = -1
    for i in failed.tolist():
        if state.converged[i]:
            continue
        solved = np.flatnonzero(state.converged)
        if solved.size == 0:
            return
        left = solved[solved < i]
        start = int(left[-1]) if left.size else int(solved[0])
        if left.size and start == abandoned:
            continue
        if not chain(problem, task, state, start, i, settings) and left.size:
            abandoned = start


def solve(problem: IKProblem, task: Task, state: BatchState, q_start: Array, settings: FastSettings) -> None:
    """Solve every sample of ``task`` into ``state`` (see the module docstring).

    On return, converged samples hold the solution, its multipliers and active set and the model
    values at it, and most of them their exact rates (computed in the same compiled call as the
    last model evaluation where no inequality is active; the caller completes the others).
    """
    n = len(task)
    strides = level_strides(n, settings.top_count)
    top = refine_by_distance(level_indices(n, strides[0]), task.position, settings.coarse_step)
    if approach(problem, task, state, int(top[0]), q_start, settings):
        start, rest = _sample_start(state, int(top[0])), top[1:]
    else:
        start, rest = _rest_start(q_start, task.m, state.mu.shape[1]), top
    newton.solve_in_order(problem, task, state, rest, start, settings.newton, with_rates=True)
    _rescue(problem, task, state, top[~state.converged[top]], settings)
    _complete_rates(problem, task, state, top)
    progress.report(int(np.count_nonzero(state.converged)), n)  # each level about doubles the samples solved
    for stride in strides[1:]:
        level = level_indices(n, stride)
        new = level[~state.converged[level]]
        if new.size == 0:
            continue
        _start_level(problem, task, state, new)
        converged = _iterate_in_blocks(problem, task, state, new, settings)
        if not converged.all():
            _rescue(problem, task, state, new[~converged], settings)
        if stride != 1:
            _complete_rates(problem, task, state, level)
        progress.report(int(np.count_nonzero(state.converged)), n)
    state.method[state.converged & (state.method == "")] = METHOD


#: Bytes of one KKT array (``(samples, s, s)`` doubles, ``s = n + m + k``) that a level's Newton
#: iteration builds at once: a long arm's level is iterated in blocks of samples of this size. Each
#: sample's iteration is independent of the others in the batch, so the blocks give the same values;
#: what they save is the memory traffic of arrays of gigabytes (the 50-module arm's KKT matrices of
#: 6,284 samples: 2.6 GB, allocated and filled at every step). The paper's robot's levels (a KKT
#: matrix of 1.2 kB a sample) are never split.
BLOCK_BYTES = 64 * 2**20


def _iterate_in_blocks(
    problem: IKProblem, task: Task, state: BatchState, idx: Index, settings: FastSettings
) -> NDArray[np.bool_]:
    """:func:`vgtarm.ik.newton.iterate` of the samples ``idx`` with exact rates, in blocks of :data:`BLOCK_BYTES`."""
    size = problem.n + task.m + problem.n_triangle
    block = max(1, BLOCK_BYTES // (8 * size * size))
    if idx.size <= block:
        return newton.iterate(problem, task, state, idx, settings.newton, with_rates=True)
    parts = [
        newton.iterate(problem, task, state, idx[start : start + block], settings.newton, with_rates=True)
        for start in range(0, idx.size, block)
    ]
    return np.concatenate(parts)


def _complete_rates(problem: IKProblem, task: Task, state: BatchState, idx: Index) -> None:
    """Exact rates of the converged samples ``idx`` that do not have them yet (active inequalities)."""
    missing = idx[state.converged[idx] & ~state.rates_ready[idx]]
    if missing.size:
        rates.exact(problem, task, state, missing)


#: Ratio of the sample spacing of consecutive levels.
LEVEL_RATIO = 8


def level_strides(n: int, top_count: int = 4) -> list[int]:
    """Strides ``[8^J, ..., 8, 1]`` with the coarsest level holding about ``top_count`` samples or more."""
    strides = [1]
    while (n - 1) // (strides[-1] * LEVEL_RATIO) >= top_count:
        strides.append(strides[-1] * LEVEL_RATIO)
    return strides[::-1]


def level_indices(n: int, stride: int) -> Index:
    """Every ``stride``-th sample of ``n`` and the last one."""
    indices = np.arange(0, n, stride, dtype=np.intp)
    return indices if indices[-1] == n - 1 else np.append(indices, np.intp(n - 1))


def refine_by_distance(indices: Index, points: Array, step: float) -> Index:
    """Add samples to sorted ``indices`` so that consecutive chosen ``points`` ``(N, 3)`` are at most ``step`` apart.

    Distances are measured along the sampled path (arc length), so a loop between two chosen
    samples counts in full.
    """
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    chosen = [int(indices[0])]
    for b in indices[1:].tolist():
        a = chosen[-1]
        pieces = int(np.ceil((arc[b] - arc[a]) / step)) if step > 0 else 1
        if pieces > 1:
            marks = arc[a] + (arc[b] - arc[a]) * np.arange(1, pieces) / pieces
            inner = np.searchsorted(arc[a : b + 1], marks) + a
            chosen.extend(int(i) for i in np.unique(inner) if a < i < b)
        chosen.append(int(b))
    return np.asarray(sorted(set(chosen)), dtype=np.intp)


def quintic_hermite(t_known: Array, y: Array, yd: Array, ydd: Array, t: Array) -> Array:
    """Quintic Hermite interpolation at times ``t`` ``(n,)`` of samples at sorted ``t_known`` ``(K,)``.

    ``y``, ``yd``, ``ydd`` ``(K, d)`` are values and first and second derivatives. Returns ``(n, d)``;
    times outside the known range are extrapolated from the nearest segment.
    """
    segment = np.clip(np.searchsorted(t_known, t, side="right") - 1, 0, t_known.shape[0] - 2)
    t0, t1 = t_known[segment], t_known[segment + 1]
    h = (t1 - t0)[:, None]
    s = ((t - t0) / (t1 - t0))[:, None]
    s2 = s * s
    s3 = s2 * s
    s4 = s3 * s
    s5 = s4 * s
    h0 = 1 - 10 * s3 + 15 * s4 - 6 * s5
    h1 = s - 6 * s3 + 8 * s4 - 3 * s5
    h2 = 0.5 * s2 - 1.5 * s3 + 1.5 * s4 - 0.5 * s5
    h3 = 0.5 * s3 - s4 + 0.5 * s5
    h4 = -4 * s3 + 7 * s4 - 3 * s5
    h5 = 10 * s3 - 15 * s4 + 6 * s5
    a, b = segment, segment + 1
    y, yd, ydd = (np.asarray(v, dtype=float) for v in (y, yd, ydd))
    # h0 y[a] + h1 h yd[a] + h2 h h ydd[a] + h3 h h ydd[b] + h4 h yd[b] + h5 y[b], summed left to right,
    # each term in the buffer of its gathered rows (the same operations, no temporary of (n, d) more)
    out = y[a]
    out *= h0
    for weight, rows in ((h1 * h, yd[a]), (h2 * h * h, ydd[a]), (h3 * h * h, ydd[b]), (h4 * h, yd[b]), (h5, y[b])):
        rows *= weight
        out += rows
    return np.asarray(out)


def linear(t_known: Array, y: Array, t: Array) -> Array:
    """Piecewise-linear interpolation of ``y`` ``(K, d)`` at times ``t`` ``(n,)``, ``(n, d)``."""
    segment = np.clip(np.searchsorted(t_known, t, side="right") - 1, 0, t_known.shape[0] - 2)
    t0, t1 = t_known[segment], t_known[segment + 1]
    s = ((t - t0) / (t1 - t0))[:, None]
    y = np.asarray(y, dtype=float)
    out, after = y[segment], y[segment + 1]  # (1 - s) y[segment] + s y[segment + 1], in the gathered rows
    out *= 1 - s
    after *= s
    out += after
    return np.asarray(out)
