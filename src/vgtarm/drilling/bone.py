"""A bone to drill and the drill's thrust and torque in it: the plant side of force-controlled
drilling (issue 38, ``docs/drilling.md``).

A bone file (TOML) gives the layers the drill crosses along its axis (cortical, cancellous,
cortical, ...), each with its thickness (m), its material and optionally its density (kg/m^3);
the drill (diameter, point angle); and the constants of the empirical cutting law of each
material. The law of one layer, at the feed rate ``v`` (m/s) and the spindle speed ``w`` (rad/s,
SI: 1500 rpm is 50 pi = 157.08 rad/s), is

    F = K (v / v_ref)^a (w / w_ref)^b,    T = K_T (v / v_ref)^a_T (w / w_ref)^b_T,

with ``K`` and ``K_T`` the thrust (N) and torque (N m) at the reference feed, speed and density,
scaled by ``(rho / rho_ref)^d`` for a layer of another density. Below the feed ``feed_floor`` the
power law (whose slope is unbounded at zero feed) is replaced by the quadratic that meets it with
the same value and slope, so the feed derivative stays finite; at ``v <= 0`` (retracting or
still) nothing is cut and both are zero.

The point (a cone of length ``L = (D / 2) / tan(point_angle / 2)``) enters each layer gradually:
past an interface by ``u``, the engaged share of the lips is the cubic smoothstep ``E(u / L)``
(``E(s) = s^2 (3 - 2 s)`` on [0, 1], 0 before, 1 after; C1, with the same mean as the straight
ramp of a uniformly loaded lip). The chisel edge at the very tip carries the share ``c`` of the
thrust (``Drill.chisel_share``) and enters over its own, shorter axial length
``l = (web / 2) / tan(point_angle / 2)``. A layer between the depths ``z0 < z1`` weighs, in the
thrust, ``(1 - c) (E_L(z - z0) - E_L(z - z1)) + c (E_l(z - z0) - E_l(z - z1))`` at the tip depth
``z``, and in the torque the lips' part alone; each part integrates to ``z1 - z0`` over the travel,
so the work of a layer does not depend on ``c``, and ``c = 0`` is the lips' model exactly. The
forces are zero before contact (``z <= 0``) and after breakthrough (``z >= depth of the far
surface + L``), and drop smoothly in between.

Every power is the C library's ``pow`` (:func:`math.pow`, element by element), not NumPy's
``power``, which on machines with AVX-512 takes SIMD routines that differ from it in the last bit
(5,204 of 100,000 random feeds, measured on the project's machine): the C header
``model/csrc/vgt_drill.h`` does the same arithmetic in the same order, so a compiled loop gives the same
bits as the NumPy one (``tests/test_drilling_model.py``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import checks
from ..errors import ConfigError, InputError, cut, shown
from ..fileio import parse_toml, read_text_limited

Array = NDArray[np.float64]

#: The C header with the same arithmetic (static inline functions, C99, no heap).
HEADER = Path(__file__).resolve().parent.parent / "model" / "csrc" / "vgt_drill.h"
#: The femur's bone file shipped with the package (the same as ``examples/bones/femur_diaphysis.toml``):
#: ``vgtarm reproduce`` drills it.
FEMUR = Path(__file__).resolve().parent / "data" / "femur_diaphysis.toml"
#: The same femur with its far cortex's cap breaking out (``examples/bones/femur_diaphysis_cap.toml``).
FEMUR_CAP = FEMUR.with_name("femur_diaphysis_cap.toml")
#: Largest bone file read (bytes).
BONE_FILE_LIMIT = 2**20
#: Most layers a bone may have.
MAX_LAYERS = 64
#: Numbers per layer in :attr:`Bone.coefficients` (the C header's ``VGT_DRILL_COEFFICIENTS``).
N_COEFFICIENTS = 6
#: Columns of :attr:`Bone.coefficients`, in order.
COEFFICIENT_NAMES = (
    "thrust",
    "thrust_feed_exponent",
    "thrust_speed_exponent",
    "torque",
    "torque_feed_exponent",
    "torque_speed_exponent",
)
_SOURCE_LENGTH = 200
# Generous physical bounds: far beyond any bone or surgical drill, they keep every product finite.
_MAX_THICKNESS = 1.0  # m
_MAX_DENSITY = 1e5  # kg/m^3
_MAX_FORCE = 1e5  # N
_MAX_TORQUE = 1e3  # N m
_MAX_DIAMETER = 0.1  # m
_MAX_FEED = 1.0  # m/s
_MAX_SPEED = 1e5  # rad/s


@dataclass(frozen=True)
class Material:
    """The cutting law's constants of one bone material: the thrust (N) and torque (N m) at the
    bone's reference feed and spindle speed and at this material's reference ``density``
    (kg/m^3), their exponents in the feed and the speed, and the exponent of the density."""

    name: str
    density: float
    thrust: float
    thrust_feed_exponent: float
    thrust_speed_exponent: float
    torque: float
    torque_feed_exponent: float
    torque_speed_exponent: float
    density_exponent: float


@dataclass(frozen=True)
class Layer:
    """One layer along the drill axis: its ``material`` (a name of the bone's materials), its
    ``thickness`` (m) and ``density`` (kg/m^3)."""

    material: str
    thickness: float
    density: float


@dataclass(frozen=True)
class Drill:
    """A twist drill: its ``diameter`` (m), ``point_angle`` (rad, the full angle of the cone), the
    share of the thrust its chisel edge carries (``chisel_share``, 0 to < 1; 0 gives the lips
    alone, the model before the chisel was added) and its ``web_thickness`` (m, < diameter: the
    width of the chisel edge, which sets the chisel's axial length)."""

    diameter: float
    point_angle: float
    chisel_share: float
    web_thickness: float

    @property
    def point_length(self) -> float:
        """Length of the drill point along the axis (m): ``(D / 2) / tan(point_angle / 2)``, the
        distance over which the lips enter a layer."""
        return 0.5 * self.diameter / math.tan(0.5 * self.point_angle)

    @property
    def chisel_length(self) -> float:
        """Axial length of the chisel edge's region at the tip (m): ``(web / 2) / tan(point_angle / 2)``,
        the depth of the cone under the web, over which the chisel's share enters a layer (shorter
        than :attr:`point_length` since the web is thinner than the drill)."""
        return 0.5 * self.web_thickness / math.tan(0.5 * self.point_angle)


@dataclass(frozen=True)
class Bone:
    """A bone to drill through: its layers from the entry surface down, the drill, the materials'
    constants and the law's reference feed (m/s), spindle speed (rad/s) and feed floor (m/s).
    Build with :func:`load_bone` or :func:`bone_from_dict`; :meth:`to_dict` gives the mapping back."""

    name: str
    layers: tuple[Layer, ...]
    drill: Drill
    materials: tuple[Material, ...]
    reference_feed: float
    reference_speed: float
    feed_floor: float
    cap_strength: float | None = None  # (Pa) the far cortex's cap breaks out (:func:`cap_thickness`); None: never

    def material(self, name: str) -> Material:
        """The material called ``name``."""
        for m in self.materials:
            if m.name == name:
                return m
        checks.refuse("material", name, f"one of {[m.name for m in self.materials]}", InputError)

    @property
    def point_length(self) -> float:
        """Length of the drill point (m), :attr:`Drill.point_length`."""
        return self.drill.point_length

    @property
    def chisel_length(self) -> float:
        """Axial length of the chisel edge (m), :attr:`Drill.chisel_length`."""
        return self.drill.chisel_length

    @property
    def chisel_share(self) -> float:
        """Share of the thrust the chisel edge carries, :attr:`Drill.chisel_share`."""
        return self.drill.chisel_share

    @cached_property
    def boundaries(self) -> Array:
        """Depths of the interfaces (m), ``(n_layers + 1,)``, read-only: 0 (the entry surface),
        then each layer's far side, summed in order."""
        depths = [0.0]
        for layer in self.layers:
            depths.append(depths[-1] + layer.thickness)
        return _frozen(np.array(depths))

    @property
    def thickness(self) -> float:
        """Depth of the far surface (m): the sum of the layers' thicknesses."""
        return float(self.boundaries[-1])

    @property
    def breakthrough_depth(self) -> float:
        """Tip depth (m) at which the whole point has left the last layer: the forces are zero
        beyond it."""
        return self.thickness + self.point_length

    @cached_property
    def coefficients(self) -> Array:
        """The law's numbers of each layer, ``(n_layers, 6)``, read-only, columns :data:`COEFFICIENT_NAMES`:
        the thrust (N) and torque (N m) at the reference feed and speed, already scaled by
        ``(density / material density)^density_exponent`` (:func:`math.pow`), and the exponents.
        The C header takes this array as it is."""
        rows = []
        for layer in self.layers:
            m = self.material(layer.material)
            scale = math.pow(layer.density / m.density, m.density_exponent)
            rows.append(
                (
                    m.thrust * scale,
                    m.thrust_feed_exponent,
                    m.thrust_speed_exponent,
                    m.torque * scale,
                    m.torque_feed_exponent,
                    m.torque_speed_exponent,
                )
            )
        return _frozen(np.array(rows, dtype=np.float64).reshape(len(self.layers), N_COEFFICIENTS))

    def to_dict(self) -> dict[str, Any]:
        """The bone as the mapping a bone file parses to (:func:`bone_from_dict` reads it back)."""
        materials = {
            m.name: {key: getattr(m, key) for key in _MATERIAL_BOUNDS}
            for m in self.materials  # fields of each material, without its name
        }
        return {
            "name": self.name,
            "drill": {key: getattr(self.drill, key) for key in (*_DRILL_BOUNDS, *_DRILL_OPTIONAL)},
            "model": {
                "reference_feed": self.reference_feed,
                "reference_speed": self.reference_speed,
                "feed_floor": self.feed_floor,
                **({} if self.cap_strength is None else {"cap_strength": self.cap_strength}),
            },
            "materials": materials,
            "layers": [{"material": x.material, "thickness": x.thickness, "density": x.density} for x in self.layers],
        }


def _frozen(array: Array) -> Array:
    """``array`` made read-only (a cached property of a frozen bone)."""
    array.flags.writeable = False
    return array


@dataclass(frozen=True)
class DrillingForces:
    """The drill's thrust (N, along the axis, against the feed) and torque (N m, about the axis,
    against the spindle) and the thrust's derivatives in the tip depth (N/m: the contact's
    stiffness along the axis) and in the feed rate (N s/m: its damping), each of the broadcast
    shape of the depth, the feed and the speed given."""

    thrust: Array
    torque: Array
    thrust_depth_slope: Array
    thrust_feed_slope: Array


# -- the bone file ---------------------------------------------------------------------------------

#: Each material's fields, their bounds and units (a feed exponent in (0, 2) keeps the feed law's
#: quadratic below the floor increasing).
_MATERIAL_BOUNDS: dict[str, dict[str, Any]] = {
    "density": {"above": 0.0, "maximum": _MAX_DENSITY, "unit": "kg/m^3"},
    "thrust": {"minimum": 0.0, "maximum": _MAX_FORCE, "unit": "N"},
    "thrust_feed_exponent": {"above": 0.0, "below": 2.0},
    "thrust_speed_exponent": {"minimum": -2.0, "maximum": 2.0},
    "torque": {"minimum": 0.0, "maximum": _MAX_TORQUE, "unit": "N m"},
    "torque_feed_exponent": {"above": 0.0, "below": 2.0},
    "torque_speed_exponent": {"minimum": -2.0, "maximum": 2.0},
    "density_exponent": {"minimum": 0.0, "maximum": 4.0},
}
_MODEL_BOUNDS: dict[str, dict[str, Any]] = {
    "reference_feed": {"above": 0.0, "maximum": _MAX_FEED, "unit": "m/s"},
    "reference_speed": {"above": 0.0, "maximum": _MAX_SPEED, "unit": "rad/s"},
    "feed_floor": {"above": 0.0, "maximum": _MAX_FEED, "unit": "m/s"},
}
_DRILL_BOUNDS: dict[str, dict[str, Any]] = {
    "diameter": {"above": 0.0, "maximum": _MAX_DIAMETER, "unit": "m"},
    "point_angle": {"above": 0.0, "below": math.pi, "unit": "rad"},
}
#: The drill's optional keys: without ``chisel_share`` the lips carry all the thrust (the model of
#: files written before the chisel edge was added); without ``web_thickness`` the web is this share
#: of the diameter (the lower end of the 0.1-0.2 D of twist drills; it matters only with a chisel share).
_DRILL_OPTIONAL = ("chisel_share", "web_thickness")
DEFAULT_WEB_RATIO = 0.1


class _Reader:
    """Checks of a parsed bone file, each refusing in one :class:`ConfigError` line naming the file
    and the field: ``bone.toml: field 'layers[1].thickness' = -0.001: expected ...``."""

    def __init__(self, source: str) -> None:
        self.source = cut(str(source), _SOURCE_LENGTH)

    def field(self, name: str) -> str:
        return f"{self.source}: field '{name}'"

    def table(self, data: object, where: str, required: set[str], optional: frozenset[str] = frozenset()) -> None:
        """``data`` is a table with every key of ``required`` and no key but those and ``optional``."""
        if not isinstance(data, Mapping):
            checks.refuse(self.field(where or "top level"), data, "a table", ConfigError)
        allowed = required | optional
        unknown = sorted((str(k) for k in data if k not in allowed), key=str)
        if unknown:
            raise ConfigError(
                f"{self.source}: unknown key '{_join(where, cut(unknown[0]))}'; expected one of {sorted(allowed)}"
            )
        missing = sorted(required - set(data))
        if missing:
            raise ConfigError(f"{self.source}: missing key '{_join(where, missing[0])}'")

    def numbers(self, data: Mapping[str, Any], where: str, bounds: dict[str, dict[str, Any]]) -> dict[str, float]:
        """Every field of ``bounds`` in the table ``data`` as a float within its bounds."""
        self.table(data, where, set(bounds))
        return {
            key: checks.number(self.field(_join(where, key)), data[key], error=ConfigError, **spec)
            for key, spec in bounds.items()
        }


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def load_bone(path: str | os.PathLike[str]) -> Bone:
    """The bone of the TOML file ``path`` (the format of ``examples/bones/*.toml``).

    Raises:
        ConfigError: one line naming the file and, for a bad value, the field: a missing,
            unreadable or too large file, a TOML syntax error, an unknown or missing key, an empty
            layer list, a thickness <= 0, an unknown material, a NaN or any value out of bounds.
    """
    if not isinstance(path, str | os.PathLike):
        raise ConfigError(f"bone file {shown(path)}: expected a file name (str or Path)")
    text = read_text_limited(path, BONE_FILE_LIMIT, "bone file", error=ConfigError)
    return bone_from_dict(parse_toml(text, cut(str(path), _SOURCE_LENGTH), error=ConfigError), source=str(path))


def bone_from_dict(data: Mapping[str, Any], *, source: str = "<dict>") -> Bone:
    """Build a :class:`Bone` from the mapping a bone file parses to (see :func:`load_bone`)."""
    reader = _Reader(source)
    reader.table(data, "", {"drill", "model", "materials", "layers"}, frozenset({"name"}))
    name = data.get("name", "bone")
    if not isinstance(name, str) or not name.strip() or len(name) > 200:
        checks.refuse(reader.field("name"), name, "a text of 1 to 200 characters", ConfigError)
    drill = _read_drill(reader, data["drill"])
    table = data["model"]
    cap = None
    if isinstance(table, Mapping) and "cap_strength" in table:  # optional: the cap's breakout
        cap = checks.number(
            reader.field("model.cap_strength"),
            table["cap_strength"],
            above=0.0,
            maximum=1e10,
            unit="Pa",
            error=ConfigError,
        )
        table = {key: value for key, value in table.items() if key != "cap_strength"}
    model = reader.numbers(table, "model", _MODEL_BOUNDS)
    materials = _read_materials(reader, data["materials"])
    layers = _read_layers(reader, data["layers"], {m.name: m for m in materials})
    return Bone(name.strip(), layers, drill, materials, **model, cap_strength=cap)


#: The factor ``k`` of :func:`cap_thickness`: the largest bending stress of a thin circular plate
#: under a central load is about ``k F / t^2`` (Roark's formulas, a simply supported plate under a
#: load on a small central circle: ``k`` from 0.5 to 0.9 with the load circle; the lower end here).
CAP_FACTOR = 0.5


def cap_thickness(bone: Bone, thrust: float) -> float:
    """The thickness (m) of bone left ahead of the drill's apex below which the cap breaks out under
    ``thrust`` (N): ``sqrt(CAP_FACTOR thrust / cap_strength)``; 0 without a cap strength."""
    if bone.cap_strength is None or thrust <= 0.0:
        return 0.0
    return math.sqrt(CAP_FACTOR * thrust / bone.cap_strength)


def _read_drill(reader: _Reader, table: object) -> Drill:
    """The ``[drill]`` table: diameter and point angle, and the optional chisel share (in [0, 1))
    and web thickness (in (0, diameter))."""
    reader.table(table, "drill", set(_DRILL_BOUNDS), frozenset(_DRILL_OPTIONAL))
    assert isinstance(table, Mapping)
    values = {
        key: checks.number(reader.field(f"drill.{key}"), table[key], error=ConfigError, **spec)
        for key, spec in _DRILL_BOUNDS.items()
    }
    diameter = values["diameter"]
    share = table.get("chisel_share", 0.0)
    share = checks.number(reader.field("drill.chisel_share"), share, minimum=0.0, below=1.0, error=ConfigError)
    web = table.get("web_thickness", DEFAULT_WEB_RATIO * diameter)
    web = checks.number(
        reader.field("drill.web_thickness"), web, above=0.0, below=diameter, unit="m", error=ConfigError
    )
    return Drill(diameter, values["point_angle"], share, web)


def _read_materials(reader: _Reader, table: object) -> tuple[Material, ...]:
    if not isinstance(table, Mapping) or not table:
        checks.refuse(reader.field("materials"), table, "a table of one or more materials", ConfigError)
    return tuple(
        Material(str(key), **reader.numbers(entry, f"materials.{cut(str(key))}", _MATERIAL_BOUNDS))
        for key, entry in table.items()
    )


def _read_layers(reader: _Reader, items: object, materials: Mapping[str, Material]) -> tuple[Layer, ...]:
    if not isinstance(items, list) or not items:
        checks.refuse(reader.field("layers"), items, "a list of one or more layers ([[layers]])", ConfigError)
    if len(items) > MAX_LAYERS:
        checks.refuse(reader.field("layers"), f"<{len(items)} layers>", f"at most {MAX_LAYERS} layers", ConfigError)
    layers = []
    for i, item in enumerate(items):
        where = f"layers[{i}]"
        reader.table(item, where, {"material", "thickness"}, frozenset({"density"}))
        material = item["material"]
        if not isinstance(material, str) or material not in materials:
            checks.refuse(reader.field(f"{where}.material"), material, f"one of {sorted(materials)}", ConfigError)
        thickness = checks.number(
            reader.field(f"{where}.thickness"),
            item["thickness"],
            above=0.0,
            maximum=_MAX_THICKNESS,
            unit="m",
            error=ConfigError,
        )
        density = materials[material].density
        if "density" in item:
            spec = _MATERIAL_BOUNDS["density"]
            density = checks.number(reader.field(f"{where}.density"), item["density"], error=ConfigError, **spec)
        layers.append(Layer(material, thickness, density))
    return tuple(layers)


# -- the law -----------------------------------------------------------------------------------------


def engagement(u: ArrayLike, length: float) -> Array:
    """Engaged share of the lips (0 to 1) with the tip ``u`` (m) past an interface, for a point of
    ``length`` (m): the cubic smoothstep ``s^2 (3 - 2 s)`` of ``s = u / length`` clipped to [0, 1]
    (``vgt_drill_engagement``)."""
    s = np.clip(np.asarray(u, dtype=np.float64) / length, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def engagement_slope(u: ArrayLike, length: float) -> Array:
    """Derivative of :func:`engagement` in ``u`` (1/m): ``6 s (1 - s) / length``, zero outside the
    point (``vgt_drill_engagement_slope``)."""
    s = np.clip(np.asarray(u, dtype=np.float64) / length, 0.0, 1.0)
    return 6.0 * s * (1.0 - s) / length


_pow = np.frompyfunc(math.pow, 2, 1)


def _power(base: Array, exponent: float) -> Array:
    """``base ** exponent`` element by element with the C library's ``pow`` (:func:`math.pow`),
    the same bits as the C header's (module docstring); ``base`` must be > 0."""
    return np.asarray(_pow(base, exponent), dtype=np.float64).reshape(base.shape)


def feed_law(feed: ArrayLike, exponent: float, reference_feed: float, feed_floor: float) -> tuple[Array, Array]:
    """The feed's factor of the law and its derivative in the feed (s/m), ``(g, dg/dv)``
    (``vgt_drill_feed_law``): 0 for ``feed <= 0``; ``(feed / reference_feed)^exponent`` from
    ``feed_floor`` up; below it ``c t ((2 - a) + (a - 1) t)`` with ``t = feed / feed_floor`` and
    ``c = (feed_floor / reference_feed)^a``, which meets the power law with the same value and
    slope at the floor and has a finite slope ``c (2 - a) / feed_floor`` at zero."""
    v = np.asarray(feed, dtype=np.float64)
    a = exponent
    g = np.zeros_like(v)
    dg = np.zeros_like(v)
    high = v >= feed_floor
    if high.any():
        g[high] = _power(v[high] / reference_feed, a)
        dg[high] = a * g[high] / v[high]
    low = (v > 0.0) & ~high
    if low.any():
        c = math.pow(feed_floor / reference_feed, a)
        t = v[low] / feed_floor
        g[low] = c * t * ((2.0 - a) + (a - 1.0) * t)
        dg[low] = c * ((2.0 - a) + 2.0 * (a - 1.0) * t) / feed_floor
    return g, dg


def _inputs(depth: ArrayLike, feed: ArrayLike, spindle_speed: ArrayLike) -> tuple[Array, Array, Array]:
    """The three arguments checked (finite; speed > 0) and broadcast to one shape."""
    z = checks.finite_array("depth", depth)
    v = checks.finite_array("feed", feed)
    w = checks.finite_array("spindle_speed", spindle_speed)
    if (w <= 0.0).any():
        index = tuple(int(i) for i in np.argwhere(w <= 0.0)[0])
        where = f"spindle_speed[{', '.join(map(str, index))}]" if index else "spindle_speed"
        checks.refuse(where, float(w[index]), "a finite number > 0 (rad/s)")
    try:
        z, v, w = np.broadcast_arrays(z, v, w)
    except ValueError:
        checks.refuse("depth, feed, spindle_speed shapes", (z.shape, v.shape, w.shape), "shapes that broadcast")
    return z, v, w


def layer_weights(bone: Bone, depth: ArrayLike) -> tuple[Array, Array]:
    """Each layer's share of the thrust at the tip depths ``depth`` (m, from the entry surface along
    the axis) and its derivative in the depth (1/m), each ``(..., n_layers)``: for the layer between
    the interfaces ``z_i`` and ``z_{i+1}``, ``(1 - c) (E_L(z - z_i) - E_L(z - z_{i+1})) +
    c (E_l(z - z_i) - E_l(z - z_{i+1}))``, the lips' ramp over the point length ``L`` and the chisel
    edge's over its length ``l``, ``c`` the chisel share. The torque's weight is the lips' alone
    (``c = 0``)."""
    z = checks.finite_array("depth", depth)[..., None]
    edges = bone.boundaries
    lips, lips_slope = _ramp_pair(z - edges[:-1], z - edges[1:], bone.point_length)
    chisel, chisel_slope = _ramp_pair(z - edges[:-1], z - edges[1:], bone.chisel_length)
    share = bone.chisel_share
    keep = 1.0 - share
    return keep * lips + share * chisel, keep * lips_slope + share * chisel_slope


def _ramp_pair(top: Array, bottom: Array, length: float) -> tuple[Array, Array]:
    """``E(top) - E(bottom)`` and its slope over a ramp of ``length`` (m): a layer's weight of one
    edge of the drill with the tip ``top`` past its near side and ``bottom`` past its far side."""
    weight = engagement(top, length) - engagement(bottom, length)
    slope = engagement_slope(top, length) - engagement_slope(bottom, length)
    return weight, slope


def layer_index(bone: Bone, depth: ArrayLike) -> NDArray[np.int64]:
    """Index of the layer that holds the tip at ``depth`` (m): -1 before the entry surface
    (``depth <= 0``), ``i`` for ``z_i < depth <= z_{i+1}``, ``n_layers`` past the far surface."""
    z = checks.finite_array("depth", depth)
    return np.searchsorted(bone.boundaries, z, side="left").astype(np.int64) - 1


def drilling_forces(bone: Bone, depth: ArrayLike, feed: ArrayLike, spindle_speed: ArrayLike) -> DrillingForces:
    """The thrust, torque and the thrust's derivatives with the tip at ``depth`` (m, along the
    axis from the entry surface), fed at ``feed`` (m/s, into the bone; <= 0 cuts nothing) with
    the spindle at ``spindle_speed`` (rad/s, > 0); the three broadcast together.

    Per layer, in the order of ``vgt_drill_forces``: the lips' weight ``w_L`` and slope and the
    chisel's ``w_l`` and slope (:func:`layer_weights`), the thrust's weight
    ``w = (1 - c) w_L + c w_l`` and slope, the feed factors and speed factors of thrust and torque,
    and the sums ``thrust += F w``, ``d thrust / d depth += F dw``, ``d thrust / d feed += K g' s w``,
    ``torque += T w_L`` (the chisel edge is taken to cut no torque: it scrapes near the axis).
    """
    z, v, w = _inputs(depth, feed, spindle_speed)
    edges, length, table = bone.boundaries, bone.point_length, bone.coefficients
    chisel_length, share = bone.chisel_length, bone.chisel_share
    keep = 1.0 - share
    thrust, torque = np.zeros(z.shape), np.zeros(z.shape)
    depth_slope, feed_slope = np.zeros(z.shape), np.zeros(z.shape)
    speed_ratio = w / bone.reference_speed
    for i, (k, a, b, k_torque, a_torque, b_torque) in enumerate(table):
        lips, lips_slope = _ramp_pair(z - edges[i], z - edges[i + 1], length)
        chisel, chisel_slope = _ramp_pair(z - edges[i], z - edges[i + 1], chisel_length)
        weight = keep * lips + share * chisel
        slope = keep * lips_slope + share * chisel_slope
        g, dg = feed_law(v, a, bone.reference_feed, bone.feed_floor)
        g_torque, _ = feed_law(v, a_torque, bone.reference_feed, bone.feed_floor)
        s = _power(speed_ratio, b)
        s_torque = _power(speed_ratio, b_torque)
        force = k * g * s
        thrust = thrust + force * weight
        depth_slope = depth_slope + force * slope
        feed_slope = feed_slope + k * dg * s * weight
        torque = torque + k_torque * g_torque * s_torque * lips
    return DrillingForces(thrust, torque, depth_slope, feed_slope)


def _scalar_engagement(u: float, length: float) -> tuple[float, float]:
    """:func:`engagement` and :func:`engagement_slope` of one float, in the same operations."""
    s = min(max(u / length, 0.0), 1.0)
    return s * s * (3.0 - 2.0 * s), 6.0 * s * (1.0 - s) / length


def _scalar_feed_law(v: float, a: float, reference_feed: float, feed_floor: float) -> tuple[float, float]:
    """:func:`feed_law` of one float, in the same operations."""
    if v >= feed_floor:
        g = math.pow(v / reference_feed, a)
        return g, a * g / v
    if v > 0.0:
        c = math.pow(feed_floor / reference_feed, a)
        t = v / feed_floor
        return c * t * ((2.0 - a) + (a - 1.0) * t), c * ((2.0 - a) + 2.0 * (a - 1.0) * t) / feed_floor
    return 0.0, 0.0


def drilling_forces_at(
    bone: Bone, depth: float, feed: float, spindle_speed: float
) -> tuple[float, float, float, float]:
    """:func:`drilling_forces` at one tip depth (m), feed (m/s) and spindle speed (rad/s) in plain
    floats, for a loop that steps one sample at a time (5 us a call against 170 us for the arrays):
    ``(thrust, torque, thrust_depth_slope, thrust_feed_slope)``, the same bits as the arrays and the
    C header. The arguments are not checked (finite; speed > 0): the loop checks its inputs once."""
    edges = bone.boundaries.tolist()
    length, chisel_length, share = bone.point_length, bone.chisel_length, bone.chisel_share
    keep = 1.0 - share
    thrust = torque = depth_slope = feed_slope = 0.0
    speed_ratio = spindle_speed / bone.reference_speed
    for i, (k, a, b, k_torque, a_torque, b_torque) in enumerate(bone.coefficients.tolist()):
        e_top, slope_top = _scalar_engagement(depth - edges[i], length)
        e_bottom, slope_bottom = _scalar_engagement(depth - edges[i + 1], length)
        lips, lips_slope = e_top - e_bottom, slope_top - slope_bottom
        e_top, slope_top = _scalar_engagement(depth - edges[i], chisel_length)
        e_bottom, slope_bottom = _scalar_engagement(depth - edges[i + 1], chisel_length)
        chisel, chisel_slope = e_top - e_bottom, slope_top - slope_bottom
        weight = keep * lips + share * chisel
        slope = keep * lips_slope + share * chisel_slope
        g, dg = _scalar_feed_law(feed, a, bone.reference_feed, bone.feed_floor)
        g_torque, _ = _scalar_feed_law(feed, a_torque, bone.reference_feed, bone.feed_floor)
        s = math.pow(speed_ratio, b)
        s_torque = math.pow(speed_ratio, b_torque)
        force = k * g * s
        thrust = thrust + force * weight
        depth_slope = depth_slope + force * slope
        feed_slope = feed_slope + k * dg * s * weight
        torque = torque + k_torque * g_torque * s_torque * lips
    return thrust, torque, depth_slope, feed_slope
