"""ctypes binding of the compiled closed-loop drivers (``csrc/closed_loop.c``).

This is the model layer's fast path for the simulation and for the genetic algorithm's
fitness: whole runs of computed force control, and whole batches of gain candidates, each in
one call into C. Layers above use :class:`ClosedLoopDriver` when the backend is compiled and
their NumPy reference implementation otherwise.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .compiled import CompiledBackend

Array = NDArray[np.float64]
_double_p = ctypes.POINTER(ctypes.c_double)

#: Status codes of ``vgt_simulate``.
DONE, ABOVE_THRESHOLD, NOT_FINITE, NOT_ASSEMBLABLE, OUTSIDE_LIMITS, FUNCTION_FAILED, NO_MEMORY = (
    0,
    1,
    -1,
    -2,
    -3,
    -4,
    -5,
)
INTEGRATOR_CODES = {"euler": 0, "semi_implicit_euler": 1, "rk4": 2}


class _Call(ctypes.Structure):
    _fields_ = [
        ("f", ctypes.c_void_p),
        ("sz_arg", ctypes.c_longlong),
        ("sz_res", ctypes.c_longlong),
        ("sz_iw", ctypes.c_longlong),
        ("sz_w", ctypes.c_longlong),
    ]


class _Model(ctypes.Structure):
    _fields_ = [("cfc", _Call), ("fd", _Call), ("tip_state", _Call), ("tip", _Call)]


class _Settings(ctypes.Structure):
    _fields_ = [
        ("dt", ctypes.c_double),
        ("integrator", ctypes.c_int),
        ("substeps", ctypes.c_int),
        ("cutting", ctypes.c_int),
        ("cutting_force", ctypes.c_double),
        ("cutting_speed", ctypes.c_double),
        ("threshold", ctypes.c_double),
        ("limit_tolerance", ctypes.c_double),
    ]


class _Run(ctypes.Structure):
    _fields_ = [("n", ctypes.c_long)] + [
        (name, _double_p)
        for name in (
            "q_d",
            "qd_d",
            "qdd_d",
            "tip_d",
            "disturbance",
            "p_plant",
            "p_ctrl",
            "G",
            "h",
            "q_min",
            "q_max",
            "q",
            "qd",
            "F",
            "f_ext",
            "tip",
            "error",
        )
    ]


def _ptr(array: Array) -> ctypes._Pointer[ctypes.c_double]:
    if array.dtype != np.float64 or not array.flags.c_contiguous:
        raise ValueError("closed-loop arrays must be C-contiguous float64")
    return array.ctypes.data_as(_double_p)


@dataclass(frozen=True)
class LoopSettings:
    """Settings of one closed-loop run (see ``vgt_settings`` in ``closed_loop.c``)."""

    dt: float
    integrator: str
    substeps: int
    cutting: bool
    cutting_force: float
    cutting_speed: float
    threshold: float
    limit_tolerance: float


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
        n = len(q_d)
        self.n = n
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
        self.q = np.full((n, 7), np.nan)
        self.qd = np.full((n, 7), np.nan)
        self.q[0], self.qd[0] = q0, qd0
        self.F = np.full((n, 7), np.nan)
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
        self.struct = _Run(n=n, **fields)


class ClosedLoopDriver:
    """The compiled closed loop of one backend."""

    def __init__(self, backend: CompiledBackend) -> None:
        self.backend = backend
        calls = {}
        for field, name in (("cfc", "cfc"), ("fd", "fd"), ("tip_state", "tip_state"), ("tip", "tip")):
            sig = backend.signature(name)
            calls[field] = _Call(backend.function_pointer(name), sig.sz_arg, sig.sz_res, sig.sz_iw, sig.sz_w)
        self._model = _Model(**calls)
        self._simulate = backend.library.vgt_simulate
        self._simulate.restype = ctypes.c_int
        self._fitness = backend.library.vgt_ga_fitness
        self._fitness.restype = ctypes.c_int
        vp, long_ = ctypes.c_void_p, ctypes.c_long
        self._fitness.argtypes = [vp, vp, ctypes.c_double, long_, vp, vp, vp, vp, vp, vp, long_, vp, vp, vp]

    def simulate(
        self, settings: LoopSettings, arrays: LoopArrays, Kp: Array, Kv: Array, k0: int, k1: int
    ) -> tuple[int, int]:
        """Run samples ``k0 .. k1-1`` with gains ``Kp``, ``Kv`` (7x7); returns (status, stop sample)."""
        s = _Settings(
            dt=settings.dt,
            integrator=INTEGRATOR_CODES[settings.integrator],
            substeps=settings.substeps,
            cutting=int(settings.cutting),
            cutting_force=settings.cutting_force,
            cutting_speed=settings.cutting_speed,
            threshold=settings.threshold,
            limit_tolerance=settings.limit_tolerance,
        )
        kp = np.ascontiguousarray(Kp, dtype=np.float64)
        kv = np.ascontiguousarray(Kv, dtype=np.float64)
        stop = ctypes.c_long(0)
        status = self._simulate(
            ctypes.byref(self._model),
            ctypes.byref(s),
            ctypes.byref(arrays.struct),
            _ptr(kp),
            _ptr(kv),
            ctypes.c_long(k0),
            ctypes.c_long(k1),
            ctypes.byref(stop),
        )
        return int(status), int(stop.value)

    def ga_predictor(
        self, p_ctrl: Array, dt: float, q0: Array, qd0: Array, q_d: Array, qd_d: Array, qdd_d: Array, tip_d: Array
    ) -> Callable[[Array, Array], Array]:
        """The GA's fitness for one state and reference window, bound once for many calls.

        ``q0``, ``qd0`` (7,): the state at sample k; ``q_d``, ``qd_d``, ``qdd_d`` (H+1, 7) and
        ``tip_d`` (H+1, 3): the reference at samples k .. k+H. The returned function maps
        ``Kp``, ``Kv`` (n, 7, 7) to the predicted tip-error norms (n,).
        """
        fixed = [np.ascontiguousarray(a, dtype=np.float64) for a in (p_ctrl, q0, qd0, q_d, qd_d, qdd_d, tip_d)]
        head = (
            ctypes.byref(self._model),
            fixed[0].ctypes.data,
            ctypes.c_double(dt),
            len(fixed[3]) - 1,
            *[a.ctypes.data for a in fixed[1:]],
        )

        def predict(Kp: Array, Kv: Array) -> Array:
            kp = np.ascontiguousarray(Kp, dtype=np.float64)
            kv = np.ascontiguousarray(Kv, dtype=np.float64)
            fitness = np.empty(kp.shape[0])
            status = self._fitness(*head, kp.shape[0], kp.ctypes.data, kv.ctypes.data, fitness.ctypes.data)
            if status != DONE:
                raise MemoryError("the compiled GA fitness could not allocate its work arrays")
            assert fixed  # the bound arrays live as long as this function
            return fitness

        return predict
