"""The mechanism's drawn geometry: every point, bar and plate of the robot at a configuration.

One plain record, :class:`MechanismGeometry`, is built from the model's forward kinematics and
the robot's dimensions, and everything that shows the robot reads it: the Matplotlib drawing
(:mod:`vgtarm.app.pictures.drawing`), the animation (:mod:`vgtarm.app.pictures.animation`) and the interactive page
(:mod:`vgtarm.app.reports.html`). Nothing here is a sketch: the joints follow the spec's module
(``docs/conventions.md``) from the passive angles the model returns.

Any robot is drawn the same way, as a stack of modules (the paper's robot is the stack of
:func:`~vgtarm.model.stack.description.stack_from_parameters`: modules at 0 and 90 degrees, a
twist ``h1`` high after module 2, no tool offset). Module ``k`` stands on a frame ``(o, R)`` (F0
for module 1) and lies in its plane ``(h, z)``: base joints ``A = (-b, 0)``, ``B = (b, 0)``; top
joints ``A' = A + s (cos alpha, sin alpha)`` and ``B' = A + p (cos beta, sin beta)``. With
``phi`` the module's plane angle, ``h`` runs along ``R (-sin phi, cos phi, 0)`` and ``z`` along
``R u3``: ``(h, z) -> o + R (-h sin phi, h cos phi, z)``, which is module 1's ``(0, h, z)`` and
module 2's mirrored ``(-h, 0, z)`` of the paper. The platform centre ``O_k`` is the middle of
``A'B'``, its frame ``C_0k`` the model's. What stands on module ``k`` stands on ``(O_k, C_0k)``,
or, after a twist joint ``psi``, on ``(O_k + height C_0k u3, C_0k Rz(psi))``; the tip is the last
such origin plus the end-effector's rotation times the tool offset. From the tip a short line runs
along the tool's axis (``C03 @ axis``, :meth:`vgtarm.Robot.tool_axis`). The tests check the centres
and the tip against the model's own.

Lengths are in metres, in F0.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import InputError, shown
from ...model.parameters import JOINT_NAMES, JOINT_UNITS, RobotParameters
from ...model.robot import ForwardKinematics, Robot
from ...model.stack.description import Stack, stack_from_parameters
from ...model.stack.symbolic import plane_direction

Array = NDArray[np.float64]

#: Kinds of drawn segment, in drawing order.
SEGMENT_KINDS = (
    "base",
    "leg",
    "platform",
    "twist",
    "twist_axis",
    "twist_bar",
    "tool",
    "end_effector",
    "tool_axis",
)
#: Length of the frames' axis arrows as a fraction of module 1's base half-width.
FRAME_AXIS_FRACTION = 0.6
#: Length of the tool's axis drawn from the tip, as a fraction of module 1's base half-width
#: (longer than the frames' axes, so it shows past the end-effector frame's ``z`` arrow).
TOOL_AXIS_FRACTION = 1.0
#: Half-length of a twist's cross-bar (the end-effector's, or an inner twist's) as a fraction of the
#: half-width of the platform it stands on.
END_EFFECTOR_FRACTION = 0.6
#: How far a dashed twist axis runs past its part at each end, as a fraction of the part's height.
TWIST_AXIS_OVERHANG = 0.5


@dataclass(frozen=True)
class Segment:
    """One straight bar of the drawing.

    Attributes:
        name: ``"s1"``, ``"v1"``, ``"p1"`` ... for legs (the joint's name), ``"base1"``,
            ``"platform1"`` (the module's top edge ``A'B'``), ``"tool"`` (the end-effector, from
            the last platform centre to the tip), ``"twist_axis"`` (the end-effector's twist
            axis), ``"end_effector"`` (its cross-bar), ``"tool_axis"`` (from the tip along the
            tool's axis, :data:`TOOL_AXIS_FRACTION` of module 1's base half-width); a twist
            joint ``psiN`` inside the arm gives ``"twistN"`` (its part, from the platform centre
            to the next module's mount), ``"twist_axisN"`` and ``"twist_barN"`` (its cross-bar).
        kind: one of :data:`SEGMENT_KINDS`.
        start, end: end points (3,) in F0 (m).
        joint: index in ``q`` of the joint that drives this bar (legs, the twists' cross-bars and
            the end-effector's when a twist turns it), else ``None``.
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
    """A flat body drawn as a closed polygon: ``"base"``, ``"platform1"``, ``"platform2"`` ...,
    and ``"twistN"`` (the mount on top of an inner twist joint ``psiN``).

    ``vertices`` (k, 3) in F0 (m), in order around the polygon (not repeated at the end).
    """

    name: str
    vertices: Array


@dataclass(frozen=True)
class FrameAxes:
    """A frame drawn as three short axes: ``origin`` (3,) and ``rotation`` (3, 3) in F0.

    ``label`` is ``"F0"`` (the base), ``"F1"`` .. ``"Fm"`` (the platforms of the ``m`` modules)
    and ``"F{m+1}"``, the end-effector's frame drawn at the tip (the paper's F3: its orientation
    is ``C03``; the spec puts its origin at O2, where F2's axes already are).
    """

    label: str
    origin: Array
    rotation: Array


@dataclass(frozen=True)
class MechanismGeometry:
    """Everything drawn of the robot at one configuration ``q`` (m, rad, F0).

    Attributes:
        q: the configuration (n,).
        joints: named joint points (3,): ``A1, B1, A1', B1', A2, ...`` (base and top joints of
            each module), ``O1, O2, ...`` (platform centres), ``P`` (the tip).
        segments: the bars, in the order of :data:`SEGMENT_KINDS`.
        plates: base, platforms and twist mounts as polygons.
        frames: F0, the platforms' frames and the end-effector's as small axes.
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


@dataclass(frozen=True)
class ArmLayout:
    """What the drawing needs of a robot's structure, module by module (``m`` modules, ``n`` joints).

    Attributes:
        joint_names: ``(n,)`` names of the joints, in the order of ``q``.
        lower, upper: ``(n,)`` joint limits (m, rad).
        b, d: ``(m,)`` base and platform half-widths (m).
        planes: ``(m,)`` ``(cos, sin)`` of each module's plane angle (exact for multiples of 90 degrees).
        legs: ``(m,)`` indices in ``q`` of each module's ``(s, v, p)``.
        twists: ``(m,)`` the twist joint after each module as ``(index in q, height in m)``, or None.
        tool: ``(3,)`` tip point from the last mount point, in the end-effector's frame (m).
        tool_rotation: ``(3, 3)`` the tool frame in the end-effector's frame (``z`` its axis).
    """

    joint_names: tuple[str, ...]
    lower: Array
    upper: Array
    b: tuple[float, ...]
    d: tuple[float, ...]
    planes: tuple[tuple[float, float], ...]
    legs: tuple[tuple[int, int, int], ...]
    twists: tuple[tuple[int, float] | None, ...]
    tool: Array
    tool_rotation: Array = field(default_factory=lambda: np.eye(3))

    @property
    def n_modules(self) -> int:
        """Number of modules."""
        return len(self.b)


def arm_layout(parameters: RobotParameters | Stack) -> ArmLayout:
    """The :class:`ArmLayout` of the paper's robot (as its stack) or of a stack."""
    if isinstance(parameters, RobotParameters):
        stack = stack_from_parameters(parameters)
    elif isinstance(parameters, Stack):
        stack = parameters
    else:
        raise InputError(
            f"parameters = {shown(parameters)}: expected RobotParameters or a Stack (see vgtarm.load_robot)"
        )
    twists: list[tuple[int, float] | None] = []
    for module, (_, _, i_p) in zip(stack.modules, stack.leg_indices, strict=True):
        twists.append(None if module.twist is None else (i_p + 1, float(module.twist.height)))
    return ArmLayout(
        joint_names=stack.joint_names,
        lower=stack.lower,
        upper=stack.upper,
        b=tuple(float(m.b) for m in stack.modules),
        d=tuple(float(m.d) for m in stack.modules),
        planes=tuple(plane_direction(m.plane) for m in stack.modules),
        legs=stack.leg_indices,
        twists=tuple(twists),
        tool=np.array(stack.tool, dtype=float),
        tool_rotation=stack.tool_rotation,
    )


def limit_closeness(q: ArrayLike, lower: ArrayLike, upper: ArrayLike) -> Array:
    """How close each joint is to its nearer limit: ``1 - 2 min(u, 1 - u)`` with ``u`` the
    position within ``[lower, upper]``; 0 at mid-range, 1 at a limit, above 1 outside.

    Shapes broadcast; ``(..., n)`` in, ``(..., n)`` out.
    """
    qa, lo, hi = (np.asarray(x, dtype=float) for x in (q, lower, upper))
    u = (qa - lo) / (hi - lo)
    return np.asarray(1.0 - 2.0 * np.minimum(u, 1.0 - u))


def leg_joints(parameters: RobotParameters | Stack) -> list[tuple[int, int, int]]:
    """Indices in ``q`` of ``(s, v, p)`` of each module (``s1, v1, p1`` ... of the joint names)."""
    if isinstance(parameters, Stack):
        return list(parameters.leg_indices)
    found = []
    for k in range(1, len(parameters.modules) + 1):
        try:
            found.append(tuple(JOINT_NAMES.index(f"{leg}{k}") for leg in "svp"))
        except ValueError:
            raise InputError(f"the joint vector {JOINT_NAMES} has no legs s{k}, v{k}, p{k} for module {k}") from None
    return found  # type: ignore[return-value]


def twist_joint() -> int:
    """Index in ``q`` of the paper's robot's twist joint: its one angular (``rad``) joint."""
    angular = [i for i, unit in enumerate(JOINT_UNITS) if unit == "rad"]
    if len(angular) != 1:
        raise InputError(f"expected one angular joint in {JOINT_NAMES}, found {len(angular)}")
    return angular[0]


def twist_joints(parameters: RobotParameters | Stack) -> tuple[int, ...]:
    """Indices in ``q`` of every twist joint of a robot, base first (the paper's: ``(6,)``)."""
    return tuple(twist[0] for twist in arm_layout(parameters).twists if twist is not None)


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


def _diamond(origin: Array, rotation: Array, plane: tuple[float, float], half: float) -> Array:
    """A square plate of half-diagonal ``half`` in the frame ``(origin, rotation)``, with two corners
    on a module's plane of direction ``plane`` (where its base joints are)."""
    c, s = plane
    corners = half * np.array([[c, s, 0.0], [-s, c, 0.0], [-c, -s, 0.0], [s, -c, 0.0]])
    return np.stack([origin + rotation @ corner for corner in corners])


def _twist_rotation(rotation: Array, angle: float) -> Array:
    """``rotation Rz(angle)``: the frame turned by a twist joint about its u3 axis."""
    c, s = np.cos(angle), np.sin(angle)
    return np.asarray(rotation @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))


def _geometry(layout: ArmLayout, q: ArrayLike, fk: ForwardKinematics) -> MechanismGeometry:
    """The drawn geometry of one configuration ``q`` (n,) of a robot laid out as ``layout``."""
    qa = np.asarray(q, dtype=float)
    m, n = layout.n_modules, len(layout.joint_names)
    if qa.shape != (n,) or fk.tip.shape != (3,) or fk.platform_position.shape != (m, 3):
        raise InputError(
            f"q must be one configuration ({n},) with its forward kinematics ({m} platforms), got shape {qa.shape}"
        )
    drawing = _Drawing(layout, qa, fk)
    tip = drawing.end_effector(drawing.modules())
    plates = drawing.plates()
    joints = drawing.joints
    joints.update(drawing.centres)
    joints["P"] = tip
    return MechanismGeometry(
        q=qa.copy(),
        joints=joints,
        segments=tuple(sorted(drawing.segments, key=lambda seg: SEGMENT_KINDS.index(seg.kind))),
        plates=tuple(plates),
        frames=tuple(drawing.frames),
        axis_length=FRAME_AXIS_FRACTION * layout.b[0],
    )


class _Drawing:
    """The parts of :func:`_geometry`'s drawing as they are collected, module by module from the
    base (:meth:`modules`), then the end-effector and the plates: joint points, platform centres,
    bars, twist mounts and frames."""

    def __init__(self, layout: ArmLayout, q: Array, fk: ForwardKinematics) -> None:
        self.layout, self.q, self.fk = layout, q, fk
        self.m = layout.n_modules
        self.closeness = limit_closeness(q, layout.lower, layout.upper)
        self.joints: dict[str, Array] = {}
        self.centres: dict[str, Array] = {}
        self.segments: list[Segment] = []
        self.mounts: dict[int, Plate] = {}  # the plate on top of the twist joint after module k
        self.frames = [FrameAxes("F0", np.zeros(3), np.eye(3))]

    def driven(self, name: str, kind: str, start: Array, end: Array, joint: int | None) -> Segment:
        """A bar, with the joint that drives it and how close that joint is to a limit."""
        if joint is None:
            return Segment(name, kind, start, end)
        return Segment(name, kind, start, end, joint=joint, closeness=float(self.closeness[joint]))

    def modules(self) -> Array:
        """Every module and the twist after it, base first; returns the origin the end-effector's
        tool is mounted at (the last platform's centre, or the top of its twist)."""
        origin, rotation = np.zeros(3), np.eye(3)  # the frame module k stands on
        for k in range(self.m):
            centre, platform = self.module(k, origin, rotation)
            origin, rotation = centre, platform
            twist = self.layout.twists[k]
            if twist is not None:
                origin, rotation = self.twist(k, twist, centre, platform)
        return origin

    def module(self, k: int, origin: Array, rotation: Array) -> tuple[Array, Array]:
        """Module ``k``'s joints, centre, frame and bars, standing on the frame ``(origin,
        rotation)``; returns its platform's centre and frame."""
        layout, joints, number = self.layout, self.joints, k + 1
        c, s = layout.planes[k]
        # (h, z) in the module's plane -> origin + R (-h sin phi, h cos phi, z) in F0
        for name, (h, z) in _module_points(self.q, layout.legs[k], self.fk.passive[k], layout.b[k]).items():
            joints[f"{name}{number}"] = origin + rotation @ np.array([-s * h, c * h, z])
        centre = 0.5 * (joints[f"A'{number}"] + joints[f"B'{number}"])
        platform = self.fk.platform_rotation[k]
        self.centres[f"O{number}"] = centre
        self.frames.append(FrameAxes(f"F{number}", centre, platform))
        self.segments.append(Segment(f"base{number}", "base", joints[f"A{number}"], joints[f"B{number}"]))
        i_s, i_v, i_p = layout.legs[k]
        for index, start, end in ((i_s, "A", "A'"), (i_v, "B", "B'"), (i_p, "A", "B'")):
            self.segments.append(
                self.driven(
                    layout.joint_names[index], "leg", joints[f"{start}{number}"], joints[f"{end}{number}"], index
                )
            )
        self.segments.append(Segment(f"platform{number}", "platform", joints[f"A'{number}"], joints[f"B'{number}"]))
        return centre, platform

    def twist(self, k: int, twist: tuple[int, float], centre: Array, platform: Array) -> tuple[Array, Array]:
        """The twist joint after module ``k`` (its axis; inside the arm also its part, cross-bar
        and mount plate); returns the frame what follows stands on."""
        layout = self.layout
        index, height = twist
        axis = platform[:, 2]
        mount = centre + height * axis
        overhang = TWIST_AXIS_OVERHANG * height
        ends = (centre - overhang * axis, mount + overhang * axis)
        rotation = self.fk.rotation if k == self.m - 1 else _twist_rotation(platform, float(self.q[index]))
        if k == self.m - 1:  # the end-effector's twist: its part belongs to the tool drawn below
            self.segments.append(Segment("twist_axis", "twist_axis", *ends))
            return mount, rotation
        label = f"{k + 2}"  # psi{k+1} after module k, as the stack names it
        half_bar = END_EFFECTOR_FRACTION * layout.d[k]
        bar_centre, bar = centre + 0.5 * height * axis, rotation[:, 0]
        self.segments.append(Segment(f"twist{label}", "twist", centre, mount))
        self.segments.append(Segment(f"twist_axis{label}", "twist_axis", *ends))
        self.segments.append(
            self.driven(
                f"twist_bar{label}",
                "twist_bar",
                bar_centre - half_bar * bar,
                bar_centre + half_bar * bar,
                index,
            )
        )
        self.mounts[k] = Plate(f"twist{label}", _diamond(mount, rotation, layout.planes[k + 1], layout.b[k + 1]))
        return mount, rotation

    def end_effector(self, origin: Array) -> Array:
        """The tool from the last platform's centre to the tip, the end-effector's cross-bar and
        its frame, with the tool mounted at ``origin``; returns the tip."""
        layout, fk, last = self.layout, self.fk, self.m - 1
        centre = self.centres[f"O{self.m}"]
        tip = origin + fk.rotation @ layout.tool
        self.segments.append(Segment("tool", "tool", centre, tip))
        twist = layout.twists[last]
        half_bar = END_EFFECTOR_FRACTION * layout.d[last]
        if twist is not None:
            bar_centre = centre + 0.5 * twist[1] * fk.platform_rotation[last][:, 2]
        else:
            bar_centre = 0.5 * (centre + tip)
        bar = fk.rotation[:, 0]
        end_joint = None if twist is None else twist[0]
        self.segments.append(
            self.driven(
                "end_effector", "end_effector", bar_centre - half_bar * bar, bar_centre + half_bar * bar, end_joint
            )
        )
        self.frames.append(FrameAxes(f"F{self.m + 1}", tip, fk.rotation))
        axis = fk.rotation @ layout.tool_rotation[:, 2]
        self.segments.append(Segment("tool_axis", "tool_axis", tip, tip + TOOL_AXIS_FRACTION * layout.b[0] * axis))
        return tip

    def plates(self) -> list[Plate]:
        """The base, each platform and the twist mounts: each platform has its top joints on one
        diagonal; on the other, the base joints of the module standing right on it (not in the
        same plane), else its own half-width across its plane."""
        layout, joints, last = self.layout, self.joints, self.m - 1
        plates = [Plate("base", _diamond(np.zeros(3), np.eye(3), layout.planes[0], layout.b[0]))]
        for k in range(self.m):
            number = k + 1
            centre, platform = self.centres[f"O{number}"], self.fk.platform_rotation[k]
            c, s = layout.planes[k]
            on_top = (
                k < last
                and layout.twists[k] is None
                and abs(_relative_sine(layout.planes[k], layout.planes[k + 1])) > 1e-9
            )
            if on_top:
                across = (joints[f"A{number + 1}"], joints[f"B{number + 1}"])
            else:
                side = layout.d[k] * (platform @ np.array([c, s, 0.0]))
                across = (centre + side, centre - side)
            corners = np.stack([joints[f"A'{number}"], across[0], joints[f"B'{number}"], across[1]])
            plates.append(Plate(f"platform{number}", corners))
            if k in self.mounts:
                plates.append(self.mounts[k])
        return plates


def _relative_sine(below: tuple[float, float], above: tuple[float, float]) -> float:
    """``sin(phi_above - phi_below)`` of two stacked modules' plane directions ``(cos, sin)``: 0 when
    the upper module lies in the plane of the lower one, its base joints on the platform's edge."""
    return above[1] * below[0] - above[0] * below[1]


def geometry_from_kinematics(
    parameters: RobotParameters | Stack, q: ArrayLike, fk: ForwardKinematics
) -> MechanismGeometry:
    """The drawn geometry of one configuration ``q`` (n,) from its forward kinematics ``fk``.

    ``parameters`` are the robot's (:attr:`vgtarm.Robot.parameters`: the paper's or a stack). ``fk``
    must be the forward kinematics of ``q`` alone (no batch axes); the passive angles and the
    platform rotations are taken from it, the points are built from the module equations.
    """
    qa = np.asarray(q, dtype=float)
    if qa.ndim != 1 or fk.tip.shape != (3,):
        raise InputError(f"q must be one configuration (n,), got shape {qa.shape}")
    return _geometry(arm_layout(parameters), qa, fk)


def mechanism_geometry(robot: Robot, q: ArrayLike) -> MechanismGeometry:
    """The drawn geometry of ``robot`` at one configuration ``q`` (n,) (m, rad)."""
    qa = np.asarray(q, dtype=float)
    if qa.ndim != 1:
        raise InputError(f"q must be one configuration (n,), got shape {qa.shape}; use mechanism_geometries")
    return geometry_from_kinematics(robot.parameters, qa, robot.forward_kinematics(qa))


def mechanism_geometries(robot: Robot, q: ArrayLike) -> list[MechanismGeometry]:
    """The drawn geometry of every configuration of ``q`` (k, n), from one batched FK call."""
    qa = np.asarray(q, dtype=float)
    if qa.ndim != 2:
        raise InputError(f"q must be a batch of configurations (k, n), got shape {qa.shape}")
    fk = robot.forward_kinematics(qa)
    layout = arm_layout(robot.parameters)
    return [
        _geometry(
            layout,
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
