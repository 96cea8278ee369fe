"""The recursive model of a stack: its arm as data arrays, evaluated in batches by the C loops.

:class:`RecursiveModel` turns a :class:`~vgtarm.model.stack.description.Stack` into the arrays of
``vgt_rec_arm`` (``csrc/vgt_rec.h``): one body per joint (a platform on its module, the part of a
twist stage on its twist joint), their spatial inertias, the module geometry, the friction,
gravity and tip point. Building one takes microseconds and compiles nothing.

The bodies are those of the symbolic model (:func:`~vgtarm.model.stack.symbolic.stack_dynamics`):
each platform, each twist part (none: a massless body of the chain), and the end-effector,
rigidly fixed to the last body (its inertia is added to it); the legs are massless. The twist
after module ``k`` turns about the platform's normal at its centre; the next module stands on the
twist frame moved up by the twist part's ``height``. Viscous friction acts on every joint, gravity
on every body, the tool force ``f`` at the tip point and the moment ``m`` on the end-effector:
``M qdd + C = F + J_P^T f + J_W^T m`` as in the symbolic model.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ... import checks
from ...errors import AssemblyError, InputError, shown
from ...machine import PROBE_ROWS, split_rows
from ..assembly import TRIANGLE_INEQUALITIES
from ..parameters import Body
from ..sanity import as_float, real_array
from ..stack.description import LEG_NAMES, Stack
from ..stack.symbolic import plane_direction
from .library import load_library

Array = NDArray[np.float64]

#: The joint types of ``vgt_rec_arm.type``.
MODULE, TWIST = 3, 1


def spatial_inertia(body: Body | None) -> Array:
    """The 6x6 spatial inertia of ``body`` about its frame's origin, in its frame ((angular,
    linear) order); zero for ``None`` (a massless part)."""
    inertia = np.zeros((6, 6))
    if body is None:
        return inertia
    m = body.mass
    c = np.array(body.com, dtype=float)
    cx = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
    inertia[:3, :3] = np.array(body.inertia, dtype=float) + m * (c @ c * np.eye(3) - np.outer(c, c))
    inertia[:3, 3:] = m * cx
    inertia[3:, :3] = m * cx.T
    inertia[3:, 3:] = m * np.eye(3)
    return inertia


class RecursiveModel:
    """Kinematics and dynamics of a stack by recursive algorithms over its modules, O(n) per sample.

    Every method takes one configuration (arrays ``(n,)``) or a batch (``(N, n)``) and returns
    results of the same leading shape. Inputs are checked as :class:`~vgtarm.model.stack.StackModel`
    checks them: the right length, real and finite numbers, every module assemblable.
    """

    def __init__(self, stack: Stack, *, gravity: ArrayLike | None = None, threads: int | None = 1) -> None:
        if not isinstance(stack, Stack):
            raise InputError(f"stack = {shown(stack)}: expected a Stack (see vgtarm.model.stack.load_stack)")
        if threads is not None:
            threads = checks.whole("threads", threads, 1, expected="a number of threads >= 1, or None (the machine's)")
        self.stack = stack
        #: Threads a batch runs on (:func:`vgtarm.machine.split_rows`): 1, the default, the calling
        #: thread alone; ``None`` as many as :func:`vgtarm.machine.batch_threads` gives (the
        #: :class:`~vgtarm.model.robot.Robot`'s backend). The results are the same bit for bit.
        self.threads = threads
        self.n = stack.n_joints
        self._ffi, self._lib = load_library()
        types: list[int] = []
        qi: list[int] = []
        tz: list[float] = []
        geom: list[float] = []
        inertias: list[Array] = []
        lift = 0.0  # height of the twist part below the next module
        i = 0
        self.module_bodies: list[int] = []
        for module in stack.modules:
            c, s = plane_direction(module.plane)
            self.module_bodies.append(len(types))
            types.append(MODULE)
            qi.append(i)
            tz.append(lift)
            geom += [module.b, module.d, c, s]
            inertias.append(spatial_inertia(module.platform))
            i += 3
            lift = 0.0
            if module.twist is not None:
                types.append(TWIST)
                qi.append(i)
                tz.append(0.0)
                geom += [0.0, 0.0, 0.0, 0.0]
                inertias.append(spatial_inertia(module.twist.body))
                i += 1
                lift = module.twist.height
        inertias[-1] = inertias[-1] + spatial_inertia(stack.end_effector)
        self.n_bodies = len(types)
        g = stack.gravity if gravity is None else np.asarray(gravity, dtype=float)
        self._arrays: dict[str, Any] = {
            "type": np.array(types, dtype=np.intc),
            "qi": np.array(qi, dtype=np.intc),
            "tz": np.array(tz, dtype=float),
            "geom": np.array(geom, dtype=float),
            "inertia": np.ascontiguousarray(np.stack(inertias)),
            "viscous": np.ascontiguousarray(stack.viscous, dtype=float),
            "gravity": np.array(g, dtype=float),
            "tip": np.array([0.0, 0.0, lift], dtype=float) + np.array(stack.tool, dtype=float),
        }
        arm = self._ffi.new("vgt_rec_arm *")
        arm.nb, arm.nq, arm.nm = self.n_bodies, self.n, stack.n_modules
        for name, array in self._arrays.items():
            kind = "int *" if array.dtype == np.intc else "double *"
            setattr(arm, name, self._ffi.cast(kind, self._ffi.from_buffer(array)))
        self._arm = arm
        G, h = stack.margin_form()
        legs = np.array(stack.leg_indices)
        rows = np.stack([G[6 * k : 6 * k + 6, legs[k]] for k in range(stack.n_modules)])
        if not (rows == rows[0]).all():  # the rows of the triangle inequalities hold for any b, d
            raise AssertionError("the assembly rows differ between modules")
        self._rows = np.ascontiguousarray(rows[0])
        self._h = np.ascontiguousarray(h)

    def __repr__(self) -> str:
        return f"RecursiveModel({self.stack.name!r}, {self.stack.n_modules} modules, {self.n} joints)"

    def with_gravity(self, gravity: ArrayLike) -> RecursiveModel:
        """The same arm under another gravity (the zero vector gives the pure inertial model)."""
        return RecursiveModel(self.stack, gravity=gravity, threads=self.threads)

    # -- checks and calls ------------------------------------------------------------------

    def _batch(self, value: ArrayLike, name: str, size: int) -> Array:
        raw = real_array(value, name, size, self.stack.joint_names if size == self.n else ())
        if raw.ndim not in (1, 2) or raw.shape[-1] != size:
            raise InputError(f"{name} must have shape ({size},) or (N, {size}), got shape {raw.shape}")
        array = np.ascontiguousarray(as_float(raw).reshape(-1, size))
        if not np.isfinite(array).all():
            row, col = np.argwhere(~np.isfinite(array))[0]
            raise InputError(f"{name} must be finite; {name}[{row}, {col}] = {array[row, col]}")
        return array

    def _q(self, q: ArrayLike) -> Array:
        qa = self._batch(q, "q", self.n)
        where = self._ffi.new("int[2]")
        sample = self._lib.vgt_rec_unassembled(
            self._arm, len(qa), self._ptr(qa), self._ptr(self._rows), self._ptr(self._h), where
        )
        if sample >= 0:
            k, inequality = where[0], where[1]
            idx = self.stack.leg_indices[k]
            margin = float(self._rows[inequality] @ qa[sample, list(idx)] + self._h[6 * k + inequality])
            legs = ", ".join(f"{leg}{k + 1} = {qa[sample, i]:.6g}" for leg, i in zip(LEG_NAMES, idx, strict=True))
            raise AssemblyError(
                f"q[{sample}]: module {k + 1} cannot be assembled: '{TRIANGLE_INEQUALITIES[inequality]}' fails "
                f"(margin {margin:.6g} m; {legs})"
            )
        return qa

    def _wrench(self, f_tip: ArrayLike | None, m_tip: ArrayLike | None, count: int) -> Array | None:
        if f_tip is None and m_tip is None:
            return None
        wrench = np.zeros((count, 6))
        for part, value, name in ((slice(0, 3), f_tip, "f_tip"), (slice(3, 6), m_tip, "m_tip")):
            if value is not None:
                wrench[:, part] = self._batch(value, name, 3)
        return wrench

    def _ptr(self, array: Array | None) -> Any:
        return self._ffi.NULL if array is None else self._ffi.cast("double *", self._ffi.from_buffer(array))

    def _call(self, name: str, count: int, *arrays: Array | None) -> None:
        """``name(arm, count, arrays...)`` over the batch: every array holds ``count`` rows (or is
        ``None``), each sample is computed alone, so the rows are split over :attr:`threads`."""
        function, arm = getattr(self._lib, name), self._arm
        pointers = [self._ptr(a) for a in arrays]
        if self.threads == 1 or count <= PROBE_ROWS:
            if function(arm, count, *pointers) != 0:
                raise MemoryError(f"{name}: the recursive model could not allocate its scratch memory")
            return
        rows = [0 if a is None else a.size // count for a in arrays]

        def work(start: int, stop: int) -> None:
            moved = [p if r == 0 else p + start * r for p, r in zip(pointers, rows, strict=True)]
            if function(arm, stop - start, *moved) != 0:
                raise MemoryError(f"{name}: the recursive model could not allocate its scratch memory")

        split_rows(count, work, self.threads)

    @staticmethod
    def _shaped(value: ArrayLike, result: Array) -> Array:
        return result[0] if np.ndim(value) == 1 else result

    # -- kinematics ------------------------------------------------------------------------

    def tip_position(self, q: ArrayLike) -> Array:
        """The tip ``(..., 3)`` alone (the joints' poses only: the same values as
        :meth:`forward_kinematics`' ``tip``, without the frames of every body)."""
        qa = self._q(q)
        tip = np.empty((len(qa), 3))
        self._call("vgt_rec_tip", len(qa), qa, tip)
        return self._shaped(q, tip)

    def forward_kinematics(self, q: ArrayLike) -> dict[str, Array]:
        """``tip`` ``(..., 3)``, ``rotation`` ``(..., 3, 3)`` of the end-effector, the platform frames
        ``platform_position`` ``(..., m, 3)`` and ``platform_rotation`` ``(..., m, 3, 3)``, and the
        ``passive`` angles ``(..., m, 4)`` (alpha, beta, gamma, theta of each module), and the frames of
        every body of the chain (platforms and twist parts, base first; origin at the platform
        centre), ``body_position`` ``(..., b, 3)`` and ``body_rotation`` ``(..., b, 3, 3)``."""
        qa = self._q(q)
        count, nb, m = len(qa), self.n_bodies, self.stack.n_modules
        tip, rot = np.empty((count, 3)), np.empty((count, 3, 3))
        pos, brot, passive = np.empty((count, nb, 3)), np.empty((count, nb, 3, 3)), np.empty((count, m, 4))
        self._call("vgt_rec_fk", count, qa, tip, rot, pos, brot, passive)
        out = {
            "tip": tip,
            "rotation": rot,
            "platform_position": pos[:, self.module_bodies],
            "platform_rotation": brot[:, self.module_bodies],
            "passive": passive,
            "body_position": pos,
            "body_rotation": brot,
        }
        return {key: self._shaped(q, value) for key, value in out.items()}

    def jacobians(self, q: ArrayLike) -> tuple[Array, Array]:
        """Tip Jacobian ``J_P`` and end-effector angular Jacobian ``J_W`` (F0), ``(..., 3, n)`` each."""
        qa = self._q(q)
        jp, jw = np.empty((len(qa), 3, self.n)), np.empty((len(qa), 3, self.n))
        self._call("vgt_rec_jacobian", len(qa), qa, jp, jw)
        return self._shaped(q, jp), self._shaped(q, jw)

    # -- dynamics --------------------------------------------------------------------------

    def mass_matrix(self, q: ArrayLike) -> Array:
        """``M(q)`` by composite rigid bodies, ``(..., n, n)``."""
        qa = self._q(q)
        M = np.empty((len(qa), self.n, self.n))
        self._call("vgt_rec_mass", len(qa), qa, M)
        return self._shaped(q, M)

    def inverse_dynamics(
        self,
        q: ArrayLike,
        qd: ArrayLike,
        qdd: ArrayLike,
        f_tip: ArrayLike | None = None,
        m_tip: ArrayLike | None = None,
    ) -> Array:
        """Efforts ``M qdd + C - J_P^T f_tip - J_W^T m_tip`` by recursive Newton-Euler, ``(..., n)``."""
        qa = self._q(q)
        qda, qdda = self._batch(qd, "qd", self.n), self._batch(qdd, "qdd", self.n)
        self._same(qa, qda, qdda)
        wrench = self._wrench(f_tip, m_tip, len(qa))
        tau = np.empty((len(qa), self.n))
        self._call("vgt_rec_inverse", len(qa), qa, qda, qdda, wrench, tau)
        return self._shaped(q, tau)

    def bias_forces(self, q: ArrayLike, qd: ArrayLike) -> Array:
        """``C(q, qd)``: velocity products, gravity and viscous friction, ``(..., n)``."""
        return self.inverse_dynamics(q, qd, np.zeros(np.shape(q)))

    def forward_dynamics(
        self, q: ArrayLike, qd: ArrayLike, F: ArrayLike, f_tip: ArrayLike | None = None, m_tip: ArrayLike | None = None
    ) -> Array:
        """Accelerations ``M^-1 (F + J_P^T f_tip + J_W^T m_tip - C)`` by articulated bodies, ``(..., n)``."""
        qa = self._q(q)
        qda, Fa = self._batch(qd, "qd", self.n), self._batch(F, "F", self.n)
        self._same(qa, qda, Fa)
        wrench = self._wrench(f_tip, m_tip, len(qa))
        qdd = np.empty((len(qa), self.n))
        self._call("vgt_rec_forward", len(qa), qa, qda, Fa, wrench, qdd)
        return self._shaped(q, qdd)

    @staticmethod
    def _same(*arrays: Array) -> None:
        if len({len(a) for a in arrays}) != 1:
            raise InputError(f"the batches differ in length: {[len(a) for a in arrays]}")
