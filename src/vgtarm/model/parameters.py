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
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from ..errors import ConfigError
from .assembly import TRIANGLE_INEQUALITIES, triangle_margins

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
_INERTIA_RELATIVE_TOLERANCE = 1e-9


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


@dataclass(frozen=True)
class RobotParameters:
    """Everything that defines one manipulator. Build with :func:`load_parameters`.

    Attributes are plain tuples (immutable, hashable); NumPy views are given by properties.
    ``dataclasses.replace`` re-runs the validation, so a modified copy is checked too.
    """

    name: str
    modules: tuple[ModuleGeometry, ModuleGeometry]
    h1: float
    q_min: tuple[float, ...]
    q_max: tuple[float, ...]
    q_home: tuple[float, ...]
    bodies: tuple[Body, Body, Body]
    viscous: tuple[float, ...]
    gravity: tuple[float, float, float]
    source: str = field(default="<parameters>", compare=False)

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
        """Lower joint limits, (7,)."""
        return np.array(self.q_min)

    @property
    def upper(self) -> NDArray[np.float64]:
        """Upper joint limits, (7,)."""
        return np.array(self.q_max)

    @property
    def home(self) -> NDArray[np.float64]:
        """Home configuration, (7,)."""
        return np.array(self.q_home)

    @property
    def total_mass(self) -> float:
        """Sum of the body masses (kg)."""
        return float(sum(body.mass for body in self.bodies))

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

        Convenient for giving a controller a wrong model of the plant.
        """
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


def load_parameters(path: str | Path | None = None) -> RobotParameters:
    """Load robot parameters from a TOML file; ``None`` loads the shipped reference robot.

    Raises :class:`~vgtarm.errors.ConfigError` for a missing or unreadable file, a TOML syntax
    error, an unknown or missing key, or any invalid value.
    """
    if path is None:
        text = resources.files("vgtarm.model.data").joinpath(_REFERENCE_FILE).read_text("utf-8")
        source = f"<reference robot {_REFERENCE_FILE}>"
    else:
        file = Path(path)
        source = str(file)
        try:
            text = file.read_text("utf-8")
        except FileNotFoundError:
            raise ConfigError(f"{source}: configuration file not found") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{source}: cannot read the configuration file: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    return parameters_from_dict(data, source=source)


def parameters_from_dict(data: Mapping[str, Any], *, source: str = "<dict>") -> RobotParameters:
    """Build :class:`RobotParameters` from the nested mapping a TOML file parses to."""
    reader = _Reader(source)
    reader.keys(
        data, "", required={"geometry", "limits", "home", "bodies"}, optional={"name", "friction", "environment"}
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
    q_min, q_max = [], []
    for name in JOINT_NAMES:
        pair = reader.vector(limits[name], f"limits.{name}", 2, "[min, max]")
        q_min.append(pair[0])
        q_max.append(pair[1])
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
    friction = data.get("friction", {"viscous": [0.0] * 7})
    reader.keys(friction, "friction", required={"viscous"})
    environment = data.get("environment", {"gravity": [0.0, 0.0, -9.81]})
    reader.keys(environment, "environment", required={"gravity"})
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str):
        reader.fail("name", name, "a string")
    return RobotParameters(
        name=name,
        modules=(modules[0], modules[1]),
        h1=reader.number(geometry["h1"], "geometry.h1"),
        q_min=tuple(q_min),
        q_max=tuple(q_max),
        q_home=tuple(reader.vector(home["q"], "home.q", 7, "seven joint values")),
        bodies=(bodies[0], bodies[1], bodies[2]),
        viscous=tuple(reader.vector(friction["viscous"], "friction.viscous", 7, "seven values")),
        gravity=tuple(reader.vector(environment["gravity"], "environment.gravity", 3, "[gx, gy, gz]")),  # type: ignore[arg-type]
        source=source,
    )


class _Reader:
    """Type checks of raw TOML values, raising :class:`ConfigError` with the field's path."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, field_name: str, value: object, expected: str) -> NoReturn:
        raise ConfigError(f"{self.source}: field '{field_name}' = {value!r}: expected {expected}")

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
        unknown = sorted(set(table) - allowed)
        if unknown:
            raise ConfigError(
                f"{self.source}: unknown key '{_join(where, unknown[0])}' in {label}; expected one of {sorted(allowed)}"
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
    raise ConfigError(f"{p.source}: field '{field_name}' = {value!r}: expected {expected}")


def _finite(values: Sequence[float]) -> bool:
    return all(math.isfinite(x) for x in values)


def _validate(p: RobotParameters) -> None:
    """Check every value of ``p``; raise :class:`ConfigError` at the first bad one."""
    for k, module in enumerate(p.modules, start=1):
        for attr in ("b", "d"):
            value = getattr(module, attr)
            if not (math.isfinite(value) and value > 0.0):
                _fail(p, f"geometry.module{k}.{attr}", value, "a positive finite length (m)")
        if module.d >= module.b:
            _fail(
                p,
                f"geometry.module{k}.d",
                module.d,
                f"d < b = {module.b} (the module is a trapezoid, platform narrower than base)",
            )
    if not (math.isfinite(p.h1) and p.h1 >= 0.0):
        _fail(p, "geometry.h1", p.h1, "a finite length >= 0 (m)")
    if not (len(p.q_min) == len(p.q_max) == len(p.q_home) == 7):
        _fail(p, "limits", (p.q_min, p.q_max), "seven [min, max] pairs")
    for i, name in enumerate(JOINT_NAMES):
        lo, hi = p.q_min[i], p.q_max[i]
        if not _finite([lo, hi]):
            _fail(p, f"limits.{name}", [lo, hi], "finite limits")
        if not lo < hi:
            _fail(p, f"limits.{name}", [lo, hi], "min < max (the range is inverted or empty)")
        if i < 6 and lo <= 0.0:
            _fail(p, f"limits.{name}", [lo, hi], "a positive minimum length (m)")
    if not _finite(p.q_home):
        _fail(p, "home.q", list(p.q_home), "finite joint values")
    for i, name in enumerate(JOINT_NAMES):
        if not p.q_min[i] <= p.q_home[i] <= p.q_max[i]:
            _fail(p, f"home.q[{i}] ({name})", p.q_home[i], f"a value inside the limits [{p.q_min[i]}, {p.q_max[i]}]")
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
    if len(p.viscous) != 7:
        _fail(p, "friction.viscous", list(p.viscous), "seven coefficients")
    for i, c in enumerate(p.viscous):
        if not (math.isfinite(c) and c >= 0.0):
            _fail(p, f"friction.viscous[{i}] ({JOINT_NAMES[i]})", c, "a finite coefficient >= 0")
    if len(p.gravity) != 3 or not _finite(p.gravity):
        _fail(p, "environment.gravity", list(p.gravity), "a finite 3-vector (m/s^2)")


def _validate_body(p: RobotParameters, body: Body) -> None:
    where = f"bodies.{body.name}"
    if not (math.isfinite(body.mass) and body.mass > 0.0):
        _fail(p, f"{where}.mass", body.mass, "a positive finite mass (kg)")
    if len(body.com) != 3 or not _finite(body.com):
        _fail(p, f"{where}.com", list(body.com), "a finite 3-vector (m)")
    inertia = np.array(body.inertia, dtype=float)
    if inertia.shape != (3, 3) or not np.isfinite(inertia).all():
        _fail(p, f"{where}.inertia", body.inertia, "a finite 3x3 matrix (kg m^2)")
    scale = float(np.abs(inertia).max())
    tol = _INERTIA_RELATIVE_TOLERANCE * max(scale, 1e-300)
    if not np.allclose(inertia, inertia.T, rtol=0.0, atol=tol):
        _fail(p, f"{where}.inertia", inertia.tolist(), "a symmetric matrix")
    moments = np.linalg.eigvalsh(inertia)
    if not moments[0] > 0.0:
        _fail(
            p,
            f"{where}.inertia",
            inertia.tolist(),
            f"a positive definite matrix (principal moments {moments.tolist()})",
        )
    if moments[0] + moments[1] < moments[2] * (1.0 - _INERTIA_RELATIVE_TOLERANCE):
        _fail(
            p,
            f"{where}.inertia",
            inertia.tolist(),
            "principal moments that satisfy the triangle inequality I1 + I2 >= I3 "
            f"(principal moments {moments.tolist()})",
        )
