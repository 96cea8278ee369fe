"""A robot described as a stack of planar VGT modules: frozen, validated dataclasses and TOML.

A stack is an ordered list of modules, base first. Module ``k`` (numbered from 1) has the base
and platform half-widths ``b > d``, its three leg coordinates ``s_k, v_k, p_k`` with their limits
and home values, its platform body, and the angle of its operating plane about the stack axis
(degrees, measured in the frame it stands on; the paper's robot: 0 and 90). A twist joint may
follow any module: it turns what stands above that module about the platform normal, and its
part has a height along that normal (the mount point of the next module, or of the tool). The
end-effector body rides on the last frame; the tool point is given from the last mount point,
and the tool's orientation in the end-effector frame (F3 of the paper's robot) by its axis (the
direction a drill advances) and its edge (a blade's cutting edge): the tool frame has ``z`` along
the axis and ``x`` along the edge (:attr:`Stack.tool_rotation`; by default the identity).

Joints are numbered along the chain: ``s1, v1, p1, [psi2], s2, v2, p2, [psi3], ...``. The twist
joint after module ``k`` is ``psi{k+1}``: it turns the frame between module ``k`` and module
``k+1`` (frame ``F3`` of the paper's robot, whose twist after module 2 stays ``psi3``).

The file format (see ``examples/paper_robot.toml``)::

    name = "..."                       # optional
    [[modules]]                        # one table per module, base first
    b = 0.15                           # base half-width (m)
    d = 0.10                           # platform half-width (m), d < b
    plane = 0.0                        # operating-plane angle about the stack axis (degrees)
    limits = { s = [0.22, 0.36], v = [0.22, 0.36], p = [0.30, 0.46] }   # [min, max] (m)
    home = [0.284, 0.284, 0.375]       # s, v, p at the home pose (m)
    viscous = [200.0, 200.0, 200.0]    # optional, N s/m (default 0)
    platform = { mass = 2.75, com = [0, 0, 0], inertia = [[...], [...], [...]] }
    [modules.twist]                    # optional: a twist joint after this module
    height = 0.10                      # from the platform centre to the mount point (m)
    limits = [-3.14159, 3.14159]       # rad
    home = 0.0                         # optional (rad, default 0)
    viscous = 0.0                      # optional (N m s/rad, default 0)
    body = { mass = ..., com = ..., inertia = ... }   # optional: the twist part (twist frame)
    [end_effector]                     # the body on the last frame (its origin: last platform centre)
    mass = 0.75
    com = [0.0, 0.0, 0.05]
    inertia = [[...], [...], [...]]
    tool = [0.0, 0.0, 0.0]             # optional: tip point from the last mount point (m)
    tool_axis = [0.0, 0.0, 1.0]        # optional: the tool's axis, a unit vector in F3
    tool_edge = [1.0, 0.0, 0.0]        # optional: its edge, a unit vector in F3 perpendicular to the axis
    [environment]
    gravity = [0.0, 0.0, -9.81]        # optional
    [actuators]                        # optional: vgtarm.model.actuators
    [stiffness]                        # optional: each joint's stiffness (N/m, N m/rad), by group
    legs = 2.0e5                       # or by joint (p1 = 3.0e5); see vgtarm.model.parameters.JointStiffness

Validation happens when a :class:`Stack` is built (from a file or directly), so a bad stack fails
with a :class:`~vgtarm.errors.ConfigError` of one line naming the module and the field
(``module2.d``, ``module3.twist.limits``...), the value and what was expected.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from ... import checks
from ...errors import ConfigError, cut, shown
from ...fileio import parse_toml, read_text_limited
from ...kinds import other_toml
from ..actuators import Actuators, read_actuators
from ..assembly import TRIANGLE_INEQUALITIES, linear_form
from ..factors import model_factor
from ..parameters import (
    _RENAMED,
    _SOURCE_LENGTH,
    MAX_FRICTION,
    MAX_GRAVITY,
    MAX_LENGTH,
    MAX_MASS,
    NAME_LENGTH,
    ROBOT_FILE_LIMIT,
    Body,
    JointStiffness,
    RobotParameters,
    _Reader,
    check_actuators,
    check_body,
    check_stiffness,
    fail_field,
    load_parameters,
    read_stiffness,
)

#: Most modules a stack may have (a bound on the size of the model, far beyond any arm built).
MAX_MODULES = 50
#: Largest magnitude of an operating-plane angle (degrees).
MAX_PLANE = 360.0
#: Names of a module's three leg coordinates, in the order of the joint vector.
LEG_NAMES: tuple[str, str, str] = ("s", "v", "p")
#: Passive angles of one module, in the order of the kinematics' ``passive`` output.
PASSIVE_NAMES: tuple[str, str, str, str] = ("alpha", "beta", "gamma", "theta")
#: Length of one body in :meth:`Stack.vector`: mass, com (3), Ixx, Iyy, Izz, Ixy, Ixz, Iyz.
BODY_VALUES = 10
#: The default tool axis and edge (in the end-effector frame): the identity tool frame.
TOOL_AXIS: tuple[float, float, float] = (0.0, 0.0, 1.0)
TOOL_EDGE: tuple[float, float, float] = (1.0, 0.0, 0.0)
#: How far the tool's axis and edge may be from unit length, and their dot product from 0.
TOOL_FRAME_TOLERANCE = 1e-9
_TOLERANCE_TEXT = "1e-9"


@dataclass(frozen=True)
class Twist:
    """A twist joint after a module: it turns everything above about the platform normal.

    ``height`` (m) goes from the platform centre, along the normal, to the mount point of what
    follows; ``limits`` and ``home`` are in rad, ``viscous`` in N m s/rad; ``body`` is the twist
    part (in the twist frame, origin at the platform centre), or ``None`` for a massless part.
    """

    height: float
    limits: tuple[float, float]
    home: float = 0.0
    viscous: float = 0.0
    body: Body | None = None


@dataclass(frozen=True)
class StackModule:
    """One planar VGT module of a stack (see the module docstring for the meaning of each field).

    ``limits`` and ``home`` are ``(s, v, p)`` (m); ``plane`` is in degrees; ``platform`` is given
    in the platform frame (origin at the platform centre); ``viscous`` in N s/m per leg.
    """

    b: float
    d: float
    plane: float
    limits: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    home: tuple[float, float, float]
    platform: Body
    viscous: tuple[float, float, float] = (0.0, 0.0, 0.0)
    twist: Twist | None = None


@dataclass(frozen=True)
class Stack:
    """A manipulator made of stacked VGT modules. Build with :func:`load_stack` or directly.

    Every field is checked when the stack is built; ``dataclasses.replace`` checks the copy too.
    """

    name: str
    modules: tuple[StackModule, ...]
    end_effector: Body
    tool: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tool_axis: tuple[float, float, float] = TOOL_AXIS
    tool_edge: tuple[float, float, float] = TOOL_EDGE
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    source: str = field(default="<stack>", compare=False)
    #: The joints' actuators (:mod:`vgtarm.model.actuators`), or ``None``: no limits.
    actuators: Actuators | None = None
    #: The joints' stiffness (the ``[stiffness]`` table), or ``None``: rigid joints.
    stiffness: JointStiffness | None = None

    def __post_init__(self) -> None:
        _validate(self)

    # -- sizes and names -------------------------------------------------------------------

    @property
    def n_modules(self) -> int:
        """Number of modules."""
        return len(self.modules)

    @property
    def n_twists(self) -> int:
        """Number of twist joints."""
        return sum(module.twist is not None for module in self.modules)

    @property
    def n_joints(self) -> int:
        """Number of joints: three per module plus one per twist joint."""
        return 3 * self.n_modules + self.n_twists

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Joint names in the order of ``q``: ``s1, v1, p1, [psi2], s2, ...``."""
        names: list[str] = []
        for k, module in enumerate(self.modules, start=1):
            names += [f"{leg}{k}" for leg in LEG_NAMES]
            if module.twist is not None:
                names.append(f"psi{k + 1}")
        return tuple(names)

    @property
    def joint_units(self) -> tuple[str, ...]:
        """Unit of each joint coordinate (``m`` for legs, ``rad`` for twists)."""
        return tuple("rad" if name.startswith("psi") else "m" for name in self.joint_names)

    @property
    def leg_indices(self) -> tuple[tuple[int, int, int], ...]:
        """Indices in ``q`` of each module's ``(s, v, p)``."""
        indices: list[tuple[int, int, int]] = []
        i = 0
        for module in self.modules:
            indices.append((i, i + 1, i + 2))
            i += 3 + (module.twist is not None)
        return tuple(indices)

    @property
    def body_names(self) -> tuple[str, ...]:
        """Bodies in the order of the model: platforms, twist parts (after their module), end-effector."""
        names: list[str] = []
        for k, module in enumerate(self.modules, start=1):
            names.append(f"platform{k}")
            if module.twist is not None and module.twist.body is not None:
                names.append(f"twist{k + 1}")
        return (*names, "end_effector")

    @property
    def bodies(self) -> tuple[Body, ...]:
        """The bodies, in the order of :attr:`body_names`."""
        found: list[Body] = []
        for module in self.modules:
            found.append(module.platform)
            if module.twist is not None and module.twist.body is not None:
                found.append(module.twist.body)
        return (*found, self.end_effector)

    # -- joint-space arrays ----------------------------------------------------------------

    def _per_joint(
        self, leg: Callable[[StackModule, int], float], twist: Callable[[Twist], float]
    ) -> NDArray[np.float64]:
        values: list[float] = []
        for module in self.modules:
            values += [leg(module, i) for i in range(3)]
            if module.twist is not None:
                values.append(twist(module.twist))
        return np.array(values, dtype=float)

    @property
    def lower(self) -> NDArray[np.float64]:
        """Lower joint limits, ``(n_joints,)``."""
        return self._per_joint(lambda m, i: m.limits[i][0], lambda t: t.limits[0])

    @property
    def upper(self) -> NDArray[np.float64]:
        """Upper joint limits, ``(n_joints,)``."""
        return self._per_joint(lambda m, i: m.limits[i][1], lambda t: t.limits[1])

    @property
    def home(self) -> NDArray[np.float64]:
        """Home configuration, ``(n_joints,)``."""
        return self._per_joint(lambda m, i: m.home[i], lambda t: t.home)

    @property
    def viscous(self) -> NDArray[np.float64]:
        """Viscous friction coefficient of each joint, ``(n_joints,)``."""
        return self._per_joint(lambda m, i: m.viscous[i], lambda t: t.viscous)

    @property
    def q_min(self) -> tuple[float, ...]:
        """Deprecated: the lower joint limits as a tuple; use :attr:`lower`."""
        warnings.warn(_RENAMED.format(old="q_min", new="lower"), DeprecationWarning, stacklevel=2)
        return tuple(float(x) for x in self.lower)

    @property
    def q_max(self) -> tuple[float, ...]:
        """Deprecated: the upper joint limits as a tuple; use :attr:`upper`."""
        warnings.warn(_RENAMED.format(old="q_max", new="upper"), DeprecationWarning, stacklevel=2)
        return tuple(float(x) for x in self.upper)

    @property
    def q_home(self) -> tuple[float, ...]:
        """Home configuration as a tuple."""
        return tuple(float(x) for x in self.home)

    @property
    def b(self) -> tuple[float, ...]:
        """Base half-width of each module (m)."""
        return tuple(module.b for module in self.modules)

    @property
    def d(self) -> tuple[float, ...]:
        """Platform half-width of each module (m)."""
        return tuple(module.d for module in self.modules)

    @property
    def tool_rotation(self) -> NDArray[np.float64]:
        """The tool frame in the end-effector frame, ``(3, 3)``: its columns are ``edge, axis x edge,
        axis`` (``x`` along the edge, ``z`` along the axis); the identity by default."""
        return tool_rotation(self.tool_axis, self.tool_edge)

    @property
    def total_mass(self) -> float:
        """Sum of the body masses (kg)."""
        return float(sum(body.mass for body in self.bodies))

    def margin_form(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``G`` ``(6 n_modules, n_joints)`` and ``h``: the triangle margins ``G q + h`` of every module,
        six rows per module in the order of :data:`~vgtarm.model.assembly.TRIANGLE_INEQUALITIES`
        (all > 0 to assemble)."""
        G = np.zeros((6 * self.n_modules, self.n_joints))
        h = np.zeros(6 * self.n_modules)
        for k, (module, idx) in enumerate(zip(self.modules, self.leg_indices, strict=True)):
            Gk, hk = linear_form((module.b, module.b), (module.d, module.d))
            G[6 * k : 6 * k + 6, list(idx)] = Gk[:6, :3]
            h[6 * k : 6 * k + 6] = hk[:6]
        return G, h

    def margin_legs(self) -> tuple[tuple[int, int, int], ...]:
        """Indices in ``q`` of each module's legs ``(s, v, p)``, in the order of the margin rows."""
        return self.leg_indices

    def scaled(self, *, mass: float = 1.0, inertia: float = 1.0, friction: float = 1.0) -> Stack:
        """A copy with every body mass, inertia and friction coefficient multiplied by a factor
        (as :meth:`RobotParameters.scaled`; each factor in :data:`~vgtarm.model.factors.MODEL_FACTOR_RANGE`)."""
        mass, inertia, friction = (
            model_factor(label, factor, error=ConfigError)
            for label, factor in (("mass", mass), ("inertia", inertia), ("friction", friction))
        )

        def body(b: Body) -> Body:
            return replace(b, mass=b.mass * mass, inertia=tuple(tuple(x * inertia for x in row) for row in b.inertia))

        modules = []
        for module in self.modules:
            twist = module.twist
            if twist is not None:
                twist = replace(
                    twist,
                    viscous=twist.viscous * friction,
                    body=None if twist.body is None else body(twist.body),
                )
            modules.append(
                replace(
                    module,
                    platform=body(module.platform),
                    viscous=tuple(c * friction for c in module.viscous),  # type: ignore[arg-type]
                    twist=twist,
                )
            )
        return replace(
            self,
            name=f"{self.name} (mass x{mass:g}, inertia x{inertia:g}, friction x{friction:g})",
            modules=tuple(modules),
            end_effector=body(self.end_effector),
        )

    # -- the flat parameter vector ---------------------------------------------------------

    def vector(self) -> NDArray[np.float64]:
        """The flat parameter vector of the symbolic model, ``(n_parameters,)``.

        Layout, module by module: ``b, d``, the platform body; then, if a twist follows, its
        ``height`` and, if it has one, its body. Then the end-effector body, the tool point (3),
        the viscous coefficients (one per joint) and gravity (3). A body is ``mass, com (3),
        Ixx, Iyy, Izz, Ixy, Ixz, Iyz`` (as in :meth:`RobotParameters.vector`). The plane angles
        and which twists exist are the stack's structure, not parameters.
        """
        values: list[float] = []
        for module in self.modules:
            values += [module.b, module.d, *_body_values(module.platform)]
            if module.twist is not None:
                values.append(module.twist.height)
                if module.twist.body is not None:
                    values += _body_values(module.twist.body)
        values += _body_values(self.end_effector)
        values += [*self.tool, *self.viscous, *self.gravity]
        return np.array(values, dtype=float)

    @property
    def n_parameters(self) -> int:
        """Length of :meth:`vector`."""
        return len(self.vector())


def tool_rotation(axis: tuple[float, float, float], edge: tuple[float, float, float]) -> NDArray[np.float64]:
    """The rotation ``[edge, axis x edge, axis]`` (columns) of a tool's axis and edge, ``(3, 3)``.

    The axis and edge are unit and perpendicular within :data:`TOOL_FRAME_TOLERANCE` (a stack's are
    checked); they are made so to round-off here (the axis normalised, the edge's part across it
    normalised), so the result is a rotation. The defaults give the identity exactly."""
    z = np.array(axis, dtype=float)
    z /= math.hypot(*z)
    x = np.array(edge, dtype=float)
    x -= (x @ z) * z
    x /= math.hypot(*x)
    return np.column_stack([x, np.cross(z, x), z])


def _body_values(body: Body) -> list[float]:
    i = body.inertia
    return [body.mass, *body.com, i[0][0], i[1][1], i[2][2], i[0][1], i[0][2], i[1][2]]


# -- assemblability ------------------------------------------------------------------------


def module_margins(legs: NDArray[np.float64], b: float, d: float) -> NDArray[np.float64]:
    """Margins of one module's six triangle inequalities, ``(..., 6)`` (m), for legs ``(..., 3)``.

    In the order of :data:`~vgtarm.model.assembly.TRIANGLE_INEQUALITIES`; all > 0 to assemble.
    (The rows of module 1 of the fixed model's linear form, which hold for any ``b, d``.)
    """
    G, h = linear_form((b, b), (d, d))
    return np.asarray(legs, dtype=float) @ G[:6, :3].T + h[:6]


def stack_margins(stack: Stack, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Triangle margins of every module, ``(..., n_modules, 6)`` (m), for ``q`` ``(..., n_joints)``."""
    qa = np.asarray(q, dtype=float)
    return np.stack(
        [
            module_margins(qa[..., list(idx)], module.b, module.d)
            for module, idx in zip(stack.modules, stack.leg_indices, strict=True)
        ],
        axis=-2,
    )


# -- reading a file ------------------------------------------------------------------------

_TOP_KEYS = {"modules", "end_effector"}
_TOP_OPTIONAL = {"name", "environment", "actuators", "stiffness"}
_MODULE_KEYS = {"b", "d", "plane", "limits", "home", "platform"}
_MODULE_OPTIONAL = {"viscous", "twist"}
_TWIST_KEYS = {"height", "limits"}
_TWIST_OPTIONAL = {"home", "viscous", "body"}
_BODY_KEYS = {"mass", "com", "inertia"}


def load_stack(path: str | os.PathLike[str]) -> Stack:
    """Load a stack from a TOML file (layout in this module's docstring).

    Raises :class:`~vgtarm.errors.ConfigError` with one line naming the file and the field.
    """
    if not isinstance(path, str | os.PathLike):
        raise ConfigError(f"stack file {shown(path)}: expected a file name (str or Path)")
    source = str(path)
    text = read_text_limited(path, ROBOT_FILE_LIMIT, "stack file", error=ConfigError)
    return stack_from_dict(parse_toml(text, cut(source, _SOURCE_LENGTH), error=ConfigError), source=source)


def stack_from_dict(data: Mapping[str, Any], *, source: str = "<dict>") -> Stack:
    """Build a :class:`Stack` from the nested mapping a TOML stack file parses to."""
    other = other_toml(data, "a stack robot file")  # a 7-joint robot or a study file: said in those words
    if other is not None:
        raise ConfigError(f"{cut(str(source), _SOURCE_LENGTH)}: {other}")
    reader = _Reader(cut(str(source), _SOURCE_LENGTH))
    reader.keys(data, "", required=_TOP_KEYS, optional=_TOP_OPTIONAL)
    entries = data["modules"]
    if not isinstance(entries, list):
        reader.fail("modules", entries, "an array of tables [[modules]], one per module, base first")
    if not entries:
        reader.fail("modules", entries, "at least one module ([[modules]] tables, base first)")
    if len(entries) > MAX_MODULES:
        reader.fail("modules", f"<{len(entries)} modules>", f"at most {MAX_MODULES} modules")
    modules = [_read_module(reader, entry, k) for k, entry in enumerate(entries, start=1)]
    effector = data["end_effector"]
    end_effector = _read_body(
        reader, effector, "end_effector", "end_effector", optional={"tool", "tool_axis", "tool_edge"}
    )
    tool = reader.vector(effector.get("tool", [0.0, 0.0, 0.0]), "end_effector.tool", 3, "[x, y, z]")
    axis = reader.vector(effector.get("tool_axis", list(TOOL_AXIS)), "end_effector.tool_axis", 3, "[x, y, z]")
    edge = reader.vector(effector.get("tool_edge", list(TOOL_EDGE)), "end_effector.tool_edge", 3, "[x, y, z]")
    environment = data.get("environment", {"gravity": [0.0, 0.0, -9.81]})
    reader.keys(environment, "environment", required={"gravity"})
    gravity = reader.vector(environment["gravity"], "environment.gravity", 3, "[gx, gy, gz]")
    name = data.get("name", Path(str(source)).stem)
    if not isinstance(name, str) or len(name) > NAME_LENGTH:
        reader.fail("name", name, f"a string of at most {NAME_LENGTH} characters")
    actuators = None
    if "actuators" in data:
        names = _joint_names(modules)
        actuators = read_actuators(data["actuators"], names, source)
    stiffness = None
    if "stiffness" in data:
        stiffness = read_stiffness(data["stiffness"], _joint_names(modules), source)
    return Stack(
        name=name,
        modules=tuple(modules),
        end_effector=end_effector,
        tool=(tool[0], tool[1], tool[2]),
        tool_axis=(axis[0], axis[1], axis[2]),
        tool_edge=(edge[0], edge[1], edge[2]),
        gravity=(gravity[0], gravity[1], gravity[2]),
        source=source,
        actuators=actuators,
        stiffness=stiffness,
    )


def _joint_names(modules: list[StackModule]) -> tuple[str, ...]:
    """The joint names of a stack of these modules (as :attr:`Stack.joint_names`), before it is built."""
    names: list[str] = []
    for k, module in enumerate(modules, start=1):
        names += [f"{leg}{k}" for leg in LEG_NAMES]
        if module.twist is not None:
            names.append(f"psi{k + 1}")
    return tuple(names)


def _read_body(reader: _Reader, entry: object, where: str, name: str, optional: set[str] | None = None) -> Body:
    reader.keys(entry, where, required=_BODY_KEYS, optional=optional)
    entry = cast(Mapping[str, Any], entry)  # reader.keys refused anything but a table
    rows = entry["inertia"]
    if not isinstance(rows, list) or len(rows) != 3:
        reader.fail(f"{where}.inertia", rows, "a 3x3 matrix written as three rows of three")
    inertia = tuple(
        tuple(reader.vector(row, f"{where}.inertia[{i}]", 3, "a row of three numbers")) for i, row in enumerate(rows)
    )
    com = reader.vector(entry["com"], f"{where}.com", 3, "[x, y, z]")
    return Body(
        name=name, mass=reader.number(entry["mass"], f"{where}.mass"), com=(com[0], com[1], com[2]), inertia=inertia
    )


def _pair(reader: _Reader, value: object, where: str) -> tuple[float, float]:
    pair = reader.vector(value, where, 2, "[min, max]")
    return (pair[0], pair[1])


def _read_module(reader: _Reader, entry: object, k: int) -> StackModule:
    where = f"module{k}"
    reader.keys(entry, where, required=_MODULE_KEYS, optional=_MODULE_OPTIONAL)
    entry = cast(Mapping[str, Any], entry)
    limits = entry["limits"]
    reader.keys(limits, f"{where}.limits", required=set(LEG_NAMES))
    home = reader.vector(entry["home"], f"{where}.home", 3, "[s, v, p]")
    viscous = reader.vector(entry.get("viscous", [0.0, 0.0, 0.0]), f"{where}.viscous", 3, "[c_s, c_v, c_p]")
    twist = None
    if "twist" in entry:
        twist = _read_twist(reader, entry["twist"], f"{where}.twist", k)
    return StackModule(
        b=reader.number(entry["b"], f"{where}.b"),
        d=reader.number(entry["d"], f"{where}.d"),
        plane=reader.number(entry["plane"], f"{where}.plane"),
        limits=tuple(_pair(reader, limits[leg], f"{where}.limits.{leg}") for leg in LEG_NAMES),  # type: ignore[arg-type]
        home=(home[0], home[1], home[2]),
        platform=_read_body(reader, entry["platform"], f"{where}.platform", f"platform{k}"),
        viscous=(viscous[0], viscous[1], viscous[2]),
        twist=twist,
    )


def _read_twist(reader: _Reader, entry: object, where: str, k: int) -> Twist:
    reader.keys(entry, where, required=_TWIST_KEYS, optional=_TWIST_OPTIONAL)
    entry = cast(Mapping[str, Any], entry)
    body = None
    if "body" in entry:
        body = _read_body(reader, entry["body"], f"{where}.body", f"twist{k + 1}")
    return Twist(
        height=reader.number(entry["height"], f"{where}.height"),
        limits=_pair(reader, entry["limits"], f"{where}.limits"),
        home=reader.number(entry.get("home", 0.0), f"{where}.home"),
        viscous=reader.number(entry.get("viscous", 0.0), f"{where}.viscous"),
        body=body,
    )


# -- validation ----------------------------------------------------------------------------


def _field(source: str, where: str) -> str:
    """How a refusal names the field ``where`` of the file ``source`` (as :func:`fail_field` does)."""
    return f"{cut(str(source), _SOURCE_LENGTH)}: field '{where}'"


def _validate(stack: Stack) -> None:
    """Check every value of ``stack``; raise :class:`ConfigError` at the first bad one."""
    source = stack.source
    if not isinstance(stack.name, str) or len(stack.name) > NAME_LENGTH:
        fail_field(source, "name", stack.name, f"a string of at most {NAME_LENGTH} characters")
    modules = stack.modules
    if not (isinstance(modules, tuple) and all(isinstance(m, StackModule) for m in modules)):
        fail_field(source, "modules", modules, "a tuple of StackModule, base first")
    if not modules:
        fail_field(source, "modules", modules, "at least one module ([[modules]] tables, base first)")
    if len(modules) > MAX_MODULES:
        fail_field(source, "modules", f"<{len(modules)} modules>", f"at most {MAX_MODULES} modules")
    for k, module in enumerate(modules, start=1):
        _validate_module(source, module, f"module{k}")
    if not isinstance(stack.end_effector, Body):
        fail_field(source, "end_effector", stack.end_effector, "a Body")
    _check_body(source, "end_effector", stack.end_effector)
    tool = _field(source, "end_effector.tool")
    checks.vector(tool, stack.tool, 3, minimum=-MAX_LENGTH, maximum=MAX_LENGTH, unit="m", error=ConfigError)
    _validate_tool_frame(source, stack.tool_axis, stack.tool_edge)
    gravity = _field(source, "environment.gravity")
    checks.vector(gravity, stack.gravity, 3, minimum=-MAX_GRAVITY, maximum=MAX_GRAVITY, unit="m/s^2", error=ConfigError)
    check_actuators(source, stack.actuators, _joint_names(list(modules)))
    check_stiffness(source, stack.stiffness, _joint_names(list(modules)))


def _validate_tool_frame(source: str, axis: object, edge: object) -> None:
    """The tool's axis and edge: finite unit vectors (within :data:`TOOL_FRAME_TOLERANCE`, else the
    message gives the normalised vector to paste), the edge perpendicular to the axis."""
    directions: dict[str, NDArray[np.float64]] = {}
    for name, value in (("tool_axis", axis), ("tool_edge", edge)):
        where = _field(source, f"end_effector.{name}")
        given = list(value) if isinstance(value, tuple | list) else value  # shown as the file writes it
        vector = checks.vector(where, given, 3, expected="3 finite numbers [x, y, z]", error=ConfigError)
        norm = math.hypot(*vector)
        if norm == 0.0:
            checks.refuse(where, given, "a unit vector (a direction), not the zero vector", ConfigError)
        if abs(norm - 1.0) > TOOL_FRAME_TOLERANCE:
            expected = f"a unit vector (norm 1 within {_TOLERANCE_TEXT}), its norm is {_norm_text(norm)}"
            normalised = _pasted(np.array(vector) / norm)
            checks.refuse(where, given, f"{expected}; normalised: {normalised}", ConfigError)
        directions[name] = np.array(vector)
    z, x = directions["tool_axis"], directions["tool_edge"]
    dot = float(z @ x)
    if abs(dot) > TOOL_FRAME_TOLERANCE:
        expected = (
            f"a direction perpendicular to tool_axis = {_pasted(z)} (|axis . edge| <= {_TOLERANCE_TEXT}), "
            f"axis . edge is {dot:.6g}"
        )
        part = x - dot * z  # the edge's part across the axis
        if np.linalg.norm(part) > 1e-6:
            expected += f"; its part across the axis, normalised: {_pasted(part / np.linalg.norm(part))}"
        checks.refuse(_field(source, "end_effector.tool_edge"), [float(v) for v in x], expected, ConfigError)


def _norm_text(norm: float) -> str:
    """A norm refused as not 1, with the digits that show it is not 1."""
    for digits in (6, 12):
        text = f"{norm:.{digits}g}"
        if float(text) != 1.0:
            return text
    return repr(norm)


def _pasted(vector: NDArray[np.float64]) -> str:
    """A direction as TOML to paste, 12 significant digits (a unit vector to ~1e-12)."""
    return "[" + ", ".join(f"{x + 0.0:.12g}" for x in vector) + "]"


def _check_body(source: str, where: str, body: Body) -> None:
    checks.number(_field(source, f"{where}.mass"), body.mass, above=0, maximum=MAX_MASS, unit="kg", error=ConfigError)
    com = _field(source, f"{where}.com")
    checks.vector(com, body.com, 3, minimum=-MAX_LENGTH, maximum=MAX_LENGTH, unit="m", error=ConfigError)
    rows = body.inertia
    if not (isinstance(rows, tuple | list) and len(rows) == 3):
        fail_field(source, f"{where}.inertia", rows, "a 3x3 matrix: three rows of three numbers")
    for i, row in enumerate(rows):
        checks.vector(_field(source, f"{where}.inertia[{i}]"), row, 3, unit="kg m^2", error=ConfigError)
    check_body(source, where, body)


def _validate_module(source: str, module: StackModule, where: str) -> None:
    for attr in ("b", "d"):
        name = _field(source, f"{where}.{attr}")
        checks.number(name, getattr(module, attr), above=0, maximum=MAX_LENGTH, unit="m", error=ConfigError)
    if module.d >= module.b:
        fail_field(
            source,
            f"{where}.d",
            module.d,
            f"d < b = {module.b} (the module is a trapezoid, platform narrower than base)",
        )
    plane = _field(source, f"{where}.plane")
    checks.number(plane, module.plane, minimum=-MAX_PLANE, maximum=MAX_PLANE, unit="degrees", error=ConfigError)
    if not (isinstance(module.limits, tuple | list) and len(module.limits) == 3):
        fail_field(source, f"{where}.limits", module.limits, "three [min, max] pairs (s, v, p)")
    for leg, pair in zip(LEG_NAMES, module.limits, strict=True):
        limits = _field(source, f"{where}.limits.{leg}")
        checks.interval(limits, pair, above=0, maximum=MAX_LENGTH, unit="m", error=ConfigError)
    checks.vector(_field(source, f"{where}.home"), module.home, 3, unit="m", error=ConfigError)
    for i, leg in enumerate(LEG_NAMES):
        lo, hi = module.limits[i]
        if not lo <= module.home[i] <= hi:
            fail_field(source, f"{where}.home[{i}] ({leg})", module.home[i], f"a value inside the limits [{lo}, {hi}]")
    margins = module_margins(np.array(module.home), module.b, module.d)
    if not (margins > 0.0).all():
        row = int(np.argmin(margins))
        fail_field(
            source,
            f"{where}.home",
            module.home,
            f"legs that can be assembled; '{TRIANGLE_INEQUALITIES[row]}' fails (margin {margins[row]:.6g} m)",
        )
    viscous = _field(source, f"{where}.viscous")
    checks.vector(viscous, module.viscous, 3, minimum=0, maximum=MAX_FRICTION, unit="N s/m", error=ConfigError)
    if not isinstance(module.platform, Body):
        fail_field(source, f"{where}.platform", module.platform, "a Body")
    _check_body(source, f"{where}.platform", module.platform)
    if module.twist is not None:
        _validate_twist(source, module.twist, f"{where}.twist")


def _validate_twist(source: str, twist: Twist, where: str) -> None:
    if not isinstance(twist, Twist):
        fail_field(source, where, twist, "a Twist or None")
    height = _field(source, f"{where}.height")
    checks.number(height, twist.height, minimum=0, maximum=MAX_LENGTH, unit="m", error=ConfigError)
    limits = _field(source, f"{where}.limits")
    lo, hi = checks.interval(
        limits, twist.limits, minimum=-MAX_LENGTH, maximum=MAX_LENGTH, unit="rad", error=ConfigError
    )
    checks.number(_field(source, f"{where}.home"), twist.home, minimum=lo, maximum=hi, unit="rad", error=ConfigError)
    viscous = _field(source, f"{where}.viscous")
    checks.number(viscous, twist.viscous, minimum=0, maximum=MAX_FRICTION, unit="N m s/rad", error=ConfigError)
    if twist.body is not None:
        if not isinstance(twist.body, Body):
            fail_field(source, f"{where}.body", twist.body, "a Body or None")
        _check_body(source, f"{where}.body", twist.body)


# -- today's fixed model as a stack, and back to TOML ------------------------------------------


def stack_from_parameters(parameters: RobotParameters) -> Stack:
    """The fixed 7-joint robot (two modules at 0 and 90 degrees, a twist after module 2) as a stack.

    Every value is copied unchanged: the stack's model gives the numbers of the fixed model (the
    tool point is 0 from the mount point, which is ``h1`` above platform 2, as in paper eq. 6).
    """
    if not isinstance(parameters, RobotParameters):
        raise ConfigError(f"parameters = {shown(parameters)}: expected RobotParameters (see vgtarm.load_parameters)")
    p = parameters
    modules = []
    for k, plane in enumerate((0.0, 90.0)):
        legs = range(3 * k, 3 * k + 3)
        twist = None
        if k == 1:
            twist = Twist(height=p.h1, limits=(p.limits[6][0], p.limits[6][1]), home=p.q_home[6], viscous=p.viscous[6])
        modules.append(
            StackModule(
                b=p.modules[k].b,
                d=p.modules[k].d,
                plane=plane,
                limits=tuple((p.limits[i][0], p.limits[i][1]) for i in legs),  # type: ignore[arg-type]
                home=tuple(p.q_home[i] for i in legs),  # type: ignore[arg-type]
                platform=p.bodies[k],
                viscous=tuple(p.viscous[i] for i in legs),  # type: ignore[arg-type]
                twist=twist,
            )
        )
    return Stack(
        name=p.name,
        modules=tuple(modules),
        end_effector=p.bodies[2],
        tool=(0.0, 0.0, 0.0),
        gravity=p.gravity,
        source=p.source,
        actuators=p.actuators,
        stiffness=p.stiffness,
    )


def _toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml_value(x) for x in value) + "]"
    number = float(value)  # type: ignore[arg-type]
    return repr(number)  # shortest text that reads back to the same double


def _toml_body(body: Body) -> str:
    return (
        f"{{ mass = {_toml_value(body.mass)}, com = {_toml_value(body.com)}, inertia = {_toml_value(body.inertia)} }}"
    )


def parameters_to_toml(parameters: RobotParameters, *, header: str = "") -> str:
    """The TOML text of the paper robot's format (the reference robot file's tables, with its
    ``[actuators]`` and ``[stiffness]`` when it has them); :func:`vgtarm.load_robot` reads it back to
    equal parameters, bit for bit. ``header`` (comment lines, without ``#``) opens the file."""
    p = parameters
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    lines += [""] if lines else []
    lines += [f"name = {_toml_value(p.name)}", "", "[geometry]"]
    lines += [f"module{k} = {{ b = {_toml_value(m.b)}, d = {_toml_value(m.d)} }}" for k, m in enumerate(p.modules, 1)]
    lines += [f"h1 = {_toml_value(p.h1)}", "", "[limits]"]
    lines += [f"{name} = {_toml_value(pair)}" for name, pair in zip(p.joint_names, p.limits, strict=True)]
    lines += ["", "[home]", f"q = {_toml_value(p.q_home)}", "", "[bodies]"]
    lines += [f"{body.name} = {_toml_body(body)}" for body in p.bodies]
    lines += ["", "[friction]", f"viscous = {_toml_value(p.viscous)}"]
    lines += ["", "[environment]", f"gravity = {_toml_value(p.gravity)}"]
    if p.actuators is not None:
        lines += ["", "[actuators]"]
        for joint, entry in p.actuators.entries().items():
            lines.append(f"{joint} = {{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in entry.items()) + " }")
    if p.stiffness is not None:
        lines += ["", "[stiffness]", *(f"{joint} = {_toml_value(v)}" for joint, v in p.stiffness.entries().items())]
    return "\n".join(lines) + "\n"


def robot_to_toml(parameters: RobotParameters | Stack, *, header: str = "") -> str:
    """The robot file of ``parameters`` in its own format: :func:`stack_to_toml` for a stack,
    :func:`parameters_to_toml` for the paper robot's."""
    if isinstance(parameters, Stack):
        return stack_to_toml(parameters, header=header)
    return parameters_to_toml(parameters, header=header)


def stack_to_toml(stack: Stack, *, header: str = "") -> str:
    """The TOML text of ``stack``; :func:`load_stack` reads it back to an equal stack, bit for bit.

    ``header`` (comment lines, without ``#``) opens the file.
    """
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    lines += [""] if lines else []
    lines.append(f"name = {_toml_value(stack.name)}")
    for module in stack.modules:
        lines += [
            "",
            "[[modules]]",
            f"b = {_toml_value(module.b)}",
            f"d = {_toml_value(module.d)}",
            f"plane = {_toml_value(module.plane)}",
            "limits = { "
            + ", ".join(f"{leg} = {_toml_value(pair)}" for leg, pair in zip(LEG_NAMES, module.limits, strict=True))
            + " }",
            f"home = {_toml_value(module.home)}",
            f"viscous = {_toml_value(module.viscous)}",
            f"platform = {_toml_body(module.platform)}",
        ]
        if module.twist is not None:
            twist = module.twist
            lines += [
                "[modules.twist]",
                f"height = {_toml_value(twist.height)}",
                f"limits = {_toml_value(twist.limits)}",
                f"home = {_toml_value(twist.home)}",
                f"viscous = {_toml_value(twist.viscous)}",
            ]
            if twist.body is not None:
                lines.append(f"body = {_toml_body(twist.body)}")
    body = stack.end_effector
    lines += [
        "",
        "[end_effector]",
        f"mass = {_toml_value(body.mass)}",
        f"com = {_toml_value(body.com)}",
        f"inertia = {_toml_value(body.inertia)}",
        f"tool = {_toml_value(stack.tool)}",
    ]
    # the tool's orientation only when it is not the default (old files write back as they were)
    lines += [f"tool_axis = {_toml_value(stack.tool_axis)}"] if tuple(stack.tool_axis) != TOOL_AXIS else []
    lines += [f"tool_edge = {_toml_value(stack.tool_edge)}"] if tuple(stack.tool_edge) != TOOL_EDGE else []
    lines += [
        "",
        "[environment]",
        f"gravity = {_toml_value(stack.gravity)}",
    ]
    if stack.actuators is not None:
        lines += ["", "[actuators]"]
        for joint, entry in stack.actuators.entries().items():
            fields = ", ".join(f"{key} = {_toml_value(value)}" for key, value in entry.items())
            lines.append(f"{joint} = {{ {fields} }}")
    if stack.stiffness is not None:
        lines += ["", "[stiffness]"]
        lines += [f"{joint} = {_toml_value(value)}" for joint, value in stack.stiffness.entries().items()]
    return "\n".join(lines) + "\n"


def reference_stack() -> Stack:
    """The shipped reference robot (:func:`vgtarm.load_parameters` ``()``) as a stack."""
    return stack_from_parameters(load_parameters())


__all__ = [
    "TOOL_AXIS",
    "TOOL_EDGE",
    "Stack",
    "StackModule",
    "Twist",
    "load_stack",
    "reference_stack",
    "stack_from_dict",
    "stack_from_parameters",
    "stack_margins",
    "stack_to_toml",
    "tool_rotation",
]
