"""The mechanism drawn with Matplotlib: legs, platforms, twist axis, tool (and its axis) and frames, to scale.

:func:`draw_mechanism` draws one :class:`~vgtarm.app.pictures.geometry.MechanismGeometry` into a 3-D Axes
and returns the artists, which :meth:`MechanismArtists.update` moves to another configuration
(the animation uses that). :func:`pose_figure` makes the picture of ``vgtarm draw``: the plane of
module 1, the plane of module 2 and an isometric view side by side (a stack: module 1's plane, the
first plane across it if any, see :func:`plane_views`), legs and twists coloured by how close
their joints are to their limits, with a colour bar. Coordinates are drawn in mm with equal scaling on
every axis; every bar's Line3D carries the segment's name as its ``gid``, so its drawn data can be
read back (the tests do).

Nothing here touches pyplot; the figures render headless with the Agg canvas.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Colormap, LinearSegmentedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d.art3d import Line3D, Poly3DCollection
from mpl_toolkits.mplot3d.axes3d import Axes3D
from numpy.typing import ArrayLike, NDArray

from ...errors import InputError
from ...markup import mpl_text
from ...model.robot import Robot
from .geometry import MechanismGeometry, mechanism_geometry

#: Drawing unit: metres to millimetres.
MM = 1e3
#: Colours of the legs' closeness to a limit at 0, 0.5 and 1: green in mid-range, amber, red at a limit.
CLOSENESS_COLOURS = ("#1a9850", "#e8a200", "#d73027")
#: Colour map of the legs' closeness to a limit.
LEG_CMAP = LinearSegmentedColormap.from_list("vgtarm_closeness", CLOSENESS_COLOURS)
#: Colour scale of the closeness: 0 (mid-range) to 1 (at a limit).
CLOSENESS_NORM = Normalize(vmin=0.0, vmax=1.0)
#: Label of the colour bar.
CLOSENESS_LABEL = "closeness to a joint limit (0 mid-range, 1 at a limit)"
#: A view: title, (elevation, azimuth) in degrees, axis seen end-on (hidden, its ticks dropped) or None.
View = tuple[str, tuple[float, float], int | None]
#: The three views of :func:`pose_figure` of the paper's robot.
VIEWS: tuple[View, ...] = (
    ("module 1's plane (u2-u3 of F0)", (0.0, 0.0), 0),
    ("module 2's plane (u1-u3 of F1)", (0.0, -90.0), 1),
    ("isometric", (22.0, -52.0), None),
)
#: Size of the paper's robot's :func:`pose_figure` (inches).
PAPER_FIGURE_SIZE = (11.0, 5.6)
#: Size of a stack's :func:`pose_figure` (inches).
STACK_FIGURE_SIZE = (11.0, 6.4)
#: A robot taller than wide (:data:`PLANE_ZOOM_ASPECT`, a stack): a wider figure and the
#: magnification of its plane views. Matplotlib draws a 3-D panel in a square as wide as the
#: panel, so a tall robot is as tall as a panel is wide: wider panels draw it larger (by 40 % from
#: the 6.4 in high stack figure's), and a magnification past 1.1 would cut its ends off.
TALL_FIGURE_SIZE = (14.0, 7.0)
TALL_ZOOM = 1.1
#: Plane views are magnified 1.3 times unless the robot is taller than this times its width.
PLANE_ZOOM_ASPECT = 3.0
#: Longest line of joint values in the title of :func:`pose_figure` (characters).
TITLE_WIDTH = 125
#: Two modules' planes closer than this (degrees) are seen in one view.
SAME_VIEW_DEGREES = 10.0
_STYLE: dict[str, dict[str, Any]] = {
    "base": {"color": "0.25", "linewidth": 4.0},
    "leg": {"linewidth": 3.2, "solid_capstyle": "round"},
    "platform": {"color": "0.15", "linewidth": 3.0},
    "twist": {"color": "black", "linewidth": 2.6},
    "twist_axis": {"color": "0.45", "linewidth": 0.9, "linestyle": (0, (4, 3))},
    "twist_bar": {"linewidth": 3.0},
    "tool": {"color": "black", "linewidth": 2.6},
    "end_effector": {"linewidth": 3.0},
    "tool_axis": {"color": "tab:red", "linewidth": 1.4, "linestyle": (0, (6, 2, 1, 2))},
}
#: Colours of the plates: the base, then the platforms alternately (the paper's two: blue, purple).
_PLATE_COLOURS = {"base": "0.55", "platform1": "tab:blue", "platform2": "tab:purple"}
_PLATFORM_COLOURS = ("tab:blue", "tab:purple")
_MOUNT_COLOUR = "tab:olive"
#: Colour of an end-effector's cross-bar that no joint turns (a stack ending without a twist).
_FIXED_BAR_COLOUR = "0.15"
_FRAME_COLOURS = ("tab:red", "tab:green", "tab:blue")


@dataclass
class MechanismArtists:
    """The artists of one drawn mechanism in ``ax``; :meth:`update` redraws them at a new pose.

    ``lines`` maps each segment's name to its Line3D (data in mm); ``plates`` each plate's name to
    its polygon; ``frames`` each frame's label to its three axis lines and its text; ``joints`` the
    scatter of the legs' joints.
    """

    ax: Axes3D
    cmap: Colormap
    lines: dict[str, Line3D] = field(default_factory=dict)
    plates: dict[str, Poly3DCollection] = field(default_factory=dict)
    frames: dict[str, tuple[list[Line3D], object]] = field(default_factory=dict)
    labels: dict[str, object] = field(default_factory=dict)
    joints: Any = None

    def update(self, geometry: MechanismGeometry) -> None:
        """Move every artist to ``geometry`` (same robot, another configuration)."""
        for seg in geometry.segments:
            line = self.lines[seg.name]
            xyz = np.stack([seg.start, seg.end]) * MM
            line.set_data_3d(xyz[:, 0], xyz[:, 1], xyz[:, 2])
            if seg.closeness is not None:
                line.set_color(self.cmap(CLOSENESS_NORM(seg.closeness)))
            if seg.name in self.labels:
                mid = 0.5 * (seg.start + seg.end) * MM
                self.labels[seg.name].set_position_3d(mid)  # type: ignore[attr-defined]
        for plate in geometry.plates:
            self.plates[plate.name].set_verts([plate.vertices * MM])
        if self.joints is not None:
            points = _joint_points(geometry) * MM
            self.joints._offsets3d = (points[:, 0], points[:, 1], points[:, 2])
        for frame in geometry.frames:
            axes_lines, text = self.frames[frame.label]
            for i, line in enumerate(axes_lines):
                end = frame.origin + geometry.axis_length * frame.rotation[:, i]
                xyz = np.stack([frame.origin, end]) * MM
                line.set_data_3d(xyz[:, 0], xyz[:, 1], xyz[:, 2])
            text.set_position_3d(frame.origin * MM)  # type: ignore[attr-defined]


def _joint_points(geometry: MechanismGeometry) -> NDArray[np.float64]:
    """The legs' end joints (k, 3) in m (``A``, ``B``, ``A'``, ``B'`` of each module; platform
    centres and tip excluded)."""
    return np.stack([p for name, p in geometry.joints.items() if name[0] in "AB"])


def _plate_colour(name: str) -> str:
    if name in _PLATE_COLOURS:
        return _PLATE_COLOURS[name]
    if name.startswith("platform") and name[len("platform") :].isdigit():
        return _PLATFORM_COLOURS[(int(name[len("platform") :]) - 1) % 2]
    return _MOUNT_COLOUR if name.startswith("twist") else "0.6"


def _cmap(cmap: str | Colormap) -> Colormap:
    from matplotlib import colormaps

    return colormaps[cmap] if isinstance(cmap, str) else cmap


def draw_mechanism(
    geometry: MechanismGeometry,
    ax: Axes3D | None = None,
    *,
    cmap: str | Colormap = LEG_CMAP,
    frames: bool = True,
    leg_labels: bool = True,
) -> MechanismArtists:
    """Draw ``geometry`` into the 3-D Axes ``ax`` (a new figure's when None), in mm.

    Returns the :class:`MechanismArtists` (``.ax`` is the Axes). Legs and the twists' bars (the
    end-effector's among them) are coloured by their joint's closeness to a limit with ``cmap``;
    ``frames`` draws the frames (F0..F3 for the paper's robot);
    ``leg_labels`` writes each leg's joint name at its middle.
    """
    if ax is None:
        ax = Figure(figsize=(6.0, 6.0), layout="constrained").add_subplot(projection="3d")
    colours = _cmap(cmap)
    artists = MechanismArtists(ax=ax, cmap=colours)
    for plate in geometry.plates:
        poly = Poly3DCollection(
            [plate.vertices * MM],
            facecolor=_plate_colour(plate.name),
            edgecolor="none",
            alpha=0.28,
        )
        poly.set_gid(plate.name)
        ax.add_collection3d(poly)
        artists.plates[plate.name] = poly
    for seg in geometry.segments:
        style = dict(_STYLE[seg.kind])
        if seg.closeness is not None:
            style["color"] = colours(CLOSENESS_NORM(seg.closeness))
        style.setdefault("color", _FIXED_BAR_COLOUR)
        xyz = np.stack([seg.start, seg.end]) * MM
        (line,) = ax.plot(xyz[:, 0], xyz[:, 1], xyz[:, 2], gid=seg.name, **style)
        artists.lines[seg.name] = line
        if leg_labels and seg.kind == "leg":
            mid = 0.5 * (seg.start + seg.end) * MM
            artists.labels[seg.name] = ax.text(*mid, f" {seg.name}", fontsize=7, color="0.1")
    joints = _joint_points(geometry) * MM
    artists.joints = ax.scatter(
        joints[:, 0], joints[:, 1], joints[:, 2], s=9, color="0.1", depthshade=False, gid="joints"
    )
    if frames:
        for frame in geometry.frames:
            axis_lines = []
            for i in range(3):
                end = frame.origin + geometry.axis_length * frame.rotation[:, i]
                xyz = np.stack([frame.origin, end]) * MM
                (line,) = ax.plot(
                    xyz[:, 0],
                    xyz[:, 1],
                    xyz[:, 2],
                    color=_FRAME_COLOURS[i],
                    linewidth=1.2,
                    gid=f"{frame.label}.u{i + 1}",
                )
                axis_lines.append(line)
            text = ax.text(*(frame.origin * MM), f"  {frame.label}", fontsize=7, color="0.3")
            artists.frames[frame.label] = (axis_lines, text)
    return artists


def set_equal_extent(
    ax: Axes3D, points: ArrayLike, *, pad: float = 0.06, hidden: int | None = None, zoom: float = 1.0
) -> None:
    """Limits that hold ``points`` (k, 3) in drawing units with one scale on every axis.

    The box's sides are proportional to the data's ranges (true proportions); ``hidden`` is the
    axis seen end-on in a plane view, whose ticks are dropped.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = float((hi - lo).max())
    margin = pad * span
    lo, hi = lo - margin, hi + margin
    ranges = np.maximum(hi - lo, 0.05 * span)
    centre = 0.5 * (lo + hi)
    lo, hi = centre - ranges / 2, centre + ranges / 2
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(tuple(ranges), zoom=zoom)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5))
    if hidden is not None:
        [ax.set_xticks, ax.set_yticks, ax.set_zticks][hidden]([])
        [ax.set_xlabel, ax.set_ylabel, ax.set_zlabel][hidden]("")


def label_axes(ax: Axes3D) -> None:
    """Axis labels in mm."""
    ax.set_xlabel("x (mm)", fontsize=8)
    ax.set_ylabel("y (mm)", fontsize=8)
    ax.set_zlabel("z (mm)", fontsize=8)
    ax.tick_params(labelsize=7)


def plane_views(geometry: MechanismGeometry) -> tuple[View, ...]:
    """The views of a stack's :func:`pose_figure`: module 1's plane, the plane of the first module
    across it (more than :data:`SAME_VIEW_DEGREES` away) if there is one, and an isometric view.

    A module's plane is seen face on, level, along its normal as it stands in ``geometry`` (its
    base joints' line turned a quarter turn about u3), from the side with the azimuth in
    [-90, 90) degrees; a plane view along u1 or u2 hides that axis.
    """
    views: list[View] = []
    seen: list[float] = []
    for k, base in enumerate(geometry.of_kind("base"), start=1):
        h = base.end - base.start  # A -> B: the module's h axis
        if math.hypot(h[0], h[1]) <= 1e-6 * float(np.linalg.norm(h)):
            continue  # a plane lying flat: no level view shows it
        azimuth = (math.degrees(math.atan2(-h[0], h[1])) + 90.0) % 180.0 - 90.0
        if any(abs((azimuth - other + 90.0) % 180.0 - 90.0) < SAME_VIEW_DEGREES for other in seen):
            continue
        seen.append(azimuth)
        hidden = 0 if abs(azimuth) < 1e-9 else 1 if abs(azimuth + 90.0) < 1e-9 else None
        views.append((f"module {k}'s plane", (0.0, round(azimuth, 9) + 0.0), hidden))
        if len(views) == 2:
            break
    return (*views, VIEWS[-1])


def pose_figure(
    robot: Robot,
    q: ArrayLike,
    *,
    title: str | None = None,
    cmap: str | Colormap = LEG_CMAP,
    views: Sequence[View] | None = None,
    figsize: tuple[float, float] | None = None,
    dpi: float = 100.0,
) -> Figure:
    """The robot at ``q`` (n,) seen in each of ``views``, legs and twists coloured by closeness
    to their limits, with a colour bar.

    ``views`` default: both operating planes and an isometric view (:data:`VIEWS`) for the paper's
    robot, :func:`plane_views` for a stack. ``figsize`` default: :data:`PAPER_FIGURE_SIZE` for the
    paper's robot, :data:`STACK_FIGURE_SIZE` for a stack (room for a title of many joints).
    """
    qa = np.asarray(q, dtype=float)
    n = robot.n_joints
    if qa.shape != (n,):
        raise InputError(f"q must hold {n} joint values {list(robot.joint_names)}, got shape {qa.shape}")
    geometry = mechanism_geometry(robot, qa)
    if views is None:
        views = plane_views(geometry) if robot.is_stack else VIEWS
    spans = np.ptp(geometry.points(), axis=0)
    # plane views are magnified to fill their panel; a tall robot (a stack) gets a wider figure
    tall = spans[2] > PLANE_ZOOM_ASPECT * max(spans[0], spans[1])
    if figsize is None:
        figsize = STACK_FIGURE_SIZE if robot.is_stack else PAPER_FIGURE_SIZE
        if tall:
            figsize = TALL_FIGURE_SIZE
    plane_zoom = TALL_ZOOM if tall else 1.3
    fig = Figure(figsize=figsize, dpi=dpi, layout="constrained")
    axes = []
    for i, (name, (elev, azim), hidden) in enumerate(views):
        ax = fig.add_subplot(1, len(views), i + 1, projection="3d")
        ax.set_proj_type("ortho")
        draw_mechanism(geometry, ax, cmap=cmap, leg_labels=hidden is None)
        ax.view_init(elev=elev, azim=azim)
        label_axes(ax)
        set_equal_extent(ax, geometry.points() * MM, hidden=hidden, zoom=1.0 if hidden is None else plane_zoom)
        ax.set_title(name, fontsize=10)
        if tall:  # a narrow panel: few ticks across, so that their labels do not run together
            for index, axis in enumerate((ax.xaxis, ax.yaxis)):
                if index != hidden:  # the axis seen end-on keeps no ticks
                    axis.set_major_locator(MaxNLocator(3))
        axes.append(ax)
    fig.colorbar(
        ScalarMappable(norm=CLOSENESS_NORM, cmap=_cmap(cmap)),
        ax=axes,
        shrink=0.6,
        label=CLOSENESS_LABEL,
        location="right",
    )
    # one line of "name = value" entries, wrapped between entries (a stack's many joints)
    entries = [
        f"{name}\N{NO-BREAK SPACE}=\N{NO-BREAK SPACE}{value:.4g}"
        for name, value in zip(robot.joint_names, qa, strict=True)
    ]
    values = "\n".join(textwrap.wrap(", ".join(entries), TITLE_WIDTH)).replace("\N{NO-BREAK SPACE}", " ")
    tip = np.round(geometry.tip * MM, 1) + 0.0  # no "-0.0" for a round-off below 0.05 mm
    name = mpl_text(robot.parameters.name)  # a user's name: a "$" in it starts no math
    fig.suptitle(
        title or f"{name}\n{values} (m, rad); tip ({tip[0]:.1f}, {tip[1]:.1f}, {tip[2]:.1f}) mm",
        fontsize=10,
    )
    return fig
