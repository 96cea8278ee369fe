"""Coarse-to-fine sample sets of a path and quintic Hermite interpolation between solved samples.

The fast solver solves a few samples sequentially, then every ``8^j``-th sample, ..., then all
of them; each level starts from the quintic Hermite interpolation of the solved samples (values,
exact first and second derivatives), whose error falls as the sixth power of the spacing, so
most samples of the finest level already satisfy the optimality conditions before any Newton step.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
Index = NDArray[np.intp]

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
    return np.asarray(
        h0 * y[a] + h1 * h * yd[a] + h2 * h * h * ydd[a] + h3 * h * h * ydd[b] + h4 * h * yd[b] + h5 * y[b]
    )


def linear(t_known: Array, y: Array, t: Array) -> Array:
    """Piecewise-linear interpolation of ``y`` ``(K, d)`` at times ``t`` ``(n,)``, ``(n, d)``."""
    segment = np.clip(np.searchsorted(t_known, t, side="right") - 1, 0, t_known.shape[0] - 2)
    t0, t1 = t_known[segment], t_known[segment + 1]
    s = ((t - t0) / (t1 - t0))[:, None]
    return np.asarray((1 - s) * y[segment] + s * y[segment + 1])
