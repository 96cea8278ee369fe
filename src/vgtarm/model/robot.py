"""The user-facing robot: parameters plus the compiled model, with batch-first methods.

Every method takes arrays whose last axis is the joint (or force) vector and broadcasts over the
leading axes: ``q`` of shape ``(..., n)`` gives results of shape ``(..., ...)``, ``n`` the robot's
number of joints (7 for the paper's robot, :attr:`Robot.n_joints`). One call on a batch runs one
compiled loop, so prefer batches to Python loops over single configurations. One state given as
1-D float64 arrays takes a shorter path (``Robot._call``: the same checks and the same
numbers, the compiled function called directly): a few microseconds a call.

A robot is the paper's (:class:`RobotParameters`, the fixed 7-joint model) or any stack of modules
(:class:`~vgtarm.model.stack.Stack`, read by :func:`load_robot` from a file with ``[[modules]]``
tables): both go through the same code generation and compiled backend, a stack with a library of
its own per structure (:mod:`vgtarm.model.definition`).
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ConfigError, InputError, cut, shown
from ..fileio import parse_toml, read_text_limited
from ..kinds import other_toml
from ..machine import blas_on_one_thread
from ..markup import html_table
from ..memory import check_batch, limit_variable_set
from .actuators import Actuators, check_holding
from .assembly import check_margins
from .backends import checked_single_call, single_call
from .compiled import Backend, CompiledBackend, InterpretedBackend, get_backend
from .definition import PAPER, Definition, StackDefinition
from .parameters import ROBOT_FILE_LIMIT, JointStiffness, RobotParameters, load_parameters, parameters_from_dict
from .recursive.backend import RecursiveBackend
from .sanity import (
    FORCE_NAMES,
    RANGE_REASONS,
    as_float,
    check_input,
    check_joint_range,
    finite,
    input_ranges,
    input_units,
    real_array,
)
from .stack.description import Stack, stack_from_dict

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ForwardKinematics:
    """Forward kinematics of a batch of configurations (leading shape ``S``).

    Attributes (``m`` modules: 2 for the paper's robot):
        passive: ``S + (m, 4)`` passive angles ``(alpha, beta, gamma, theta)`` of each module (rad).
        platform_position: ``S + (m, 3)`` platform centres O1, O2, ... in F0 (m).
        platform_rotation: ``S + (m, 3, 3)`` orientations C01, C02, ... of the platform frames.
        tip: ``S + (3,)`` tip point P in F0 (m).
        rotation: ``S + (3, 3)`` end-effector orientation C03.
    """

    passive: Array
    platform_position: Array
    platform_rotation: Array
    tip: Array
    rotation: Array


@dataclass(frozen=True)
class BiasAccelerations:
    """Velocity-product ("bias") accelerations, i.e. accelerations when ``qdd = 0``.

    Attributes:
        tip: ``S + (3,)`` of the tip point (m/s^2), so ``a_tip = J_P qdd + tip``.
        angular: ``S + (3,)`` of the end-effector frame (rad/s^2).
        com: ``S + (b, 3)`` of each body's centre of mass (the paper's bodies 7, 8, 9; a stack's
            in the order of its ``body_names``).
        body_angular: ``S + (b, 3)`` of each body frame.
    """

    tip: Array
    angular: Array
    com: Array
    body_angular: Array


#: Per row of a batch, the bytes of the checks' temporaries for each triangle margin row.
_MARGIN_BYTES = 17
#: A result that is not finite is blamed on ``q`` if a triangle margin is below this (m: the model is
#: singular where a module cannot be assembled), else on an input above this fraction of its bound.
_SINGULAR_MARGIN = 1e-6
_LARGE_INPUT = 1e-3
#: Size (rows x joints x margin rows) from which the margin check's product ``q @ G.T`` runs with
#: NumPy's BLAS held to one thread. OpenBLAS splits a product above 262,144 multiply-adds over its
#: threads (a 10-module arm's batch of 2,000: 4.2 million), which then spin for a while after it:
#: through the Robot, a batch of the recursive model's forward dynamics burned a second core for
#: nothing (13.7 us CPU a state for 6.9 us wall, against 6.4 us each for the model alone) and took
#: twice the wall time when another process held a core. One thread gives the same product bit
#: for bit (OpenBLAS splits the rows and columns of the result, never its sums); the limit costs
#: about 10 us, so a product OpenBLAS keeps on one thread anyway skips it.
_BLAS_THREADED_PRODUCT = 262144


#: One part of a method's result: the indices of the outputs of its compiled function that make it
#: (several: stacked on a new axis after the leading ones) and its shape after the leading ones.
Piece = tuple[tuple[int, ...], tuple[int, ...]]


class _Spec(NamedTuple):
    """What a method of :class:`Robot` evaluates: the compiled function, its inputs ``(argument, size of
    the last axis)`` in the function's order (``q`` first), the floats it creates per row (for the
    memory estimate, :meth:`Robot._arrays`) and the pieces of its result."""

    function: str
    inputs: tuple[tuple[str, int], ...]
    outputs: int
    pieces: tuple[Piece, ...]


#: The tip force of a method called without one.
_NO_TIP_FORCE = np.zeros(3)
_NO_TIP_FORCE.flags.writeable = False
_COPY = np.ndarray.copy
#: Outputs of at most this many elements are checked finite by their sum (:func:`_all_finite`).
_SUMMED = 24
_SUBTRACT = np.subtract
_FLOAT = np.dtype(np.float64)
_NDARRAY = np.ndarray
#: A triangle margin the single-state check computes is trusted from this fraction of the sizes of
#: its terms (the joints' accepted bounds and the offset ``h``) up: its sum is taken in any order
#: (BLAS; the C driver ``csrc/single.c`` term after term), the batch path's as ``(G q) + h``, and
#: the two differ by a few units of the last place (2**-52) of those sizes times the number of
#: terms at most (a few thousand joints would still be far from 2**12 units). A margin below it
#: (1e-12 m for the paper's legs) goes the batch path, which decides as it always has.
_MARGIN_TRUST = 2.0**-40


class _SingleState:
    """One method of a :class:`Robot` for one state, at the speed of its compiled call (issue 35).

    It serves only 1-D float64 arrays (``numpy.ndarray`` itself) of the right length, copies them
    into its own buffer and runs the same checks as the batch path, in the same order: the memory
    estimate (only when ``$VGTARM_MEMORY_LIMIT`` is set, in Python), then every input finite and
    inside :meth:`Robot.input_ranges`, the triangle margins of ``q`` above zero, the function's
    status and every output finite, all in one C call on the compiled backend
    (:func:`~vgtarm.model.backends.checked_single_call`), as a few whole-array operations on the
    others (:func:`_checked`). When any check fails (or is not conclusive: a margin within
    :data:`_MARGIN_TRUST`), or for any other input (lists, other types, batches), it gives None
    and the method takes the batch path, which refuses the input with its message or gives its
    result. Its numbers are the batch path's bit for bit: the same function on the same inputs.

    The buffers of one call (a frame: the inputs between their bounds, the outputs, the work arrays)
    are taken from a free list and put back after the call, so threads (a cffi call releases the
    GIL) never share one.
    """

    __slots__ = (
        "backend",
        "bounds",
        "frames",
        "function",
        "margins",
        "method",
        "n",
        "p",
        "shapes",
        "spec",
        "_row_bytes",
    )

    def __init__(self, robot: Robot, method: str, spec: _Spec) -> None:
        self.backend, self.method, self.function, self.spec = robot.backend, method, spec.function, spec
        sizes = [size for _, size in spec.inputs]
        self.shapes = tuple((size,) for size in sizes)
        self.p, self.n = robot._p.copy(), robot.n_joints
        # the inputs one after the other behind a 1 (x) and its bounds [low, x, high]
        low = np.concatenate([[1.0], *(robot._ranges[label][0] for label, _ in spec.inputs)])
        high = np.concatenate([[1.0], *(robot._ranges[label][1] for label, _ in spec.inputs)])
        self.bounds = (low, high)
        self.margins = robot._trusted_margins()
        self._row_bytes = 8 * spec.outputs + _MARGIN_BYTES * robot._G.shape[0] + 3 * sum(sizes)
        self.frames: list[tuple[Any, ...]] = [self.frame()]

    def frame(self) -> tuple[Any, ...]:
        """The buffers of one call: the inputs' views of ``x`` (a 1, then the inputs one after the
        other, held in ``[low, x, high]``), the checked call (returns 0 when the result stands) and the
        views of the outputs that make the pieces."""
        low, high = self.bounds
        k = len(low)
        bounded = np.concatenate([low, np.empty(k), high])
        x = bounded[k : 2 * k]
        x[0] = 1.0  # the factor of the margins' offsets, between bounds [1, 1]; never written again
        sig = self.backend.signature(self.function)
        offsets = np.cumsum((1, *(size for _, size in self.spec.inputs))).tolist()
        inputs = [x[a:b] for a, b in zip(offsets[:-1], offsets[1:], strict=True)]
        outputs = np.empty(sum(sig.nnz_out))
        if not outputs.size:
            raise ValueError(f"{self.function} has no outputs")
        run = checked_single_call(self.backend, self.function, [*inputs, self.p], outputs, bounded, self.margins)
        if run is None:  # no C driver (CasADi's interpreter, the recursive model): the checks in NumPy
            call = single_call(self.backend, self.function, [*inputs, self.p], outputs)
            above, below, q = bounded[k:], bounded[: 2 * k], x[: 1 + self.n]
            run = partial(_checked, above, below, q, np.empty(2 * k), self.margins, call, outputs)
        pieces = tuple(_piece(outputs, sig.nnz_out, piece) for piece in self.spec.pieces)
        return inputs, run, pieces

    def row_bytes(self, arrays: tuple[Array, ...]) -> int:
        """The batch path's estimate of a row (:meth:`Robot._arrays`) for these float64 arrays."""
        return self._row_bytes + sum(8 * a.size for a in arrays if not a.flags.c_contiguous)

    def __call__(self, arrays: tuple[Any, ...]) -> tuple[Array, ...] | None:
        """The pieces of the result for ``arrays`` (one per input), or None: take the batch path."""
        frames = self.frames
        frame = frames.pop() if frames else self.frame()
        views, run, pieces = frame
        # one array per input, as the methods pass them (not strict: a strict zip costs 0.1 us)
        for view, shape, array in zip(views, self.shapes, arrays, strict=False):
            # numpy's own float64 (not a subclass such as a masked array), 1-D of the right length;
            # copied into the frame at once (a slice assignment each: cheaper than a concatenate, or
            # than handing the C driver each array's pointer through cffi's from_buffer)
            if type(array) is not _NDARRAY or array.shape != shape or array.dtype is not _FLOAT:
                frames.append(frame)
                return None
            view[...] = array
        if limit_variable_set():  # checked after the types, as the batch path does
            try:
                check_batch(1, self.row_bytes(arrays), self.method)
            except BaseException:
                frames.append(frame)
                raise
        result = None
        if not run():
            result = (pieces[0].copy(),) if len(pieces) == 1 else tuple(map(_COPY, pieces))
        frames.append(frame)
        return result


def _checked(above: Array, below: Array, q: Array, differences: Array, margins: Array, call: Any, y: Array) -> int:
    """The checks of ``vgt_single_call`` (``csrc/single.c``) in NumPy, around ``call``: 0 when every
    input lies inside its bounds (``above`` ``[x, high]`` less ``below`` ``[low, x]``, >= 0), every
    trusted margin ``margins @ q`` (``[1, q]``) >= 0, the call returned 0 and every output ``y`` is
    finite; else 1."""
    _SUBTRACT(above, below, out=differences)  # x - low, high - x: >= 0 exactly when inside
    if differences.item(differences.argmin()) >= 0.0:  # a NaN is the argmin and fails
        found = margins.dot(q)  # only now: finite inputs inside their bounds cannot overflow
        if found.item(found.argmin()) >= 0.0 and not call() and _all_finite(y):
            return 0
    return 1


def _all_finite(y: Array) -> bool:
    """Whether every element of the 1-D ``y`` is finite, without a floating-point warning: the sum of
    a few elements as Python floats (not finite if one is not; a finite sum that overflows only sends
    the call to the batch path), else the smallest and largest (a NaN is both)."""
    if len(y) <= _SUMMED:
        return math.isfinite(sum(y.tolist()))
    return math.isfinite(y.item(y.argmin())) and math.isfinite(y.item(y.argmax()))


def _piece(outputs: Array, sizes: tuple[int, ...], piece: Piece) -> Array:
    """The view of ``outputs`` (every output of a function one after the other, ``sizes``) that holds
    one piece of a result for one state: one output, or equal outputs at equal spacing stacked."""
    indices, shape = piece
    starts = np.cumsum((0, *sizes)).tolist()
    first, size = starts[indices[0]], sizes[indices[0]]
    step = starts[indices[1]] - first if len(indices) > 1 else size
    if any(sizes[i] != size or starts[i] != first + k * step for k, i in enumerate(indices)):
        raise ValueError(f"outputs {indices} are not equal outputs at equal spacing")
    rows = np.lib.stride_tricks.as_strided(outputs[first:], shape=(len(indices), size), strides=(8 * step, 8))
    view = rows.reshape(shape)
    if not np.shares_memory(view, outputs):
        raise ValueError(f"outputs {indices} do not make a view of shape {shape}")
    return view


def definition_of(parameters: RobotParameters | Stack) -> Definition:
    """The model whose compiled functions serve ``parameters``: the paper's, or a stack's structure."""
    if isinstance(parameters, RobotParameters):
        return PAPER
    if isinstance(parameters, Stack):
        return StackDefinition.of(parameters)
    raise InputError(f"parameters = {shown(parameters)}: expected RobotParameters or a Stack (see vgtarm.load_robot)")


class Robot:
    """A manipulator model: :class:`RobotParameters` (the paper's robot) or a
    :class:`~vgtarm.model.stack.Stack` evaluated through the compiled backend.

    Build one with :func:`load_robot`. ``robot.with_parameters(p)`` gives a robot with other
    parameters sharing the same compiled code (for example a controller's imperfect model; for a
    stack, a stack of the same structure).

    Every method refuses, with one :class:`~vgtarm.errors.InputError` line naming the argument,
    the element and the user's value (:mod:`vgtarm.model.sanity`):

    - arrays that are not real numbers (complex values, even with a zero imaginary part;
      booleans, ``None``, text) or of the wrong shape, and leading shapes that do not broadcast;
    - values that are not finite or lie outside :meth:`input_ranges`: joint values ``q`` outside
      :meth:`joint_range` (lengths within ten spans of their limits and >= 0, angles within 1000
      turns), rates ``qd`` beyond a million spans of the limits per second, accelerations ``qdd``
      beyond that rate reached in a microsecond, efforts ``F`` and the tip force ``f_tip`` beyond
      1e12 N (N m);
    - a batch whose estimated memory exceeds what the machine has (or ``$VGTARM_MEMORY_LIMIT``),
      before anything is allocated, naming the rows, the estimate and the limit;
    - a result that is still not finite, naming the input that drove it (a configuration at the
      edge of assembly, for example);

    and, with :class:`~vgtarm.errors.AssemblyError`, leg sets that cannot be assembled. A batch of
    zero rows gives empty results.

    Kinematics: :meth:`forward_kinematics` (passive angles, platform frames, the tip point and the
    end-effector's orientation ``C03``), :meth:`tip_position`, :meth:`tip_jacobian`,
    :meth:`tip_hessian`, :meth:`angular_jacobian`, :meth:`tip_velocity`,
    :meth:`bias_accelerations`, and the tool's frame: :attr:`tool_rotation` (the tool frame in the
    end-effector frame: ``x`` along the tool's edge, ``z`` along its axis; a stack's
    ``[end_effector] tool_axis``, ``tool_edge``, the identity by default and for the paper's
    robot), :meth:`tool_frame` (the tip and ``C03 @ tool_rotation``) and :meth:`tool_axis`
    (``C03 @ axis``, the direction a drill advances, in F0).
    """

    def __init__(
        self,
        parameters: RobotParameters | Stack,
        backend: CompiledBackend | InterpretedBackend | Backend | None = None,
    ) -> None:
        definition = definition_of(parameters)
        # RobotParameters or Stack (typed Any: the layers above read the fields both share)
        self.parameters: Any = parameters
        self.definition = definition
        self.backend = backend if backend is not None else get_backend(None, definition)
        self._p = parameters.vector()
        self._ranges = input_ranges(parameters)
        self._low, self._high = self._ranges["q"]
        self._units = input_units(parameters)
        self._G, self._h = parameters.margin_form()
        # the tool frame in the end-effector frame (the paper's robot has none: the identity)
        self._tool_rotation = parameters.tool_rotation if isinstance(parameters, Stack) else np.eye(3)
        self._tool_rotation.flags.writeable = False
        self._tool_default = bool(np.array_equal(self._tool_rotation, np.eye(3)))
        self.n_joints: int = parameters.n_joints
        self.joint_names: tuple[str, ...] = parameters.joint_names
        self.joint_units: tuple[str, ...] = parameters.joint_units
        self.body_names: tuple[str, ...] = definition.body_names
        self.n_modules = len(parameters.margin_legs())
        self._spec_table: dict[str, _Spec] | None = None
        self._margins_trust: Array | None = None
        #: Per method, the backend it was built for and its single-state path (None: has none).
        self._single_states: dict[str, tuple[Any, _SingleState | None]] = {}

    def __repr__(self) -> str:
        return f"Robot({self.parameters.name!r}, backend={self.backend.kind!r})"

    def _repr_html_(self) -> str:
        """The robot in a notebook: its name, size and backend, and a table of its joints with their
        units, limits and home values (every name escaped)."""
        p = self.parameters
        rows: list[list[object]] = [
            [name, unit, f"{lo:.6g}", f"{hi:.6g}", f"{home:.6g}"]
            for name, unit, lo, hi, home in zip(
                self.joint_names, self.joint_units, p.lower, p.upper, p.home, strict=True
            )
        ]
        caption = (
            f"{p.name}: {self.n_joints} joints, {self.n_modules} module(s), "
            f"{'stack' if self.is_stack else 'the paper' + chr(39) + 's model'}, {self.backend.kind} backend, "
            f"fingerprint {self.fingerprint}"
        )
        return html_table(("joint", "unit", "lower", "upper", "home"), rows, caption=caption)

    @property
    def fingerprint(self) -> str:
        """A short hash (12 hex digits) of the parameters and joint limits: two robots with the same
        fingerprint have the same model. Results record it (an IK result says which robot it was
        solved for)."""
        digest = hashlib.sha256(np.ascontiguousarray(self._p, dtype="<f8").tobytes())
        limits = [self.parameters.lower, self.parameters.upper]
        digest.update(np.ascontiguousarray(limits, dtype="<f8").tobytes())
        return digest.hexdigest()[:12]

    @property
    def parameter_vector(self) -> Array:
        """The flat parameter vector given to the compiled functions ((45,) for the paper's robot)."""
        return self._p.copy()

    @property
    def is_stack(self) -> bool:
        """Whether the robot is a stack of modules (else the paper's fixed 7-joint model)."""
        return self.definition != PAPER

    def with_parameters(self, parameters: RobotParameters | Stack) -> Robot:
        """A robot with other parameters and the same compiled model (a stack: of the same structure)."""
        if not isinstance(parameters, RobotParameters | Stack):
            raise InputError(
                f"parameters = {shown(parameters)}: expected RobotParameters or a Stack (see vgtarm.load_robot)"
            )
        same = (
            isinstance(parameters, RobotParameters)
            if self.definition == PAPER
            else isinstance(parameters, Stack) and StackDefinition.of(parameters) == self.definition
        )
        if not same:
            raise InputError(
                f"parameters = {shown(parameters)}: expected parameters of the same structure as robot "
                f"{shown(self.parameters.name)} (its compiled model)"
            )
        return Robot(parameters, self.backend)

    def margin_form(self) -> tuple[Array, Array]:
        """``G`` ``(6 m, n)`` and ``h`` ``(6 m,)``: the triangle margins ``G q + h`` of the ``m`` modules
        (six rows per module, in the order of :data:`~vgtarm.model.assembly.TRIANGLE_INEQUALITIES`)."""
        return self._G.copy(), self._h.copy()

    def check_assembly(self, q: ArrayLike, *, where: str = "q") -> None:
        """Raise :class:`~vgtarm.errors.AssemblyError` naming the module and the triangle inequality
        if a configuration of ``q`` ``(..., n)`` cannot be assembled (:class:`InputError` if ``q``
        is not an array of finite real numbers)."""
        if not isinstance(where, str):
            raise InputError(f"where = {shown(where)}: expected the name of the argument (str)")
        raw = real_array(q, where, self.n_joints, self.joint_names)
        shape = raw.shape[:-1]
        check_batch(math.prod(shape), _MARGIN_BYTES * self._G.shape[0] + 16 * self.n_joints, "check_assembly")
        qa = as_float(raw)
        largest = np.full(self.n_joints, np.finfo(float).max)
        check_input(qa, where, (-largest, largest), self.joint_names, self._units["q"], raw=raw)
        self._check_margins(qa, where)

    def joint_limits(self) -> tuple[Array, Array]:
        """The joints' limits from the robot file, lower and upper, ``(n,)`` each (m, rad): what the
        inverse kinematics keeps every joint within and what a run is stopped outside of.
        (:meth:`joint_range` is the wider range of values the methods accept at all.)"""
        return self.parameters.lower.copy(), self.parameters.upper.copy()

    def joint_range(self) -> tuple[Array, Array]:
        """Lowest and highest joint values the methods accept, ``(n,)`` each (m, rad); wider than
        :meth:`joint_limits`.

        The joint limits widened on each side by :data:`~vgtarm.model.sanity.SANE_WIDENING`
        times their span for lengths (at least 0), by :data:`~vgtarm.model.sanity.SANE_TURNS`
        turns for angles; beyond, values are refused as not a configuration.
        """
        return self._low.copy(), self._high.copy()

    def input_ranges(self) -> dict[str, tuple[Array, Array]]:
        """Lowest and highest accepted value of each input, by argument name: ``q`` (as
        :meth:`joint_range`), ``qd``, ``qdd``, ``F`` ``(n,)`` each (SI per joint: m, rad; per s;
        per s^2; N, N m) and ``f_tip`` ``(3,)`` (N). See :mod:`vgtarm.model.sanity` for the bounds."""
        return {label: (low.copy(), high.copy()) for label, (low, high) in self._ranges.items()}

    def in_joint_range(self, q: ArrayLike) -> NDArray[np.bool_]:
        """Whether each configuration ``(..., n)`` is finite and inside :meth:`joint_range`."""
        (qa,), _ = self._arrays("in_joint_range", [("q", q, self.n_joints)], outputs=0, finite=False)
        return np.asarray(((qa >= self._low) & (qa <= self._high)).all(axis=-1))

    # -- helpers -----------------------------------------------------------------------------

    def _arrays(
        self,
        method: str,
        named: list[tuple[str, ArrayLike, int]],
        *,
        outputs: int,
        finite: bool = True,
        margins: bool = False,
    ) -> tuple[list[Array], tuple[int, ...]]:
        """The inputs of ``method`` checked (real numbers, shape, memory of the batch, ranges) as float
        arrays (views where possible), and their broadcast leading shape.

        ``named`` holds ``(argument, value, size of the last axis)``; ``outputs`` is the number of
        floats ``method`` creates per row; ``margins``: the method evaluates the triangle margins.
        ``finite=False`` checks only the type and the shape."""
        raws = [real_array(value, label, size, self._names(label)) for label, value, size in named]
        shapes = [raw.shape[:-1] for raw in raws]
        try:
            shape = shapes[0] if shapes.count(shapes[0]) == len(shapes) else np.broadcast_shapes(*shapes)
        except ValueError:
            given = ", ".join(f"{label} {raw.shape}" for (label, _, _), raw in zip(named, raws, strict=True))
            raise InputError(f"{method}: leading shapes do not broadcast: {given}") from None
        row_bytes = 8 * outputs + (_MARGIN_BYTES * self._G.shape[0] if margins else 0)
        for raw in raws:
            size = raw.shape[-1]
            row_bytes += 3 * size  # the range check's booleans
            row_bytes += 8 * size if raw.dtype != np.float64 else 0  # the conversion
            row_bytes += 8 * size if raw.shape[:-1] != shape or not raw.flags.c_contiguous else 0  # one row each
        check_batch(math.prod(shape), max(row_bytes, 1), method)
        arrays = [as_float(raw) for raw in raws]
        if finite:
            for (label, _, _), raw, array in zip(named, raws, arrays, strict=True):
                if label == "q":
                    check_joint_range(array, self.parameters, (self._low, self._high), where=label, raw=raw)
                else:
                    check_input(
                        array,
                        label,
                        self._ranges[label],
                        self._names(label),
                        self._units[label],
                        raw=raw,
                        explain=RANGE_REASONS.get(label, ""),
                    )
        return arrays, shape

    def _specs(self) -> dict[str, _Spec]:
        """What each method that evaluates the model evaluates (see :class:`_Spec`), by method name."""
        if self._spec_table is not None:
            return self._spec_table
        n, m, nb = self.n_joints, self.n_modules, len(self.body_names)
        q, qd = ("q", n), ("qd", n)
        if self.definition == PAPER:  # passive, o1, C01, o2, C02, tip, C03
            fk: tuple[Piece, ...] = (
                ((0,), (m, 4)),
                ((1, 3), (m, 3)),
                ((2, 4), (m, 3, 3)),
                ((5,), (3,)),
                ((6,), (3, 3)),
            )
        else:  # passive, origins, rotations, tip, C03
            fk = (((0,), (m, 4)), ((1,), (m, 3)), ((2,), (m, 3, 3)), ((3,), (3,)), ((4,), (3, 3)))
        self._spec_table = {
            "forward_kinematics": _Spec("fk", (q,), 28 * m + 12, fk),
            "tip_position": _Spec("tip", (q,), 3, (((0,), (3,)),)),
            "tip_jacobian": _Spec("jac", (q,), 6 * n, (((0,), (3, n)),)),
            "tip_hessian": _Spec("tip_hessian", (q,), 3 * n * n, (((0,), (3, n, n)),)),
            "angular_jacobian": _Spec("jac", (q,), 6 * n, (((1,), (3, n)),)),
            "com_jacobians": _Spec("com_jac", (q,), 6 * nb * n, (((0,), (nb, 3, n)), ((1,), (nb, 3, n)))),
            "tip_velocity": _Spec("velocity", (q, qd), 6, (((0,), (3,)), ((1,), (3,)))),
            "bias_accelerations": _Spec(
                "bias_acc", (q, qd), 6 + 6 * nb, (((0,), (3,)), ((1,), (3,)), ((2,), (nb, 3)), ((3,), (nb, 3)))
            ),
            "mass_matrix": _Spec("mass", (q,), n * n, (((0,), (n, n)),)),
            "bias_forces": _Spec("bias_forces", (q, qd), n, (((0,), (n,)),)),
            "forward_dynamics": _Spec("fd", (q, qd, ("F", n), ("f_tip", 3)), n, (((0,), (n,)),)),
            "inverse_dynamics": _Spec("id", (q, qd, ("qdd", n), ("f_tip", 3)), n, (((0,), (n,)),)),
            "energy": _Spec("energy", (q, qd), 2, (((0,), ()), ((1,), ()))),
        }
        return self._spec_table

    def _call(self, method: str, *arrays: Any) -> tuple[Array, ...]:
        """The pieces of ``method``'s result (:meth:`_specs`) for its arguments ``arrays``: one state
        of 1-D float64 arrays through its single-state path (:class:`_SingleState`), anything else
        (and whatever that path declines) through the batch path (:meth:`_evaluate`)."""
        entry = self._single_states.get(method)
        if entry is None or entry[0] is not self.backend:
            entry = self._single_states[method] = (self.backend, self._single_state(method))
        if entry[1] is not None:
            result = entry[1](arrays)
            if result is not None:
                return result
        spec = self._specs()[method]
        named = [(label, value, size) for (label, size), value in zip(spec.inputs, arrays, strict=True)]
        shape, out = self._evaluate(method, spec.function, named, outputs=spec.outputs)
        return tuple(
            (out[i[0]] if len(i) == 1 else np.stack([out[j] for j in i], axis=1)).reshape(shape + piece)
            for i, piece in spec.pieces
        )

    def _trusted_margins(self) -> Array:
        """``[h - trust, G]`` ``(6 m, 1 + n)``: its product with ``[1, q]`` is each triangle margin less
        :data:`_MARGIN_TRUST` of the sizes of its terms (one row of 1 for a robot of no module)."""
        if self._margins_trust is None:
            largest = np.maximum(np.abs(self._low), np.abs(self._high))
            trust = _MARGIN_TRUST * (np.abs(self._G) @ largest + np.abs(self._h))
            margins = np.concatenate([(self._h - trust)[:, None], self._G], axis=1)
            self._margins_trust = margins if len(margins) else np.eye(1, 1 + self.n_joints)
        return self._margins_trust

    def _single_state(self, method: str) -> _SingleState | None:
        """The single-state path of ``method`` on this robot's backend (None if its outputs cannot be
        served as views of one buffer, or the backend does not know the function)."""
        try:
            return _SingleState(self, method, self._specs()[method])
        except (ValueError, KeyError, TypeError):
            return None

    def _names(self, label: str) -> tuple[str, ...]:
        """Names of the entries of argument ``label``'s last axis (joints, or x y z of a force)."""
        return FORCE_NAMES if label == "f_tip" else self.joint_names if label in self._ranges else ()

    def _evaluate(
        self, method: str, name: str, named: list[tuple[str, ArrayLike, int]], outputs: int
    ) -> tuple[tuple[int, ...], list[Array]]:
        """Evaluate the compiled function ``name`` for ``method`` on checked inputs (the first is ``q``,
        refused outside the range and when it cannot be assembled); ``outputs`` as for :meth:`_arrays`.
        A result that is not finite is refused, naming the input that drove it."""
        arrays, shape = self._arrays(method, named, outputs=outputs, margins=True)
        self._check_margins(arrays[0], named[0][0])
        n = math.prod(shape)
        flat = [np.broadcast_to(a, shape + a.shape[-1:]).reshape(n, a.shape[-1]) for a in arrays]
        results = self.backend.evaluate(name, [*flat, self._p], n)
        for result in results:
            if not finite(result):
                self._refuse_result(method, named, flat, shape, results)
        return shape, results

    def _check_margins(self, q: Array, where: str) -> None:
        p = self.parameters
        if q.size * self._G.shape[0] <= _BLAS_THREADED_PRODUCT:
            check_margins(q, self._G, self._h, p.margin_legs(), p.b, p.d, where=where)
            return
        with blas_on_one_thread():  # the same product, on the calling thread (see _BLAS_THREADED_PRODUCT)
            check_margins(q, self._G, self._h, p.margin_legs(), p.b, p.d, where=where)

    def _refuse_result(
        self,
        method: str,
        named: list[tuple[str, ArrayLike, int]],
        flat: list[Array],
        shape: tuple[int, ...],
        results: list[Array],
    ) -> None:
        """Raise the :class:`InputError` of a result that is not finite from inputs that passed every
        check: name the first such row and what drove it (an unassemblable neighbourhood of ``q``,
        else the input that is largest for its range)."""
        bad = np.zeros(len(flat[0]), dtype=bool)
        for result in results:
            bad |= ~np.isfinite(result).all(axis=1)
        row = int(np.argmax(bad))
        index = tuple(int(i) for i in np.unravel_index(row, shape)) if shape else ()
        location = f" for configuration {index}" if shape else ""
        margin = float((flat[0][row] @ self._G.T + self._h).min())
        ratios = [
            (float(np.max(np.abs(a[row]) / self._ranges[label][1])), label, a[row])
            for (label, _, _), a in zip(named, flat, strict=True)
            if label != "q"
        ]
        ratio, label, values = max(ratios, key=lambda item: item[0], default=(0.0, "", flat[0][row]))
        if margin < _SINGULAR_MARGIN:
            culprit = (
                f"q{location} is {margin:.3g} m from a leg set that cannot be assembled, where the model is singular"
            )
        elif ratio >= _LARGE_INPUT:
            j = int(np.argmax(np.abs(values) / self._ranges[label][1]))
            names, unit = self._names(label), self._units[label][j]
            element = f"{label}[{j}] ({names[j]})" if j < len(names) else f"{label}[{j}]"
            culprit = (
                f"{element} = {float(values[j]):.6g} {unit} drove it out of range ({100 * ratio:.3g} % of its bound "
                f"{self._ranges[label][1][j]:.6g} {unit}); use smaller values"
            )
        else:
            culprit = (
                f"the parameters of robot {shown(self.parameters.name)} make the model overflow there "
                "(check its masses and inertias)"
            )
        raise InputError(
            f"{method}: the result is not finite{location} although every input is finite and inside its accepted "
            f"range; {culprit}"
        )

    def evaluate(self, name: str, inputs: Mapping[str, ArrayLike], n: int) -> dict[str, Array]:
        """Evaluate the compiled function ``name`` on ``n`` samples, inputs and outputs by name.

        ``inputs`` maps each input name of the function but ``p`` (the robot's parameters, added
        here) to an ``(n, size)`` array or a ``(size,)`` value shared by every sample. Returns
        ``{output name: (n, size)}``. This is how layers above (inverse kinematics) reach the
        generated functions that have no method of their own.
        """
        try:
            sig = self.backend.signature(name)
        except (KeyError, TypeError):
            raise InputError(f"evaluate: no compiled function named {shown(name)}") from None
        if not isinstance(inputs, Mapping):
            raise InputError(f"evaluate: inputs = {shown(inputs)}: expected a mapping of input names to arrays")
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 0:
            raise InputError(f"evaluate: n = {shown(n)}: expected a number of samples (a whole number >= 0)")
        n = int(n)
        wanted = [label for label in sig.in_names if label != "p"]
        unknown = sorted(set(inputs) - set(wanted), key=str)
        missing = [label for label in wanted if label not in inputs]
        if unknown or missing:
            raise InputError(f"{name}: inputs {wanted} expected, got unknown {unknown} and missing {missing}")
        sizes = dict(zip(sig.in_names, sig.nnz_in, strict=True))
        raws = []
        for label in wanted:
            raw = real_array(inputs[label], f"{name} input {label}", sizes[label])
            if raw.shape not in ((n, sizes[label]), (sizes[label],)):
                raise InputError(
                    f"{name} input {label}: expected shape ({n}, {sizes[label]}) or ({sizes[label]},), got {raw.shape}"
                )
            raws.append(raw)
        row_bytes = 8 * (sum(sig.nnz_out) + sum(r.shape[-1] for r in raws if r.ndim == 2 and r.dtype != np.float64))
        check_batch(n, max(row_bytes, 1), f"evaluate {name}")
        arrays = [as_float(raw) for raw in raws]
        for label, raw, array in zip(wanted, raws, arrays, strict=True):
            if not finite(array):
                index = tuple(int(i) for i in np.argwhere(~np.isfinite(array))[0])
                raise InputError(
                    f"{name} input {label} must be finite; {label}[{', '.join(map(str, index))}] = "
                    f"{shown(raw[index].item() if isinstance(raw[index], np.generic) else raw[index])}"
                )
        outputs = self.backend.evaluate(name, [*arrays, self._p], n)
        return dict(zip(sig.out_names, outputs, strict=True))

    # -- kinematics --------------------------------------------------------------------------

    def is_assemblable(self, q: ArrayLike, margin: float = 0.0) -> NDArray[np.bool_]:
        """Whether each configuration ``(..., n)`` can be assembled with the given margin (m)."""
        if isinstance(margin, bool) or not isinstance(margin, int | float | np.integer | np.floating):
            raise InputError(f"margin = {shown(margin)}: expected a length (m)")
        if not math.isfinite(margin):
            raise InputError(f"margin = {shown(margin)}: expected a finite length (m)")
        largest = np.full(self.n_joints, np.finfo(float).max)
        (qa,), _ = self._arrays("is_assemblable", [("q", q, self.n_joints)], outputs=0, margins=True, finite=False)
        check_input(qa, "q", (-largest, largest), self.joint_names, self._units["q"])
        if qa.size * self._G.shape[0] <= _BLAS_THREADED_PRODUCT:
            return np.asarray((qa @ self._G.T + self._h > margin).all(axis=-1))
        with blas_on_one_thread():
            return np.asarray((qa @ self._G.T + self._h > margin).all(axis=-1))

    def forward_kinematics(self, q: ArrayLike) -> ForwardKinematics:
        """Passive angles, platform frames, tip point and orientation (paper eqs. 1-11)."""
        passive, origins, rotations, tip, rotation = self._call("forward_kinematics", q)
        return ForwardKinematics(passive, origins, rotations, tip, rotation)

    @property
    def actuators(self) -> Actuators | None:
        """The joints' actuators (peak force, no-load speed, acceleration limit, force-speed line) of
        the robot file's ``[actuators]`` table, or ``None`` (no limits, the paper's robot); see
        :mod:`vgtarm.model.actuators`."""
        return self.parameters.actuators

    @property
    def stiffness(self) -> JointStiffness | None:
        """The joints' stiffness of the robot file's ``[stiffness]`` table (N/m, N m/rad), or ``None``
        (rigid joints, the paper's robot); see :mod:`vgtarm.design.stiffness`."""
        return self.parameters.stiffness

    @property
    def tool_rotation(self) -> Array:
        """The tool frame in the end-effector frame F3, ``(3, 3)``: its columns are the tool's edge,
        ``axis x edge`` and axis (a stack's ``[end_effector] tool_edge`` and ``tool_axis``); the
        identity by default and for the paper's robot."""
        return self._tool_rotation.copy()

    def tool_frame(self, q: ArrayLike) -> tuple[Array, Array]:
        """The tool frame in F0: the tip point ``(..., 3)`` (m) and the orientation
        ``C03 @ tool_rotation`` ``(..., 3, 3)`` (``z`` the tool's axis, ``x`` its edge); with the
        default tool the orientation is ``C03`` itself."""
        fk = self.forward_kinematics(q)
        if self._tool_default:
            return fk.tip, fk.rotation
        return fk.tip, fk.rotation @ self._tool_rotation

    def tool_axis(self, q: ArrayLike) -> Array:
        """The tool's axis in F0, ``C03 @ axis`` ``(..., 3)`` (a unit vector: the direction a drill
        advances)."""
        return self.forward_kinematics(q).rotation @ self._tool_rotation[:, 2]

    def tip_position(self, q: ArrayLike) -> Array:
        """Tip point P in F0, ``(..., 3)`` (m). Cheaper than the full forward kinematics."""
        return self._call("tip_position", q)[0]

    def tip_jacobian(self, q: ArrayLike) -> Array:
        """Translational Jacobian of the tip ``J_P = dP/dq``, ``(..., 3, n)``."""
        return self._call("tip_jacobian", q)[0]

    def tip_hessian(self, q: ArrayLike) -> Array:
        """Second derivatives of the tip point ``d^2 P_k / dq_l dq_m``, ``(..., 3, n, n)``."""
        return self._call("tip_hessian", q)[0]

    def angular_jacobian(self, q: ArrayLike) -> Array:
        """Angular Jacobian of the end-effector (F0 components), ``(..., 3, n)``."""
        return self._call("angular_jacobian", q)[0]

    def com_jacobians(self, q: ArrayLike) -> tuple[Array, Array]:
        """Jacobians of the bodies' centres of mass and angular velocities, each ``(..., b, 3, n)``.

        Axis ``-3`` is the body (:attr:`body_names`: platform 1, platform 2, end-effector for the
        paper's robot).
        """
        jv, jw = self._call("com_jacobians", q)
        return jv, jw

    def tip_velocity(self, q: ArrayLike, qd: ArrayLike) -> tuple[Array, Array]:
        """Tip velocity ``J_P qd`` (m/s) and end-effector angular velocity (rad/s), ``(..., 3)`` each."""
        v, w = self._call("tip_velocity", q, qd)
        return v, w

    def bias_accelerations(self, q: ArrayLike, qd: ArrayLike) -> BiasAccelerations:
        """Accelerations due to ``qd`` alone (``qdd = 0``): ``Jdot qd`` of the tip and bodies."""
        tip, angular, com, body_angular = self._call("bias_accelerations", q, qd)
        return BiasAccelerations(tip, angular, com, body_angular)

    def inverse_kinematics(self, path: Any, *, check: bool = True, **options: Any) -> Any:
        """Convenience for :func:`vgtarm.ik.inverse_kinematics` ``(self, path, check=check, **options)``.

        ``check`` (default True) raises :class:`~vgtarm.errors.UnreachableError` for a sample out
        of reach; with False the result is returned with ``status`` ``"unreachable"`` and its rows
        solved up to that sample (see :func:`vgtarm.ik.inverse_kinematics`).

        The model layer does not depend on inverse kinematics: the ``ik`` package is imported
        only when this method is called (``import vgtarm.model`` never loads it).
        """
        from ..ik import inverse_kinematics  # the one upward reference, resolved at call time

        return inverse_kinematics(self, path, check=check, **options)

    # -- dynamics ----------------------------------------------------------------------------

    def mass_matrix(self, q: ArrayLike) -> Array:
        """Mass matrix ``M(q)`` of eq. 15, ``(..., n, n)``."""
        return self._call("mass_matrix", q)[0]

    def bias_forces(self, q: ArrayLike, qd: ArrayLike) -> Array:
        """``C(q, qd)`` of eq. 15: velocity products + gravity + viscous friction, ``(..., n)``."""
        return self._call("bias_forces", q, qd)[0]

    def forward_dynamics(self, q: ArrayLike, qd: ArrayLike, F: ArrayLike, f_tip: ArrayLike | None = None) -> Array:
        """Joint accelerations ``M^-1 (F + J_P^T f_tip - C)``, ``(..., n)``.

        ``F`` are the actuator efforts (N, and N m for the twist); ``f_tip`` the force acting
        on the end-effector at the tip point, in F0 (N), default zero.
        """
        return self._call("forward_dynamics", q, qd, F, _NO_TIP_FORCE if f_tip is None else f_tip)[0]

    def inverse_dynamics(self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, f_tip: ArrayLike | None = None) -> Array:
        """Actuator efforts ``M qdd + C - J_P^T f_tip`` that produce ``qdd``, ``(..., n)``."""
        return self._call("inverse_dynamics", q, qd, qdd, _NO_TIP_FORCE if f_tip is None else f_tip)[0]

    def energy(self, q: ArrayLike, qd: ArrayLike) -> tuple[Array, Array]:
        """Kinetic and potential (gravity) energy, each of shape ``(...)`` (J)."""
        kinetic, potential = self._call("energy", q, qd)
        return kinetic, potential


#: The models a stack's Robot can run on (``load_robot(model=...)``, ``$VGTARM_MODEL``, ``--model``).
MODEL_CHOICES = ("symbolic", "recursive")

#: A stack of this many modules or more runs on the recursive model unless told otherwise. Measured
#: (``docs/benchmarks.md``): the recursive model is as fast as the symbolic library from two modules
#: and 3 to 4 times faster at six (forward dynamics, IK of case 1, computed force control), and it
#: builds nothing per arm, while the symbolic library of seven modules takes minutes to build and
#: grows as ``n^2`` in code; up to six modules the symbolic library stays the default because it
#: has every function (the pose and effort IK tasks, energies, the centres of mass' Jacobians).
RECURSIVE_FROM_MODULES = 7


def default_model(parameters: RobotParameters | Stack) -> str:
    """The model a robot runs on when none is chosen: the paper's robot, and a stack of fewer than
    :data:`RECURSIVE_FROM_MODULES` modules, the symbolic one; a longer stack the recursive one."""
    if isinstance(parameters, Stack) and parameters.n_modules >= RECURSIVE_FROM_MODULES:
        return "recursive"
    return "symbolic"


def recursive_robot(stack: Stack) -> Robot:
    """A robot of ``stack`` on the recursive model (:mod:`vgtarm.model.recursive`): forward kinematics,
    Jacobians, ``M``, ``C``, forward and inverse dynamics in ``O(n)``, the position task's inverse
    kinematics and the compiled closed loop, nothing compiled for the arm; the functions it lacks
    (the pose and effort IK tasks, energies, ...) are refused by name."""
    if not isinstance(stack, Stack):
        raise InputError(f"stack = {shown(stack)}: expected a Stack (the recursive model is for stacks of modules)")
    return Robot(stack, RecursiveBackend(stack))


def _robot_of(parameters: RobotParameters | Stack, model: str | None) -> Robot:
    """The robot of ``parameters`` on the chosen model (the paper's robot: always its symbolic one)."""
    choice = (os.environ.get("VGTARM_MODEL", "") or default_model(parameters)) if model is None else model
    if choice not in MODEL_CHOICES:
        where = "model" if model is not None else "$VGTARM_MODEL"
        raise ConfigError(f"{where} = {shown(choice)}: expected one of {', '.join(MODEL_CHOICES)}")
    if choice == "recursive":
        if isinstance(parameters, RobotParameters):
            raise ConfigError(
                "model = 'recursive' is for stacks of modules; the paper's robot keeps its symbolic model "
                "(convert it: vgtarm convert-robot --out stack.toml)"
            )
        robot = recursive_robot(parameters)
    else:
        robot = Robot(parameters)
    if parameters.actuators is not None:  # a file's actuators must at least hold the robot at home
        home = parameters.home
        holding = robot.inverse_dynamics(home, np.zeros_like(home), np.zeros_like(home))
        check_holding(parameters.actuators, holding, parameters.source)
    return robot


def load_robot(config: str | Path | None = None, *, model: str | None = None) -> Robot:
    """Load a robot: the shipped reference robot, or the TOML file ``config``.

    A file with ``[[modules]]`` tables (or an ``[end_effector]`` table) describes a stack of modules
    (:mod:`vgtarm.model.stack.description`); any other, the paper's 7-joint robot
    (:func:`load_parameters`). Either way a bad file raises one
    :class:`~vgtarm.errors.ConfigError` line naming the field.

    ``model`` (default ``$VGTARM_MODEL``, else :func:`default_model`: ``recursive`` for a stack of
    :data:`RECURSIVE_FROM_MODULES` modules or more) chooses a stack's model: ``symbolic`` (the
    compiled symbolic library) or ``recursive`` (:func:`recursive_robot`: any size at once; the
    position-task IK and the closed loop, not the pose and effort tasks). The paper's robot always
    runs on its symbolic model.
    """
    if config is None:
        return _robot_of(load_parameters(None), model)
    if isinstance(config, str | os.PathLike):
        text = read_text_limited(config, ROBOT_FILE_LIMIT, "configuration file", error=ConfigError)
        data = parse_toml(text, cut(str(config), 200), error=ConfigError)
        return _robot_of(robot_parameters_from_dict(data, source=str(config)), model)
    return _robot_of(load_parameters(config), model)


def is_stack_format(data: Mapping[str, Any]) -> bool:
    """Whether a parsed robot file is in the stack format (it has keys only that format has)."""
    return "modules" in data or "end_effector" in data


def robot_parameters_from_dict(data: Mapping[str, Any], *, source: str = "<dict>") -> RobotParameters | Stack:
    """The validated parameters of a parsed robot file of either format (see :func:`load_robot`);
    nothing is compiled."""
    other = other_toml(data, "robot")  # a study file given as a robot: said in those words
    if other is not None:
        raise ConfigError(f"{cut(str(source), 200)}: {other}")
    if is_stack_format(data):
        return stack_from_dict(data, source=source)
    return parameters_from_dict(data, source=source)


def robot_from_dict(data: Mapping[str, Any], *, source: str = "<dict>", model: str | None = None) -> Robot:
    """A robot from a parsed robot file of either format, on the model :func:`load_robot` would choose
    for it (``model``, else ``$VGTARM_MODEL``, else :func:`default_model`: a long stack's is the
    recursive one, whose symbolic library would take hours to build)."""
    return _robot_of(robot_parameters_from_dict(data, source=source), model)
