"""Batched active-set (semismooth) Newton iteration on the KKT conditions of many samples at once.

Each iteration evaluates the task (tip, Jacobian, Hessian of ``lam^T c``) for every sample that is
still working in one compiled call, predicts the active sets (primal-dual active-set rule), solves
all the fixed-size condensed KKT systems of :mod:`vgtarm.ik.kkt` in one batched solve and updates
``q`` and the multipliers. A sample stops when its equality residual and its Lagrangian gradient
are below the tolerances and its active set is consistent (active rows with ``mu >= 0``, inactive
rows satisfied). Steps are limited in length and cut so that the iterate stays assemblable (every
triangle margin keeps a tenth of its current value), so the model is never evaluated where the
truss cannot exist.

Sequential warm-started continuation, computed in parallel and checked.

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

from . import kkt
from . import rates as rate_modes
from .options import NewtonSettings
from .problem import BatchState, IKProblem, Task, largest_magnitude, rows_all, rows_any, rows_times

Array = NDArray[np.float64]
Index = NDArray[np.intp]


def _step_length(problem: IKProblem, q: Array, dq: Array, max_step: float) -> Array:
    """Step fractions ``(n,)`` in ``(0, 1]``: step length limit and fraction-to-boundary of assemblability."""
    longest = largest_magnitude(dq)
    alpha = np.minimum(1.0, max_step / np.maximum(longest, 1e-300))
    margins = rows_times(q, problem.G_all) + problem.h_all
    change = rows_times(dq, problem.G_all)
    with np.errstate(divide="ignore", invalid="ignore"):
        limit = np.where(change < 0, -0.9 * margins / change, np.inf)
    return np.minimum(alpha, limit.min(axis=1))


#: Smallest eigenvalue of the reduced Hessian, over the mean cost weight, that counts as positive
#: curvature (the verification's :attr:`~vgtarm.ik.options.Tolerances.curvature`).
CURVATURE_TOLERANCE = 1e-10
#: Smallest length of the step along a direction of negative curvature (times ``max_step``).
ESCAPE_FRACTION = 0.1


def negative_curvature(problem: IKProblem, W: Array, J: Array, active: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Samples ``(n,)`` with no active inequality whose Hessian of the Lagrangian ``W`` has a direction of
    negative (or zero) curvature on the null space of the task Jacobian ``J``: their KKT point is no minimum.

    Gershgorin's bound of ``W`` clears most samples; the others get the eigenvalues of their reduced
    Hessian ``Z^T W Z`` (``Z`` an orthonormal basis of the null space of ``J``, from a QR factorisation).
    """
    scale = float(problem.weight.mean())
    out = np.zeros(W.shape[0], dtype=bool)
    diagonal = np.diagonal(W, axis1=1, axis2=2)
    bound = (diagonal - (np.abs(W).sum(axis=2) - np.abs(diagonal))).min(axis=1)
    need = np.flatnonzero(~rows_any(active) & ~(bound > CURVATURE_TOLERANCE * scale))
    if need.size:
        Z = _null_basis(J[need])
        reduced = Z.transpose(0, 2, 1) @ W[need] @ Z
        smallest = np.linalg.eigvalsh(reduced)[:, 0]
        out[need] = ~(smallest > CURVATURE_TOLERANCE * scale)
    return out


def _null_basis(J: Array) -> Array:
    """Orthonormal bases ``(n, nj, nj - m)`` of the null spaces of ``J`` ``(n, m, nj)`` (full row rank)."""
    m = J.shape[1]
    Q, _ = np.linalg.qr(J.transpose(0, 2, 1), mode="complete")
    return np.asarray(Q[:, :, m:])


def curvature_step(
    problem: IKProblem, q: Array, W: Array, J: Array, residual: Array, g: Array | None, max_step: float
) -> Array:
    """Steps ``x = (dq, lam, mu_g)`` ``(n, nj + m + k)`` for samples whose reduced Hessian is indefinite.

    The step is the Newton step of the equality-constrained problem in null-space form with the
    reduced Hessian's eigenvalues replaced by their absolute values (at least the smallest cost
    weight): the range-space part restores the task, the null-space part descends the Lagrangian,
    moving away from the KKT point along each direction of negative curvature (a saddle of the
    cost on the task's manifold, such as the straight branch of a buckling arm) instead of towards
    it. Along the most negative direction the step is at least ``ESCAPE_FRACTION * max_step`` long,
    downhill (its sign chosen by the gradient; positive at an exact saddle), so an iterate that
    sits on the saddle leaves it; the distance then grows at each step until the curvature turns
    positive and the ordinary Newton step takes over. The new task multipliers are the least-squares
    solution of stationarity after the step; inequality multipliers stay zero (no active row).
    """
    nj = problem.n
    n, m = J.shape[0], J.shape[1]
    Q, R = np.linalg.qr(J.transpose(0, 2, 1), mode="complete")
    Q1, Z, R1 = Q[:, :, :m], Q[:, :, m:], R[:, :m, :]
    gradient = kkt.cost_gradient(problem, q, g)
    y = np.linalg.solve(R1.transpose(0, 2, 1), -residual[..., None])
    dq_range = (Q1 @ y)[..., 0]
    reduced_gradient = np.einsum("nji,nj->ni", Z, gradient + np.einsum("nij,nj->ni", W, dq_range))
    values, vectors = np.linalg.eigh(Z.transpose(0, 2, 1) @ W @ Z)
    floor = float(problem.weight.min())
    along = np.einsum("nji,nj->ni", vectors, reduced_gradient)
    p = -along / np.maximum(np.abs(values), floor)
    kick = ESCAPE_FRACTION * max_step
    first = p[:, 0]
    direction = np.where(along[:, 0] > 0, -1.0, 1.0)
    p[:, 0] = np.where((values[:, 0] < 0) & (np.abs(first) < kick), kick * direction, first)
    dq = dq_range + np.einsum("nij,nj->ni", Z, np.einsum("nij,nj->ni", vectors, p))
    stationary = gradient + np.einsum("nij,nj->ni", W, dq)
    lam = -np.linalg.solve(R1, np.einsum("nji,nj->ni", Q1, stationary)[..., None])[..., 0]
    x = np.zeros((n, nj + m + problem.n_triangle))
    x[:, :nj], x[:, nj : nj + m] = dq, lam
    return x


def stopping_test(
    problem: IKProblem,
    q: Array,
    lam: Array,
    mu: Array,
    active: NDArray[np.bool_],
    model: tuple[Array, Array, Array],
    settings: NewtonSettings,
    g: Array | None = None,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_]]:
    """Which samples have converged, the predicted active sets, and which model values are finite.

    ``model`` is ``(residual, J, H)`` at ``(q, lam)``; ``g`` the model part of the cost gradient (effort).
    """
    residual, J, H = model
    primal = largest_magnitude(residual)
    stationarity = largest_magnitude(kkt.stationarity(problem, q, J, lam, mu, g))
    # NaN in the model values propagates into these maxima; H comes from the same expressions as J.
    finite = np.isfinite(primal + stationarity) & rows_all(np.isfinite(H[:, :, 0]))
    predicted = kkt.predict_active(problem, q, mu, active, settings.tol_active)
    with np.errstate(invalid="ignore"):
        done = (
            finite
            & (primal <= settings.tol_primal)
            & (stationarity <= settings.tol_stationarity)
            & rows_all(predicted == active)
        )
    return np.asarray(done), predicted, np.asarray(finite)


def _store_rates(state: BatchState, working: Index, ready: NDArray[np.bool_], rates: tuple[Array, ...]) -> None:
    if ready.all():  # the finest level: every sample stops at its first evaluation
        rows = working
        qd, lam_d, qdd, lam_dd = rates
    else:
        rows = working[ready]
        qd, lam_d, qdd, lam_dd = (r[ready] for r in rates)
    state.qd[rows], state.lam_d[rows], state.qdd[rows], state.lam_dd[rows] = qd, lam_d, qdd, lam_dd
    state.rates_ready[rows] = True


def iterate(
    problem: IKProblem,
    task: Task,
    state: BatchState,
    idx: Index,
    settings: NewtonSettings,
    *,
    with_rates: bool = False,
    curvature: bool = False,
) -> NDArray[np.bool_]:
    """Run Newton on the samples ``idx`` from their current ``state``; returns which converged ``(len(idx),)``.

    Updates ``state`` rows ``idx`` in place, including the model values at the last iterate. With
    ``with_rates`` every evaluation also computes the exact rates in the same compiled call
    (:meth:`Task.evaluate_with_rates`); they are kept for samples that converge with no active
    inequality (``rates_ready``), whose KKT matrix is the one the compiled call assumes. A reduced
    task (a planar robot's, :attr:`Task.compiled_rates` False) gets the same rates from
    :func:`vgtarm.ik.rates.exact` on the same samples instead.

    With ``curvature`` a sample with no active inequality whose reduced Hessian is not positive
    definite (:func:`negative_curvature`: a saddle or a maximum of the cost on the task, not a
    minimum) does not stop there, and takes the :func:`curvature_step` instead of the Newton step.
    Samples with positive curvature take the same steps as without it.
    """
    compiled_rates = with_rates and task.compiled_rates
    in_call = compiled_rates and not task.rates_at_the_end  # else asked for where samples stop
    working = np.asarray(idx, dtype=np.intp)
    state.converged[working] = False
    state.rates_ready[working] = False
    for step in range(settings.max_iterations + 1):
        if working.size == 0:
            break
        q, lam, mu, active = state.q[working], state.lam[working], state.mu[working], state.active[working]
        residual, J, H, g, rates = _evaluate(task, working, q, lam, problem.weight, in_call)
        done, predicted, finite = stopping_test(problem, q, lam, mu, active, (residual, J, H), settings, g)
        saddle = np.zeros(working.size, dtype=bool)
        W = None
        if curvature:
            check = finite & ~rows_any(predicted)
            W = kkt.hessian(problem, H)
            saddle[check] = negative_curvature(problem, _rows(W, check), J[check], predicted[check])
            done &= ~saddle
        keep = finite & ~done
        last = step == settings.max_iterations
        _store_model(state, working, None if last else ~keep, (residual, J, H, g))
        state.converged[working[done]] = True
        if compiled_rates and not in_call:
            _rates_at_the_end(problem, task, state, working, q, lam, done & ~rows_any(active))
        elif in_call:
            _store_rates(state, working, done & ~rows_any(active), rates)
        elif with_rates:
            rate_modes.exact(problem, task, state, working[done & ~rows_any(active)])
        if last:
            break
        working = working[keep]
        if working.size == 0:
            break
        g = None if g is None else g[keep]
        model = (residual[keep], J[keep], H[keep], g)
        W = None if W is None else W[keep]
        working = _newton_step(problem, state, working, q[keep], model, predicted[keep], saddle[keep], settings, W)
    return np.asarray(state.converged[idx])


def _rows(a: Array, mask: NDArray[np.bool_]) -> Array:
    """``a[mask]``, or ``a`` itself when the mask keeps every row (no copy)."""
    return a if mask.all() else a[mask]


def _evaluate(
    task: Task, working: Index, q: Array, lam: Array, weight: Array, in_call: bool
) -> tuple[Array, Array, Array, Array | None, tuple[Array, ...]]:
    """The model values ``(residual, J, H, g)`` at the iterate ``(q, lam)`` of the samples ``working``
    and with ``in_call`` the exact rates from the same compiled call (else an empty tuple); ``weight``
    is the diagonal of the Hessian of ``Phi``. :func:`_store_model` keeps them in the state."""
    if in_call:
        return task.evaluate_with_rates(working, q, lam, weight)
    residual, J, H, g = task.evaluate_cost(working, q, lam)
    return residual, J, H, g, ()


def _store_model(
    state: BatchState,
    working: Index,
    leaving: NDArray[np.bool_] | None,
    model: tuple[Array, Array, Array, Array | None],
) -> None:
    """Store the model values ``(residual, J, H, g)`` of the samples ``working`` that leave the
    iteration here (``leaving``; None: all of them) into ``state``.

    A sample that goes on is evaluated again at its next iterate, whose values would overwrite these:
    only the values at each sample's last evaluation are written (on a long arm ``H`` is a quarter of
    a megabyte a sample).
    """
    residual, J, H, g = model
    if leaving is not None and not leaving.all():
        if not leaving.any():
            return
        working, residual, J, H = working[leaving], residual[leaving], J[leaving], H[leaving]
        g = None if g is None else g[leaving]
    state.residual[working], state.J[working], state.H[working] = residual, J, H
    if g is not None and state.g is not None:
        state.g[working] = g


def _rates_at_the_end(
    problem: IKProblem, task: Task, state: BatchState, working: Index, q: Array, lam: Array, ready: NDArray[np.bool_]
) -> None:
    """The exact rates of the samples ``working[ready]`` that stopped here, by one more compiled
    call at their iterate ``(q, lam)`` (a task whose rates come :attr:`Task.rates_at_the_end`)."""
    if ready.any():
        rows = working[ready]
        *_, late = task.evaluate_with_rates(rows, q[ready], lam[ready], problem.weight)
        _store_rates(state, rows, np.ones(rows.size, dtype=bool), late)


def _newton_step(
    problem: IKProblem,
    state: BatchState,
    working: Index,
    q: Array,
    model: tuple[Array, Array, Array, Array | None],
    active: NDArray[np.bool_],
    saddle: NDArray[np.bool_],
    settings: NewtonSettings,
    W: Array | None = None,
) -> Index:
    """One step of the samples ``working`` still going from ``q`` (the model's ``(residual, J, H,
    g)`` there), with the predicted active sets ``active``: the Newton step of the KKT system (the
    :func:`curvature_step` for a ``saddle``), limited in length and kept assemblable, written into
    ``state``. ``W``: :func:`kkt.hessian` of ``H`` if already computed. Returns the samples that took
    it: those whose step could be solved (the model values of the others are stored, as those of
    samples that stop)."""
    nj = problem.n
    residual, J, H, g = model
    if W is None:
        W = kkt.hessian(problem, H)
    K = kkt.kkt_matrix(problem, W, J, active)
    x, solvable = kkt.solve(K, kkt.newton_rhs(problem, q, residual, active, g))
    if saddle.any():
        x[saddle] = curvature_step(
            problem,
            q[saddle],
            W[saddle],
            J[saddle],
            residual[saddle],
            None if g is None else g[saddle],
            settings.max_step,
        )
        solvable[saddle] = np.isfinite(x[saddle]).all(axis=1)
    solvable &= rows_all(np.isfinite(x))
    if not solvable.all():
        _store_model(state, working, ~solvable, model)
        working, q, W, J, x, active = (a[solvable] for a in (working, q, W, J, x, active))  # type: ignore[assignment]
        g = None if g is None else g[solvable]
    m = J.shape[1]
    dq = x[:, :nj]
    mu_new = kkt.bound_multipliers(problem, q, W, J, x, active, g)
    alpha = _step_length(problem, q, dq, settings.max_step)[:, None]
    q_new = q + alpha * dq
    full = alpha[:, 0] == 1.0
    lower, upper = active[:, :nj] & full[:, None], active[:, nj : 2 * nj] & full[:, None]
    q_new = np.where(lower, problem.lower, np.where(upper, problem.upper, q_new))
    lam_old, mu_old = state.lam[working], state.mu[working]
    state.q[working] = q_new
    state.lam[working] = lam_old + alpha * (x[:, nj : nj + m] - lam_old)
    state.mu[working] = mu_old + alpha * (mu_new - mu_old)
    state.active[working] = active
    state.iterations[working] += 1
    return working


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
    curvature: bool = True,
) -> None:
    """Solve samples ``order`` as the sequential chain from ``start`` would, into ``state``.

    ``start`` holds one sample's ``q``, ``lam``, ``mu`` and ``active`` to begin from. Samples whose
    Newton solve from their predecessor fails are left unconverged and skipped (the next one starts
    from the last solved sample). ``with_rates`` is passed to :func:`iterate`.
    """
    pending = np.asarray(order, dtype=np.intp)
    while pending.size:
        _start_all(state, pending, start)
        iterate(problem, task, state, pending, settings, with_rates=with_rates, curvature=curvature)
        run_a = _take(state, pending)
        ok_a = state.converged[pending].copy()
        agree = ok_a.copy()
        ok_b = np.zeros(pending.size, dtype=bool)
        if pending.size > 1:
            later = pending[1:]
            for name in _SOLUTION_FIELDS:
                getattr(state, name)[later] = run_a[name][:-1]
            iterate(problem, task, state, later, settings, with_rates=with_rates, curvature=curvature)
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
