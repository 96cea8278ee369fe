"""The mechanism's drawn geometry: every point, bar and plate of the robot at a configuration.

One plain record, :class:`MechanismGeometry`, is built from the model's forward kinematics and
the robot's dimensions, and everything that shows the robot reads it: the Matplotlib drawing
(:mod:`vgtarm.app.drawing`), the animation (:mod:`vgtarm.app.animation`) and the interactive page
(:mod:`vgtarm.app.html_report`). Nothing here is a sketch: the joints follow the spec's module
(``shared/spec/mechanism.md``) from the passive angles the model returns.

Module ``k`` in its own plane ``(h, z)``: base joints ``A = (-b, 0)``, ``B = (b, 0)``; top joints
``A' = A + s (cos alpha, sin alpha)`` and ``B' = A + p (cos beta, sin beta)``. Module 1's plane is
F0's ``u2-u3`` plane, ``(h, z) -> (0, h, z)``; module 2's is F1's ``u1-u3`` plane, mirrored,
``(h, z) -> (-h, 0, z)``, carried into F0 by ``O1`` and ``C01``. The platform centres, the tool
(from O2 along ``C02 u3`` for ``h1``) and the frames follow; the tests check them against the
model's own platform centres and tip.

Lengths are in metres, in F0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from ..model.parameters import JOINT_NAMES, JOINT_UNITS, RobotParameters
from ..model.robot import ForwardKinematics, Robot

Array = NDArray[np.float64]

#: Kinds of drawn segment, in drawing order.
SEGMENT_KINDS = ("base", "leg", "platform", "twist_axis", "tool", "end_effector")
#: Length of the frames' axis arrows as a fraction of module 1's base half-width.
FRAME_AXIS_FRACTION = 0.6
#: Half-length of the end-effector's cross-bar as a fraction of module 2's platform half-width.
END_EFFECTOR_FRACTION = 0.6
#: How far the dashed twist axis runs past the tool at each end, as a fraction of ``h1``.
TWIST_AXIS_OVERHANG = 0.5


@dataclass(frozen=True)
class Segment:
    """One straight bar of the drawing.

    Attributes:
        name: ``"s1"``, ``"v1"``, ``"p1"`` ... for legs (the joint's name), ``"base1"``,
            ``"platform1"`` (the module's top edge ``A'B'``), ``"tool"``, ``"twist_axis"``,
            ``"end_effector"``.
        kind: one of :data:`SEGMENT_KINDS`.
        start, end: end points (3,) in F0 (m).
        joint: index in ``q`` of the joint that drives this bar (legs, and the twist for the
            end-effector's cross-bar), else ``None``.
        closeness: how close that joint is to a limit, 0 in the middle of its range, 1 at a
            limit (see :func:`limit_closeness`); ``None`` for bars without a joint.
    """

    name: str
    kind: str
    start: Array
    end: Array
    joint: int | None = None
    closeness: float | None = None

    @property
    def length(self) -> float:
        """Distance between the end points (m)."""
        return float(np.linalg.norm(self.end - self.start))


@dataclass(frozen=True)
class Plate:
    """A flat body drawn as a closed polygon: ``"base"``, ``"platform1"``, ``"platform2"``.

    ``vertices`` (k, 3) in F0 (m), in order around the polygon (not repeated at the end).
    """

    name: str
    vertices: Array


@dataclass(frozen=True)
class FrameAxes:
    """A frame drawn as three short axes: ``origin`` (3,) and ``rotation`` (3, 3) in F0.

    ``label`` is ``"F0"`` .. ``"F3"``; F3's axes are drawn at the tip (its orientation is the
    end-effector's ``C03``; the spec puts its origin at O2, where F2's axes already are).
    """

    label: str
    origin: Array
    rotation: Array


@dataclass(frozen=True)
class MechanismGeometry:
    """Everything drawn of the robot at one configuration ``q`` (m, rad, F0).

    Attributes:
        q: the configuration (n,).
        joints: named joint points (3,): ``A1, B1, A1', B1', A2, B2, A2', B2'`` (base and top
            joints of each module), ``O1, O2`` (platform centres), ``P`` (the tip).
        segments: the bars, in the order of :data:`SEGMENT_KINDS`.
        plates: base and platforms as polygons.
        frames: F0, F1, F2, F3 as small axes.
        axis_length: length of the frames' axes (m).
    """

    q: Array
    joints: dict[str, Array]
    segments: tuple[Segment, ...]
    plates: tuple[Plate, ...]
    frames: tuple[FrameAxes, ...]
    axis_length: float

    @property
    def tip(self) -> Array:
        """The tip point P (3,) in F0 (m), the far end of the tool."""
        return self.joints["P"]

    def segment(self, name: str) -> Segment:
        """The segment called ``name``; :class:`~vgtarm.errors.InputError` lists the names if unknown."""
        for seg in self.segments:
            if seg.name == name:
                return seg
        raise InputError(f"segment = {name!r}: expected one of {[s.name for s in self.segments]}")

    def of_kind(self, kind: str) -> tuple[Segment, ...]:
        """The segments of one kind (see :data:`SEGMENT_KINDS`)."""
        if kind not in SEGMENT_KINDS:
            raise InputError(f"kind = {kind!r}: expected one of {list(SEGMENT_KINDS)}")
        return tuple(s for s in self.segments if s.kind == kind)

    def points(self) -> Array:
        """Every drawn point stacked, (m, 3): for the extent of a view."""
        parts = [np.stack([s.start, s.end]) for s in self.segments]
        parts += [p.vertices for p in self.plates]
        parts += [f.origin + self.axis_length * f.rotation.T for f in self.frames]
        return np.concatenate(parts)


def limit_closeness(q: ArrayLike, lower: ArrayLike, upper: ArrayLike) -> Array:
    """How close each joint is to its nearer limit: ``1 - 2 min(u, 1 - u)`` with ``u`` the
    position within ``[lower, upper]``; 0 at mid-range, 1 at a limit, above 1 outside.

    Shapes broadcast; ``(..., n)`` in, ``(..., n)`` out.
    """
    qa, lo, hi = (np.asarray(x, dtype=float) for x in (q, lower, upper))
    u = (qa - lo) / (hi - lo)
    return np.asarray(1.0 - 2.0 * np.minimum(u, 1.0 - u))


def leg_joints(parameters: RobotParameters) -> list[tuple[int, int, int]]:
    """Indices in ``q`` of ``(s, v, p)`` of each module, from the joint names (``s1, v1, p1`` ...)."""
    found = []
    for k in range(1, len(parameters.modules) + 1):
        try:
            found.append(tuple(JOINT_NAMES.index(f"{leg}{k}") for leg in "svp"))
        except ValueError:
            raise InputError(f"the joint vector {JOINT_NAMES} has no legs s{k}, v{k}, p{k} for module {k}") from None
    return found  # type: ignore[return-value]


def twist_joint() -> int:
    """Index in ``q`` of the twist joint: the one angular (``rad``) joint."""
    angular = [i for i, unit in enumerate(JOINT_UNITS) if unit == "rad"]
    if len(angular) != 1:
        raise InputError(f"expected one angular joint in {JOINT_NAMES}, found {len(angular)}")
    return angular[0]


def _module_points(q: Array, legs: tuple[int, int, int], passive: Array, b: float) -> dict[str, Array]:
    """Base and top joints of one module in its plane, ``(h, z)``."""
    s, _, p = (float(q[i]) for i in legs)
    alpha, beta = float(passive[0]), float(passive[1])
    a = np.array([-b, 0.0])
    return {
        "A": a,
        "B": np.array([b, 0.0]),
        "A'": a + s * np.array([np.cos(alpha), np.sin(alpha)]),
        "B'": a + p * np.array([np.cos(beta), np.sin(beta)]),
    }


def geometry_from_kinematics(parameters: RobotParameters, q: ArrayLike, fk: ForwardKinematics) -> MechanismGeometry:
    """The drawn geometry of one configuration ``q`` (n,) from its forward kinematics ``fk``.

    ``fk`` must be the forward kinematics of ``q`` alone (no batch axes); the passive angles and
    the platform rotations are taken from it, the points are built from the module equations.
    """
    qa = np.asarray(q, dtype=float)
    if qa.ndim != 1 or fk.tip.shape != (3,):
        raise InputError(f"q must be one configuration (n,), got shape {qa.shape}")
    p = parameters
    legs = leg_joints(p)
    twist = twist_joint()
    closeness = limit_closeness(qa, p.lower, p.upper)
    c01, c02 = fk.platform_rotation[0], fk.platform_rotation[1]
    # Module 1: (h, z) -> (0, h, z) in F0. Module 2: (h, z) -> (-h, 0, z) in F1, then O1 + C01 x.
    plane1 = _module_points(qa, legs[0], fk.passive[0], p.modules[0].b)
    plane2 = _module_points(qa, legs[1], fk.passive[1], p.modules[1].b)
    joints: dict[str, Array] = {f"{name}1": np.array([0.0, hz[0], hz[1]]) for name, hz in plane1.items()}
    o1 = 0.5 * (joints["A'1"] + joints["B'1"])
    for name, hz in plane2.items():
        joints[f"{name}2"] = o1 + c01 @ np.array([-hz[0], 0.0, hz[1]])
    o2 = 0.5 * (joints["A'2"] + joints["B'2"])
    axis = c02[:, 2]
    tip = o2 + p.h1 * axis
    joints.update(O1=o1, O2=o2, P=tip)

    segments: list[Segment] = []
    for k in (1, 2):
        segments.append(Segment(f"base{k}", "base", joints[f"A{k}"], joints[f"B{k}"]))
    for k, (i_s, i_v, i_p) in enumerate(legs, start=1):
        for index, start, end in ((i_s, "A", "A'"), (i_v, "B", "B'"), (i_p, "A", "B'")):
            segments.append(
                Segment(
                    JOINT_NAMES[index],
                    "leg",
                    joints[f"{start}{k}"],
                    joints[f"{end}{k}"],
                    joint=index,
                    closeness=float(closeness[index]),
                )
            )
    for k in (1, 2):
        segments.append(Segment(f"platform{k}", "platform", joints[f"A'{k}"], joints[f"B'{k}"]))
    overhang = TWIST_AXIS_OVERHANG * p.h1
    segments.append(Segment("twist_axis", "twist_axis", o2 - overhang * axis, tip + overhang * axis))
    segments.append(Segment("tool", "tool", o2, tip))
    half_bar = END_EFFECTOR_FRACTION * p.modules[1].d
    bar_centre = o2 + 0.5 * p.h1 * axis
    bar = fk.rotation[:, 0]
    segments.append(
        Segment(
            "end_effector",
            "end_effector",
            bar_centre - half_bar * bar,
            bar_centre + half_bar * bar,
            joint=twist,
            closeness=float(closeness[twist]),
        )
    )

    b1, d2 = p.modules[0].b, p.modules[1].d
    base_plate = np.array([[b1, 0.0, 0.0], [0.0, b1, 0.0], [-b1, 0.0, 0.0], [0.0, -b1, 0.0]])
    plates = (
        Plate("base", base_plate),
        # platform 1 carries module 1's top joints and module 2's base joints
        Plate("platform1", np.stack([joints["A'1"], joints["A2"], joints["B'1"], joints["B2"]])),
        # platform 2 carries module 2's top joints; its other diagonal (no joints) is drawn as long
        Plate("platform2", np.stack([joints["A'2"], o2 + d2 * c02[:, 1], joints["B'2"], o2 - d2 * c02[:, 1]])),
    )
    frames = (
        FrameAxes("F0", np.zeros(3), np.eye(3)),
        FrameAxes("F1", o1, c01),
        FrameAxes("F2", o2, c02),
        FrameAxes("F3", tip, fk.rotation),
    )
    return MechanismGeometry(
        q=qa.copy(),
        joints=joints,
        segments=tuple(sorted(segments, key=lambda s: SEGMENT_KINDS.index(s.kind))),
        plates=plates,
        frames=frames,
        axis_length=FRAME_AXIS_FRACTION * b1,
    )


def mechanism_geometry(robot: Robot, q: ArrayLike) -> MechanismGeometry:
    """The drawn geometry of ``robot`` at one configuration ``q`` (n,) (m, rad)."""
    qa = np.asarray(q, dtype=float)
    if qa.ndim != 1:
        raise InputError(f"q must be one configuration (n,), got shape {qa.shape}; use mechanism_geometries")
    return geometry_from_kinematics(robot.parameters, qa, robot.forward_kinematics(qa))


def mechanism_geometries(robot: Robot, q: ArrayLike) -> list[MechanismGeometry]:
    """The drawn geometry of every configuration of ``q`` (m, n), from one batched FK call."""
    qa = np.asarray(q, dtype=float)
    if qa.ndim != 2:
        raise InputError(f"q must be a batch of configurations (m, n), got shape {qa.shape}")
    fk = robot.forward_kinematics(qa)
    return [
        geometry_from_kinematics(
            robot.parameters,
            qa[i],
            ForwardKinematics(
                passive=fk.passive[i],
                platform_position=fk.platform_position[i],
                platform_rotation=fk.platform_rotation[i],
                tip=fk.tip[i],
                rotation=fk.rotation[i],
            ),
        )
        for i in range(len(qa))
    ]
