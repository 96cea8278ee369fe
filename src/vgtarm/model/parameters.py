"""Robot parameters: frozen, validated dataclasses loaded from TOML.

The reference robot of the spec ships as ``vgtarm/data/reference_robot.toml``; a user's file has
the same layout (see that file, every assumed value is marked there). Every value is checked when
the parameters are built, so a bad file fails at load time with a message that names the field,
the value and what was expected.

The compiled model takes the parameters as a flat vector (:meth:`RobotParameters.vector`), so one
compiled library serves every robot: changing a mass or a dimension never recompiles.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from importlib import resources
from numbers import Real
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from .. import checks
from ..errors import ConfigError, cut, shown
from ..fileio import parse_toml, read_text_limited
from ..kinds import other_toml
from .actuators import Actuators, read_actuators
from .assembly import TRIANGLE_INEQUALITIES, linear_form, triangle_margins
from .factors import model_factor

#: Joint names, in the order of the joint vector ``q``.
JOINT_NAMES: tuple[str, ...] = ("s1", "v1", "p1", "s2", "v2", "p2", "psi3")
#: Number of joints (actuated coordinates) of the model.
N_JOINTS = len(JOINT_NAMES)
#: Units of each joint coordinate.
JOINT_UNITS: tuple[str, ...] = ("m", "m", "m", "m", "m", "m", "rad")
#: Units of each actuator effort.
EFFORT_UNITS: tuple[str, ...] = ("N", "N", "N", "N", "N", "N", "N m")
#: Body names, in the order of the model (paper links 7, 8, 9).
BODY_NAMES: tuple[str, ...] = ("platform1", "platform2", "end_effector")
#: Length of :meth:`RobotParameters.vector`.
N_PARAMETERS = 45

_REFERENCE_FILE = "reference_robot.toml"
#: Largest robot file read (bytes); the reference robot's file is about 3 kB.
ROBOT_FILE_LIMIT = 2**20
#: Longest robot name (characters).
NAME_LENGTH = 200
#: Longest rendering of a file name in messages (the name is at its end).
_SOURCE_LENGTH = 200
#: Longest rendering of a whole matrix or vector the validation computed (values are cut shorter).
_ARRAY_LENGTH = 160
_INERTIA_RELATIVE_TOLERANCE = 1e-9
# Generous physical bounds: far beyond any arm of this kind, they keep every product of the model
# (masses times squared lengths, gravity torques) finite, so no value turns into inf or NaN.
#: Largest length, joint limit (m, or rad for the twist) and centre-of-mass coordinate (m).
MAX_LENGTH = 1e3
#: Largest body mass (kg).
MAX_MASS = 1e6
#: Largest entry of an inertia matrix (kg m^2).
MAX_INERTIA = 1e6
#: Largest viscous friction coefficient (N s/m, N m s/rad).
MAX_FRICTION = 1e9
#: Largest gravity component (m/s^2).
MAX_GRAVITY = 1e3
#: Largest joint stiffness (N/m, N m/rad): far beyond any leg, it keeps ``K (q - q0)`` finite.
MAX_STIFFNESS = 1e12


@dataclass(frozen=True)
class ModuleGeometry:
    """One planar VGT module: base half-width ``b`` and platform half-width ``d`` (m), ``d < b``."""

    b: float
    d: float


@dataclass(frozen=True)
class Body:
    """A rigid body: mass (kg), centre of mass (m, in the body frame), inertia about it (kg m^2)."""

    name: str
    mass: float
    com: tuple[float, float, float]
    inertia: tuple[tuple[float, ...], ...]

    @property
    def inertia_matrix(self) -> NDArray[np.float64]:
        """Inertia about the centre of mass in the body frame, (3, 3)."""
        return np.array(self.inertia, dtype=float)


#: The warning of a deprecated name of the joint limits (RobotParameters, Stack).
_RENAMED = "{old} is deprecated: the joint limits are named lower and upper (arrays, m and rad); use .{new}"


@dataclass(frozen=True)
class RobotParameters:
    """Everything that defines one manipulator. Build with :func:`load_parameters`.

    Attributes are plain tuples (immutable, hashable); NumPy views are given by properties.
    ``dataclasses.replace`` re-runs the validation, so a modified copy is checked too.

    The joint limits are ``limits``, one ``(min, max)`` pair per joint in the order of
    :data:`JOINT_NAMES` (m, rad), as the file's ``[limits]`` table and a stack module's
    ``limits`` give them; :attr:`lower` and :attr:`upper` are the same as arrays, the names used
    everywhere (:meth:`vgtarm.Robot.joint_limits`, the IK results, :class:`~vgtarm.model.stack.Stack`).
    ``q_min`` and ``q_max`` are deprecated aliases of them (tuples).
    """

    name: str
    modules: tuple[ModuleGeometry, ModuleGeometry]
    h1: float
    limits: tuple[tuple[float, float], ...]
    q_home: tuple[float, ...]
    bodies: tuple[Body, Body, Body]
    viscous: tuple[float, ...]
    gravity: tuple[float, float, float]
    source: str = field(default="<parameters>", compare=False)
    #: The joints' actuators (:mod:`vgtarm.model.actuators`), or ``None``: no limits (the paper).
    actuators: Actuators | None = None
    #: The joints' stiffness (the ``[stiffness]`` table, :class:`JointStiffness`), or ``None``:
    #: rigid joints (the paper). Not a parameter of the compiled model (nor of the fingerprint).
    stiffness: JointStiffness | None = None

    def __post_init__(self) -> None:
        _validate(self)

    @property
    def b(self) -> tuple[float, float]:
        """Base half-widths of the two modules (m)."""
        return (self.modules[0].b, self.modules[1].b)

    @property
    def d(self) -> tuple[float, float]:
        """Platform half-widths of the two modules (m)."""
        return (self.modules[0].d, self.modules[1].d)

    @property
    def lower(self) -> NDArray[np.float64]:
        """Lower joint limits, (7,) (m, rad)."""
        return np.array([pair[0] for pair in self.limits])

    @property
    def upper(self) -> NDArray[np.float64]:
        """Upper joint limits, (7,) (m, rad)."""
        return np.array([pair[1] for pair in self.limits])

    @property
    def q_min(self) -> tuple[float, ...]:
        """Deprecated: the lower joint limits as a tuple; use :attr:`lower` (or :attr:`limits`)."""
        warnings.warn(_RENAMED.format(old="q_min", new="lower"), DeprecationWarning, stacklevel=2)
        return tuple(pair[0] for pair in self.limits)

    @property
    def q_max(self) -> tuple[float, ...]:
        """Deprecated: the upper joint limits as a tuple; use :attr:`upper` (or :attr:`limits`)."""
        warnings.warn(_RENAMED.format(old="q_max", new="upper"), DeprecationWarning, stacklevel=2)
        return tuple(pair[1] for pair in self.limits)

    @property
    def home(self) -> NDArray[np.float64]:
        """Home configuration, (7,)."""
        return np.array(self.q_home)

    @property
    def total_mass(self) -> float:
        """Sum of the body masses (kg)."""
        return float(sum(body.mass for body in self.bodies))

    @property
    def n_joints(self) -> int:
        """Number of joints (7)."""
        return N_JOINTS

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Joint names in the order of ``q`` (:data:`JOINT_NAMES`)."""
        return JOINT_NAMES

    @property
    def joint_units(self) -> tuple[str, ...]:
        """Unit of each joint coordinate (:data:`JOINT_UNITS`)."""
        return JOINT_UNITS

    def margin_form(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``G`` (12, 7) and ``h`` (12,): the triangle margins ``G q + h`` of both modules, six rows per
        module (:func:`vgtarm.model.assembly.linear_form`)."""
        return linear_form(self.b, self.d)

    def margin_legs(self) -> tuple[tuple[int, int, int], ...]:
        """Indices in ``q`` of each module's legs ``(s, v, p)``, in the order of the margin rows."""
        return ((0, 1, 2), (3, 4, 5))

    def vector(self) -> NDArray[np.float64]:
        """The flat parameter vector the compiled model takes, (45,).

        Layout: ``b1, d1, b2, d2, h1``; then per body ``mass, com (3), Ixx, Iyy, Izz, Ixy, Ixz,
        Iyz``; then the seven viscous friction coefficients; then gravity (3).
        """
        values: list[float] = [self.modules[0].b, self.modules[0].d]
        values += [self.modules[1].b, self.modules[1].d, self.h1]
        for body in self.bodies:
            inertia = body.inertia
            values += [body.mass, *body.com]
            values += [inertia[0][0], inertia[1][1], inertia[2][2]]
            values += [inertia[0][1], inertia[0][2], inertia[1][2]]
        values += list(self.viscous) + list(self.gravity)
        return np.array(values, dtype=float)

    def scaled(self, *, mass: float = 1.0, inertia: float = 1.0, friction: float = 1.0) -> RobotParameters:
        """A copy with every body mass, inertia and friction coefficient multiplied by a factor.

        Convenient for giving a controller a wrong model of the plant. Each factor must be a
        number in :data:`~vgtarm.model.factors.MODEL_FACTOR_RANGE` (``ConfigError`` otherwise).
        """
        mass, inertia, friction = (
            model_factor(label, factor, error=ConfigError)
            for label, factor in (("mass", mass), ("inertia", inertia), ("friction", friction))
        )
        bodies = tuple(
            replace(
                body,
                mass=body.mass * mass,
                inertia=tuple(tuple(x * inertia for x in row) for row in body.inertia),
            )
            for body in self.bodies
        )
        return replace(
            self,
            name=f"{self.name} (mass x{mass:g}, inertia x{inertia:g}, friction x{friction:g})",
            bodies=bodies,  # type: ignore[arg-type]
            viscous=tuple(c * friction for c in self.viscous),
        )


def load_parameters(path: str | os.PathLike[str] | None = None) -> RobotParameters:
    """Load robot parameters from a TOML file; ``None`` loads the shipped reference robot.

    Raises :class:`~vgtarm.errors.ConfigError` (one line naming the file) for an empty name, a
    missing, unreadable, non-UTF-8 or too large file (over :data:`ROBOT_FILE_LIMIT` bytes), a TOML
    syntax error or nesting too deep to parse, an unknown or missing key, or any invalid value.
    """
    if path is None:
        text = resources.files("vgtarm.model.data").joinpath(_REFERENCE_FILE).read_text("utf-8")
        source = f"<reference robot {_REFERENCE_FILE}>"
    else:
        if not isinstance(path, str | os.PathLike):
            raise ConfigError(f"robot configuration {shown(path)}: expected a file name (str or Path) or None")
        source = str(path)
        text = read_text_limited(path, ROBOT_FILE_LIMIT, "configuration file", error=ConfigError)
    return parameters_from_dict(parse_toml(text, cut(source, _SOURCE_LENGTH), error=ConfigError), source=source)


def parameters_from_dict(data: Mapping[str, Any], *, source: str = "<dict>") -> RobotParameters:
    """Build :class:`RobotParameters` from the nested mapping a TOML file parses to."""
    other = other_toml(data, "a robot file")  # a study or a stack file given as a 7-joint robot: said so
    if other is not None:
        raise ConfigError(f"{cut(str(source), _SOURCE_LENGTH)}: {other}")
    reader = _Reader(cut(str(source), _SOURCE_LENGTH))
    reader.keys(
        data,
        "",
        required={"geometry", "limits", "home", "bodies"},
        optional={"name", "friction", "environment", "actuators", "stiffness"},
    )
    geometry = data["geometry"]
    reader.keys(geometry, "geometry", required={"module1", "module2", "h1"})
    modules = []
    for k in (1, 2):
        entry = geometry[f"module{k}"]
        reader.keys(entry, f"geometry.module{k}", required={"b", "d"})
        modules.append(
            ModuleGeometry(
                b=reader.number(entry["b"], f"geometry.module{k}.b"),
                d=reader.number(entry["d"], f"geometry.module{k}.d"),
            )
        )
    limits = data["limits"]
    reader.keys(limits, "limits", required=set(JOINT_NAMES))
    pairs = []
    for name in JOINT_NAMES:
        pair = reader.vector(limits[name], f"limits.{name}", 2, "[min, max]")
        pairs.append((pair[0], pair[1]))
    home = data["home"]
    reader.keys(home, "home", required={"q"})
    bodies_table = data["bodies"]
    reader.keys(bodies_table, "bodies", required=set(BODY_NAMES))
    bodies = []
    for name in BODY_NAMES:
        entry = bodies_table[name]
        where = f"bodies.{name}"
        reader.keys(entry, where, required={"mass", "com", "inertia"})
        rows = entry["inertia"]
        if not isinstance(rows, list) or len(rows) != 3:
            reader.fail(f"{where}.inertia", rows, "a 3x3 matrix written as three rows of three")
        inertia = tuple(
            tuple(reader.vector(row, f"{where}.inertia[{i}]", 3, "a row of three numbers"))
            for i, row in enumerate(rows)
        )
        bodies.append(
            Body(
                name=name,
                mass=reader.number(entry["mass"], f"{where}.mass"),
                com=tuple(reader.vector(entry["com"], f"{where}.com", 3, "[x, y, z]")),  # type: ignore[arg-type]
                inertia=inertia,
            )
        )
    friction = data.get("friction", {"viscous": [0.0] * N_JOINTS})
    reader.keys(friction, "friction", required={"viscous"})
    environment = data.get("environment", {"gravity": [0.0, 0.0, -9.81]})
    reader.keys(environment, "environment", required={"gravity"})
    name = data.get("name", Path(str(source)).stem)
    if not isinstance(name, str) or len(name) > NAME_LENGTH:
        reader.fail("name", name, f"a string of at most {NAME_LENGTH} characters")
    return RobotParameters(
        name=name,
        modules=(modules[0], modules[1]),
        h1=reader.number(geometry["h1"], "geometry.h1"),
        limits=tuple(pairs),
        q_home=tuple(reader.vector(home["q"], "home.q", N_JOINTS, "one value per joint")),
        bodies=(bodies[0], bodies[1], bodies[2]),
        viscous=tuple(reader.vector(friction["viscous"], "friction.viscous", N_JOINTS, "one value per joint")),
        gravity=tuple(reader.vector(environment["gravity"], "environment.gravity", 3, "[gx, gy, gz]")),  # type: ignore[arg-type]
        source=source,
        actuators=None if "actuators" not in data else read_actuators(data["actuators"], JOINT_NAMES, source),
        stiffness=None if "stiffness" not in data else read_stiffness(data["stiffness"], JOINT_NAMES, source),
    )


# -- the [stiffness] table ---------------------------------------------------------------------------

#: The groups of the ``[stiffness]`` table: every leg (N/m) and every twist joint (N m/rad).
STIFFNESS_GROUPS = ("legs", "twists")


@dataclass(frozen=True)
class JointStiffness:
    """The stiffness of each actuated joint, from a robot file's ``[stiffness]`` table::

        [stiffness]
        legs = 2.0e5        # every leg (N/m)
        twists = 500.0      # every twist joint (N m/rad)
        p1 = 3.0e5          # one joint: overrides its group

    ``names`` are the joint names and ``values`` their stiffness in the same order (N/m for a
    leg, N m/rad for a twist), every one finite and > 0; ``origins`` says which entry of the
    table gave each (its group or its own name: what a refusal names). Like the actuators, the
    stiffness is not in the parameter vector of the compiled model nor in the fingerprint.
    """

    names: tuple[str, ...]
    values: tuple[float, ...]
    origins: tuple[str, ...] = field(default=(), compare=False)

    @property
    def array(self) -> NDArray[np.float64]:
        """The joint stiffnesses, ``(n,)`` (N/m, N m/rad)."""
        array = np.array(self.values, dtype=float)
        array.flags.writeable = False
        return array

    def entries(self) -> dict[str, float]:
        """The ``[stiffness]`` table of a robot file, one entry per joint."""
        return dict(zip(self.names, self.values, strict=True))


def _stiffness_unit(name: str) -> str:
    return "N m/rad" if name.startswith("psi") else "N/m"


def read_stiffness(table: object, names: Sequence[str], source: str) -> JointStiffness:
    """The ``[stiffness]`` table of a robot file whose joints are ``names``: a group's value
    (``legs``, ``twists``) or a joint's own. Every joint needs one; an unknown key, a value that is
    not a finite number > 0 (zero, negative, NaN, text) or a joint left without one is refused with
    one :class:`ConfigError` line naming the field (``stiffness.p1``)."""
    head = cut(str(source), _SOURCE_LENGTH)
    if not isinstance(table, Mapping):
        checks.refuse(f"{head}: field 'stiffness'", table, "a table of joints and groups (legs, twists)", ConfigError)
    for key in table:
        if key not in STIFFNESS_GROUPS and key not in names:
            raise ConfigError(
                f"{head}: unknown key 'stiffness.{cut(str(key))}'; expected a joint "
                f"({', '.join(names[:8])}{', ...' if len(names) > 8 else ''}) or a group (legs, twists)"
            )
    values: list[float] = []
    origins: list[str] = []
    for name in names:
        group = "twists" if name.startswith("psi") else "legs"
        key = name if name in table else group
        if key not in table:
            raise ConfigError(
                f"{head}: missing key 'stiffness.{name}' (joint {name} needs a stiffness, in its own entry "
                f"or its group's, {group})"
            )
        given = f"{head}: field 'stiffness.{key}'" + ("" if key == name else f" (joint {name})")
        values.append(
            checks.number(
                given,
                table[key],
                above=0,
                maximum=MAX_STIFFNESS,
                unit=_stiffness_unit(name),
                error=ConfigError,
            )
        )
        origins.append(key)
    return JointStiffness(names=tuple(names), values=tuple(values), origins=tuple(origins))


def check_stiffness(source: str, stiffness: object, names: tuple[str, ...]) -> None:
    """``stiffness`` is ``None`` or a :class:`JointStiffness` of the joints ``names``, each value a
    finite number in (0, :data:`MAX_STIFFNESS`]."""
    if stiffness is None:
        return
    if not isinstance(stiffness, JointStiffness) or tuple(stiffness.names) != tuple(names):
        fail_field(source, "stiffness", stiffness, f"None or JointStiffness of the joints {', '.join(names)}")
    if len(stiffness.values) != len(names):
        fail_field(source, "stiffness", list(stiffness.values), f"{len(names)} values, one per joint")
    for name, value in zip(names, stiffness.values, strict=True):
        unit = _stiffness_unit(name)
        head = f"{cut(str(source), _SOURCE_LENGTH)}: field 'stiffness.{name}'"
        checks.number(head, value, above=0, maximum=MAX_STIFFNESS, unit=unit, error=ConfigError)


class _Reader:
    """Type checks of raw TOML values, raising :class:`ConfigError` with the field's path."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, field_name: str, value: object, expected: str) -> NoReturn:
        raise ConfigError(f"{self.source}: field '{field_name}' = {shown(value)}: expected {expected}")

    def keys(
        self,
        table: object,
        where: str,
        required: set[str],
        optional: set[str] | None = None,
    ) -> None:
        label = where or "top level"
        if not isinstance(table, Mapping):
            self.fail(label, table, "a table")
            return
        allowed = required | (optional or set())
        unknown = sorted(set(table) - allowed, key=str)
        if unknown:
            raise ConfigError(
                f"{self.source}: unknown key '{_join(where, cut(str(unknown[0])))}' in {label};"
                f" expected one of {sorted(allowed)}"
            )
        missing = sorted(required - set(table))
        if missing:
            raise ConfigError(f"{self.source}: missing key '{_join(where, missing[0])}'")

    def number(self, value: object, field_name: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(field_name, value, "a number")
        return float(value)

    def vector(self, value: object, field_name: str, n: int, expected: str) -> list[float]:
        if not isinstance(value, list) or len(value) != n:
            self.fail(field_name, value, f"{expected} (a list of {n} numbers)")
        return [self.number(x, f"{field_name}[{i}]") for i, x in enumerate(value)]


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _fail(p: RobotParameters, field_name: str, value: object, expected: str) -> NoReturn:
    fail_field(p.source, field_name, value, expected)


def fail_field(source: str, field_name: str, value: object, expected: str) -> NoReturn:
    """Raise the one-line :class:`ConfigError` of a bad field of the file ``source``."""
    limit = _ARRAY_LENGTH if isinstance(value, list | tuple) else None
    text = shown(value) if limit is None else shown(value, limit)
    raise ConfigError(f"{cut(str(source), _SOURCE_LENGTH)}: field '{field_name}' = {text}: expected {expected}")


def _finite(values: Sequence[float], bound: float = math.inf) -> bool:
    """Whether every value is finite and at most ``bound`` in magnitude."""
    return all(math.isfinite(x) and abs(x) <= bound for x in values)


def _is_real(value: object) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool)


def _check_types(p: RobotParameters) -> None:
    """Check the types and sizes of ``p``'s fields (given directly, not read from a file)."""
    if not isinstance(p.name, str):
        _fail(p, "name", p.name, "a string")
    modules = p.modules
    if not (isinstance(modules, tuple) and len(modules) == 2 and all(isinstance(m, ModuleGeometry) for m in modules)):
        _fail(p, "modules", modules, "a pair of ModuleGeometry")
    scalars = {"geometry.h1": p.h1}
    for k, module in enumerate(modules, start=1):
        scalars.update({f"geometry.module{k}.b": module.b, f"geometry.module{k}.d": module.d})
    limits = p.limits
    if not (isinstance(limits, tuple | list) and len(limits) == N_JOINTS):
        _fail(p, "limits", limits, f"{N_JOINTS} [min, max] pairs")
    vectors: dict[str, tuple[object, int]] = {
        **{f"limits.{name}": (pair, 2) for name, pair in zip(JOINT_NAMES, limits, strict=True)},
        "home.q": (p.q_home, N_JOINTS),
        "friction.viscous": (p.viscous, N_JOINTS),
        "environment.gravity": (p.gravity, 3),
    }
    bodies = p.bodies
    if not (isinstance(bodies, tuple) and len(bodies) == len(BODY_NAMES) and all(isinstance(b, Body) for b in bodies)):
        _fail(p, "bodies", bodies, f"a tuple of {len(BODY_NAMES)} Body")
    for body in bodies:
        scalars[f"bodies.{body.name}.mass"] = body.mass
        vectors[f"bodies.{body.name}.com"] = (body.com, 3)
        rows = body.inertia
        if not (isinstance(rows, tuple | list) and len(rows) == 3):
            _fail(p, f"bodies.{body.name}.inertia", rows, "a 3x3 matrix: three rows of three numbers")
        for i, row in enumerate(rows):
            vectors[f"bodies.{body.name}.inertia[{i}]"] = (row, 3)
    for field_name, value in scalars.items():
        if not _is_real(value):
            _fail(p, field_name, value, "a number")
    for field_name, (values, n) in vectors.items():
        if not (isinstance(values, tuple | list) and len(values) == n and all(_is_real(x) for x in values)):
            _fail(p, field_name, values, f"{n} numbers")


def _validate(p: RobotParameters) -> None:
    """Check every value of ``p``; raise :class:`ConfigError` at the first bad one."""
    _check_types(p)
    for k, module in enumerate(p.modules, start=1):
        for attr in ("b", "d"):
            value = getattr(module, attr)
            if not (math.isfinite(value) and 0.0 < value <= MAX_LENGTH):
                _fail(p, f"geometry.module{k}.{attr}", value, f"a positive length <= {MAX_LENGTH:g} (m)")
        if module.d >= module.b:
            _fail(
                p,
                f"geometry.module{k}.d",
                module.d,
                f"d < b = {module.b} (the module is a trapezoid, platform narrower than base)",
            )
    if not (math.isfinite(p.h1) and 0.0 <= p.h1 <= MAX_LENGTH):
        _fail(p, "geometry.h1", p.h1, f"a length in [0, {MAX_LENGTH:g}] (m)")
    if not (len(p.limits) == len(p.q_home) == N_JOINTS):
        _fail(p, "limits", p.limits, "seven [min, max] pairs")
    for i, name in enumerate(JOINT_NAMES):
        lo, hi = p.limits[i]
        if not _finite([lo, hi], MAX_LENGTH):
            _fail(p, f"limits.{name}", [lo, hi], f"finite limits within +-{MAX_LENGTH:g} (m, rad)")
        if not lo < hi:
            _fail(p, f"limits.{name}", [lo, hi], "min < max (the range is inverted or empty)")
        if i < 6 and lo <= 0.0:
            _fail(p, f"limits.{name}", [lo, hi], "a positive minimum length (m)")
    if not _finite(p.q_home):
        _fail(p, "home.q", list(p.q_home), "finite joint values")
    for i, name in enumerate(JOINT_NAMES):
        lo, hi = p.limits[i]
        if not lo <= p.q_home[i] <= hi:
            _fail(p, f"home.q[{i}] ({name})", p.q_home[i], f"a value inside the limits [{lo}, {hi}]")
    margins = triangle_margins(np.array(p.q_home), p.b, p.d)
    if not (margins > 0.0).all():
        row = int(np.argmin(margins))
        _fail(
            p,
            "home.q",
            list(p.q_home),
            f"a pose that can be assembled; module {row // 6 + 1} breaks the triangle "
            f"inequality '{TRIANGLE_INEQUALITIES[row % 6]}' (margin {margins[row]:.6g} m)",
        )
    for body in p.bodies:
        _validate_body(p, body)
    if len(p.viscous) != N_JOINTS:
        _fail(p, "friction.viscous", list(p.viscous), "seven coefficients")
    for i, c in enumerate(p.viscous):
        if not (math.isfinite(c) and 0.0 <= c <= MAX_FRICTION):
            _fail(p, f"friction.viscous[{i}] ({JOINT_NAMES[i]})", c, f"a coefficient in [0, {MAX_FRICTION:g}]")
    if len(p.gravity) != 3 or not _finite(p.gravity, MAX_GRAVITY):
        _fail(p, "environment.gravity", list(p.gravity), f"a 3-vector with entries within +-{MAX_GRAVITY:g} (m/s^2)")
    check_actuators(p.source, p.actuators, JOINT_NAMES)
    check_stiffness(p.source, p.stiffness, JOINT_NAMES)


def check_actuators(source: str, actuators: object, names: tuple[str, ...]) -> None:
    """``actuators`` is ``None`` or an :class:`~vgtarm.model.actuators.Actuators` of the joints ``names``."""
    if actuators is None:
        return
    if not isinstance(actuators, Actuators) or tuple(actuators.names) != tuple(names):
        fail_field(source, "actuators", actuators, f"None or Actuators of the joints {', '.join(names)}")


def _validate_body(p: RobotParameters, body: Body) -> None:
    check_body(p.source, f"bodies.{body.name}", body)


def check_body(source: str, where: str, body: Body) -> None:
    """Check a body's mass, centre of mass and inertia (positive definite, triangle inequality of the
    principal moments); a bad value raises :class:`ConfigError` naming ``<where>.mass``, ``.com`` or
    ``.inertia`` in the file ``source``."""
    if not (math.isfinite(body.mass) and 0.0 < body.mass <= MAX_MASS):
        fail_field(source, f"{where}.mass", body.mass, f"a positive mass <= {MAX_MASS:g} (kg)")
    if len(body.com) != 3 or not _finite(body.com, MAX_LENGTH):
        fail_field(source, f"{where}.com", list(body.com), f"a 3-vector with entries within +-{MAX_LENGTH:g} (m)")
    inertia = np.array(body.inertia, dtype=float)
    if inertia.shape != (3, 3) or not (np.isfinite(inertia).all() and np.abs(inertia).max() <= MAX_INERTIA):
        expected = f"a 3x3 matrix with entries within +-{MAX_INERTIA:g} (kg m^2)"
        fail_field(source, f"{where}.inertia", body.inertia, expected)
    scale = float(np.abs(inertia).max())
    tol = _INERTIA_RELATIVE_TOLERANCE * max(scale, 1e-300)
    if not np.allclose(inertia, inertia.T, rtol=0.0, atol=tol):
        fail_field(source, f"{where}.inertia", inertia.tolist(), "a symmetric matrix")
    moments = np.linalg.eigvalsh(inertia)
    if not moments[0] > 0.0:
        fail_field(
            source,
            f"{where}.inertia",
            inertia.tolist(),
            f"a positive definite matrix (principal moments {moments.tolist()})",
        )
    if moments[0] + moments[1] < moments[2] * (1.0 - _INERTIA_RELATIVE_TOLERANCE):
        fail_field(
            source,
            f"{where}.inertia",
            inertia.tolist(),
            "principal moments that satisfy the triangle inequality I1 + I2 >= I3 "
            f"(principal moments {moments.tolist()})",
        )
