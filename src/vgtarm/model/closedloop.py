"""Binding of the compiled closed-loop drivers (``csrc/closed_loop.c``) through ``csrc/vgtarm.h``.

This is the model layer's fast path for the simulation and for the genetic algorithm's
fitness: whole runs of computed force control, and whole batches of gain candidates, each in
one call into C. Layers above use :class:`ClosedLoopDriver` when the backend is compiled and
their NumPy reference implementation otherwise. Structures, status and integrator codes come
from the header (:mod:`.interface`); nothing of the C interface is repeated here.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from ..machine import threads_setting, usable_cpus
from .actuators import Actuators
from .compiled import CompiledBackend
from .interface import enum, ffi

if TYPE_CHECKING:
    from .recursive.backend import RecursiveBackend

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
PAUSED = _STATUS["VGT_PAUSED"]
#: Integrator codes by name (enum ``vgt_integrator`` of the header, ``VGT_RK4`` -> ``"rk4"``).
INTEGRATOR_CODES = {name.removeprefix("VGT_").lower(): code for name, code in enum("vgt_integrator").items()}

#: Observer codes by name (enum ``vgt_observer`` of the header, ``VGT_OBSERVER_MOMENTUM`` -> ``"momentum"``).
OBSERVER_CODES = {name.removeprefix("VGT_OBSERVER_").lower(): code for name, code in enum("vgt_observer").items()}

#: Estimator codes by name (enum ``vgt_estimator`` of the header, ``VGT_ESTIMATOR_KALMAN`` -> ``"kalman"``).
ESTIMATOR_CODES = {name.removeprefix("VGT_ESTIMATOR_").lower(): code for name, code in enum("vgt_estimator").items()}

#: The generated functions the loop calls, by field of ``vgt_model``.
_MODEL_FIELDS = ("cfc", "fd", "tip_state", "tip", "id", "jac", "tip_hessian")


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
    observer: str = "none"
    observer_gain: float = 0.0
    sensing: bool = False
    velocity_filter: float = 0.0
    estimator: str = "difference"
    kalman_gain: tuple[float, float, float] = (0.0, 0.0, 0.0)
    threshold_measured: bool = False
    tool_feedforward: bool = False
    #: the actuators (``LoopArrays``' ``force_limit``, ``speed_limit``, ``force_speed``): the controller
    #: clips its effort to the peak forces, the plant delivers it through the force-speed lines
    saturation: bool = False

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
                "observer": OBSERVER_CODES[self.observer],
                "observer_gain": self.observer_gain,
                "sensing": int(self.sensing),
                "velocity_filter": self.velocity_filter,
                "estimator": ESTIMATOR_CODES[self.estimator],
                "kalman_gain": list(self.kalman_gain),
                "threshold_measured": int(self.threshold_measured),
                "tool_feedforward": int(self.tool_feedforward),
                "saturation": int(self.saturation),
            },
        )


class LoopArrays:
    """The input and output arrays of one run, kept alive while C holds pointers to them.

    ``inputs`` holds the input arrays by the names of the fields of ``vgt_run`` (``vgtarm.h``),
    where the joint limits ``lower`` and ``upper`` are ``q_min`` and ``q_max``.
    """

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
        lower: Array,
        upper: Array,
        q0: Array,
        qd0: Array,
        resolution: Array | None = None,
        velocity_noise: Array | None = None,
        tool_force_expected: Array | None = None,
        actuators: Actuators | None = None,
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
                q_min=lower,
                q_max=upper,
                resolution=np.zeros(n_joints) if resolution is None else resolution,
                velocity_noise=np.zeros((n, n_joints)) if velocity_noise is None else velocity_noise,
                tool_force_expected=np.zeros((n, 3)) if tool_force_expected is None else tool_force_expected,
                # the actuators' limits (used with LoopSettings.saturation): none by default
                force_limit=np.full(n_joints, np.inf) if actuators is None else actuators.force,
                speed_limit=np.full(n_joints, np.inf) if actuators is None else actuators.speed,
                force_speed=np.zeros(n_joints) if actuators is None else actuators.force_speed.astype(float),
            ).items()
        }
        self.q = np.full((n, n_joints), np.nan)
        self.qd = np.full((n, n_joints), np.nan)
        self.q[0], self.qd[0] = q0, qd0
        self.F = np.full((n, n_joints), np.nan)
        self.f_ext = np.full((n, 3), np.nan)
        self.tip = np.full((n, 3), np.nan)
        self.error = np.full(n, np.nan)
        self.q_meas = np.full((n, n_joints), np.nan)
        self.qd_meas = np.full((n, n_joints), np.nan)
        self.tau_hat = np.full((n, n_joints), np.nan)
        #: the Kalman estimator's q^, v^, d^ and model acceleration (unused by the other estimator)
        self.x_hat = np.full((n, 4, n_joints), np.nan)
        #: the tip error the switching threshold was tested on, at each sample where it was (NaN elsewhere)
        self.seen = np.full(n, np.nan)
        fields = {name: _ptr(a) for name, a in self.inputs.items()}
        fields.update(
            q=_ptr(self.q),
            qd=_ptr(self.qd),
            F=_ptr(self.F),
            f_ext=_ptr(self.f_ext),
            tip=_ptr(self.tip),
            error=_ptr(self.error),
            q_meas=_ptr(self.q_meas),
            qd_meas=_ptr(self.qd_meas),
            tau_hat=_ptr(self.tau_hat),
            x_hat=_ptr(self.x_hat),
            seen=_ptr(self.seen),
        )
        self.struct = ffi().new("vgt_run *", {"n": n, **fields})


#: Wall time each compiled slice of a run aims at (s): Python handles Ctrl-C between two slices.
SLICE_SECONDS = 0.05
#: Work units (sub-steps integrated, samples controlled) of a run's first slice, before the
#: driver has measured how fast they go (about 30 ms of RK4 sub-steps on a slow machine).
FIRST_SLICE_BUDGET = 2_000
#: Bounds of the measured slice budget.
SLICE_BUDGET_RANGE = (100, 100_000_000)
#: Settings structures a driver keeps built (the safe variant's hold makes one per activation).
_SETTINGS_KEPT = 64


class ClosedLoopDriver:
    """The compiled closed loop of one backend.

    A run proceeds in slices of bounded work (``vgt_simulate_slice``), each about
    :data:`SLICE_SECONDS` long (the budget follows the measured speed), so Ctrl-C is handled
    between two slices; the results are the same, bit for bit, however the run is sliced.
    ``slice_budget`` fixes the work units per slice instead (the tests slice a run finely). The
    switching loop (:meth:`simulate_switching`) is called for as many samples as take about as
    long (it cannot pause inside a sample).
    """

    def __init__(self, backend: CompiledBackend | RecursiveBackend, *, slice_budget: int | None = None) -> None:
        if slice_budget is not None and not (isinstance(slice_budget, int) and slice_budget >= 1):
            raise ValueError(f"slice_budget = {slice_budget!r}: expected a whole number >= 1")
        self.backend = backend
        self._model = ffi().new("vgt_model *", {field: backend.call(field) for field in _MODEL_FIELDS})
        # a backend whose loop functions find their model by the parameter vector's address (the
        # recursive model's adapters) is told every vector before a driver sees it
        self._bind = getattr(backend, "bind_parameters", None)
        # a backend whose loop can use a run's gain matrices and margin rows beforehand (the recursive
        # model's fused step: their nonzero entries) is told them for each call, and untold after it
        self._run_arrays = getattr(backend, "bind_run", None)
        self._lib = backend.library
        self._settings: dict[tuple[LoopSettings, int, int], Any] = {}
        self.slice_budget = slice_budget
        self._budget = FIRST_SLICE_BUDGET
        self._slices: dict[int, tuple[Any, Array]] = {}
        self._switching_samples = 1  # samples of the next switching-loop call (follows the speed)
        #: Compiled calls made by :meth:`simulate` so far (a run's slices).
        self.slices = 0

    @property
    def model(self) -> Any:
        """The ``vgt_model`` structure (generated functions the drivers call)."""
        return self._model

    def simulate(
        self, settings: LoopSettings, arrays: LoopArrays, Kp: Array, Kv: Array, k0: int, k1: int
    ) -> tuple[int, int]:
        """Run samples ``k0 .. k1-1`` with gains ``Kp``, ``Kv`` (n x n); returns (status, stop sample)."""
        self.bind(arrays.inputs["p_plant"], arrays.inputs["p_ctrl"])
        key = (settings, arrays.n_joints, arrays.n_margins)
        s = self._settings.get(key)
        if s is None:  # the switching loop alternates two settings thousands of times: build each once
            if len(self._settings) >= _SETTINGS_KEPT:  # a held set's watch: one threshold per activation
                self._settings.clear()
            s = self._settings[key] = settings.struct(arrays.n_joints, arrays.n_margins)
        kp = np.ascontiguousarray(Kp, dtype=np.float64)
        kv = np.ascontiguousarray(Kv, dtype=np.float64)
        stop = ffi().new("long *")
        piece, _state = self._slice(arrays.n_joints)
        piece.substep = 0
        k = k0
        self._bind_run(kp, kv, arrays.inputs["G"])
        try:
            while True:
                budget = self.slice_budget or self._budget
                piece.budget = budget
                started = time.perf_counter()
                status = self._lib.vgt_simulate_slice(
                    self._model, s, arrays.struct, _ptr(kp), _ptr(kv), k, k1, stop, piece
                )
                elapsed = time.perf_counter() - started
                self.slices += 1
                if status == PAUSED or elapsed > 0.1 * SLICE_SECONDS:  # long enough to time
                    rate = piece.used / max(elapsed, 1e-9)
                    low, high = SLICE_BUDGET_RANGE
                    self._budget = int(min(max(rate * SLICE_SECONDS, low), high))
                if status != PAUSED:
                    return int(status), int(stop[0])
                k = int(stop[0])  # Ctrl-C raises KeyboardInterrupt here, between two slices
        finally:
            self._bind_run(None, None)

    def bind(self, *vectors: Array) -> None:
        """Tell the backend the parameter vectors the drivers are about to receive (if it asks)."""
        if self._bind is not None:
            self._bind(*vectors)

    def _bind_run(self, kp: Array | None, kv: Array | None, G: Array | None = None) -> None:
        if self._run_arrays is not None:
            self._run_arrays(kp, kv, G)

    def _slice(self, n_joints: int) -> tuple[Any, Array]:
        """The ``vgt_slice`` of runs of ``n_joints`` joints and the plant state it points at."""
        made = self._slices.get(n_joints)
        if made is None:
            state = np.zeros((2, n_joints))
            piece = ffi().new("vgt_slice *", {"q": _ptr(state[0]), "qd": _ptr(state[1])})
            made = self._slices[n_joints] = (piece, state)
        return made

    def simulate_switching(
        self,
        settings: LoopSettings,
        unswitched: LoopSettings,
        arrays: LoopArrays,
        Kp: Array,
        Kv: Array,
        ga: CompiledGA,
        k0: int,
        k1: int,
    ) -> tuple[int, int]:
        """Samples ``k0 .. k1-1`` under switching control with the GA in the loop (``csrc/ga.c``):
        the fixed gains ``Kp``, ``Kv`` below ``settings.threshold``; above it, one activation of
        ``ga`` (bound with :meth:`CompiledGA.bind_switching`) whose gains control that sample with
        ``unswitched``. Returns (status, stop sample); the activations are in ``ga``'s records."""
        self.bind(arrays.inputs["p_plant"], arrays.inputs["p_ctrl"], ga.parameters)
        structs = []
        for one in (settings, unswitched):
            key = (one, arrays.n_joints, arrays.n_margins)
            if key not in self._settings:
                self._settings[key] = one.struct(arrays.n_joints, arrays.n_margins)
            structs.append(self._settings[key])
        kp = np.ascontiguousarray(Kp, dtype=np.float64)
        kv = np.ascontiguousarray(Kv, dtype=np.float64)
        stop = ffi().new("long *")
        piece, _state = self._slice(arrays.n_joints)
        piece.substep = 0
        ga.switching.slice = piece
        ga.switching.pending = 0
        k = k0
        # in calls of about SLICE_SECONDS each (samples, and sub-steps within a sample, with the
        # loop's budget), so Ctrl-C is handled between two of them
        self._bind_run(kp, kv, arrays.inputs["G"])
        try:
            while True:
                k_end = min(k1, k + self._switching_samples)
                piece.budget = self.slice_budget or self._budget
                started = time.perf_counter()
                status = self._lib.vgt_simulate_switching(
                    self._model, structs[0], structs[1], arrays.struct, _ptr(kp), _ptr(kv), ga.switching, k, k_end, stop
                )
                elapsed = time.perf_counter() - started
                self.slices += 1
                if status == PAUSED:
                    k = int(stop[0])
                    continue
                if status != DONE or k_end == k1:
                    return int(status), int(stop[0])
                rate = (k_end - k) / max(elapsed, 1e-9)
                self._switching_samples = int(min(max(rate * SLICE_SECONDS, 1), 4 * self._switching_samples))
                k = k_end
        finally:
            self._bind_run(None, None)

    def ga_predictor(
        self,
        p_ctrl: Array,
        dt: float,
        q0: Array,
        qd0: Array,
        q_d: Array,
        qd_d: Array,
        qdd_d: Array,
        tip_d: Array,
        actuators: tuple[Array, Array, Array] | None = None,
    ) -> Callable[[Array, Array], Array]:
        """The GA's fitness for one state and reference window, bound once for many calls.

        ``q0``, ``qd0`` (n,): the state at sample k; ``q_d``, ``qd_d``, ``qdd_d`` (H+1, n) and
        ``tip_d`` (H+1, 3): the reference at samples k .. k+H; ``actuators``: ``(force, speed,
        line)`` the effort is clipped to (``vgt_ga_fitness_limited``), or ``None``. The returned
        function maps ``Kp``, ``Kv`` (P, n, n) to the predicted tip-error norms (P,).
        """
        fixed = [np.ascontiguousarray(a, dtype=np.float64) for a in (p_ctrl, q0, qd0, q_d, qd_d, qdd_d, tip_d)]
        limits = [np.ascontiguousarray(a, dtype=np.float64) for a in actuators] if actuators is not None else []
        self.bind(fixed[0])
        settings = ffi().new("vgt_settings *", {"n_joints": len(fixed[1]), "dt": dt})
        head = (self._model, settings, _ptr(fixed[0]), len(fixed[3]) - 1, *[_ptr(a) for a in fixed[1:]])
        head += tuple(_ptr(a) for a in limits) if limits else (ffi().NULL,) * 3
        lib = self._lib

        def predict(Kp: Array, Kv: Array) -> Array:
            kp = np.ascontiguousarray(Kp, dtype=np.float64)
            kv = np.ascontiguousarray(Kv, dtype=np.float64)
            fitness = np.empty(kp.shape[0])
            status = lib.vgt_ga_fitness_limited(*head, kp.shape[0], _ptr(kp), _ptr(kv), _ptr(fitness))
            if status != DONE:
                raise MemoryError("the compiled GA fitness could not allocate its work arrays")
            assert fixed and (limits or actuators is None)  # the bound arrays live as long as this function
            return fitness

        return predict


#: GA prediction modes by name (enum ``vgt_prediction`` of the header, ``VGT_PREDICT_LINEAR`` -> ``"linear"``).
PREDICTIONS = {name.removeprefix("VGT_PREDICT_").lower(): code for name, code in enum("vgt_prediction").items()}


def bit_words(n_bits_total: int) -> int:
    """64-bit words per packed individual of ``n_bits_total`` bits (one spare word, always zero)."""
    return -(-n_bits_total // 64) + 1


def pack_bits(bits: NDArray[np.uint8], words: int) -> NDArray[np.uint64]:
    """Rows of 0/1 bits ``(..., L)`` packed most significant bit first into ``(..., words)`` words."""
    packed = np.packbits(np.asarray(bits, dtype=np.uint8), axis=-1)
    padded = np.zeros(packed.shape[:-1] + (words * 8,), dtype=np.uint8)
    padded[..., : packed.shape[-1]] = packed
    return np.ascontiguousarray(padded.view(">u8").astype(np.uint64))


def unpack_bits(words: NDArray[np.uint64], n_bits_total: int) -> NDArray[np.uint8]:
    """Inverse of :func:`pack_bits`."""
    as_bytes = np.ascontiguousarray(np.asarray(words, dtype=np.uint64).astype(">u8")).view(np.uint8)
    return np.unpackbits(as_bytes, axis=-1, count=n_bits_total)


@dataclass(frozen=True)
class GAActivationResult:
    """What one compiled GA activation returns."""

    genes: Array
    best_cost: float
    seeded_cost: float
    generations: int
    evaluations: int
    exact_candidates: int = 0
    exact_steps: int = 0
    threads: int = 1  #: threads predicting at the end of the activation
    dropped: bool = False  #: safe variant: the fixed gains replaced the GA's best (see ``csrc/ga.c``)


#: Most threads the GA's prediction uses by default: a generation of the paper's GA predicts about
#: 40 children, five blocks of eight, so a fourth thread is the last that can shorten it.
MAX_GA_THREADS = 4


def ga_threads() -> int:
    """Threads of the compiled GA's prediction: ``$VGTARM_THREADS``, else the CPUs this process may
    use, at most :data:`MAX_GA_THREADS`. A study's workers set 1 (they already fill the CPUs)."""
    value = threads_setting()
    return value if value is not None else min(usable_cpus(), MAX_GA_THREADS)


def _ga_arrays(
    lower: Array,
    upper: Array,
    p_ctrl: Array,
    reference: dict[str, Array],
    quadratic: bool,
    actuators: tuple[Array, Array, Array] | None = None,
) -> dict[str, Array]:
    """The arrays the compiled GA reads and fills, C-contiguous float64: the gene bounds, the
    controller's parameters, the reference ``q_d, qd_d, qdd_d`` ``(N, n)`` and ``tip_d`` ``(N, 3)``,
    and room for the tip offsets ``(N, 3)``, Jacobians ``(N, 3, n)`` and, with ``quadratic``, Hessians
    ``(N, 3, n, n)`` at the reference (one element without); with ``actuators`` (peak force, no-load
    speed, force-speed line flags, each ``(n,)``) those and room for the model's effort ``(N, n)``,
    mass matrix, its inverse and the effort's velocity Jacobian ``(N, n, n)`` along the reference."""
    n, n_joints = np.shape(reference["q_d"])
    limited: dict[str, Any] = {}
    if actuators is not None:
        limited = dict(
            force_limit=actuators[0],
            speed_limit=actuators[1],
            force_speed=actuators[2],
            F_d=np.zeros((n, n_joints)),
            M_d=np.zeros((n, n_joints, n_joints)),
            Minv_d=np.zeros((n, n_joints, n_joints)),
            D_d=np.zeros((n, n_joints, n_joints)),
        )
    return {
        name: np.ascontiguousarray(value, dtype=np.float64)
        for name, value in dict(
            lower=lower,
            upper=upper,
            p_ctrl=p_ctrl,
            **reference,
            tip_offset=np.zeros((n, 3)),
            J_d=np.zeros((n, 3, n_joints)),
            H_d=np.zeros((n, 3, n_joints, n_joints) if quadratic else 1),
            **limited,
        ).items()
    }


class GASearchOptions(Protocol):
    """The settings of the GA's search the compiled GA reads (:class:`vgtarm.ga.GAOptions`)."""

    @property
    def n_bits(self) -> int: ...
    @property
    def population_size(self) -> int: ...
    @property
    def max_generations(self) -> int: ...
    @property
    def crossover_probability(self) -> float: ...
    @property
    def mutation_probability(self) -> float: ...
    @property
    def elite_count(self) -> int: ...


class SwitchingRecord(Protocol):
    """What the compiled GA reads of switching control's record (:class:`vgtarm.control.SwitchingControl`):
    the GA's settings, the prediction, and the genes' bounds and seeded rows."""

    @property
    def ga(self) -> GASearchOptions: ...
    @property
    def horizon(self) -> int: ...
    @property
    def prediction(self) -> str: ...
    @property
    def exact_above(self) -> float: ...

    def bounds(self) -> tuple[Array, Array]: ...

    def initial_bits(self) -> NDArray[np.uint8]: ...


class CompiledGA:
    """The switching method's genetic algorithm in C (``csrc/ga.c``), bound to one run.

    Args:
        driver: the compiled loop of the backend.
        switching: the switching method's record (:class:`vgtarm.control.SwitchingControl`): its
            GA's settings (``ga``), ``horizon`` (control periods), ``prediction`` (``"exact"``,
            ``"linear"`` or ``"quadratic"``, see ``csrc/ga.c``; ``"quadratic"`` needs the tip
            Hessian), ``exact_above`` (joint-error norm above which a candidate is predicted
            exactly; 0: never), the genes' ``bounds()`` (``Kp`` then ``Kv``, row by row) and
            ``initial_bits()`` (0/1 rows that start the first population).
        dt: control period (s).
        p_ctrl: the controller's parameter vector.
        reference: ``q_d, qd_d, qdd_d`` ``(N, n)`` joint reference and ``tip_d`` ``(N, 3)`` desired
            tip. The tip offsets ``tip_d - P^(q_d)`` and the model's tip Jacobian and Hessian at
            ``q_d`` are computed in C, row by row, the first time an activation's window needs them
            (``ensure_rows`` in ``csrc/ga.c``).
        threads: threads that predict a generation's candidates (default :func:`ga_threads`);
            any count gives the same activation bit for bit.
        safe: ``(kv, lo, hi)`` for the safe variant of switching control (``Kp`` symmetrised, ``Kv
            = kv I``, admitted iff the eigenvalues of ``Kp`` lie in ``[lo, hi]``); ``None``: the
            paper's GA.
        damping: with ``safe``, ``(step, lo, hi)``: the damping is tuned on the grid ``j step`` with
            the admitted interval ``[lo[j], hi[j]]`` of each grid point (``SwitchingControl.
            damping_table``); ``None``: ``Kv = kv I`` held.
        actuators: ``(force, speed, line)``, each ``(n,)``: the peak forces, no-load speeds and
            force-speed line flags (1 or 0) the prediction clips the effort to, as the run's
            controller and plant do (``LoopSettings.saturation``); ``None``: no actuators.
    """

    def __init__(
        self,
        driver: ClosedLoopDriver,
        switching: SwitchingRecord,
        *,
        dt: float,
        p_ctrl: Array,
        reference: dict[str, Array],
        threads: int | None = None,
        safe: tuple[float, float, float] | None = None,
        damping: tuple[float, tuple[float, ...], tuple[float, ...]] | None = None,
        actuators: tuple[Array, Array, Array] | None = None,
    ) -> None:
        prediction = switching.prediction
        if prediction not in PREDICTIONS:
            raise ValueError(f"prediction = {prediction!r}: expected one of {sorted(PREDICTIONS)}")
        self.driver = driver
        n, n_joints = np.shape(reference["q_d"])
        lower, upper = switching.bounds()
        n_genes = len(lower)
        options = switching.ga
        self.n_joints, self.n_genes, self.n = n_joints, n_genes, n
        self.horizon = switching.horizon
        words = bit_words(n_genes * options.n_bits)
        quadratic = prediction == "quadratic"
        rows = {name: reference[name] for name in ("q_d", "qd_d", "qdd_d", "tip_d")}
        self._arrays = _ga_arrays(lower, upper, p_ctrl, rows, quadratic, actuators)
        self._ready = np.zeros(n, dtype=np.uint8)  # rows whose tip derivatives ga.c has computed
        self._initial = pack_bits(np.atleast_2d(switching.initial_bits()), words)
        self._settings = ffi().new("vgt_settings *", {"n_joints": n_joints, "dt": dt})
        self._ga = ffi().new(
            "vgt_ga_settings *",
            {
                "n_genes": n_genes,
                "n_bits": options.n_bits,
                "words": words,
                "population": options.population_size,
                "generations": options.max_generations,
                "elite": options.elite_count,
                "n_seeded": len(self._initial),
                "prediction": PREDICTIONS[prediction],
                "p_crossover": options.crossover_probability,
                "p_mutation": options.mutation_probability,
                "horizon": switching.horizon,
                "exact_above": switching.exact_above,
                "threads": ga_threads() if threads is None else threads,
                **({"safe": 1, "safe_kv": safe[0], "safe_lo": safe[1], "safe_hi": safe[2]} if safe is not None else {}),
            },
        )
        if safe is not None and damping is not None:
            self._bind_damping(damping)
        self._best = np.empty(n_genes)
        self._state = np.empty((2, n_joints))
        self._result = ffi().new("vgt_ga_result *", {"best": _ptr(self._best)})
        self._bind_problem(quadratic)

    def _bind_damping(self, damping: tuple[float, tuple[float, ...], tuple[float, ...]]) -> None:
        """The safe variant's damping grid ``(step, lo, hi)`` in the GA's settings."""
        self._damping = np.ascontiguousarray([damping[1], damping[2]], dtype=np.float64)
        self._ga.safe_nkv = self._damping.shape[1]
        self._ga.safe_kv_step = damping[0]
        self._ga.safe_lo_tab = _ptr(self._damping[0])
        self._ga.safe_hi_tab = _ptr(self._damping[1])

    def _bind_problem(self, quadratic: bool) -> None:
        """The ``vgt_ga_problem`` structure pointing into the arrays (the bounds, the seeded rows,
        the controller's parameters, the start state), the reference's rows from sample 0 and each
        row's length, by which :meth:`_window` moves them."""
        n_joints = self.n_joints
        self._problem = ffi().new("vgt_ga_problem *")
        self._problem.lower = _ptr(self._arrays["lower"])
        self._problem.upper = _ptr(self._arrays["upper"])
        self._problem.initial_bits = ffi().cast("uint64_t *", self._initial.ctypes.data)
        self._problem.p_ctrl = _ptr(self._arrays["p_ctrl"])
        self.driver.bind(self._arrays["p_ctrl"])
        self._problem.q0 = _ptr(self._state[0:1])
        self._problem.qd0 = ffi().cast("double *", self._state[1:2].ctypes.data)
        self._base = {name: _ptr(self._arrays[name]) for name in ("q_d", "qd_d", "qdd_d", "tip_d", "tip_offset", "J_d")}
        self._base["H_d"] = _ptr(self._arrays["H_d"])
        self._base["ready"] = ffi().cast("unsigned char *", self._ready.ctypes.data)
        self._row = {"q_d": n_joints, "qd_d": n_joints, "qdd_d": n_joints, "tip_d": 3, "tip_offset": 3}
        self._row["J_d"] = 3 * n_joints
        self._row["H_d"] = 3 * n_joints * n_joints if quadratic else 0
        self._row["ready"] = 1
        if "force_limit" in self._arrays:  # the actuators: their limits, and rows moved as the others
            for name in ("force_limit", "speed_limit", "force_speed"):
                setattr(self._problem, name, _ptr(self._arrays[name]))
            for name, length in (
                ("F_d", n_joints),
                ("M_d", n_joints**2),
                ("Minv_d", n_joints**2),
                ("D_d", n_joints**2),
            ):
                self._base[name] = _ptr(self._arrays[name])
                self._row[name] = length

    def _window(self, k: int, q0: Array, qd0: Array) -> int:
        """Point the problem at samples ``k .. k+h``; returns the horizon ``h`` left."""
        horizon = min(self.horizon, self.n - 1 - k)
        self._state[0], self._state[1] = q0, qd0
        for name, base in self._base.items():
            setattr(self._problem, name, base + k * self._row[name])
        self._ga.horizon = horizon
        return horizon

    @property
    def parameters(self) -> Array:
        """The controller's parameter vector the GA's predictions use (the array the drivers see)."""
        return self._arrays["p_ctrl"]

    def activate(self, k: int, q0: Array, qd0: Array, seed: int) -> GAActivationResult:
        """Run one activation at sample ``k`` from the state ``(q0, qd0)`` with the generator's ``seed``."""
        self._window(k, q0, qd0)
        self.driver.bind(self.parameters)
        status = self.driver.backend.library.vgt_ga_activation(
            self.driver.model, self._settings, self._ga, self._problem, seed, self._result
        )
        if status != DONE:
            raise MemoryError("the compiled genetic algorithm could not allocate its work arrays")
        return GAActivationResult(
            genes=self._best.copy(),
            best_cost=float(self._result.best_cost),
            seeded_cost=float(self._result.seeded_cost),
            generations=int(self._result.generations),
            evaluations=int(self._result.evaluations),
            exact_candidates=int(self._result.exact_candidates),
            exact_steps=int(self._result.exact_steps),
            threads=int(self._result.threads),
            dropped=bool(self._result.dropped),
        )

    def bind_switching(self, seeds: NDArray[np.int64], hold: int = 1, watch_from: int = 2) -> None:
        """Prepare switching control in the loop (:meth:`ClosedLoopDriver.simulate_switching`):
        ``seeds`` are the generator seeds of the GA activations in order, one each, and bound the
        activations recorded (the loop returns when the records are full); an admitted gain set
        controls ``hold`` periods from its activation (1: that sample only, the paper's) unless the
        error seen at one of them, from period ``watch_from`` on (the activation's sample is period
        0; ``hold`` or more: never), exceeds the one seen at the activation: the set is then dropped
        there for the fixed gains."""
        capacity = len(seeds)
        # 1 at the samples a held set controlled, 2 where one was dropped for the fixed gains
        self.held = np.zeros(self.n, dtype=np.uint8)
        self._seeds = np.ascontiguousarray(np.asarray(seeds, dtype=np.int64).view(np.uint64))
        self._records: dict[str, NDArray[Any]] = {
            **{n: np.zeros(capacity, dtype=np.int64) for n in ("sample", "generations", "evaluations", "threads")},
            **{name: np.zeros(capacity) for name in ("best_cost", "seeded_cost", "wall_time")},
        }
        self._switch_work = np.zeros(2 * self.n_joints + self.n_genes)
        base = ffi().new("vgt_ga_problem *", self._problem[0])  # bounds, seeded rows, parameters
        for name, pointer in self._base.items():  # the reference from sample 0
            setattr(base, name, pointer)
        work = self._switch_work
        self._switching = ffi().new(
            "vgt_switching *",
            {
                "g": self._ga,
                "pb": base,
                "seeds": ffi().cast("uint64_t *", self._seeds.ctypes.data),
                "max_activations": capacity,
                **{name: _ptr(a) for name, a in self._records.items() if a.dtype == np.float64},
                **{n: ffi().cast("long *", a.ctypes.data) for n, a in self._records.items() if a.dtype == np.int64},
                "q0": _ptr(work),
                "qd0": ffi().cast("double *", work[self.n_joints :].ctypes.data),
                "best": ffi().cast("double *", work[2 * self.n_joints :].ctypes.data),
                "backoff": 1,
                "hold": hold,
                "watch_from": watch_from,
                "held": ffi().cast("unsigned char *", self.held.ctypes.data),
            },
        )
        self._switch_base = base  # the struct points into it: keep it alive

    @property
    def switching(self) -> Any:
        """The ``vgt_switching`` structure (after :meth:`bind_switching`)."""
        return self._switching

    def records(self, first: int, last: int) -> dict[str, NDArray[Any]]:
        """Copies of the in-loop activation records ``first .. last-1``."""
        return {name: array[first:last].copy() for name, array in self._records.items()}

    def predict(self, k: int, q0: Array, qd0: Array, genes: Array) -> Array:
        """The GA's predicted tip error of decoded candidates ``genes`` ``(P, n_genes)`` at sample ``k``."""
        self._window(k, q0, qd0)
        g = np.ascontiguousarray(np.atleast_2d(genes), dtype=np.float64)
        cost = np.empty(len(g))
        self.driver.bind(self.parameters)
        status = self.driver.backend.library.vgt_ga_predict(
            self.driver.model, self._settings, self._ga, self._problem, len(g), _ptr(g), _ptr(cost)
        )
        if status != DONE:
            raise MemoryError("the compiled GA prediction could not allocate its work arrays")
        return cost
