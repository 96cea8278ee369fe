"""Kinematic calibration: the robot's lengths and its leg sensors' zero offsets identified from
measured tool positions (and, where measured, orientations).

The identified parameters (:func:`calibration_parameters`) are every length of the robot file that
moves the tool: each module's ``b`` and ``d``, the paper robot's ``h1`` or a stack's twist heights
and tool point; and the zero offset of each leg's length sensor (a reading is the true length plus
its offset, ``q_read = q + offset``). The model is the robot's own symbolic definition
(``robot.definition``, the expressions the compiled library is generated from), whose
parameters are a runtime vector: the identification Jacobian ``d tool / d parameters`` is its
automatic derivative (CasADi), evaluated for a batch of poses in one call (:class:`ToolModel`).

Steps, each a function returning a frozen record:

- :func:`identifiability`: the SVD of the identification Jacobian over the poses; combinations of
  parameters whose singular value is below ``rtol`` times the largest are undetermined (named), one
  parameter per undetermined direction is held at its nominal value (chosen by a pivoted QR of the
  null space), parameters with no part in the null space are determined, the others determined
  only given the held ones.
- :func:`plan_poses`: ``K`` poses chosen greedily (D-optimal) from seeded random joint
  configurations within the limits (the redundancy: many joint sets per tool point), with the
  condition number against random poses.
- :func:`calibrate`: Levenberg-Marquardt on the free parameters with the AD Jacobian, standard
  errors from the residual variance and ``(J^T J)^-1``; :meth:`Calibration.robot_toml` writes the
  corrected robot file in the input's format (:func:`write_robot_file`: atomically, never over a file
  vgtarm did not write).
- :func:`read_measurements`: the CSV of joint readings and measured ``x, y, z`` (optionally the tool
  frame's quaternion ``qw, qx, qy, qz``), refused in one line naming the row.

Units: m and rad throughout.
"""

from __future__ import annotations

import csv
import io
import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..errors import InputError, cut, shown
from ..fileio import OutputPathError, atomic_write_text, check_output_file, read_text_limited
from ..model.parameters import ModuleGeometry, RobotParameters
from ..model.robot import Robot
from ..model.stack.description import BODY_VALUES, Stack, robot_to_toml

Array = NDArray[np.float64]

#: Relative singular-value tolerance below which a direction of parameters is undetermined.
DEFAULT_RTOL = 1e-6
#: A parameter whose part in the null space (norm of its row of the null basis) is below this is
#: determined on its own.
NULL_PART_TOLERANCE = 1e-6
#: Measurement noise assumed to weight positions against orientations (m, rad).
DEFAULT_POSITION_NOISE = 0.05e-3
DEFAULT_ORIENTATION_NOISE = 1e-4
#: Poses chosen by default, and random candidates they are chosen from.
DEFAULT_POSES = 50
DEFAULT_CANDIDATES = 3000
#: Triangle margin (m) and fraction of each joint's span kept from the limits by planned poses, so a
#: built robot a few millimetres off still assembles there.
DEFAULT_MARGIN = 0.01
LIMIT_FRACTION = 0.02
#: First comment line of a robot file written here: only such a file is ever replaced.
WRITTEN_MARK = "# Written by vgtarm calibrate"
#: Columns of the optional orientation (unit quaternion of the tool frame, scalar first).
QUATERNION_COLUMNS = ("qw", "qx", "qy", "qz")
POSITION_COLUMNS = ("x", "y", "z")
MEASUREMENT_FILE_LIMIT = 16 * 2**20


# -- the parameters -----------------------------------------------------------------------------


@dataclass(frozen=True)
class CalibrationParameters:
    """The identified parameters of a robot: geometric lengths, then the legs' sensor offsets.

    Attributes:
        names: ``(m,)`` the robot file's field of each length (``geometry.module1.b``,
            ``module2.twist.height``, ``end_effector.tool[2]``), then ``offset.<leg>``.
        vector_index: ``(g,)`` index of each length in :attr:`vgtarm.Robot.parameter_vector`.
        offset_joint: ``(m - g,)`` joint index of each offset.
        nominal: ``(m,)`` the robot file's lengths and zero offsets (m).
    """

    names: tuple[str, ...]
    vector_index: tuple[int, ...]
    offset_joint: tuple[int, ...]
    nominal: Array

    @property
    def size(self) -> int:
        return len(self.names)

    @property
    def n_lengths(self) -> int:
        return len(self.vector_index)


def _stack_lengths(stack: Stack) -> list[tuple[str, int]]:
    """``(field, index in Stack.vector)`` of a stack's lengths, walking the vector's layout."""
    found: list[tuple[str, int]] = []
    o = 0
    for k, module in enumerate(stack.modules, start=1):
        found += [(f"module{k}.b", o), (f"module{k}.d", o + 1)]
        o += 2 + BODY_VALUES
        if module.twist is not None:
            found.append((f"module{k}.twist.height", o))
            o += 1 + (BODY_VALUES if module.twist.body is not None else 0)
    o += BODY_VALUES  # the end-effector body
    return found + [(f"end_effector.tool[{i}]", o + i) for i in range(3)]


def calibration_parameters(robot: Robot, *, sensor_offsets: bool = True) -> CalibrationParameters:
    """The lengths of ``robot``'s file that move the tool and, with ``sensor_offsets``, one sensor
    offset per leg (without: the legs' sensors are trusted to read true lengths)."""
    if not isinstance(robot, Robot):
        checks.refuse("robot", robot, "a vgtarm.Robot (vgtarm.load_robot)")
    parameters = robot.parameters
    if isinstance(parameters, Stack):
        lengths = _stack_lengths(parameters)
        legs = [i for idx in parameters.leg_indices for i in idx]
    else:
        fields = ("geometry.module1.b", "geometry.module1.d", "geometry.module2.b", "geometry.module2.d")
        lengths = [(name, i) for i, name in enumerate((*fields, "geometry.h1"))]
        legs = [i for idx in parameters.margin_legs() for i in idx]
    legs = legs if checks.flag("sensor_offsets", sensor_offsets) else []
    p = robot.parameter_vector
    names = tuple(name for name, _ in lengths) + tuple(f"offset.{robot.joint_names[j]}" for j in legs)
    nominal = np.concatenate([[p[i] for _, i in lengths], np.zeros(len(legs))])
    return CalibrationParameters(names, tuple(i for _, i in lengths), tuple(legs), nominal)


def corrected_parameters(robot: Robot, values: ArrayLike, *, name: str | None = None) -> RobotParameters | Stack:
    """``robot``'s parameters with the lengths of ``values`` (``(m,)`` in the order of
    :func:`calibration_parameters`, with or without the sensor offsets, which are not part of a
    robot file and are ignored)."""
    spec = calibration_parameters(robot)
    x = checks.finite_array("values", values, (None,))
    if len(x) not in (spec.size, spec.n_lengths):
        checks.refuse("values.shape", x.shape, f"({spec.size},) or ({spec.n_lengths},): the calibration parameters")
    lengths = dict(zip(spec.names, x[: spec.n_lengths].tolist(), strict=False))
    parameters = robot.parameters
    title = name if name is not None else f"{parameters.name} (calibrated)"
    if isinstance(parameters, RobotParameters):
        modules = tuple(
            ModuleGeometry(b=lengths[f"geometry.module{k}.b"], d=lengths[f"geometry.module{k}.d"]) for k in (1, 2)
        )
        return replace(parameters, name=cut(title, 200), modules=modules, h1=lengths["geometry.h1"])  # type: ignore[arg-type]
    new_modules = []
    for k, module in enumerate(parameters.modules, start=1):
        twist = module.twist
        if twist is not None:
            twist = replace(twist, height=lengths[f"module{k}.twist.height"])
        new_modules.append(replace(module, b=lengths[f"module{k}.b"], d=lengths[f"module{k}.d"], twist=twist))
    tool = tuple(lengths[f"end_effector.tool[{i}]"] for i in range(3))
    return replace(parameters, name=cut(title, 200), modules=tuple(new_modules), tool=tool)


# -- the model and its automatic derivative ---------------------------------------------------------


class ToolModel:
    """The tool point (and frame) of joint readings ``q`` for calibration parameters ``x``, with its
    Jacobian ``d/dx``, from the robot's symbolic definition by CasADi's automatic differentiation.

    ``tool(q, x) = P(q - offsets(x), p(x))``: the robot's parameter vector with the lengths of ``x``.
    With ``orientation``, the residual of a measured tool frame ``R_m`` is
    ``vee(R_m^T R - R^T R_m) / 2`` (rad: the sine of the angle between them times its axis, in the
    measured frame), also differentiated.
    """

    def __init__(self, robot: Robot, *, orientation: bool = False, sensor_offsets: bool = True) -> None:
        self.robot = robot
        self.spec = calibration_parameters(robot, sensor_offsets=sensor_offsets)
        self.orientation = bool(orientation)
        n, spec = robot.n_joints, self.spec
        q, x = ca.SX.sym("q", n), ca.SX.sym("x", spec.size)
        p = ca.SX(robot.parameter_vector)
        for k, index in enumerate(spec.vector_index):
            p[index] = x[k]
        shift = ca.SX.zeros(n)
        for k, joint in enumerate(spec.offset_joint):
            shift[joint] = x[spec.n_lengths + k]
        kinematics = robot.definition.kinematics(q - shift, p)
        outputs = [kinematics.tip]
        inputs = [q, x]
        if self.orientation:
            entries = ca.SX.sym("R", 9)
            measured = ca.reshape(entries, 3, 3)  # filled column by column
            rotation = kinematics.C03 @ ca.DM(robot.tool_rotation)
            skew = measured.T @ rotation - rotation.T @ measured
            outputs.append(0.5 * ca.vertcat(skew[2, 1], skew[0, 2], skew[1, 0]))
            inputs.append(entries)
        residual = ca.vertcat(*outputs)
        self._rows = residual.shape[0]
        self._functions = {
            "values": ca.Function("tool", inputs, [residual]),
            "jacobian": ca.Function("tool_jacobian", inputs, [residual, ca.jacobian(residual, x)]),
        }
        self._maps: dict[tuple[str, int], ca.Function] = {}

    @property
    def rows(self) -> int:
        """Residual rows per pose: 3, or 6 with the orientation."""
        return self._rows

    def _run(self, kind: str, q: Array, x: Array, rotation: Array | None) -> list[Any]:
        count = len(q)
        key = (kind, count)
        if key not in self._maps:
            self._maps[key] = self._functions[kind].map(count, "serial")
        args: list[Any] = [q.T, x]
        if self.orientation:
            if rotation is None:
                raise InputError("rotation: measured tool frames (K, 3, 3) are needed by a model with orientation")
            args.append(rotation.transpose(0, 2, 1).reshape(count, 9).T)  # column by column
        out = self._maps[key](*args)
        return [out] if isinstance(out, ca.DM) else list(out)

    def values(self, q: Array, x: Array, rotation: Array | None = None) -> Array:
        """The model's rows ``(K, rows)``: the tool point (m), then the orientation residual (rad),
        for readings ``q`` ``(K, n)``; NaN where ``x`` cannot assemble ``q``."""
        return np.asarray(self._run("values", q, x, rotation)[0]).T.copy()

    def evaluate(self, q: Array, x: Array, rotation: Array | None = None) -> tuple[Array, Array]:
        """:meth:`values` and their Jacobian ``(K, rows, m)`` with respect to ``x``, in one call."""
        values, jacobian = self._run("jacobian", q, x, rotation)
        rows, m = self._rows, self.spec.size
        y = np.asarray(values).T.copy()
        J = np.asarray(jacobian).reshape(rows, len(q), m).transpose(1, 0, 2).copy()
        return y, J


# -- measurements ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Measurements:
    """Measured poses: joint readings ``q`` ``(K, n)`` (m, rad), tool points ``tip`` ``(K, 3)`` (m) and,
    if measured, tool frames ``rotation`` ``(K, 3, 3)`` in F0."""

    q: Array
    tip: Array
    rotation: Array | None = None
    source: str = "<measurements>"

    def __len__(self) -> int:
        return len(self.q)

    def to_csv(self, joint_names: Sequence[str]) -> str:
        """The CSV text :func:`read_measurements` reads (17 significant digits)."""
        header = [*joint_names, *POSITION_COLUMNS]
        table = [self.q, self.tip]
        if self.rotation is not None:
            header += list(QUATERNION_COLUMNS)
            table.append(np.array([_quaternion(r) for r in self.rotation]).reshape(len(self), 4))
        stream = io.StringIO()
        stream.write(",".join(header) + "\n")
        np.savetxt(stream, np.column_stack(table), delimiter=",", fmt="%.17g")
        return stream.getvalue()


def _quaternion(rotation: Array) -> Array:
    """The unit quaternion ``(w, x, y, z)`` (w >= 0) of a rotation matrix (Shepperd's method)."""
    r = rotation
    trace = float(np.trace(r))
    k = int(np.argmax([trace, r[0, 0], r[1, 1], r[2, 2]]))
    if k == 0:
        w = math.sqrt(1.0 + trace) / 2
        v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (4 * w)
        out = np.array([w, *v])
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        s = math.sqrt(1.0 + r[i, i] - r[j, j] - r[m, m]) * 2
        out = np.empty(4)
        out[0] = (r[m, j] - r[j, m]) / s
        out[1 + i] = s / 4
        out[1 + j] = (r[j, i] + r[i, j]) / s
        out[1 + m] = (r[m, i] + r[i, m]) / s
    return out if out[0] >= 0 else -out


def _rotation(quaternion: Array) -> Array:
    """The rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = quaternion
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _header(rows: list[list[str]], label: str, robot: Robot) -> tuple[list[int], bool]:
    """Column indices of the joints then ``x, y, z`` (then ``qw..qz`` if present) in the header
    (which is the first line that is not blank: refused as ``line 1``)."""
    if not rows:
        raise InputError(f"{label}: empty file; expected a header {','.join([*robot.joint_names, *POSITION_COLUMNS])}")
    header = [cell.strip() for cell in rows[0]]
    wanted = [*robot.joint_names, *POSITION_COLUMNS]
    with_rotation = any(name in header for name in QUATERNION_COLUMNS)
    wanted += list(QUATERNION_COLUMNS) if with_rotation else []
    unknown = [name for name in header if name not in wanted]
    missing = [name for name in wanted if name not in header]
    if unknown or missing or len(set(header)) != len(header):
        raise InputError(
            f"{label} line 1: header {shown(','.join(header))}: expected the columns "
            f"{','.join(wanted)} (one each, any order; qw,qx,qy,qz optional)"
        )
    return [header.index(name) for name in wanted], with_rotation


def _row_values(cells: list[str], columns: list[int], names: list[str], where: str) -> Array:
    """One data row's numbers in the order of ``names``; refused naming the row and the column."""
    if len(cells) != len(columns):
        raise InputError(f"{where}: {len(cells)} values: expected {len(columns)}, one per column of the header")
    values = np.empty(len(columns))
    for k, (column, name) in enumerate(zip(columns, names, strict=True)):
        text = cells[column].strip()
        try:
            values[k] = float(text)
        except ValueError:
            raise InputError(f"{where}: {name} = {shown(cut(text, 40))}: expected a number") from None
        if not math.isfinite(values[k]):
            raise InputError(f"{where}: {name} = {text}: expected a finite number")
    return values


def read_measurements(path: str | os.PathLike[str], robot: Robot, *, sensor_offsets: bool = True) -> Measurements:
    """Read a CSV of measured poses: a header naming each joint of ``robot`` and ``x, y, z`` (m),
    optionally ``qw, qx, qy, qz`` (the tool frame's unit quaternion in F0), any column order, one row
    per pose. Each refusal is one :class:`~vgtarm.errors.InputError` line naming the file and the
    row (data rows numbered from 1; the line in the file is one more): a value that is not a finite
    number (NaN), a reading outside the joint limits, a pose the nominal robot cannot assemble, a
    quaternion that is not unit (within 1e-3), too few poses for the calibration's parameters (with
    or without the ``sensor_offsets``)."""
    label = f"measurements {shown(cut(os.fspath(path), 200))}"
    text = read_text_limited(path, MEASUREMENT_FILE_LIMIT, "measurement file")
    reader = csv.reader(io.StringIO(text))
    lines, rows = [], []  # blank lines skipped; each row keeps the line it ends on
    for row in reader:
        if any(cell.strip() for cell in row):
            lines.append(reader.line_num)
            rows.append(row)
    columns, with_rotation = _header(rows, label, robot)
    names = [*robot.joint_names, *POSITION_COLUMNS, *(QUATERNION_COLUMNS if with_rotation else ())]
    table = np.array(
        [
            _row_values(r, columns, names, f"{label} row {k} (line {line})")
            for k, (line, r) in enumerate(zip(lines[1:], rows[1:], strict=True), start=1)
        ]
    ).reshape(-1, len(names))
    n = robot.n_joints
    q, tip = table[:, :n], table[:, n : n + 3]
    rotation = None
    if with_rotation:
        quaternions = table[:, n + 3 :]
        norms = np.linalg.norm(quaternions, axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
        if bad.size:
            k = int(bad[0])
            raise InputError(f"{label} row {k + 1}: quaternion norm {norms[k]:.6g}: expected a unit quaternion")
        rotation = np.array([_rotation(u / np.linalg.norm(u)) for u in quaternions]).reshape(-1, 3, 3)
    measurements = Measurements(q, tip, rotation, source=os.fspath(path))
    check_measurements(robot, measurements, label=label, sensor_offsets=sensor_offsets)
    return measurements


def check_measurements(
    robot: Robot, measurements: Measurements, *, label: str = "measurements", sensor_offsets: bool = True
) -> None:
    """Refuse, in one line naming the row, poses outside the joint limits or that ``robot`` cannot
    assemble, values that are not finite, and too few poses for the calibration's parameters."""
    q, tip = measurements.q, measurements.tip
    n = robot.n_joints
    checks.number_array(f"{label} q", q, (None, n))
    checks.number_array(f"{label} tip", tip, (len(q), 3))
    for name, array in (("q", q), ("tip", tip)):
        bad = np.argwhere(~np.isfinite(array))
        if bad.size:
            k, j = (int(i) for i in bad[0])
            column = robot.joint_names[j] if name == "q" else POSITION_COLUMNS[j]
            raise InputError(f"{label} row {k + 1}: {column} = {array[k, j]}: expected a finite number")
    lower, upper = robot.joint_limits()
    outside = np.argwhere((q < lower) | (q > upper))
    if outside.size:
        k, j = (int(i) for i in outside[0])
        raise InputError(
            f"{label} row {k + 1}: {robot.joint_names[j]} = {q[k, j]:.9g} {robot.joint_units[j]}: expected a reading "
            f"within the joint limits [{lower[j]:.9g}, {upper[j]:.9g}]"
        )
    assembles = robot.is_assemblable(q) if len(q) else np.ones(0, dtype=bool)
    if not assembles.all():
        k = int(np.argmin(assembles))
        raise InputError(f"{label} row {k + 1}: the legs {np.round(q[k], 9).tolist()} cannot be assembled")
    spec = calibration_parameters(robot, sensor_offsets=sensor_offsets)
    rows = 3 + (3 if measurements.rotation is not None else 0)
    if rows * len(q) <= spec.size:
        need = spec.size // rows + 1
        raise InputError(
            f"{label}: {len(q)} poses give {rows * len(q)} residuals for {spec.size} parameters: expected at least "
            f"{need} poses (more than one residual per parameter)"
        )


# -- identifiability -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Identifiability:
    """What the measured poses determine (the SVD of the weighted identification Jacobian).

    Attributes:
        names: ``(m,)`` the parameters (:func:`calibration_parameters`).
        singular_values: ``(m,)`` of the Jacobian weighted by the measurement noise, largest first.
        tolerance: singular values at most this (``rtol`` times the largest) span the null space.
        null_space: ``(m, m - rank)`` orthonormal basis of the undetermined directions.
        status: per parameter ``"determined"`` (no part in the null space), ``"held"`` (kept at its
            nominal value: one per undetermined direction) or ``"given held"`` (determined only once
            the held ones are fixed).
        combinations: the undetermined directions written as combinations of parameters.
        condition_number: of the Jacobian's columns of the free (not held) parameters.
    """

    names: tuple[str, ...]
    singular_values: Array
    tolerance: float
    null_space: Array
    status: tuple[str, ...]
    combinations: tuple[str, ...]
    condition_number: float

    @property
    def rank(self) -> int:
        return len(self.names) - self.null_space.shape[1]

    @property
    def free(self) -> NDArray[np.bool_]:
        """Which parameters are fitted (not held)."""
        return np.array([s != "held" for s in self.status])

    def text(self) -> str:
        """The analysis in a few lines (for a report)."""
        lines = [
            f"rank {self.rank} of {len(self.names)} parameters (singular values above {self.tolerance:.3g}); "
            f"condition number of the free parameters {self.condition_number:.4g}"
        ]
        lines += [f"undetermined: {c}" for c in self.combinations]
        return "\n".join(lines)


def combination_text(vector: Array, names: Sequence[str], *, smallest: float = 1e-3) -> str:
    """``0.707 module2.twist.height - 0.707 end_effector.tool[2]``: a direction of parameters with its
    coefficients (3 digits; below ``smallest`` dropped), its first coefficient positive."""
    kept = np.flatnonzero(np.abs(vector) >= smallest)
    v = vector * (1.0 if not kept.size or vector[kept[0]] > 0 else -1.0)
    text = ""
    for i in kept.tolist():
        c, name = float(v[i]), names[i]
        text += (
            f"{'-' if c < 0 else ''}{abs(c):.3g} {name}"
            if not text
            else f" {'-' if c < 0 else '+'} {abs(c):.3g} {name}"
        )
    return text


def _weights(model: ToolModel, count: int, position_noise: float, orientation_noise: float) -> Array:
    """``(count, rows)`` 1/noise of each residual row (1/m, 1/rad)."""
    row = [1.0 / position_noise] * 3 + ([1.0 / orientation_noise] * 3 if model.orientation else [])
    return np.tile(np.array(row), (count, 1))


def identifiability_of(jacobian: Array, names: Sequence[str], *, rtol: float = DEFAULT_RTOL) -> Identifiability:
    """:class:`Identifiability` of a weighted identification Jacobian ``(rows, m)``."""
    m = len(names)
    _, s, vt = np.linalg.svd(jacobian, full_matrices=len(jacobian) < m)  # every right vector, U thin
    s = np.concatenate([s, np.zeros(m - len(s))]) if len(s) < m else s
    tolerance = rtol * float(s[0]) if len(s) else 0.0
    rank = int(np.count_nonzero(s > tolerance))
    null = vt[rank:].T
    status = ["determined"] * m
    if null.shape[1]:
        part = np.linalg.norm(null, axis=1)
        # one held parameter per undetermined direction: a pivoted QR of the null basis' rows, later
        # parameters first (a tool offset is held before the twist height it shares a direction with)
        bias = 1.0 + 1e-9 * np.arange(m)[::-1]  # ties (equal parts) go to the later parameter
        _, _, pivots = scipy.linalg.qr(null.T[:, ::-1] * bias, pivoting=True)
        held = {m - 1 - int(i) for i in pivots[: null.shape[1]]}
        for i in range(m):
            if i in held:
                status[i] = "held"
            elif part[i] > NULL_PART_TOLERANCE:
                status[i] = "given held"
    free = np.array([x != "held" for x in status])
    sf = np.linalg.svd(jacobian[:, free], compute_uv=False) if free.any() else np.ones(1)
    condition = float(sf[0] / sf[-1]) if sf[-1] > 0 else math.inf
    combinations = tuple(combination_text(null[:, k], names) for k in range(null.shape[1]))
    return Identifiability(tuple(names), s, tolerance, null, tuple(status), combinations, condition)


def identifiability(
    robot: Robot,
    measurements: Measurements | ArrayLike,
    *,
    values: ArrayLike | None = None,
    rtol: float = DEFAULT_RTOL,
    position_noise: float = DEFAULT_POSITION_NOISE,
    orientation_noise: float = DEFAULT_ORIENTATION_NOISE,
    sensor_offsets: bool = True,
) -> Identifiability:
    """Which parameters the poses determine, at the parameters ``values`` (default nominal).

    ``measurements``: :class:`Measurements` (its orientation rows count if it has them) or joint
    readings ``(K, n)`` (positions only)."""
    rtol = checks.number("rtol", rtol, above=0, below=1)
    model, q, rotation = _model_of(robot, measurements, sensor_offsets)
    x = model.spec.nominal if values is None else checks.finite_array("values", values, (model.spec.size,))
    weights = _weights(model, len(q), position_noise, orientation_noise)
    return _identifiability(model, q, rotation, x, weights, rtol)


def _identifiability(
    model: ToolModel, q: Array, rotation: Array | None, x: Array, weights: Array, rtol: float
) -> Identifiability:
    _, J = model.evaluate(q, x, rotation)
    if not np.isfinite(J).all():
        raise InputError("measurements: the model cannot be assembled at some pose for these parameter values")
    return identifiability_of((J * weights[:, :, None]).reshape(-1, model.spec.size), model.spec.names, rtol=rtol)


def _model_of(
    robot: Robot, measurements: Measurements | ArrayLike, sensor_offsets: bool
) -> tuple[ToolModel, Array, Array | None]:
    if isinstance(measurements, Measurements):
        model = ToolModel(robot, orientation=measurements.rotation is not None, sensor_offsets=sensor_offsets)
        return model, measurements.q, measurements.rotation
    q = checks.finite_array("q", measurements, (None, robot.n_joints))
    return ToolModel(robot, sensor_offsets=sensor_offsets), q, None


# -- choosing the poses ----------------------------------------------------------------------------


@dataclass(frozen=True)
class PosePlan:
    """Poses chosen to make the identification Jacobian well conditioned.

    Attributes:
        q: ``(K, n)`` joint values to command and read (m, rad).
        tip: ``(K, 3)`` the nominal robot's tool point there (m), where to aim the instrument.
        condition_number: of the Jacobian's free columns over the chosen poses.
        random_condition_numbers: the same for ``trials`` sets of ``K`` random candidates (seeded).
        smallest_singular_value: of the Jacobian (m/m) of the free parameters over the chosen poses:
            the noise (m) divided by it is the standard error of the worst-determined direction.
        identifiability: the analysis over the chosen poses.
        candidates: how many assemblable random configurations they were chosen from.
        seed: the seed of the candidates and of the random comparison.
    """

    q: Array
    tip: Array
    condition_number: float
    random_condition_numbers: Array
    smallest_singular_value: float
    identifiability: Identifiability
    candidates: int
    seed: int

    def to_csv(self, joint_names: Sequence[str]) -> str:
        """The poses as a measurement file's columns (joints, then the nominal ``x, y, z`` to replace
        with the measured ones)."""
        return Measurements(self.q, self.tip).to_csv(joint_names)


def candidate_poses(robot: Robot, count: int, *, seed: int = 0, margin: float = DEFAULT_MARGIN) -> Array:
    """Up to ``count`` random joint configurations ``(N, n)``, uniform within the joint limits less
    :data:`LIMIT_FRACTION` of each span, that ``robot`` assembles with ``margin`` (m) to spare."""
    count = checks.whole("candidates", count, 1, 10**6)
    seed = checks.seed("seed", seed)
    margin = checks.number("margin", margin, minimum=0, unit="m")
    lower, upper = robot.joint_limits()
    inset = LIMIT_FRACTION * (upper - lower)
    rng = np.random.default_rng(seed)
    q = lower + inset + (upper - lower - 2 * inset) * rng.random((count, robot.n_joints))
    return q[robot.is_assemblable(q, margin)]


def _greedy_d_optimal(blocks: Array, k: int) -> list[int]:
    """Indices of ``k`` blocks (``(N, rows, m)``) chosen one at a time, each the one that most raises
    ``log det(A)``, ``A = eps I + sum J_i^T J_i`` (a regularised D-optimal design)."""
    m = blocks.shape[2]
    scale = float(np.mean(np.einsum("nrm,nrm->n", blocks, blocks))) / m
    A_inv = np.eye(m) / (1e-6 * scale)
    chosen: list[int] = []
    available = np.ones(len(blocks), dtype=bool)
    eye = np.eye(blocks.shape[1])
    for _ in range(k):
        # det(A + J^T J) = det(A) det(I + J A^-1 J^T)
        S = eye + (blocks @ A_inv) @ blocks.transpose(0, 2, 1)
        gain = np.linalg.slogdet(S)[1]
        gain[~available] = -np.inf
        best = int(np.argmax(gain))
        chosen.append(best)
        available[best] = False
        J = blocks[best]
        middle = np.linalg.inv(eye + J @ A_inv @ J.T)
        A_inv = A_inv - A_inv @ J.T @ middle @ J @ A_inv  # Woodbury
    return chosen


def _exchange(blocks: Array, chosen: list[int], passes: int, tries: int, rng: np.random.Generator) -> list[int]:
    """Lower the condition number of the chosen blocks by exchanges: for each chosen pose in turn,
    ``tries`` random candidates take its place, the best kept if it lowers the condition number."""
    chosen = list(chosen)
    best = _condition(blocks[chosen])
    for _ in range(passes):
        for position in range(len(chosen)):
            for candidate in rng.choice(len(blocks), min(tries, len(blocks)), replace=False).tolist():
                if candidate in chosen:
                    continue
                trial = chosen.copy()
                trial[position] = candidate
                value = _condition(blocks[trial])
                if value < best:
                    best, chosen = value, trial
    return chosen


def _condition(blocks: Array) -> float:
    s = np.linalg.svd(blocks.reshape(-1, blocks.shape[2]), compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else math.inf


def plan_poses(
    robot: Robot,
    poses: int = DEFAULT_POSES,
    *,
    candidates: int = DEFAULT_CANDIDATES,
    seed: int = 0,
    margin: float = DEFAULT_MARGIN,
    trials: int = 20,
    passes: int = 1,
    tries: int = 100,
    rtol: float = DEFAULT_RTOL,
    sensor_offsets: bool = True,
) -> PosePlan:
    """Choose ``poses`` measurement poses among ``candidates`` seeded random configurations (within
    the limits, assembled with ``margin`` m to spare; the arm's redundancy gives many joint sets for
    each tool point): a greedy D-optimal design on the free parameters' Jacobian (positions only),
    then ``passes`` of exchanges (each chosen pose against ``tries`` random candidates) that lower its
    condition number; compared with ``trials`` random choices of as many candidates."""
    poses = checks.whole("poses", poses, 1, 10**5)
    passes = checks.whole("passes", passes, 0, 100)
    tries = checks.whole("tries", tries, 1, 10**6)
    trials = checks.whole("trials", trials, 1, 10**4)
    q = candidate_poses(robot, candidates, seed=seed, margin=margin)
    spec = calibration_parameters(robot, sensor_offsets=sensor_offsets)
    if 3 * poses <= spec.size:
        checks.refuse("poses", poses, f"more than {spec.size // 3} poses (3 residuals each for {spec.size} parameters)")
    if len(q) < poses:
        raise InputError(
            f"candidates = {candidates}: only {len(q)} of them assemble with margin {margin:g} m; expected at least "
            f"poses = {poses} (give more candidates or a smaller margin)"
        )
    model = ToolModel(robot, sensor_offsets=sensor_offsets)
    _, J = model.evaluate(q, spec.nominal)
    whole = identifiability_of(J.reshape(-1, spec.size), spec.names, rtol=rtol)
    blocks = J[:, :, whole.free] / DEFAULT_POSITION_NOISE
    rng = np.random.default_rng([seed, 1])
    chosen = _exchange(blocks, _greedy_d_optimal(blocks, poses), passes, tries, rng)
    randoms = np.array([_condition(blocks[rng.choice(len(q), poses, replace=False)]) for _ in range(trials)])
    analysis = identifiability_of(J[chosen].reshape(-1, spec.size) / DEFAULT_POSITION_NOISE, spec.names, rtol=rtol)
    s = np.linalg.svd(blocks[chosen].reshape(-1, blocks.shape[2]), compute_uv=False)
    tip = robot.tip_position(q[chosen])
    smallest = float(s[-1]) * DEFAULT_POSITION_NOISE
    return PosePlan(q[chosen], tip, _condition(blocks[chosen]), randoms, smallest, analysis, len(q), seed)


# -- the fit ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Calibration:
    """The identified parameters and the corrected robot.

    Attributes:
        names: ``(m,)`` the parameters (:func:`calibration_parameters`).
        nominal: ``(m,)`` the robot file's values (m).
        values: ``(m,)`` the fitted values; a ``held`` parameter keeps its nominal value.
        standard_errors: ``(m,)`` (m); NaN for a held parameter (undetermined: no value is made up).
        covariance: ``(m, m)`` of the fitted values (zero rows and columns for the held ones).
        identifiability: the analysis at the fitted values (statuses, undetermined combinations).
        residuals: ``(K, rows)`` measured less fitted (m; then rad for the orientation rows).
        nominal_residuals: ``(K, rows)`` measured less the nominal model's.
        rms_residual: RMS of the position residuals (m).
        sigma: the noise estimated from the weighted residuals (``sqrt(RSS / (rows - free))``, in
            units of the assumed noise: about 1 when the assumed noise is right).
        iterations, evaluations: Levenberg-Marquardt iterations and model evaluations (each gives
            the residuals and the Jacobian).
        success, message: whether it converged, and why it stopped.
        seconds: wall time of the fit (s).
        parameters: the corrected robot's parameters (its lengths fitted).
    """

    names: tuple[str, ...]
    nominal: Array
    values: Array
    standard_errors: Array
    covariance: Array
    identifiability: Identifiability
    residuals: Array
    nominal_residuals: Array
    rms_residual: float
    sigma: float
    iterations: int
    evaluations: int
    success: bool
    message: str
    seconds: float
    parameters: RobotParameters | Stack = field(repr=False)

    @property
    def status(self) -> tuple[str, ...]:
        return self.identifiability.status

    @property
    def offsets(self) -> dict[str, float]:
        """The sensor offsets by joint name (m): subtract them from the readings."""
        return {
            n[len("offset.") :]: float(v)
            for n, v in zip(self.names, self.values, strict=True)
            if n.startswith("offset.")
        }

    def table(self) -> str:
        """The parameters as a Markdown table (mm): nominal, fitted, change, standard error, status."""
        lines = [
            "| parameter | nominal (mm) | fitted (mm) | change (mm) | std. error (mm) | status |",
            "|---|---|---|---|---|---|",
        ]
        for name, x0, x, se, status in zip(
            self.names, self.nominal, self.values, self.standard_errors, self.status, strict=True
        ):
            if status == "held":
                lines.append(f"| {name} | {1e3 * x0:.4f} | undetermined | | | held at nominal |")
            else:
                lines.append(
                    f"| {name} | {1e3 * x0:.4f} | {1e3 * x:.4f} | {1e3 * (x - x0):+.4f} | {1e3 * se:.4f} | {status} |"
                )
        return "\n".join(lines)

    def figure(self, ax: Any = None) -> Any:
        """Bar chart of each pose's position residual (mm), nominal model against calibrated; returns
        the figure (on ``ax`` if given; never shown)."""
        from matplotlib.figure import Figure

        if ax is None:
            ax = Figure(figsize=(8, 3.5), layout="constrained").add_subplot()
        poses = np.arange(1, len(self.residuals) + 1)
        before = 1e3 * np.linalg.norm(self.nominal_residuals[:, :3], axis=1)
        after = 1e3 * np.linalg.norm(self.residuals[:, :3], axis=1)
        ax.bar(poses - 0.2, before, width=0.4, label="nominal model")
        ax.bar(poses + 0.2, after, width=0.4, label="calibrated model")
        if (before > 0).all() and (after > 0).all():  # exact data has zero residuals
            ax.set_yscale("log")
        ax.set_xlabel("pose")
        ax.set_ylabel("position residual (mm)")
        ax.set_title(f"RMS residual {1e3 * self.rms_residual:.4f} mm per coordinate after calibration")
        ax.legend()
        return ax.figure

    def robot_toml(self) -> str:
        """The corrected robot file in the input's format (a stack's or the paper robot's)."""
        return robot_toml(self.parameters, header=self._header())

    def _header(self) -> str:
        lines = [
            WRITTEN_MARK[2:] + f": lengths fitted to {len(self.residuals)} measured poses",
            f"RMS position residual {1e3 * self.rms_residual:.4g} mm; undetermined: "
            + ("; ".join(self.identifiability.combinations) or "none"),
            "Sensor zero offsets (m; subtract from the readings): "
            + (", ".join(f"{k} {v:+.6g}" for k, v in self.offsets.items()) or "none fitted"),
        ]
        return "\n".join(lines)


@dataclass
class CalibrationProblem:
    """The weighted least-squares problem of the free parameters ``z`` (the held ones at nominal):
    residuals ``(model - measured) / noise`` and their Jacobian (the AD one), for :func:`calibrate`'s
    solver or another (``scipy.optimize.least_squares(problem.residuals, problem.z0,
    jac=problem.jacobian)``). ``evaluations`` counts the model's evaluations."""

    model: ToolModel
    q: Array
    target: Array
    weights: Array
    rotation: Array | None
    x0: Array
    free: NDArray[np.bool_]
    evaluations: int = 0

    def full(self, z: Array) -> Array:
        x = self.x0.copy()
        x[self.free] = z
        return x

    @property
    def z0(self) -> Array:
        """The free parameters' nominal values."""
        return self.x0[self.free].copy()

    def residuals(self, z: Array) -> Array:
        """Weighted residuals ``(rows,)`` alone (one evaluation of the model without its Jacobian)."""
        self.evaluations += 1
        y = self.model.values(self.q, self.full(z), self.rotation)
        return ((y - self.target) * self.weights).ravel()

    def jacobian(self, z: Array) -> Array:
        """The Jacobian ``(rows, free)`` of :meth:`residuals`."""
        return self.residual_and_jacobian(z)[1]

    def residual_and_jacobian(self, z: Array) -> tuple[Array, Array]:
        """Weighted residuals ``(rows,)`` (model less measured) and their Jacobian ``(rows, free)``."""
        self.evaluations += 1
        y, J = self.model.evaluate(self.q, self.full(z), self.rotation)
        r = ((y - self.target) * self.weights).ravel()
        return r, (J * self.weights[:, :, None]).reshape(len(r), -1)[:, self.free]


def _levenberg_marquardt(
    problem: CalibrationProblem, z0: Array, max_iterations: int, tolerance: float
) -> tuple[Array, int, bool, str]:
    """Minimise ``|r(z)|^2`` from ``z0``: Levenberg-Marquardt with Marquardt's scaling and Nielsen's
    damping update; stops when a step changes no parameter by more than ``tolerance`` times its size
    (plus ``tolerance`` m), or the gradient vanishes. A step whose residuals are not finite (a pose
    that cannot be assembled) is refused like one that raises the cost."""
    z = z0.copy()
    r, J = problem.residual_and_jacobian(z)
    if not (np.isfinite(r).all() and np.isfinite(J).all()):
        return z, 0, False, "the nominal parameters cannot assemble every measured pose"
    cost, lam, nu = float(r @ r), 1e-6, 2.0  # nearly Gauss-Newton from the start: a small-residual problem
    for iteration in range(1, max_iterations + 1):
        g, H = J.T @ r, J.T @ J
        if np.abs(g).max() <= 1e-30 + 1e-15 * cost:
            return z, iteration, True, "gradient vanished"
        newton = np.linalg.lstsq(H, -g, rcond=None)[0]  # the undamped step: the optimum is within it
        if np.all(np.abs(newton) <= tolerance * (np.abs(z) + 1.0)):
            return z, iteration, True, "Gauss-Newton step below tolerance"
        diag = np.diag(H).copy()
        step = np.linalg.solve(H + lam * np.diag(diag), -g)
        trial = z + step
        r1, J1 = problem.residual_and_jacobian(trial)
        cost1 = float(r1 @ r1) if np.isfinite(r1).all() and np.isfinite(J1).all() else math.inf
        predicted = float(-(step @ g) + lam * step @ (diag * step))  # the linear model's decrease
        rho = (cost - cost1) / predicted if predicted > 0 else -1.0
        if rho > 0:
            z, r, J, cost = trial, r1, J1, cost1
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            if np.all(np.abs(step) <= tolerance * (np.abs(z) + 1.0)):
                return z, iteration, True, "step below tolerance"
        else:
            lam *= nu
            nu *= 2.0
            if lam > 1e16:
                return z, iteration, False, "no step lowers the cost (damping beyond 1e16)"
    return z, max_iterations, False, f"not converged in {max_iterations} iterations"


def least_squares_problem(
    robot: Robot,
    measurements: Measurements,
    *,
    position_noise: float = DEFAULT_POSITION_NOISE,
    orientation_noise: float = DEFAULT_ORIENTATION_NOISE,
    rtol: float = DEFAULT_RTOL,
    sensor_offsets: bool = True,
) -> CalibrationProblem:
    """The problem :func:`calibrate` solves (:class:`CalibrationProblem`), for another solver."""
    return _problem(robot, measurements, position_noise, orientation_noise, rtol, sensor_offsets)[0]


def _problem(
    robot: Robot,
    measurements: Measurements,
    position_noise: float,
    orientation_noise: float,
    rtol: float,
    sensor_offsets: bool,
) -> tuple[CalibrationProblem, Identifiability]:
    if not isinstance(measurements, Measurements):
        checks.refuse("measurements", measurements, "Measurements (vgtarm.calibration.kinematic.read_measurements)")
    position_noise = checks.positive("position_noise", position_noise, "m")
    orientation_noise = checks.positive("orientation_noise", orientation_noise, "rad")
    check_measurements(robot, measurements, sensor_offsets=sensor_offsets)
    model = ToolModel(robot, orientation=measurements.rotation is not None, sensor_offsets=sensor_offsets)
    count = len(measurements)
    target = measurements.tip if not model.orientation else np.column_stack([measurements.tip, np.zeros((count, 3))])
    weights = _weights(model, count, position_noise, orientation_noise)
    rtol = checks.number("rtol", rtol, above=0, below=1)
    x0 = model.spec.nominal.copy()
    analysis = _identifiability(model, measurements.q, measurements.rotation, x0, weights, rtol)
    problem = CalibrationProblem(model, measurements.q, target, weights, measurements.rotation, x0, analysis.free)
    return problem, analysis


def calibrate(
    robot: Robot,
    measurements: Measurements,
    *,
    position_noise: float = DEFAULT_POSITION_NOISE,
    orientation_noise: float = DEFAULT_ORIENTATION_NOISE,
    rtol: float = DEFAULT_RTOL,
    max_iterations: int = 100,
    tolerance: float = 1e-10,
    sensor_offsets: bool = True,
) -> Calibration:
    """Fit the lengths and sensor offsets of ``robot`` to the measured poses (without
    ``sensor_offsets``: the lengths alone, the leg sensors trusted to read true lengths).

    The undetermined directions (:func:`identifiability` at the nominal values) are removed by
    holding one parameter each at its nominal value; the others are fitted by Levenberg-Marquardt
    on the residuals weighted by ``position_noise`` (m) and ``orientation_noise`` (rad), with the
    AD Jacobian. Standard errors: ``sigma^2 (J^T J)^-1`` at the optimum, ``sigma^2`` the weighted
    residual variance (``RSS / (rows - free)``), so they hold whatever the true noise."""
    max_iterations = checks.whole("max_iterations", max_iterations, 1, 10**6)
    tolerance = checks.positive("tolerance", tolerance)
    start = time.perf_counter()
    problem, _ = _problem(robot, measurements, position_noise, orientation_noise, rtol, sensor_offsets)
    z, iterations, success, message = _levenberg_marquardt(problem, problem.x0[problem.free], max_iterations, tolerance)
    seconds = time.perf_counter() - start
    return _result(robot, problem, z, iterations, success, message, seconds, rtol)


def _result(
    robot: Robot,
    problem: CalibrationProblem,
    z: Array,
    iterations: int,
    success: bool,
    message: str,
    seconds: float,
    rtol: float,
) -> Calibration:
    """The :class:`Calibration` record of the free parameters ``z``."""
    r, J = problem.residual_and_jacobian(z)
    x = problem.full(z)
    m, free = len(x), problem.free
    dof = max(len(r) - int(free.sum()), 1)
    sigma2 = float(r @ r) / dof
    covariance = np.zeros((m, m))
    if np.isfinite(J).all():
        covariance[np.ix_(free, free)] = sigma2 * np.linalg.pinv(J.T @ J)
    errors = np.sqrt(np.diag(covariance))
    errors[~free] = np.nan
    analysis = _analysis_at(problem, x, rtol)
    residuals = -(r.reshape(problem.weights.shape) / problem.weights)
    nominal = -(problem.residuals(problem.z0).reshape(problem.weights.shape) / problem.weights)
    rms = float(np.sqrt(np.mean(residuals[:, :3] ** 2)))
    parameters = corrected_parameters(robot, x)
    return Calibration(
        problem.model.spec.names, problem.x0.copy(), x, errors, covariance, analysis, residuals, nominal, rms,
        math.sqrt(sigma2), iterations, problem.evaluations, success, message, seconds, parameters,
    )  # fmt: skip


def _analysis_at(problem: CalibrationProblem, x: Array, rtol: float) -> Identifiability:
    """The identifiability at the fitted values, keeping the held parameters chosen at nominal."""
    y, J = problem.model.evaluate(problem.q, x, problem.rotation)
    weighted = (J * problem.weights[:, :, None]).reshape(-1, len(x))
    if not np.isfinite(weighted).all():
        weighted = np.nan_to_num(weighted)
    found = identifiability_of(weighted, problem.model.spec.names, rtol=rtol)
    if found.free.tolist() == problem.free.tolist():
        return found
    status = tuple(
        "held" if not f else ("given held" if s == "held" else s)
        for f, s in zip(problem.free, found.status, strict=True)
    )
    return replace(found, status=status)


# -- the corrected robot file ----------------------------------------------------------------------


def robot_toml(parameters: RobotParameters | Stack, *, header: str = "") -> str:
    """The robot file of ``parameters`` in its own format (a stack's or the paper robot's):
    :func:`vgtarm.model.stack.robot_to_toml`."""
    if not isinstance(parameters, RobotParameters | Stack):
        checks.refuse("parameters", parameters, "RobotParameters or a Stack")
    return robot_to_toml(parameters, header=header)


def write_robot_file(path: str | os.PathLike[str], text: str, *, inputs: Sequence[str | os.PathLike[str]] = ()) -> Path:
    """Write a robot file atomically; an existing file is replaced only if vgtarm calibrate wrote it
    (its first line is :data:`WRITTEN_MARK`), else refused with an :class:`~vgtarm.fileio.OutputPathError`."""
    target = check_output_file(path, "robot file", inputs=inputs)
    if target.exists():
        with open(target, encoding="utf-8", errors="replace") as stream:
            first = stream.readline()
        if not first.startswith(WRITTEN_MARK):
            raise OutputPathError(
                f"robot file {shown(cut(os.fspath(path), 200))}: exists and was not written by vgtarm calibrate; "
                "give a new name (vgtarm never overwrites a file it did not write)",
                path,
            )
    if not text.startswith(WRITTEN_MARK):
        text = f"{WRITTEN_MARK}\n{text}"
    return atomic_write_text(target, text, "robot file")


# -- synthetic data --------------------------------------------------------------------------------


def perturbed_values(robot: Robot, *, seed: int = 0, lengths: float = 2e-3, offsets: float = 2e-3) -> Array:
    """Calibration parameters ``(m,)`` with every length moved by a uniform amount within
    ``+-lengths`` and every sensor offset within ``+-offsets`` (m), seeded: a "built" robot."""
    spec = calibration_parameters(robot)
    lengths = checks.number("lengths", lengths, minimum=0, unit="m")
    offsets = checks.number("offsets", offsets, minimum=0, unit="m")
    rng = np.random.default_rng(checks.seed("seed", seed))
    bound = np.concatenate([np.full(spec.n_lengths, lengths), np.full(spec.size - spec.n_lengths, offsets)])
    return spec.nominal + bound * rng.uniform(-1.0, 1.0, spec.size)


def synthetic_measurements(
    robot: Robot,
    q: ArrayLike,
    values: ArrayLike,
    *,
    noise: float = DEFAULT_POSITION_NOISE,
    orientation_noise: float = 0.0,
    orientation: bool = False,
    seed: int = 0,
) -> Measurements:
    """What an instrument would measure on the robot of calibration parameters ``values`` at the
    joint readings ``q`` ``(K, n)``: its tool points with Gaussian noise of ``noise`` (m) on each
    coordinate (seeded) and, with ``orientation``, its tool frames turned by Gaussian angles of
    ``orientation_noise`` (rad) about each axis."""
    spec = calibration_parameters(robot)
    x = checks.finite_array("values", values, (spec.size,))
    readings = checks.finite_array("q", q, (None, robot.n_joints))
    noise = checks.number("noise", noise, minimum=0, unit="m")
    rng = np.random.default_rng(checks.seed("seed", seed))
    built = robot.with_parameters(corrected_parameters(robot, x))
    true_q = readings.copy()
    true_q[:, list(spec.offset_joint)] -= x[spec.n_lengths :]
    tip, rotation = built.tool_frame(true_q)
    tip = tip + noise * rng.standard_normal(tip.shape)
    if not orientation:
        return Measurements(readings, tip, None, source="<synthetic>")
    angles = orientation_noise * rng.standard_normal((len(readings), 3))
    turned = np.array([r @ _exp(a) for r, a in zip(rotation, angles, strict=True)]).reshape(-1, 3, 3)
    return Measurements(readings, tip, turned, source="<synthetic>")


def _exp(w: Array) -> Array:
    """The rotation of the rotation vector ``w`` (rad), Rodrigues' formula."""
    angle = float(np.linalg.norm(w))
    if angle == 0.0:
        return np.eye(3)
    k = w / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


#: Random pose sets :func:`pose_conditioning` compares the measured poses with.
RANDOM_TRIALS = 20


def _condition_number(blocks: np.ndarray) -> float:
    """Largest over smallest singular value of stacked Jacobian blocks ``(K, rows, m)``."""
    s = np.linalg.svd(blocks.reshape(-1, blocks.shape[2]), compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def pose_conditioning(
    robot: Robot, result: Calibration, measurements: Measurements, *, candidates: int, seed: int, sensor_offsets: bool
) -> dict[str, Any]:
    """How well the measured poses condition the identification: the condition number of the free
    parameters' Jacobian over them (positions only, at the fitted values), and the same for
    :data:`RANDOM_TRIALS` sets of as many random poses (``candidates`` seeded configurations within
    the limits, :func:`~vgtarm.calibration.kinematic.candidate_poses`), as ``plan.md`` compares a plan."""
    model = ToolModel(robot, sensor_offsets=sensor_offsets)
    free = result.identifiability.free
    _, jacobian = model.evaluate(measurements.q, result.values)
    found: dict[str, Any] = {"condition_number": _condition_number(jacobian[:, :, free]), "random": None}
    pool = candidate_poses(robot, candidates, seed=seed)
    count = len(measurements)
    if len(pool) < count:
        return found
    _, blocks = model.evaluate(pool, result.values)
    blocks = blocks[:, :, free]
    usable = np.isfinite(blocks).all(axis=(1, 2))
    blocks = blocks[usable]
    if len(blocks) < count:
        return found
    rng = np.random.default_rng([seed, 1])
    values = np.array(
        [_condition_number(blocks[rng.choice(len(blocks), count, replace=False)]) for _ in range(RANDOM_TRIALS)]
    )
    found["random"] = {
        "trials": RANDOM_TRIALS,
        "candidates": len(blocks),
        "seed": seed,
        "median": float(np.median(values)),
        "best": float(values.min()),
        "worst": float(values.max()),
    }
    return found
