"""Sequential warm-started continuation, computed in parallel and checked.

Solving samples ``i_0, i_1, ...`` in order, each by Newton started from the solution of the one
before (``i_0`` from a start pose), follows one branch of optimal solutions along the path. The
same result is obtained with two batched Newton runs instead of a loop:

A. every pending sample is solved from the common start;
B. every pending sample ``i_j`` (``j >= 1``) is solved again, started from run A's solution of
   ``i_{j-1}``.

Where run B converges to run A's point for every sample up to ``i_r`` the two runs agree with
the sequential chain up to ``i_r`` (by induction: Newton from the previous sample's solution lands
on this one), and those samples are accepted. The first disagreeing sample takes run B's answer
when that converged (it *is* the Newton solve from its predecessor's solution), and the procedure
repeats from there. On a path without branch switching that is two batched runs; in the worst
case it degrades to the sequential loop.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from . import newton
from .newton import NewtonSettings
from .problem import IKProblem
from .state import BatchState
from .tasks import Task

Array = NDArray[np.float64]
Index = NDArray[np.intp]

#: Largest joint difference (m, rad) for two Newton runs to count as the same solution.
SAME_SOLUTION = 1e-8

_SOLUTION_FIELDS = ("q", "lam", "mu", "active")
_MODEL_FIELDS = ("residual", "J", "H")


def _take(state: BatchState, idx: Index) -> dict[str, Array]:
    return {name: getattr(state, name)[idx].copy() for name in _SOLUTION_FIELDS + _MODEL_FIELDS}


def _start_all(state: BatchState, idx: Index, start: dict[str, Array]) -> None:
    for name in _SOLUTION_FIELDS:
        getattr(state, name)[idx] = start[name]


def solve_in_order(
    problem: IKProblem,
    task: Task,
    state: BatchState,
    order: Index,
    start: dict[str, Array],
    settings: NewtonSettings,
    *,
    with_rates: bool = False,
) -> None:
    """Solve samples ``order`` as the sequential chain from ``start`` would, into ``state``.

    ``start`` holds one sample's ``q``, ``lam``, ``mu`` and ``active`` to begin from. Samples whose
    Newton solve from their predecessor fails are left unconverged and skipped (the next one starts
    from the last solved sample). ``with_rates`` is passed to :func:`newton.iterate`.
    """
    pending = np.asarray(order, dtype=np.intp)
    while pending.size:
        _start_all(state, pending, start)
        newton.iterate(problem, task, state, pending, settings, with_rates=with_rates)
        run_a = _take(state, pending)
        ok_a = state.converged[pending].copy()
        agree = ok_a.copy()
        ok_b = np.zeros(pending.size, dtype=bool)
        if pending.size > 1:
            later = pending[1:]
            for name in _SOLUTION_FIELDS:
                getattr(state, name)[later] = run_a[name][:-1]
            newton.iterate(problem, task, state, later, settings, with_rates=with_rates)
            ok_b[1:] = state.converged[later]
            same = np.abs(state.q[later] - run_a["q"][1:]).max(axis=1) <= SAME_SOLUTION
            agree[1:] = ok_a[1:] & ok_b[1:] & same
        r = int(np.argmin(agree)) if not agree.all() else pending.size
        # The state now holds run A's answer for the first sample and run B's (identical to run A's
        # where they agree) for the others; keep a copy of that in run_a for the next start.
        if pending.size > 1:
            for name, array in _take(state, pending[1:]).items():
                run_a[name][1:] = array
        if r == pending.size:
            return
        # Sample r: its sequential answer is run B's (Newton from its accepted predecessor).
        failed_here = not (ok_b[r] if r > 0 else ok_a[0])
        state.converged[pending[r + 1 :]] = False
        if failed_here:
            state.converged[pending[r]] = False
            anchor = r - 1
        else:
            anchor = r
        if anchor >= 0:
            start = {name: run_a[name][anchor] for name in _SOLUTION_FIELDS}
        pending = pending[r + 1 :]
