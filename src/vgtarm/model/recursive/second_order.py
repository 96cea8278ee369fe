"""Exact second- and third-order tip terms of the recursive model, for the inverse kinematics.

The tip is a product of the joints' transforms, ``P = T_1(q_1) T_2(q_2) ... T_b(q_b) p`` (4x4
homogeneous, ``q_a`` the coordinates of joint ``a``: three legs of a module, or a twist angle; the
offset ``tz`` of each joint is in its ``T``). A partial derivative in a coordinate of joint ``a``
falls on ``T_a`` alone, so every derivative of ``P`` is the same product with some factors replaced
by their own partial derivatives. Those come from the generated module function
``vgt_rec_module_taylor`` (automatic differentiation of the one module solution up to third order,
:mod:`.joint`) and, for a twist, from ``Rz``'s closed form. Nothing here is a finite difference.

What the inverse kinematics' Newton steps and exact rates need (the functions ``ik_position``,
``ik_position_d2`` and ``ik_position_rates`` of the symbolic library, :mod:`vgtarm.model.codegen.ik`):

- the tip ``P``, its Jacobian ``J`` (3 x n);
- ``H = d^2 (lam . P) / dq^2``: for coordinates ``i``, ``j`` of joints ``a < b``,
  ``d^2 P / dq_i dq_j = omega_i x (dP / dq_j)`` (``omega_i`` the angular velocity per unit rate of
  ``q_i``, ``dP / dq_j`` the column of ``J``), so the blocks off the diagonal are one product
  ``Omega [lam]x^T J``; the diagonal blocks are ``lam . (L_a d^2 T_a R_a)``;
- along a direction ``v`` (``qd``): the tip's ``D^2 P[v, v]``, ``DJ[v]`` and
  ``d/dq (lam . D^2 P[v, v])`` (a third derivative), by second-order Taylor jets in ``t`` of
  ``P(q + t v)``: prefix products ``L_a(t) = T_1 ... T_(a-1)`` and suffix products
  ``R_a(t) = T_(a+1) ... T_b p`` (``O(n)`` per sample), and for each coordinate ``i`` of joint ``a``
  the jet of ``L_a(t) dT_a/dq_i(t) R_a(t)``.

Cost per sample: ``O(n)`` for everything but ``H``, which has ``n^2`` entries.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from .model import RecursiveModel

Array = NDArray[np.float64]


def _module_jets(values: Array, tz: Array, third: bool) -> tuple[Array, Array, Array, Array | None]:
    """Homogeneous ``T`` ``(N, m, 4, 4)`` and its partials ``(N, m, 3, 4, 4)``, ``(N, m, 3, 3, 4, 4)``,
    ``(N, m, 3, 3, 3, 4, 4)`` of the ``m`` modules from the generated values ``(N, m, 480)`` and the
    modules' offsets ``tz`` ``(m,)``."""
    lead = values.shape[:2]

    def lift(block: Array, shape: tuple[int, ...], one: bool) -> Array:
        flat = block.reshape((*lead, *shape, 12))
        out = np.zeros((*lead, *shape, 4, 4))
        out[..., :3, :3] = flat[..., :9].reshape((*lead, *shape, 3, 3))
        out[..., :3, 3] = flat[..., 9:]
        if one:
            out[..., 3, 3] = 1.0
            out[..., 2, 3] += tz
        return out

    d0 = lift(values[..., :12], (), True)
    d1 = lift(values[..., 12:48], (3,), False)
    d2 = lift(values[..., 48:156], (3, 3), False)
    d3 = lift(values[..., 156:480], (3, 3, 3), False) if third else None
    return d0, d1, d2, d3


def _twist_jets(theta: Array, tz: float) -> tuple[Array, Array, Array, Array | None]:
    """``T = Trans(0, 0, tz) Rz(theta)`` and its derivatives, shaped as :func:`_module_jets` with one coordinate."""
    count = theta.shape[0]
    out = []
    for k in range(4):
        c, s = np.cos(theta + k * np.pi / 2), np.sin(theta + k * np.pi / 2)
        m = np.zeros((count, 4, 4))
        m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1] = c, -s, s, c
        if k == 0:
            m[:, 2, 2] = m[:, 3, 3] = 1.0
            m[:, 2, 3] = tz
        out.append(m)
    return out[0], out[1][:, None], out[2][:, None, None], out[3][:, None, None, None]


def _joint_jets(model: RecursiveModel, q: Array, third: bool) -> list[tuple[Array, Array, Array, Array | None]]:
    """The jets of every joint's transform at ``q`` ``(N, n)``, bodies base first."""
    arrays = model._arrays
    count = q.shape[0]
    taylor = np.empty((count, model.stack.n_modules, 480))
    model._call("vgt_rec_taylor", count, q, taylor)
    modules = np.flatnonzero(arrays["type"] == 3)
    every = _module_jets(taylor, arrays["tz"][modules], third)
    jets = []
    module = 0
    for body in range(model.n_bodies):
        tz, start = float(arrays["tz"][body]), int(arrays["qi"][body])
        if arrays["type"][body] == 3:
            d3 = None if every[3] is None else every[3][:, module]
            jets.append((every[0][:, module], every[1][:, module], every[2][:, module], d3))
            module += 1
        else:
            jets.append(_twist_jets(q[:, start], tz))
    return jets


def _vee_rotated(rotation: Array, d: Array, R: Array) -> Array:
    """``rotation vee(d R^T)`` for ``d`` ``(N, k, 3, 3)``: the angular velocity per unit rate in F0."""
    w = np.einsum("nkij,nlj->nkil", d, R)  # d R^T
    local = np.stack([w[..., 2, 1], w[..., 0, 2], w[..., 1, 0]], axis=-1)
    return np.einsum("nij,nkj->nki", rotation, local)


def _skew(x: Array) -> Array:
    out = np.zeros(x.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -x[..., 2], x[..., 1], -x[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = x[..., 2], -x[..., 1], x[..., 0]
    return out


def tip_terms(
    model: RecursiveModel, q: Array, lam: Array, qd: Array | None = None, lam_d: Array | None = None
) -> dict[str, Array]:
    """``c`` ``(N, 3)``, ``J`` ``(N, 3, n)``, ``H`` ``(N, n, n)`` at ``q`` ``(N, n)`` with multipliers
    ``lam`` ``(N, 3)``; with ``qd`` and ``lam_d`` also ``d2`` ``(N, n + 3)``: the second derivative of
    ``[J^T lam; P]`` along ``(qd, lam_d)`` (the symbolic library's ``ik_position_d2``), and ``Pvv``
    ``(N, 3)`` (``D^2 P[qd, qd]``, the tip's acceleration at ``qdd = 0``) and ``DJ`` ``(N, 3, n)``."""
    count, n = q.shape
    jets = _joint_jets(model, q, qd is not None)
    qi, types = model._arrays["qi"], model._arrays["type"]
    sizes = [3 if t == 3 else 1 for t in types]
    ordered = qd is not None
    order = 3 if ordered else 1
    # local t-jets of each joint and of its partials (derivative in t of order k, not Taylor coefficients)
    local: list[list[Array]] = []
    partial: list[list[Array]] = []
    for (d0, d1, d2, d3), start, k in zip(jets, qi, sizes, strict=True):
        if ordered:
            assert qd is not None and d3 is not None
            v = qd[:, start : start + k]
            local.append([d0, np.einsum("nk,nkij->nij", v, d1), np.einsum("nk,nl,nklij->nij", v, v, d2)])
            partial.append([d1, np.einsum("nl,nklij->nkij", v, d2), np.einsum("nl,nm,nklmij->nkij", v, v, d3)])
        else:
            local.append([d0])
            partial.append([d1])
    nb = len(jets)
    eye = np.broadcast_to(np.eye(4), (count, 4, 4))
    zero = np.zeros((count, 4, 4))
    prefix: list[list[Array]] = [[eye, zero, zero][:order]]
    for a in range(nb):
        prefix.append(_product(prefix[-1], local[a]))
    tip_point = np.append(np.asarray(model._arrays["tip"], dtype=float), 1.0)
    point = np.broadcast_to(tip_point, (count, 4))
    suffix: list[list[Array]] = [[] for _ in range(nb)]
    suffix[nb - 1] = [point, np.zeros((count, 4)), np.zeros((count, 4))][:order]
    for a in range(nb - 1, 0, -1):
        suffix[a - 1] = _apply(local[a], suffix[a])
    J = np.empty((count, 3, n))
    omega = np.empty((count, n, 3))
    DJ = np.empty((count, 3, n)) if ordered else None
    third = np.empty((count, 3, n)) if ordered else None
    H = np.zeros((count, n, n))
    for a in range(nb):
        start, k = int(qi[a]), sizes[a]
        L, D, R = prefix[a], partial[a], suffix[a]
        cols = _triple(L, D, R)  # jets of dP/dq_i, (N, k, 4) each
        J[:, :, start : start + k] = cols[0][..., :3].transpose(0, 2, 1)
        if ordered:
            assert DJ is not None and third is not None
            DJ[:, :, start : start + k] = cols[1][..., :3].transpose(0, 2, 1)
            third[:, :, start : start + k] = cols[2][..., :3].transpose(0, 2, 1)
        omega[:, start : start + k] = _vee_rotated(L[0][:, :3, :3], D[0][..., :3, :3], local[a][0][:, :3, :3])
        d2 = jets[a][2]  # (N, k, k, 4, 4)
        block = np.einsum("nij,nklj->nkli", L[0][:, :3], np.einsum("nklij,nj->nkli", d2, R[0]))
        H[:, start : start + k, start : start + k] = np.einsum("nkli,ni->nkl", block, lam)
    # blocks off the diagonal: lam . (omega_i x J_j) for joint(i) < joint(j)
    joint_of = np.repeat(np.arange(nb), sizes)
    before = joint_of[:, None] < joint_of[None, :]
    upper = np.einsum("nia,nab,nbj->nij", omega, -_skew(lam), J, optimize=True) * before
    H += upper + upper.transpose(0, 2, 1)
    tip = np.einsum("nij,nj->ni", prefix[nb][0][:, :3], point)
    out = {"c": tip, "J": J, "H": H, "omega": omega}
    if ordered:
        assert DJ is not None and third is not None and lam_d is not None
        Pvv = np.einsum("nij,nj->ni", prefix[nb][2][:, :3], point)
        d2 = np.empty((count, n + 3))
        d2[:, :n] = np.einsum("nij,ni->nj", third, lam) + 2 * np.einsum("nij,ni->nj", DJ, lam_d)
        d2[:, n:] = Pvv
        out.update(d2=d2, Pvv=Pvv, DJ=DJ)
    return out


def _product(f: list[Array], g: list[Array]) -> list[Array]:
    """Jets (derivatives of orders 0..) of the matrix product ``f g``."""
    out = [f[0] @ g[0]]
    if len(f) > 1:
        out.append(f[1] @ g[0] + f[0] @ g[1])
        out.append(f[2] @ g[0] + 2 * (f[1] @ g[1]) + f[0] @ g[2])
    return out


def _apply(f: list[Array], x: list[Array]) -> list[Array]:
    """Jets of ``f x`` for matrices ``f`` ``(N, 4, 4)`` and vectors ``x`` ``(N, 4)``."""
    out = [np.einsum("nij,nj->ni", f[0], x[0])]
    if len(f) > 1:
        out.append(np.einsum("nij,nj->ni", f[1], x[0]) + np.einsum("nij,nj->ni", f[0], x[1]))
        out.append(
            np.einsum("nij,nj->ni", f[2], x[0])
            + 2 * np.einsum("nij,nj->ni", f[1], x[1])
            + np.einsum("nij,nj->ni", f[0], x[2])
        )
    return out


def _triple(L: list[Array], D: list[Array], R: list[Array]) -> list[Array]:
    """Jets of ``L D_k R`` for each partial ``k``: ``L`` ``(N, 4, 4)``, ``D`` ``(N, k, 4, 4)``, ``R`` ``(N, 4)``."""

    def lr(Lm: Array, Dm: Array, Rv: Array) -> Array:
        return np.einsum("nij,nkj->nki", Lm, np.einsum("nkij,nj->nki", Dm, Rv))

    out = [lr(L[0], D[0], R[0])]
    if len(L) > 1:
        out.append(lr(L[1], D[0], R[0]) + lr(L[0], D[1], R[0]) + lr(L[0], D[0], R[1]))
        out.append(
            lr(L[2], D[0], R[0])
            + lr(L[0], D[2], R[0])
            + lr(L[0], D[0], R[2])
            + 2 * (lr(L[1], D[1], R[0]) + lr(L[1], D[0], R[1]) + lr(L[0], D[1], R[1]))
        )
    return out


def ik_terms(
    model: RecursiveModel, q: Array, lam: Array, qd: Array | None = None, lam_d: Array | None = None
) -> dict[str, Array]:
    """As :func:`tip_terms` (``c``, ``J``, ``H`` and, with ``qd`` and ``lam_d``, ``d2``), computed per
    sample by the C loops (``vgt_rec_ik_terms``: the same algebra; :func:`tip_terms` is its NumPy twin)."""
    count, n = q.shape
    arrays = [np.ascontiguousarray(a, dtype=float) for a in (q, lam)]
    ordered = qd is not None and lam_d is not None
    extra = [np.ascontiguousarray(a, dtype=float) for a in (qd, lam_d)] if ordered else [None, None]
    c, J, H = np.empty((count, 3)), np.empty((count, 3, n)), np.empty((count, n, n))
    d2 = np.empty((count, n + 3)) if ordered else None
    model._call("vgt_rec_ik_terms", count, *arrays, *extra, c, J, H, d2)
    out = {"c": c, "J": J, "H": H}
    if d2 is not None:
        out["d2"] = d2
    return out
