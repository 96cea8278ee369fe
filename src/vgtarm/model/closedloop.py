"""Binding of the compiled closed-loop drivers (``csrc/closed_loop.c``) through ``csrc/vgtarm.h``.

This is the model layer's fast path for the simulation and for the genetic algorithm's
fitness: whole runs of computed force control, and whole batches of gain candidates, each in
one call into C. Layers above use :class:`ClosedLoopDriver` when the backend is compiled and
their NumPy reference implementation otherwise. Structures, status and integrator codes come
from the header (:mod:`.interface`); nothing of the C interface is repeated here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .compiled import CompiledBackend
from .interface import enum, ffi

Array = NDArray[np.float64]

_STATUS = enum("vgt_status")
#: Status codes of ``vgt_simulate`` (enum ``vgt_status`` of the header).
DONE = _STATUS["VGT_DONE"]
ABOVE_THRESHOLD = _STATUS["VGT_ABOVE_THRESHOLD"]
NOT_FINITE = _STATUS["VGT_NOT_FINITE"]
NOT_ASSEMBLABLE = _STATUS["VGT_NOT_ASSEMBLABLE"]
OUTSIDE_LIMITS = _STATUS["VGT_OUTSIDE_LIMITS"]
FUNCTION_FAILED = _STATUS["VGT_FUNCTION_FAILED"]
NO_MEMORY = _STATUS["VGT_NO_MEMORY"]
#: Integrator codes by name (enum ``vgt_integrator`` of the header, ``VGT_RK4`` -> ``"rk4"``).
INTEGRATOR_CODES = {name.removeprefix("VGT_").lower(): code for name, code in enum("vgt_integrator").items()}

#: The generated functions the loop calls, by field of ``vgt_model``.
_MODEL_FIELDS = ("cfc", "fd", "tip_state", "tip")


def _ptr(array: Array) -> Any:
    if array.dtype != np.float64 or not array.flags.c_contiguous:
        raise ValueError("closed-loop arrays must be C-contiguous float64")
    return ffi().cast("double *", array.ctypes.data)


@dataclass(frozen=True)
class LoopSettings:
    """Settings of one closed-loop run (``vgt_settings`` of ``vgtarm.h``)."""

    dt: float
    integrator: str
    substeps: int
    cutting: bool
    cutting_force: float
    cutting_speed: float
    threshold: float
    limit_tolerance: float

    def struct(self, n_joints: int, n_margins: int) -> Any:
        """The C structure of these settings for a robot of ``n_joints`` joints."""
        return ffi().new(
            "vgt_settings *",
            {
                "n_joints": n_joints,
                "n_margins": n_margins,
                "dt": self.dt,
                "integrator": INTEGRATOR_CODES[self.integrator],
                "substeps": self.substeps,
                "cutting": int(self.cutting),
                "cutting_force": self.cutting_force,
                "cutting_speed": self.cutting_speed,
                "threshold": self.threshold,
                "limit_tolerance": self.limit_tolerance,
            },
        )


class LoopArrays:
    """The input and output arrays of one run, kept alive while C holds pointers to them."""

    def __init__(
        self,
        *,
        q_d: Array,
        qd_d: Array,
        qdd_d: Array,
        tip_d: Array,
        disturbance: Array,
        p_plant: Array,
        p_ctrl: Array,
        G: Array,
        h: Array,
        q_min: Array,
        q_max: Array,
        q0: Array,
        qd0: Array,
    ) -> None:
        n, n_joints = np.shape(q_d)
        self.n = n
        self.n_joints = n_joints
        self.n_margins = len(h)
        self.inputs = {
            name: np.ascontiguousarray(value, dtype=np.float64)
            for name, value in dict(
                q_d=q_d,
                qd_d=qd_d,
                qdd_d=qdd_d,
                tip_d=tip_d,
                disturbance=disturbance,
                p_plant=p_plant,
                p_ctrl=p_ctrl,
                G=G,
                h=h,
                q_min=q_min,
                q_max=q_max,
            ).items()
        }
        self.q = np.full((n, n_joints), np.nan)
        self.qd = np.full((n, n_joints), np.nan)
        self.q[0], self.qd[0] = q0, qd0
        self.F = np.full((n, n_joints), np.nan)
        self.f_ext = np.full((n, 3), np.nan)
        self.tip = np.full((n, 3), np.nan)
        self.error = np.full(n, np.nan)
        fields = {name: _ptr(a) for name, a in self.inputs.items()}
        fields.update(
            q=_ptr(self.q),
            qd=_ptr(self.qd),
            F=_ptr(self.F),
            f_ext=_ptr(self.f_ext),
            tip=_ptr(self.tip),
            error=_ptr(self.error),
        )
        self.struct = ffi().new("vgt_run *", {"n": n, **fields})


class ClosedLoopDriver:
    """The compiled closed loop of one backend."""

    def __init__(self, backend: CompiledBackend) -> None:
        self.backend = backend
        self._model = ffi().new("vgt_model *", {field: backend.call(field) for field in _MODEL_FIELDS})
        self._lib = backend.library

    def simulate(
        self, settings: LoopSettings, arrays: LoopArrays, Kp: Array, Kv: Array, k0: int, k1: int
    ) -> tuple[int, int]:
        """Run samples ``k0 .. k1-1`` with gains ``Kp``, ``Kv`` (n x n); returns (status, stop sample)."""
        s = settings.struct(arrays.n_joints, arrays.n_margins)
        kp = np.ascontiguousarray(Kp, dtype=np.float64)
        kv = np.ascontiguousarray(Kv, dtype=np.float64)
        stop = ffi().new("long *")
        status = self._lib.vgt_simulate(self._model, s, arrays.struct, _ptr(kp), _ptr(kv), k0, k1, stop)
        return int(status), int(stop[0])

    def ga_predictor(
        self, p_ctrl: Array, dt: float, q0: Array, qd0: Array, q_d: Array, qd_d: Array, qdd_d: Array, tip_d: Array
    ) -> Callable[[Array, Array], Array]:
        """The GA's fitness for one state and reference window, bound once for many calls.

        ``q0``, ``qd0`` (n,): the state at sample k; ``q_d``, ``qd_d``, ``qdd_d`` (H+1, n) and
        ``tip_d`` (H+1, 3): the reference at samples k .. k+H. The returned function maps
        ``Kp``, ``Kv`` (P, n, n) to the predicted tip-error norms (P,).
        """
        fixed = [np.ascontiguousarray(a, dtype=np.float64) for a in (p_ctrl, q0, qd0, q_d, qd_d, qdd_d, tip_d)]
        settings = ffi().new("vgt_settings *", {"n_joints": len(fixed[1]), "dt": dt})
        head = (self._model, settings, _ptr(fixed[0]), len(fixed[3]) - 1, *[_ptr(a) for a in fixed[1:]])
        lib = self._lib

        def predict(Kp: Array, Kv: Array) -> Array:
            kp = np.ascontiguousarray(Kp, dtype=np.float64)
            kv = np.ascontiguousarray(Kv, dtype=np.float64)
            fitness = np.empty(kp.shape[0])
            status = lib.vgt_ga_fitness(*head, kp.shape[0], _ptr(kp), _ptr(kv), _ptr(fitness))
            if status != DONE:
                raise MemoryError("the compiled GA fitness could not allocate its work arrays")
            assert fixed  # the bound arrays live as long as this function
            return fitness

        return predict
