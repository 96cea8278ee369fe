"""The recursive model behind :class:`~vgtarm.model.robot.Robot`: a backend of the model's functions.

``Robot(stack, RecursiveBackend(stack))`` (:func:`vgtarm.model.robot.recursive_robot`,
``load_robot(path, model="recursive")``) is a robot whose forward
kinematics, tip and angular Jacobians, ``M``, ``C``, forward and inverse dynamics come from the
recursive model (:class:`~.model.RecursiveModel`), with the Robot's own checks of every input and
result. Nothing is compiled for the arm, so any stack up to the 50 modules of
:data:`~vgtarm.model.stack.description.MAX_MODULES` gets them at once. The functions keep the
names, inputs and outputs of the symbolic library's (``fk``, ``tip``, ``jac``, ``mass``,
``bias_forces``, ``fd``, ``id``; sizes from :func:`vgtarm.model.outline.shapes`); the others (the
inverse kinematics', the control law's, the closed loops) are not on it yet and are refused by name.

The parameter vector ``p`` every function takes is read back into a stack of the backend's
structure (:func:`stack_from_vector`), so :meth:`Robot.with_parameters` works as with the
compiled library: a robot with other masses or dimensions shares the backend.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import interface
from ..compiled import Signature
from ..definition import StackDefinition
from ..outline import shapes
from ..parameters import Body
from ..stack.description import BODY_VALUES, Stack
from .library import load_library, loop_library
from .model import RecursiveModel
from .second_order import ik_terms

Array = NDArray[np.float64]

#: The functions of the symbolic library that the recursive model provides.
FUNCTIONS = (
    "fk",
    "tip",
    "jac",
    "mass",
    "bias_forces",
    "fd",
    "id",
    "ik_position",
    "ik_position_d2",
    "ik_position_rates",
    "velocity",
    "tip_state",
    "tip_hessian",
    "cfc",
)


def _body(values: Array, name: str) -> Body:
    m, cx, cy, cz, ixx, iyy, izz, ixy, ixz, iyz = (float(x) for x in values)
    inertia = ((ixx, ixy, ixz), (ixy, iyy, iyz), (ixz, iyz, izz))
    return Body(name=name, mass=m, com=(cx, cy, cz), inertia=inertia)


def stack_from_vector(stack: Stack, p: Array) -> Stack:
    """The stack of ``stack``'s structure whose :meth:`~Stack.vector` is ``p`` (checked as any stack)."""
    p = np.asarray(p, dtype=float).ravel()
    if p.shape != (stack.n_parameters,):
        raise ValueError(f"p must have {stack.n_parameters} values for this stack, got {p.shape}")
    o = 0
    modules = []
    for k, module in enumerate(stack.modules, start=1):
        b, d = float(p[o]), float(p[o + 1])
        platform = _body(p[o + 2 : o + 2 + BODY_VALUES], f"platform{k}")
        o += 2 + BODY_VALUES
        twist = module.twist
        if twist is not None:
            height = float(p[o])
            o += 1
            body = None
            if twist.body is not None:
                body = _body(p[o : o + BODY_VALUES], f"twist{k + 1}")
                o += BODY_VALUES
            twist = replace(twist, height=height, body=body)
        modules.append((b, d, platform, twist))
    end_effector = _body(p[o : o + BODY_VALUES], "end_effector")
    o += BODY_VALUES
    tool = p[o : o + 3]
    viscous = p[o + 3 : o + 3 + stack.n_joints]
    gravity = p[o + 3 + stack.n_joints :]
    built = []
    i = 0
    for module, (b, d, platform, twist) in zip(stack.modules, modules, strict=True):
        legs = (float(viscous[i]), float(viscous[i + 1]), float(viscous[i + 2]))
        i += 3
        if twist is not None:
            twist = replace(twist, viscous=float(viscous[i]))
            i += 1
        built.append(replace(module, b=b, d=d, platform=platform, viscous=legs, twist=twist))
    return replace(
        stack,
        modules=tuple(built),
        end_effector=end_effector,
        tool=(float(tool[0]), float(tool[1]), float(tool[2])),
        gravity=(float(gravity[0]), float(gravity[1]), float(gravity[2])),
    )


#: The closed loop's functions (fields of ``vgt_model``) and the adapters that give them.
LOOP_FUNCTIONS = {
    "cfc": "vgt_rec_fn_cfc",
    "fd": "vgt_rec_fn_fd",
    "tip_state": "vgt_rec_fn_tip_state",
    "tip": "vgt_rec_fn_tip",
    "id": "vgt_rec_fn_id",
    "jac": "vgt_rec_fn_jac",
    "tip_hessian": "vgt_rec_fn_tip_hessian",
}
#: The same on the loop step's shared kinematics (``vgt_rec_step_*``): the joints of a step's state
#: computed once for the plant's tip state, the CFC law and the plant's forward dynamics.
FUSED_LOOP_FUNCTIONS = {
    **LOOP_FUNCTIONS,
    "cfc": "vgt_rec_fn_cfc_fused",
    "fd": "vgt_rec_fn_fd_fused",
    "tip_state": "vgt_rec_fn_tip_state_fused",
    "tip": "vgt_rec_fn_tip_fused",
    "id": "vgt_rec_fn_id_fused",
}
#: Slots of the C registry of bound parameter vectors (``vgt_rec_bind``), shared by every backend
#: of the process: each holds the array (so its address stays its own) and its model.
_SLOTS = 64
_bound: dict[int, tuple[int, Array, RecursiveModel]] = {}  # address -> (slot, array, model)
_next_slot = [0]


def _solve(K: Array, rhs: Array) -> Array:
    """``K x = rhs`` per sample (LAPACK, batched); a singular sample's row is NaN (the IK then treats
    it as the symbolic library's QR solve's non-finite result)."""
    try:
        return np.asarray(np.linalg.solve(K, rhs[..., None])[..., 0])
    except np.linalg.LinAlgError:
        out = np.full(rhs.shape, np.nan)
        for i in range(K.shape[0]):
            try:
                out[i] = np.linalg.solve(K[i], rhs[i])
            except np.linalg.LinAlgError:
                pass
        return out


class RecursiveBackend:
    """The functions :data:`FUNCTIONS` of a stack's model, evaluated by the recursive model."""

    kind = "recursive"

    def __init__(self, stack: Stack, *, fused: bool = True, threads: int | None = None) -> None:
        self.stack = stack
        #: Threads of a batch (:attr:`RecursiveModel.threads`): ``None``, the default, as many as
        #: :func:`vgtarm.machine.batch_threads` gives; 1 the calling thread alone (the same results).
        self.threads = threads
        #: The closed loop's functions share a step's kinematics (:data:`FUSED_LOOP_FUNCTIONS`) and
        #: ``tip`` is computed from the poses alone; ``False``: the previous implementation (the
        #: separate adapters of :data:`LOOP_FUNCTIONS`, ``tip`` from the whole forward kinematics),
        #: kept as the benchmarks' baseline: the same results bit for bit.
        self.fused = fused
        self.n = stack.n_joints
        found = shapes(StackDefinition.of(stack))
        self._signatures = {
            key: Signature(
                name=found[key].name,
                nnz_in=found[key].nnz_in,
                nnz_out=found[key].nnz_out,
                sz_arg=0,
                sz_res=0,
                sz_iw=0,
                sz_w=0,
                in_names=found[key].in_names,
                out_names=found[key].out_names,
            )
            for key in FUNCTIONS
        }
        self._models: dict[bytes, RecursiveModel] = {stack.vector().tobytes(): RecursiveModel(stack, threads=threads)}

    #: The compiled closed loop runs on this backend (:class:`~vgtarm.model.closedloop.ClosedLoopDriver`).
    closed_loop = True

    @property
    def library(self) -> Any:
        """The recursive library opened with the closed loop's interface (:func:`.library.loop_library`)."""
        return loop_library()

    def call(self, name: str) -> Any:
        """A ``vgt_call`` of the closed loop's function ``name`` (its adapter on the recursive model)."""
        ffi, lib = load_library()
        functions = FUSED_LOOP_FUNCTIONS if self.fused else LOOP_FUNCTIONS
        address = int(ffi.cast("intptr_t", getattr(lib, functions[name])))
        loop_ffi = interface.ffi()
        return loop_ffi.new("vgt_call *", [loop_ffi.cast("vgt_fn", address), 8, 2, 0, 0])[0]

    def bind_parameters(self, *vectors: Array) -> None:
        """Register, for the closed loop's adapters, the arm of each parameter vector (by its address:
        the arrays must be the C-contiguous float64 arrays whose pointers the drivers receive)."""
        ffi, lib = load_library()
        for p in vectors:
            if p.dtype != np.float64 or not p.flags.c_contiguous or p.shape != (self.stack.n_parameters,):
                raise ValueError("bind_parameters: expected the stack's parameter vectors (C-contiguous float64)")
            address = int(p.ctypes.data)
            known = _bound.get(address)
            if known is not None and known[1] is p and np.array_equal(known[2].stack.vector(), p):
                continue
            slot = known[0] if known is not None else _next_slot[0]
            if known is None:
                _next_slot[0] = (slot + 1) % _SLOTS
                for old, entry in list(_bound.items()):
                    if entry[0] == slot:
                        del _bound[old]
            model = self._model(p)  # equal vectors (plant, exact controller model): one arm
            _bound[address] = (slot, p, model)
            lib.vgt_rec_bind(slot, ffi.cast("double *", address), model._arm)

    def bind_run(self, Kp: Array | None, Kv: Array | None, G: Array | None = None) -> None:
        """Tell the fused step, in this thread, the gain matrices ``Kp``, ``Kv`` (``n x n``) and the
        margin rows ``G`` (``rows x n``) the next driver call passes (C-contiguous float64): the CFC
        law sums the gains' products and the driver's assembly check the margins' over their nonzero
        entries only (the same values). ``None`` unbinds. The arrays must not change until unbound
        (the driver unbinds after its call)."""
        ffi, lib = load_library()
        if Kp is None or Kv is None or not self.fused:  # the previous implementation binds nothing
            lib.vgt_rec_bind_run(ffi.NULL, ffi.NULL, 0, ffi.NULL, 0)
            return
        arrays = [(Kp, (self.n, self.n)), (Kv, (self.n, self.n))]
        if G is not None:
            arrays.append((G, (G.shape[0] if G.ndim == 2 else -1, self.n)))
        for A, shape in arrays:
            if A.dtype != np.float64 or not A.flags.c_contiguous or A.shape != shape:
                raise ValueError("bind_run: expected C-contiguous float64 gains (n x n) and margin rows (rows x n)")
        rows = 0 if G is None else G.shape[0]
        pointers = [ffi.NULL if A is None else ffi.cast("double *", A.ctypes.data) for A in (Kp, Kv, G)]
        if lib.vgt_rec_bind_run(pointers[0], pointers[1], self.n, pointers[2], rows):
            raise MemoryError("bind_run: could not allocate the index of the gains and margins")

    def signature(self, name: str) -> Signature:
        if name not in self._signatures:
            raise KeyError(f"{name!r} is not on the recursive model (it has {', '.join(FUNCTIONS)})")
        return self._signatures[name]

    def _model(self, p: Array) -> RecursiveModel:
        key = np.ascontiguousarray(p, dtype=float).ravel().tobytes()
        model = self._models.get(key)
        if model is None:
            if len(self._models) > 16:
                self._models.clear()
            model = self._models[key] = RecursiveModel(
                stack_from_vector(self.stack, np.frombuffer(key)), threads=self.threads
            )
        model.threads = self.threads
        return model

    def evaluate(self, name: str, inputs: Sequence[Array], n: int) -> list[Array]:
        sig = self.signature(name)
        if len(inputs) != len(sig.nnz_in):
            raise ValueError(f"{name}: {len(sig.nnz_in)} inputs expected, got {len(inputs)}")
        *arrays, p = (np.asarray(x, dtype=float) for x in inputs)
        model = self._model(p)
        rows = [np.ascontiguousarray(np.broadcast_to(a, (n, a.shape[-1]))) for a in arrays]
        if n == 0:
            return [np.empty((0, size)) for size in sig.nnz_out]
        q = rows[0]
        if name == "tip" and self.fused:
            return [model.tip_position(q)]
        if name == "tip":  # the previous implementation's (the benchmarks' baseline): the same values
            return [model.forward_kinematics(q)["tip"]]
        if name == "fk":
            fk = model.forward_kinematics(q)
            return [
                fk["passive"].reshape(n, -1),
                fk["platform_position"].reshape(n, -1),
                fk["platform_rotation"].reshape(n, -1),
                fk["tip"],
                fk["rotation"].reshape(n, -1),
            ]
        if name == "jac":
            jp, jw = model.jacobians(q)
            return [jp.reshape(n, -1), jw.reshape(n, -1)]
        if name == "mass":
            return [model.mass_matrix(q).reshape(n, -1)]
        if name == "bias_forces":
            return [model.bias_forces(q, rows[1])]
        if name == "fd":
            return [model.forward_dynamics(q, rows[1], rows[2], rows[3])]
        if name == "id":
            return [model.inverse_dynamics(q, rows[1], rows[2], rows[3])]
        if name in ("velocity", "tip_state"):
            jp, jw = model.jacobians(q)
            velocity = np.einsum("nij,nj->ni", jp, rows[1])
            if name == "tip_state":
                return [model.forward_kinematics(q)["tip"], velocity]
            return [velocity, np.einsum("nij,nj->ni", jw, rows[1])]
        if name == "tip_hessian":
            qa = model._q(q)
            return [
                np.stack([ik_terms(model, qa, np.broadcast_to(e, (n, 3)))["H"] for e in np.eye(3)], axis=1).reshape(
                    n, -1
                )
            ]
        if name == "cfc":  # M (qdd_d + Kp e + Kv e_dot) + C: inverse dynamics of the commanded acceleration
            q_d, qd_d, qdd_d = rows[2], rows[3], rows[4]
            Kp, Kv = rows[5].reshape(n, self.n, self.n), rows[6].reshape(n, self.n, self.n)
            commanded = qdd_d + np.einsum("nij,nj->ni", Kp, q_d - q) + np.einsum("nij,nj->ni", Kv, qd_d - rows[1])
            return [model.inverse_dynamics(q, rows[1], commanded)]
        return self._ik(name, model, rows, n)

    def _ik(self, name: str, model: RecursiveModel, rows: list[Array], n: int) -> list[Array]:
        """The position task's functions (:mod:`vgtarm.model.codegen.ik`) from :func:`.second_order.tip_terms`."""
        q, lam = model._q(rows[0]), rows[1]
        nj = self.n
        if name == "ik_position_d2":
            return [ik_terms(model, q, lam, rows[2], rows[3])["d2"]]
        out = ik_terms(model, q, lam)
        c, J, H = out["c"], out["J"], out["H"]
        flat = [c, J.reshape(n, -1), H.reshape(n, -1)]
        if name == "ik_position":
            return flat
        # ik_position_rates: the KKT matrix [[diag(w) + H, J^T], [J, 0]], solved by LAPACK for both systems
        w, xd, xdd = rows[2], rows[3], rows[4]
        K = np.zeros((n, nj + 3, nj + 3))
        K[:, :nj, :nj] = H
        K[:, :nj, :nj][:, np.arange(nj), np.arange(nj)] += w
        K[:, :nj, nj:] = J.transpose(0, 2, 1)
        K[:, nj:, :nj] = J
        rhs = np.zeros((n, nj + 3))
        rhs[:, nj:] = xd
        first = _solve(K, rhs)
        d2 = ik_terms(model, q, lam, first[:, :nj], first[:, nj:])["d2"]
        rhs = -d2
        rhs[:, nj:] += xdd
        second = _solve(K, rhs)
        return [*flat, first[:, :nj], first[:, nj:], second[:, :nj], second[:, nj:]]
